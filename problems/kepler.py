"""The planar Kepler problem r'' = -r/|r|^3 (GM = 1): `kepler-circular`, `kepler-elliptic` (e = 0.6)
and the highly eccentric `kepler-e0.9` and `kepler-e0.99` (same definition, other start).

The exact solution for any bound initial state comes from Kepler's equation written for the
change of eccentric anomaly x = E - E0 since t0 (Lagrange's f and g functions, e.g. Danby,
Fundamentals of Celestial Mechanics, 2nd ed., Willmann-Bell 1988):

    M = n (t - t0) mod 2 pi,   x + c (1 - cos x) - s sin x = M,
    c = (r0 . v0)/sqrt(a) = e sin E0,   s = 1 - r0/a = e cos E0,   n = a^(-3/2),

    r = f r0 + g v0,   v = fdot r0 + gdot v0,
    f = 1 - a (1 - cos x)/r0,   g = (c (1 - cos x) + (r0/a) sin x)/n,
    fdot = -sqrt(a) sin x/(r r0),   gdot = 1 - a (1 - cos x)/r,   r = a (1 - s cos x + c sin x).

It needs no argument of pericentre, so the circular orbit (e = 0) is no special case. The
equation is solved by safeguarded Newton iteration (the root lies in [M - 2e, M + 2e] and the
left side is increasing) in numpy's extended precision, then rounded to float64.
"""

from __future__ import annotations

import math

import numpy as np

from harness.errors import InputError
from harness.problem import NBody, Problem
from harness.tolerances import CONVERGENCE_PERIODS

__all__ = [
    "PROBLEMS", "KEPLER_CIRCULAR", "KEPLER_ELLIPTIC", "KEPLER_ECCENTRIC", "kepler_exact",
    "orbital_elements", "pericentre_start",
]

_COURSE_ODE = (
    "course material 004_bfdbb1594143ed8b.txt (A. Mignone, lecture notes 'Ordinary Differential "
    "Equations: Initial Value Problems', Univ. Torino 2017-18), Practice Session #3 (kepler.cpp: "
    "GM = 1, start at (4, 0) with the velocity along y, circular and elliptic orbits, 10 orbits)"
)

# A massless body about a fixed unit mass (G M = 1): the heliocentric two-body structure from
# which the right-hand side r'' = -r/|r|^3 is derived, and which Kepler-splitting integrators read.
_STRUCTURE = NBody(masses=(1.0, 0.0), G=1.0, central=0, frame="heliocentric", dimension=2,
                   names=("centre", ""))
_VARIABLES, _NEWTONIAN, _ = _STRUCTURE.derive()
_x, _y, _vx, _vy = _VARIABLES
_r2 = _x * _x + _y * _y
_inv_r = _r2 ** (-0.5)
_L = _x * _vy - _y * _vx

_INVARIANTS = {
    "energy": (_vx * _vx + _vy * _vy) / 2.0 - _inv_r,
    "angular_momentum": _L,
    "runge_lenz_x": _vy * _L - _x * _inv_r,
    "runge_lenz_y": -_vx * _L - _y * _inv_r,
}


def orbital_elements(y0: np.ndarray) -> dict[str, np.ndarray]:
    """Semi-major axis, eccentricity, mean motion and period of states shaped (4, N).

    Parameters
    ----------
    y0 : ndarray, shape (4, N), states (x, y, vx, vy) with GM = 1.

    Returns
    -------
    dict of str to ndarray: 'a', 'e', 'n', 'period' and 'energy', each shape (N,).
    """
    y0 = np.asarray(y0, dtype=np.float64)
    x, y, vx, vy = y0
    r = np.hypot(x, y)
    energy = (vx * vx + vy * vy) / 2.0 - 1.0 / r
    a = -1.0 / (2.0 * energy)
    L = x * vy - y * vx
    e = np.sqrt(np.maximum(0.0, 1.0 + 2.0 * energy * L * L))
    n = a**-1.5
    return {"a": a, "e": e, "n": n, "period": 2.0 * math.pi / n, "energy": energy}


