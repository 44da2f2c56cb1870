"""What to integrate: a problem defined once, symbolically, and everything derived from it.

A `Problem` is written with heyoka expressions: state variables, the first-order right-hand side
(or, for Newtonian problems, the acceleration a(q, t) or a(q, v, t), from which the first-order
system is built), parameters (`hy.par[i]`), invariants, an optional exact solution, and a
literature reference. From that single definition the harness derives, on demand and cached per
process:

- `Dynamics`: NumPy-callable, ensemble-batched right-hand side, acceleration and Jacobian
  (heyoka compiled functions), with evaluation counters;
- invariant functions;
- the ground-truth integrator (`harness.ground_truth`).

Contract for a problem definition (checked in `Problem.__init__`):
1. `variables` are distinct heyoka variables; `rhs` has one expression per variable.
2. A Newtonian problem orders its state as (positions..., velocities...); its acceleration uses
   only positions, velocities, parameters and `hy.time`.
3. `y0` has one finite value per variable; `t_span` is finite with t_end > t0.
4. Parameters are `hy.par[0..P-1]` in the order of `parameters` (name -> default value).
5. `exact(t, y0, t0, pars)`, when given, maps initial states shaped (dim, N) to states at t.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import heyoka as hy
import numpy as np

from harness import cache
from harness.errors import InputError

__all__ = ["Problem", "NewtonianForm", "NBody", "Dynamics", "check_state", "check_time"]

ExactSolution = Callable[[float, np.ndarray, float, np.ndarray], np.ndarray]


def _names(exprs: Sequence[hy.expression]) -> set[str]:
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

    @property
    def velocity_dependent(self) -> bool:
        used = _names(self.acceleration)
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
        angular momentum of a lone massless body)."""
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
        return {"kind": "n-body", "masses": list(self.masses), "G": float(self.G),
                "central": self.central, "frame": self.frame, "dimension": self.dimension,
                "names": list(self.names)}


