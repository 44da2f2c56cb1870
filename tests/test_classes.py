"""Orders per problem class, stage order, stiff ranges and the predicted leading error.

Oracles: the linear order (R(z) against e^z, an independent computation) is the class order of
degree-1 fields; published tableaux (Williamson's and Carpenter-Kennedy's low-storage methods,
the SSP(4,3) method, Dormand-Prince 5(4), Radau IIA, TR-BDF2) with their published orders and
stage orders; generated methods whose class order exceeds their order, confirmed by measuring
the slope; and the predicted error coefficient against errors measured at several step sizes.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction as F

import numpy as np
import pytest
from scipy.optimize import least_squares

from harness.coefficients import ButcherTableau
from harness.facts import ProblemFacts, method_facts
from harness.registry import get_problem, get_stepper, steppers
from harness.rules import convergence_expectation, judge_convergence
from harness.theory import rk_linear_order, rk_order, rooted_trees
from harness.theory.classes import (
    rk_class_order,
    rk_error_defects,
    rk_stage_order,
    rk_stiffly_accurate,
    tree_survives,
)
from implementations.runge_kutta import ExplicitRungeKutta


def _two_register(name: str, A: list, B: list) -> ButcherTableau:
    """A 2N-storage scheme (Williamson 1980: dq = A_i dq + h f(y), y += B_i dq) as its tableau."""
    s = len(B)
    alpha = [[F(0)] * s for _ in range(s)]
    for i in range(s):
        alpha[i][i] = F(1)
        for j in range(i):
            alpha[i][j] = A[i] * alpha[i - 1][j]
    a = [[sum((B[m] * alpha[m][j] for m in range(j, i)), F(0)) if j < i else F(0) for j in range(s)]
         for i in range(s)]
    b = [sum((B[m] * alpha[m][j] for m in range(j, s)), F(0)) for j in range(s)]
    return ButcherTableau(name, a, b)


# J. H. Williamson, J. Comput. Phys. 35 (1980) 48-56, the third-order scheme of his Table 1.
WILLIAMSON3 = _two_register("williamson-3", [F(0), F(-5, 9), F(-153, 128)], [F(1, 3), F(15, 16), F(8, 15)])
# M. H. Carpenter, C. A. Kennedy, NASA TM-109112 (1994), the fourth-order five-stage 2N scheme.
CARPENTER_KENNEDY4 = _two_register(
    "carpenter-kennedy-4",
    [F(0), F(-567301805773, 1357537059087), F(-2404267990393, 2016746695238),
     F(-3550918686646, 2091501179385), F(-1275806237668, 842570457699)],
    [F(1432997174477, 9575080441755), F(5161836677717, 13612068292357),
     F(1720146321549, 2090206949498), F(3134564353537, 4481467310338),
     F(2277821191437, 14882151754819)])
# Four-stage third-order SSP method (Spiteri & Ruuth, SIAM J. Numer. Anal. 40 (2002) 469-491).
SSP43 = ButcherTableau("ssp-4-3", [[0, 0, 0, 0], [F(1, 2), 0, 0, 0], [F(1, 2), F(1, 2), 0, 0],
                                   [F(1, 6), F(1, 6), F(1, 6), 0]], [F(1, 6), F(1, 6), F(1, 6), F(1, 2)])
# Dormand & Prince, J. Comput. Appl. Math. 6 (1980) 19-26: the fifth-order weights and the
# fourth-order embedded ones of the same stages.
_DP_A = [[0] * 7, [F(1, 5)] + [0] * 6, [F(3, 40), F(9, 40)] + [0] * 5,
         [F(44, 45), F(-56, 15), F(32, 9)] + [0] * 4,
         [F(19372, 6561), F(-25360, 2187), F(64448, 6561), F(-212, 729)] + [0] * 3,
         [F(9017, 3168), F(-355, 33), F(46732, 5247), F(49, 176), F(-5103, 18656), 0, 0],
         [F(35, 384), 0, F(500, 1113), F(125, 192), F(-2187, 6784), F(11, 84), 0]]
_DP_B5 = _DP_A[6]
_DP_B4 = [F(5179, 57600), 0, F(7571, 16695), F(393, 640), F(-92097, 339200), F(187, 2100), F(1, 40)]
# Radau IIA of order 5 (Hairer & Wanner II, IV.5, Table 5.6), rounded to float64.
_S6 = math.sqrt(6.0)
RADAU5 = ButcherTableau("radau-iia-5", [
    [(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
    [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
    [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9]], [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9])
# TR-BDF2 as an ESDIRK (Hosea & Shampine, Appl. Numer. Math. 20 (1996) 21-37), gamma = 2 - sqrt 2.
_G = 2 - math.sqrt(2.0)
_D = _G / 2
TRBDF2 = ButcherTableau("tr-bdf2", [[0, 0, 0], [_D, _D, 0],
                                    [1 / (2 * (2 - _G)), 1 / (2 * (2 - _G)), _D]],
                        [1 / (2 * (2 - _G)), 1 / (2 * (2 - _G)), _D])

# The implicit part of Kennedy & Carpenter's ARK3(2)4L[2]SA (Appl. Numer. Math. 44 (2003)
# 139-181), an ESDIRK of order 3, stage order 2, stiffly accurate (as tabulated in the
# fishac/IMEXMRISRPaper repository, src/methods/DIRK/instances/ARK32ESDIRKCoefficients.hpp).
_KC_G = F(1767732205903, 4055673282236)
_KC_LAST = [F(1471266399579, 7840856788654), F(-4482444167858, 7529755066697),
            F(11266239266428, 11593286722821), _KC_G]
ESDIRK3 = ButcherTableau("esdirk-3-2-4l-2-sa", [
    [0, 0, 0, 0], [_KC_G, _KC_G, 0, 0],
    [F(2746238789719, 10658868560708), F(-640167445237, 6845629431997), _KC_G, 0], _KC_LAST], _KC_LAST)


def _mixed_dp(eps: float) -> ButcherTableau:
    """(1 - eps) b5 + eps b4 on Dormand-Prince's stages: order 4 with order-5 defects eps times
    those of b4 (a fourth-order method whose leading error term is tiny)."""
    b = [(1 - F(eps)) * x + F(eps) * y for x, y in zip(_DP_B5, _DP_B4, strict=True)]
    return ButcherTableau(f"dp-mix-{eps:g}", _DP_A, b)


def _registry_tableaux() -> list[ButcherTableau]:
    out = {}
    for name in steppers.names():
        c = getattr(get_stepper(name), "coefficients", None)
        if isinstance(c, ButcherTableau):
            out[c.fingerprint()] = c
    return list(out.values())


PUBLISHED = [WILLIAMSON3, CARPENTER_KENNEDY4, SSP43, RADAU5, TRBDF2, ESDIRK3, _mixed_dp(1e-4),
             ButcherTableau("dp5", _DP_A, _DP_B5)]


def _lift(name: str, stages: int, order: int, missed: str, offset: float, seed: int) -> ButcherTableau:
    """A generated explicit method that satisfies every order condition up to `order` except the
    one of the tree `missed`, which is off by `offset` (solved by least squares from a seeded
    start; the tests check the orders the result has)."""
    trees, lower = rooted_trees(order), np.tril_indices(stages, -1)
    m = len(lower[0])

    def tableau(x):
        A = np.zeros((stages, stages))
        A[lower] = x[:m]
        return A, x[m:]

    def residuals(x):
        A, b = tableau(x)
        g, out = [], []
        for t in trees:
            v = np.ones(stages)
            for k in t.children:
                v = v * (A @ g[k])
            g.append(v)
            out.append(b @ v - 1 / t.gamma - (offset if t.label == missed else 0.0))
        return out

    x0 = np.random.default_rng(seed).uniform(-1, 1, m + stages)
    return ButcherTableau(name, *tableau(least_squares(residuals, x0, xtol=1e-15, ftol=1e-15, gtol=1e-15).x))


def _quadratic_lift(seed: int) -> ButcherTableau:
    """Five stages, order 3, every order-4 condition but [***]'s: order 4 on quadratic fields."""
    return _lift(f"quadratic-lift-{seed}", 5, 4, "[***]", 0.02, seed)


