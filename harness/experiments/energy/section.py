"""The energy section: relative energy (and angular momentum) error against time by drift class."""

from __future__ import annotations

from harness import tolerances as tol
from harness.experiments.energy.figures import angular_momentum_figure, energy_figure
from harness.kit import Measure, RunView, ScoreColumn, Section, SectionSpec, anchor, df_table
from harness.kit.view import part, problems_in, rows_of


def _energy_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    s = rows_of(view, "energy", stepper)
    if s.empty:
        return [("—", "")], False
    parts: list[tuple[str, str]] = []
    for cls, g in s.groupby("drift_class", sort=False):
        cls = cls or "not measurable"  # the experiment gives such a cell no class
        parts += [(", " if parts else "", ""),
                  (f"{cls} ×{len(g)}" if len(g) > 1 else str(cls),
                   "#" + anchor("energy", stepper, g["problem"].iloc[0]))]
    return parts, True


def energy(view: RunView, sec: Section) -> None:
    """Add the energy figures and tables to `sec`, read from `view`."""
    rows = view.rowtable("energy")
    summ = view.summary("energy")
    symplectic = view.flag("symplectic")
    for problem in problems_in(view, summ):
        g = part(view, rows, "problem", problem)
        s = part(view, summ, "problem", problem)
        sec.figure(energy_figure(problem, g, view.palette, symplectic,
                                   classes=dict(zip(s["stepper"], s["drift_class"], strict=True))),
                   f"Relative energy error on {problem}, by drift class; solid: symplectic "
                   "steppers, dashed: the others.")
        if "quantity" in g and (g["quantity"] == "angular_momentum").any():
            sec.figure(angular_momentum_figure(
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


SECTION = SectionSpec(
    "energy", title="Energy drift",
    intro=("Relative energy error against time over long runs on log axes, the same step size for "
           "every stepper of a problem; lines are the largest error in log-spaced time bins. "
           "Each panel holds one drift class (bounded, sqrt, linear, unstable) as measured from "
           "the growth of the error's running maximum, and runs too short or otherwise not "
           "measurable get none; symplectic steppers are drawn solid."),
    measures=(Measure("max_rel_energy_error", "max relative energy error",
                      factor=tol.REPORT_CHANGE_ROUNDING),),
    score=(ScoreColumn("energy drift class", _energy_score),),
    build=energy,
)