class Problem:
    """One entry of the problem catalogue (see the module docstring for the contract)."""

    def __init__(
        self,
        name: str,
        *,
        variables: Sequence[hy.expression],
        rhs: Sequence[hy.expression] | None = None,
        newtonian: NewtonianForm | None = None,
        y0: Sequence[float],
        t_span: tuple[float, float],
        parameters: Mapping[str, float] | None = None,
        invariants: Mapping[str, hy.expression] | None = None,
        exact: ExactSolution | None = None,
        approximations: Mapping[str, ExactSolution] | None = None,
        description: str = "",
        reference: str = "",
        conservative: bool = False,
        central_force: bool = False,
        convergence_t_end: float | None = None,
        perturbation: float | None = None,
        period: float | None = None,
        tags: Sequence[str] = (),
        structure: NBody | None = None,
    ):
        if not isinstance(name, str) or not name.strip():
            raise InputError(f"problem `name` must be a non-empty string, got {name!r}")
        variables = tuple(variables)
        var_names = [str(v) for v in variables]
        if len(set(var_names)) != len(var_names):
            raise InputError(f"problem {name!r}: `variables` must be distinct, got {var_names}")
        if newtonian is not None:
            nq = len(newtonian.positions)
            if tuple(map(str, newtonian.positions + newtonian.velocities)) != tuple(var_names):
                raise InputError(
                    f"problem {name!r}: a Newtonian state must be (positions..., velocities...)"
                )
            if len(newtonian.acceleration) != nq:
                raise InputError(
                    f"problem {name!r}: `acceleration` needs {nq} expressions, got "
                    f"{len(newtonian.acceleration)}"
                )
            derived = tuple(newtonian.velocities) + tuple(newtonian.acceleration)
            if rhs is not None:
                raise InputError(f"problem {name!r}: give `rhs` or `newtonian`, not both")
            rhs = derived
        if rhs is None:
            raise InputError(f"problem {name!r}: `rhs` (or `newtonian`) is required")
        rhs = tuple(hy.expression(r) if not isinstance(r, hy.expression) else r for r in rhs)
        if len(rhs) != len(variables):
            raise InputError(
                f"problem {name!r}: `rhs` needs one expression per variable ({len(variables)}), "
                f"got {len(rhs)}"
            )
        parameters = dict(parameters or {})
        unknown = _names(rhs) - set(var_names)
        if unknown:
            raise InputError(f"problem {name!r}: `rhs` uses undeclared variables {sorted(unknown)}")
        try:
            y0_arr = np.asarray(y0, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"problem {name!r}: `y0` must be numbers, got {y0!r}") from None
        if y0_arr.shape != (len(variables),):
            raise InputError(
                f"problem {name!r}: `y0` needs {len(variables)} values, got shape {y0_arr.shape}"
            )
        if not np.all(np.isfinite(y0_arr)):
            raise InputError(f"problem {name!r}: `y0` must be finite, got {y0_arr.tolist()}")
        try:
            t0, t_end = (float(t_span[0]), float(t_span[1]))
        except (TypeError, ValueError, OverflowError, IndexError, KeyError):
            raise InputError(f"problem {name!r}: `t_span` must be two real numbers, got {t_span!r}") from None
        if not (math.isfinite(t0) and math.isfinite(t_end)) or t_end <= t0:
            raise InputError(f"problem {name!r}: `t_span` must be finite with t_end > t0, got {t_span}")
        period = _check_optional_positive(name, "period", period)
        perturbation = _check_optional_positive(name, "perturbation", perturbation)
        y0_arr.setflags(write=False)
        self.name = name
        self.variables = variables
        self.rhs = rhs
        self.newtonian = newtonian
        self.y0 = y0_arr
        self.t0 = t0
        self.t_end = t_end
        self.parameters = parameters
        self.invariants = dict(invariants or {})
        self.exact = exact
        self.approximations = dict(approximations or {})
        self.description = description
        self.reference = reference
        self.conservative = conservative
        self.central_force = central_force
        self.declared_convergence_t_end = float(convergence_t_end) if convergence_t_end else None
        self.perturbation = perturbation
        self.period = period
        self.tags = tuple(tags)
        if structure is not None:
            _check_structure(name, structure, var_names)
        self.structure = structure
        self._lock = threading.Lock()

    # -- declared facts -------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return len(self.variables)

    @property
    def form(self) -> str:
        """'newtonian' when an acceleration is declared, else 'first-order'."""
        return "newtonian" if self.newtonian is not None else "first-order"

    @property
    def velocity_dependent(self) -> bool:
        return self.newtonian is not None and self.newtonian.velocity_dependent

    @cached_property
    def time_dependent(self) -> bool:
        return bool(self.compiled("rhs", None).is_time_dependent)

    @property
    def convergence_t_end(self) -> float:
        """The convergence horizon: declared, else the span cut to HORIZON_PERIODS natural
        periods (`time_scale`; order does not depend on the horizon, a long span only costs)."""
        if self.declared_convergence_t_end is not None:
            return self.declared_convergence_t_end
        from harness.tolerances import HORIZON_PERIODS

        return min(self.t_end, self.t0 + HORIZON_PERIODS * self.time_scale.period)

    @property
    def parameter_values(self) -> np.ndarray:
        return np.array(list(self.parameters.values()), dtype=np.float64)

    def describe(self) -> dict[str, Any]:
        """Declared properties as plain data (for `harness list problems`)."""
        return {
            "name": self.name,
            "form": self.form,
            "dim": self.dim,
            "variables": [str(v) for v in self.variables],
            "rhs": [str(e) for e in self.rhs],
            "y0": self.y0.tolist(),
            "t_span": [self.t0, self.t_end],
            "convergence_t_end": self.declared_convergence_t_end,
            "period": self.period,
            "perturbation": self.perturbation,
            "parameters": dict(self.parameters),
            "invariants": sorted(self.invariants),
            "exact_solution": self.exact is not None,
            "approximations": sorted(self.approximations),
            "velocity_dependent": self.velocity_dependent,
            "time_dependent": self.time_dependent,
            "conservative": self.conservative,
            "reference": self.reference,
            "description": self.description,
            "structure": None if self.structure is None else self.structure.describe(),
        }

    def fingerprint(self) -> str:
        """A text form of the whole definition: changes whenever the problem changes."""
        parts = [self.name, *map(str, self.variables), *map(str, self.rhs), self.y0.tobytes().hex()]
        horizon = self.declared_convergence_t_end
        parts += [repr((self.t0, self.t_end, self.t_end if horizon is None else horizon))]
        parts += [f"{k}={v!r}" for k, v in (("period", self.period), ("perturbation", self.perturbation))
                  if v is not None]
        parts += [f"{k}={v!r}" for k, v in self.parameters.items()]
        parts += [f"{k}:{e}" for k, e in sorted(self.invariants.items())]
        if getattr(self, "structure", None) is not None:
            parts.append(repr(sorted(self.structure.describe().items())))
        return "|".join(parts)

    # -- initial states -------------------------------------------------------------------------
    def ensemble(self, size: int, *, seed: int = 0, scale: float | None = None) -> np.ndarray:
        """`size` initial states shaped (dim, size): member 0 is `y0`, the others perturbed.

        Component i moves by u * scale * s_i, u uniform in [-1, 1] and s_i the component's scale
        along the orbit (`ensemble_perturbation`), so an order is never the artefact of one
        start. `scale` defaults to the problem's size (declared, or derived so that every
        member stays in the start's dynamical regime: `harness.scales`).
        """
        from harness.scales import draw_noise

        size = check_ensemble_size(size)
        if size == 1:
            return self.y0[:, None].copy()
        pert = self.ensemble_perturbation
        if scale is None:
            scale = pert.size
        else:
            scale = _check_optional_positive(self.name, "perturbation", scale)
        noise = draw_noise(self.dim, size, int(seed)) * (scale * pert.component_scale)[:, None]
        return self.y0[:, None] + noise

    def pars_for(self, size: int, pars: np.ndarray | Mapping[str, float] | None = None) -> np.ndarray:
        """Parameter values shaped (P, size), from defaults, a mapping, or an array."""
        P = len(self.parameters)
        if pars is None:
            return np.repeat(self.parameter_values[:, None], size, axis=1)
        if isinstance(pars, Mapping):
            unknown = set(pars) - set(self.parameters)
            if unknown:
                raise InputError(
                    f"`pars` names unknown parameters {sorted(unknown)} of problem {self.name!r}; "
                    f"known: {sorted(self.parameters)}"
                )
            try:
                vals = np.array([float(pars.get(k, v)) for k, v in self.parameters.items()])
            except (TypeError, ValueError, OverflowError):
                raise InputError(f"`pars` values must be real numbers, got {dict(pars)!r}") from None
            if not np.all(np.isfinite(vals)):
                raise InputError("`pars` must be finite")
            return np.repeat(vals[:, None], size, axis=1)
        try:
            arr = np.asarray(pars, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"`pars` must be numeric, got {type(pars).__name__}") from None
        if arr.ndim == 1:
            arr = np.repeat(arr[:, None], size, axis=1)
        if arr.shape != (P, size):
            raise InputError(f"`pars` must have shape ({P}, {size}), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise InputError("`pars` must be finite")
        return arr

    # -- derived time scale and perturbation (harness.scales) -------------------------------------
    @cached_property
    def time_scale(self):
        """Natural period, fastest rate and the long-run step size (`harness.scales.TimeScale`)."""
        from harness.scales import derive_time_scale

        return derive_time_scale(self)

    @cached_property
    def ensemble_perturbation(self):
        """Relative size and component scales of the ensemble (`harness.scales.Perturbation`)."""
        from harness.scales import derive_perturbation

        return derive_perturbation(self)

    # -- derived numerical functions --------------------------------------------------------------
    def dynamics(self, pars: np.ndarray | None = None, size: int = 1) -> Dynamics:
        """Ensemble-batched numerical functions bound to parameter values (P, size)."""
        return Dynamics(self, self.pars_for(size, pars))

    @cached_property
    def jacobian_expressions(self) -> list[hy.expression]:
        """d rhs_i / d y_j as heyoka expressions, row by row (the derived Jacobian)."""
        return [hy.diff(f, v) for f in self.rhs for v in self.variables]

    def compiled(self, kind: str, constants: tuple[float, ...] | None) -> Any:
        """The compiled function `kind` ('rhs', 'accel', 'accel_q' (of positions only, for
        accelerations that ignore velocity), 'jac', 'inv'), parameters either
        substituted as constants (a tuple of values) or left as runtime parameters (None)."""
        key = (kind, constants)
        with self._lock:
            store = self.__dict__.setdefault("_compiled", {})
            if key in store:
                return store[key]
        if kind == "rhs":
            exprs = list(self.rhs)
        elif kind in ("accel", "accel_q"):
            if self.newtonian is None:
                raise InputError(f"problem {self.name!r} has no Newtonian form (no acceleration)")
            exprs = list(self.newtonian.acceleration)
        elif kind == "jac":
            exprs = self.jacobian_expressions
        elif kind == "inv":
            exprs = [self.invariants[k] for k in sorted(self.invariants)]
        else:
            raise InputError(f"`kind` must be rhs, accel, accel_q, jac or inv, got {kind!r}")
        if constants is not None and self.parameters:
            mapping = {f"p{i}": hy.expression(float(v)) for i, v in enumerate(constants)}
            exprs = [_subs_pars(e, mapping) for e in exprs]
        cache.configure_heyoka_cache()
        variables = list(self.newtonian.positions) if kind == "accel_q" else list(self.variables)
        fn = hy.cfunc(exprs, variables) if exprs else None
        with self._lock:
            self.__dict__["_compiled"][key] = fn
        return fn

    def invariant_values(self, y: np.ndarray, t: float = 0.0, pars: np.ndarray | None = None) -> dict:
        """Invariants of states shaped (dim, N): name -> array (N,)."""
        if not self.invariants:
            return {}
        y = np.asarray(y, dtype=np.float64)
        N = y.shape[1]
        P = self.pars_for(N, pars)
        fn = self.compiled("inv", None)
        out = fn(np.ascontiguousarray(y), pars=P, time=np.full(N, float(t)))
        return {k: out[i] for i, k in enumerate(sorted(self.invariants))}

    def __repr__(self) -> str:
        return f"Problem({self.name!r}, dim={self.dim}, form={self.form})"

    def __getstate__(self):
        state = dict(self.__dict__)
        state.pop("_lock", None)
        state.pop("_compiled", None)
        state.pop("jacobian_expressions", None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._lock = threading.Lock()


def _check_optional_positive(problem: str, name: str, value: Any) -> float | None:
    if value is None:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"problem {problem!r}: `{name}` must be a positive number, got {value!r}") from None
    if not (math.isfinite(x) and x > 0.0):
        raise InputError(f"problem {problem!r}: `{name}` must be a positive finite number, got {value!r}")
    return x


def _check_structure(name: str, structure: Any, var_names: list[str]) -> None:
    """A declared N-body structure must describe exactly this state (its derived variables)."""
    if not isinstance(structure, NBody):
        raise InputError(f"problem {name!r}: `structure` must be an NBody, got {type(structure).__name__}")
    derived = [str(v) for v in structure.derive()[0]]
    if derived != var_names:
        raise InputError(
            f"problem {name!r}: `structure` describes the state {derived}, the problem has {var_names}"
        )


def _subs_pars(e: hy.expression, mapping: dict[str, hy.expression]) -> hy.expression:
    """Replace runtime parameters p0, p1, ... by constants."""
    pars = [hy.par[int(k[1:])] for k in mapping]
    return hy.subs(e, dict(zip(pars, mapping.values(), strict=True)))


class Dynamics:
    """A problem's numerical functions for one ensemble: f(t, Y), a(t, Q, V), J(t, Y).

    States are shaped (dim, N), ensemble axis last. Each call counts as one right-hand-side (or
    force, or Jacobian) evaluation of the whole ensemble: `counts` keeps the books.
    Parameters shared by all members are compiled in as constants (faster calls); differing
    parameters are passed at run time. The call path is chosen once, here, because steppers
    call these functions millions of times: a plain compiled call costs ~2.5 us, and every
    keyword argument or dictionary built per call adds to it.
    """

    def __init__(self, problem: Problem, pars: np.ndarray):
        self.problem = problem
        self.pars = np.ascontiguousarray(pars, dtype=np.float64)
        self.size = self.pars.shape[1] if self.pars.ndim == 2 else 1
        uniform = self.pars.size == 0 or bool(np.all(self.pars == self.pars[:, :1]))
        self.constants = tuple(float(v) for v in self.pars[:, 0]) if uniform and self.size else None
        self.time_dependent = problem.time_dependent
        self.dim = problem.dim
        self.nq = len(problem.newtonian.positions) if problem.newtonian is not None else 0
        self.counts = {"rhs": 0, "accel": 0, "jac": 0}
        self._runtime_pars = self.constants is None and self.pars.size > 0
        self._tbuf = np.zeros(self.size)
        self._f = problem.compiled("rhs", self.constants)
        self._a = None
        self._a_positions_only = False
        if problem.newtonian is not None:
            self._a_positions_only = not problem.velocity_dependent
            kind = "accel_q" if self._a_positions_only else "accel"
            self._a = problem.compiled(kind, self.constants)
        self._qv = np.empty((self.dim, self.size)) if problem.newtonian is not None else None

    def _kwargs(self, t: float, n: int) -> dict:
        kw = {}
        if self._runtime_pars:
            kw["pars"] = self.pars
        if self.time_dependent:
            if self._tbuf.shape[0] != n:
                self._tbuf = np.zeros(n)
            self._tbuf.fill(t)
            kw["time"] = self._tbuf
        return kw

    def _call(self, fn, t: float, x: np.ndarray, out: np.ndarray | None) -> np.ndarray:
        if not (self.time_dependent or self._runtime_pars):
            if out is None:
                return fn(x)
            fn(x, outputs=out)
            return out
        if out is None:
            return fn(x, **self._kwargs(t, x.shape[1]))
        fn(x, outputs=out, **self._kwargs(t, x.shape[1]))
        return out

    def f(self, t: float, y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """First-order right-hand side, y shaped (dim, N)."""
        self.counts["rhs"] += 1
        return self._call(self._f, t, y, out)

    def accel(self, t: float, q: np.ndarray, v: np.ndarray | None = None, out=None) -> np.ndarray:
        """Acceleration a(q, v, t), q and v shaped (nq, N). v may be None when a ignores it."""
        if self._a is None:
            raise InputError(f"problem {self.problem.name!r} has no Newtonian form")
        self.counts["accel"] += 1
        if self._a_positions_only:
            if not q.flags.c_contiguous:
                q = np.ascontiguousarray(q)
            return self._call(self._a, t, q, out)
        n = q.shape[1]
        if self._qv is None or self._qv.shape[1] != n:
            self._qv = np.empty((self.dim, n))
        self._qv[: self.nq] = q
        if v is None:
            self._qv[self.nq :] = 0.0
        else:
            self._qv[self.nq :] = v
        return self._call(self._a, t, self._qv, out)

    def jac(self, t: float, y: np.ndarray) -> np.ndarray:
        """Jacobian df/dy shaped (dim, dim, N)."""
        self.counts["jac"] += 1
        fn = self.problem.compiled("jac", self.constants)
        out = self._call(fn, t, y, None)
        return out.reshape(self.dim, self.dim, y.shape[1])


# -- input checks shared by the public API ------------------------------------------------------
def check_time(value: Any, name: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"`{name}` must be a real number, got {value!r}") from None
    if not math.isfinite(x):
        raise InputError(f"`{name}` must be finite, got {x!r}")
    return x


def check_ensemble_size(size: Any) -> int:
    from harness.tolerances import MAX_ENSEMBLE_SIZE

    if isinstance(size, bool) or not isinstance(size, int | np.integer):
        raise InputError(f"`ensemble` size must be a positive integer, got {size!r}")
    if size < 1:
        raise InputError(f"`ensemble` size must be at least 1, got {size}")
    if size > MAX_ENSEMBLE_SIZE:
        raise InputError(f"`ensemble` size must be at most {MAX_ENSEMBLE_SIZE}, got {size}")
    return int(size)


def check_state(y: Any, dim: int, name: str = "y0") -> np.ndarray:
    """A state shaped (dim,) or (dim, N) as a float64 (dim, N) array, finite."""
    try:
        arr = np.array(y, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"`{name}` must be numeric, got {type(y).__name__}") from None
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] != dim or arr.shape[1] < 1:
        raise InputError(f"`{name}` must have shape ({dim},) or ({dim}, N), got {np.shape(y)}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"`{name}` must be finite (no NaN or inf)")
    return arr
