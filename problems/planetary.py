"""Planetary systems: two well-separated massive planets (`planets-pair`) and a close encounter
(`planets-encounter`).

`planets-pair`: a star of unit mass and two planets of mass 1e-2 (G = 1; eps = 1e-2, ten times
Jupiter's ratio, so the interaction terms of Wisdom-Holman-type maps, eps^2 h^2 and eps^2 h^4,
stand well above float64 rounding over a decade of steps) on near-circular orbits at a = 1 and
a = 2.5 (e = 0.05, mutual inclination 0.02): 4.5 mutual Hill radii apart, beyond the 2 sqrt(3)
Hill-stability limit (Gladman 1993), so no encounter ever happens. Span: 20 inner orbits;
convergence horizon: 2 inner orbits (t = 4 pi): over 10 the built-in RK4 and RK3/8 sweeps stay
pre-asymptotic (4.37, 4.23) and scipy's RK45 and BDF miss their tolerance. In the default
catalogue.

A star of unit mass and two Jupiter-mass planets (m = 1e-3, G = 1, so the inner orbit has period
2 pi). The inner planet starts on a circular orbit at a = 1 (true anomaly 3.2); the outer one on
an eccentric orbit (a = 1.35, e = 0.3, inclination 0.02, true anomaly 0.785) whose pericentre
(0.945) lies inside the inner orbit. Near t = 8.4 the planets pass within ~0.04 of each other,
about 0.6 Hill radii (r_H = a (m / 3M)^(1/3) = 0.069): the interaction force grows several
hundredfold for a fraction of an orbit, the regime for which hybrid schemes switch from a
Wisdom-Holman map to a direct integrator. Span [0, 4 pi] (two inner orbits) holds the encounter;
the convergence experiment uses the whole span, so every step-size sweep has to resolve it.

`planets-encounter` is listed on request only (tag `on-request`: `--problem planets-encounter`).
Measured on the convergence experiment's full
settings, the encounter leaves euler, symplectic Euler, backward Euler, rk38, yoshida6, yoshida8
and SABAC4 `insufficient-range` (the encounter amplifies rounding above the sweep's rounding level
sqrt(n) eps |y|, so the floor is read as a pre-asymptotic range) and scipy's RK45 and BDF miss their
tolerance by 2e4 and 2e5 x tol: every registry-wide gate would fail on it until the gate's rules
account for flow-amplified rounding.

Initial state: heliocentric orbital elements converted to Cartesian coordinates with
mu = G (M + m_i) (Murray & Dermott, Solar System Dynamics, 1999, 2.8), then shifted to the
barycentre, so the system's centre of mass rests at the origin.
References: J. E. Chambers, MNRAS 304 (1999) 793-799 (close encounters and the hybrid
symplectic integrator); H. Rein, D. Tamayo, MNRAS 452 (2015) 376-388 (WHFast);
Hairer, Lubich & Wanner, Geometric Numerical Integration (2006), I.2.4 (N-body problems).
"""

from __future__ import annotations

import math

import numpy as np

from harness.problem import NBody, Problem

__all__ = ["PROBLEMS", "PLANETS_PAIR", "PLANETS_ENCOUNTER", "elements_to_cartesian"]


