"""Argument checks shared by the theory functions: a one-line `InputError` naming the argument."""

from __future__ import annotations

from typing import Any

import numpy as np

from harness.errors import InputError

__all__ = ["check_int", "check_type"]

def check_int(value: Any, name: str, lo: int, hi: int) -> int:
    """`value` as an int, after checking it is a whole number in [`lo`, `hi`].

    Parameters
    ----------
    value : the argument; name : its name in the error message; lo, hi : the allowed range.

    Returns
    -------
    int
        `value` as a Python int.
    """
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise InputError(f"`{name}` must be a whole number, got {value!r}")
    if not lo <= value <= hi:
        raise InputError(f"`{name}` must lie in [{lo}, {hi}], got {value}")
    return int(value)


def check_type(obj: Any, cls: type, name: str) -> None:
    """Raise `InputError` naming `name` unless `obj` is an instance of `cls`."""
    if not isinstance(obj, cls):
        raise InputError(f"`{name}` must be a {cls.__name__}, got {type(obj).__name__}")
