"""Implicit Runge-Kutta and linear multistep steppers (families implicit-rk, multistep) against
the stepper contract and their own claims.

Every test sweeps the registered steppers of these two families. Sources of the expectations:
course material 004 (backward Euler's unconditional stability on y' = lambda y; Adams-Bashforth
formulas and the need for a starter), Hairer & Wanner II, IV.3 and V.1 (A-stability, stability
intervals of Adams methods), Hairer, Lubich & Wanner, GNI IV.2 and VI.4 (Gauss methods preserve
quadratic invariants; symmetric methods retrace their steps).
"""

from __future__ import annotations

import math

import heyoka as hy
import numpy as np
import pytest
from helpers import BLOWUP

from harness.errors import IncompatibleError, InputError
from harness.problem import Problem
from harness.registry import get_problem, get_stepper
from harness.stepper import StepFailure
from harness.tolerances import BLOWUP_ERROR
from implementations import implicit_rk, multistep
from implementations.implicit_rk import ImplicitRungeKutta
from implementations.multistep import LinearMultistepStepper

IMPLICIT_RK = list(implicit_rk.STEPPERS)
MULTISTEP = list(multistep.STEPPERS)
OWN = IMPLICIT_RK + MULTISTEP
IMPLICIT = [s for s in OWN if not s.info.explicit]


def ids(items):
    return [s.info.name for s in items]


# -- local problems ---------------------------------------------------------------------------------
_y = hy.make_vars("y")
STIFF_LAMBDA = 1000.0
# y' = -1000 (y - cos t): a stiff decay onto the slow solution a cos t + b sin t
# (a = lambda^2 / (1 + lambda^2), b = lambda / (1 + lambda^2)); Hairer & Wanner II, IV.1.
STIFF_COS = Problem(
    "test-stiff-cos",
    variables=[_y],
    rhs=[-STIFF_LAMBDA * (_y - hy.cos(hy.time))],
    y0=[0.0],
    t_span=(0.0, 5.0),
    reference="Hairer & Wanner, Solving ODEs II, IV.1 (Curtiss-Hirschfelder type test equation)",
)


def stiff_exact(t: float, y0: float) -> float:
    lam = STIFF_LAMBDA
    a, b = lam * lam / (1 + lam * lam), lam / (1 + lam * lam)
    return a * math.cos(t) + b * math.sin(t) + (y0 - a) * math.exp(-lam * t)


# -- registration and declared properties ---------------------------------------------------------
def test_every_family_stepper_is_registered():
    for stepper in OWN:
        assert get_stepper(stepper.info.name) is stepper


@pytest.mark.parametrize("stepper", OWN, ids=ids(OWN))
def test_declared_properties_are_complete(stepper):
    info = stepper.info
    assert info.family in ("implicit-rk", "multistep")
    assert isinstance(info.claimed_order, int) and info.claimed_order >= 1
    assert info.reference and info.description and info.evals_per_step > 0
    assert info.form == "first-order" and not info.adaptive
    assert info.explicit == bool(stepper.coefficients.explicit)
    if not info.explicit:
        assert info.extra["newton"] in ("full", "simplified") and info.extra["newton_tol"] > 0
        assert "typical" in info.description
    if info.family == "multistep":
        assert info.extra["starter"] == "rk4" and "starter='rk4'" in info.description
        assert stepper.history_length == stepper.coefficients.steps
    if info.symplectic:
        assert info.symmetric


# -- order: error ratio when halving h --------------------------------------------------------------
# Quick check with two step sizes inside the asymptotic range (the gate does the full fit):
# gaussian (non-autonomous, so stage times matter) on [0, 3], harmonic on [0, 2].
ORDER_STEPS = {1: 200, 2: 100, 3: 200, 4: 100}
ORDER_TOL = 0.15
ORDER_PROBLEMS = [("gaussian", 3.0), ("harmonic", 2.0)]


