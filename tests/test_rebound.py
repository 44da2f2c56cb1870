"""The REBOUND adapter (implementations/rebound_adapter.py): REBOUND's integrators run with its own
gravity on problems that declare an N-body structure. The adapter without REBOUND is tested with
the other optional adapters in tests/test_steppers.py."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from harness.errors import IncompatibleError
from harness.ground_truth import reference
from harness.problem import NBody, Problem
from harness.registry import get_problem, steppers
from harness.stepper import check_compatible
from implementations import rebound_adapter
from problems.planetary import PLANETS_ENCOUNTER

HAVE_REBOUND = importlib.util.find_spec("rebound") is not None
needs_rebound = pytest.mark.skipif(
    not HAVE_REBOUND, reason="REBOUND is not installed (optional extra: pip install .[rebound])"
)
ADAPTED = {s.info.name: s for s in rebound_adapter.STEPPERS}


def get_stepper(name: str):
    return ADAPTED[name]


@needs_rebound
def test_in_the_default_registry_every_rebound_integrator_is_registered():
    names = [s.info.name for s in rebound_adapter.STEPPERS]
    assert len(names) == 7
    assert all(n in steppers.names() and steppers.origin(n) == "builtin" for n in names)


@needs_rebound
def test_with_rebound_nothing_is_listed_unavailable():
    from implementations import unavailable_steppers

    assert "rebound" not in unavailable_steppers()


def _errors(name: str, problem: str, steps: list[int], members: int = 2) -> np.ndarray:
    P = PLANETS_ENCOUNTER if problem == PLANETS_ENCOUNTER.name else get_problem(problem)
    T = P.convergence_t_end
    y0 = P.ensemble(members)
    exact = reference(P, np.array([T]), y0).y[-1]
    s = get_stepper(name)
    return np.array([np.max(np.abs(s.integrate(P, h=(T - P.t0) / n, n_steps=n, y0=y0).final - exact))
                     for n in steps])


def _slopes(errors: np.ndarray) -> np.ndarray:
    return -np.diff(np.log2(errors))


@needs_rebound
@pytest.mark.parametrize(
    "name, problem, steps, order",
    [
        ("rebound-leapfrog", "kepler-circular", [200, 400, 800], 2.0),
        ("rebound-whfast", "outer-solar-system", [200, 400, 800], 2.0),
        ("rebound-mercurius", "planets-encounter", [400, 800, 1600], 2.0),
        ("rebound-sabacl4", "planets-encounter", [400, 800, 1600], 4.0),
    ],
)
def test_fixed_step_orders(name, problem, steps, order):
    slopes = _slopes(_errors(name, problem, steps))
    assert np.all(np.abs(slopes - order) < 0.1), slopes


def _two_planets(mu: float) -> Problem:
    """Two planets of mass mu on near-circular orbits (a = 1 and 1.6) about a unit mass."""
    s = NBody(masses=(1.0, mu, mu), G=1.0, frame="heliocentric", names=("star", "b", "c"))
    variables, form, invariants = s.derive()
    y0 = [1.0, 0.0, 0.0, 0.0, 1.6, 0.02, 0.0, math.sqrt(1 + mu), 0.0, -math.sqrt((1 + mu) / 1.6), 0.0, 0.0]
    return Problem(f"two-planets-{mu:g}", variables=variables, newtonian=form, y0=y0,
                   t_span=(0.0, 20.0), invariants=invariants, structure=s, reference="test system")


@needs_rebound
def test_error_scales_with_the_perturbation_as_documented():
    """At h = 0.1 over 20 time units, masses 1e-3 -> 1e-4 -> 1e-5: leapfrog's error does not
    depend on the perturbation eps, WHFast's and MERCURIUS's scale as eps (eps h^2), the
    corrected WHFast's and SABA4's as eps^2 (their eps h^18, eps h^8 terms are far smaller)."""
    expected = {"rebound-leapfrog": 0.0, "rebound-whfast": 1.0, "rebound-mercurius": 1.0,
                "rebound-whfast-c17": 2.0, "rebound-saba4": 2.0}
    errors = {name: [] for name in expected}
    for mu in (1e-3, 1e-4, 1e-5):
        P = _two_planets(mu)
        exact = reference(P, np.array([20.0]), P.y0[:, None]).y[-1]
        for name in expected:
            errors[name].append(np.max(np.abs(get_stepper(name).integrate(P, h=0.1, n_steps=200).final
                                              - exact)))
    for name, power in expected.items():
        exponents = np.diff(np.log10(errors[name])) / np.diff(np.log10([1e-3, 1e-4, 1e-5]))
        assert np.all(np.abs(exponents - power) < 0.15), (name, errors[name], exponents)
        law = get_stepper(name).info.extra["perturbation_error"]
        if law is not None:
            assert min(t[0] for t in law if t[1] <= 2) == power


@needs_rebound
@pytest.mark.parametrize("name", ["rebound-whfast", "rebound-saba4", "rebound-mercurius"])
def test_kepler_split_maps_are_exact_on_an_unperturbed_orbit(name):
    """A Wisdom-Holman-type map's drift is the Kepler flow: on the two-body problem only rounding
    remains, at every step size (the fact `kepler_flow_exact` records)."""
    assert get_stepper(name).info.extra["kepler_flow_exact"]
    assert np.all(_errors(name, "kepler-elliptic", [8, 64]) < 1e-12)
    assert np.all(_errors("rebound-leapfrog", "kepler-elliptic", [8, 64]) > 1e-3)


@needs_rebound
@pytest.mark.parametrize("problem", ["kepler-elliptic", "outer-solar-system"])
def test_state_round_trips_through_a_simulation(problem):
    """Zero steps: the state read back from REBOUND is the state put in (frame and order)."""
    P = get_problem(problem)
    y0 = P.ensemble(3)
    tr = get_stepper("rebound-whfast").integrate(P, h=1.0, n_steps=1, y0=y0, save_steps=[0])
    assert np.array_equal(tr.y[0], y0)


@needs_rebound
def test_members_are_separate_simulations():
    P = get_problem("outer-solar-system")
    y0 = P.ensemble(3)
    s = get_stepper("rebound-saba4")
    together = s.integrate(P, h=50.0, n_steps=20, y0=y0).final
    for m in range(3):
        alone = s.integrate(P, h=50.0, n_steps=20, y0=y0[:, m]).final[:, 0]
        assert np.array_equal(together[:, m], alone)


@needs_rebound
def test_symmetric_maps_return_and_ias15_meets_its_tolerance():
    P = get_problem("outer-solar-system")
    start, back = get_stepper("rebound-whfast").round_trip(P, h=43.0, n_steps=500)
    assert np.max(np.abs(back - start)) < 1e-10 * np.max(np.abs(start))
    K = get_problem("kepler-elliptic")
    exact = reference(K, np.array([K.convergence_t_end]), K.y0[:, None]).y[-1]
    ias15 = get_stepper("rebound-ias15").with_tolerance(1e-9)
    tr = ias15.integrate(K, h=K.convergence_t_end, n_steps=1)
    assert np.max(np.abs(tr.final - exact)) < 1e-9 and tr.evals["internal_steps"] > 10


@needs_rebound
def test_a_problem_without_nbody_structure_is_incompatible_with_a_reason():
    with pytest.raises(IncompatibleError, match="declares its masses, G and central body"):
        check_compatible(get_stepper("rebound-whfast"), get_problem("harmonic"))


@needs_rebound
def test_rebound_claims_through_the_public_api():
    """The gate in another project's suite, on an outside integrator: WHFast's documented claims
    hold on the outer solar system; claiming order 4 for it fails with the measured table."""
    from harness.api import ClaimError, check

    report = check(get_stepper("rebound-whfast"), ["outer-solar-system"], order=2, symmetric=True,
                   energy="bounded")
    assert report.passed and len(report.table) == 3
    with pytest.raises(ClaimError, match=r"measured order 2\.\d+ differs from the expected 4"):
        check(get_stepper("rebound-whfast"), ["outer-solar-system"], order=4)
