"""The gate's rule for maps with an error law in the perturbation, eps^a h^b (harness.perturbation_law):
the expected slope follows from the law and the problem's masses, never from a name."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from harness.perturbation_law import (
    ErrorLaw,
    error_law,
    judge_split_map,
    perturbation_expectation,
    perturbation_size,
)
from harness.registry import get_problem

SABA4 = ErrorLaw(((1, 8), (2, 2)), True)  # Laskar & Robutel 2001: eps h^8 + eps^2 h^2


def _stepper(law, claimed=2, exact=True):
    """Any stepper with a declared law: a bare object, no name the rule could read."""
    return SimpleNamespace(info=SimpleNamespace(
        claimed_order=claimed, extra={"perturbation_error": law, "kepler_flow_exact": exact}))


def _record(verdict="converged", order=2.0, h=(0.01, 0.1)):
    return {"verdict": verdict, "measured_order": order, "fit_h_min": h[0], "fit_h_max": h[1],
            "message": ""}


def test_perturbation_size_from_the_masses():
    assert perturbation_size(get_problem("kepler-elliptic")) == 0.0  # a test particle
    assert perturbation_size(get_problem("outer-solar-system")) == pytest.approx(9.5478e-4, rel=1e-3)
    assert perturbation_size(get_problem("planets-pair")) == pytest.approx(1e-2)
    assert perturbation_size(get_problem("harmonic")) is None


def test_no_perturbation_and_an_exact_kepler_drift_means_exact():
    e = perturbation_expectation(SABA4, 0.0, 1.0, None)
    assert e.verdict == "exact" and "Kepler flow" in e.reason


def test_one_dominant_term_sets_the_expected_order_and_the_crossover_is_printed():
    eps, tau = 1e-2, 1.0  # crossover eps h^8 = eps^2 h^2 at h = eps^(1/6) = 0.464
    small = perturbation_expectation(SABA4, eps, tau, (0.01, 0.1))
    assert small.verdict == "converged" and small.order == 2.0
    assert "h* = 0.464" in small.reason
    large = perturbation_expectation(SABA4, eps, tau, (2.0, 8.0))
    assert large.order == 8.0


@pytest.mark.parametrize("measured, outcome", [(2.03, "pass"), (7.9, "pass"), (5.0, "not-measurable"),
                                               (1.0, "fail"), (9.5, "fail")])
def test_near_a_crossover_a_slope_between_the_powers_is_not_measurable(measured, outcome):
    stepper = _stepper([[1, 8], [2, 2]])
    got = judge_split_map(_record(order=measured, h=(0.1, 1.0)), stepper, get_problem("planets-pair"))
    assert got[0] == outcome, got
    if outcome != "pass":
        assert "h* = " in got[2]


def test_the_dominant_term_is_held_to_its_power():
    stepper = _stepper([[1, 2]])
    ok = judge_split_map(_record(order=2.01), stepper, get_problem("outer-solar-system"))
    bad = judge_split_map(_record(order=3.0), stepper, get_problem("outer-solar-system"))
    assert ok[0] == "pass" and ok[3] == 2.0
    assert bad[0] == "fail" and "differs from the expected 2" in bad[2]


def test_on_an_unperturbed_problem_a_map_must_be_exact():
    stepper = _stepper([[1, 2]])
    assert judge_split_map(_record("exact", math.nan), stepper, get_problem("kepler-elliptic"))[0] == "pass"
    got = judge_split_map(_record("converged", 2.0), stepper, get_problem("kepler-elliptic"))
    assert got[0] == "fail" and "expected exact" in got[2]


def test_rule_does_not_apply_without_a_law_a_structure_or_a_consistent_claim():
    assert judge_split_map(_record(), _stepper(None), get_problem("planets-pair")) is None
    assert judge_split_map(_record(), _stepper([[1, 2]]), get_problem("harmonic")) is None
    # claiming order 4 for an eps h^2 map: judged as the plain claim (and fails where 2 is measured)
    assert judge_split_map(_record(), _stepper([[1, 2]], claimed=4), get_problem("planets-pair")) is None
    assert error_law(_stepper([[1, 8], [2, 4]])) == ErrorLaw(((1, 8), (2, 4)), True)
