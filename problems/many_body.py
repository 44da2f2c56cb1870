"""Problems with several degrees of freedom: `henon-heiles`, `henon-heiles-chaotic`,
`outer-solar-system`, `lennard-jones`.

The state may have any size; these problems exercise the ensemble design on larger systems and
carry the invariants a structure-preserving method should keep (energy, total momentum, angular
momentum). Integer powers are written as products (heyoka's Taylor recurrence for pow divides by
its base).
"""

from __future__ import annotations

import math

import heyoka as hy

from harness.problem import NBody, NewtonianForm, Problem

__all__ = [
    "PROBLEMS",
    "HENON_HEILES",
    "HENON_HEILES_CHAOTIC",
    "OUTER_SOLAR_SYSTEM",
    "LENNARD_JONES",
    "henon_heiles_start",
]

_GNI = "E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed., Springer 2006"


# -- Hénon-Heiles ---------------------------------------------------------------------------------
def henon_heiles_start(energy: float, y0: float) -> list[float]:
    """A start on the section x = 0 with py = 0 and px > 0 chosen so that H = `energy`.

    Parameters
    ----------
    energy : float, the energy H.
    y0 : float, the start's y.

    Returns
    -------
    list of float: (x, y, px, py).
    """
    px2 = 2.0 * energy - y0 * y0 + 2.0 * y0 * y0 * y0 / 3.0
    return [0.0, y0, math.sqrt(px2), 0.0]


_hx, _hy, _hpx, _hpy = hy.make_vars("x", "y", "px", "py")
_HH_NEWTONIAN = NewtonianForm(
    positions=(_hx, _hy),
    velocities=(_hpx, _hpy),
    acceleration=(-_hx - 2.0 * _hx * _hy, -_hy - _hx * _hx + _hy * _hy),
)
_HH_ENERGY = {
    "energy": (_hpx * _hpx + _hpy * _hpy) / 2.0
    + (_hx * _hx + _hy * _hy) / 2.0
    + _hx * _hx * _hy
    - _hy * _hy * _hy / 3.0
}
_HH_REF = f"M. Hénon, C. Heiles, Astron. J. 69 (1964) 73-79; energies 1/12 and 1/8 as in {_GNI}, section I.3."

def _henon_heiles(name: str, energy: float, y: float, description: str, orbit: str) -> Problem:
    """The Hénon-Heiles orbit of the given energy from x = 0, `y`, py = 0 (henon_heiles_start)
    over [0, 50]. The convergence sweep runs a shorter horizon: over 50 time units first-order
    methods need more steps than the sweep's budget to bring the error below 1e-2 of the state."""
    return Problem(
        name,
        variables=[_hx, _hy, _hpx, _hpy],
        newtonian=_HH_NEWTONIAN,
        y0=henon_heiles_start(energy, y),
        t_span=(0.0, 50.0),
        convergence_t_end=10.3,
        invariants=_HH_ENERGY,
        conservative=True,
        description=description,
        reference=_HH_REF,
        tags=("newtonian", "hamiltonian", orbit),
    )


HENON_HEILES = _henon_heiles(
    "henon-heiles", 1.0 / 12.0, 0.1,
    "Hénon-Heiles Hamiltonian H = (px^2 + py^2)/2 + (x^2 + y^2)/2 + x^2 y - y^3/3 at energy "
    "1/12, start x = 0, y = 0.1, py = 0 on a regular (quasi-periodic) orbit: the finite-time "
    "Lyapunov exponent over t = 3000 is below 1e-4. Span [0, 50].",
    "regular",
)

HENON_HEILES_CHAOTIC = _henon_heiles(
    "henon-heiles-chaotic", 1.0 / 8.0, -0.2,
    "Hénon-Heiles at energy 1/8, start x = 0, y = -0.2, py = 0 in the chaotic sea (finite-time "
    "Lyapunov exponent ~0.07 over t = 3000): errors grow ~30x over the span [0, 50], so the "
    "reference's own error is what limits how far a method can be judged.",
    "chaotic",
)


