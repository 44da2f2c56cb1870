"""The work-precision section: error against evaluations, the cost of reaching the target error,
then the timed part (`timing_section`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.experiments.work_precision.figures import WORK_TARGET_ERROR, work_precision_figure
from harness.experiments.work_precision.timing_section import add_time_sections
from harness.kit import (
    Measure,
    RunView,
    Section,
    SectionSpec,
    df_table,
)
from harness.kit.view import part, problems_in


def _work_table(summ: pd.DataFrame) -> pd.DataFrame:
    """One row per (stepper, problem) of the work-precision summary: its sweep kind, number of
    points, lowest error and the evaluations there, and the evaluations and wall time of the
    cheapest point at or below WORK_TARGET_ERROR (grouped operations: thousands of rows)."""
    keys = ["stepper", "problem"]
    cols = ["stepper", "problem", "kind", "points", "lowest_error", "evals_at_lowest",
            "evals_to_target", "wall_to_target", "unit"]
    if summ.empty:
        return pd.DataFrame(columns=cols)
    nan = pd.Series(np.nan, index=summ.index)
    df = pd.DataFrame({
        "stepper": summ["stepper"], "problem": summ["problem"],
        "kind": summ["kind"].astype(str) if "kind" in summ else "",
        "unit": summ["evals_unit"].astype(str) if "evals_unit" in summ else "",
        "err": summ["error"].astype(float),
        "evals": summ["rhs_evals"].astype(float) if "rhs_evals" in summ else nan,
        "wall": summ[next((c for c in ("t_min_s", "wall_s") if c in summ), "")].astype(float)
        if {"t_min_s", "wall_s"} & set(summ.columns) else nan})  # the warm time where timed
    grouped = df.groupby(keys, sort=False)
    out = grouped.agg(kind=("kind", "first"), points=("err", "size"), unit=("unit", "first"))
    finite = df[np.isfinite(df["err"])]
    lowest = finite.loc[finite.groupby(keys, sort=False)["err"].idxmin()].set_index(keys)
    out["lowest_error"] = lowest["err"]
    out["evals_at_lowest"] = lowest["evals"]
    hit = finite[(finite["err"] <= WORK_TARGET_ERROR) & finite["evals"].notna()]
    cheapest = hit.loc[hit.groupby(keys, sort=False)["evals"].idxmin()].set_index(keys)
    out["evals_to_target"] = cheapest["evals"]
    out["wall_to_target"] = cheapest["wall"]
    out = out.reset_index()
    out["points"] = out["points"].astype(int)
    return out[cols]


def work_precision(view: RunView, sec: Section) -> None:
    """Add the work-precision figures and tables to `sec`, read from `view`.

    Parameters
    ----------
    view : RunView, the run: work-precision rows and the steppers' adaptive flags.
    sec : Section, the work-precision section (a warning note when the rows have no errors).
    """
    name = "work-precision"
    rows = view.rowtable(name)
    adaptive = view.flag("adaptive")
    if "error" not in rows:
        sec.note("The work-precision rows have no `error` column; nothing to draw.", cls="warning")
        return
    sec.note(f"Each figure: error against evaluations on one problem; bold, the best of each "
             f"family (fewest evaluations to reach {WORK_TARGET_ERROR:g}), faint, the others. "
             "Error against warm time, by the timing protocol, follows under 'Error against time'.")
    for problem in problems_in(view, rows):
        sec.figure(work_precision_figure(problem, part(view, rows, "problem", problem), view.palette,
                                           adaptive),
                   f"Error against evaluations on {problem}.")
    summ = view.summary(name)
    if len(summ) and {"stepper", "problem", "error"} <= set(summ.columns):
        table = _work_table(summ)
        cols = [("stepper", "stepper"), ("problem", "problem"), ("kind", "sweep"), ("points", "points"),
                ("lowest_error", "lowest error"), ("evals_at_lowest", "evaluations there"),
                ("evals_to_target", f"evaluations to reach {WORK_TARGET_ERROR:g}"),
                ("wall_to_target", f"wall s to reach {WORK_TARGET_ERROR:g}"), ("unit", "evaluation unit")]
        sec.table(df_table(table, cols, f"Per stepper and problem: cost of reaching "
                           f"{WORK_TARGET_ERROR:g}", experiment=name, status=None, sort_failing=False))
    add_time_sections(view, sec)  # error against warm time, time to target, same-method groups


SECTION = SectionSpec(
    "work-precision", title="Work–precision",
    intro=("Error at the final time against the work spent — right-hand-side (or force) "
           "evaluations, then warm wall time measured like a benchmark — over a step-size sweep "
           "(fixed-step methods) or a tolerance sweep (adaptive ones, dashed). Lower and further "
           "left is better; the best method of each family (to reach the target error) is bold."),
    measures=(Measure("evals_to_target", "evaluations to reach the target error",
                      rtol=tol.REPORT_CHANGE_RTOL),),
    build=work_precision,
)
