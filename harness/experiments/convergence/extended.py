"""Extended-precision reruns of convergence sweeps, and what the coefficients say about a sweep.

Where the float64 rounding floor ended a sweep before its asymptotic range, the same exact
coefficients run in real128 (`harness.extended`) and those rows replace the float64 ones, or the
message says why not. A slope above the order bound (the coefficients', or a black box's
claims: `harness.coefficient_floors.order_bound`) marks the float64 points pre-asymptotic first, so
such a sweep is rerun like any floor-bound one.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.coefficient_floors import mark_above_order, order_bound
from harness.extended import NotMeasurable, extended_sweep
from harness.stepper import Stepper

__all__ = ["floor_bound", "extended_if_floor_bound"]


def floor_bound(g: pd.DataFrame) -> bool:
    """The float64 sweep ended at the rounding floor (or the reference's accuracy) with too few
    asymptotic points, and not every point is at the floor (that is `exact`).

    Parameters
    ----------
    g : DataFrame, one cell's global-error rows (h, in_fit, excluded).

    Returns
    -------
    bool
    """
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
    `amplification(T)` is the flow's error amplification over the horizon ending at T.

    Parameters
    ----------
    stepper : Stepper, whose coefficients are rerun.
    problem : Problem
    frame : DataFrame, the cell's float64 rows.
    config : mapping, the convergence settings.
    amplification : callable, T -> the flow's error amplification up to T.

    Returns
    -------
    DataFrame: `frame`, or with its global rows replaced by the real128 ones.
    """
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
