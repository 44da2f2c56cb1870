"""Fitting an order to (h, error) points: least-squares slope with its 95 % interval, the
asymptotic window (where the local slopes have settled), and each point's classification
(blow-up, reference, roundoff, coefficients, pre-asymptotic) with its reason.

The window is asymptotic only where the error has stopped curving, at any order: the local
slopes next to the floor form a plateau, they do not drift monotonically across it, and the
slope fitted over it is an order at all. The global error of a one-step method on a smooth
problem expands as C_p h^p + C_{p+1} h^{p+1} + ... with integer exponents (Hairer, Norsett &
Wanner I, II.8, Theorem 8.1), so its log-log slope tends to the integer p; a slope steady at
8.5 or 5.3 is a mixture of terms still changing weight, not an order, however flat it looks
over a few halvings (an optimized pair's tiny leading constant, an order-12 method whose h^13
term dominates down to the float64 floor)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import stats

from harness import tolerances as tol

__all__ = ["fit_order", "asymptotic_window", "classify_points"]


def _local_slopes(h: np.ndarray, e: np.ndarray) -> np.ndarray:
    return np.diff(np.log(e)) / np.diff(np.log(h))


def fit_order(h: Sequence[float], error: Sequence[float]) -> dict[str, float]:
    """Least-squares slope of log(error) against log(h), with RMS residual (in log10 units) and
    a 95 % confidence interval from Student's t.

    Parameters
    ----------
    h, error : sequences of positive step sizes and errors (ValueError for fewer than two).

    Returns
    -------
    dict: 'order' (the slope), 'intercept', 'residual', 'ci_low', 'ci_high' (NaN for two points).
    """
    x = np.log(np.asarray(h, dtype=float))
    y = np.log(np.asarray(error, dtype=float))
    n = x.size
    if n < 2:
        raise ValueError("`h` needs at least two points to fit a slope")
    A = np.vstack([x, np.ones_like(x)]).T
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    slope, intercept = float(coef[0]), float(coef[1])
    resid = y - (slope * x + intercept)
    rms = float(np.sqrt(np.mean(resid**2)) / math.log(10))
    if n > 2:
        s2 = float(resid @ resid) / (n - 2)
        se = math.sqrt(s2 / float(((x - x.mean()) ** 2).sum()))
        half = float(stats.t.ppf(0.975, n - 2)) * se
    else:
        half = float("nan")
    return {"order": slope, "intercept": intercept, "residual": rms, "ci_low": slope - half,
            "ci_high": slope + half}


def asymptotic_window(h: np.ndarray, error: np.ndarray, usable: np.ndarray) -> tuple[int, int] | None:
    """The asymptotic range among the usable points (ordered from large h to small h): the run
    of consecutive usable points nearest the floor, extended from its small-h end towards
    larger h for as long as each local slope stays within the plateau tolerance of the slopes
    next to the floor. Anchoring at the small-h end keeps a slowly drifting pre-asymptotic
    start out of the fit.

    Parameters
    ----------
    h, error : arrays of step sizes and errors; usable : bool array, the points not excluded.

    Returns
    -------
    tuple (first, last) of indices, or None for fewer than two points.
    """
    idx = np.flatnonzero(usable)
    if idx.size < 2:
        return None
    runs: list[list[int]] = [[int(idx[0])]]
    for i in idx[1:]:
        if i == runs[-1][-1] + 1:
            runs[-1].append(int(i))
        else:
            runs.append([int(i)])
    long_runs = [r for r in runs if len(r) >= tol.MIN_FIT_POINTS]
    run = long_runs[-1] if long_runs else max(runs, key=len)
    if len(run) < 2:
        return None
    pts = np.array(run)
    slopes = _local_slopes(h[pts], error[pts])
    plateau = float(np.median(slopes[-min(3, slopes.size):]))
    width = max(tol.PLATEAU_SLOPE_TOL, tol.PLATEAU_SLOPE_RTOL * abs(plateau))
    first = slopes.size  # index into pts of the window's first point
    while first > 0 and abs(slopes[first - 1] - plateau) <= width:
        first -= 1
    if first == slopes.size:  # even the last slope disagrees with its neighbours
        first = slopes.size - 1
    # Still drifting: local slopes that move monotonically by more than PLATEAU_DRIFT_TOL across
    # the window are not yet asymptotic (an order-8 method rising 7.6 -> 7.9 as the floor
    # arrives); its large-h end is dropped until they settle or too few points remain.
    while slopes.size - first >= tol.MIN_FIT_POINTS - 1:
        w = slopes[first:]
        steps = np.diff(w)
        monotone = bool(np.all(steps > 0) or np.all(steps < 0))
        if not (monotone and abs(w[-1] - w[0]) > tol.PLATEAU_DRIFT_TOL):
            break
        first += 1
    # Not an order: a slope fitted over the window that no integer explains within
    # INTEGER_ORDER_TOL is still a mixture of error terms; the large-h end is dropped while that
    # holds, and a window that never settles on an order is no window.
    while True:
        window = pts[first:]
        if window.size < 2:
            return None
        slope = fit_order(h[window], error[window])["order"] if window.size > 2 else float(slopes[-1])
        if abs(slope - round(slope)) <= tol.INTEGER_ORDER_TOL:
            break
        if window.size <= tol.MIN_FIT_POINTS:
            return None
        first += 1
    return int(pts[first]), int(pts[-1])


def classify_points(
    h: np.ndarray,
    error: np.ndarray,
    reference_error: np.ndarray,
    rounding_level: np.ndarray,
    start_error: float | None = None,
    coefficient_floor: np.ndarray | None = None,
) -> np.ndarray:
    """Reason each point is excluded from the fit ('' when it is kept), by the rules above.
    Points must be ordered from the largest h to the smallest; `start_error` is absolute (the
    caller scales it by the state's size); `coefficient_floor` is the error the coefficients'
    own defects in the order conditions leave at each h (`harness.theory.defects`), and a point
    within COEFFICIENT_FLOOR_MARGIN of it measures the record's digits, not the method.

    Parameters
    ----------
    h, error : step sizes and errors; reference_error : each point's reference error;
    rounding_level : each point's expected rounding error; start_error : float or None;
    coefficient_floor : array or None.

    Returns
    -------
    ndarray of str: '', 'blow-up', 'reference', 'roundoff', 'coefficients' or 'pre-asymptotic'.
    """
    n = h.size
    reason = np.array([""] * n, dtype=object)
    for i in range(n):
        if not np.isfinite(error[i]) or error[i] > tol.BLOWUP_ERROR:
            reason[i] = "blow-up"
        elif error[i] < tol.REFERENCE_MARGIN * reference_error[i]:
            reason[i] = "reference"
        elif error[i] < tol.ROUNDOFF_MARGIN * rounding_level[i]:
            reason[i] = "roundoff"
        elif coefficient_floor is not None and error[i] < tol.COEFFICIENT_FLOOR_MARGIN * coefficient_floor[i]:
            reason[i] = "coefficients"
        elif start_error is not None and error[i] >= start_error:
            reason[i] = "pre-asymptotic"
    usable = reason == ""
    window = asymptotic_window(h, error, usable)
    for i in np.flatnonzero(usable):
        if window is None or not (window[0] <= i <= window[1]):
            reason[i] = "pre-asymptotic"
    return reason


# -- the experiment ---------------------------------------------------------------------------
