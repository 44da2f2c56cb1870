"""Verdicts of the convergence experiment: one summary record per (stepper, problem) cell.

Kept apart from `convergence.py` (which measures) so that a change in how measurements are
judged never invalidates cached measurements: the cell cache is keyed by the measuring code.

Verdicts, in the order they are decided:
- `meets-tolerance` / `misses-tolerance` for adaptive steppers (error within
  TOLERANCE_FACTOR x tol x |y| at every tolerance), `failed` if a solve failed;
- `failed`: no step size produced a finite error, and a step failure says why;
- `exact`: every point is at the roundoff floor or the reference's accuracy;
- `converged`: at least MIN_FIT_POINTS points in the asymptotic range; the order is their fit;
- `insufficient-range` also when every coarse step size blew up and every stable one is at the
  floor (a decaying problem at its end point): stable, with no range to read an order from;
- `unstable`: the finest step size blew up (or no step size gave a finite error);
- `insufficient-range`: finite errors, but fewer than MIN_FIT_POINTS points in the asymptotic
  range within the work budget.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.order_fit import fit_order
from harness.rules import tolerance_allowance
from harness.stepper import Stepper

__all__ = ["summarize_cell", "insufficient_range_reason", "summarise_clauses"]


def _fit_kind(g: pd.DataFrame, kind: str) -> float:
    sub = g[(g.kind == kind) & g.in_fit]
    if len(sub) < tol.MIN_FIT_POINTS:
        return float("nan")
    return fit_order(sub.h.values, sub.error.values)["order"]


def summarize_cell(stepper: Stepper, problem: str, g: pd.DataFrame) -> dict:
    """The summary record of one convergence cell: the fit over the asymptotic points, the
    local exponents and the verdict (module docstring), with the reason in `message`.

    Parameters
    ----------
    stepper : Stepper, the cell's method (its claimed order).
    problem : str, the problem's name.
    g : DataFrame, the cell's rows (all kinds).

    Returns
    -------
    dict: one value per column of the convergence experiment's SUMMARY_COLUMNS.
    """
    info = stepper.info
    base = {
        "stepper": info.name, "problem": problem, "claimed_order": info.claimed_order,
        "measured_order": np.nan, "order_ci_low": np.nan, "order_ci_high": np.nan,
        "fit_residual": np.nan, "fit_points": 0, "fit_h_min": np.nan, "fit_h_max": np.nan,
        "fit_error_min": np.nan, "fit_error_max": np.nan, "local_exponent": np.nan,
        "local_exponent_q": np.nan,
        "reference_error": float(g.reference_error.max()),
        "reference_precision": str(g["reference_precision"].dropna().iloc[0])
        if "reference_precision" in g and g["reference_precision"].notna().any() else "",
        "points": int((g.kind.isin(["global", "tolerance"])).sum()),
        "total_steps": int(g.loc[g.kind == "global", "n_steps"].sum()),
        "wall_s": float(g.wall_s.sum(skipna=True)) if "wall_s" in g else np.nan,
        "implementation": str(g["implementation"].dropna().iloc[0])
        if "implementation" in g and g["implementation"].notna().any() else "numpy",
        "perturbation": float(g["perturbation"].iloc[0]) if "perturbation" in g else np.nan,
        "message": "",
        # the sweep's finest step and its horizon (a shortened one included): the judge reads a
        # step failure and the stiffness over the measured span against them
        "finest_h": float(g.loc[g.kind == "global", "h"].min()) if (g.kind == "global").any() else np.nan,
        "t_end": float(g["t_end"].iloc[0]) if "t_end" in g and len(g) else np.nan,
    }
    messages = [m for m in g.get("message", pd.Series(dtype=str)).fillna("") if m]
    not_run = g[g.kind == "tolerance-not-run"]
    if not (g.kind == "tolerance").any() and (not_run.excluded == "tol-range").any():
        # every tolerance of the sweep is outside the library's documented range: nothing ran,
        # so nothing is judged (not a pass on zero points, not a failure)
        listed = ", ".join(f"{t:.0e}" for t in sorted(not_run.tol, reverse=True))
        first = str(not_run[not_run.excluded == "tol-range"].message.iloc[0])
        why = first[first.find(" is outside") + 1:] if " is outside" in first else first
        base["verdict"] = "insufficient-range"
        base["message"] = f"not measurable: no tolerance of the sweep ran (tol {listed}): {why}"
        return base
    if (g.kind == "tolerance").any():
        t = g[g.kind == "tolerance"]
        scale = t.rounding_level / tol.EPS  # the state's size, as the sweep measured it

        members = t["ensemble_size"].clip(lower=1) if "ensemble_size" in t else 1
        amp = t["flow_amplification"] if "flow_amplification" in t else np.nan
        allowed = [tolerance_allowance(float(n), float(a)) for n, a in
                   zip(t.n_steps / members, np.broadcast_to(amp, len(t)), strict=True)]
        factor = np.array([a[0] for a in allowed])
        within = (t.error <= factor * t.tol * scale) | (t.excluded == "reference")
        ok = bool(within.all()) and bool(t.error.notna().all())
        fit_rows = t[t.in_fit & (t.error >= tol.PROPORTIONALITY_MIN_RATIO * t.tol * scale)]
        if len(fit_rows) >= 2:
            f = fit_order(fit_rows.tol.values, fit_rows.error.values)
            base["measured_order"] = f["order"]  # tolerance proportionality exponent
            ok = ok and f["order"] >= tol.MIN_TOLERANCE_EXPONENT
        base["verdict"] = "meets-tolerance" if ok else "misses-tolerance"
        if not ok:
            worst = float((t.error / (t.tol * scale)).max())
            k = int(np.argmax((t.error / (factor * t.tol * scale)).values))
            base["message"] = (f"error up to {worst:.3g} x tol x |y| (allowed at tol {t.tol.iloc[k]:.0e}: "
                               f"{allowed[k][1]}); "
                               f"tolerance exponent {base['measured_order']:.3g} "
                               f"(minimum {tol.MIN_TOLERANCE_EXPONENT:g})")
        not_run = g[g.kind == "tolerance-not-run"]
        capped = not_run[not_run.excluded != "tol-range"]
        outside = not_run[not_run.excluded == "tol-range"]
        if len(outside):  # not measurable there: said once, with the library's range
            listed = ", ".join(f"{t:.0e}" for t in sorted(outside.tol, reverse=True))
            first = str(outside.message.iloc[0])
            why = first[first.find(" is outside") + 1:] if " is outside" in first else first
            base["message"] = "; ".join(filter(None, [base["message"], (
                f"not measurable at tol {listed}: {why}")]))
        messages = [m for m in t.message.fillna("") if m]  # failures of tolerances that ran
        if len(capped):
            listed = ", ".join(f"{t:.0e}" for t in sorted(capped.tol, reverse=True))
            base["message"] = "; ".join(filter(None, [base["message"], (
                f"tolerance{'s' if len(capped) > 1 else ''} {listed} not run: the predicted cost would pass "
                f"the sweep's cap of {tol.TOLERANCE_SWEEP_STEPS} internal steps per member")]))
        if messages:
            base["verdict"], base["message"] = "failed", messages[0]
        return base
    gl = g[g.kind == "global"].sort_values("h", ascending=False)
    kept = gl[gl.in_fit]
    finite = gl[np.isfinite(gl.error) & (gl.error <= tol.BLOWUP_ERROR)]
    at_floor = gl.excluded.isin(["roundoff", "reference"])
    blew_up = gl.excluded == "blow-up"
    # a step that could not be completed (StepFailure) leaves its point's error NaN with the
    # failure as message; the sweep's own notes (a shortened horizon) sit on every row and are no
    # failure: a sweep whose every point blew up is `unstable`, not `failed`
    failures = [m for m, e in zip(gl.get("message", pd.Series(dtype=str)).fillna(""), gl.error,
                                  strict=True) if m and np.isnan(e)]
    if failures and finite.empty:
        base["verdict"], base["message"] = "failed", failures[0]
    elif len(gl) and at_floor.all():
        base["verdict"] = "exact"
    elif len(kept) >= tol.MIN_FIT_POINTS:
        f = fit_order(kept.h.values, kept.error.values)
        base.update({
            "verdict": "converged", "measured_order": f["order"], "order_ci_low": f["ci_low"],
            "order_ci_high": f["ci_high"], "fit_residual": f["residual"],
            "fit_points": len(kept), "fit_h_min": float(kept.h.min()),
            "fit_h_max": float(kept.h.max()), "fit_error_min": float(kept.error.min()),
            "fit_error_max": float(kept.error.max()),
        })
    elif blew_up.any() and (blew_up | at_floor).all() and at_floor.iloc[-1]:
        # stable at the finest steps, where the error is already at the floor (a decaying problem
        # at its end point): a convergent method's behaviour, with no range to read an order from
        stable = gl[at_floor]
        base["verdict"] = "insufficient-range"
        base["message"] = (f"every step size from h = {float(gl[blew_up].h.min()):.3g} up blew up and every "
                           f"stable one (h <= {float(stable.h.max()):.3g}) is already at the floor (errors "
                           f"{float(stable.error.max()):.3g} and below): no asymptotic range on this problem")
    elif (finite.empty or not np.isfinite(gl.error.iloc[-1]) or gl.error.iloc[-1] > tol.BLOWUP_ERROR
          or (blew_up.any() and (blew_up | at_floor).all())):
        base["verdict"] = "unstable"
    else:
        base["verdict"] = "insufficient-range"
        base["message"] = summarise_clauses(  # the sweep's own notes (horizon, extended precision)
            [insufficient_range_reason(gl, len(kept)), *(m for m in gl.get("message", []) if m)])
    base["local_exponent"] = _fit_kind(g, "local")
    base["local_exponent_q"] = _fit_kind(g, "local-q")
    if messages and not base["message"]:
        base["message"] = messages[0]
    return base




def summarise_clauses(clauses: list[str]) -> str:
    """The clauses joined by '; ', each said once: clauses that differ only in their numbers
    (one note per step size or member) are kept at their first, with how many more there were;
    a note that is itself several clauses joined by '; ' is split into them first.

    Parameters
    ----------
    clauses : list of str, the notes (empty ones dropped).

    Returns
    -------
    str
    """
    variants: dict[str, dict[str, None]] = {}  # shape -> its distinct texts, in order
    # A note may already be several clauses joined by '; ' (a step's failure, then the sweep's
    # notes): each clause is grouped on its own, so a note repeated inside another is said once.
    for c in (part for note in clauses if note for part in note.split("; ")):
        if c:
            variants.setdefault(re.sub(r"[-+]?\d[\d.]*(?:e[-+]?\d+)?", "#", c), {})[c] = None
    return "; ".join(next(iter(v)) + (f" (and {len(v) - 1} more like it)" if len(v) > 1 else "")
                     for v in variants.values())


def insufficient_range_reason(gl: pd.DataFrame, fit_points: int) -> str:
    """Which limit ended a sweep with fewer than MIN_FIT_POINTS asymptotic points: the float64
    floor or the reference's accuracy (the finest step's error is judged there), else the work
    budget (the sweep ran out of steps while the errors were still pre-asymptotic); with the
    horizon and the errors the sweep reached, so a user can decide what to change. A finest
    point at the coefficients' own floor names that limit instead.

    Parameters
    ----------
    gl : DataFrame, the cell's global rows, coarsest step first.
    fit_points : int, the asymptotic points found.

    Returns
    -------
    str: one sentence.
    """
    finest = gl.iloc[-1]
    horizon = float(gl["t_end"].iloc[0]) if "t_end" in gl else float("nan")
    limit = {
        "roundoff": "the float64 rounding floor",
        "reference": "the reference's certified accuracy",
        "coefficients": "the coefficients' own accuracy (their defects in the order conditions)",
    }.get(str(finest.excluded), "the work budget")
    return (f"{fit_points} of {tol.MIN_FIT_POINTS} asymptotic points before {limit} stopped the "
            f"sweep: {len(gl)} step sizes down to h = {float(finest.h):.3g} "
            f"({int(gl.n_steps.sum())} steps in all), errors {float(gl.error.max()):.3g} to "
            f"{float(gl.error.min()):.3g}, horizon t_end = {horizon:.6g}")
