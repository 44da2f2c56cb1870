"""The convergence section: error against h per problem with the fitted range, judged by the gate;
the scoreboard's measured order and evaluations per step."""

from __future__ import annotations

import numpy as np
import pandas as pd

from harness.experiments.convergence.figures import convergence_figure, same_curves
from harness.kit import (
    Measure,
    RunView,
    ScoreColumn,
    Section,
    SectionSpec,
    anchor,
    df_table,
    fmt,
    summary_verdicts,
)
from harness.kit.view import part, problems_in, rows_of


# -- convergence ----------------------------------------------------------------------------------
def _convergence_judged(view: RunView) -> pd.DataFrame:
    summ = view.summary("convergence")
    gate = view.gate()
    if not len(gate) or summ.empty:
        return summ.assign(passed=None, reason="")
    cols = [c for c in ("stepper", "problem", "passed", "outcome", "reason", "expected",
                        "measured_coefficient", "predicted_coefficient", "prediction_note") if c in gate]
    return summ.merge(gate[cols], on=["stepper", "problem"], how="left")


def _convergence_verdicts(view: RunView) -> pd.DataFrame:
    return summary_verdicts("convergence", _convergence_judged(view), ("stepper", "problem"),
                            reason="reason")


def _order_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    s = rows_of(view, "convergence", stepper)
    if s.empty:
        return [("—", "")], False
    info = view.infos.get(stepper)
    link = lambda problem: "#" + anchor("convergence", stepper, problem)  # noqa: E731
    if info is not None and info.claimed_order is None:
        ok = s[s["verdict"] == "meets-tolerance"]
        first = ok["problem"].iloc[0] if len(ok) else s["problem"].iloc[0]
        return [(f"meets tolerance on {len(ok)}/{len(s)}", link(first))], True
    conv = s[s["verdict"] == "converged"].assign(m=lambda d: d["measured_order"].astype(float))
    conv = conv[np.isfinite(conv["m"])].sort_values("m")
    others = s.loc[s["verdict"] != "converged"]
    parts: list[tuple[str, str]] = []
    if len(conv):
        med = conv.iloc[(len(conv) - 1) // 2]
        lo, hi = conv.iloc[0], conv.iloc[-1]
        parts += [(f"{med['m']:.2f}", link(med["problem"])), (" (", ""),
                  (f"{lo['m']:.2f}", link(lo["problem"])), ("–", ""),
                  (f"{hi['m']:.2f}", link(hi["problem"])),
                  (f", {len(conv)} problem{'s' if len(conv) != 1 else ''})", "")]
    for verdict, g in others.groupby("verdict", sort=False):
        parts += [("; " if parts else "", ""), (f"{verdict} ×{len(g)}", link(g["problem"].iloc[0]))]
    return parts or [("—", "")], True


def _evals_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    info = view.infos.get(stepper)
    declared = fmt(info.evals_per_step, 3) if info is not None else "—"
    rows = view.rowtable("convergence")
    if rows.empty or not {"kind", "stepper", "n_steps"} <= set(rows.columns):
        return [(f"{declared} / —", "")], False
    g = part(view, rows, "stepper", stepper)
    g = g[g["kind"] == "global"]
    if "message" in g:  # a failed step counts no evaluations
        g = g[g["message"].fillna("").astype(str) == ""]
    if "error" in g:
        g = g[np.isfinite(g["error"].astype(float))]
    if g.empty:
        return [(f"{declared} / —", "")], False
    evals = sum(g[c].fillna(0).astype(float) for c in ("rhs_evals", "force_evals") if c in g)
    per = (evals / g["n_steps"].astype(float)).replace([np.inf, -np.inf], np.nan).dropna()
    if per.empty:
        return [(f"{declared} / —", "")], False
    text = fmt(per.median(), 3)
    if abs(per.max() - per.min()) >= 1e-9 * max(1.0, per.max()):
        text += f" ({fmt(per.min(), 3)}–{fmt(per.max(), 3)})"
    problem = g.loc[per.index[0], "problem"]
    return [(f"{declared} / ", ""), (text, "#" + anchor("convergence", stepper, problem))], True


def convergence(view: RunView, sec: Section) -> None:
    """Add the convergence figures and tables to `sec`, read from `view`."""
    rows = view.rowtable("convergence")
    judged = _convergence_judged(view)
    sec.note("Each figure: error against h, markers at the two ends of the range the order fit "
             "used, the thin line alone beyond them where points were excluded (pre-asymptotic, "
             "roundoff or reference floor; the CSV says which point is which); dashed, the fitted "
             "slope over that range; dotted, the reference floor.")
    sec.note("Error constants: measured C is the smallest fitted error over h^p at its step (p the "
             "expected order); predicted C is the leading global error term h^p e(T) from the "
             "coefficients' defects and the problem's elementary differentials carried to the final "
             "time by the variational equation (HNW I, II.8, Theorem 8.1), for Runge-Kutta tableaus "
             "where an h^p law is expected. It follows the problem's own start while the measured "
             "error is the largest over the ensemble, so measured/predicted is about 1 or above, far "
             "above where the leading term nearly cancels at the own start's final time; a cell "
             "without a prediction says why. Information only: the verdict judges the slope.")
    for problem in problems_in(view, judged):
        g = part(view, rows, "problem", problem) if "problem" in rows else pd.DataFrame()
        ref = part(view, judged, "problem", problem)["reference_error"].astype(float)
        ref_err = float(ref.max()) if len(ref) and np.isfinite(ref).any() else None
        if len(g):
            glob = g[g["kind"] == "global"] if "kind" in g else g
            same = [" = ".join([k, *v]) for k, v in same_curves(glob).items() if v] if len(glob) else []
            sec.figure(convergence_figure(problem, g, view.palette, ref_err),
                       f"Error against h on {problem}."
                       + (f" Identical curves drawn once: {'; '.join(same)}." if same else ""))
    cols = [("stepper", "stepper"), ("problem", "problem"), ("claimed_order", "claimed"),
            ("measured_order", "measured"), ("order_ci_low", "95% CI low"),
            ("order_ci_high", "95% CI high"), ("fit_points", "fit points"), ("verdict", "verdict"),
            ("reason", "why"), ("measured_coefficient", "measured C"),
            ("predicted_coefficient", "predicted C"), ("prediction_note", "why no prediction")]
    sec.table(df_table(judged, cols, f"Per cell: {len(judged)} stepper × problem fits",
                       experiment="convergence", digits=4))


SECTION = SectionSpec(
    "convergence", title="Convergence",
    intro=("Global error at the final time against the step size h, one figure per problem with "
           "one panel per family; the slope of the fitted range (dashed) is the measured order, "
           "judged against the order the coefficients give. Markers bound the range the fit "
           "used; points beyond it were excluded (roundoff floor, reference floor — dotted — or "
           "pre-asymptotic); adaptive steppers are judged against their tolerance instead."),
    measures=(Measure("measured_order", "measured order", ci=("order_ci_low", "order_ci_high")),),
    verdicts=_convergence_verdicts,
    score=(ScoreColumn("measured order: median (min–max over problems)", _order_score),
           ScoreColumn("evaluations per step declared / measured", _evals_score)),
    build=convergence,
)