# -- gravitational N-body -------------------------------------------------------------------------
# Hairer, Lubich & Wanner, GNI section I.2.4, Table 2.1: masses relative to the Sun (the Sun's
# includes the inner planets), heliocentric positions in AU, velocities in AU/day; G in
# AU^3 / (solar mass day^2). The same table is reproduced in
# SciML/DiffEqDocs.jl (docs/src/models/physical.md) and in the MatMol examples (G_solar.m).
_SOLAR_G = 2.95912208286e-4
_SOLAR_BODIES = (
    # name, mass, position, velocity
    ("sun", 1.00000597682, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    (
        "jupiter",
        0.000954786104043,
        (-3.5023653, -3.8169847, -1.5507963),
        (0.00565429, -0.00412490, -0.00190589),
    ),
    ("saturn", 0.000285583733151, (9.0755314, -3.0458353, -1.6483708), (0.00168318, 0.00483525, 0.00192462)),
    (
        "uranus",
        0.0000437273164546,
        (8.3101420, -16.2901086, -7.2521278),
        (0.00354178, 0.00137102, 0.00055029),
    ),
    (
        "neptune",
        0.0000517759138449,
        (11.4707666, -25.7294829, -10.8169456),
        (0.00288930, 0.00114527, 0.00039677),
    ),
    ("pluto", 1.0 / 1.3e8, (-15.5387357, -25.2225594, -3.1902382), (0.00276725, -0.00170702, -0.00136504)),
)
_SOLAR_STRUCTURE = NBody(masses=tuple(b[1] for b in _SOLAR_BODIES), G=_SOLAR_G, central=0,
                         frame="inertial", names=tuple(b[0] for b in _SOLAR_BODIES))
_solar_vars, _solar_nf, _solar_inv = _SOLAR_STRUCTURE.derive()

OUTER_SOLAR_SYSTEM = Problem(
    "outer-solar-system",
    variables=_solar_vars,
    newtonian=_solar_nf,
    structure=_SOLAR_STRUCTURE,
    y0=[c for b in _SOLAR_BODIES for c in b[2]] + [c for b in _SOLAR_BODIES for c in b[3]],
    t_span=(0.0, 20000.0),
    invariants=_solar_inv,
    conservative=True,
    # 1000 days (a quarter of Jupiter's orbit) is enough to measure an order; the certifying
    # real128 run costs ~40 ms per member per 1000 days, and low-order methods would need far
    # more steps than the sweep budget allows over the full 20000 days.
    convergence_t_end=1000.0,
    # Ensemble members move each component by up to this fraction, and the Sun's zero components
    # by this much in absolute terms (AU, AU/day): 1e-5 keeps the Sun's velocity kick far below
    # the planets' speeds (3e-3 to 7e-3 AU/day), so every member stays a planet-like system.
    perturbation=1e-5,
    description=(
        "The Sun and the five outer bodies (Jupiter, Saturn, Uranus, Neptune, Pluto) under "
        "Newtonian gravity, G = 2.95912208286e-4 AU^3/(solar mass day^2), days as time unit; "
        "36 state variables, span [0, 20000] days. Energy, total momentum and total angular "
        "momentum are conserved."
    ),
    reference=(
        f"{_GNI}, section I.2.4 (outer solar system, Table 2.1 data, G = 2.95912208286e-4); "
        "table reproduced in SciML/DiffEqDocs.jl docs/src/models/physical.md."
    ),
    tags=("newtonian", "hamiltonian", "n-body"),
)


# -- Lennard-Jones cluster ------------------------------------------------------------------------
def _lennard_jones(
    n_atoms: int,
) -> tuple[list[hy.expression], NewtonianForm, dict[str, hy.expression]]:
    """2-D Lennard-Jones cluster, epsilon = sigma = mass = 1: V = sum 4 (r^-12 - r^-6)."""
    q = [hy.make_vars(f"a{i}_x", f"a{i}_y") for i in range(n_atoms)]
    v = [hy.make_vars(f"a{i}_vx", f"a{i}_vy") for i in range(n_atoms)]
    acc = [[hy.expression(0.0), hy.expression(0.0)] for _ in range(n_atoms)]
    potential = hy.expression(0.0)
    for i in range(n_atoms):
        for j in range(i + 1, n_atoms):
            dx, dy = q[i][0] - q[j][0], q[i][1] - q[j][1]
            inv_r2 = 1.0 / (dx * dx + dy * dy)
            inv_r6 = inv_r2 * inv_r2 * inv_r2
            # force on i along (q_i - q_j): 24 (2 r^-12 - r^-6) / r^2
            scale = 24.0 * (2.0 * inv_r6 * inv_r6 - inv_r6) * inv_r2
            for c, d in enumerate((dx, dy)):
                acc[i][c] = acc[i][c] + scale * d
                acc[j][c] = acc[j][c] - scale * d
            potential = potential + 4.0 * (inv_r6 * inv_r6 - inv_r6)
    kinetic = sum(((vx * vx + vy * vy) / 2.0 for vx, vy in v), hy.expression(0.0))
    invariants = {
        "energy": kinetic + potential,
        "momentum_x": sum((vx for vx, _ in v), hy.expression(0.0)),
        "momentum_y": sum((vy for _, vy in v), hy.expression(0.0)),
        "angular_momentum": sum(
            (x * vy - y * vx for (x, y), (vx, vy) in zip(q, v, strict=True)), hy.expression(0.0)
        ),
    }
    positions = tuple(c for atom in q for c in atom)
    velocities = tuple(c for atom in v for c in atom)
    nf = NewtonianForm(
        positions=positions, velocities=velocities, acceleration=tuple(a for atom in acc for a in atom)
    )
    return list(positions + velocities), nf, invariants


_LJ_BOND = 2.0 ** (1.0 / 6.0)  # the pair potential's minimum: every pair of the triangle sits there
_LJ_POSITIONS = [  # centred on the origin
    (0.0, _LJ_BOND / math.sqrt(3.0)),
    (-_LJ_BOND / 2.0, -_LJ_BOND / (2.0 * math.sqrt(3.0))),
    (_LJ_BOND / 2.0, -_LJ_BOND / (2.0 * math.sqrt(3.0))),
]
# Small fixed velocities (kinetic energy ~1e-3 per atom against a well depth of 1) with zero
# total momentum: the last atom's velocity balances the others.
_LJ_VELOCITIES = [(0.031, -0.017), (-0.024, 0.042)]
_LJ_VELOCITIES.append((-sum(v[0] for v in _LJ_VELOCITIES), -sum(v[1] for v in _LJ_VELOCITIES)))
_lj_vars, _lj_nf, _lj_inv = _lennard_jones(3)

LENNARD_JONES = Problem(
    "lennard-jones",
    variables=_lj_vars,
    newtonian=_lj_nf,
    y0=[c for p in _LJ_POSITIONS for c in p] + [c for v in _LJ_VELOCITIES for c in v],
    t_span=(0.0, 2.0),
    invariants=_lj_inv,
    conservative=True,
    description=(
        "Three Lennard-Jones atoms in the plane (epsilon = sigma = mass = 1) on an equilateral "
        "triangle of side 2^(1/6), the equilibrium (every pair at the potential's minimum), "
        "centred at the origin, with small velocities of zero total momentum: the cluster "
        "vibrates and rotates slowly over [0, 2] (~4 periods of the fastest normal mode). 12 "
        "state variables; energy, momentum and angular momentum are conserved. Kept to three "
        "atoms and a short span because the certifying real128 run costs ~2 ms per Taylor step "
        "and pair."
    ),
    reference=(
        "L. Verlet, Phys. Rev. 159 (1967) 98 (molecular dynamics of Lennard-Jones particles with "
        "the Verlet scheme); course material 002_b3abae41bf42a307.txt (the many-particle, "
        "Lennard-Jones use of the Verlet/leapfrog scheme)."
    ),
    tags=("newtonian", "hamiltonian", "n-body", "molecular-dynamics"),
)

PROBLEMS: list[Problem] = [HENON_HEILES, HENON_HEILES_CHAOTIC, OUTER_SOLAR_SYSTEM, LENNARD_JONES]
