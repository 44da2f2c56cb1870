"""A user's experiment from outside the package: right-hand-side evaluations per step.

One folder, laid out as a built-in experiment's: this module measures and judges, `section.py`
presents (over the presentation kit `harness.kit`), and the class names its section. Registered
through the entry-point group `harness.experiments` by an installed distribution
(tests/test_registry_entry_points.py builds one), it appears in `harness list experiments`, runs
with `harness run evals-per-step` and gets its own section in the report, after the built-ins'.

Claim checked: a fixed-step stepper's declared cost `info.evals_per_step` (evaluations of the
right-hand side or the force per step). Over n steps an explicit method spends n times its
stages, plus at most one start-up evaluation per stage (a first-same-as-last method such as
leapfrog evaluates the force once at the start): Hairer, Norsett & Wanner, Solving ODEs I, II.1
(stages of an explicit Runge-Kutta method) and Hairer, Lubich & Wanner, Geometric Numerical
Integration, I.1.4 (the Stormer-Verlet scheme's one force evaluation per step).
"""

import pandas as pd

from harness.experiments.base import Cell, Experiment, Skip
from harness.registry import get_problem, get_stepper

from .section import SECTION

__all__ = ["EvalsPerStep", "SECTION"]


class EvalsPerStep(Experiment):
    """Evaluations counted over `n_steps` steps against the stepper's declared cost per step."""

    description = "Right-hand-side evaluations per step against the stepper's declared cost."
    default_config = {"n_steps": 100, "h": 0.01}
    quick_config = {"n_steps": 20}

    def cells(self, steppers, problems, config):
        cells, skips = [], []
        for s in steppers:
            info = get_stepper(s).info
            for p in problems:
                if info.adaptive or not info.explicit:
                    skips.append(Skip(self.name, s, p, "only explicit fixed-step steppers have a "
                                                       "fixed count of evaluations per step"))
                else:
                    cells.append(Cell(self.name, s, p))
        return cells, skips

    def run_cell(self, cell, config):
        stepper, problem = get_stepper(cell.stepper), get_problem(cell.problem)
        n = int(config["n_steps"])
        tr = stepper.integrate(problem, h=float(config["h"]), n_steps=n)
        evals = int(tr.evals.get("rhs", 0) + tr.evals.get("accel", 0))
        return pd.DataFrame({"n_steps": [n], "evals": [evals],
                             "declared": [float(stepper.info.evals_per_step)]})

    def summarize(self, rows, config):
        out = rows[["stepper", "problem", "n_steps", "evals", "declared"]].copy()
        low, high = out["declared"] * out["n_steps"], out["declared"] * (out["n_steps"] + 1)
        out["passed"] = (out["evals"] >= low) & (out["evals"] <= high)
        out["verdict"] = out["passed"].map({True: "as declared", False: "not as declared"})
        return out.reset_index(drop=True)
