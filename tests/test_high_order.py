"""High orders: fits that hold at any order, the coefficients' own precision, published tableaus
of orders 5-12 (tests/plugins/published_rk.py) and generated populations of known order 4-12.

Every record of the published plugin must have the order its source claims, from its
coefficients; a few are measured through the convergence experiment (the real exam: each must
pass or be not measurable with its reason, never `converged` at a wrong order).
"""

from __future__ import annotations

import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from harness import tolerances as tol
from harness.coefficients import ButcherTableau
from harness.methods import method_from_record
from harness.order_fit import classify_points
from harness.theory.defects import condition_defects

sys.path.insert(0, str(Path(__file__).parent / "plugins"))
import published_rk  # noqa: E402

RECORDS = {r["name"]: r for r in published_rk.METHODS}


# -- exact input ---------------------------------------------------------------------------------------
def test_rational_strings_are_exact_coefficients_and_carry_to_the_embedded_weights():
    pair = method_from_record({"name": "bs3", "A": [[0, 0, 0, 0], ["1/2", 0, 0, 0], [0, "3/4", 0, 0],
                                                    ["2/9", "1/3", "4/9", 0]],
                               "b": ["2/9", "1/3", "4/9", 0], "b_hat": ["7/24", "1/4", "1/3", "1/8"],
                               "claimed_order": 3, "claimed_embedded_order": 2,
                               "reference": "Bogacki & Shampine, Appl. Math. Lett. 2 (1989) 321"})
    tableau = pair.coefficients
    assert tableau.exact[0][3][2] == Fraction(4, 9) and tableau.A[1, 0] == 0.5
    embedded = pair.steppers()[1].coefficients
    assert embedded.exact is not None and embedded.exact[1] == (Fraction(7, 24), Fraction(1, 4),
                                                                Fraction(1, 3), Fraction(1, 8))
    assert embedded.order() == 2 and tableau.order() == 3


def test_a_malformed_rational_string_is_one_clear_error():
    from harness.errors import CoefficientError

    with pytest.raises(CoefficientError, match=r"`x.b` must hold real numbers"):
        ButcherTableau("x", [[0, 0], ["1/2", 0]], ["1/0", "1"])


# -- the published tableaus ------------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(RECORDS))
def test_published_tableaus_have_their_claimed_order_from_their_coefficients(name):
    record = RECORDS[name]
    method = method_from_record(record)
    c = method.coefficients
    assert c.exact is not None, "every published record is given exactly (rationals or decimals)"
    assert c.order() == record["claimed_order"]
    if "claimed_embedded_order" in record:
        assert c.embedded_order() == record["claimed_embedded_order"]
        assert c.embedded().exact is not None


def test_defects_in_the_order_conditions_measure_the_records_digits():
    dp5 = method_from_record(RECORDS["dormand-prince-5"]).coefficients  # exact rationals
    pd8 = method_from_record(RECORDS["prince-dormand-8"]).coefficients  # ~18-digit rational approximations
    verner = method_from_record(RECORDS["verner-8-efficient"]).coefficients  # 40 digits
    assert max(d for d, _ in condition_defects(dp5, 5)) < 1e-90
    assert 1e-19 < max(d for d, _ in condition_defects(pd8, 8)) < 1e-15
    assert max(d for d, _ in condition_defects(verner, 8)) < 1e-34
    assert max(d for d, _ in condition_defects(pd8, 7, "b_hat")) > 1e-19  # embedded weights too


def test_large_coefficients_lose_their_order_conditions_to_float64_rounding_not_exactly():
    from harness.high_order import extrapolation_tableau

    A, b = extrapolation_tableau(11, "forward-euler")
    tableau = ButcherTableau("e11", A, b)
    assert float(np.abs(tableau.b).sum()) > 1e4
    as_run = max(d for d, _ in condition_defects(tableau, 11, as_run_in_float64=True))
    exact = max(d for d, _ in condition_defects(tableau, 11))
    assert as_run > 1e3 * tol.EPS and exact < 1e-80


# -- the fit at any order ---------------------------------------------------------------------------------
def _series(slopes, e0=1e-3):
    h = 0.5 ** np.arange(len(slopes) + 1)
    e = e0 * np.exp(np.concatenate([[0.0], np.cumsum(-np.array(slopes) * np.log(2))]))
    return h, e


def _classify(h, e, floor=None):
    n = h.size
    return classify_points(h, e, np.full(n, 1e-40), np.full(n, 1e-40), None, floor)


def test_a_steady_slope_that_is_no_integer_is_not_an_asymptotic_window():
    h, e = _series([8.5] * 7)  # steady, but a mixture of error terms: no order is 8.5
    assert set(_classify(h, e)) == {"pre-asymptotic"}
    h, e = _series([8.0] * 7)
    assert (_classify(h, e) == "").all()
    h, e = _series([9.0, 8.8, 8.6, 8.4, 8.2, 8.05, 8.02, 8.0, 8.0])  # settles: the tail is kept
    reasons = _classify(h, e)
    assert reasons[-1] == "" and reasons[0] == "pre-asymptotic"


