"""The `Problem` class: one symbolic definition (heyoka expressions) checked against the contract
in `harness.problem`, with everything derived from it (ensembles, parameters, fingerprint,
compiled functions, invariants)."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from functools import cached_property
from typing import Any

import heyoka as hy
import numpy as np

from harness import cache
from harness.errors import InputError
from harness.problem.checks import check_ensemble_size, check_positive
from harness.problem.dynamics import Dynamics
from harness.problem.nbody import NBody, NewtonianForm, expression_names
from harness.problem.published import Published
from harness.problem.validation import check_definition, check_start
from harness.scales import derive_perturbation, derive_time_scale, draw_noise
from harness.tolerances import HORIZON_PERIODS

ExactSolution = Callable[[float, np.ndarray, float, np.ndarray], np.ndarray]


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
        published: Published | None = None,
    ):
        variables = tuple(variables)
        name = check_definition(name, variables, newtonian)
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
        unknown = expression_names(rhs) - set(var_names)
        if unknown:
            raise InputError(f"problem {name!r}: `rhs` uses undeclared variables {sorted(unknown)}")
        y0_arr = check_start(name, y0, len(variables))
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
        if published is not None:
            if not isinstance(published, Published):
                raise InputError(f"problem {name!r}: `published` must be a Published record")
            published.check(name, y0_arr, parameters, t_end)
        self.published = published
        self._lock = threading.Lock()

    # -- declared facts -------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        """The number of state variables."""
        return len(self.variables)

    @property
    def form(self) -> str:
        """'newtonian' when an acceleration is declared, else 'first-order'."""
        return "newtonian" if self.newtonian is not None else "first-order"

    @property
    def velocity_dependent(self) -> bool:
        """True for a Newtonian problem whose acceleration reads the velocities."""
        return self.newtonian is not None and self.newtonian.velocity_dependent

    @cached_property
    def time_dependent(self) -> bool:
        """True when the right-hand side reads `hy.time` (non-autonomous)."""
        clock = hy.expression(0.0)  # symbolic: listing a problem compiles nothing
        return any(str(hy.subs(e, {hy.time: clock})) != str(e) for e in self.rhs)

    @property
    def convergence_t_end(self) -> float:
        """The convergence horizon: declared, else the span cut to HORIZON_PERIODS natural
        periods (`time_scale`; order does not depend on the horizon, a long span only costs).
        A problem that turns stiff within its span but not within that cut (ten periods of the
        fastest rate end inside the initial layer, or the fast phase comes later, as OREGO's)
        gets the horizon where it turns stiff (`TimeScale.stiff_onset`: the first T at which T
        times the largest spectral radius up to T reaches STIFF_HORIZON_STEPS), so the
        measurement reaches the slow manifold and the stiff phase. With the fastest rate at the
        start this is STIFF_HORIZON_STEPS / rate: many layer widths."""
        if self.declared_convergence_t_end is not None:
            return self.declared_convergence_t_end

        scale = self.time_scale
        horizon = min(self.t_end, self.t0 + HORIZON_PERIODS * scale.period)
        onset = scale.stiff_onset
        if onset is not None and onset > horizon:
            horizon = min(self.t_end, onset)
        return horizon

    @property
    def parameter_values(self) -> np.ndarray:
        """The default parameter values, in the order of `parameters`."""
        return np.array(list(self.parameters.values()), dtype=np.float64)

    def describe(self) -> dict[str, Any]:
        """Declared properties as plain data (for `harness list problems`).

        Returns
        -------
        dict
            Name, form, dimension, variables and right-hand side as text, y0, span, declared
            horizon, period and perturbation, parameters, invariants and the rest of the declaration.
        """
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
            "published": None if self.published is None else self.published.describe(),
            "on_request": "on-request" in self.tags,
        }

    def fingerprint(self) -> str:
        """A text form of the whole definition: changes whenever the problem changes.

        Returns
        -------
        str
            Name, variables, right-hand side, y0, span, declared scales, parameters, invariants and
            any structure or published form, joined by "|".
        """
        parts = [self.name, *map(str, self.variables), *map(str, self.rhs), self.y0.tobytes().hex()]
        horizon = self.declared_convergence_t_end
        parts += [repr((self.t0, self.t_end, self.t_end if horizon is None else horizon))]
        parts += [f"{k}={v!r}" for k, v in (("period", self.period), ("perturbation", self.perturbation))
                  if v is not None]
        parts += [f"{k}={v!r}" for k, v in self.parameters.items()]
        parts += [f"{k}:{e}" for k, e in sorted(self.invariants.items())]
        if getattr(self, "structure", None) is not None:
            parts.append(repr(sorted(self.structure.describe().items())))
        if getattr(self, "published", None) is not None:
            parts.append(repr(self.published))
        return "|".join(parts)

    # -- initial states -------------------------------------------------------------------------
    def ensemble(self, size: int, *, seed: int = 0, scale: float | None = None) -> np.ndarray:
        """`size` initial states shaped (dim, size): member 0 is `y0`, the others perturbed.

        Component i moves by u * scale * s_i, u uniform in [-1, 1] and s_i the component's scale
        along the orbit (`ensemble_perturbation`), so an order is never the artefact of one
        start. `scale` defaults to the problem's size (declared, or derived so that every
        member stays in the start's dynamical regime: `harness.scales`).

        Parameters
        ----------
        size : int, ensemble size, 1 to MAX_ENSEMBLE_SIZE.
        seed : int, optional, seed of the draws (default 0); member j's draws do not depend on `size`.
        scale : float, optional, the relative size of the perturbation (positive and finite).

        Returns
        -------
        ndarray, shape (dim, size): the initial states.
        """
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
        """Parameter values shaped (P, size), from defaults, a mapping, or an array.

        Parameters
        ----------
        size : int, ensemble size N.
        pars : ndarray or mapping, optional
            None (the defaults), a mapping name -> value (the others default), a (P,) array (the
            same for every member) or a (P, N) array.

        Returns
        -------
        ndarray, shape (P, size): finite float64 values; `InputError` names a bad `pars`.
        """
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
        return derive_time_scale(self)

    @cached_property
    def ensemble_perturbation(self):
        """Relative size and component scales of the ensemble (`harness.scales.Perturbation`)."""
        return derive_perturbation(self)

    # -- derived numerical functions --------------------------------------------------------------
    def dynamics(self, pars: np.ndarray | None = None, size: int = 1) -> Dynamics:
        """Ensemble-batched numerical functions bound to parameter values (P, size).

        Parameters
        ----------
        pars : ndarray, optional, parameter values, as in `pars_for`.
        size : int, optional, ensemble size N (default 1).

        Returns
        -------
        Dynamics: the right-hand side, acceleration and Jacobian with evaluation counters.
        """
        return Dynamics(self, self.pars_for(size, pars))

    @cached_property
    def jacobian_expressions(self) -> list[hy.expression]:
        """d rhs_i / d y_j as heyoka expressions, row by row (the derived Jacobian)."""
        return [hy.diff(f, v) for f in self.rhs for v in self.variables]

    def compiled(self, kind: str, constants: tuple[float, ...] | None) -> Any:
        """The compiled function `kind` ('rhs', 'accel', 'accel_q' (of positions only, for
        accelerations that ignore velocity), 'jac', 'inv'), parameters either
        substituted as constants (a tuple of values) or left as runtime parameters (None).

        Parameters
        ----------
        kind : str, which expressions: 'rhs', 'accel', 'accel_q', 'jac' or 'inv'.
        constants : tuple of float or None, parameter values substituted into the expressions, or None.

        Returns
        -------
        heyoka cfunc or None
            Compiled once per (kind, constants) and kept on the problem; None when there are no
            expressions (no invariants).
        """
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
            exprs = [subs_pars(e, mapping) for e in exprs]
        cache.configure_heyoka_cache()
        variables = list(self.newtonian.positions) if kind == "accel_q" else list(self.variables)
        fn = cache.interruptible(lambda: hy.cfunc(exprs, variables)) if exprs else None
        with self._lock:
            self.__dict__["_compiled"][key] = fn
        return fn

    def invariant_values(self, y: np.ndarray, t: float = 0.0, pars: np.ndarray | None = None) -> dict:
        """Invariants of states shaped (dim, N): name -> array (N,).

        Parameters
        ----------
        y : ndarray, shape (dim, N), states.
        t : float, optional, their time (default 0.0).
        pars : ndarray, optional, parameter values, as in `pars_for`.

        Returns
        -------
        dict of str to ndarray: each invariant's values, shape (N,); empty when the problem declares none.
        """
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
    return check_positive(value, f"problem {problem!r}: `{name}`")


def _check_structure(name: str, structure: Any, var_names: list[str]) -> None:
    """A declared N-body structure must describe exactly this state (its derived variables)."""
    if not isinstance(structure, NBody):
        raise InputError(f"problem {name!r}: `structure` must be an NBody, got {type(structure).__name__}")
    derived = [str(v) for v in structure.derive()[0]]
    if derived != var_names:
        raise InputError(
            f"problem {name!r}: `structure` describes the state {derived}, the problem has {var_names}"
        )


def subs_pars(e: hy.expression, mapping: dict[str, hy.expression]) -> hy.expression:
    """Replace runtime parameters p0, p1, ... by constants.

    Parameters
    ----------
    e : heyoka expression, the expression.
    mapping : dict, "p<i>" -> the expression put in place of ``hy.par[i]``.

    Returns
    -------
    heyoka expression: `e` with the substitutions.
    """
    pars = [hy.par[int(k[1:])] for k in mapping]
    return hy.subs(e, dict(zip(pars, mapping.values(), strict=True)))
