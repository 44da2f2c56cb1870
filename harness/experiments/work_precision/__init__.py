"""Work-precision: error at the final time against cost (evaluations and wall time).

Every stepper runs on the same problem to the same final time (the problem's
`convergence_t_end`; a test-set problem's published end point, `Problem.published`, as the test
set's own reports do) against the same certified ground truth:

- every problem applies; fixed-step steppers by a step-size sweep, and adaptive steppers by a
  tolerance sweep (`AdaptiveStepper.with_tolerance`), both the convergence experiment's own
  sweeps (`harness.experiments.convergence.step_sweep` and `tolerance_sweep`, with the local error
  sweep turned off), so the two experiments measure identical points;
- one trajectory (`ensemble` = 1): the step count differs from point to point, so the ensemble
  axis cannot batch a sweep, and one member keeps wall times comparable between NumPy steppers
  (whose cost barely depends on the ensemble size) and per-member solvers (scipy, heyoka);
- cost: `rhs_evals` counts right-hand-side plus force evaluations (one call of the ensemble
  each; for `taylor`, whose unit is the Taylor jet, its internal steps, `evals_unit` says so).
  Jacobian evaluations and linear solves of implicit methods show in the wall time only.
  `wall_s` is the sweep's own run (plus one error evaluation; the first point's includes
  compiling and loading); the timed columns (`t_min_s`, ...) come from warm repeats by the
  protocol of `harness.timing` (`harness.experiments.work_precision.timed_runs`): the experiment is
  `exclusive`, so its cells run one at a time on one worker, with no other cell beside them.
A sweep runs down to the rounding floor or until it has spent `work_budget` right-hand-side
evaluations (the convergence sweep's own rule, `convergence.step_budget`: implicit steps also pay
for their Newton solves), so cheap and dear methods get comparable ranges. `pareto_front` marks
the points no other point beats in both cost and error (`pareto_evals`, `pareto_wall` for the
sweep's wall time, `pareto_time` for the warm minimum `t_min_s`).

References: Hairer, Norsett & Wanner, *Solving Ordinary Differential Equations I*, II.10
(work-precision diagrams); E. Hairer & G. Wanner, *Solving ODEs II*, IV.10.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from harness import timing
from harness import tolerances as tol
from harness.errors import InputError
from harness.experiments.base import Cell, Experiment, get_experiment, register_experiment
from harness.experiments.common import check_config, perturbation_used, problem_cells
from harness.experiments.convergence import step_sweep, tolerance_sweep
from harness.experiments.work_precision.section import SECTION
from harness.experiments.work_precision.timed_runs import TIMING_COLUMNS, time_points
from harness.registry import get_problem, get_stepper
from harness.stepper import AdaptiveStepper

__all__ = ["WorkPrecisionExperiment", "pareto_front", "COLUMNS", "SECTION"]

COLUMNS = [
    "stepper", "problem", "kind", "h", "tol", "n_steps", "t_end", "error", "reference_error",
    "rhs_evals", "force_evals", "evals_unit", "wall_s", "claimed_order", "explicit", "adaptive",
    "ensemble_size", "perturbation", "pareto_evals", "pareto_wall", "message", "implementation",
    "rounding_level", *TIMING_COLUMNS, "pareto_time",
]


def pareto_front(df: pd.DataFrame, cost: str = "rhs_evals") -> pd.DataFrame:
    """The points of `df` that no other point of the same problem beats in both `cost` and
    `error` (finite errors only), sorted by problem and cost. Evaluation counts are compared
    only within one unit (`evals_unit`: a Taylor step is not an f evaluation).

    Parameters
    ----------
    df : DataFrame, work-precision rows (problem, error and the `cost` column).
    cost : str, optional, the cost column ('rhs_evals' default, 'wall_s', 't_min_s').

    Returns
    -------
    DataFrame: the front's rows (a copy of `df` when it is empty).
    """
    if df.empty:
        return df.copy()
    keep = np.zeros(len(df), dtype=bool)
    frame = df.reset_index(drop=True)
    groups = ["problem"] + (["evals_unit"] if cost == "rhs_evals" and "evals_unit" in frame else [])
    for _, g in frame.groupby(groups, sort=False):
        g = g[np.isfinite(g["error"].to_numpy(dtype=float)) & (g[cost] > 0)]
        g = g.sort_values([cost, "error"])
        best = np.inf
        for i, err in zip(g.index, g["error"], strict=True):
            if err < best:
                keep[i] = True
                best = err
    return frame[keep].sort_values([*groups, cost]).reset_index(drop=True)


class WorkPrecisionExperiment(Experiment):
    exclusive = True  # timed cells: the runner executes them one at a time (harness.timing)
    finite_columns = ("n_steps", "t_end", "rhs_evals", "wall_s")
    description = "Error at the final time against evaluations and wall time (step-size or tolerance sweep)."
    default_config: Mapping[str, Any] = {
        "t_end": None,  # None: the published end point of a test-set problem, else its convergence horizon
        "perturbation": None,  # None: the problem's (used when `ensemble` > 1)
        "ensemble": 1,
        "seed": 0,
        "start_error": tol.SWEEP_START_ERROR,
        "ratio": tol.SWEEP_RATIO,
        "work_budget": tol.SWEEP_WORK_BUDGET // 2,
        "n_start": 4,
        # The convergence sweep stops once an order fit has its points; a work-precision
        # diagram wants the whole range, down to the rounding floor or the work budget.
        "target_points": 1_000_000,
        "tolerances": [10.0**-k for k in range(3, 15)],
        "local": False,
        "timing_max_repeats": timing.TIMING_MAX_REPEATS,
        "timing_budget_s": timing.TIMING_POINT_BUDGET_S,
    }
    quick_config: Mapping[str, Any] = {
        "work_budget": tol.SWEEP_WORK_BUDGET // 16,
        "tolerances": [10.0**-k for k in range(3, 13, 2)],
        "timing_max_repeats": timing.TIMING_QUICK_MAX_REPEATS,
        "timing_budget_s": timing.TIMING_QUICK_POINT_BUDGET_S,
    }

    def cells(self, steppers, problems, config):
        """Every pair the stepper can run, once the settings (counts, timing budget, the list of
        tolerances in (0, 1)) pass their checks.

        Parameters
        ----------
        steppers, problems : sequence of str, the chosen names.
        config : mapping, checked here; a bad `tolerances` raises `InputError`.

        Returns
        -------
        (list of Cell, list of Skip)
        """
        check_config(config, counts=("ensemble", "work_budget", "n_start", "timing_max_repeats"),
                     positives=("timing_budget_s",), optional_positives=("t_end", "perturbation"))
        tolerances = config.get("tolerances")
        listed = not isinstance(tolerances, str | bytes) and isinstance(tolerances, Sequence)
        if not listed or not tolerances or not all(
            isinstance(t, int | float) and not isinstance(t, bool) and 0.0 < t < 1.0 for t in tolerances
        ):
            raise InputError(f"config `tolerances` must be a non-empty list of numbers in (0, 1), "
                             f"got {tolerances!r}")

        return problem_cells(self.name, steppers, problems, lambda problem: None)

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """The convergence experiment's sweep (step sizes, or tolerances for an adaptive
        stepper) without the local error, to the published end point of a test-set problem, with
        evaluation counts in one unit and each point timed by the timing protocol.

        Parameters
        ----------
        cell : Cell, one stepper on one problem.
        config : mapping, this experiment's settings over the convergence defaults.

        Returns
        -------
        DataFrame: the COLUMNS present, one row per point.
        """
        stepper = get_stepper(cell.stepper)
        problem = get_problem(cell.problem)
        # The convergence sweeps read their own settings: start from theirs, then this config.
        cfg = {**get_experiment("convergence").default_config, **config, "local": False}
        if cfg.get("t_end") is None and problem.published is not None:
            cfg["t_end"] = float(problem.t_end)  # the published end point, rounded to float64
        if isinstance(stepper, AdaptiveStepper):
            frame = tolerance_sweep(stepper, problem, cfg)
            kind = "tolerance"
        else:
            frame = step_sweep(stepper, problem, cfg)
            kind = "step-size"
        frame = frame[frame["kind"].isin(["global", "tolerance"])].copy()
        frame["kind"] = kind
        counted = frame["rhs_evals"].fillna(0) + frame["force_evals"].fillna(0)
        # A Taylor integrator evaluates no right-hand side: its work is counted in internal steps.
        jets = bool(counted.eq(0).all()) and kind == "tolerance"
        frame["evals_unit"] = "taylor-step" if jets else "f-or-force"
        frame["rhs_evals"] = np.where(jets, frame["n_steps"], counted).astype(np.int64)
        frame["claimed_order"] = float(stepper.info.claimed_order or np.nan)
        frame["explicit"] = bool(stepper.info.explicit)
        frame["adaptive"] = isinstance(stepper, AdaptiveStepper)
        frame["perturbation"] = perturbation_used(problem, cfg) if int(cfg["ensemble"]) > 1 else 0.0
        if "message" not in frame:
            frame["message"] = ""
        frame["message"] = frame["message"].fillna("").astype(str)
        frame["implementation"] = (frame["implementation"].astype(str) if "implementation" in frame
                                   else stepper.info.implementation)
        frame = time_points(stepper, problem, frame.reset_index(drop=True), cfg)
        keep = [c for c in COLUMNS if c in frame.columns]
        return frame[keep].reset_index(drop=True)

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """All rows, each marked when it is on the Pareto front of evaluations, of wall time
        or of warm time.

        Parameters
        ----------
        rows : DataFrame, every cell's points.
        config : mapping, not used.

        Returns
        -------
        DataFrame: COLUMNS with `pareto_evals`, `pareto_wall`, `pareto_time`.
        """
        if rows.empty:
            return pd.DataFrame(columns=COLUMNS)
        out = rows.reset_index(drop=True).copy()
        out["pareto_evals"] = False
        out["pareto_wall"] = False
        out["pareto_time"] = False
        key = ["stepper", "problem", "kind", "h", "tol"]
        for cost, column in (("rhs_evals", "pareto_evals"), ("wall_s", "pareto_wall"),
                             ("t_min_s", "pareto_time")):
            if cost not in out:
                continue
            front = pareto_front(out, cost)
            marks = set(map(tuple, front[key].astype(str).to_numpy()))
            out[column] = [tuple(r) in marks for r in out[key].astype(str).to_numpy()]
        for c in COLUMNS:
            if c not in out:
                out[c] = np.nan
        return out[COLUMNS]


register_experiment(WorkPrecisionExperiment())