def _nystrom_lift() -> ButcherTableau:
    """Six stages, order 4, every order-5 condition but [[**]*]'s (the one tree whose elementary
    differential vanishes on x'' = g(x)): order 5 on the Nystrom class only."""
    return _lift("nystrom-lift", 6, 5, "[[**]*]", 0.01, 5)


# -- class orders ------------------------------------------------------------------------------
@pytest.mark.parametrize("tableau", _registry_tableaux() + PUBLISHED, ids=lambda t: t.name)
def test_degree_one_class_order_is_the_linear_order_and_classes_never_lower_the_order(tableau):
    top = tableau.stages if tableau.explicit else 2 * tableau.stages
    assert rk_class_order(tableau, degree=1) == min(rk_linear_order(tableau), top)
    p = rk_order(tableau)
    nys, q2, q3 = (rk_class_order(tableau, nystrom=True), rk_class_order(tableau, degree=2),
                   rk_class_order(tableau, degree=3))
    assert min(nys, q3) >= p and q2 >= q3
    assert rk_class_order(tableau, nystrom=True, degree=2) >= max(nys, q2)


def test_first_trees_that_vanish_on_each_class():
    trees = rooted_trees(6)
    gone = {k: [t.label for t in trees if not tree_survives(t, **kw)]
            for k, kw in {"nystrom": {"nystrom": True}, "quadratic": {"degree": 2},
                          "linear": {"degree": 1}}.items()}
    assert gone["nystrom"][0] == "[[**]*]" and min(len(x) for x in gone["nystrom"]) == len("[[**]*]")
    assert all(t.order >= 5 for t in trees if not tree_survives(t, nystrom=True))
    assert gone["quadratic"][0] == "[***]"
    # linear fields keep only the tall trees [[...[*]...]]: one per order
    assert [t.order for t in trees if tree_survives(t, degree=1)] == [1, 2, 3, 4, 5, 6]


