"""Step contracts that fit real libraries: a solver with state (init/step), implicit solvers
offered the problem's Jacobian and linear solve, multistep starters, and JAX-compiled stepping.

`StateStepper(init, step, y=...)` wraps a library's own init/step pair:

1. `init(field, t0, y0, h) -> state` builds the solver's state at t0 (y0 shaped (dim, N),
   ensemble axis last). With `history=k > 1` (a k-step method) it is called once the harness
   has the k starting states: `init(field, t0, [y0, ..., y_{k-1}], h)` at t0, ..., t0+(k-1)h, the
   later ones from the certified reference (`harness.ground_truth.reference`), so a starter's
   error never shows in the method's order. Until then the harness steps through the
   starting values itself.
2. `step(field, state) -> state` advances the state by the h given to `init` (negative after
   a time reversal). It never modifies its argument.
3. `y(state)` reads the state's y, shaped (dim, N) (default: `state.y` or `state["y"]`).
4. `reverse(state) -> state` turns time around (h -> -h) keeping whatever the method carries
   (a reversible method's auxiliary state, a multistep method's history). Without it the
   harness restarts with `init` from the current y and -h: exact for a one-step method whose
   state holds nothing but y (and derived data such as an FSAL derivative), wrong for a
   reversible Heun's second state; a k-step method must give `reverse`.
5. `field` is what the step may call: `field(t, y)` the right-hand side, `field.accel(t, q, v)`
   the acceleration of a Newtonian problem, `field.jac(t, y)` the Jacobian (dim, dim, N), and
   `field.solve(A, b)` the linear solve of A x = b for each member (A (dim, dim, N), b (dim, N)).
   An implicit method (`implicit=True`) uses the last two; the harness counts every call of
   f, accel and jac (NumPy backend).
6. `backend="jax"`: the field is the problem's JAX functions (`harness.jax_problem`), the state
   JAX arrays, and `step` a pure JAX function: n steps run as one jit-compiled loop
   (`jax.lax.fori_loop`), so a check runs at JAX speed. Calls inside compiled code cannot be
   counted; each step books `evals_per_step` right-hand-side evaluations.
7. An embedded pair states its error estimate: `error(state)` returns the last step's
   y - y_hat (y_hat from the second weights), `embedded_order` the order claimed for y_hat.
   `embedded()` is then the stepper of the embedded method itself: each step advances the
   state and restarts `init` from y_hat, so y_hat is what is propagated and measured.
8. The state's y must be float64 (a float32 state is refused: its rounding would be measured as
   the method's error).
Claims (order, symmetric, symplectic, implicit) are stated, never inferred from a name.
Reference: diffrax's `AbstractSolver.init`/`step` (Kidger, *On Neural Differential Equations*,
2021, ch. 5) is the model of rules 1-2; Hairer, Norsett & Wanner, *Solving ODEs I*, III.1
(starting values of multistep methods).
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import weakref
from collections.abc import Callable
from typing import Any

import numpy as np

from harness.errors import InputError, StepperOutputError
from harness.ground_truth import reference
from harness.jax_problem import jax_functions, require_x64
from harness.problem import Dynamics
from harness.problem.checks import check_positive
from harness.sources import source_of
from harness.stepper import FORMS, AdaptiveStepper, Carry, Stepper, StepperInfo

__all__ = ["Field", "StateStepper", "AdaptiveStateStepper", "BACKENDS", "checked_float64", "batched_solve",
           "user_step_info"]

BACKENDS = ("numpy", "jax")


def batched_solve(A: Any, b: Any, xp: Any = np) -> Any:
    """x with A[:, :, k] x[:, k] = b[:, k] for every member k (A (dim, dim, N), b (dim, N)).

    Parameters
    ----------
    A : array, shape (dim, dim, N), one matrix per member.
    b : array, shape (dim, N), one right-hand side per member.
    xp : module, optional, the array namespace (numpy, or jax.numpy).

    Returns
    -------
    array, shape (dim, N): the solutions.
    """
    mats = xp.moveaxis(A, -1, 0)
    rhs = xp.moveaxis(b, -1, 0)[..., None]
    return xp.moveaxis(xp.linalg.solve(mats, rhs)[..., 0], 0, -1)


def checked_float64(y: Any, name: str, when: str) -> np.ndarray:
    """`y` as a float64 array; `StepperOutputError` when it holds fewer than 64-bit floats.

    Parameters
    ----------
    y : array_like, a state a library step returned.
    name : str, the stepper's name (for the message).
    when : str, where in the run (for the message).

    Returns
    -------
    ndarray: `y` as float64; `StepperOutputError` for a narrower float or a complex state.
    """
    dtype = getattr(y, "dtype", None)
    if dtype is not None and np.issubdtype(np.dtype(dtype), np.floating) and np.dtype(dtype).itemsize < 8:
        raise StepperOutputError(
            f"stepper {name!r} returned a {np.dtype(dtype).name} state {when}; the harness measures "
            "float64 steppers (a float32 state's rounding, ~1e-7, would read as method error): "
            "step in float64 (for JAX: jax.config.update('jax_enable_x64', True))"
        )
    if np.iscomplexobj(y):
        raise StepperOutputError(f"stepper {name!r} returned a complex state {when}; expected real "
                                 "numbers (complex values are not cast to real)")
    return np.asarray(y, dtype=np.float64)


def user_step_info(step: Callable, name: str | None, order: int, evals: int, claims: dict,
                   what: str, implementation: str) -> StepperInfo:
    """The `StepperInfo` of a stepper made from user functions, as `FunctionStepper` and
    `StateStepper` declare it (family "user", its claims taken as given).

    Parameters
    ----------
    step : the step function (its name, module, qualified name and docstring fill the blanks).
    name, order, evals : the stepper's name (None: the function's), claimed order and
        evaluations per step; claims : implicit, symplectic, symmetric, form,
        velocity_dependent, reference and description as the constructor took them.
    what, implementation : how the reference and `implementation` name the functions.

    Returns
    -------
    StepperInfo
    """
    where = f"{getattr(step, '__module__', '?')}.{getattr(step, '__qualname__', repr(step))}"
    return StepperInfo(
        name=name or getattr(step, "__name__", "user-step"),
        family="user",
        claimed_order=order,
        explicit=not claims["implicit"],
        symplectic=bool(claims["symplectic"]),
        symmetric=bool(claims["symmetric"]),
        evals_per_step=evals,
        form=claims["form"],
        velocity_dependent=bool(claims["velocity_dependent"]),
        reference=claims["reference"] or f"user-supplied {what} {where}",
        description=claims["description"] or (inspect.getdoc(step) or "").split("\n")[0],
        implementation=implementation,
    )


class Field:
    """The problem's functions offered to a step (rule 5 of the module docstring)."""

    def __init__(self, f: Callable, accel: Callable | None, jac: Callable, solve: Callable):
        self._f, self.accel, self.jac, self.solve = f, accel, jac, solve

    def __call__(self, t: Any, y: Any) -> Any:
        return self._f(t, y)

    @classmethod
    def numpy(cls, dyn: Dynamics) -> Field:
        """A field over `dyn`'s counted NumPy functions.

        Parameters
        ----------
        dyn : Dynamics, the problem's dynamics at fixed parameters.

        Returns
        -------
        Field
        """
        accel = dyn.accel if dyn.problem.newtonian is not None else None
        return cls(dyn.f, accel, dyn.jac, batched_solve)

    @classmethod
    def jax(cls, dyn: Dynamics) -> Field:
        """A field over the problem's JAX functions, bound to `dyn`'s parameters.

        Parameters
        ----------
        dyn : Dynamics, the problem's dynamics (its problem and parameter values are used).

        Returns
        -------
        Field
        """
        import jax.numpy as jnp

        f, jac, accel = jax_functions(dyn.problem).bind(dyn.pars)
        return cls(f, accel, jac, lambda A, b: batched_solve(A, b, jnp))


