"""Extended-precision reruns of convergence sweeps, and what the coefficients say about a sweep.

Where the float64 rounding floor ended a sweep before its asymptotic range, the same exact
coefficients run in real128 (`harness.extended`) and those rows replace the float64 ones, or the
message says why not. Two facts of the coefficients bound what a sweep can show:
- `coefficient_floor`: the record's own defects in the order conditions leave an error no
  arithmetic removes (`harness.theory.defects`); points near it are excluded as `coefficients`;
- `order_bound`: no problem shows a slope above max(order, linear order) asymptotically (the
  linear order counts the tall trees, which every class keeps); a fitted slope above it by more
  than ABOVE_ORDER_TOL is higher-order terms still dominating, so its points are pre-asymptotic,
  and where the floor came first the sweep is rerun in real128 like any floor-bound one.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.stepper import Stepper

__all__ = ["floor_bound", "extended_if_floor_bound", "coefficient_floor", "coefficient_rounding_floor",
           "order_bound", "mark_above_order", "problem_rate"]


def problem_rate(problem) -> float:
    """The problem's fastest rate along its orbit (`harness.scales`), the size of an elementary
    differential per order; 1 per unit time where it cannot be derived."""
    from harness.scales import derive_time_scale

    try:
        rate = float(derive_time_scale(problem).fastest_rate)
    except Exception:  # a problem whose orbit sampling fails keeps its cell: unit rate
        return 1.0
    return rate if np.isfinite(rate) and rate > 0 else 1.0


def coefficient_rounding_floor(coefficients, problem, *, span: float,
                               scale: float) -> Callable[[np.ndarray], np.ndarray | None]:
    """h -> the error a float64 loop owes to its tableau's coefficients rounded to float64 (their
    defects in the order conditions as run, `harness.theory.defects`): part of the float64
    rounding floor, which it raises only for coefficients of large magnitude (an order-11
    extrapolation tableau's weights sum |b| to ~1e5 and lose ~1e-11); None where every defect
    is within DEFECT_NOISE_ULPS roundings, as for coefficients of ordinary size."""
    from harness.coefficients import ButcherTableau
    from harness.theory.defects import condition_defects, defect_floor

    none = lambda h: None  # noqa: E731
    if not isinstance(coefficients, ButcherTableau) or not coefficients.explicit:
        return none
    defects = condition_defects(coefficients, coefficients.order(), as_run_in_float64=True)
    if not any(d > tol.DEFECT_NOISE_ULPS * tol.EPS for d, _ in defects):
        return none
    rate = problem_rate(problem)
    return lambda h: defect_floor(defects, 0.0, h, span=span, rate=rate, scale=scale)


def coefficient_floor(coefficients, problem, *, span: float, scale: float,
                      noise: float) -> Callable[[np.ndarray], np.ndarray | None]:
    """h -> the error floor an explicit Runge-Kutta tableau's defects in the order conditions
    leave (`harness.theory.defects.defect_floor`), or None where those defects are within
    `noise` (the arithmetic's unit roundoff) of rounding or `coefficients` is no such tableau."""
    from harness.coefficients import ButcherTableau
    from harness.theory.defects import condition_defects, defect_floor

    none = lambda h: None  # noqa: E731
    if not isinstance(coefficients, ButcherTableau) or not coefficients.explicit:
        return none
    defects = condition_defects(coefficients, coefficients.order())
    threshold = tol.DEFECT_NOISE_ULPS * noise
    if not any(d > threshold * q * max(1.0, size) for q, (d, size) in enumerate(defects, start=1)):
        return none
    rate = problem_rate(problem)

    def floor(h: np.ndarray) -> np.ndarray:
        return defect_floor(defects, threshold, h, span=span, rate=rate, scale=scale)

    return floor


def order_bound(stepper: Stepper) -> int | None:
    """max(order, linear order) of the stepper's coefficients, or None without coefficients."""
    coefficients = getattr(stepper, "coefficients", None)
    try:
        return max(int(coefficients.order()), int(coefficients.linear_order()))
    except Exception:  # a black box, or a family without both facts
        return None


def mark_above_order(h: np.ndarray, error: np.ndarray, reasons: np.ndarray,
                     bound: int | None) -> str:
    """Where the points kept (reason '') fit a slope above `bound` + ABOVE_ORDER_TOL, mark them
    `pre-asymptotic` in place and return the reason; else ''."""
    from harness.experiments.convergence_fit import fit_order

    kept = np.flatnonzero(reasons == "")
    if bound is None or kept.size < 2:
        return ""
    slope = fit_order(h[kept], error[kept])["order"]
    if slope <= bound + tol.ABOVE_ORDER_TOL:
        return ""
    reasons[kept] = "pre-asymptotic"
    return (f"slope {slope:.3f} over the settled points is above the coefficients' order bound {bound} "
            f"(max of order and linear order): higher-order error terms still dominate there")


def floor_bound(g: pd.DataFrame) -> bool:
    """The float64 sweep ended at the rounding floor (or the reference's accuracy) with too few
    asymptotic points, and not every point is at the floor (that is `exact`)."""
    g = g.sort_values("h", ascending=False)
    if len(g) == 0 or int(g.in_fit.sum()) >= tol.MIN_FIT_POINTS:
        return False
    at_floor = g.excluded.isin(["roundoff", "reference"])
    return bool(at_floor.iloc[-1]) and not bool(at_floor.all())


def extended_if_floor_bound(stepper: Stepper, problem, frame: pd.DataFrame, config,
                            amplification: Callable[[float], float]) -> pd.DataFrame:
    """Where the float64 floor ended the sweep before the asymptotic range, the same coefficients
    run again in real128 on the problem's own start (`harness.extended`), and those rows replace
    the float64 global rows, with a message saying so; where they cannot (coefficients given
    only to float64, an implicit method, ...), the float64 rows stay and the message says why.
    `amplification(T)` is the flow's error amplification over the horizon ending at T."""
    from harness.extended import NotMeasurable, extended_sweep

    bound = order_bound(stepper)
    mine = (frame.kind == "global").values
    if mine.any():
        g = frame[mine].sort_values("h", ascending=False)
        reasons = g.excluded.values.copy()
        why = mark_above_order(g.h.values, g.error.values, reasons, bound)
        if why:
            frame = frame.copy()
            frame.loc[g.index, "excluded"] = reasons
            frame.loc[g.index, "in_fit"] = reasons == ""
            frame["message"] = frame["message"].fillna("").astype(str)
            frame.loc[g.index, "message"] = ["; ".join(x for x in (m, why) if x)
                                             for m in frame.loc[g.index, "message"]]
    g = frame[frame.kind == "global"]
    if config.get("extended") is False or not floor_bound(g):
        return frame
    T = float(g["t_end"].iloc[0])
    head = (f"the float64 floor came with {int(g.in_fit.sum())} asymptotic point(s) "
            f"(errors down to {float(g.error.min()):.3g})")
    coefficients = getattr(stepper, "coefficients", None)
    try:
        if coefficients is None:
            raise NotMeasurable("not measurable in extended precision: a black box has no coefficients")
        ext = extended_sweep(coefficients, problem, T=T, amplification=amplification(T),
                             work_budget=config.get("extended_work_budget"), order_bound=bound)
    except NotMeasurable as exc:
        frame = frame.copy()
        frame["message"] = frame["message"].fillna("").astype(str)
        mine = frame.kind == "global"
        frame.loc[mine, "message"] = ["; ".join(x for x in (m, f"{head}; {exc}") if x)
                                      for m in frame.loc[mine, "message"]]
        return frame
    rows = pd.DataFrame(ext["rows"])
    rows["in_fit"] = rows["excluded"] == ""
    rows["kind"] = "global"
    rows["tol"] = np.nan
    rows["rhs_evals"] = np.nan
    rows["force_evals"] = np.nan
    rows["wall_s"] = ext["wall_s"] / len(rows)
    rows["reference_precision"] = ext["reference_precision"]
    fit = ext["fit"]
    measured = (f"fitted {fit['order']:.3f} over {fit['points']} points" if fit else
                f"{int(rows.in_fit.sum())} asymptotic point(s) before {ext['stopped_by']}")
    rows["message"] = (f"{head}; measured in real128 from the problem's start with the exact "
                       f"coefficients against a {ext['reference_precision']} reference: {measured}, "
                       f"local slopes " + " ".join(f"{x:.3f}" for x in ext["local_slopes"][-5:])
                       + (f"; {ext['note']}" if ext.get("note") else ""))
    for col in ("stepper", "problem", "t_end"):
        rows[col] = g[col].iloc[0]
    rows["implementation"] = "real128"
    rows["ensemble_size"] = 1
    rows["perturbation"] = 0.0
    out = pd.concat([rows, frame[frame.kind != "global"]], ignore_index=True)
    out.attrs.update(frame.attrs)
    return out