@pytest.mark.parametrize("tableau, order", [(WILLIAMSON3, 3), (CARPENTER_KENNEDY4, 4), (SSP43, 3),
                                            (ESDIRK3, 3), (RADAU5, 5), (TRBDF2, 2), (_mixed_dp(1e-4), 4)],
                         ids=lambda x: getattr(x, "name", str(x)))
def test_published_orders(tableau, order):
    assert rk_order(tableau) == order


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_generated_method_gains_an_order_on_quadratic_fields_and_the_slope_shows_it(seed):
    tableau = _quadratic_lift(seed)
    assert rk_order(tableau) == 3
    assert rk_class_order(tableau, degree=2) == 4
    assert rk_class_order(tableau, nystrom=True, degree=2) == 4
    assert rk_class_order(tableau, nystrom=True) == 3
    stepper = ExplicitRungeKutta(tableau, claimed_order=3, reference="generated")
    hh = get_problem("henon-heiles")  # quadratic force, no velocities: order 4
    T = hh.convergence_t_end - hh.t0
    errors = [_error(stepper, hh, T, n) for n in (400, 800)]
    assert abs(math.log2(errors[0] / errors[1]) - 4.0) < 0.2


def test_generated_method_gains_an_order_on_the_nystrom_class_and_the_slope_shows_it():
    tableau = _nystrom_lift()
    orders = rk_order(tableau), rk_class_order(tableau, nystrom=True), rk_class_order(tableau, degree=3)
    assert orders == (4, 5, 4)
    stepper = ExplicitRungeKutta(tableau, claimed_order=4, reference="generated")
    # pendulum: x'' = -sin x; forced Duffing: x'' = g(x, t) (the time joins the positions);
    # the Gaussian y' = -2ty is no second-order problem: the generic order
    for name, expected in (("pendulum", 5.0), ("forced-duffing", 5.0), ("gaussian", 4.0)):
        problem = get_problem(name)
        T = problem.convergence_t_end - problem.t0
        errors = [_error(stepper, problem, T, n) for n in (800, 1600)]
        assert abs(math.log2(errors[0] / errors[1]) - expected) < 0.1, name


