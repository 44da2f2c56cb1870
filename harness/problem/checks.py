"""Input checks shared by the public API: times, ensemble sizes and states, each a one-line
`InputError` naming the argument."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from harness.errors import InputError


def check_time(value: Any, name: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"`{name}` must be a real number, got {value!r}") from None
    if not math.isfinite(x):
        raise InputError(f"`{name}` must be finite, got {x!r}")
    return x


def check_ensemble_size(size: Any) -> int:
    from harness.tolerances import MAX_ENSEMBLE_SIZE

    if isinstance(size, bool) or not isinstance(size, int | np.integer):
        raise InputError(f"`ensemble` size must be a positive integer, got {size!r}")
    if size < 1:
        raise InputError(f"`ensemble` size must be at least 1, got {size}")
    if size > MAX_ENSEMBLE_SIZE:
        raise InputError(f"`ensemble` size must be at most {MAX_ENSEMBLE_SIZE}, got {size}")
    return int(size)


def check_state(y: Any, dim: int, name: str = "y0") -> np.ndarray:
    """A state shaped (dim,) or (dim, N) as a float64 (dim, N) array, finite."""
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
