"""The sections of the built-in experiments, one `register_section` each.

A section adds its figures and one folded per-cell table to the `Section` it is given; its
registration carries the two-sentence intro, the scoreboard columns it fills (every number
linked to its row), the figures the changed-since comparison follows, and, where the judgement
is not the summary's own `passed` column, the verdict rows (convergence is judged by the gate).
An experiment without a registration gets `sections.generic_section`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.report import figures as F
from harness.report.sections import (
    Measure,
    RunView,
    ScoreColumn,
    Section,
    anchor,
    df_table,
    fmt,
    is_missing,
    register_section,
    yes_no,
)

__all__: list[str] = []


def _split(view: RunView, table: pd.DataFrame, column: str) -> dict:
    """`table`'s rows by their value of `column`, split once per table and view (sections ask
    for one stepper's or one problem's rows many times; a boolean mask each time scans all)."""
    cache = view.__dict__.setdefault("_splits", {})
    key = (id(table), column)
    if key not in cache:
        cache[key] = (table, dict(tuple(table.groupby(column, sort=False))) if column in table else {})
    return cache[key][1]


def _part(view: RunView, table: pd.DataFrame, column: str, value: object) -> pd.DataFrame:
    part = _split(view, table, column).get(value)
    return part if part is not None else table.iloc[0:0]


def _rows_of(view: RunView, name: str, stepper: str) -> pd.DataFrame:
    s = view.summary(name)
    if s.empty or "stepper" not in s:
        return s
    return _part(view, s, "stepper", stepper)


def _problems_in(view: RunView, table: pd.DataFrame) -> list[str]:
    present = set(table["problem"]) if "problem" in table else set()
    return [p for p in view.problems if p in present] + sorted(present - set(view.problems))


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
    from harness.report.verdicts import summary_verdicts

    return summary_verdicts("convergence", _convergence_judged(view), ("stepper", "problem"),
                            reason="reason")


def _order_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    s = _rows_of(view, "convergence", stepper)
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
    g = _part(view, rows, "stepper", stepper)
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


@register_section(
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
)
def convergence(view: RunView, sec: Section) -> None:
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
    for problem in _problems_in(view, judged):
        g = _part(view, rows, "problem", problem) if "problem" in rows else pd.DataFrame()
        ref = _part(view, judged, "problem", problem)["reference_error"].astype(float)
        ref_err = float(ref.max()) if len(ref) and np.isfinite(ref).any() else None
        if len(g):
            glob = g[g["kind"] == "global"] if "kind" in g else g
            same = [" = ".join([k, *v]) for k, v in F.same_curves(glob).items() if v] if len(glob) else []
            sec.figure(F.convergence_figure(problem, g, view.palette, ref_err),
                       f"Error against h on {problem}."
                       + (f" Identical curves drawn once: {'; '.join(same)}." if same else ""))
    cols = [("stepper", "stepper"), ("problem", "problem"), ("claimed_order", "claimed"),
            ("measured_order", "measured"), ("order_ci_low", "95% CI low"),
            ("order_ci_high", "95% CI high"), ("fit_points", "fit points"), ("verdict", "verdict"),
            ("reason", "why"), ("measured_coefficient", "measured C"),
            ("predicted_coefficient", "predicted C"), ("prediction_note", "why no prediction")]
    sec.table(df_table(judged, cols, f"Per cell: {len(judged)} stepper × problem fits",
                       experiment="convergence", digits=4))


# -- stability ------------------------------------------------------------------------------------
def _stability_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    s = _rows_of(view, "stability", stepper)
    if s.empty:
        return [("—", "")], False
    r = s.iloc[0]
    href = "#" + anchor("stability", stepper, r["problem"])
    if r.get("form") == "newtonian":
        return [("hω ≤ ", ""), (fmt(r.get("hw_limit"), 4), href)], True
    re_iv, im_iv = float(r.get("real_interval")), float(r.get("imag_interval"))
    re_t = "unbounded" if np.isinf(re_iv) else f"[−{fmt(re_iv, 4)}, 0]"
    im_t = "unbounded" if np.isinf(im_iv) else f"±{fmt(im_iv, 4)}"
    return [("real ", ""), (re_t, href), ("; imag ", ""), (im_t, href)], True


@register_section(
    "stability", title="Stability",
    intro=("Linear stability measured from the outside: one step of y' = λy over a grid of "
           "complex hλ (first-order methods), or of x'' = −ω²x (Newtonian methods), compared "
           "with the formula from the coefficients. Each panel overlays one family's boundaries "
           "|R(hλ)| = 1 with the stable side shaded; the bars give the first instability in hω, "
           "and the table lists every unstable hω band, found exactly on the propagator's "
           "polynomials (narrow resonance bands near hω = kπ included)."),
    measures=(Measure("real_interval", "real stability interval", rtol=tol.REPORT_CHANGE_RTOL),
              Measure("imag_interval", "imaginary stability interval", rtol=tol.REPORT_CHANGE_RTOL),
              Measure("hw_limit", "hω limit", rtol=tol.REPORT_CHANGE_RTOL)),
    score=(ScoreColumn("stability (probe)", _stability_score),),
)
def stability(view: RunView, sec: Section) -> None:
    rows = view.rowtable("stability")
    summ = view.summary("stability")
    first = rows[rows["kind"] == "grid"] if "kind" in rows else pd.DataFrame()
    if len(first):
        sec.figure(F.stability_overlay_figure(first, view.palette),
                   "Boundaries |R(hλ)| = 1 of the first-order methods, one panel per family.")
    sec.figure(F.hw_limits_figure(summ, view.palette),
               "Largest stable hω of each Newtonian stepper on the harmonic oscillator; hatched "
               "bars are unbounded within the search limit.")
    s = summ.assign(agrees=summ["analytic_agrees"].map(
        lambda v: "—" if v is None or (isinstance(v, float) and math.isnan(v)) else ("yes" if v else "NO")))
    cols = [("stepper", "stepper"), ("problem", "problem"), ("form", "form"),
            ("real_interval", "real (probe)"), ("analytic_real_interval", "real (formula)"),
            ("imag_interval", "imag (probe)"), ("analytic_imag_interval", "imag (formula)"),
            ("hw_limit", "hω (probe)"), ("analytic_hw_limit", "hω (formula)"),
            ("hw_bands", "unstable hω bands (exact)"), ("agrees", "probe = formula"),
            ("verdict", "verdict"), ("message", "why")]
    sec.table(df_table(s, cols, "Per stepper: stability intervals, probe against formula (real "
                       "[−x, 0], imaginary [−y, y])", experiment="stability", digits=8))


# -- claimed / measured properties ----------------------------------------------------------------
def _claimed_measured(view: RunView, name: str, stepper: str, claimed: bool,
                      within: Iterable[tuple[bool, str]]) -> tuple[list[tuple[str, str]], bool]:
    """'claimed / measured' with the measured part linked to a row that shows it."""
    w = list(within)
    if not w:
        return [(f"{yes_no(claimed)} / —", "")], False
    n = sum(1 for ok, _ in w if ok)
    measured = "yes" if n == len(w) else ("no" if n == 0 else f"mixed ({n}/{len(w)} yes)")
    witness = next((a for ok, a in w if ok != claimed), w[0][1])  # a row against the claim, if any
    return [(f"{yes_no(claimed)} / ", ""), (measured, "#" + witness)], True


def _reversible_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    info = view.infos.get(stepper)
    s = _rows_of(view, "reversibility", stepper)
    if not s.empty and "verdict" in s:
        s = s[s.verdict != "not-measurable"]  # a saturated flow: says nothing either way
    within = [] if s.empty else [
        (bool(np.isfinite(float(r["return_error_ulps"]))
              and float(r["return_error_ulps"]) <= float(r["rounding_bound_ulps"])),
         anchor("reversibility", stepper, r["problem"])) for r in s.to_dict("records")]
    return _claimed_measured(view, "reversibility", stepper, bool(getattr(info, "symmetric", False)), within)


@register_section(
    "reversibility", title="Reversibility",
    intro=("N steps forward, time reversed, N steps back: the distance from the start in units "
           "of the rounding bound (what rounding alone explains), against N. A method claimed "
           "symmetric (solid) must stay under the dotted line at 1 on every problem; one not "
           "claimed symmetric (dashed) must stay above it."),
    key=("stepper", "problem", "steps"), row_key=("stepper", "problem"),
    measures=(Measure("return_error_ulps", "return error (ulps)", factor=tol.REPORT_CHANGE_ROUNDING),),
    score=(ScoreColumn("reversible claimed / measured", _reversible_score),),
)
def reversibility(view: RunView, sec: Section) -> None:
    summ = view.summary("reversibility")
    symmetric = view.flag("symmetric")
    sec.figure(F.reversibility_figure(summ, view.palette, symmetric),
               "Return error over the rounding bound against N, every problem in one figure: for "
               "each method the worst case against its claim (largest ratio over the problems if "
               "claimed symmetric, smallest if not). Each problem's values: the CSV and the table.")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("h", "h"),
            ("claimed_symmetric", "claimed symmetric"), ("steps", "N"),
            ("return_error_ulps", "return error (ulps), per N"),
            ("rounding_bound_ulps", "rounding bound (ulps), per N"),
            ("growth_exponent", "growth exponent"), ("verdict", "verdict, per N"), ("message", "why")]
    folded = fold_per_n(summ)
    sec.table(df_table(folded, cols, f"Per stepper and problem: {len(summ)} round trips in "
                       f"{len(folded)} rows, the values of each N in order",
                       experiment="reversibility", key=("stepper", "problem")))


def _steps_text(n: object) -> str:
    """A step count as a reader takes it in: 10⁴ for a power of ten, else the integer."""
    try:
        k = int(n)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        return fmt(n)
    e = len(str(k)) - 1
    if k >= 100 and k == 10 ** e:
        return "10" + str(e).translate(str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return str(k)


def fold_per_n(summ: pd.DataFrame) -> pd.DataFrame:
    """Reversibility rows folded to one per (stepper, problem): the per-N figures listed in the
    order of N (`steps`), one verdict word when every N has the same, the reasons of the Ns
    joined; `passed` False when any N failed, True when all that were judged passed. Every
    value of every round trip stays (and each is in the figure's CSV at full precision)."""
    if summ.empty or not {"stepper", "problem", "steps"} <= set(summ.columns):
        return summ
    groups: dict[tuple, list[dict]] = {}
    for rec in summ.to_dict("records"):
        groups.setdefault((rec["stepper"], rec["problem"]), []).append(rec)
    out = []
    for (stepper, problem), recs in groups.items():
        recs.sort(key=lambda r: float(r["steps"]))
        ns = [_steps_text(r["steps"]) for r in recs]
        judged = [bool(r["passed"]) for r in recs if not is_missing(r.get("passed"))]
        verdicts = [str(r.get("verdict", "")) for r in recs]
        reasons = [(n, " ".join(str(r.get("message") or "").split())) for n, r in zip(ns, recs, strict=True)]
        reasons = [(n, m) for n, m in reasons if m and m != "nan"]
        if len({m for _, m in reasons}) == 1 and len(reasons) == len(recs):
            why = reasons[0][1]
        else:
            why = "; ".join(f"N = {n}: {m}" for n, m in reasons)
        first = recs[0]
        out.append({
            "stepper": stepper, "problem": problem, "h": first.get("h"),
            "claimed_symmetric": first.get("claimed_symmetric"), "steps": ", ".join(ns),
            "return_error_ulps": ", ".join(fmt(r.get("return_error_ulps")) for r in recs),
            "rounding_bound_ulps": ", ".join(fmt(r.get("rounding_bound_ulps")) for r in recs),
            "growth_exponent": first.get("growth_exponent"),
            "verdict": verdicts[0] if len(set(verdicts)) == 1 else ", ".join(verdicts),
            "passed": (all(judged) if judged else None), "message": why})
    return pd.DataFrame(out)


def _energy_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    s = _rows_of(view, "energy", stepper)
    if s.empty:
        return [("—", "")], False
    parts: list[tuple[str, str]] = []
    for cls, g in s.groupby("drift_class", sort=False):
        cls = cls or "not measurable"  # the experiment gives such a cell no class
        parts += [(", " if parts else "", ""),
                  (f"{cls} ×{len(g)}" if len(g) > 1 else str(cls),
                   "#" + anchor("energy", stepper, g["problem"].iloc[0]))]
    return parts, True


@register_section(
    "energy", title="Energy drift",
    intro=("Relative energy error against time over long runs on log axes, the same step size for "
           "every stepper of a problem; lines are the largest error in log-spaced time bins. "
           "Each panel holds one drift class (bounded, sqrt, linear, unstable) as measured from "
           "the growth of the error's running maximum, and runs too short or otherwise not "
           "measurable get none; symplectic steppers are drawn solid."),
    measures=(Measure("max_rel_energy_error", "max relative energy error",
                      factor=tol.REPORT_CHANGE_ROUNDING),),
    score=(ScoreColumn("energy drift class", _energy_score),),
)
def energy(view: RunView, sec: Section) -> None:
    rows = view.rowtable("energy")
    summ = view.summary("energy")
    symplectic = view.flag("symplectic")
    for problem in _problems_in(view, summ):
        g = _part(view, rows, "problem", problem)
        s = _part(view, summ, "problem", problem)
        sec.figure(F.energy_figure(problem, g, view.palette, symplectic,
                                   classes=dict(zip(s["stepper"], s["drift_class"], strict=True))),
                   f"Relative energy error on {problem}, by drift class; solid: symplectic "
                   "steppers, dashed: the others.")
        if "quantity" in g and (g["quantity"] == "angular_momentum").any():
            sec.figure(F.angular_momentum_figure(
                problem, g, view.palette, symplectic,
                classes=dict(zip(s["stepper"], s["angular_momentum_class"], strict=True))),
                f"Relative change of the angular momentum on {problem} (solid: symplectic "
                f"steppers, dashed: the others), with the rounding bound of "
                f"a method that conserves it exactly ({tol.ANGULAR_MOMENTUM_ROUNDING_ULPS:g} ulp per step).")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("h", "h"), ("steps", "steps"),
            ("claimed_symplectic", "claimed symplectic"), ("drift_class", "drift class"),
            ("expected_class", "expected"), ("drift_exponent", "growth exponent"),
            ("max_rel_energy_error", "max rel. energy error"),
            ("max_rel_angular_momentum_error", "max rel. L error"),
            ("angular_momentum_conserved", "L conserved"), ("verdict", "verdict"), ("message", "why")]
    sec.table(df_table(summ, cols, f"Per cell: {len(summ)} long runs", experiment="energy"))