def measured_order(stepper, problem, t_end: float, n: int) -> float:
    y0 = problem.ensemble(4)
    exact = problem.exact(t_end, y0, problem.t0, None)
    errors = []
    for steps in (n, 2 * n):
        tr = stepper.integrate(problem, h=t_end / steps, n_steps=steps, y0=y0)
        errors.append(np.max(np.abs(tr.final - exact)))
    return math.log2(errors[0] / errors[1])


@pytest.mark.parametrize("problem_name, t_end", ORDER_PROBLEMS)
@pytest.mark.parametrize("stepper", OWN, ids=ids(OWN))
def test_order_from_step_halving(stepper, problem_name, t_end):
    order = measured_order(
        stepper, get_problem(problem_name), t_end, ORDER_STEPS[stepper.info.claimed_order]
    )
    assert abs(order - stepper.info.claimed_order) <= ORDER_TOL, order


# -- stiffness: y' = -1000 (y - cos t) at h = 0.1, so h lambda = -100 ----------------------------
# A-stable methods keep the initial offset (1) from the slow solution bounded; explicit methods
# and am3 (real stability interval 6 < 100) blow up. Euler from the registry is the explicit
# contrast of course material 004.
STIFF_EXPECTED = {
    "backward-euler": "stable",
    "trapezoid": "stable",
    "implicit-midpoint": "stable",
    "gauss-legendre-4": "stable",
    "bdf2": "stable",
    "am3": "unstable",
    "ab2": "unstable",
    "ab3": "unstable",
    "ab4": "unstable",
    "euler": "unstable",
}


def test_stiff_table_covers_the_families():
    assert set(ids(OWN)) <= set(STIFF_EXPECTED)


@pytest.mark.parametrize("name, expected", sorted(STIFF_EXPECTED.items()))
def test_stiff_linear_problem(name, expected):
    tr = get_stepper(name).integrate(STIFF_COS, h=0.1, n_steps=50, y0=np.zeros((1, 2)))
    error = float(np.max(np.abs(tr.final - stiff_exact(5.0, 0.0)))) if tr.finite else math.inf
    if expected == "stable":
        assert error <= 1.0
    else:
        assert error > BLOWUP_ERROR


def test_stiff_van_der_pol_implicit_converge_where_explicit_blow_up():
    """van-der-pol-stiff (eps = 1e-3, stiff eigenvalue ~ -2000) at h = 0.005: rk4 is far outside
    its stability interval (h |lambda| ~ 10 > 2.79) while the A-stable methods follow the slow
    solution to the ground truth."""
    from harness.ground_truth import reference

    P = get_problem("van-der-pol-stiff")
    y0 = P.ensemble(4)
    truth = reference(P, [0.5], y0).y[-1]
    assert not get_stepper("rk4").integrate(P, h=0.005, n_steps=100, y0=y0).finite
    for name in [n for n, e in STIFF_EXPECTED.items() if e == "stable"]:
        tr = get_stepper(name).integrate(P, h=0.005, n_steps=100, y0=y0)
        assert np.max(np.abs(tr.final - truth)) < 1e-2, name


# -- quadratic invariants ---------------------------------------------------------------------------
# Gauss methods (implicit midpoint, gauss-legendre-4) preserve every quadratic invariant to
# rounding; trapezoid preserves the harmonic energy only because the problem is linear (it then
# coincides with the midpoint rule) and loses Kepler's angular momentum; backward Euler damps.
PRESERVED = 1e-13  # relative drift after ~1000 steps: a few hundred ulps of rounding
LOST = 1e-8
INVARIANT_CASES = [
    ("implicit-midpoint", "harmonic", "energy", True),
    ("gauss-legendre-4", "harmonic", "energy", True),
    ("trapezoid", "harmonic", "energy", True),
    ("backward-euler", "harmonic", "energy", False),
    ("implicit-midpoint", "kepler-elliptic", "angular_momentum", True),
    ("gauss-legendre-4", "kepler-elliptic", "angular_momentum", True),
    ("trapezoid", "kepler-elliptic", "angular_momentum", False),
]


