"""The explicit and Newtonian in-house steppers (families explicit-rk, splitting, stormer, taylor)
against the stepper contract and their own claims.

Every test sweeps the registered steppers of these families; the method-specific checks at the
end reproduce the course material's formulas (course-material files 000, 002 and 004).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import heyoka as hy
import numpy as np
import pytest
from helpers import adapter_without

import implementations
from harness.errors import IncompatibleError, InputError, PluginError
from harness.problem import NewtonianForm, Problem
from harness.registry import get_problem, get_stepper, load_plugin, steppers
from harness.stepper import StepFailure
from harness.tolerances import EPS, ROUNDOFF_MARGIN
from implementations import ProblemCache, runge_kutta, splitting, taylor, verlet

MODULES = (runge_kutta, splitting, verlet, taylor)
FAMILY_MODULES = {m.__name__ for m in MODULES}
OWN = [s for s in steppers.all() if type(s).__module__ in FAMILY_MODULES]
FIXED = [s for s in OWN if not s.info.adaptive]
NEWTONIAN = [s for s in OWN if s.info.form == "newtonian"]


def ids(items):
    return [s.info.name for s in items]


@pytest.mark.parametrize("listing, modules", [
    ("builtin_steppers", "FAMILY_MODULES"),
    ("unavailable_steppers", "FAMILY_MODULES"),
    ("unavailable_steppers", "OPTIONAL_MODULES"),
])
def test_a_missing_family_module_is_an_error_not_a_smaller_registry(monkeypatch, listing, modules):
    """Only an optional adapter's library may be absent (then it is listed as unavailable, with
    its install command); a deleted or renamed module is an error wherever it is listed."""
    import implementations

    monkeypatch.setattr(implementations, modules, (*getattr(implementations, modules), "renamed_family"))
    with pytest.raises(ModuleNotFoundError, match="implementations.renamed_family"):
        getattr(implementations, listing)()


# Each optional adapter: (module, the library it imports, the package that installs it).
OPTIONAL_ADAPTERS = [
    ("rebound_adapter", "rebound", "rebound"),
    ("sundials_adapter", "sksundae", "scikit-sundae"),
]


def test_every_optional_adapter_is_tested_without_its_library():
    import implementations

    assert {a for a, _, _ in OPTIONAL_ADAPTERS} == set(implementations.OPTIONAL_MODULES)


@pytest.mark.parametrize("adapter, library, package", OPTIONAL_ADAPTERS)
def test_without_its_library_an_optional_adapter_registers_nothing_and_says_how_to_install(
        monkeypatch, adapter, library, package):
    from implementations import unavailable_steppers

    path = Path(implementations.__file__).parent / f"{adapter}.py"
    module = adapter_without(monkeypatch, library, path, f"implementations.{adapter}")
    install = f"pip install {package}=="
    assert module.STEPPERS == []
    assert install in module.UNAVAILABLE[package]
    assert install in unavailable_steppers()[package]
    with pytest.raises(PluginError, match=rf"ImportError: .+ is not installed; install it with: {install}"):
        load_plugin(path)


def counted(stepper, evals):
    return evals["accel"] if stepper.info.form == "newtonian" else evals["rhs"]


# Round trips on `harmonic` (course file 004: symmetric methods retrace their steps):
# a symmetric method returns to rounding (a few hundred steps times eps), a non-symmetric one
# misses by its local error times the step count, far above that.
ROUND_TRIP = dict(h=0.05, n_steps=100)
SYMMETRIC_RETURN = 1e-12
NON_SYMMETRIC_MISS = 1e-9

# Quick order check over t in [0, 1] (not a whole period, where symplectic Euler superconverges):
# steps n and 2n with the error far above rounding and inside the asymptotic range.
ORDER_STEPS = {1: 64, 2: 32, 3: 16, 4: 16, 6: 8, 8: 8}
ORDER_TOL = 0.1


def _harmonic():
    return get_problem("harmonic")


def test_every_family_stepper_is_registered():
    for module in MODULES:
        for stepper in module.STEPPERS:
            assert get_stepper(stepper.info.name) is stepper
    assert len(OWN) == sum(len(m.STEPPERS) for m in MODULES)


@pytest.mark.parametrize("stepper", OWN, ids=ids(OWN))
def test_declared_properties_are_complete(stepper):
    """What StepperInfo cannot check alone: a family, a description, a positive cost, and an
    order claimed exactly when the steps are fixed (its form, reference and the order's range
    are refused by the constructor)."""
    info = stepper.info
    assert info.family and info.description
    assert info.evals_per_step > 0
    assert (info.claimed_order is None) == info.adaptive


@pytest.mark.parametrize("bad, pattern", [
    ({"form": "hamiltonian"}, r"`form` must be one of"),
    ({"claimed_order": 0}, r"`claimed_order` must be between 1 and 50, got 0"),
    ({"claimed_order": 2.0}, r"`claimed_order` must be a whole number, got 2.0"),
    ({"claimed_order": True}, r"`claimed_order` must be a whole number, got True"),
    ({"claimed_order": 10**30}, r"`claimed_order` must be between 1 and 50, got a 31-digit number"),
    ({"reference": ""}, r"`reference` \(literature source\) is required"),
])
def test_declared_properties_the_constructor_refuses(bad, pattern):
    """The checks test_declared_properties_are_complete leaves to StepperInfo."""
    import dataclasses

    with pytest.raises(InputError, match=pattern):
        dataclasses.replace(get_stepper("rk4").info, **bad)


@pytest.mark.parametrize("name, problem", [("taylor", "harmonic"), ("verlet-damped", "damped-cubic")])
def test_a_pickled_stepper_leaves_its_per_problem_cache_behind_and_rebuilds_it(name, problem):
    """What a stepper builds per problem (heyoka integrators, velocity structures) is not sent to
    a worker process: the copy arrives with an empty cache and computes the same steps."""
    import pickle

    stepper, P = get_stepper(name), get_problem(problem)
    here = stepper.integrate(P, h=0.1, n_steps=5)
    copy = pickle.loads(pickle.dumps(stepper))
    cache = next(v for v in vars(copy).values() if isinstance(v, ProblemCache))
    assert len(cache) == 0
    np.testing.assert_array_equal(copy.integrate(P, h=0.1, n_steps=5).final, here.final)
    assert len(cache) == 1


# -- evaluation counts ----------------------------------------------------------------------------
@pytest.mark.parametrize("stepper", FIXED, ids=ids(FIXED))
def test_declared_evaluations_per_step_equal_counted(stepper):
    P = _harmonic()
    short = stepper.integrate(P, h=0.01, n_steps=10).evals
    long = stepper.integrate(P, h=0.01, n_steps=30).evals
    per_step = (counted(stepper, long) - counted(stepper, short)) / 20
    assert per_step == stepper.info.evals_per_step
    startup = counted(stepper, short) - 10 * stepper.info.evals_per_step
    assert startup in (0, 1)
    assert long["jac"] == 0
    other = "rhs" if stepper.info.form == "newtonian" else "accel"
    assert long[other] == 0


def test_verlet_damped_costs_one_force_per_step_on_damped_cubic():
    # da/dv = -1 is constant: one Jacobian at the start, then one force evaluation per step.
    evals = get_stepper("verlet-damped").integrate(get_problem("damped-cubic"), h=1e-3, n_steps=50).evals
    assert evals["accel"] == 50 + 1
    assert evals["jac"] == 1


def test_taylor_counts_internal_steps_per_trajectory():
    # Members run their own adaptive steps; the count is that of the member that took the most.
    P = _harmonic()
    stepper = get_stepper("taylor")
    small, large = [1e-5, 0.0], [1.0, 0.0]  # heyoka's tolerance is absolute below |y| = 1
    one_small = stepper.integrate(P, h=5.0, n_steps=4, y0=small).evals
    one_large = stepper.integrate(P, h=5.0, n_steps=4, y0=large).evals
    both = stepper.integrate(P, h=5.0, n_steps=4, y0=np.array([small, large]).T).evals
    assert one_small["rhs"] == one_small["accel"] == one_small["jac"] == 0
    assert one_small["internal_steps"] < one_large["internal_steps"]
    assert one_large["internal_steps"] > 4  # several internal steps per output step of length 5
    assert both["internal_steps"] == max(one_small["internal_steps"], one_large["internal_steps"])


# -- ensemble, saving, input ----------------------------------------------------------------------
def _problem_for(stepper):
    return get_problem("damped-cubic" if stepper.info.velocity_dependent and stepper.info.form
                       == "newtonian" else "pendulum")


@pytest.mark.parametrize("stepper", OWN, ids=ids(OWN))
def test_ensemble_equals_single_member_runs(stepper):
    P = _problem_for(stepper)
    y0 = P.ensemble(5, seed=3)
    h, n = 0.05, 20
    together = stepper.integrate(P, h=h, n_steps=n, y0=y0).final
    for j in range(y0.shape[1]):
        alone = stepper.integrate(P, h=h, n_steps=n, y0=y0[:, j]).final[:, 0]
        np.testing.assert_allclose(together[:, j], alone, rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("stepper", OWN, ids=ids(OWN))
def test_saved_steps_have_the_right_shapes_and_values(stepper):
    P = _problem_for(stepper)
    y0 = P.ensemble(3, seed=1)
    h = 0.05
    tr = stepper.integrate(P, h=h, n_steps=10, y0=y0, save_steps=[7, 0, 3, 10])
    assert tr.y.shape == (4, P.dim, 3)
    np.testing.assert_array_equal(tr.steps, [0, 3, 7, 10])
    np.testing.assert_allclose(tr.t, P.t0 + h * np.array([0, 3, 7, 10]))
    np.testing.assert_allclose(tr.y[0], y0, rtol=0, atol=1e-15)
    # Saving on the way does not change the result.
    straight = stepper.integrate(P, h=h, n_steps=10, y0=y0)
    np.testing.assert_allclose(tr.final, straight.final, rtol=1e-14, atol=1e-15)
    assert straight.y.shape == (2, P.dim, 3) and tr.finite


BAD_STEPS = [
    (dict(h=0.0), r"`h` must be positive, got 0.0"),
    (dict(h=-0.1), r"`h` must be positive, got -0.1"),
    (dict(h=float("nan")), r"`h` must be finite, got nan"),
    (dict(h=float("inf")), r"`h` must be finite, got inf"),
    (dict(h="fast"), r"`h` must be a real number"),
    (dict(n_steps=2.5), r"`n_steps` must be a whole number, got 2.5"),
    (dict(n_steps="10"), r"`n_steps` must be a whole number"),
    (dict(n_steps=True), r"`n_steps` must be a whole number"),
    (dict(n_steps=0), r"`n_steps` must be at least 1, got 0"),
    (dict(y0=[float("nan"), 0.0]), r"`y0` must be finite"),
    (dict(y0=[1.0, 0.0, 0.0]), r"`y0` must have shape \(2,\) or \(2, N\)"),
]


@pytest.mark.parametrize("stepper", OWN, ids=ids(OWN))
@pytest.mark.parametrize("bad, pattern", BAD_STEPS, ids=[p for _, p in BAD_STEPS])
def test_bad_input_is_refused(stepper, bad, pattern):
    kwargs = dict(h=0.1, n_steps=10) | bad
    with pytest.raises(InputError, match=pattern):
        stepper.integrate(_harmonic(), **kwargs)


@pytest.mark.parametrize("stepper", NEWTONIAN, ids=ids(NEWTONIAN))
def test_newtonian_stepper_refuses_a_first_order_problem(stepper):
    pattern = rf"stepper '{stepper.info.name}' needs a Newtonian problem .* 'gaussian' is a first-order"
    with pytest.raises(IncompatibleError, match=pattern):
        stepper.integrate(get_problem("gaussian"), h=0.1, n_steps=10)


@pytest.mark.parametrize(
    "stepper", [s for s in NEWTONIAN if not s.info.velocity_dependent],
    ids=ids([s for s in NEWTONIAN if not s.info.velocity_dependent]),
)
def test_velocity_independent_stepper_refuses_a_damped_problem(stepper):
    with pytest.raises(IncompatibleError, match=r"needs an acceleration independent of velocity"):
        stepper.round_trip(get_problem("damped-cubic"), h=0.1, n_steps=10)


# -- claims: symmetry and order ----------------------------------------------------------------------
@pytest.mark.parametrize("stepper", FIXED, ids=ids(FIXED))
def test_round_trip_returns_exactly_when_symmetric(stepper):
    start, back = stepper.round_trip(_harmonic(), **ROUND_TRIP)
    miss = float(np.max(np.abs(back - start)))
    if stepper.info.symmetric:
        assert miss <= SYMMETRIC_RETURN
    else:
        assert miss >= NON_SYMMETRIC_MISS


@pytest.mark.parametrize("stepper", FIXED, ids=ids(FIXED))
def test_quick_order_on_harmonic(stepper):
    P = _harmonic()
    p = stepper.info.claimed_order
    exact = P.exact(1.0, P.y0[:, None], 0.0, None)
    errors = []
    for n in (ORDER_STEPS[p], 2 * ORDER_STEPS[p]):
        final = stepper.integrate(P, h=1.0 / n, n_steps=n).final
        errors.append(float(np.max(np.abs(final - exact))))
    assert min(errors) > ROUNDOFF_MARGIN * 2 * ORDER_STEPS[p] * EPS, "stay above rounding"
    assert abs(math.log2(errors[0] / errors[1]) - p) <= ORDER_TOL


@functools.cache
def _time_dependent_case(form: str) -> tuple[Problem, np.ndarray]:
    if form == "first-order":
        P = get_problem("gaussian")
        return P, P.exact(1.0, P.y0[:, None], 0.0, None)
    duffing = get_problem("forced-duffing")
    P = Problem(  # started away from rest, so every term of the force matters from t = 0
        "forced-duffing-moving", variables=duffing.variables, newtonian=duffing.newtonian,
        y0=[0.5, 0.3], t_span=(0.0, 1.0),
    )
    return P, get_stepper("taylor").integrate(P, h=1.0, n_steps=1).final


@pytest.mark.parametrize("stepper", FIXED, ids=ids(FIXED))
def test_quick_order_with_explicit_time_dependence(stepper):
    """Stage and kick times: gaussian y' = -t y (first order, exact exp(-t^2/2)) or the forced
    Duffing oscillator (Newtonian, against the Taylor integrator)."""
    p = stepper.info.claimed_order
    P, target = _time_dependent_case(stepper.info.form)
    n0 = ORDER_STEPS[p] // 2 if p >= 6 else ORDER_STEPS[p]
    errors = [
        float(np.max(np.abs(stepper.integrate(P, h=1.0 / n, n_steps=n).final - target)))
        for n in (n0, 2 * n0)
    ]
    assert min(errors) > ROUNDOFF_MARGIN * 2 * n0 * EPS
    assert abs(math.log2(errors[0] / errors[1]) - p) <= 2 * ORDER_TOL


# -- method-specific checks ----------------------------------------------------------------------------
def test_stormer_verlet_reproduces_the_course_recurrence():
    """Course file 000, Example 1: x_1 = h^2/20, then x_{n+1} = 2x_n - x_{n-1} + h^2 a(x_n, t_n)."""
    P = get_problem("forced-duffing")
    h, n = 1e-3, 400
    x = np.zeros(n + 1)
    x[1] = h**2 / 20.0
    for k in range(1, n):
        x[k + 1] = 2.0 * x[k] - x[k - 1] + h**2 * (-x[k] + x[k] ** 3 + 0.1 * np.cos(k * h))
    tr = get_stepper("stormer-verlet").integrate(P, h=h, n_steps=n, save_steps=range(n + 1))
    positions, velocities = tr.y[:, 0, 0], tr.y[:, 1, 0]
    assert positions[1] == pytest.approx(h**2 / 20.0, rel=1e-15)
    np.testing.assert_allclose(positions, x, rtol=1e-12, atol=1e-20)
    # Velocity: v_0 as given, then the central difference of the positions.
    assert velocities[0] == 0.0
    central = (positions[2:] - positions[:-2]) / (2 * h)
    np.testing.assert_allclose(velocities[1:-1], central, rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("name", ["stormer-verlet", "verlet-damped"])
def test_two_step_recurrence_has_local_error_of_order_h4(name):
    """Course file 000: from exact x_(n-1), x_n the recurrence misses x_(n+1) by O(h^4)."""
    P = get_problem("pendulum")
    stepper = get_stepper(name)
    assert stepper.history_length == 2
    errors = []
    for h in (0.1, 0.05):
        exact = get_stepper("taylor").integrate(P, h=h, n_steps=2, save_steps=[0, 1, 2]).y
        step = stepper.step_from_history(P, h=h, history=[exact[0], exact[1]])
        errors.append(abs(step[0, 0] - exact[2][0, 0]))
    assert abs(math.log2(errors[0] / errors[1]) - 4) <= ORDER_TOL


def test_stormer_verlet_taylor_start_uses_the_initial_velocity():
    P = _harmonic()
    h = 0.1
    tr = get_stepper("stormer-verlet").integrate(P, h=h, n_steps=1, y0=[1.0, 0.3])
    assert tr.final[0, 0] == pytest.approx(1.0 + 0.3 * h - h * h / 2.0, rel=1e-15)


def test_stormer_verlet_equals_velocity_verlet():
    """HLW I.1.4: the two-step form with the central-difference velocity is velocity Verlet."""
    P = get_problem("kepler-elliptic")
    a = get_stepper("stormer-verlet").integrate(P, h=0.01, n_steps=200, save_steps=range(201))
    b = get_stepper("velocity-verlet").integrate(P, h=0.01, n_steps=200, save_steps=range(201))
    np.testing.assert_allclose(a.y, b.y, rtol=0, atol=1e-11)


def test_verlet_damped_matches_the_course_closed_form():
    """Course file 000, Example 2: x_1 = 10 - 500 h^2, then
    x_{n+1} = (2x_n - (1 - h/2) x_{n-1} - h^2 x_n^3) / (1 + h/2), h = 0.001 to t = 3."""
    h, n = 1e-3, 3000
    x = np.zeros(n + 1)
    x[0], x[1] = 10.0, 10.0 - 500.0 * h**2
    for k in range(1, n):
        x[k + 1] = (2.0 * x[k] - (1.0 - h / 2) * x[k - 1] - h**2 * x[k] ** 3) / (1.0 + h / 2)
    tr = get_stepper("verlet-damped").integrate(
        get_problem("damped-cubic"), h=h, n_steps=n, save_steps=range(n + 1)
    )
    np.testing.assert_allclose(tr.y[:, 0, 0], x, rtol=1e-13, atol=1e-13)


def test_leapfrog_and_velocity_verlet_agree():
    P = get_problem("kepler-elliptic")
    a = get_stepper("leapfrog").integrate(P, h=0.01, n_steps=300, save_steps=range(301))
    b = get_stepper("velocity-verlet").integrate(P, h=0.01, n_steps=300, save_steps=range(301))
    np.testing.assert_allclose(a.y[:, :2], b.y[:, :2], rtol=0, atol=1e-13)  # positions
    np.testing.assert_allclose(a.y[:, 2:], b.y[:, 2:], rtol=0, atol=1e-12)  # synchronised v


def test_leapfrog_staggers_the_velocity():
    """Half-step start v_1/2 = v_0 + h a_0 / 2 (course file 004): after one step the position is
    x_0 + h v_1/2, and the reported velocity is synchronised to v_1 = v_1/2 + h a_1 / 2."""
    h = 0.1
    tr = get_stepper("leapfrog").integrate(_harmonic(), h=h, n_steps=1, y0=[1.0, 0.5])
    v_half = 0.5 + h / 2 * (-1.0)
    x1 = 1.0 + h * v_half
    assert tr.final[0, 0] == pytest.approx(x1, rel=1e-15)
    assert tr.final[1, 0] == pytest.approx(v_half + h / 2 * (-x1), rel=1e-14)


# Local problems for the implicit branches of verlet-damped: a force nonlinear in v (Newton) and
# one linear in v with a position-dependent coefficient (van der Pol, closed form per step).
_x, _v = hy.make_vars("x", "v")
CUBIC_DRAG = Problem(
    "cubic-drag", variables=[_x, _v],
    newtonian=NewtonianForm((_x,), (_v,), (-_x - 0.5 * _v * _v * _v,)),
    y0=[1.0, 0.5], t_span=(0.0, 2.0),
)
VAN_DER_POL = Problem(
    "van-der-pol-newtonian", variables=[_x, _v],
    newtonian=NewtonianForm((_x,), (_v,), ((1.0 - _x * _x) * _v - _x,)),
    y0=[2.0, 0.0], t_span=(0.0, 2.0),
)
QUADRATIC_PUSH = Problem(
    "quadratic-push", variables=[_x, _v],
    newtonian=NewtonianForm((_x,), (_v,), (_v * _v,)),
    y0=[0.0, 1.0], t_span=(0.0, 2.0),
)


def _implicit_residual(P, tr, accel):
    """x_{n+1} - 2x_n + x_{n-1} - h^2 a(x_n, (x_{n+1} - x_{n-1})/2h) at every inner step."""
    h = tr.h
    x = tr.y[:, 0, 0]
    v = (x[2:] - x[:-2]) / (2 * h)
    return x[2:] - 2 * x[1:-1] + x[:-2] - h * h * accel(x[1:-1], v)


@pytest.mark.parametrize(
    "problem, accel, jac_per_step",
    [
        (CUBIC_DRAG, lambda x, v: -x - 0.5 * v**3, None),
        (VAN_DER_POL, lambda x, v: (1.0 - x * x) * v - x, 1),
    ],
    ids=["newton", "linear-in-v"],
)
def test_verlet_damped_solves_the_implicit_equation(problem, accel, jac_per_step):
    stepper = get_stepper("verlet-damped")
    n = 200
    tr = stepper.integrate(problem, h=0.01, n_steps=n, save_steps=range(n + 1))
    residual = _implicit_residual(problem, tr, accel)
    assert np.max(np.abs(residual)) <= 1e-14
    if jac_per_step is not None:
        assert tr.evals["jac"] == jac_per_step * n
    # Second order against the Taylor integrator.
    target = get_stepper("taylor").integrate(problem, h=1.0, n_steps=1).final
    errors = [
        float(np.max(np.abs(stepper.integrate(problem, h=1.0 / m, n_steps=m).final - target)))
        for m in (64, 128)
    ]
    assert abs(math.log2(errors[0] / errors[1]) - 2) <= ORDER_TOL


def test_verlet_damped_reports_a_newton_failure():
    # x'' = v^2 with h = 1 from v = 1: the central-difference equation for x_2 has no real root.
    with pytest.raises(StepFailure, match=r"Newton's method for x_\(n\+1\) .* did not converge"):
        get_stepper("verlet-damped").integrate(QUADRATIC_PUSH, h=1.0, n_steps=3)


# -- the Taylor stepper -----------------------------------------------------------------------------
def test_taylor_is_accurate_to_its_tolerance():
    P = _harmonic()
    y0 = P.ensemble(4, seed=2)
    tr = get_stepper("taylor").integrate(P, h=0.5, n_steps=20, y0=y0)
    exact = P.exact(10.0, y0, 0.0, None)
    assert np.max(np.abs(tr.final - exact)) <= 1e3 * EPS
    loose = get_stepper("taylor").with_tolerance(1e-6)
    assert loose.tol == 1e-6 and loose.info.extra["tol"] == 1e-6
    assert get_stepper("taylor").tol == EPS


def test_taylor_uses_each_members_parameters():
    P = get_problem("dahlquist")
    pars = np.array([[-1.0, -0.5, 0.2], [0.0, 2.0, -1.0]])  # lambda_re, lambda_im per member
    y0 = np.repeat(P.y0[:, None], 3, axis=1)
    tr = get_stepper("taylor").integrate(P, h=0.25, n_steps=4, y0=y0, pars=pars)
    exact = P.exact(1.0, y0, 0.0, pars)
    np.testing.assert_allclose(tr.final, exact, rtol=0, atol=1e3 * EPS)


def test_taylor_rejects_a_bad_tolerance():
    with pytest.raises(InputError, match=r"`tol` must be a positive finite number, got -1.0"):
        get_stepper("taylor").with_tolerance(-1.0)
