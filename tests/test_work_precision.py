"""Work-precision: the tidy cost/error table for fixed-step and adaptive steppers, the Pareto
front, and the reuse of the convergence experiment's sweeps.

Expectations: error falls as work grows; at equal work a higher-order method is more accurate
in its asymptotic range (Hairer, Norsett & Wanner, Solving ODEs I, II.10).
"""

from __future__ import annotations

import json
from functools import partial

import helpers
import numpy as np
import pandas as pd
import pytest

from harness.cli import main
from harness.experiments import convergence, get_experiment
from harness.experiments.work_precision import COLUMNS, pareto_front
from harness.registry import problems, steppers
from harness.stepper import AdaptiveStepper

EXP = get_experiment("work-precision")
STEPPERS = steppers.names()
ADAPTIVE = [s for s in STEPPERS if isinstance(steppers.get(s), AdaptiveStepper)]
FIXED = [s for s in ("euler", "rk4", "velocity-verlet", "implicit-midpoint") if s in steppers]

run = partial(helpers.run_through_runner, EXP)


@pytest.fixture(scope="module")
def table():
    return run(FIXED + ADAPTIVE[:2], ["kepler-elliptic"])


# -- the pareto front on a table of known shape ---------------------------------------------------
def test_pareto_front_keeps_exactly_the_undominated_points():
    df = pd.DataFrame({
        "stepper": ["a", "a", "b", "b", "c", "c"],
        "problem": ["p"] * 6,
        "rhs_evals": [10, 100, 20, 200, 10, 1000],
        "wall_s": [1.0, 2.0, 0.5, 0.6, 3.0, 4.0],
        "error": [1e-2, 1e-4, 1e-3, 1e-8, 5e-3, np.inf],
    })
    front = pareto_front(df)
    assert list(zip(front.stepper, front.rhs_evals, strict=True)) == [
        ("c", 10), ("b", 20), ("a", 100), ("b", 200)]
    by_wall = pareto_front(df, "wall_s")
    assert list(by_wall.wall_s) == [0.5, 0.6]


def test_pareto_front_is_per_problem_and_per_evaluation_unit():
    df = pd.DataFrame({"stepper": ["a", "b"], "problem": ["p", "q"], "rhs_evals": [10, 100],
                       "error": [1e-2, 1e-1], "wall_s": [1.0, 1.0]})
    assert len(pareto_front(df)) == 2
    df = pd.DataFrame({"stepper": ["f", "taylor"], "problem": ["p", "p"], "rhs_evals": [100, 10],
                       "evals_unit": ["f-or-force", "taylor-step"], "error": [1e-3, 1e-9],
                       "wall_s": [1.0, 0.5]})
    assert len(pareto_front(df)) == 2  # different units: neither dominates the other
    assert list(pareto_front(df, "wall_s").stepper) == ["taylor"]


# -- measured tables --------------------------------------------------------------------------------
def test_table_has_the_promised_tidy_columns(table):
    assert list(table.columns) == COLUMNS
    for field in ("stepper", "problem", "error", "rhs_evals", "wall_s", "h", "tol"):
        assert field in table.columns
    measured = table[table.message == ""]
    assert len(measured) and (measured.rhs_evals > 0).all() and (measured.wall_s > 0).all()
    # A point whose implicit solve failed (coarse steps) stays in the table, with its reason.
    failed = table[table.message != ""]
    assert failed.error.isna().all() and failed.message.str.contains("Newton|step").all()
    fixed = table[table.kind == "step-size"]
    assert fixed.h.notna().all() and fixed.tol.isna().all()
    adaptive = table[table.kind == "tolerance"]
    assert set(adaptive.stepper) == set(ADAPTIVE[:2])
    assert adaptive.tol.notna().all()
    assert sorted(set(adaptive.tol), reverse=True) == EXP.config(quick=True)["tolerances"]


def test_every_point_reaches_the_same_final_time(table):
    assert table.t_end.nunique() == 1


def test_fixed_step_cost_is_steps_times_evaluations_per_step(table):
    for name in FIXED:
        g = table[table.stepper == name]
        per_step = g.rhs_evals / g.n_steps
        declared = steppers.get(name).info.evals_per_step
        if steppers.get(name).info.explicit:  # a Newton solve's count varies per step
            assert np.allclose(per_step, declared, rtol=0.01, atol=2.0 / g.n_steps.min()), name


