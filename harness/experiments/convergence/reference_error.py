"""Errors against the certified reference, as the convergence sweeps measure them: the state's
size, the max-norm error, the best reference heyoka certifies (one end time, or each member's own
clock) and the flow's error amplification over a span.
"""

from __future__ import annotations

import math

import numpy as np

from harness import tolerances as tol
from harness.errors import ReferenceError_
from harness.flow import flow_amplification
from harness.ground_truth import reference

__all__ = ["best_reference", "error_amplification", "max_error", "reference_at_clocks",
           "state_scale"]


def state_scale(*arrays: np.ndarray) -> float:
    """The size of the state (max-norm over components, members and the arrays given): errors,
    the start threshold and the rounding level are measured against it.

    Parameters
    ----------
    *arrays : ndarray, states (any shapes).

    Returns
    -------
    float: at least SCALE_FLOOR.
    """
    return max(tol.SCALE_FLOOR, max(float(np.max(np.abs(a))) for a in arrays))


def max_error(y: np.ndarray, ref: np.ndarray) -> float:
    """The max-norm of `y - ref` over components and members.

    Parameters
    ----------
    y, ref : ndarray, the computed and the reference states (same shape).

    Returns
    -------
    float: inf when any difference is not finite.
    """
    with np.errstate(all="ignore"):
        d = np.abs(y - ref)
    if not np.all(np.isfinite(d)):
        return float("inf")
    return float(np.max(d))


def best_reference(problem, T: float, y0: np.ndarray):
    """The ground truth at T, certified to float64 rounding of the state where heyoka's levels
    allow it, else the best certified level; points the reference cannot judge are excluded
    later by the REFERENCE_MARGIN rule, never silently used.

    Parameters
    ----------
    problem : Problem
    T : float, the end time.
    y0 : ndarray, shape (dim, members), the starts.

    Returns
    -------
    Reference: `harness.ground_truth.reference`'s result at T, with its certified error.
    """
    try:
        return reference(problem, np.array([T]), y0, required_error=tol.EPS * state_scale(y0))
    except ReferenceError_:
        return reference(problem, np.array([T]), y0)


def reference_at_clocks(problem, times: np.ndarray, y0: np.ndarray, t0: float):
    """The ground truth of each member at its own time (steppers whose h is a control
    parameter report per-member clocks, `Trajectory.member_t`): (states, certified error).

    Parameters
    ----------
    problem : Problem
    times : ndarray, shape (members,), each member's end time.
    y0 : ndarray, shape (dim, members), the starts.
    t0 : float, not read (the reference starts at the problem's own t0).

    Returns
    -------
    (ndarray, float): the states, shape (dim, members), and the largest certified error.
    """
    out = np.empty_like(y0)
    worst = 0.0
    for i, t in enumerate(np.asarray(times, dtype=float)):
        ref = best_reference(problem, float(t), y0[:, i : i + 1])
        out[:, i] = ref.y[-1][:, 0]
        worst = max(worst, float(np.max(ref.error[-1])))
    return out, worst


def error_amplification(problem, span: float, y0: np.ndarray) -> float:
    """max(1, ||d Phi_span||) (`harness.flow.flow_amplification`), 1 where it cannot be had.

    Parameters
    ----------
    problem : Problem
    span : float, the time the flow runs.
    y0 : ndarray, shape (dim,), the start.

    Returns
    -------
    float: at least 1.
    """
    try:
        value = flow_amplification(problem, span, y0)
    except Exception:  # a problem whose float64 Taylor orbit fails: the plain rounding level
        return 1.0
    return max(1.0, value) if math.isfinite(value) else 1.0
