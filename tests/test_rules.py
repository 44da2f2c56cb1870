"""Verdicts follow from facts, never from names: rules swept over the registry and populations.

- A stepper that carries a built-in's coefficients under another name gets the same facts and
  the same expectation on every problem.
- No built-in stepper's name appears in the harness's code outside the course-material claims
  the report checks by name (harness/report/claims.py).
- Problem facts derived from the symbolic definitions: free fall has a quadratic solution,
  the oscillators are linear, the stiff van der Pol problem is stiff for explicit methods.
- Method facts: linear order above the order for a published SSP method, embedded orders.
- Populations of generated methods (harness.populations): no false alarm, no miss.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from harness.coefficients import ButcherTableau
from harness.facts import method_facts, problem_facts
from harness.registry import get_problem, problems, steppers
from harness.rules import convergence_expectation

ROOT = Path(__file__).resolve().parent.parent
# The course texts make claims about named methods (the report's claims table, and the roundoff
# experiment that checks the lecture's rounding claim about original Verlet, leapfrog and
# velocity Verlet): checking those claims by name is their subject.
NAMES_ALLOWED_IN = {
    ROOT / "harness" / "report" / "claims.py",
    ROOT / "harness" / "experiments" / "roundoff" / "__init__.py",
}


def _with_coefficients():
    out = []
    for name in steppers.names():
        s = steppers.get(name)
        if getattr(s, "coefficients", None) is not None and hasattr(s.coefficients, "order"):
            out.append(name)
    return out


@pytest.mark.parametrize("name", _with_coefficients())
def test_same_coefficients_same_expectations_under_any_name(name):
    from implementations.compiled import compiled_variant  # noqa: F401  (the registry's own)

    original = steppers.get(name)
    facts = method_facts(original)
    renamed = type(original).__new__(type(original))
    renamed.__dict__.update(original.__dict__)
    renamed.info = type(original.info)(**{**original.info.__dict__, "name": f"user-{name}"})
    assert method_facts(renamed) == facts
    for p in problems.names():
        pf = problem_facts(get_problem(p))
        assert convergence_expectation(method_facts(renamed), pf) == convergence_expectation(facts, pf)


def test_no_builtin_stepper_name_in_harness_code():
    names = [n for n in steppers.names() if "@" not in n]
    pattern = re.compile("[\"'](" + "|".join(map(re.escape, names)) + ")[\"']")
    offenders = []
    for path in (ROOT / "harness").rglob("*.py"):
        if path in NAMES_ALLOWED_IN:
            continue
        for lineno, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                offenders.append(f"{path.relative_to(ROOT)}:{lineno}: {line.strip()}")
    assert not offenders, "\n".join(offenders)


@pytest.mark.parametrize(("problem", "linear", "degree"), [
    ("free-fall", True, 2), ("harmonic", True, None), ("dahlquist", True, None),
    ("pendulum", False, None), ("kepler-elliptic", False, None), ("forced-duffing", False, None),
])
def test_problem_facts_from_the_symbolic_definition(problem, linear, degree):
    f = problem_facts(get_problem(problem))
    assert f.linear is linear
    assert f.polynomial_degree == degree


def test_stiff_problem_is_stiff_for_explicit_and_not_for_a_stable_implicit_method():
    pf = problem_facts(get_problem("van-der-pol-stiff"))
    assert pf.stiffness > 1e3
    explicit = method_facts(steppers.get("ab4"))
    implicit = method_facts(steppers.get("bdf2"))
    assert "unstable" in convergence_expectation(explicit, pf).tolerated
    assert "unstable" not in convergence_expectation(implicit, pf).tolerated
    # The same explicit method on a non-stiff problem: blowing up would be a failure.
    gaussian = problem_facts(get_problem("gaussian"))
    assert "unstable" not in convergence_expectation(explicit, gaussian).tolerated


def test_method_with_linear_order_above_its_order():
    # Three stages, c = (0, 1, 1): b^T c = 1/2 and b^T A c = 1/6 hold, b^T c^2 = 1/2 != 1/3, so
    # the order is 2 while R(z) = 1 + z + z^2/2 + z^3/6: order 3 on linear problems (the
    # situation of several SSP methods, whose R is a longer Taylor polynomial than their order).
    from implementations.runge_kutta import ExplicitRungeKutta

    tab = ButcherTableau("lin3", [[0, 0, 0], [1, 0, 0], [0.5, 0.5, 0]], [0.5, 1 / 6, 1 / 3])
    assert tab.order() == 2
    assert tab.linear_order() == 3
    stepper = ExplicitRungeKutta(tab, claimed_order=2, reference="constructed for this test")
    exp = convergence_expectation(method_facts(stepper), problem_facts(get_problem("harmonic")))
    assert exp.order == 3 and "linear" in exp.reason
    exp = convergence_expectation(method_facts(stepper), problem_facts(get_problem("pendulum")))
    assert exp.order == 2


def test_embedded_pair_order():
    # Bogacki-Shampine 3(2), Appl. Math. Lett. 2 (1989) 321.
    A = [[0, 0, 0, 0], [1 / 2, 0, 0, 0], [0, 3 / 4, 0, 0], [2 / 9, 1 / 3, 4 / 9, 0]]
    tab = ButcherTableau("bs32", A, [2 / 9, 1 / 3, 4 / 9, 0], b_hat=[7 / 24, 1 / 4, 1 / 3, 1 / 8])
    assert tab.order() == 3
    assert tab.embedded_order() == 2


def test_large_weights_pass_the_scaled_self_check_and_order_conditions():
    # Richardson extrapolation of explicit Euler with step sequence 1..6 (Aitken-Neville): the
    # weights sum |b| to hundreds, their rounding exceeds 1e-14, and the order is 6.
    from harness.theory import rk_order

    seq = [1, 2, 3, 4, 5, 6]
    import numpy as np

    s = sum(seq)
    A = np.zeros((s, s))
    b = np.zeros(s)
    start = 0
    # Extrapolation weights for T_{k} = sum_j w_j T_{j,1} with T_{j,1} = Euler with n_j steps.
    ns = np.array(seq, dtype=float)
    w = np.array([np.prod([ns[j] / (ns[j] - ns[m]) for m in range(len(ns)) if m != j])
                  for j in range(len(ns))])
    for j, n in enumerate(seq):
        for i in range(n):
            row = start + i
            A[row, start:start + i] = 1.0 / n
            b[row] = w[j] / n
        start += n
    tab = ButcherTableau("euler-extrapolation-6", A, b)
    assert float(np.abs(tab.b).sum()) > 100
    assert rk_order(tab) == 6
    assert math.isfinite(tab.linear_order())


def test_population_has_no_false_alarm_and_no_miss():
    """`harness population`: generated correct methods pass, every mutant fails, for the gate
    and for the measurement alone; the rates are saved with the run."""
    from harness import results
    from harness.cli import main

    assert main(["population", "--size", "2", "--seed", "11"]) == 0
    rates = results.load("latest", "gate-population", table="summary")
    overall = rates[rates.family == "all"].iloc[0]
    assert overall.correct_methods == 12 and overall.mutants >= 24 + 6
    assert overall.gate_false_alarms == 0 and overall.gate_misses == 0
    assert overall.measurement_false_alarms == 0 and overall.measurement_misses == 0
    rows = results.load("latest", "gate-population")
    assert set(rows.kind) == {"correct", "perturbed", "subtle", "overclaimed"}
    wrong = rows[(rows.kind == "correct") != rows.gate_passed]
    assert wrong.empty, wrong[["stepper", "kind", "detail"]].to_string()


def test_embedded_method_of_a_pair_is_registered_and_measured():
    from harness.gate import gate_table
    from harness.runner import run_experiment

    pair = steppers.get("bogacki-shampine")
    embedded = steppers.get("bogacki-shampine@embedded")
    assert pair.coefficients.embedded_order() == 2
    assert embedded.info.claimed_order == 2 and embedded.coefficients.order() == 2
    result = run_experiment("convergence", ["bogacki-shampine@embedded"], ["forced-duffing"], jobs=1,
                            progress=False)
    table = gate_table(result.summary)
    row = table[table.problem == "forced-duffing"].iloc[0]
    assert row.outcome == "pass" and abs(row.measured_order - 2) <= 0.2, row.to_dict()
