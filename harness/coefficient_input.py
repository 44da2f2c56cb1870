"""Reading coefficients as they are typed: numbers, decimal strings and exact rationals ("2/3"),
their exact form where they are given exactly (`harness.extended` needs better than float64),
and the precision of a table printed as cut decimals.

Used by the coefficient objects of `harness.coefficients` (which re-exports `as_float_array` and
`exact_value`) and by the method records of `harness.methods`.
"""

from __future__ import annotations

from collections.abc import Sequence
from decimal import Decimal
from fractions import Fraction

import numpy as np

from harness.errors import CoefficientError
from harness.tolerances import COEFFICIENT_TOL, COEFFICIENT_ULPS, EPS, PUBLISHED_MIN_DIGITS

__all__ = ["Number", "as_float_array", "close_to_rounding", "exact_value", "exact_rows",
           "published_precision"]

# A coefficient as it may be typed: a float, an int or an exact rational.
Number = float | int | Fraction


def _real(v) -> float:
    """One coefficient as float64: numbers as they are, strings as decimals ("0.25") or as exact
    rationals ("2/3", rounded once)."""
    if isinstance(v, str) and "/" in v:
        return float(Fraction(v.strip()))
    return float(v)


def as_float_array(values: Sequence, name: str, ndim: int) -> np.ndarray:
    """Convert coefficients (floats, ints, Fractions, decimal or rational strings such as "2/3",
    nested lists) to a read-only float64 array.

    Parameters
    ----------
    values : sequence (nested for ndim 2) of numbers or strings; name : str, the argument's name
    in errors; ndim : int, 1 or 2.

    Returns
    -------
    ndarray: read-only float64. Raises CoefficientError for a non-number, a wrong shape or a
    non-finite value.
    """
    try:
        arr = np.array(
            [[_real(v) for v in row] for row in values] if ndim == 2 else [_real(v) for v in values],
            dtype=np.float64,
        )
    except (TypeError, ValueError, ZeroDivisionError, OverflowError) as exc:
        raise CoefficientError(f"`{name}` must hold real numbers in float64's range: {exc}") from None
    if arr.ndim != ndim:
        raise CoefficientError(f"`{name}` must be {ndim}-dimensional, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise CoefficientError(f"`{name}` must be finite, got {arr.tolist()}")
    arr.setflags(write=False)
    return arr


def published_precision(*values) -> float:
    """Half a unit in the last digit of the coarsest coefficient typed as a cut decimal (shortest
    float text of PUBLISHED_MIN_DIGITS to 15 significant digits), else 0.0. Integers and
    Fractions are exact rationals, not printed decimals, whatever their float text looks like
    (an exact extrapolation weight such as 1e8/807 prints as 123915.73729863692): they are
    passed over.

    Parameters
    ----------
    *values : the coefficients as given (arrays, nested sequences or numbers).

    Returns
    -------
    float
        The printing's half unit, or 0.0 when no coefficient is a cut decimal.
    """
    def flat(v):
        if isinstance(v, np.ndarray):
            yield from v.ravel().tolist()
        elif isinstance(v, (list, tuple)):
            for x in v:
                yield from flat(x)
        else:
            yield v

    typed = [float(Fraction(x)) if isinstance(x, str) else float(x) for v in values for x in flat(v)
             if not (isinstance(x, (int, Fraction)) and not isinstance(x, bool))]
    cut = [Decimal(repr(x)).as_tuple() for x in typed if x != 0.0]
    return max([0.5 * 10.0 ** int(e) for _, d, e in cut if PUBLISHED_MIN_DIGITS <= len(d) <= 15],
               default=0.0)


def exact_value(x) -> Fraction | None:
    """`x` as an exact rational when it is given exactly (int, Fraction, Decimal, a decimal
    string, or a float that is a short dyadic such as 0.5), else None: a float like 1/3 is only
    a float64 approximation, and extended-precision runs (`harness.extended`) need better.

    Parameters
    ----------
    x : a number or a string.

    Returns
    -------
    Fraction or None.
    """
    if isinstance(x, bool):
        return None
    if isinstance(x, (int, Fraction, Decimal, str)):
        try:
            return Fraction(x)
        except (ValueError, ZeroDivisionError):
            return None
    if isinstance(x, (float, np.floating)) and np.isfinite(x):
        f = Fraction(float(x))
        return f if f.denominator <= _EXACT_DYADIC and abs(f.numerator) <= _EXACT_DYADIC else None
    return None


def exact_rows(values, ndim: int):
    """Nested tuples of `exact_value`s, or None when any entry is not exact.

    Parameters
    ----------
    values : a sequence (ndim 1) or a sequence of rows (ndim 2); ndim : int, 1 or 2.

    Returns
    -------
    tuple of Fraction (ndim 1), tuple of tuples (ndim 2), or None.
    """
    try:
        rows = [values] if ndim == 1 else list(values)
        out = tuple(tuple(exact_value(x) for x in row) for row in rows)
    except TypeError:
        return None
    if any(v is None for row in out for v in row):
        return None
    return out[0] if ndim == 1 else out


# A float with numerator and denominator (a power of two) at most this is taken as exact (0.5,
# 0.25, 3.0): a rounded decimal such as 0.1 or 1/3 has a 2^52-sized denominator.
_EXACT_DYADIC = 1 << 20


def close_to_rounding(a: float, b: float, size: float = 1.0, terms: int = 1) -> bool:
    """a == b up to the rounding of the coefficients that produced them: `size` is the sum of
    the magnitudes of the `terms` numbers summed (a tableau whose weights sum |b| to 2842 rounds
    its sum to ~1e-13, and that is no defect).

    Parameters
    ----------
    a, b : float, the values compared; size : float, the magnitudes' sum; terms : int, how many
    numbers were summed.

    Returns
    -------
    bool: True within COEFFICIENT_TOL or COEFFICIENT_ULPS roundings of the size.
    """
    scale = max(1.0, abs(a), abs(b), float(size))
    return abs(a - b) <= max(COEFFICIENT_TOL, COEFFICIENT_ULPS * EPS * (terms + 1) * scale)
