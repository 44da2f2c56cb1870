"""The reversibility section: return error over the rounding bound against N, one row per
stepper and problem with the values of each N."""

from __future__ import annotations

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.experiments.reversibility.figures import reversibility_figure
from harness.kit import Measure, RunView, ScoreColumn, Section, SectionSpec, anchor, df_table, fmt, is_missing
from harness.kit.section import claimed_measured
from harness.kit.view import rows_of


def _reversible_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    info = view.infos.get(stepper)
    s = rows_of(view, "reversibility", stepper)
    if not s.empty and "verdict" in s:
        s = s[s.verdict != "not-measurable"]  # a saturated flow: says nothing either way
    within = [] if s.empty else [
        (bool(np.isfinite(float(r["return_error_ulps"]))
              and float(r["return_error_ulps"]) <= float(r["rounding_bound_ulps"])),
         anchor("reversibility", stepper, r["problem"])) for r in s.to_dict("records")]
    return claimed_measured(view, "reversibility", stepper, bool(getattr(info, "symmetric", False)), within)


def reversibility(view: RunView, sec: Section) -> None:
    """Add the reversibility figures and tables to `sec`, read from `view`."""
    summ = view.summary("reversibility")
    symmetric = view.flag("symmetric")
    sec.figure(reversibility_figure(summ, view.palette, symmetric),
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


SECTION = SectionSpec(
    "reversibility", title="Reversibility",
    intro=("N steps forward, time reversed, N steps back: the distance from the start in units "
           "of the rounding bound (what rounding alone explains), against N. A method claimed "
           "symmetric (solid) must stay under the dotted line at 1 on every problem; one not "
           "claimed symmetric (dashed) must stay above it."),
    key=("stepper", "problem", "steps"), row_key=("stepper", "problem"),
    measures=(Measure("return_error_ulps", "return error (ulps)", factor=tol.REPORT_CHANGE_ROUNDING),),
    score=(ScoreColumn("reversible claimed / measured", _reversible_score),),
    build=reversibility,
)