def kepler_exact(t: float, y0: np.ndarray, t0: float, pars: np.ndarray | None = None) -> np.ndarray:
    """Exact state at t of bound Kepler orbits starting from states y0 shaped (4, N) at t0.

    Parameters
    ----------
    t : float, the time.
    y0 : ndarray, shape (4, N), bound starts (x, y, vx, vy), GM = 1; `InputError` for an unbound one.
    t0 : float, their time.
    pars : ndarray, optional, unused (the problem has no parameters).

    Returns
    -------
    ndarray, shape (4, N)
    """
    y0 = np.asarray(y0, dtype=np.float64)
    ld = np.longdouble
    x0, y0_, vx0, vy0 = (y0[i].astype(ld) for i in range(4))
    r0 = np.sqrt(x0 * x0 + y0_ * y0_)
    energy = (vx0 * vx0 + vy0 * vy0) / 2 - 1 / r0
    if np.any(energy >= 0) or np.any(r0 == 0):
        raise InputError(
            "Kepler exact solution needs bound orbits (energy < 0, r != 0), got energy "
            f"{float(np.max(energy))}"
        )
    a = -1 / (2 * energy)
    sqrt_a = np.sqrt(a)
    n = 1 / (a * sqrt_a)
    c = (x0 * vx0 + y0_ * vy0) / sqrt_a
    s = 1 - r0 / a
    e = np.sqrt(c * c + s * s)
    two_pi = 2 * np.arccos(ld(-1))
    M = np.mod(n * (ld(t) - ld(t0)), two_pi)
    lo, hi = M - 2 * e, M + 2 * e
    xk = M.copy()
    for _ in range(100):
        F = xk + c * (1 - np.cos(xk)) - s * np.sin(xk) - M
        lo = np.where(F < 0, xk, lo)
        hi = np.where(F > 0, xk, hi)
        dF = 1 + c * np.sin(xk) - s * np.cos(xk)
        step = F / dF
        xn = xk - step
        outside = (xn <= lo) | (xn >= hi)
        xn = np.where(outside, (lo + hi) / 2, xn)
        done = np.all(np.abs(xn - xk) <= 4 * np.finfo(ld).eps * (1 + np.abs(xk)))
        xk = xn
        if done:
            break
    cx, sx = np.cos(xk), np.sin(xk)
    one_minus_cos = 2 * np.sin(xk / 2) ** 2
    r = a * (1 - s * cx + c * sx)
    f = 1 - a * one_minus_cos / r0
    g = (c * one_minus_cos + (r0 / a) * sx) / n
    fdot = -sqrt_a * sx / (r * r0)
    gdot = 1 - a * one_minus_cos / r
    out = np.stack([f * x0 + g * vx0, f * y0_ + g * vy0, fdot * x0 + gdot * vx0, fdot * y0_ + gdot * vy0])
    return out.astype(np.float64)


_PERIOD_CIRCULAR = 2.0 * math.pi * 4.0**1.5  # a = 4
_PERIOD_ELLIPTIC = 2.0 * math.pi  # a = 1


def _kepler_orbit(name: str, y0: list[float], period: float, description: str, reference: str) -> Problem:
    """A bound Kepler orbit (GM = 1) from `y0` over 10 periods; the convergence sweep runs
    CONVERGENCE_PERIODS orbits: 10 orbits at the finest step sizes of low-order methods exceed
    the sweep budget and add nothing to the measured order."""
    return Problem(
        name,
        variables=_VARIABLES,
        newtonian=_NEWTONIAN,
        structure=_STRUCTURE,
        y0=y0,
        t_span=(0.0, 10.0 * period),
        period=period,
        invariants=_INVARIANTS,
        exact=kepler_exact,
        conservative=True,
        central_force=True,
        convergence_t_end=CONVERGENCE_PERIODS * period,
        description=description,
        reference=reference,
        tags=("newtonian", "central-force", "hamiltonian"),
    )


