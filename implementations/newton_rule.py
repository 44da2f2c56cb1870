"""Newton's stopping test, one rule for every implicit step loop: the NumPy loops call
`newton_stop` as it is, the compiled kernels compile this same function with numba
(`implementations.kernels.common.newton_converged`), so the two cannot drift apart. Plain
Python on floats, nothing numba cannot compile; the kernels' cache digest includes this file."""

from __future__ import annotations

import math

from harness.tolerances import EPS, NEWTON_ROUNDING_ULPS, NEWTON_STALL_CONTRACTION

__all__ = ["newton_stop"]


def newton_stop(norm: float, previous: float, tol: float, theta: float,
                size: float) -> tuple[bool, float]:
    """The stopping test of Newton's iteration, rounding-aware (Hairer & Wanner, Solving ODEs II,
    IV.8). The NumPy loops call it as it is; the kernels compile this same function
    (`implementations.kernels.common.newton_converged`).

    Converged when the scaled increment `norm` is at most `tol`; or when the contraction
    theta = norm / previous gives an estimated remaining error theta / (1 - theta) * norm at most
    `tol` (eq. 8.10); or when the increment has stopped decreasing (theta >=
    NEWTON_STALL_CONTRACTION) at the rounding level of the iterate, norm <= NEWTON_ROUNDING_ULPS x
    eps x (1 + size): an ill-conditioned solve whose increments are rounding noise, which no
    further iteration can lower. A divergent iteration (growing increments far above that level)
    still fails.

    Parameters
    ----------
    norm : float, this increment's scaled max-norm; previous : float, the last one (inf before
    the second iteration); tol : float, the Newton tolerance; theta : float, the contraction so
    far; size : float, the scaled max-norm of the iterate after this increment.

    Returns
    -------
    tuple (bool, float): (converged, contraction).
    """
    if norm <= tol:
        return True, theta
    if math.isfinite(previous):
        theta = norm / previous
        if theta < 1.0 and theta / (1.0 - theta) * norm <= tol:
            return True, theta
        if theta >= NEWTON_STALL_CONTRACTION and norm <= NEWTON_ROUNDING_ULPS * EPS * (1.0 + size):
            return True, theta
    return False, theta
