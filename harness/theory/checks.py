"""Argument checks shared by the theory functions: a one-line `InputError` naming the argument."""

from __future__ import annotations

from typing import Any

import numpy as np

from harness.errors import InputError

__all__ = ["FAMILIES", "check_int", "check_type", "family_of"]

# The coefficient families the theory reads: the `family` tag each coefficient class of
# `harness.coefficients` declares -> that class's name (for messages). The theory reads the tag and
# the arrays and never imports the classes, so the one arrow between the two modules points from
# the coefficient objects to the theory they are asked about.
FAMILIES = {
    "runge-kutta": "ButcherTableau",
    "splitting": "SplittingScheme",
    "multistep": "LinearMultistep",
    "second-order multistep": "SecondOrderMultistep",
}

def check_int(value: Any, name: str, lo: int, hi: int) -> int:
    """`value` as an int, after checking it is a whole number in [`lo`, `hi`].

    Parameters
    ----------
    value : the argument; name : its name in the error message; lo, hi : the allowed range.

    Returns
    -------
    int: `value` as a Python int.
    """
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise InputError(f"`{name}` must be a whole number, got {value!r}")
    if not lo <= value <= hi:
        raise InputError(f"`{name}` must lie in [{lo}, {hi}], got {value}")
    return int(value)


def family_of(obj: Any) -> str | None:
    """The coefficient family `obj` declares.

    Parameters
    ----------
    obj : any object; a coefficient object declares its family as the class attribute `family`.

    Returns
    -------
    str or None: one of the keys of `FAMILIES`, or None when `obj` declares none of them.
    """
    family = getattr(type(obj), "family", None)
    return family if isinstance(family, str) and family in FAMILIES else None


def check_type(obj: Any, family: str, name: str) -> None:
    """Raise `InputError` naming `name` unless `obj` is a coefficient object of `family`.

    Parameters
    ----------
    obj : the argument; family : a key of `FAMILIES`; name : the argument's name in the message.
    """
    if family_of(obj) != family:
        raise InputError(f"`{name}` must be a {FAMILIES[family]}, got {type(obj).__name__}")
