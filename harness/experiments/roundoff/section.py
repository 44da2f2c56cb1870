"""The roundoff section: the rounding floor at a fixed step count."""

from __future__ import annotations

from harness.experiments.roundoff.figures import roundoff_figure
from harness.kit import RunView, Section, SectionSpec, df_table


def roundoff(view: RunView, sec: Section) -> None:
    """Add the roundoff figures and tables to `sec`, read from `view`.

    Parameters
    ----------
    view : RunView, whose roundoff rows draw the figure and whose summary fills the table.
    sec : Section, the one written to.
    """
    ro = view.rowtable("roundoff")
    if len(ro):
        sec.figure(roundoff_figure(ro, view.palette),
                   "Relative position error against h at a fixed step count.")
    summ = view.summary("roundoff")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("n_steps", "N"), ("floor_error", "floor error"),
            ("floor_h", "at h"), ("floor_eps", "floor (ulps)"), ("rounding_limited", "rounding-limited"),
            ("growth_exponent", "growth ∝ n^"),
            ("verdict", "verdict"), ("message", "why")]
    sec.table(df_table(summ, cols, "Per stepper: the rounding floor", experiment="roundoff", status=None))


SECTION = SectionSpec(
    "roundoff", title="Roundoff",
    intro=("Position error after a fixed number of steps as h shrinks to where rounding, not "
           "truncation, dominates. The dotted line is the truncation error alone (∝ h^(p+1) at "
           "fixed N, p the order); below it what is left is rounding, which the two-step Verlet "
           "form (and every k-step method of that form) accumulates far more of than the one-step "
           "forms: along the run at the smallest h its error grows like n² (a slowly varying rounding "
           "bias integrated twice), theirs like n^(1/2)."),
    build=roundoff,
)