def _symplectic_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    info = view.infos.get(stepper)
    s = _rows_of(view, "symplecticity", stepper)
    within = [] if s.empty else [
        (bool(np.isfinite(float(r["deviation"])) and float(r["deviation"]) <= float(r["threshold"])),
         anchor("symplecticity", stepper, r["problem"])) for r in s.to_dict("records")]
    return _claimed_measured(view, "symplecticity", stepper, bool(getattr(info, "symplectic", False)),
                             within)


@register_section(
    "symplecticity", title="Symplecticity",
    intro=("The one-step map's Jacobian J, by central differences at points along the orbit: "
           "the deviation ‖JᵀΩJ − Ω‖ / ‖J‖² is zero for a symplectic map. A method claimed "
           "symplectic must stay at the finite-difference level (the threshold); one not "
           "claimed must rise clearly above it."),
    measures=(Measure("deviation", "symplectic deviation", factor=tol.REPORT_CHANGE_ROUNDING),),
    score=(ScoreColumn("symplectic claimed / measured", _symplectic_score),),
)
def symplecticity(view: RunView, sec: Section) -> None:
    summ = view.summary("symplecticity")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("h", "h"), ("states", "states"),
            ("deviation", "deviation"), ("threshold", "threshold"),
            ("claimed_symplectic", "claimed symplectic"), ("verdict", "verdict"), ("message", "why")]
    sec.figure(F.symplecticity_figure(summ, view.palette),
               "Deviation from symplecticity of each stepper on each problem (log scale), with "
               "the finite-difference threshold.")
    sec.table(df_table(summ, cols, f"Per cell: {len(summ)} Jacobians", experiment="symplecticity"))


