"""A user's problem as a plugin file: the Pleiades, seven bodies in the plane with close encounters.

x_i'' = sum_{j != i} m_j (x_j - x_i) / r_ij^3, masses m_i = i (G = 1), on [0, 3], from the
published start. Nothing about it is registered anywhere in the harness: the experiments derive
its time scale, its perturbation and which of them apply from this definition alone.

Reference: E. Hairer, S. P. Norsett, G. Wanner, Solving Ordinary Differential Equations I,
2nd ed., Springer 1993, section II.10 (the Pleiades problem, PLEI).
"""

import heyoka as hy

from harness.problem import NewtonianForm, Problem

MASSES = [float(i) for i in range(1, 8)]
X0 = [3.0, 3.0, -1.0, -3.0, 2.0, -2.0, 2.0]
Y0 = [3.0, -3.0, 2.0, 0.0, 0.0, -4.0, 4.0]
VX0 = [0.0, 0.0, 0.0, 0.0, 0.0, 1.75, -1.5]
VY0 = [0.0, 0.0, 0.0, -1.25, 1.0, 0.0, 0.0]


def _pleiades() -> Problem:
    n = len(MASSES)
    x = list(hy.make_vars(*(f"x{i}" for i in range(n))))
    y = list(hy.make_vars(*(f"y{i}" for i in range(n))))
    vx = list(hy.make_vars(*(f"vx{i}" for i in range(n))))
    vy = list(hy.make_vars(*(f"vy{i}" for i in range(n))))
    ax = [hy.expression(0.0)] * n
    ay = [hy.expression(0.0)] * n
    potential = hy.expression(0.0)
    for i in range(n):
        for j in range(i + 1, n):
            dx, dy = x[j] - x[i], y[j] - y[i]
            r2 = dx * dx + dy * dy
            inv_r3 = r2 ** (-1.5)
            ax[i] = ax[i] + MASSES[j] * dx * inv_r3
            ay[i] = ay[i] + MASSES[j] * dy * inv_r3
            ax[j] = ax[j] - MASSES[i] * dx * inv_r3
            ay[j] = ay[j] - MASSES[i] * dy * inv_r3
            potential = potential - MASSES[i] * MASSES[j] * r2 ** (-0.5)
    kinetic = sum((MASSES[i] / 2.0 * (vx[i] * vx[i] + vy[i] * vy[i]) for i in range(n)), hy.expression(0.0))
    positions = tuple(x + y)
    velocities = tuple(vx + vy)
    return Problem(
        "pleiades",
        variables=list(positions + velocities),
        newtonian=NewtonianForm(positions=positions, velocities=velocities, acceleration=tuple(ax + ay)),
        y0=X0 + Y0 + VX0 + VY0,
        t_span=(0.0, 3.0),
        invariants={"energy": kinetic + potential},
        conservative=True,
        description="Seven bodies in the plane, masses 1..7, G = 1, on [0, 3] (close encounters).",
        reference="Hairer, Norsett & Wanner, Solving ODEs I, 2nd ed. (1993), II.10 (Pleiades, PLEI).",
    )


PROBLEMS = [_pleiades()]
