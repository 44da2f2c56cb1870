"""The gate can fail: broken methods are caught, by their coefficients or by measurement."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from harness.coefficients import ButcherTableau
from harness.experiments.base import Cell
from harness.experiments.convergence import ConvergenceExperiment, classify_points, fit_order
from harness.facts import method_facts, problem_facts
from harness.gate import gate_table
from harness.registry import get_problem, steppers
from harness.rules import convergence_expectation, judge_convergence
from implementations.runge_kutta import ExplicitRungeKutta

# A nonlinear, time-dependent problem: linear test problems cannot see every order condition.
PROBLEM = "forced-duffing"


def _rk4_variant(name: str, A=None, b=None, claimed: int = 4, cls=ExplicitRungeKutta):
    rk4 = steppers.get("rk4").coefficients
    tab = ButcherTableau(name, rk4.A.tolist() if A is None else A, rk4.b.tolist() if b is None else b)
    return cls(tab, claimed_order=claimed, reference="deliberately broken test method")


class _ReuseLastStage:
    """A view of `Dynamics` whose k-th evaluation in a step silently returns the previous one."""

    def __init__(self, dyn, skip: int):
        self._dyn, self._skip, self._calls, self._last = dyn, skip, 0, None

    def __getattr__(self, name):
        return getattr(self._dyn, name)

    def f(self, t, y, out=None):
        self._calls += 1
        if self._calls == self._skip and self._last is not None:
            if out is None:
                return self._last.copy()
            out[...] = self._last
            return out
        result = self._dyn.f(t, y, out=out)
        self._last = np.array(result, copy=True)
        return result


class DropsLastStage(ExplicitRungeKutta):
    """Claims the rk4 tableau but silently reuses the third stage instead of evaluating the
    fourth: the coefficients are right, only a measurement can catch it."""

    def _step(self, dyn, c):
        super()._step(_ReuseLastStage(dyn, self.coefficients.stages), c)


def _measure(name: str, problem: str = PROBLEM) -> pd.DataFrame:
    exp = ConvergenceExperiment()
    config = exp.config({"local": False})
    rows = exp.run_cell(Cell("convergence", name, problem), config)
    return exp.summarize(rows, config)


def _perturbed_a21():
    A = steppers.get("rk4").coefficients.A.tolist()
    A[2][1] += 1e-2  # nodes follow the row sums, so the tableau still passes its self-checks
    return A


MUTANTS = {
    # name: (builder, caught by the coefficient check?)
    "mutant-perturbed-coefficient": (lambda n: _rk4_variant(n, A=_perturbed_a21()), True),
    "mutant-wrong-claim": (
        lambda n: ExplicitRungeKutta(
            ButcherTableau(n, steppers.get("heun").coefficients.A.tolist(),
                           steppers.get("heun").coefficients.b.tolist()),
            claimed_order=3, reference="Heun's method relabelled as third order"),
        True,
    ),
    "mutant-dropped-stage": (lambda n: _rk4_variant(n, cls=DropsLastStage), False),
}


@pytest.mark.parametrize("name", list(MUTANTS))
def test_gate_fails_on_broken_method(name, registered):
    build, by_coefficients = MUTANTS[name]
    registered(build(name))
    summary = _measure(name)
    table = gate_table(summary)
    assert not table["passed"].any(), table.to_dict("records")
    record = summary.iloc[0].to_dict()
    # The measurement alone (the method judged as a black box from its claim) must catch it too.
    stepper = steppers.get(name)
    claim = stepper.info.claimed_order
    black_box = replace(method_facts(stepper), source="claims", order=claim, linear_order=claim)
    expectation = convergence_expectation(black_box, problem_facts(get_problem(PROBLEM)))
    outcome, why = judge_convergence(record, expectation)
    assert outcome == "fail", f"the measured order alone let {name} through: {record}"
    assert "measured order" in why or "expected" in why
    cell = table[table.problem == PROBLEM].iloc[0]
    if by_coefficients:
        assert "coefficients give order" in cell["reason"]
    else:
        assert cell["coefficient_order"] == 4


def test_unbroken_rk4_passes_on_the_same_problem():
    summary = _measure("rk4")
    table = gate_table(summary)
    assert table["passed"].all(), table.to_dict("records")
    assert abs(summary.iloc[0]["measured_order"] - 4) <= 0.2


def test_fit_order_recovers_a_known_slope_and_interval():
    h = 0.1 * 0.5 ** np.arange(6)
    e = 3.0 * h**2.5
    f = fit_order(h, e)
    assert f["order"] == pytest.approx(2.5, abs=1e-12)
    assert f["residual"] < 1e-12


def test_classification_excludes_floor_reference_and_pre_asymptotic_points():
    h = 0.5 ** np.arange(12)
    e = 0.5 * h**2
    e[:2] = [0.4, 0.2]  # pre-asymptotic start (slope far from 2)
    e[-2:] = 1e-15  # roundoff floor
    ref = np.full(12, 1e-18)
    ref[-3] = 1e-7  # a point whose reference is not clearly more accurate
    rounding = np.full(12, 1e-16)
    reasons = classify_points(h, e, ref, rounding, start_error=1e-2)
    assert list(reasons[:2]) == ["pre-asymptotic", "pre-asymptotic"]
    assert list(reasons[-2:]) == ["roundoff", "roundoff"]
    assert reasons[-3] == "reference"
    kept = np.flatnonzero(reasons == "")
    assert len(kept) >= 3
    assert fit_order(h[kept], e[kept])["order"] == pytest.approx(2.0, abs=1e-9)


def _converged_record(stepper: str, problem: str, order: float, C: float) -> dict:
    h = np.array([1e-2, 5e-3])
    return {"stepper": stepper, "problem": problem, "claimed_order": order,
            "measured_order": order, "order_ci_low": order - 0.01, "order_ci_high": order + 0.01,
            "fit_points": 2, "fit_h_min": h[1], "fit_h_max": h[0], "fit_error_min": C * h[1]**order,
            "fit_error_max": C * h[0]**order, "verdict": "converged", "message": ""}


def test_every_gate_row_has_a_predicted_error_constant_or_says_why_not():
    """Swept over the registry on the oscillator: Runge-Kutta tableaus with an h^p law expected
    get the predicted leading constant beside the measured one (rk4 on x'' = -x: R(z) - e^z =
    -z^5/120 + ... gives a phase error of Euclidean size T h^4/120, so the largest component is
    between that over sqrt(2) and that); every other row names the reason."""
    problem = get_problem("harmonic")
    rows = []
    for name in steppers.names():
        s = steppers.get(name)
        if s.compatible(problem) and s.info.claimed_order:
            rows.append(_converged_record(name, "harmonic", float(s.info.claimed_order), 1.0))
    table = gate_table(pd.DataFrame(rows)).set_index("stepper")
    assert len(table) >= 20
    for name, r in table.iterrows():
        predicted, note = r.predicted_coefficient, str(r.prediction_note or "")
        assert np.isfinite(predicted) != bool(note), (name, predicted, note)
        coeffs = getattr(steppers.get(name), "coefficients", None)
        if not isinstance(coeffs, ButcherTableau):
            assert "Runge-Kutta tableau" in note, (name, note)
        if r.expected == "converged" and pd.notna(r.expected_order):
            assert r.measured_coefficient == pytest.approx(1.0), name
    T = problem.convergence_t_end - problem.t0
    assert T / 120 / np.sqrt(2) <= table.loc["rk4", "predicted_coefficient"] <= T / 120 * (1 + 1e-6)
    assert np.isfinite(table.loc["heun", "predicted_coefficient"])