def test_points_at_the_coefficients_floor_are_excluded_with_that_reason():
    h, e = _series([8.0] * 5 + [0.02] * 4, e0=1e-6)
    floor = np.full(h.size, 2e-18)
    reasons = _classify(h, np.maximum(e, 1.5e-17), floor)
    assert list(reasons[-4:]) == ["coefficients"] * 4
    assert (reasons[:5] == "").all()


def test_a_slope_above_the_coefficients_order_bound_is_marked_pre_asymptotic():
    from harness.coefficient_floors import mark_above_order

    h, e = _series([9.0] * 6)
    reasons = np.array([""] * h.size, dtype=object)
    why = mark_above_order(h, e, reasons, 8)
    assert "above the order bound 8" in why and set(reasons) == {"pre-asymptotic"}
    reasons = np.array([""] * h.size, dtype=object)
    assert mark_above_order(h, e, reasons, 9) == "" and set(reasons) == {""}
    assert tol.ABOVE_ORDER_TOL <= tol.GATE_ORDER_TOL


@pytest.mark.parametrize("claimed, extra, adaptive, bound", [
    (8, {}, False, 8),                      # a black box's claimed order bounds its slope
    (3, {"linear_order": 4}, False, 4),     # a declared linear order above it raises the bound
    (None, {}, False, None),                # nothing declared: no bound
    (5, {}, True, None),                    # adaptive: judged by its tolerance sweep, not a slope
])
def test_a_black_box_is_bounded_by_its_declared_claims(claimed, extra, adaptive, bound):
    from types import SimpleNamespace

    from harness.coefficient_floors import order_bound

    box = SimpleNamespace(info=SimpleNamespace(claimed_order=claimed, extra=extra, adaptive=adaptive))
    assert order_bound(box) == bound


# -- published methods through the convergence experiment (cheap cells only) -------------------------------
@pytest.mark.parametrize("name, problem", [
    ("dormand-prince-5", "harmonic"),
    ("tsitouras-5@embedded", "harmonic"),
    ("dop853@embedded", "harmonic"),  # DOP853's fifth-order estimator
    ("prince-dormand-8", "harmonic"),
])
def test_published_methods_pass_or_are_not_measurable_with_their_reason(name, problem, registered):
    from harness.experiments.base import Cell
    from harness.experiments.convergence import ConvergenceExperiment
    from harness.facts import method_facts, problem_facts
    from harness.registry import get_problem
    from harness.rules import convergence_expectation, judge_convergence

    base = name.split("@")[0]
    steppers = method_from_record(RECORDS[base]).steppers()
    stepper = next(s for s in steppers if s.info.name == name)
    registered(stepper)
    exp = ConvergenceExperiment()
    config = exp.config({"ensemble": 1, "local": False})
    summary = exp.summarize(exp.run_cell(Cell("convergence", name, problem), config), config).iloc[0]
    outcome, why = judge_convergence(summary.to_dict(), convergence_expectation(
        method_facts(stepper), problem_facts(get_problem(problem))))
    assert outcome in ("pass", "not-measurable"), (why, summary.to_dict())
    if outcome == "not-measurable":
        assert summary.verdict == "insufficient-range" and summary.message, summary.to_dict()
    if name == "prince-dormand-8":  # an 18-digit record: its own floor, never a wrong order
        assert summary.verdict != "converged" or abs(summary.measured_order - 8) <= tol.GATE_ORDER_TOL


# -- judging the judge at high order ----------------------------------------------------------------------
def test_high_order_population_has_no_false_alarm_and_no_miss():
    """`harness population --high-order` at a CI size (orders 4-6: one correct member of each
    family and its three mutants); the larger run at orders up to 12 is reported in the notes."""
    from harness import results
    from harness.cli import main

    assert main(["population", "--high-order", "--size", "1", "--seed", "5", "--max-order", "6"]) == 0
    rates = results.load("latest", "gate-population", table="summary")
    overall = rates[rates.family == "all"].iloc[0]
    assert overall.correct_methods == 3 and overall.mutants == 9
    assert overall.gate_false_alarms == 0 and overall.gate_misses == 0
    assert overall.measurement_false_alarms == 0 and overall.measurement_misses == 0
    rows = results.load("latest", "gate-population")
    assert set(rows.kind) == {"correct", "perturbed", "subtle", "overclaimed"}


def test_high_order_members_have_the_order_they_are_built_for():
    from harness.high_order import extrapolation_tableau
    from harness.populations import HIGH_FAMILIES, generate

    members = generate(1, seed=2, families=HIGH_FAMILIES, max_order=7)
    for m in members:
        order = m.stepper.coefficients.order()
        if m.kind in ("correct", "overclaimed"):
            assert order == (m.stepper.info.claimed_order - (m.kind == "overclaimed")), m.stepper.info.name
        else:
            assert order < m.stepper.info.claimed_order, m.stepper.info.name
    A, b = extrapolation_tableau(4, "forward-euler", [1, 2, 3, 5])
    assert ButcherTableau("e4", A, b).order() == 4
    with pytest.raises(ValueError, match="`steps` must be 3 increasing"):
        extrapolation_tableau(3, "gragg-midpoint", [2, 3, 4])


def test_population_refuses_an_order_outside_the_families(capsys):
    from harness.cli import main

    assert main(["population", "--high-order", "--max-order", "13"]) == 2
    assert "`--max-order` must lie in [4, 12]" in capsys.readouterr().err