@pytest.mark.parametrize("name, problem_name, invariant, preserved", INVARIANT_CASES)
def test_quadratic_invariants(name, problem_name, invariant, preserved):
    P = get_problem(problem_name)
    h, n = (0.1, 1000) if problem_name == "harmonic" else (0.01, 628)
    tr = get_stepper(name).integrate(P, h=h, n_steps=n, y0=P.ensemble(4))
    before = P.invariant_values(tr.y[0], t=0.0)[invariant]
    after = P.invariant_values(tr.y[-1], t=n * h)[invariant]
    drift = float(np.max(np.abs(after - before) / np.abs(before)))
    if preserved:
        assert drift <= PRESERVED
    else:
        assert drift > LOST


# -- time reversal ----------------------------------------------------------------------------------
SYMMETRIC_RETURN = 1e-12
NON_SYMMETRIC_MISS = 1e-9


@pytest.mark.parametrize("stepper", OWN, ids=ids(OWN))
def test_round_trip_matches_the_symmetry_claim(stepper):
    P = get_problem("harmonic")
    start, back = stepper.round_trip(P, h=0.05, n_steps=100, y0=P.ensemble(4))
    miss = float(np.max(np.abs(back - start)))
    if stepper.info.symmetric:
        assert miss <= SYMMETRIC_RETURN
    else:
        assert miss > NON_SYMMETRIC_MISS


@pytest.mark.parametrize("stepper", MULTISTEP, ids=ids(MULTISTEP))
def test_multistep_reverse_retraces_its_history(stepper):
    """Reversal turns the stored past into the values ahead: k - 1 steps out and k - 1 back
    revisit stored states only, so the round trip is exact."""
    P = get_problem("gaussian")
    k = stepper.coefficients.steps
    start, back = stepper.round_trip(P, h=0.1, n_steps=max(k - 1, 1), y0=P.ensemble(3))
    if k > 1:
        np.testing.assert_array_equal(back, start)


# -- Newton: failure, counts, settings --------------------------------------------------------------
@pytest.mark.parametrize("stepper", IMPLICIT_RK, ids=ids(IMPLICIT_RK))
def test_newton_failure_on_a_problem_without_a_solution(stepper):
    pattern = (
        rf"stepper '{stepper.info.name}': (Newton iteration did not converge|singular Newton "
        r"matrix) at t=0 .*residual"
    )
    with pytest.raises(StepFailure, match=pattern):
        stepper.integrate(BLOWUP, h=1.0, n_steps=1)


@pytest.mark.parametrize("stepper", IMPLICIT, ids=ids(IMPLICIT))
def test_iteration_cap_is_enforced(stepper):
    capped = stepper.with_newton(tol=0.0, max_iter=1)
    assert capped.info.extra["newton_tol"] == 0.0
    with pytest.raises(StepFailure, match=r"did not converge at t=.* after 1 iteration"):
        capped.integrate(get_problem("gaussian"), h=0.1, n_steps=5)


def expected_rhs(stepper, newton_iterations: int, n_steps: int) -> int:
    """Right-hand-side evaluations the loops should have made (rk4 starter: 4 per step)."""
    if stepper.info.family == "implicit-rk":
        per_iteration = stepper.info.extra["implicit_stages"]
        explicit_stage = {"trapezoid": 1}.get(stepper.info.name, 0)  # first step only (FSAL)
        return per_iteration * newton_iterations + explicit_stage
    k = stepper.coefficients.steps
    history = int(np.count_nonzero(stepper.coefficients.beta[:-1]))  # f of the exact history
    return 4 * (k - 1) + history + newton_iterations


# van-der-pol-stiff at h = 8e-4: h lambda ~ -2.4 at the start, inside the rk4 starter's real
# stability interval (2.785; at 1e-3, -3.0, the implicit tables start from the reference) and
# inside am3's too.
NEWTON_H = 0.0008