def test_error_falls_as_work_grows_and_rk4_beats_euler(table):
    for name in FIXED:
        g = table[(table.stepper == name) & np.isfinite(table.error)].sort_values("rhs_evals")
        assert len(g) >= 3, name
        assert g.error.iloc[-1] < 0.1 * g.error.iloc[0], name
    rk4 = table[table.stepper == "rk4"]
    euler = table[table.stepper == "euler"]
    work = float(euler.rhs_evals.max())
    assert rk4[rk4.rhs_evals <= work].error.min() < 1e-3 * euler[euler.rhs_evals <= work].error.min()


def test_pareto_marks_match_the_helper(table):
    front = pareto_front(table)
    marked = table[table.pareto_evals]
    assert set(marked.evals_unit) <= {"f-or-force", "taylor-step"}
    assert sorted(zip(marked.stepper, marked.rhs_evals, strict=True)) == sorted(
        zip(front.stepper, front.rhs_evals, strict=True))
    # At the coarsest steps even Euler may be the cheapest point; wherever the error is small,
    # higher-order methods dominate it.
    assert "euler" not in set(marked[marked.error < 0.1].stepper)


def test_timed_columns_follow_the_protocol(table):
    """Logic only (no wall-clock value is asserted): every measured point is timed warm with a
    repeat count and a stop reason, min <= median, the ratio columns are the time over the same
    cell's baseline, and the Pareto marks of time are the helper's."""
    timed = table[table.error.notna()]
    assert (timed.t_repeats >= 1).all() and set(timed.t_stop) <= {"spread", "max-repeats", "budget"}
    assert (timed.t_min_s <= timed.t_median_s).all()
    assert (timed.t_repeats <= EXP.config(quick=True)["timing_max_repeats"]).all()
    with_base = timed[timed.baseline_step_s.notna()]
    np.testing.assert_allclose(with_base.baseline_units, with_base.t_min_s / with_base.baseline_step_s)
    assert table.groupby("stepper").first_call_s.nunique().max() == 1  # one per cell
    front = pareto_front(table, "t_min_s")
    assert sorted(zip(table[table.pareto_time].stepper, table[table.pareto_time].t_min_s, strict=True)) \
        == sorted(zip(front.stepper, front.t_min_s, strict=True))
    # the NumPy loop timed beside the compiled loop that ran the sweep agrees with it to rounding
    twins = table[table.twin_error.notna()]
    assert set(twins.stepper) >= {"rk4", "velocity-verlet"}
    np.testing.assert_allclose(twins.twin_error, twins.error, rtol=1e-6, atol=1e-13)


def test_points_are_those_of_the_convergence_sweep():
    """The fixed-step sweep is the convergence experiment's own: same step sizes and errors."""
    from harness.registry import get_problem

    config = EXP.config(quick=True)
    ours = run(["rk4"], ["kepler-elliptic"])
    theirs = convergence._step_sweep(steppers.get("rk4"), get_problem("kepler-elliptic"),
                                     {**convergence.ConvergenceExperiment.default_config, **config,
                                      "local": False})
    theirs = theirs[theirs.kind == "global"]
    assert np.allclose(np.sort(ours.h.values), np.sort(theirs.h.values))
    assert np.allclose(np.sort(ours.error.values), np.sort(theirs.error.values), rtol=1e-12)


# -- the registry, settings and the command line ----------------------------------------------------
@pytest.mark.parametrize("name", STEPPERS)
def test_every_stepper_gets_a_cell_or_a_reason_on_every_problem(name):
    _, skips = helpers.cells_or_reasons(EXP, name)
    stepper = steppers.get(name)
    # Every problem applies: a pair is skipped only when the stepper cannot run the problem.
    for s in skips:
        assert not stepper.compatible(problems.get(s.problem)), s



def test_cli_json_records(capsys):
    code = main(["run", "work-precision", "--quick", "--stepper", "leapfrog", "--problem",
                 "kepler-elliptic", "--jobs", "1", "--fresh", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    records = pd.DataFrame(json.loads(out))
    assert set(records.stepper) == {"leapfrog"} and len(records) >= 5
    assert {"error", "rhs_evals", "wall_s"} <= set(records.columns)


def test_sweep_horizon_and_perturbation_overrides_reach_the_rows():
    """`t_end` and `perturbation` (the CLI's --t-end and --perturbation) set the sweep's horizon
    and the ensemble; both are recorded in every row."""
    out = run(["rk4"], ["harmonic"], t_end=3.0, perturbation=1e-6, ensemble=2)
    assert (out.t_end == 3.0).all() and (out.perturbation == 1e-6).all()
