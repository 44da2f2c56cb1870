"""Report section "Published test sets": the test-set problems of a run (DETEST, the Bari IVP test
set) in the style of the test set's own reports.

One row per work-precision point on a problem with a published form (`Problem.published`):
method, tolerance or step, error at the end point (max over components, against the reference the
work-precision cell used), significant digits (-log10 of that error over the largest component
of the reference: the test set's `scd` in the max norm), right-hand-side evaluations and time.
A second table says, per problem, which reference stood behind the errors (Taylor certified,
the stiff cross-check, or the published end values), its stated error, and the published form's
distance from the float64 form. The numbers are read from the run's work-precision rows; the
references come from the disk cache the cells filled.

References: F. Mazzia & C. Magherini, Test Set for IVP Solvers (Bari, 2008), section "Numerical
results" (scd, mescd against work); T. E. Hull et al., SIAM J. Numer. Anal. 9 (1972) 603-637.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from harness.facts import problem_facts
from harness.ground_truth import reference
from harness.kit.elements import Section, df_table
from harness.registry import get_problem
from harness.tolerances import STIFF_STEP_COUNT

__all__ = ["test_sets_section", "TITLE"]

EXPERIMENT = "work-precision"
TITLE = "Published test sets"
INTRO = ("Problems from the published test sets (DETEST, Hull et al. 1972; the Bari IVP test set, "
         "Mazzia & Magherini), measured as their own reports do: error at the test set's end "
         "point against work, from the work-precision experiment. They run on request "
         "(`--problem bari-rober`, `harness list problems` marks them).")


def _published(name: str):
    try:
        return get_problem(name)
    except Exception:  # a problem of a plugin this process has not loaded
        return None


def _stiff_over(problem, T: float) -> dict[str, Any]:
    """The problem's stiffness (largest -Re(lambda) along the reference over its horizon,
    `harness.facts`) times its declared span and times the span the points measured; a problem
    stiff over its span (`STIFF_STEP_COUNT`: more steps than that for stability alone at an
    interval of 1) but not over the measured one is flagged: its points test nothing stiff."""
    try:
        rate = float(problem_facts(problem).stiffness)
    except Exception as exc:  # reported in the row, never fatal
        return {"stiff_check": f"unknown: {type(exc).__name__}"}
    span, measured = rate * (problem.t_end - problem.t0), rate * (T - problem.t0)
    if span <= STIFF_STEP_COUNT:
        check = "not stiff over its span"
    elif measured <= STIFF_STEP_COUNT:
        check = f"NOT STIFF where measured (t <= {T:.3g}): the points test nothing stiff"
    else:
        check = "stiff where measured"
    return {"stiffness_span": span, "stiffness_measured": measured, "stiff_check": check}


def test_sets_section(view: Any) -> Section:
    """The section from a `RunView`: the work-precision rows of test-set problems.

    Parameters
    ----------
    view : RunView, the run (work-precision rows; a note when no test-set problem ran).

    Returns
    -------
    Section
    """
    sec = Section("test-sets", 0, TITLE)
    sec.intro = INTRO
    rows = view.rowtable(EXPERIMENT) if view.has(EXPERIMENT) else pd.DataFrame()
    problems = {n: p for n in (rows["problem"].unique() if len(rows) else [])
                if (p := _published(n)) is not None and p.published is not None}
    if not problems:
        sec.note("No test-set problem in this run: they run on request, e.g. `harness report "
                 "--problem bari-hires --problem detest-d3`.", cls="warning")
        return sec
    frame = rows[rows["problem"].isin(problems)].copy()
    refs = []
    scale: dict[str, float] = {}
    for name, problem in problems.items():
        T = float(frame.loc[frame.problem == name, "t_end"].iloc[0])
        rec: dict[str, Any] = {"problem": name, "t_end": T,
                               "published_t_end": problem.published.t_end,
                               "source": problem.published.source}
        try:  # the cells' own request (member 0 from the float64 start): a cache hit
            ref = reference(problem, np.array([T]), problem.y0.reshape(-1, 1))
            scale[name] = max(float(np.max(np.abs(ref.y[-1]))), 1e-300)
            rec.update(reference=f"{ref.precision} ({ref.certified_by[:60]})",
                       reference_error=ref.max_error, form=ref.form)
        except Exception as exc:  # reported, never fatal
            rec.update(reference=f"not available: {type(exc).__name__}", message=str(exc)[:300])
        rounding = problem.published.rounding()
        rec["float64_rounding"] = max(rounding.values())
        rec.update(_stiff_over(problem, T))
        refs.append(rec)
    frame["tol_or_h"] = [(f"tol {t:.0e}" if isinstance(t, float) and math.isfinite(t) else
                          f"h {h:.4g}") for t, h in zip(frame["tol"], frame["h"], strict=True)]
    frame["digits"] = [
        (-math.log10(e / scale[p]) if p in scale and math.isfinite(e) and e > 0 else np.nan)
        for e, p in zip(frame["error"].astype(float), frame["problem"], strict=True)]
    cols = [("problem", "problem"), ("stepper", "method"), ("tol_or_h", "tol or step"),
            ("error", "error at the end"), ("digits", "significant digits"),
            ("rhs_evals", "f evaluations"), ("wall_s", "time (s)"), ("message", "message")]
    sec.table(df_table(frame.sort_values(["problem", "stepper", "rhs_evals"]), cols,
                       "Error at the end point against work, per method", experiment=EXPERIMENT,
                       key=("stepper", "problem", "tol_or_h"), status=None, digits=3))
    table = pd.DataFrame(refs)
    for c in ("reference", "reference_error", "form", "message", "stiffness_span",
              "stiffness_measured", "stiff_check"):
        if c not in table:
            table[c] = None
    sec.table(df_table(table, [("problem", "problem"), ("t_end", "end point"),
                               ("published_t_end", "published end"), ("reference", "reference"),
                               ("reference_error", "its stated error"),
                               ("float64_rounding", "float64 rounding of the inputs"),
                               ("stiffness_span", "-Re(lambda) x span"),
                               ("stiffness_measured", "-Re(lambda) x measured span"),
                               ("stiff_check", "stiff where measured?"),
                               ("source", "source"), ("message", "message")],
                       "The reference behind each problem's errors", key=("problem",),
                       status=None, digits=3))
    sec.note("Significant digits: -log10(error / max |y_ref|). The float64 rounding is the "
             "largest relative rounding of the published start values, constants and end time; "
             "the steppers run the float64 form, and so does the reference they are measured "
             "against.")
    return sec
