"""Input checks shared by the public API: times, ensemble sizes and states, each a one-line
`InputError` naming the argument."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from harness.errors import InputError
from harness.tolerances import MAX_ENSEMBLE_SIZE


def check_time(value: Any, name: str) -> float:
    """`value` as a finite float, or `InputError` naming `name`.

    Parameters
    ----------
    value : the time given by the caller; name : the argument's name in the error message.

    Returns
    -------
    float
    """
    x = _as_float(value, f"`{name}` must be a real number, got {value!r}")
    if not math.isfinite(x):
        raise InputError(f"`{name}` must be finite, got {x!r}")
    return x


def check_ensemble_size(size: Any) -> int:
    """`size` as an int in [1, MAX_ENSEMBLE_SIZE], or `InputError` naming `size`.

    Parameters
    ----------
    size : any, the requested ensemble size (checked by `check_count`).

    Returns
    -------
    int: `size`, checked.
    """
    return check_count(size, "`ensemble` size", MAX_ENSEMBLE_SIZE)


def check_count(value: Any, label: str, maximum: int) -> int:
    """`value` as a whole number in [1, `maximum`], or `InputError` starting with `label`.

    Parameters
    ----------
    value : the count given by the caller; label : how the message names it (e.g. "`n_steps`");
    maximum : the largest count allowed.

    Returns
    -------
    int
    """
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise InputError(f"{label} must be a whole number, got {value!r}")
    if value < 1:
        raise InputError(f"{label} must be at least 1, got {value}")
    if value > maximum:
        raise InputError(f"{label} must be at most {maximum}, got {value}")
    return int(value)


def check_state(y: Any, dim: int, name: str = "y0") -> np.ndarray:
    """A state shaped (dim,) or (dim, N) as a float64 (dim, N) array, real and finite (complex
    values are refused, never cast).

    Parameters
    ----------
    y : array_like, the state or states.
    dim : int, the problem's dimension.
    name : str, optional, the argument's name in the error message (default "y0").

    Returns
    -------
    ndarray, shape (dim, N): A new float64 array.
    """
    if np.iscomplexobj(y) or (isinstance(y, list | tuple) and any(isinstance(v, complex) for v in y)):
        raise InputError(f"`{name}` must be real numbers (complex values are not cast to real)")
    try:
        arr = np.array(y, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"`{name}` must be numeric, got {type(y).__name__}") from None
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] != dim or arr.shape[1] < 1:
        raise InputError(f"`{name}` must have shape ({dim},) or ({dim}, N), got {np.shape(y)}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"`{name}` must be finite (no NaN or inf)")
    return arr


def check_positive(value: Any, label: str) -> float:
    """`value` as a positive finite float, or `InputError` starting with `label`.

    Parameters
    ----------
    value : the number given by the caller; label : how the message names it (e.g. "`h`").

    Returns
    -------
    float
    """
    message = f"{label} must be a positive finite number, got {value!r}"
    x = _as_float(value, message)
    if not (math.isfinite(x) and x > 0.0):
        raise InputError(message)
    return x


def _as_float(value: Any, message: str) -> float:
    """`float(value)`, or `InputError(message)` where `value` is not a real number."""
    try:
        return float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(message) from None
