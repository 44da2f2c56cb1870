"""`--test-sets`: one option names every problem of the published test sets for the grid
commands, and `harness report --test-sets` runs the work-precision experiment alone (the test
sets' own report: error at the end point against work)."""

from __future__ import annotations

import pytest

from harness.cli import build_parser
from harness.cli.commands import _problem_names
from harness.errors import InputError
from harness.registry import problems

TEST_SETS = [p.name for p in problems.all(variants=True) if "test-set" in p.tags]


@pytest.mark.parametrize("command", ["gate", "report", "run work-precision"])
def test_test_sets_option_names_every_test_set_problem(command):
    args = build_parser().parse_args([*command.split(), "--test-sets"])
    assert _problem_names(args) == TEST_SETS and len(TEST_SETS) == 32
    args = build_parser().parse_args([*command.split(), "--test-sets", "--problem", "harmonic"])
    assert _problem_names(args) == ["harmonic", *TEST_SETS]
    args = build_parser().parse_args(command.split())
    assert not set(_problem_names(args)) & set(TEST_SETS)  # on request only


def test_report_refuses_an_unknown_experiment_subset():
    from harness.report import build_report

    with pytest.raises(InputError, match="`experiments` must name some of"):
        build_report(steppers=["rk4"], problems=["harmonic"], experiments=["no-such"])


def _rows(errors, messages, evals, t_end=1.0):
    import pandas as pd

    return pd.DataFrame({"error": errors, "message": messages, "rhs_evals": evals,
                         "t_end": [t_end] * len(errors)})


def test_every_cell_has_points_or_a_derived_reason():
    """The test-set section's cell table: an explicit method on a problem stiff for it is not
    measurable by its stability limit (interval / stiffness, from coefficients and the problem's
    facts), an implicit one whose every point failed in Newton by that, a library by its own
    message; a cell with a finite error has points."""
    import math

    import heyoka as hy

    from harness.problem import Problem
    from harness.report.test_sets import cell_status

    y = hy.make_vars("y")
    stiff = Problem("toy-stiff-decay", variables=[y], rhs=[-1e4 * (y - 1.0)], y0=[0.0],
                    t_span=(0.0, 1.0), reference="y' = -1e4 (y - 1)")
    inf = math.inf
    rec = cell_status(_rows([inf, inf], ["", ""], [400, 800]), stiff, "rk4")
    assert rec["status"] == "not measurable" and rec["reason"].startswith("stability limit")
    assert "3.59e+03 steps" in rec["reason"]  # 1 x 1e4 / 2.785
    rec = cell_status(_rows([math.nan], ["stepper 'bdf2': Newton iteration did not converge"], [9]),
                      stiff, "bdf2")
    assert rec["status"] == "not measurable" and rec["reason"].startswith("Newton failure")
    rec = cell_status(_rows([math.nan], ["scipy Radau failed: Required step size"], [9]), stiff,
                      "scipy-radau")
    assert rec["reason"].startswith("solver or run: scipy Radau failed")
    rec = cell_status(_rows([1e-6, inf], ["", ""], [400, 800]), stiff, "rk4")
    assert rec["status"] == "points" and rec["points"] == 1


def test_the_leading_term_of_a_stiff_problem_is_not_integrated_by_explicit_taylor():
    """The gate's predicted error constant integrates the variational equation with explicit
    Taylor; on a problem stiff over its horizon (here -1e6 over 1: ~1e5 steps) it says why not,
    at once, instead of running for minutes (the stiff Bari problems in the gate)."""
    import heyoka as hy

    from harness.prediction import propagated_tree_terms
    from harness.problem import Problem

    y = hy.make_vars("y")
    stiff = Problem("toy-stiff-horizon", variables=[y], rhs=[-1e6 * (y - hy.cos(hy.time))],
                    y0=[1.0], t_span=(0.0, 1.0), convergence_t_end=1.0,
                    reference="y' = -1e6 (y - cos t)")
    out = propagated_tree_terms(stiff, 3)
    assert "stiff for the explicit Taylor" in out["why"] and "trees" not in out
