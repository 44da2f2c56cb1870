"""The symplecticity section: the deviation from symplecticity per stepper and problem."""

from __future__ import annotations

import numpy as np

from harness import tolerances as tol
from harness.experiments.symplecticity.figures import symplecticity_figure
from harness.kit import Measure, RunView, ScoreColumn, Section, SectionSpec, anchor, df_table
from harness.kit.section import claimed_measured
from harness.kit.view import rows_of


def _symplectic_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    info = view.infos.get(stepper)
    s = rows_of(view, "symplecticity", stepper)
    within = [] if s.empty else [
        (bool(np.isfinite(float(r["deviation"])) and float(r["deviation"]) <= float(r["threshold"])),
         anchor("symplecticity", stepper, r["problem"])) for r in s.to_dict("records")]
    return claimed_measured(view, "symplecticity", stepper, bool(getattr(info, "symplectic", False)),
                             within)


def symplecticity(view: RunView, sec: Section) -> None:
    """Add the symplecticity figures and tables to `sec`, read from `view`."""
    summ = view.summary("symplecticity")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("h", "h"), ("states", "states"),
            ("deviation", "deviation"), ("threshold", "threshold"),
            ("claimed_symplectic", "claimed symplectic"), ("verdict", "verdict"), ("message", "why")]
    sec.figure(symplecticity_figure(summ, view.palette),
               "Deviation from symplecticity of each stepper on each problem (log scale), with "
               "the finite-difference threshold.")
    sec.table(df_table(summ, cols, f"Per cell: {len(summ)} Jacobians", experiment="symplecticity"))


SECTION = SectionSpec(
    "symplecticity", title="Symplecticity",
    intro=("The one-step map's Jacobian J, by central differences at points along the orbit: "
           "the deviation ‖JᵀΩJ − Ω‖ / ‖J‖² is zero for a symplectic map. A method claimed "
           "symplectic must stay at the finite-difference level (the threshold); one not "
           "claimed must rise clearly above it."),
    measures=(Measure("deviation", "symplectic deviation", factor=tol.REPORT_CHANGE_ROUNDING),),
    score=(ScoreColumn("symplectic claimed / measured", _symplectic_score),),
    build=symplecticity,
)
