"""A method record's types, sizes and numbers checked before it is built, each failure one line
naming the record and the field: a bad record is refused on its own and the plugin's other
records still load (`harness.registry`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from decimal import Decimal
from fractions import Fraction
from typing import Any

import numpy as np

from harness.errors import InputError
from harness.names import check_name
from harness.tolerances import MAX_CLAIMED_ORDER, MAX_RECORD_ENTRIES

__all__ = ["check_record", "check_claimed_order"]

_ARRAYS = {"A": 2, "b": 1, "c": 1, "b_hat": 1, "alpha": 1, "beta": 1}
_MAX_TEXT = 2000  # a reference or description longer than this is not one


def check_claimed_order(value: Any, label: str, *, optional: bool = False) -> int | None:
    """`value` as a claimed order: a whole number in [1, MAX_CLAIMED_ORDER] (a bool is not one).

    Parameters
    ----------
    value : the claimed order; label : how the message names it; optional : None is allowed.

    Returns
    -------
    int or None
    """
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise InputError(f"{label} must be a whole number, got {value!r} "
                         f"({type(value).__name__})"[:300])
    if not 1 <= value <= MAX_CLAIMED_ORDER:
        shown = value if abs(value) < 10**12 else f"a {len(str(abs(value)))}-digit number"
        raise InputError(f"{label} must be between 1 and {MAX_CLAIMED_ORDER}, got {shown}")
    return int(value)


def check_record(record: Any) -> str:
    """Check a method record's fields before anything is built from it (see the module docstring).

    Parameters
    ----------
    record : the record, a mapping (`harness.methods`).

    Returns
    -------
    str: the record's name.
    """
    if not isinstance(record, Mapping):
        raise InputError(f"a method record must be a mapping, got {type(record).__name__}")
    name = check_name(record.get("name"), "method record: `name`")
    where = f"method record {name!r}"
    check_claimed_order(record.get("claimed_order"), f"{where}: `claimed_order`")
    check_claimed_order(record.get("claimed_embedded_order"),
                        f"{where}: `claimed_embedded_order`", optional=True)
    for key in ("reference", "description"):
        value = record.get(key, "")
        if not isinstance(value, str) or len(value) > _MAX_TEXT:
            raise InputError(f"{where}: `{key}` must be a string of at most {_MAX_TEXT} "
                             f"characters, got {type(value).__name__}")
    for key, ndim in _ARRAYS.items():
        if record.get(key) is not None:
            _check_array(record[key], ndim, f"{where}: `{key}`")
    if "sequence" in record:
        seq = _entries(record["sequence"], f"{where}: `sequence`")
        for i, step in enumerate(seq):
            if isinstance(step, str | bytes) or not hasattr(step, "__len__") or len(step) != 2:
                raise InputError(f"{where}: `sequence[{i}]` must be a pair (\"D\" or \"K\", "
                                 f"coefficient), got {step!r}"[:300])
            _check_number(step[1], f"{where}: `sequence[{i}]` coefficient")
    stability = record.get("stability")
    if stability is not None:
        if not isinstance(stability, Mapping):
            raise InputError(f"{where}: `stability` must be a mapping, got {type(stability).__name__}")
        for k, v in stability.items():
            _check_number(v, f"{where}: `stability[{k!r}]`")
    return name


def _entries(values: Any, label: str) -> list:
    if isinstance(values, str | bytes | Mapping) or not hasattr(values, "__len__"):
        raise InputError(f"{label} must be a list, got {type(values).__name__}")
    if len(values) > MAX_RECORD_ENTRIES:
        raise InputError(f"{label} must have at most {MAX_RECORD_ENTRIES} entries, got {len(values)}")
    return list(values)


def _check_array(values: Any, ndim: int, label: str) -> None:
    rows = _entries(values, label)
    if ndim == 2:
        for i, row in enumerate(rows):
            for j, x in enumerate(_entries(row, f"{label}[{i}]")):
                _check_number(x, f"{label}[{i}][{j}]")
    else:
        for i, x in enumerate(rows):
            _check_number(x, f"{label}[{i}]")


def _check_number(x: Any, label: str) -> None:
    """A real coefficient: int, float, Fraction, Decimal or a short decimal/rational string,
    finite and within float64's range (a bool is not a coefficient)."""
    if isinstance(x, str):
        if len(x) > 100:
            raise InputError(f"{label} must be a number or a short numeric string, got a string "
                             f"of {len(x)} characters")
        return  # parsed, and checked, where the coefficients are read
    if isinstance(x, bool) or not isinstance(x, int | float | Fraction | Decimal | np.integer
                                             | np.floating):
        raise InputError(f"{label} must be a real number, got {x!r} ({type(x).__name__})"[:300])
    if isinstance(x, int | Fraction) and _digits(x) > 400:
        raise InputError(f"{label} is too large or too finely divided for float64 "
                         f"(about {_digits(x)} digits)")
    try:
        value = float(x)
    except (OverflowError, ValueError):
        raise InputError(f"{label} is outside float64's range") from None
    if not math.isfinite(value):
        raise InputError(f"{label} must be finite, got {value!r}")


def _digits(x: int | Fraction) -> int:
    """Decimal digits of the larger of numerator and denominator, from bit lengths (printing a
    huge integer is itself slow and capped by Python)."""
    f = Fraction(x)
    return int(max(abs(f.numerator).bit_length(), f.denominator.bit_length()) * 0.30103) + 1
