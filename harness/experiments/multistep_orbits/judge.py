"""Verdict code of the multistep-orbits experiment: resonances in an error-against-h scan, their
match with the predictions, and the drift class and rate (module docstring of
`harness.experiments.multistep_orbits`).

- Onset: the smallest scanned h from which the runs go non-finite or reach an energy error of
  ENERGY_BLOWUP_ERROR, at it and at the RESONANCE_WINDOW step sizes above it (a lone blow-up
  between bounded runs is a resonance).
- Resonance (`find_spikes`): below the onset, a step size whose energy error exceeds by
  RESONANCE_SPIKE_FACTOR the straight line (log error against log h) fitted through the
  RESONANCE_WINDOW scanned neighbours on each side (the point itself left out; the line no lower
  than what rounding alone adds over the run, `energy.judge.rounding_growth`). The onset counts
  as a resonance too when it exceeds its lower neighbours' trend that way.
- A resonance is predicted when a predicted h omega lies within RESONANCE_MATCH_REL of it (and
  a prediction at most at the onset is found when a resonance lies that close to it);
  `chance_fraction` is the share of the scanned h omega range within that distance of any
  prediction (how often a resonance placed at random would match).
- Drift: over the stable, non-resonant points whose error is between SPIRAL_MIN_CHANGE and
  SPIRAL_MAX_ERROR, the drift is secular when the fitted rate times the run's length explains
  at least SECULAR_FRACTION of the largest error (median over the points), else bounded.
  Expected (the theorem): symmetric coefficients keep the energy error bounded away from
  resonances (HLW ch. XV: near-conservation of a modified energy by symmetric multistep methods
  whose parasitic components stay small over long times), the others drift secularly at the
  principal root's rate (Quinlan 1999, sec. 1), judged where that rate is predicted (a circular
  orbit); off it a non-symmetric table's drift is measured without a verdict (its secular part
  may hide under the bounded oscillation over the run: cowell8 on e = 0.6 at 2e4 steps). The
  drift rate's exponent in h is fitted over those points, beside the predicted rates' exponent.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.experiments.energy.judge import rounding_growth

__all__ = ["find_spikes", "summarize_cell", "onset_index"]


def find_spikes(h: np.ndarray, error: np.ndarray, *, factor: float = tol.RESONANCE_SPIKE_FACTOR,
                window: int = tol.RESONANCE_WINDOW, floor: float = 0.0) -> list[int]:
    """Indices whose error stands `factor` above the log-log line through their neighbours (at
    least one on each side), or above `floor` where the line runs below it.

    Parameters
    ----------
    h : ndarray, increasing step sizes.
    error : ndarray, positive finite errors at them.
    factor : float, optional, how far above the trend (default RESONANCE_SPIKE_FACTOR).
    window : int, optional, neighbours on each side (default RESONANCE_WINDOW).
    floor : float, optional, the error rounding alone leaves (default 0).

    Returns
    -------
    list of int: the spikes' indices, increasing.
    """
    x = np.log(np.asarray(h, dtype=float))
    e = np.log(np.maximum(np.asarray(error, dtype=float), tol.ENERGY_ERROR_FLOOR))
    out = []
    for i in range(1, len(x) - 1):
        near = [j for j in range(max(0, i - window), min(len(x), i + window + 1)) if j != i]
        if _excess(x, e, i, near, floor) > math.log(factor):
            out.append(i)
    return out


def _excess(x: np.ndarray, e: np.ndarray, i: int, near: list[int], floor: float) -> float:
    """log error at i minus the robust line (median pairwise slope, median intercept) through
    the points `near`, that line raised to log `floor` where below it."""
    xs, ys = x[near], e[near]
    slopes = [(ys[b] - ys[a]) / (xs[b] - xs[a]) for a in range(len(near))
              for b in range(a + 1, len(near)) if xs[b] != xs[a]]
    slope = float(np.median(slopes)) if slopes else 0.0
    intercept = float(np.median(ys - slope * xs))
    trend = max(intercept + slope * x[i], math.log(max(floor, tol.ENERGY_ERROR_FLOOR)))
    return float(e[i] - trend)


def onset_index(max_error: np.ndarray, finite: np.ndarray) -> int | None:
    """The first index from which every run blew up (non-finite, or energy error >=
    ENERGY_BLOWUP_ERROR) up to RESONANCE_WINDOW points on (a lone blow-up is a resonance).

    Parameters
    ----------
    max_error : ndarray, the largest relative energy errors, by increasing h.
    finite : ndarray of bool, whether each run stayed finite.

    Returns
    -------
    int or None
    """
    bad = (~np.asarray(finite, dtype=bool)) | ~(np.asarray(max_error, dtype=float) < tol.ENERGY_BLOWUP_ERROR)
    for i in np.flatnonzero(bad):
        if np.all(bad[i : i + tol.RESONANCE_WINDOW + 1]):
            return int(i)
    return None


def _near(value: float, targets: list[float]) -> bool:
    return any(abs(value - t) <= tol.RESONANCE_MATCH_REL * t for t in targets)


def summarize_cell(stepper, problem: str, g: pd.DataFrame) -> dict[str, Any]:
    """One summary record (module docstring).

    Parameters
    ----------
    stepper : Stepper, whose coefficients (a SecondOrderMultistep) are asked.
    problem : str, the problem's name.
    g : DataFrame, the cell's rows.

    Returns
    -------
    dict: the experiment's SUMMARY_COLUMNS.
    """
    method = stepper.coefficients
    g = g.sort_values("h_omega").reset_index(drop=True)
    hw = g["h_omega"].to_numpy(float)
    err = g["max_error"].to_numpy(float)
    finite = g["finite"].to_numpy(bool)
    listed = str(g["predictions"].iloc[0]) if "predictions" in g and len(g) else ""
    predicted = sorted(float(x) for x in listed.split() if x)
    onset = onset_index(err, finite)
    stable = len(g) if onset is None else onset
    floor = rounding_growth(float(g["steps"].max()))
    spikes = find_spikes(hw[:stable], err[:stable], floor=floor) if stable >= 3 else []
    events = [float(hw[i]) for i in spikes]
    if onset is not None and onset >= 2:  # the onset against its lower neighbours' trend
        logs = np.log(np.maximum(np.where(np.isfinite(err), err, 1e300), tol.ENERGY_ERROR_FLOOR))
        near = list(range(max(0, onset - tol.RESONANCE_WINDOW), onset))
        if _excess(np.log(hw), logs, onset, near, floor) > math.log(tol.RESONANCE_SPIKE_FACTOR):
            events.append(float(hw[onset]))
    span = (float(hw[0]), float(hw[-1]))
    limit = span[1] if onset is None else float(hw[onset]) * (1 + tol.RESONANCE_MATCH_REL)
    testable = [p for p in predicted if p <= limit]  # above the onset every run blew up
    covered = sum(2 * tol.RESONANCE_MATCH_REL * p for p in predicted)
    rec: dict[str, Any] = {
        "stepper": stepper.info.name, "problem": problem, "symmetric": bool(method.symmetric),
        "order": int(method.order()), "points": len(g),
        "predicted": (", ".join(f"{p:.4g}" for p in predicted) if len(predicted) <= 12 else
                      f"{len(predicted)} step sizes from {predicted[0]:.4g} to {predicted[-1]:.4g}"),
        "predicted_testable": len(testable),
        "predicted_found": sum(_near(p, events) for p in testable),
        "resonances": ", ".join(f"{e:.4g}" for e in events),
        "resonances_predicted": sum(_near(e, predicted) for e in events),
        "chance_fraction": min(1.0, covered / max(span[1] - span[0], tol.EPS)) if predicted else 0.0,
        "onset_h_omega": float(hw[onset]) if onset is not None else math.nan,
        "expected_class": "bounded" if method.symmetric else "secular",
        "wall_s": float(g["wall_s"].sum()),
        "message": "; ".join(dict.fromkeys(m for m in g["message"].fillna("") if m)),
    }
    rec.update(_drift(g.iloc[:stable].drop(index=spikes)))
    if rec["drift_class"] == "":
        rec.update(verdict="not-measurable", passed=None)
        rec["message"] = "; ".join(x for x in (rec["message"], (
            f"no stable, non-resonant step size with an energy error between "
            f"{tol.SPIRAL_MIN_CHANGE:g} and {tol.SPIRAL_MAX_ERROR:g}")) if x)
    elif not method.symmetric and not np.all(np.isfinite(g["predicted_rate"].astype(float))):
        rec.update(verdict="measured", passed=None)
        rec["message"] = "; ".join(x for x in (rec["message"], (
            "no predicted drift rate off a circular orbit: the secular part's size against the "
            "bounded oscillation is not known, so no verdict")) if x)
    else:
        ok = rec["drift_class"] == rec["expected_class"]
        if ok and not method.symmetric and np.isfinite(rec["rate_ratio"]):
            ok = bool(rec["sign_agrees"]) and (1 / tol.SPIRAL_RATE_FACTOR <= rec["rate_ratio"]
                                               <= tol.SPIRAL_RATE_FACTOR)
        rec.update(verdict="as-expected" if ok else "differs", passed=ok)
    return rec


def _drift(g: pd.DataFrame) -> dict[str, Any]:
    """Drift class, measured and predicted exponents, rate ratio and sign over the usable points."""
    out: dict[str, Any] = {"drift_class": "", "drift_points": 0, "drift_exponent": math.nan,
                           "predicted_exponent": math.nan, "rate_ratio": math.nan,
                           "sign_agrees": None}
    use = g[g["finite"].astype(bool) & (g["max_error"] >= tol.SPIRAL_MIN_CHANGE)
            & (g["max_error"] < tol.SPIRAL_MAX_ERROR)]
    if use.empty:
        return out
    explained = np.abs(use["drift_rate"]) * use["steps"] * use["h"] / use["max_error"]
    secular = float(np.median(explained)) >= tol.SECULAR_FRACTION
    out.update(drift_class="secular" if secular else "bounded", drift_points=len(use))
    if not secular:
        return out
    rate = use["drift_rate"].to_numpy(float)
    pred = use["predicted_rate"].to_numpy(float)
    x = np.log(use["h_omega"].to_numpy(float))
    if len(use) >= 2 and np.all(rate != 0):
        out["drift_exponent"] = float(np.polyfit(x, np.log(np.abs(rate)), 1)[0])
    if np.all(np.isfinite(pred)) and np.all(pred != 0):
        out["sign_agrees"] = bool(np.all(np.sign(pred) == np.sign(rate)))
        out["rate_ratio"] = float(np.median(rate / pred))
        if len(use) >= 2:
            out["predicted_exponent"] = float(np.polyfit(x, np.log(np.abs(pred)), 1)[0])
    return out
