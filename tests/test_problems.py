"""The problem catalogue: every registered problem is a sane, self-consistent definition.

Swept over the registry, so a new problem is checked without a new test. Exact solutions are
checked against the equation itself (central differences of the formula against the right-hand
side), independently of heyoka.
"""

from __future__ import annotations

import math

import heyoka as hy
import numpy as np
import pytest

from harness.errors import InputError
from harness.problem import NewtonianForm, Problem
from harness.registry import problems
from problems.kepler import kepler_exact, orbital_elements
from problems.oscillators import pendulum_exact

CATALOGUE = {
    "gaussian",
    "dahlquist",
    "free-fall",
    "harmonic",
    "pendulum",
    "pendulum-small",
    "forced-duffing",
    "damped-cubic",
    "kepler-circular",
    "kepler-elliptic",
    "henon-heiles",
    "henon-heiles-chaotic",
    "outer-solar-system",
    "lennard-jones",
    "van-der-pol-stiff",
}
VELOCITY_DEPENDENT = {"damped-cubic"}

ALL = problems.all()
IDS = [p.name for p in ALL]
WITH_EXACT = [p for p in ALL if p.exact is not None]

# Exact solution at t0 against y0: the formulas evaluate trigonometric, exponential and elliptic
# functions, so a few units of rounding of the largest component are allowed.
EXACT_AT_T0_ULPS = 8


def test_catalogue_names_are_registered():
    assert CATALOGUE <= set(problems.names())


@pytest.mark.parametrize("problem", ALL, ids=IDS)
def test_definition_sanity(problem: Problem):
    assert problem.dim == len(problem.y0) == len(problem.rhs) == len(problem.variables)
    assert problem.description and problem.reference
    assert problem.t0 < problem.convergence_t_end <= problem.t_end
    y0 = problem.y0[:, None]
    f = problem.dynamics().f(problem.t0, y0.copy())
    assert f.shape == (problem.dim, 1) and np.all(np.isfinite(f))
    inv = problem.invariant_values(y0, problem.t0)
    assert set(inv) == set(problem.invariants)
    assert all(np.all(np.isfinite(v)) for v in inv.values())
    if problem.conservative:
        assert "energy" in problem.invariants
    info = problem.describe()
    assert info["name"] == problem.name and "approximations" in info


@pytest.mark.parametrize("problem", ALL, ids=IDS)
def test_newtonian_form_consistent(problem: Problem):
    assert problem.velocity_dependent == (problem.name in VELOCITY_DEPENDENT)
    nf = problem.newtonian
    if nf is None:
        assert problem.form == "first-order"
        return
    nq = len(nf.positions)
    assert len(nf.velocities) == nq and problem.dim == 2 * nq
    assert [str(e) for e in problem.rhs] == [str(e) for e in (*nf.velocities, *nf.acceleration)]
    y = problem.ensemble(3)
    dyn = problem.dynamics(size=3)
    f = dyn.f(problem.t0, y)
    a = dyn.accel(problem.t0, y[:nq], y[nq:])
    np.testing.assert_array_equal(f[:nq], y[nq:])
    np.testing.assert_allclose(a, f[nq:], rtol=1e-15, atol=0)


@pytest.mark.parametrize("problem", WITH_EXACT, ids=[p.name for p in WITH_EXACT])
def test_exact_solution_starts_at_y0(problem: Problem):
    y0 = problem.ensemble(8)
    pars = problem.pars_for(8)
    for fn in (problem.exact, *problem.approximations.values()):
        y = fn(problem.t0, y0, problem.t0, pars)
        assert y.shape == y0.shape
        scale = np.max(np.abs(y0)) + 1.0
        np.testing.assert_allclose(y, y0, rtol=0, atol=EXACT_AT_T0_ULPS * np.finfo(float).eps * scale)


@pytest.mark.parametrize("problem", WITH_EXACT, ids=[p.name for p in WITH_EXACT])
def test_exact_solution_solves_the_equation(problem: Problem):
    """d/dt exact(t) by a 4th-order central difference equals f(t, exact(t))."""
    n = 4
    y0 = problem.ensemble(n)
    pars = problem.pars_for(n)
    dyn = problem.dynamics(pars, n)
    span = problem.convergence_t_end - problem.t0
    for frac in (0.137, 0.5, 0.91):
        t = problem.t0 + frac * span
        d = 1e-3 * max(1.0, span / 50.0)
        ys = [problem.exact(t + k * d, y0, problem.t0, pars) for k in (-2, -1, 1, 2)]
        deriv = (ys[0] - 8 * ys[1] + 8 * ys[2] - ys[3]) / (12 * d)
        rhs = dyn.f(t, problem.exact(t, y0, problem.t0, pars))
        scale = np.max(np.abs(rhs)) + 1.0
        np.testing.assert_allclose(deriv, rhs, rtol=0, atol=1e-7 * scale)