def test_slope_above_the_order_on_a_non_polynomial_problem_is_explained_by_the_prediction():
    """The generated order-3 method on the pendulum (not polynomial): its leading term is small
    there (C ~ 0.02 against ~5 for the next one), so the slope reads ~3.9 over the steps a sweep
    uses; the prediction says so, and says the h^3 term leads only below h ~ 4e-3."""
    from harness.prediction import explain_slope, predicted_error

    tableau = _quadratic_lift(0)
    stepper = ExplicitRungeKutta(tableau, claimed_order=3, reference="generated")
    prob = get_problem("pendulum")
    T = prob.convergence_t_end - prob.t0
    errors = [_error(stepper, prob, T, n) for n in (400, 800)]
    slope = math.log2(errors[0] / errors[1])
    assert slope > 3.5
    prediction = predicted_error(tableau, prob, 3)
    explained, why = explain_slope(slope, 3.0, prediction, (T / 800, T / 400), (errors[1], errors[0]))
    assert explained, why
    assert prediction["crossover_h"] < T / 800


def _error(stepper, problem, T, n):
    from harness.ground_truth import reference

    ref = reference(problem, np.array([problem.convergence_t_end]), problem.y0.reshape(-1, 1)).y[0][:, 0]
    y = stepper.integrate(problem, h=T / n, n_steps=n).y[-1][:, 0]
    return float(np.max(np.abs(y - ref)))


# -- stage order and the stiff range -----------------------------------------------------------
@pytest.mark.parametrize("tableau, stage_order, stiffly_accurate", [
    (get_stepper("backward-euler").coefficients, 1, True),
    (get_stepper("trapezoid").coefficients, 2, True),
    (get_stepper("implicit-midpoint").coefficients, 1, False),
    (get_stepper("gauss-legendre-4").coefficients, 2, False),
    (RADAU5, 3, True), (TRBDF2, 2, True), (ESDIRK3, 2, True), (get_stepper("rk4").coefficients, 1, False),
], ids=lambda x: getattr(x, "name", str(x)))
def test_stage_order_and_stiff_accuracy(tableau, stage_order, stiffly_accurate):
    assert rk_stage_order(tableau) == stage_order
    assert rk_stiffly_accurate(tableau) is stiffly_accurate


_STIFF = ProblemFacts(linear=False, polynomial_degree=None, newtonian=False, velocity_free=False,
                      time_dependent=False, stiffness=3000.0, horizon=0.5, rhs_degree=None)


@pytest.mark.parametrize("measured, outcome", [(2.7, "pass"), (3.0, "pass"), (1.9, "pass"),
                                               (1.5, "fail"), (3.4, "fail")])
def test_stiff_problem_range_from_stage_order_to_order(measured, outcome):
    facts = dataclasses.replace(method_facts(get_stepper("gauss-legendre-4")), order=3, stage_order=2)
    expectation = convergence_expectation(facts, _STIFF)
    assert (expectation.order_low, expectation.order) == (2.0, 3.0)
    record = {"verdict": "converged", "measured_order": measured}
    assert judge_convergence(record, expectation)[0] == outcome
    mild = convergence_expectation(facts, dataclasses.replace(_STIFF, stiffness=1.0))
    assert mild.order_low is None  # not stiff over the horizon: the single order


def test_class_rule_expects_the_class_order_from_the_problem_facts():
    tableau = _quadratic_lift(0)
    stepper = ExplicitRungeKutta(tableau, claimed_order=3, reference="generated")
    facts = method_facts(stepper)
    hh = dataclasses.replace(_STIFF, stiffness=0.0, newtonian=True, velocity_free=True, rhs_degree=2)
    assert convergence_expectation(facts, hh).order == 4.0
    assert convergence_expectation(facts, dataclasses.replace(hh, rhs_degree=None)).order == 3.0


