"""N-body structure (`harness.problem.NBody`): the right-hand side derived from masses, G and the
central body; the catalogue's N-body problems declare it; bad structures are one-line errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from harness.errors import InputError
from harness.ground_truth import reference
from harness.problem import NBody, Problem
from harness.registry import get_problem
from problems.planetary import PLANETS_ENCOUNTER


def _problem(name: str) -> Problem:
    """A catalogue problem, or the opt-in planetary system (a plugin file, not registered)."""
    return PLANETS_ENCOUNTER if name == PLANETS_ENCOUNTER.name else get_problem(name)


@pytest.mark.parametrize("name", ["kepler-circular", "kepler-elliptic", "outer-solar-system",
                                  "planets-encounter", "planets-pair"])
def test_catalogue_nbody_problems_declare_the_structure_their_rhs_comes_from(name):
    problem = _problem(name)
    s = problem.structure
    assert isinstance(s, NBody)
    variables, form, _ = s.derive()
    assert [str(v) for v in variables] == [str(v) for v in problem.variables]
    assert [str(a) for a in form.acceleration] == [str(a) for a in problem.newtonian.acceleration]
    assert problem.describe()["structure"]["masses"] == list(s.masses)


def test_fixed_centre_kepler_is_the_textbook_form():
    _, form, inv = NBody(masses=(1.0, 0.0), G=1.0, frame="heliocentric", dimension=2,
                         names=("sun", "")).derive()
    assert [str(a) for a in form.acceleration] == [
        "(-x / ((x * x) + (y * y))**1.5000000000000000)",
        "(-y / ((x * x) + (y * y))**1.5000000000000000)",
    ]
    assert "energy" in inv


def test_heliocentric_and_inertial_frames_agree_on_the_motion():
    """The same three bodies written both ways: heliocentric coordinates of the inertial solution
    equal the heliocentric solution, and both energies are conserved along it."""
    masses, G = (1.0, 1e-3, 2e-3), 1.0
    inertial = NBody(masses=masses, G=G, frame="inertial", names=("s", "p", "q"))
    helio = NBody(masses=masses, G=G, frame="heliocentric", names=("s", "p", "q"))
    r = {"p": np.array([1.0, 0.0, 0.01]), "q": np.array([0.0, 1.6, 0.0])}
    v = {"p": np.array([0.0, 1.0, 0.0]), "q": np.array([-0.8, 0.0, 0.02])}
    y_in = [0.0, 0.0, 0.0, *r["p"], *r["q"], 0.0, 0.0, 0.0, *v["p"], *v["q"]]
    y_he = [*r["p"], *r["q"], *v["p"], *v["q"]]
    problems = []
    for s, y0, label in ((inertial, y_in, "in"), (helio, y_he, "he")):
        variables, form, inv = s.derive()
        problems.append(Problem(f"three-body-{label}", variables=variables, newtonian=form, y0=y0,
                                t_span=(0.0, 5.0), invariants=inv, structure=s,
                                reference="test system"))
    times = np.array([5.0])
    a = reference(problems[0], times, problems[0].y0[:, None]).y[-1][:, 0]
    b = reference(problems[1], times, problems[1].y0[:, None]).y[-1][:, 0]
    star, planets = a[0:3], a[3:9].reshape(2, 3)
    star_v, planets_v = a[9:12], a[12:18].reshape(2, 3)
    assert np.allclose((planets - star).ravel(), b[:6], rtol=0, atol=1e-11)
    assert np.allclose((planets_v - star_v).ravel(), b[6:], rtol=0, atol=1e-11)
    for p, end in ((problems[0], a), (problems[1], b)):
        e0 = p.invariant_values(p.y0[:, None])["energy"][0]
        e1 = p.invariant_values(end[:, None])["energy"][0]
        assert abs(e1 - e0) <= 1e-12 * abs(e0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"masses": (1.0,), "G": 1.0}, "`masses` must be two or more"),
        ({"masses": (1.0, -1.0), "G": 1.0}, "`masses` must be two or more"),
        ({"masses": (1.0, 1.0), "G": 0.0}, "`G` must be positive"),
        ({"masses": (0.0, 1.0), "G": 1.0}, "`central` must index a body of positive mass"),
        ({"masses": (1.0, 1.0), "G": 1.0, "central": 5}, "`central` must index"),
        ({"masses": (1.0, 1.0), "G": 1.0, "frame": "jacobi"}, "`frame` must be"),
        ({"masses": (1.0, 1.0), "G": 1.0, "dimension": 1}, "`dimension` must be 2 or 3"),
        ({"masses": (1.0, 1.0), "G": 1.0, "names": ("a", "a")}, "`names` must name each"),
    ],
)
def test_bad_structures_are_input_errors(kwargs, match):
    with pytest.raises(InputError, match=match):
        NBody(**kwargs)


def test_a_structure_must_describe_the_problems_state():
    kepler = get_problem("kepler-circular")
    other = NBody(masses=(1.0, 0.0), G=1.0, frame="heliocentric", names=("sun", "planet"))
    with pytest.raises(InputError, match="`structure` describes the state"):
        Problem("mismatch", variables=kepler.variables, newtonian=kepler.newtonian, y0=kepler.y0,
                t_span=(0.0, 1.0), structure=other, reference="test")
    with pytest.raises(InputError, match="`structure` must be an NBody"):
        Problem("mismatch", variables=kepler.variables, newtonian=kepler.newtonian, y0=kepler.y0,
                t_span=(0.0, 1.0), structure={"masses": (1.0, 0.0)}, reference="test")


def test_perturbation_free_structures():
    assert get_problem("kepler-elliptic").structure.perturbation_free
    assert not get_problem("outer-solar-system").structure.perturbation_free
    assert not PLANETS_ENCOUNTER.structure.perturbation_free
    assert NBody(masses=(1.0, 0.0, 0.0), G=1.0).perturbation_free
    assert not NBody(masses=(1.0, 1e-3, 0.0), G=1.0).perturbation_free


def test_the_encounter_is_listed_on_request_and_passes_within_the_hill_radius():
    from harness.registry import problems

    assert "planets-encounter" not in problems.names()
    assert "planets-encounter" in problems.names(variants=True)
    P = problems.get("planets-encounter")
    times = np.linspace(8.3, 8.6, 31)
    y = reference(P, times, P.y0[:, None], t0=P.t0).y[:, :, 0]
    closest = np.min(np.linalg.norm(y[:, 3:6] - y[:, 6:9], axis=1))
    hill = (1e-3 / 3.0) ** (1.0 / 3.0)
    assert 0.5 * hill < closest < 0.7 * hill


def test_the_planet_pair_stays_beyond_the_hill_stability_limit_over_its_span():
    """planets-pair (default catalogue): eps = 1e-2 and the planets never closer than
    2 sqrt(3) mutual Hill radii (Gladman 1993) over the whole span."""
    from harness.perturbation_law import perturbation_size
    from harness.registry import problems

    P = problems.get("planets-pair")
    assert "planets-pair" in problems.names()
    assert perturbation_size(P) == pytest.approx(1e-2)
    times = np.linspace(P.t0, P.t_end, 400)[1:]
    y = reference(P, times, P.y0[:, None], t0=P.t0).y[:, :, 0]
    closest = np.min(np.linalg.norm(y[:, 3:6] - y[:, 6:9], axis=1))
    mutual_hill = (2e-2 / 3.0) ** (1.0 / 3.0) * (1.0 + 2.5) / 2.0
    assert closest > 2.0 * math.sqrt(3.0) * mutual_hill
