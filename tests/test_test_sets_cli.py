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
