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


def test_a_missing_catalogue_module_is_an_error_not_a_smaller_catalogue(monkeypatch):
    import problems as catalogue

    monkeypatch.setattr(catalogue, "PROBLEM_MODULES", (*catalogue.PROBLEM_MODULES, "renamed_family"))
    with pytest.raises(ModuleNotFoundError, match="problems.renamed_family"):
        catalogue.builtin_problems()


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


# -- derived time scales and ensemble perturbations (harness.scales) ------------------------------
from helpers import plugin_problem  # noqa: E402

from harness import regimes, scales  # noqa: E402
from harness import tolerances as tol  # noqa: E402

# The step sizes of the hand-kept table the derived time scale replaced (period / steps per
# period, chosen per problem for h omega ~ 0.1): the derivation must land near them unaided.
HAND_TUNED_H = {
    "harmonic": 2 * math.pi / 64, "pendulum": 6.534 / 64, "pendulum-small": 6.286 / 64,
    "kepler-circular": 16 * math.pi / 64, "kepler-elliptic": 2 * math.pi / 256,
    "henon-heiles": 2 * math.pi / 64, "henon-heiles-chaotic": 2 * math.pi / 64,
    "outer-solar-system": 4332.59 / 100, "lennard-jones": 0.4 / 64,
}  # (free-fall's entry, span / 64, was no dynamical scale: its Jacobian is nilpotent)


@pytest.fixture(scope="module")
def pleiades():
    return plugin_problem("pleiades.py", "pleiades")


@pytest.fixture(scope="module")
def quartic():
    return plugin_problem("quartic.py", "quartic-oscillator")


@pytest.fixture
def plugin_problems(pleiades, quartic, registered):
    """The two plugin problems registered for one test, then removed again."""
    return [registered(p) for p in (pleiades, quartic)]


def _undeclared(problem: Problem, **changes) -> Problem:
    """The same definition without its declared period (or with other keyword changes)."""
    kw = dict(variables=problem.variables, newtonian=problem.newtonian, y0=problem.y0,
              t_span=(problem.t0, problem.t_end), parameters=problem.parameters,
              invariants=problem.invariants, conservative=problem.conservative)
    if problem.newtonian is None:
        kw["rhs"] = problem.rhs
    kw.update(changes)
    return Problem(problem.name + "-undeclared", **kw)


@pytest.mark.parametrize("problem", ALL, ids=IDS)
def test_time_scale_is_derived_from_the_dynamics(problem: Problem):
    ts = problem.time_scale
    assert ts.period > 0 and ts.h > 0 and ts.reason
    if problem.period is not None:
        assert ts.source == "declared" and ts.period == problem.period
    if ts.fastest_rate > 0:
        assert ts.h * ts.fastest_rate == pytest.approx(tol.STEP_RATE_PRODUCT)


@pytest.mark.parametrize("name", sorted(HAND_TUNED_H))
def test_derived_step_lands_near_the_hand_tuned_table_it_replaced(name):
    h = problems.get(name).time_scale.h
    assert HAND_TUNED_H[name] / 1.5 <= h <= HAND_TUNED_H[name] * 1.5, (name, h)


def test_derived_period_is_the_orbital_period_where_the_linearisation_knows_it():
    """Without its declared period, the circular Kepler orbit (2 pi / a^(-3/2) = 16 pi) and the
    harmonic oscillator (2 pi) get their exact periods from max|Im lambda(J)| along the orbit;
    the outer solar system gets Jupiter's, 4332.59 days, to within 10 %."""
    circular = _undeclared(problems.get("kepler-circular"))
    assert circular.time_scale.period == pytest.approx(16 * math.pi, rel=1e-9)
    assert _undeclared(problems.get("harmonic")).time_scale.period == pytest.approx(2 * math.pi, rel=1e-12)
    assert problems.get("outer-solar-system").time_scale.period == pytest.approx(4332.59, rel=0.1)


def test_a_horizon_not_declared_is_cut_to_natural_periods(quartic):
    assert quartic.declared_convergence_t_end is None
    assert quartic.convergence_t_end == pytest.approx(
        min(quartic.t_end, quartic.t0 + tol.HORIZON_PERIODS * quartic.time_scale.period))


def test_ensemble_members_do_not_depend_on_the_ensemble_size():
    p = problems.get("kepler-elliptic")
    assert np.array_equal(p.ensemble(4, seed=3), p.ensemble(9, seed=3)[:, :4])
    big = p.ensemble(9, seed=3, scale=1e-3)
    assert np.array_equal(big[:, 0], p.y0)
    # zero components (y, vx) move relative to their block's scale, never by an absolute 1e-2
    scale = p.ensemble_perturbation.component_scale
    assert np.all(scale > 0) and np.all(np.abs(big - p.y0[:, None]) <= 1e-3 * scale[:, None] + 1e-300)


def test_bad_perturbation_is_refused_with_the_argument_named():
    with pytest.raises(InputError, match=r"`perturbation` must be a positive finite number"):
        problems.get("harmonic").ensemble(4, scale=-0.1)
    with pytest.raises(InputError, match=r"`period` must be a positive finite number"):
        _undeclared(problems.get("harmonic"), period=float("inf"))