# -- the predicted leading error ---------------------------------------------------------------
@pytest.mark.parametrize("tableau, problem, order", [(get_stepper("rk3").coefficients, "henon-heiles", 3),
                                                      (CARPENTER_KENNEDY4, "henon-heiles", 4)],
                         ids=["rk3", "carpenter-kennedy-4"])
def test_predicted_error_coefficient_matches_measured_errors(tableau, problem, order):
    from harness.prediction import predicted_error

    prob = get_problem(problem)
    C = predicted_error(tableau, prob, order)["coefficient"]
    stepper = ExplicitRungeKutta(tableau, claimed_order=order, reference="published")
    T = prob.convergence_t_end - prob.t0
    for n in (500, 1000):
        ratio = _error(stepper, prob, T, n) / (C * (T / n) ** order)
        assert 0.8 < ratio < 1.25, (n, ratio)


def test_slope_above_the_order_is_explained_by_a_tiny_leading_term():
    from harness.prediction import explain_slope, predicted_error

    tableau = _mixed_dp(1e-4)
    _, defects = rk_error_defects(tableau, 5)
    assert 0 < np.max(np.abs(defects)) < 1e-6
    prob = get_problem("pendulum")
    prediction = predicted_error(tableau, prob, 4)
    stepper = ExplicitRungeKutta(tableau, claimed_order=4, reference="published")
    T = prob.convergence_t_end - prob.t0
    errors = [_error(stepper, prob, T, n) for n in (200, 400)]
    slope = math.log2(errors[0] / errors[1])
    assert slope > 4.5
    explained, why = explain_slope(slope, 4.0, prediction, (T / 400, T / 200), (errors[1], errors[0]))
    assert explained, why
    # the same errors beside the embedded method's own (not tiny) leading term: not explained
    plain = predicted_error(ButcherTableau("dp5-b4", _DP_A, _DP_B4), prob, 4)
    assert not explain_slope(slope, 4.0, plain, (T / 400, T / 200), (errors[1], errors[0]))[0]


def test_gate_turns_an_explained_slope_above_the_order_into_not_measurable(registered):
    from harness.gate import judge

    tableau = _mixed_dp(1e-4)
    stepper = ExplicitRungeKutta(tableau, claimed_order=4, reference="published")
    name = registered(stepper)
    prob = get_problem("pendulum")
    T = prob.convergence_t_end - prob.t0
    errors = [_error(stepper, prob, T, n) for n in (200, 400)]
    record = {"stepper": name, "problem": "pendulum", "verdict": "converged",
              "measured_order": math.log2(errors[0] / errors[1]), "fit_h_min": T / 400,
              "fit_h_max": T / 200, "fit_error_min": errors[1], "fit_error_max": errors[0]}
    outcome, expected, reason, order = judge(record)
    assert (outcome, expected, order) == ("not-measurable", "converged", 4.0)
    assert "explained" in reason and "predicted C" in reason
    # a slope above the order with errors the h^4 term accounts for is still a failure
    C = float(reason.split("predicted C = ")[1].split(" ")[0])
    loud = dict(record, fit_error_min=C * (T / 400) ** 4, fit_error_max=C * (T / 200) ** 4)
    assert judge(loud)[0] == "fail"


@pytest.mark.parametrize("problem, velocity_free, degree", [
    ("henon-heiles", True, 2), ("gaussian", False, 2), ("van-der-pol-stiff", False, 3),
    ("damped-cubic", False, 3), ("dahlquist", False, 1), ("pendulum", True, None),
    ("kepler-elliptic", True, None), ("forced-duffing", True, None), ("lennard-jones", True, None),
])
def test_problem_class_facts_from_the_symbolic_definition(problem, velocity_free, degree):
    from harness.facts import problem_facts

    facts = problem_facts(get_problem(problem))
    assert (facts.velocity_free, facts.rhs_degree) == (velocity_free, degree)