# -- work-precision -------------------------------------------------------------------------------
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
    hit = finite[(finite["err"] <= F.WORK_TARGET_ERROR) & finite["evals"].notna()]
    cheapest = hit.loc[hit.groupby(keys, sort=False)["evals"].idxmin()].set_index(keys)
    out["evals_to_target"] = cheapest["evals"]
    out["wall_to_target"] = cheapest["wall"]
    out = out.reset_index()
    out["points"] = out["points"].astype(int)
    return out[cols]


@register_section(
    "work-precision", title="Work–precision",
    intro=("Error at the final time against the work spent — right-hand-side (or force) "
           "evaluations, then warm wall time measured like a benchmark — over a step-size sweep "
           "(fixed-step methods) or a tolerance sweep (adaptive ones, dashed). Lower and further "
           "left is better; the best method of each family (to reach the target error) is bold."),
    measures=(Measure("evals_to_target", "evaluations to reach the target error",
                      rtol=tol.REPORT_CHANGE_RTOL),),
)
def work_precision(view: RunView, sec: Section) -> None:
    name = "work-precision"
    rows = view.rowtable(name)
    adaptive = view.flag("adaptive")
    if "error" not in rows:
        sec.note("The work-precision rows have no `error` column; nothing to draw.", cls="warning")
        return
    sec.note(f"Each figure: error against evaluations on one problem; bold, the best of each "
             f"family (fewest evaluations to reach {F.WORK_TARGET_ERROR:g}), faint, the others. "
             "Error against warm time, by the timing protocol, follows under 'Error against time'.")
    for problem in _problems_in(view, rows):
        sec.figure(F.work_precision_figure(problem, _part(view, rows, "problem", problem), view.palette,
                                           adaptive),
                   f"Error against evaluations on {problem}.")
    summ = view.summary(name)
    if len(summ) and {"stepper", "problem", "error"} <= set(summ.columns):
        table = _work_table(summ)
        cols = [("stepper", "stepper"), ("problem", "problem"), ("kind", "sweep"), ("points", "points"),
                ("lowest_error", "lowest error"), ("evals_at_lowest", "evaluations there"),
                ("evals_to_target", f"evaluations to reach {F.WORK_TARGET_ERROR:g}"),
                ("wall_to_target", f"wall s to reach {F.WORK_TARGET_ERROR:g}"), ("unit", "evaluation unit")]
        sec.table(df_table(table, cols, f"Per stepper and problem: cost of reaching "
                           f"{F.WORK_TARGET_ERROR:g}", experiment=name, status=None, sort_failing=False))
    from harness.report.timing_section import add_time_sections

    add_time_sections(view, sec)  # error against warm time, time to target, same-method groups


# -- roundoff -------------------------------------------------------------------------------------
@register_section(
    "roundoff", title="Roundoff",
    intro=("Position error after a fixed number of steps as h shrinks to where rounding, not "
           "truncation, dominates. The dotted line is the truncation error alone (∝ h³ at fixed "
           "N); below it what is left is rounding, which the two-step Verlet form accumulates far "
           "more of than the one-step forms."),
)
def roundoff(view: RunView, sec: Section) -> None:
    ro = view.rowtable("roundoff")
    if len(ro):
        sec.figure(F.roundoff_figure(ro, view.palette),
                   "Relative position error against h at a fixed step count.")
    summ = view.summary("roundoff")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("n_steps", "N"), ("floor_error", "floor error"),
            ("floor_h", "at h"), ("floor_eps", "floor (ulps)"), ("rounding_limited", "rounding-limited"),
            ("verdict", "verdict"), ("message", "why")]
    sec.table(df_table(summ, cols, "Per stepper: the rounding floor", experiment="roundoff", status=None))


from harness.report import step_control  # noqa: E402,F401  (registers the step-control section)
