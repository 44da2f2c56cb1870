"""Gravitational N-body systems described by masses and pair laws (`NBody`), derived into the
symbolic Newtonian form a `Problem` is built from (Aarseth, *Gravitational N-Body
Simulations*, 2003, ch. 1)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import heyoka as hy

from harness.errors import InputError


def expression_names(exprs: Sequence[hy.expression]) -> set[str]:
    """The names of the variables that occur in any of `exprs`.

    Parameters
    ----------
    exprs : heyoka expressions.

    Returns
    -------
    set of str
    """
    out: set[str] = set()
    for e in exprs:
        out.update(hy.get_variables(e))
    return out


@dataclass(frozen=True, eq=False)
class NewtonianForm:
    """q'' = a(q, v, t): position and velocity variables and the acceleration expressions."""

    positions: tuple[hy.expression, ...]
    velocities: tuple[hy.expression, ...]
    acceleration: tuple[hy.expression, ...]

    @cached_property
    def velocity_dependent(self) -> bool:
        """True when the acceleration reads any velocity variable (asked on every integrate
        call: kept, the expressions are frozen)."""
        used = expression_names(self.acceleration)
        return any(str(v) in used for v in self.velocities)


@dataclass(frozen=True, eq=False)
class NBody:
    """The structure of a gravitational N-body problem: masses, G, the central body, the frame.

    Integrators that split the motion into Kepler orbits about a central mass plus interactions
    (Wisdom-Holman maps, SABA/SABAC, hybrid schemes) need these numbers, not just a right-hand
    side; `derive()` builds the symbolic right-hand side from them, so both come from one place.
    - `frame='inertial'`: the state holds every body, in an inertial frame.
    - `frame='heliocentric'`: the state holds every body but `central`, relative to it
      (r_i'' = -G (M + m_i) r_i/|r_i|^3 + sum_j G m_j ((r_j - r_i)/|r_j - r_i|^3 - r_j/|r_j|^3));
      with massless bodies it is the fixed-centre Kepler problem.
    State order: positions body by body (x, y[, z]), then velocities in the same order.
    Reference: Hairer, Lubich & Wanner, Geometric Numerical Integration (2006), I.2.3-I.2.4;
    Murray & Dermott, Solar System Dynamics (1999), 6.2 (heliocentric equations of motion).
    """

    masses: tuple[float, ...]
    G: float
    central: int = 0
    frame: str = "inertial"
    dimension: int = 3
    names: tuple[str, ...] = ()

    def __post_init__(self):
        masses = tuple(float(m) for m in self.masses)
        object.__setattr__(self, "masses", masses)
        if len(masses) < 2 or not all(math.isfinite(m) and m >= 0.0 for m in masses):
            raise InputError(f"NBody `masses` must be two or more finite masses >= 0, got {masses}")
        if not (math.isfinite(float(self.G)) and float(self.G) > 0.0):
            raise InputError(f"NBody `G` must be positive and finite, got {self.G!r}")
        central_ok = isinstance(self.central, int) and 0 <= self.central < len(masses)
        if not central_ok or masses[self.central] <= 0:
            raise InputError(f"NBody `central` must index a body of positive mass, got {self.central!r}")
        if self.frame not in ("inertial", "heliocentric"):
            raise InputError(f"NBody `frame` must be 'inertial' or 'heliocentric', got {self.frame!r}")
        if self.dimension not in (2, 3):
            raise InputError(f"NBody `dimension` must be 2 or 3, got {self.dimension!r}")
        names = tuple(self.names) or tuple(f"b{i}" for i in range(len(masses)))
        if len(names) != len(masses) or len(set(names)) != len(names):
            raise InputError(f"NBody `names` must name each of the {len(masses)} bodies once, got {names}")
        object.__setattr__(self, "names", names)

    @property
    def perturbation_free(self) -> bool:
        """True when every body but the central one moves on an unperturbed Kepler orbit about it:
        at most one other body has mass, and the massless ones feel only the central mass (a
        single planet, or test particles). A Wisdom-Holman-type map, whose drift is the Kepler
        flow and whose kicks are the interactions, then has nothing to approximate: only
        rounding remains."""
        others = [m for i, m in enumerate(self.masses) if i != self.central]
        return len(others) == 1 or all(m == 0.0 for m in others)

    @property
    def state_bodies(self) -> tuple[int, ...]:
        """Indices of the bodies held in the state, in state order."""
        n = len(self.masses)
        return tuple(i for i in range(n) if self.frame == "inertial" or i != self.central)

    def derive(self) -> tuple[list[hy.expression], NewtonianForm, dict[str, hy.expression]]:
        """(variables, Newtonian form, invariants) of this system: variables `<name>_x` ...,
        `<name>_vx` ... (just `x`, `vx` for a body named ''); energy (and, inertial frame,
        momentum and angular momentum; heliocentric frame, the specific orbital energy and
        angular momentum of a lone massless body).

        Returns
        -------
        (list of heyoka variables, NewtonianForm, dict of str to heyoka expression)
        """
        axes = "xyz"[: self.dimension]
        m, G = self.masses, float(self.G)
        bodies = self.state_bodies
        pre = {i: (f"{self.names[i]}_" if self.names[i] else "") for i in bodies}
        q = {i: hy.make_vars(*(f"{pre[i]}{c}" for c in axes)) for i in bodies}
        v = {i: hy.make_vars(*(f"{pre[i]}v{c}" for c in axes)) for i in bodies}
        q = {i: list(x) if isinstance(x, list | tuple) else [x] for i, x in q.items()}
        v = {i: list(x) if isinstance(x, list | tuple) else [x] for i, x in v.items()}
        zero = hy.expression(0.0)
        acc = {i: [zero] * len(axes) for i in bodies}
        kinetic, potential = zero, zero
        invariants: dict[str, hy.expression] = {}
        if self.frame == "inertial":
            for a_i, i in enumerate(bodies):
                for j in bodies[a_i + 1:]:
                    d = [q[j][c] - q[i][c] for c in range(len(axes))]
                    r2 = sum((d[c] * d[c] for c in range(1, len(axes))), d[0] * d[0])
                    inv_r3 = r2 ** (-1.5)
                    for c in range(len(axes)):
                        acc[i][c] = acc[i][c] + (G * m[j]) * d[c] * inv_r3
                        acc[j][c] = acc[j][c] - (G * m[i]) * d[c] * inv_r3
                    potential = potential - (G * m[i] * m[j]) * r2 ** (-0.5)
            for i in bodies:
                kinetic = kinetic + (m[i] / 2.0) * sum((v[i][c] * v[i][c] for c in range(len(axes))), zero)
            invariants["energy"] = kinetic + potential
            for c, axis in enumerate(axes):
                invariants[f"momentum_{axis}"] = sum((m[i] * v[i][c] for i in bodies), zero)
            if self.dimension == 3:
                for c, axis in enumerate(axes):
                    a, b = (c + 1) % 3, (c + 2) % 3
                    invariants[f"angular_momentum_{axis}"] = sum(
                        (m[i] * (q[i][a] * v[i][b] - q[i][b] * v[i][a]) for i in bodies), zero)
        else:
            M = m[self.central]
            r2 = {i: sum((q[i][c] * q[i][c] for c in range(1, len(axes))), q[i][0] * q[i][0])
                  for i in bodies}
            for i in bodies:
                mu = G * (M + m[i])
                inv_r3 = r2[i] ** (-1.5)
                for c in range(len(axes)):
                    # a unit coefficient is left out so the fixed-centre Kepler problem keeps its
                    # textbook form r'' = -r/|r|^3
                    acc[i][c] = (-q[i][c]) * inv_r3 if mu == 1.0 else -(mu * q[i][c]) * inv_r3
                for j in bodies:
                    if j == i or m[j] == 0.0:
                        continue
                    d = [q[j][c] - q[i][c] for c in range(len(axes))]
                    dr2 = sum((d[c] * d[c] for c in range(1, len(axes))), d[0] * d[0])
                    direct, indirect = dr2 ** (-1.5), r2[j] ** (-1.5)
                    for c in range(len(axes)):
                        acc[i][c] = acc[i][c] + (G * m[j]) * (d[c] * direct - q[j][c] * indirect)
            massive = [i for i in bodies if m[i] > 0.0]
            if not massive and len(bodies) == 1:
                (i,) = bodies
                mu = G * M
                speed2 = sum((v[i][c] * v[i][c] for c in range(1, len(axes))), v[i][0] * v[i][0])
                inv_r = r2[i] ** (-0.5)
                invariants["energy"] = speed2 / 2.0 - (inv_r if mu == 1.0 else mu * inv_r)
            else:
                # barycentric energy written in heliocentric variables: T = sum m_i v_i^2/2 -
                # |sum m_i v_i|^2 / (2 M_total), U = -G M m_i/r_i - G m_i m_j/r_ij
                total = M + sum(m[i] for i in bodies)
                P = [sum((m[i] * v[i][c] for i in bodies), zero) for c in range(len(axes))]
                kinetic = sum(((m[i] / 2.0) * sum((v[i][c] * v[i][c] for c in range(len(axes))), zero)
                               for i in bodies), zero)
                kinetic = kinetic - sum((P[c] * P[c] for c in range(len(axes))), zero) / (2.0 * total)
                for a_i, i in enumerate(bodies):
                    potential = potential - (G * M * m[i]) * r2[i] ** (-0.5)
                    for j in bodies[a_i + 1:]:
                        d = [q[j][c] - q[i][c] for c in range(len(axes))]
                        dr2 = sum((d[c] * d[c] for c in range(1, len(axes))), d[0] * d[0])
                        potential = potential - (G * m[i] * m[j]) * dr2 ** (-0.5)
                invariants["energy"] = kinetic + potential
        positions = tuple(x for i in bodies for x in q[i])
        velocities = tuple(x for i in bodies for x in v[i])
        accel = tuple(a for i in bodies for a in acc[i])
        nf = NewtonianForm(positions=positions, velocities=velocities, acceleration=accel)
        return list(positions + velocities), nf, invariants

    def describe(self) -> dict[str, Any]:
        """The system's description as plain data (masses, G, frame, dimension, body names).

        Returns
        -------
        dict: kind, masses, G, central, frame, dimension, names.
        """
        return {"kind": "n-body", "masses": list(self.masses), "G": float(self.G),
                "central": self.central, "frame": self.frame, "dimension": self.dimension,
                "names": list(self.names)}
