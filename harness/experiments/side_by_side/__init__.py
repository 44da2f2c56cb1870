"""N-body integrators side by side: every stepper on each gravitational N-body problem at one step
size and one final time, beside what the other experiments measured for it.

A cell (stepper x N-body problem, i.e. a problem with `structure=NBody(...)`) integrates the
problem's own start (one member) over its convergence horizon T with the problem's long-run step
h (`Problem.time_scale.h`, the same for every fixed-step stepper; an adaptive stepper runs at its
default tolerance in one output step to T) and records the relative error at T against the
certified reference, the force (or right-hand-side) evaluations and the wall time (a stepper
that stops on the way, e.g. a Newton iteration that fails at this step, is recorded with the
reason and an infinite error): one
work-precision point per stepper, on the same problem and final time for all of them. Nothing
here is judged: the report's section puts the point beside each stepper's claimed and measured
order (the CI gate), its energy drift class (energy experiment) and its round-trip verdict
(reversibility experiment), so integrators from another library and the built-ins can be read
row by row. Steppers that need the N-body structure (Kepler-drift maps) and those that only need
the acceleration meet here.
Reference: Hairer, Lubich & Wanner, Geometric Numerical Integration (2006), I.2.4 and VIII
(N-body problems, long-time behaviour); W. H. Press et al., Numerical Recipes (2007), 17.0
(comparing integrators by work at equal accuracy).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from harness.experiments.base import Cell, Experiment, register_experiment
from harness.experiments.common import problem_cells
from harness.experiments.side_by_side.section import SECTION
from harness.ground_truth import reference
from harness.problem import NBody
from harness.registry import get_problem, get_stepper
from harness.stepper import AdaptiveStepper, StepFailure

__all__ = ["SideBySideExperiment", "SUMMARY_COLUMNS", "nbody_reason", "SECTION"]

SUMMARY_COLUMNS = ["stepper", "problem", "implementation", "h", "t_end", "steps", "tol", "error",
                   "evals", "evals_unit", "wall_s", "message"]


def nbody_reason(problem) -> str | None:
    """Why `problem` is not compared here (None: it is a gravitational N-body problem).

    Parameters
    ----------
    problem : Problem, read for its `structure`.

    Returns
    -------
    str or None
    """
    if isinstance(getattr(problem, "structure", None), NBody):
        return None
    return "not a gravitational N-body problem (no `structure=NBody(...)`)"


class SideBySideExperiment(Experiment):
    description = ("N-body problems: every stepper at the problem's step to the same final time "
                   "(error, evaluations, wall time), beside its orders, drift and reversibility.")
    default_config: Mapping[str, Any] = {"seed": 0}
    quick_config: Mapping[str, Any] = {}

    def cells(self, steppers, problems, config):
        """One cell per stepper on each gravitational N-body problem.

        Parameters
        ----------
        steppers, problems : sequence of str, the names; only N-body problems apply.
        config : mapping, no setting is read.

        Returns
        -------
        (list of Cell, list of Skip)
        """
        return problem_cells(self.name, steppers, problems, nbody_reason)

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """One work-precision point: the relative error at T, the evaluations and the wall time.

        Parameters
        ----------
        cell : Cell, a stepper on an N-body problem.
        config : mapping, not read (T and h are the problem's).

        Returns
        -------
        DataFrame: one row.
        """
        stepper = get_stepper(cell.stepper)
        problem = get_problem(cell.problem)
        T = float(problem.convergence_t_end)
        h_problem = float(problem.time_scale.h)
        adaptive = isinstance(stepper, AdaptiveStepper)
        n = 1 if adaptive else max(1, math.ceil((T - problem.t0) / h_problem))
        h = (T - problem.t0) / n
        y0 = problem.y0.reshape(-1, 1)
        exact = reference(problem, np.array([T]), y0).y[-1][:, 0]
        started = time.perf_counter()
        try:
            tr = stepper.integrate(problem, h=h, n_steps=n, y0=y0)
        except StepFailure as exc:  # a measurement too: this stepper cannot reach T at this step
            rec = {"stepper": cell.stepper, "problem": cell.problem,
                   "implementation": stepper.info.implementation, "h": h, "t_end": T, "steps": n,
                   "tol": math.nan, "error": math.inf, "evals": math.nan, "evals_unit": "",
                   "wall_s": time.perf_counter() - started, "message": f"stopped: {exc}"}
            return pd.DataFrame([rec], columns=SUMMARY_COLUMNS)
        wall = time.perf_counter() - started
        final = tr.final[:, 0]
        with np.errstate(all="ignore"):
            error = float(np.max(np.abs(final - exact)) / max(np.max(np.abs(exact)), 1e-300))
        evals = dict(tr.evals)
        unit = "accel" if evals.get("accel") else "rhs"
        rec = {
            "stepper": cell.stepper, "problem": cell.problem,
            "implementation": stepper.info.implementation, "h": h, "t_end": T, "steps": n,
            "tol": getattr(stepper, "tol", math.nan) if adaptive else math.nan,
            "error": error if math.isfinite(error) else math.inf,
            "evals": float(evals.get(unit, 0.0)),
            "evals_unit": str(stepper.info.extra.get("evals_unit", unit)), "wall_s": wall,
            "message": "" if math.isfinite(error) else "non-finite state at T",
        }
        return pd.DataFrame([rec], columns=SUMMARY_COLUMNS)

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """The rows as they are, in SUMMARY_COLUMNS (nothing is judged).

        Parameters
        ----------
        rows : DataFrame, every cell's one row.
        config : mapping, not read.

        Returns
        -------
        DataFrame
        """
        if rows.empty:
            return pd.DataFrame(columns=SUMMARY_COLUMNS)
        return rows.reindex(columns=SUMMARY_COLUMNS).reset_index(drop=True)


register_experiment(SideBySideExperiment())