def elements_to_cartesian(
    mu: float, a: float, e: float, inc: float, f: float
) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity on the orbit (a, e, inclination `inc`, true anomaly f), node and
    argument of pericentre zero: r = p/(1 + e cos f), p = a (1 - e^2), v from sqrt(mu/p).

    Parameters
    ----------
    mu : float, gravitational parameter G (M + m).
    a, e, inc, f : float, semi-major axis, eccentricity, inclination and true anomaly.

    Returns
    -------
    (ndarray, ndarray): position and velocity, each shape (3,).
    """
    p = a * (1.0 - e * e)
    r = p / (1.0 + e * math.cos(f))
    ci, si = math.cos(inc), math.sin(inc)
    pos = r * np.array([math.cos(f), math.sin(f) * ci, math.sin(f) * si])
    k = math.sqrt(mu / p)
    vel = k * np.array([-math.sin(f), (e + math.cos(f)) * ci, (e + math.cos(f)) * si])
    return pos, vel


_G = 1.0
_NAMES = ("star", "b", "c")


def _initial_state(masses: tuple[float, ...], elements: dict) -> list[float]:
    """Barycentric Cartesian state of a star (first body) and planets given by their elements."""
    pos = [np.zeros(3)]
    vel = [np.zeros(3)]
    for name, m in zip(_NAMES[1:], masses[1:], strict=True):
        r, v = elements_to_cartesian(_G * (masses[0] + m), *elements[name])
        pos.append(r)
        vel.append(v)
    masses = np.array(masses)
    com_r = sum(m * r for m, r in zip(masses, pos, strict=True)) / masses.sum()
    com_v = sum(m * v for m, v in zip(masses, vel, strict=True)) / masses.sum()
    pos = [r - com_r for r in pos]
    vel = [v - com_v for v in vel]
    return [float(c) for r in pos for c in r] + [float(c) for v in vel for c in v]


def _star_and_two_planets(name: str, masses: tuple[float, ...], elements: dict, **fields) -> Problem:
    """A star (the first of `masses`) and planets b and c started from their heliocentric
    `elements` (body: (a, e, inclination, true anomaly)), in G = 1 units and the barycentric frame:
    the equations of motion and the invariants are derived from the N-body structure."""
    structure = NBody(masses=masses, G=_G, central=0, frame="inertial", names=_NAMES)
    variables, newtonian, invariants = structure.derive()
    return Problem(name, variables=variables, newtonian=newtonian, y0=_initial_state(masses, elements),
                   invariants=invariants, conservative=True, structure=structure, **fields)


PLANETS_ENCOUNTER = _star_and_two_planets(
    "planets-encounter",
    masses=(1.0, 1.0e-3, 1.0e-3),
    elements={"b": (1.0, 0.0, 0.0, 3.2), "c": (1.35, 0.3, 0.02, 0.785)},
    t_span=(0.0, 4.0 * math.pi),
    # Ensemble members move each component by at most 1e-7 (relative; absolute for the star's
    # zero components): the encounter distance then changes by ~1e-6, far below its 0.04.
    perturbation=1e-7,
    description=(
        "Star (m = 1) and two planets (m = 1e-3) in G = 1 units, inner orbit circular at a = 1, "
        "outer orbit a = 1.35, e = 0.3 crossing it; a close encounter (distance ~0.04, 0.6 Hill "
        "radii) near t = 8.4 within the span [0, 4 pi]. 18 state variables, barycentric frame; "
        "energy, momentum and angular momentum are conserved."
    ),
    reference=(
        "J. E. Chambers, MNRAS 304 (1999) 793-799 (close encounters, hybrid symplectic "
        "integration); elements to Cartesian coordinates: Murray & Dermott, Solar System Dynamics "
        "(1999), 2.8."
    ),
    tags=("newtonian", "hamiltonian", "n-body", "close-encounter", "on-request"),
)

PLANETS_PAIR = _star_and_two_planets(
    "planets-pair",
    masses=(1.0, 1.0e-2, 1.0e-2),
    elements={"b": (1.0, 0.05, 0.0, 0.3), "c": (2.5, 0.05, 0.02, 2.0)},
    t_span=(0.0, 40.0 * math.pi),
    convergence_t_end=4.0 * math.pi,
    # Members move each component by at most 1e-6 (relative): far below the 1.5 separation.
    perturbation=1e-6,
    description=(
        "Star (m = 1) and two planets (m = 1e-2) in G = 1 units on near-circular orbits at a = 1 "
        "and a = 2.5 (e = 0.05), 4.5 mutual Hill radii apart: a perturbed Kepler problem with "
        "eps = 1e-2 and no encounter. 18 state variables, barycentric frame."
    ),
    reference=(
        "J. Laskar, P. Robutel, Celest. Mech. Dyn. Astron. 80 (2001) 39-62 (perturbed Kepler "
        "problems, eps-h error laws); B. Gladman, Icarus 106 (1993) 247 (Hill stability); "
        "Murray & Dermott, Solar System Dynamics (1999), 2.8."
    ),
    tags=("newtonian", "hamiltonian", "n-body"),
)

PROBLEMS: list[Problem] = [PLANETS_PAIR, PLANETS_ENCOUNTER]
