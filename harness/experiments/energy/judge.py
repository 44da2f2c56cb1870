"""Verdict code of the energy experiment: the drift class of an error envelope, what rounding
alone explains, and which methods must keep quadratic invariants (the module docstring of
`harness.experiments.energy`, items 3-4).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

from harness import tolerances as tol
from harness.facts import method_facts
from harness.stepper import Stepper

__all__ = ["classify_drift", "conserves_quadratic_invariants", "rounding_growth"]


def conserves_quadratic_invariants(stepper: Stepper) -> bool:
    """True for methods whose structure conserves quadratic first integrals such as the angular
    momentum of a central force: symplectic Runge-Kutta methods (b_i a_ij + b_j a_ji = b_i b_j,
    HLW IV.2.1), drift/kick splittings (each drift and kick keeps q x v when a is parallel to q,
    HLW IV.2.2) and Stormer's rule (velocity Verlet in two-step form, HLW I.1.4).

    Parameters
    ----------
    stepper : Stepper, asked through `harness.facts.method_facts` (its coefficients).

    Returns
    -------
    bool
    """
    return bool(method_facts(stepper).symplectic)


def classify_drift(steps: np.ndarray, t: np.ndarray, error: np.ndarray, *, fit_start: int,
                   checkpoints_per_decade: int = 20, min_decades: float = 1.0,
                   period_steps: float = 0.0) -> dict[str, Any]:
    """Classify the envelope of a relative error (module item 3).

    Parameters
    ----------
    steps, t : ndarray, the sampled step indices (increasing) and their times.
    error : ndarray, the relative error there (any non-finite value: 'unstable').
    fit_start : int, the first step of the fit window.
    checkpoints_per_decade, min_decades : int, float, optional, the running maximum's log-spaced
        reads per decade, and the fewest decades the window spans.
    period_steps : float, optional, steps per natural period (0: unknown): an error of
        ENERGY_BLOWUP_ERROR or more that was as large in the first period is classified by growth.

    Returns
    -------
    dict: drift_class, drift_exponent (log-log slope of the running maximum over the window),
        drift_slope (its slope against t), secular_growth (its rise across the window),
        max_error, and fit_start (the first step read).
    """
    steps = np.asarray(steps, dtype=float)
    t = np.asarray(t, dtype=float)
    error = np.asarray(error, dtype=float)
    out: dict[str, Any] = {
        "drift_class": "unstable", "drift_exponent": float("nan"), "drift_slope": float("nan"),
        "secular_growth": float("nan"), "max_error": float("nan"), "fit_start": int(fit_start),
    }
    finite = np.isfinite(error)
    if not np.all(finite):
        out["max_error"] = float("inf")
        return out
    out["max_error"] = float(np.max(error)) if error.size else float("nan")
    first = error[(steps >= 1) & (steps <= math.ceil(max(period_steps, 1.0)))] if period_steps > 0 else []
    early = float(np.max(first)) if len(first) else 0.0  # a bounded oscillation's size (docstring)
    late = error[steps >= fit_start]  # a bounded oscillation swings back (docstring)
    swings = late.size > 0 and np.min(late) <= tol.ENERGY_RETURN_FRACTION * np.max(late)
    if error.size == 0 or (out["max_error"] >= tol.ENERGY_BLOWUP_ERROR and not (
            early > 0 and out["max_error"] <= tol.ENERGY_BOUNDED_RISE * early and swings)):
        return out
    running = np.maximum.accumulate(np.maximum(error, tol.ENERGY_ERROR_FLOOR))
    n_end = float(steps[-1])
    start = float(min(max(fit_start, 1), n_end / 10.0**min_decades))
    decades = math.log10(n_end / start)
    points = max(5, int(round(decades * checkpoints_per_decade)) + 1)
    marks = np.unique(np.geomspace(start, n_end, points))
    idx = np.searchsorted(steps, marks, side="right") - 1
    idx = np.unique(idx[idx >= 0])
    if idx.size < 3:
        out["drift_class"] = "bounded"
        return out

    x, m = steps[idx], running[idx]
    exponent = float(stats.theilslopes(np.log(m), np.log(x))[0])
    slope = float(stats.theilslopes(m, t[idx])[0])
    out.update(drift_exponent=exponent, drift_slope=slope,
               secular_growth=float(m[-1] - m[0]), fit_start=int(x[0]))
    if exponent > tol.DRIFT_UNSTABLE_EXPONENT:
        out["drift_class"] = "unstable"
    elif exponent >= tol.DRIFT_LINEAR_EXPONENT:
        out["drift_class"] = "linear"
    elif exponent >= tol.DRIFT_SQRT_EXPONENT:
        out["drift_class"] = "sqrt"
    else:
        out["drift_class"] = "bounded"
    return out


def rounding_growth(n_steps: float) -> float:
    """What rounding alone can add to a relative invariant error over n steps: a random walk of
    ENERGY_ROUNDING_ULPS ulps per step (Brouwer's law), ENERGY_ROUNDING_ULPS * sqrt(n) * eps.

    Parameters
    ----------
    n_steps : float, the number of steps (below 1 read as 1).

    Returns
    -------
    float: a relative error.
    """
    return tol.ENERGY_ROUNDING_ULPS * math.sqrt(max(n_steps, 1.0)) * tol.EPS