@pytest.mark.parametrize(
    "problem", [p for p in WITH_EXACT if p.invariants], ids=[p.name for p in WITH_EXACT if p.invariants]
)
def test_exact_solution_keeps_the_invariants(problem: Problem):
    y0 = problem.ensemble(6)
    start = problem.invariant_values(y0, problem.t0)
    t = problem.convergence_t_end
    later = problem.invariant_values(problem.exact(t, y0, problem.t0, problem.pars_for(6)), t)
    for name in start:
        np.testing.assert_allclose(later[name], start[name], rtol=1e-12, atol=1e-13, err_msg=name)


def test_pendulum_small_angle_approximation_is_close_but_not_exact():
    problem = problems.get("pendulum-small")
    approx = problem.approximations["small-angle"]
    y0 = problem.y0[:, None]
    t = 2 * math.pi
    diff = np.max(np.abs(approx(t, y0, 0.0, None) - problem.exact(t, y0, 0.0, None)))
    # Period shift of the small-angle law: dT/T ~ theta0^2/16 ~ 4e-4; over one period the
    # phase error times the amplitude is ~2e-4.
    assert 1e-5 < diff < 5e-4


def test_pendulum_exact_period_matches_energy_conservation():
    problem = problems.get("pendulum")
    period = (problem.t_end - problem.t0) / 50.0
    y = pendulum_exact(period, problem.y0[:, None], 0.0)
    np.testing.assert_allclose(y[:, 0], problem.y0, atol=1e-14)


def test_exact_solutions_reject_unsupported_starts():
    with pytest.raises(InputError, match="librating"):
        pendulum_exact(1.0, np.array([[3.0], [1.0]]), 0.0)
    with pytest.raises(InputError, match="bound orbits"):
        kepler_exact(1.0, np.array([[1.0], [0.0], [0.0], [2.0]]), 0.0)


def test_kepler_invariants_include_runge_lenz():
    problem = problems.get("kepler-elliptic")
    inv = problem.invariant_values(problem.y0[:, None])
    np.testing.assert_allclose(inv["energy"], -0.5, rtol=1e-15)
    np.testing.assert_allclose(np.hypot(inv["runge_lenz_x"], inv["runge_lenz_y"]), 0.6, rtol=1e-15)
    assert problem.central_force and problem.conservative
    elements = orbital_elements(problem.y0[:, None])
    np.testing.assert_allclose([elements["a"][0], elements["e"][0]], [1.0, 0.6], rtol=1e-15)
    np.testing.assert_allclose(elements["period"], 2 * math.pi, rtol=1e-15)


# -- invalid definitions ---------------------------------------------------------------------------
_x, _v = hy.make_vars("x", "v")


def _make(**overrides):
    kwargs = dict(
        variables=[_x, _v],
        newtonian=NewtonianForm(positions=(_x,), velocities=(_v,), acceleration=(-_x,)),
        y0=[1.0, 0.0],
        t_span=(0.0, 1.0),
    )
    kwargs.update(overrides)
    return Problem("invalid", **kwargs)


@pytest.mark.parametrize(
    "overrides, match",
    [
        ({"y0": [1.0, 0.0, 2.0]}, r"`y0` needs 2 values"),
        ({"y0": [float("nan"), 0.0]}, r"`y0` must be finite"),
        ({"t_span": (1.0, 1.0)}, r"`t_span` must be finite with t_end > t0"),
        ({"t_span": (2.0, 1.0)}, r"`t_span` must be finite with t_end > t0"),
        ({"newtonian": None, "rhs": [_v, -hy.make_vars("z")]}, r"undeclared variables \['z'\]"),
        ({"newtonian": None, "rhs": [_v]}, r"`rhs` needs one expression per variable"),
    ],
    ids=["y0-length", "y0-nan", "empty-span", "reversed-span", "undeclared", "rhs-length"],
)
def test_invalid_definitions_raise(overrides, match):
    with pytest.raises(InputError, match=match):
        _make(**overrides)