def _default_y(state: Any) -> Any:
    if hasattr(state, "y"):
        return state.y
    if isinstance(state, dict) and "y" in state:
        return state["y"]
    raise InputError("the state has no `y` (attribute or key): give `y=` to read it from the state")


class StateStepper(Stepper):
    """A library solver's init/step pair under the harness's stepper contract (module docstring).

    Parameters
    ----------
    init, step : see rules 1-2.
    y : reads the state's y (rule 3); default `state.y` or `state["y"]`.
    reverse : turns the state's time around (rule 4).
    name, order, symmetric, symplectic, implicit, form, evals_per_step, reference, description :
        the claims and the record (as `FunctionStepper`); `velocity_dependent`: the step reads
        `field.accel(t, q, v)` with v, so it can run problems whose force depends on velocity.
    history : k for a k-step method (rule 1); 1 for a one-step method.
    error, embedded_order : an embedded pair's error estimate and the embedded order (rule 7).
    coefficients : the method's published coefficients (a `ButcherTableau`) when the library
        publishes them: the rules then derive what to expect (order, stage order and its
        reduction on stiff problems, stability) from them, as for a built-in method, while the
        library's own step is what is measured.
    backend : 'numpy' (NumPy arrays, counted calls) or 'jax' (rule 6).
    """

    def __init__(
        self,
        init: Callable[..., Any],
        step: Callable[..., Any],
        *,
        y: Callable[[Any], Any] | None = None,
        reverse: Callable[[Any], Any] | None = None,
        name: str | None = None,
        order: int | None = None,
        symmetric: bool = False,
        symplectic: bool = False,
        implicit: bool = False,
        form: str = "first-order",
        evals_per_step: float = 1.0,
        velocity_dependent: bool = False,
        history: int = 1,
        error: Callable[[Any], Any] | None = None,
        embedded_order: int | None = None,
        coefficients: Any = None,
        backend: str = "numpy",
        reference: str = "",
        description: str = "",
    ):
        if (error is None) != (embedded_order is None):
            raise InputError("an embedded pair needs both `error` (its estimate) and `embedded_order`")
        for arg, fn in (("init", init), ("step", step), ("y", y), ("reverse", reverse), ("error", error)):
            if fn is not None and not callable(fn):
                raise InputError(f"`{arg}` must be a function, got {type(fn).__name__}")
        if form not in FORMS:
            raise InputError(f"`form` must be one of {FORMS}, got {form!r}")
        if backend not in BACKENDS:
            raise InputError(f"`backend` must be one of {BACKENDS}, got {backend!r}")
        if isinstance(history, bool) or not isinstance(history, int) or history < 1:
            raise InputError(f"`history` must be a whole number >= 1, got {history!r}")
        if backend == "jax":
            require_x64()
            # a JAX loop traps no overflow, so a replay cannot tell a blow-up's NaN from the
            # step's own: like a compiled loop, it gets the benefit of the doubt
            self._overflows = lambda fresh, k: True
        evals = check_positive(evals_per_step, "`evals_per_step`")
        self.init_function, self.step_function = init, step
        self.y_function = y or _default_y
        self.reverse_function = reverse
        self.backend = backend
        self.history_length = history
        self.error_function, self.embedded_order = error, embedded_order
        self.coefficients = coefficients
        self._claims = {"symmetric": symmetric, "symplectic": symplectic, "implicit": implicit,
                        "form": form, "evals_per_step": evals_per_step,
                        "velocity_dependent": velocity_dependent, "backend": backend}
        self._loops: dict[Any, Callable] = {}
        self._fields: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # one per Dynamics
        self.info = user_step_info(
            step, name or getattr(step, "__name__", "user-state-step"), order, evals,
            dict(self._claims, reference=reference, description=description),
            "init/step functions", f"user init/step ({backend})")

    def embedded(self) -> StateStepper:
        """The embedded method of a pair as a stepper of its own (rule 7), claiming
        `embedded_order`, named `<name>@embedded`.

        Returns
        -------
        StateStepper: `InputError` when the stepper declares no `error`.
        """
        if self.error_function is None:
            raise InputError(f"stepper {self.info.name!r} declares no embedded pair (`error`)")
        init, step, read_y, error = self.init_function, self.step_function, self.y_function, \
            self.error_function
        reverse = self.reverse_function

        def init_hat(f, t0, y0, h):
            return {"t": t0, "h": h, "inner": init(f, t0, y0, h)}

        def step_hat(f, s):
            inner = step(f, s["inner"])
            t1 = s["t"] + s["h"]
            return {"t": t1, "h": s["h"], "inner": init(f, t1, read_y(inner) - error(inner), s["h"])}

        def reverse_hat(s):
            inner = reverse(s["inner"]) if reverse is not None else s["inner"]
            return {"t": s["t"], "h": -s["h"], "inner": inner}

        claims = {**self._claims, "symmetric": False, "symplectic": False}
        hat = StateStepper(init_hat, step_hat, y=lambda s: read_y(s["inner"]), reverse=reverse_hat,
                           name=f"{self.info.name}@embedded", order=self.embedded_order,
                           reference=self.info.reference, description=f"embedded method of "
                           f"{self.info.name}", **claims)
        hat.parent_fingerprint = self.fingerprint()  # the wrappers' source is the same for every pair
        return hat

    def fingerprint(self) -> str:
        """`Stepper.fingerprint` plus the source of the init/step/y/reverse/error functions, the
        history length and the parent's fingerprint (an embedded method's).

        Returns
        -------
        str
        """
        parts = []
        for fn in (self.init_function, self.step_function, self.y_function, self.reverse_function,
                   self.error_function):
            if fn is None:
                continue
            try:
                parts.append(source_of(fn))
            except (OSError, TypeError):
                parts.append(getattr(fn, "__qualname__", type(fn).__qualname__))
        parts.append(getattr(self, "parent_fingerprint", ""))
        digest = hashlib.sha256("\n".join(parts).encode()).hexdigest()
        return super().fingerprint() + "\n" + f"history={self.history_length}\n{digest}"

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_loops"] = {}  # compiled loops and fields are rebuilt where the stepper runs
        state.pop("_fields", None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._fields = weakref.WeakKeyDictionary()
        if self.backend == "jax":  # built in 64-bit mode (checked); a worker process starts in 32
            import jax

            jax.config.update("jax_enable_x64", True)

    # -- the contract's private math ----------------------------------------------------------------
    def _field(self, dyn: Dynamics) -> Field:
        field = self._fields.get(dyn)
        if field is None:
            field = self._fields[dyn] = Field.jax(dyn) if self.backend == "jax" else Field.numpy(dyn)
        return field

    def _array(self, y: np.ndarray) -> Any:
        if self.backend == "jax":
            import jax.numpy as jnp

            return jnp.asarray(y, dtype=jnp.float64)
        return y

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = Carry(t0, h, y0, state=None, known=[y0], pending=[])
        if self.history_length > 1:
            count = self.history_length - 1
            times = t0 + h * np.arange(1, count + 1)
            ref = reference(dyn.problem, times, y0.copy(), t0=t0, pars=dyn.pars)
            c.pending = [np.array(ref.y[i], dtype=np.float64) for i in range(count)]
            dyn.counts["starter_steps"] = dyn.counts.get("starter_steps", 0) + count
        self._maybe_init(dyn, c)
        return c

    def _start_from_history(self, dyn: Dynamics, t0: float, h: float, history: list) -> Carry:
        k = len(history)
        c = Carry(t0 + (k - 1) * h, h, history[-1], state=None, known=list(history), pending=[])
        self._maybe_init(dyn, c)
        return c

    def _maybe_init(self, dyn: Dynamics, c: Carry) -> None:
        if c.state is not None or len(c.known) < self.history_length:
            return
        ys = [self._array(y) for y in c.known]
        t_first = c.t - (len(ys) - 1) * c.h  # the oldest known state's time
        arg = ys[0] if self.history_length == 1 else ys
        c.state = self.init_function(self._field(dyn), t_first, arg, c.h, **self._init_options())
        self._book_internal(dyn, c, fresh=True)
        c.known = []

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        if c.state is None:  # stepping through the starting values (rule 1)
            c.y = c.pending.pop(0)
            c.known.append(c.y)
            c.n += 1
            self._maybe_init(dyn, c)
            c.n -= 1  # `_advance` counts the step
            return
        if self.backend == "jax":  # one step through the compiled loop: no op-by-op dispatch
            c.state = self._loop(dyn)(c.state, 1)
            dyn.counts["rhs"] += self.info.evals_per_step
        else:
            c.state = self.step_function(self._field(dyn), c.state)
        self._book_internal(dyn, c)

    def _advance(self, dyn: Dynamics, c: Carry, n: int) -> None:
        while n > 0 and c.state is None:
            self._step(dyn, c)
            c.n += 1
            n -= 1
        if n <= 0:
            return
        if self.backend != "jax":
            super()._advance(dyn, c, n)
            return
        loop = self._loop(dyn)
        c.state = loop(c.state, n)
        c.n += n
        dyn.counts["rhs"] += n * self.info.evals_per_step
        self._book_internal(dyn, c)

    # -- hooks of the adaptive contract (AdaptiveStateStepper) ---------------------------------------
    def _init_options(self) -> dict:
        return {}

    def _book_internal(self, dyn: Dynamics, c: Carry, fresh: bool = False) -> None:
        return None

    def _loop(self, dyn: Dynamics) -> Callable:
        """n steps as one compiled loop, built once per problem definition and parameters."""
        key = (dyn.problem.fingerprint(), dyn.pars.tobytes(), dyn.pars.shape)
        loop = self._loops.get(key)
        if loop is None:
            import jax

            field, step = self._field(dyn), self.step_function

            def run(state, n):
                return jax.lax.fori_loop(0, n, lambda i, s: step(field, s), state)

            loop = self._loops[key] = jax.jit(run)
        return loop

    def _observe(self, dyn: Dynamics, c: Carry) -> np.ndarray:
        if c.state is None:
            return np.array(c.y, dtype=np.float64)
        y = checked_float64(self.y_function(c.state), self.info.name, f"at t = {c.t:.6g}")
        return y.copy()

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        y = self._observe(dyn, c)
        super()._reverse(dyn, c)
        if self.reverse_function is not None and c.state is not None:
            c.state = self.reverse_function(c.state)
            return
        if self.history_length > 1:
            raise InputError(
                f"stepper {self.info.name!r} is a {self.history_length}-step method without "
                "`reverse`: its history cannot be turned around by restarting from y"
            )
        c.state = self.init_function(self._field(dyn), c.t, self._array(y), c.h, **self._init_options())
        self._book_internal(dyn, c, fresh=True)


class AdaptiveStateStepper(StateStepper, AdaptiveStepper):
    """A library's adaptive solver under the adaptive contract (rules 7-8 of `AdaptiveStepper`):
    `init(field, t0, y0, h, tol=tol)` gets the controller's tolerance, `step(field, state)`
    advances exactly to t + h with the solver's own internal steps, and `internal_steps(state)`
    returns how many it has taken since `init` (summed over the ensemble's members), booked as
    `counts["internal_steps"]`. Experiments sweep `tol` (`with_tolerance`), not h. Other
    parameters as `StateStepper`; `order` may be None.
    """

    def __init__(self, init, step, *, internal_steps, tol: float = AdaptiveStepper.tol, **options):
        if not callable(internal_steps):
            raise InputError(f"`internal_steps` must be a function, got {type(internal_steps).__name__}")
        super().__init__(init, step, **options)
        self.internal_steps_function = internal_steps
        self.tol = check_positive(tol, "`tol`")
        self.info = dataclasses.replace(self.info, adaptive=True, extra=self.extra_info())

    def extra_info(self) -> dict:
        """The tolerance, recorded on the stepper's claims.

        Returns
        -------
        dict: {"tol": the tolerance}.
        """
        return {"tol": self.tol}

    def _init_options(self) -> dict:
        return {"tol": self.tol}

    def _book_internal(self, dyn: Dynamics, c: Carry, fresh: bool = False) -> None:
        if fresh:
            c.internal_seen = 0
            return
        taken = int(np.sum(np.asarray(self.internal_steps_function(c.state))))
        dyn.counts["internal_steps"] = dyn.counts.get("internal_steps", 0) + taken - c.internal_seen
        c.internal_seen = taken