def _closest_approach(problem: Problem, y0: np.ndarray) -> float:
    """Smallest pair distance of the seven bodies along the float64 orbit from y0 over [0, 3]."""
    y = scales.sample_orbit(problem, y0).y
    x, yy = y[:7], y[7:14]
    return min(float(np.min(np.hypot(x[a] - x[b], yy[a] - yy[b])))
               for a in range(7) for b in range(a + 1, 7))


def test_pleiades_members_keep_the_closest_approach_of_the_unperturbed_start(pleiades):
    """The derived perturbation keeps every member of a 16-member ensemble within a factor 2 of
    the unperturbed closest approach (3.4e-2); the old default, 1 % of each component and an
    absolute 1e-2 on zero components, sent members within 2e-3 of a collision."""
    base = _closest_approach(pleiades, pleiades.y0)
    assert base == pytest.approx(3.4e-2, rel=0.05)
    members = pleiades.ensemble(tol.ENSEMBLE_SIZE)
    closest = [_closest_approach(pleiades, members[:, j]) for j in range(1, members.shape[1])]
    assert base / 2 <= min(closest) and max(closest) <= 2 * base, closest
    assert pleiades.ensemble_perturbation.size < tol.ENSEMBLE_PERTURBATION
    # The old ensemble, drawn as it was (seed 0, shape (dim, 16)): several members leave the regime.
    magnitude = np.where(pleiades.y0 != 0.0, np.abs(pleiades.y0), 1.0)
    noise = np.random.default_rng(0).uniform(-1e-2, 1e-2, size=(pleiades.dim, tol.ENSEMBLE_SIZE))
    old = pleiades.y0[:, None] + noise * magnitude[:, None]
    old_closest = [_closest_approach(pleiades, old[:, j]) for j in range(1, tol.ENSEMBLE_SIZE)]
    assert sum(c < base / 10 for c in old_closest) >= 3, old_closest


def test_plugin_problems_get_every_experiment_that_applies(plugin_problems):
    """A user's problems, named nowhere in the harness: the quartic oscillator (an invariant,
    q'' = a(q)) and the Pleiades (an invariant, q'' = a(q) with masses) get energy,
    reversibility, symplecticity and work-precision cells, with no skip."""
    from harness.experiments import get_experiment

    for exp_name in ("energy", "reversibility", "symplecticity", "work-precision"):
        exp = get_experiment(exp_name)
        cells, skips = exp.cells(["velocity-verlet", "rk4"], plugin_problems, exp.config(quick=True))
        assert not skips, (exp_name, skips)
        assert {c.problem for c in cells} == set(plugin_problems), exp_name


def test_plugin_problems_verdicts(plugin_problems):
    """The plugin problems measured: velocity Verlet keeps the quartic oscillator's energy
    bounded and its maps are symplectic on both (the Pleiades' in the mass-weighted form, probed
    at its closest encounter), while rk4's are clearly not; the perturbation is stated."""
    from harness.runner import run_experiment

    def run(name, probs, **cfg):
        result = run_experiment(name, ["velocity-verlet", "rk4"], probs, quick=True, config=cfg,
                                jobs=1, cache=False, progress=False)
        assert not len(result.failures), result.failures
        return result.summary.set_index(["stepper", "problem"])

    energy = run("energy", ["quartic-oscillator"], ensemble=2, steps=4000)
    vv = energy.loc[("velocity-verlet", "quartic-oscillator")]
    assert vv.verdict == "as-claimed" and vv.perturbation == pytest.approx(
        problems.get("quartic-oscillator").ensemble_perturbation.size)
    sym = run("symplecticity", plugin_problems)
    for p in plugin_problems:
        assert sym.loc[("velocity-verlet", p)].verdict == "symplectic", p
        assert sym.loc[("rk4", p)].verdict == "non-symplectic", p


def test_applicability_follows_facts_and_says_why():
    from harness.experiments.common import hamiltonian_reason, hamiltonian_weights, reversible_reason

    assert "velocity-dependent" in reversible_reason(problems.get("damped-cubic"))
    assert "time-dependent" in hamiltonian_reason(problems.get("forced-duffing"))
    assert "first-order" in hamiltonian_reason(problems.get("van-der-pol-stiff"))
    oss = problems.get("outer-solar-system")
    w = hamiltonian_weights(oss)
    masses = np.repeat([1.00000597682, 0.000954786104043, 0.000285583733151, 0.0000437273164546,
                        0.0000517759138449, 1.0 / 1.3e8], 3)
    assert w == pytest.approx(masses / masses.max(), rel=1e-6)


def test_long_runs_stop_where_the_orbit_leaves_the_regime_of_its_span(pleiades):
    """Past its span [0, 3] the Pleiades comes closer than any encounter within it: a long run
    stops before that and says why; an oscillator's long run is never stopped."""
    stop, why = regimes.regime_end(pleiades, 18.0)
    assert pleiades.t_end <= stop < 18.0 and "leaves the regime" in why
    harmonic = problems.get("harmonic")
    assert regimes.regime_end(harmonic, 1e4) == (1e4, "")
    assert pleiades.time_scale.rate_contrast > 10 * harmonic.time_scale.rate_contrast