@pytest.mark.parametrize("stepper", IMPLICIT, ids=ids(IMPLICIT))
def test_evaluations_and_newton_iterations_are_counted(stepper):
    P = get_problem("van-der-pol-stiff")
    n = 40
    evals = stepper.integrate(P, h=NEWTON_H, n_steps=n, y0=P.ensemble(4)).evals
    iterations = evals["newton_iterations"]
    solves = n - (stepper.coefficients.steps - 1 if stepper.info.family == "multistep" else 0)
    assert 2 * solves <= iterations <= stepper.newton.max_iter * solves
    assert evals["rhs"] == expected_rhs(stepper, iterations, n)
    stages = stepper.info.extra.get("implicit_stages", 1)
    assert evals["jac"] == stages * iterations  # full Newton: a Jacobian at every iterate


@pytest.mark.parametrize("stepper", IMPLICIT, ids=ids(IMPLICIT))
def test_simplified_newton_agrees_with_full(stepper):
    P = get_problem("van-der-pol-stiff")
    y0 = P.ensemble(4)
    full = stepper.integrate(P, h=NEWTON_H, n_steps=20, y0=y0)
    simple = stepper.with_newton(mode="simplified").integrate(P, h=NEWTON_H, n_steps=20, y0=y0)
    np.testing.assert_allclose(simple.final, full.final, rtol=1e-11, atol=1e-11)
    solves = 20 - (stepper.coefficients.steps - 1 if stepper.info.family == "multistep" else 0)
    assert simple.evals["jac"] == solves  # one Jacobian per step


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({"mode": "approximate"}, r"`newton` must be one of"),
        ({"tol": -1e-12}, r"`newton_tol` must be finite and >= 0, got -1e-12"),
        ({"tol": math.nan}, r"`newton_tol` must be finite"),
        ({"max_iter": 0}, r"`newton_max_iter` must be at least 1, got 0"),
        ({"max_iter": 2.5}, r"`newton_max_iter` must be a whole number"),
    ],
)
@pytest.mark.parametrize("stepper", [IMPLICIT_RK[0], multistep.STEPPERS[-1]], ids=["irk", "lmm"])
def test_bad_newton_settings(stepper, kwargs, pattern):
    with pytest.raises(InputError, match=pattern):
        stepper.with_newton(**kwargs)


@pytest.mark.parametrize("build", [
    lambda: ImplicitRungeKutta(implicit_rk.GAUSS_LEGENDRE_4, name="g4-stated", claimed_order=4,
                               symplectic=False, symmetric=False, reference="r", description="d",
                               stability={"real_interval": 2.0}),
    lambda: LinearMultistepStepper(multistep.BDF2, name="bdf2-euler", claimed_order=2, reference="r",
                                   description="d", starter="euler", stability={"real_interval": 3.0}),
], ids=["irk", "lmm"])
def test_other_newton_settings_keep_every_keyword_the_method_was_built_with(build):
    stepper = build()
    rebuilt = stepper.with_newton(mode="simplified", tol=1e-8, max_iter=7)
    assert (rebuilt.newton.mode, rebuilt.newton.tol, rebuilt.newton.max_iter) == ("simplified", 1e-8, 7)
    for field in ("name", "claimed_order", "symplectic", "symmetric", "reference"):
        assert getattr(rebuilt.info, field) == getattr(stepper.info, field)
    assert rebuilt.info.extra["stability"] == stepper.info.extra["stability"]
    assert getattr(rebuilt, "starter_name", None) == getattr(stepper, "starter_name", None)
    assert rebuilt.with_newton(mode="full").newton.max_iter == 7


def test_wrong_coefficient_objects_are_refused():
    with pytest.raises(InputError, match=r"`table` must be a LinearMultistep, got ButcherTableau"):
        LinearMultistepStepper(
            implicit_rk.GAUSS_LEGENDRE_4, name="x", claimed_order=4, reference="r", description="d"
        )
    with pytest.raises(InputError, match=r"`tableau` must be a ButcherTableau, got LinearMultistep"):
        ImplicitRungeKutta(
            multistep.BDF2, name="x", claimed_order=2, symplectic=False, symmetric=False,
            reference="r", description="d",
        )