KEPLER_CIRCULAR = _kepler_orbit(
    "kepler-circular",
    [4.0, 0.0, 0.0, 0.5],
    _PERIOD_CIRCULAR,
    "Kepler problem r'' = -r/|r|^3 on the circular orbit of radius 4 (r = (4, 0), "
    "v = (0, 1/2), period 16 pi) over 10 orbits. Exact solution from Kepler's equation; "
    "energy, angular momentum and the Runge-Lenz vector are conserved.",
    _COURSE_ODE + "; exact solution: Lagrange's f and g functions (Danby, Fundamentals of "
    "Celestial Mechanics, 1988).",
)

KEPLER_ELLIPTIC = _kepler_orbit(
    "kepler-elliptic",
    [0.4, 0.0, 0.0, 2.0],
    _PERIOD_ELLIPTIC,
    "Kepler problem on an eccentric orbit, e = 0.6, a = 1 (start at pericentre r = (0.4, 0), "
    "v = (0, 2), period 2 pi), over 10 orbits; the close pericentre passage makes it much "
    "harder for fixed steps than the circular orbit.",
    _COURSE_ODE + "; Hairer, Lubich & Wanner, Geometric Numerical Integration (2nd ed. 2006), "
    "section I.2.3 (Kepler problem, e = 0.6); exact solution: f and g functions (Danby 1988).",
)



def pericentre_start(e: float) -> list[float]:
    """The state at pericentre of the orbit with a = 1 and eccentricity e (GM = 1):
    r = 1 - e on the x axis, speed sqrt((1 + e)/(1 - e)) along y (vis-viva).

    Parameters
    ----------
    e : float, eccentricity, in [0, 1).

    Returns
    -------
    list of float: (x, y, vx, vy).
    """
    return [1.0 - e, 0.0, 0.0, math.sqrt((1.0 + e) / (1.0 - e))]


def _eccentric(e: float) -> Problem:
    return Problem(
        f"kepler-e{e:g}",
        variables=[_x, _y, _vx, _vy],
        newtonian=_NEWTONIAN,
        y0=pericentre_start(e),
        t_span=(0.0, 10.0 * _PERIOD_ELLIPTIC),
        invariants=_INVARIANTS,
        exact=kepler_exact,
        conservative=True,
        central_force=True,
        # 1.5 orbits, ending at apocentre: at kepler-elliptic's 1.3 orbits the end point lies
        # near pericentre, where the acceleration 1/r^2 (~1e4 at e = 0.99) multiplies every
        # phase error, so no fixed step within the sweep's budget reaches the asymptotic range.
        convergence_t_end=1.5 * _PERIOD_ELLIPTIC,
        # Each component moves by p times its scale along the orbit (positions ~2, velocities
        # ~v_p): at pericentre (r = 1 - e) the energy moves by about 2p / (1 - e)^2 through the
        # position alone, so p = 0.05 (1 - e)^2 / 4 keeps that within ~2.5 % of |E| = 1/2 and
        # every member bound near the nominal orbit (1e-2 would unbind members at e = 0.99).
        perturbation=0.05 * (1.0 - e) ** 2 / 4.0,
        description=(
            f"Kepler problem on a highly eccentric orbit, e = {e:g}, a = 1 (start at pericentre "
            f"r = {1.0 - e:.3g}, period 2 pi), over 10 orbits: the pericentre passage lasts ~(1 - e)^1.5 "
            "of the period, so fixed steps spend almost all their work where nothing happens."
        ),
        reference=(
            _COURSE_ODE + " (elliptic orbits, step control with Delta theta ~ const); exact solution: "
            "f and g functions (Danby 1988)."
        ),
        tags=("newtonian", "central-force", "hamiltonian", "on-request"),
    )


KEPLER_ECCENTRIC: dict[float, Problem] = {e: _eccentric(e) for e in (0.9, 0.99)}

PROBLEMS: list[Problem] = [KEPLER_CIRCULAR, KEPLER_ELLIPTIC, *KEPLER_ECCENTRIC.values()]
