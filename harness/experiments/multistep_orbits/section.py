"""The multistep-orbits section: resonant step sizes of symmetric tables, spiralling of the others."""

from __future__ import annotations

from harness import tolerances as tol
from harness.experiments.multistep_orbits.figures import drift_figure, scan_figure
from harness.kit import RunView, Section, SectionSpec, df_table
from harness.kit.view import part, problems_in


def multistep_orbits(view: RunView, sec: Section) -> None:
    """Add the scans, the drift figures and the two tables to `sec`, read from `view`.

    Parameters
    ----------
    view : RunView, the run's multistep-orbits rows and summary.
    sec : Section, written per problem, then the tables.
    """
    rows = view.rowtable("multistep-orbits")
    summ = view.summary("multistep-orbits")
    for problem in problems_in(view, summ):
        g = part(view, rows, "problem", problem)
        s = part(view, summ, "problem", problem)
        sec.figure(scan_figure(problem, g, s, view.palette),
                   f"Largest relative energy error over the run against h ω on {problem}: a "
                   f"resonance stands {tol.RESONANCE_SPIKE_FACTOR:g}x above the trend of its "
                   "neighbours (circled); ticks mark the resonances predicted from the parasitic "
                   "roots of each symmetric table and the harmonics of the force Jacobian along the orbit.")
        sec.figure(drift_figure(problem, g, view.palette),
                   f"Energy drift rate against h ω on {problem}, measured (Theil-Sen slope) and "
                   "predicted from the principal root's growth, 2 g |v|² / |E|.")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("symmetric", "symmetric"),
            ("points", "h scanned"), ("predicted", "predicted h ω"),
            ("predicted_testable", "predicted, at most the onset"),
            ("predicted_found", "of them found"), ("resonances", "resonances found (h ω)"),
            ("resonances_predicted", "of them predicted"), ("chance_fraction", "chance match"),
            ("onset_h_omega", "unstable from h ω"), ("message", "why")]
    sec.table(df_table(summ, cols, "Resonant step sizes", experiment="multistep-orbits", status=None))
    cols = [("stepper", "stepper"), ("problem", "problem"), ("order", "order"),
            ("expected_class", "expected"), ("drift_class", "measured"),
            ("drift_points", "points"), ("drift_exponent", "rate ∝ (h ω)^"),
            ("predicted_exponent", "predicted ^"), ("rate_ratio", "measured / predicted"),
            ("sign_agrees", "sign as predicted"), ("verdict", "verdict"), ("message", "why")]
    sec.table(df_table(summ, cols, "Bounded or secular energy error", experiment="multistep-orbits"))


SECTION = SectionSpec(
    "multistep-orbits", title="Multistep methods on orbits: resonances and spiralling",
    intro=("Second-order multistep tables scanned over the step size on Kepler orbits. Symmetric "
           "tables keep the energy error bounded except at resonant step sizes, where two "
           "parasitic roots e^(±iθ) couple through a harmonic m ω of the force along the orbit "
           "(θ_i ± θ_j = m h ω mod 2π; Quinlan 1999; Hairer-Lubich-Wanner ch. XV); the others "
           "(Störmer-Cowell with k > 2) spiral: their principal root's modulus differs from 1, "
           "and the energy drifts at a rate predicted from the coefficients."),
    build=multistep_orbits,
)