def test_explicit_tableau_is_refused():
    with pytest.raises(InputError, match=r"`tableau` 'rk4' is explicit"):
        ImplicitRungeKutta(
            get_stepper("rk4").coefficients, name="x", claimed_order=4, symplectic=False,
            symmetric=False, reference="r", description="d",
        )


# -- multistep starters -----------------------------------------------------------------------------
def test_starter_is_recorded_and_changes_the_measured_order():
    """ab4 started by rk4 converges at order 4; started by Euler (local error O(h^2) in the three
    starting values) the global error is O(h^2): the starter must be reported with the result."""
    ab4 = get_stepper("ab4")
    P, t_end = get_problem("gaussian"), 3.0
    assert ab4.info.extra["starter"] == "rk4"
    assert abs(measured_order(ab4, P, t_end, ORDER_STEPS[4]) - 4.0) <= ORDER_TOL
    euler_start = ab4.with_starter("euler")
    assert euler_start.info.extra["starter"] == "euler"
    assert "starter='euler'" in euler_start.info.description
    assert measured_order(euler_start, P, t_end, ORDER_STEPS[4]) < 2.5


def test_starter_object_and_name_agree():
    ab3 = get_stepper("ab3")
    P = get_problem("harmonic")
    by_object = ab3.with_starter(get_stepper("rk4")).integrate(P, h=0.05, n_steps=40)
    by_name = ab3.integrate(P, h=0.05, n_steps=40)
    np.testing.assert_array_equal(by_object.final, by_name.final)
    assert by_object.evals == by_name.evals


def test_reference_starter_uses_the_ground_truth():
    from harness.ground_truth import reference

    P = get_problem("harmonic")
    y0 = P.ensemble(3)
    ab4 = get_stepper("ab4").with_starter("reference")
    assert ab4.info.extra["starter"] == "reference" and "ground truth" in ab4.info.description
    tr = ab4.integrate(P, h=0.1, n_steps=3, y0=y0, save_steps=[1, 2, 3])
    truth = reference(P, [0.1, 0.2, 0.3], y0).y
    np.testing.assert_allclose(tr.y, truth, rtol=0, atol=1e-15)
    assert tr.evals["rhs"] == 0  # the starting values cost no evaluation of the method
    assert abs(measured_order(ab4, get_problem("gaussian"), 3.0, ORDER_STEPS[4]) - 4.0) <= ORDER_TOL


@pytest.mark.parametrize(
    "starter, error, pattern",
    [
        (3, InputError, r"`starter` must be 'reference', a registered stepper name or a Stepper"),
        ("", InputError, r"`starter` must be"),
        (multistep.STEPPERS[0], InputError, r"`starter` must be a one-step method, got the multistep"),
    ],
)
def test_bad_starter(starter, error, pattern):
    with pytest.raises(error, match=pattern):
        get_stepper("ab2").with_starter(starter)


def test_unknown_starter_name_is_reported_at_use():
    stepper = get_stepper("ab2").with_starter("no-such-method")
    with pytest.raises(IncompatibleError, match=r"its starter cannot be used: unknown stepper"):
        stepper.integrate(get_problem("gaussian"), h=0.1, n_steps=3)


@pytest.mark.parametrize("stepper", MULTISTEP, ids=ids(MULTISTEP))
def test_local_error_from_exact_history(stepper):
    """One step of the recurrence from exact history: local error O(h^(p+1))."""
    P = get_problem("gaussian")
    k, p = stepper.coefficients.steps, stepper.info.claimed_order
    t0 = 0.5
    errors = []
    for h in (0.02, 0.01):
        history = [P.exact(t0 + j * h, P.y0[:, None], 0.0, None) for j in range(k)]
        y = stepper.step_from_history(P, h=h, history=history, t0=t0)
        errors.append(abs(float(y[0, 0] - P.exact(t0 + k * h, P.y0[:, None], 0.0, None)[0, 0])))
    assert abs(math.log2(errors[0] / errors[1]) - (p + 1)) <= 0.2
