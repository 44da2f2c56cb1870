"""diffrax's solvers as harness steppers: each solver's own `init`/`step` runs, compiled by JAX.

A solver's state here is a dict {"t", "h", "y", "s"}: the time, the step, the state (dim, N)
and the solver's own state (FSAL derivative, reversible Heun's second state, ...). `step` calls
the solver's `step(terms, t, t + h, y, None, s, made_jump=False)` exactly as `diffeqsolve` does
with a constant step size; `reverse` negates h and keeps the solver's state, which is what makes
a reversible solver reversible.

The claims (orders, reversibility, symplecticity) are diffrax's documentation's: its solver
docstrings and `order()` methods (diffrax 0.7.2, `diffrax/_solver/*.py`), stated here as data.
"""

from __future__ import annotations

import diffrax
import jax
import numpy as np
import optimistix

from harness.api import AdaptiveStateStepper, StateStepper
from harness.coefficients import ButcherTableau

jax.config.update("jax_enable_x64", True)

# Newton's iteration in the implicit solvers: stopped at rounding level, so the iteration error
# stays far below the smallest error the convergence sweep measures (~1e-12).
ROOT_TOL = 1e-13


def _terms(field, newtonian: bool, imex: bool = False):
    if imex:  # an IMEX solver's (explicit, implicit) pair: the whole field implicit
        return diffrax.MultiTerm(diffrax.ODETerm(lambda t, y, args: jax.numpy.zeros_like(y)),
                                 diffrax.ODETerm(lambda t, y, args: field(t, y)))
    if newtonian:  # y = (q, v): q' = v (first term, of v), v' = a(q) (second term, of q)
        return (diffrax.ODETerm(lambda t, v, args: v),
                diffrax.ODETerm(lambda t, q, args: field.accel(t, q)))
    return diffrax.ODETerm(lambda t, y, args: field(t, y))


def stepper(solver, *, order: int, name: str, newtonian: bool = False, imex: bool = False,
            embedded_order: int | None = None, **claims) -> StateStepper:
    """`solver` (a diffrax solver object) as a JAX `StateStepper` claiming `order`; with
    `embedded_order`, the step's error estimate y - y_hat is kept in the state ("err")."""
    import jax.numpy as jnp

    def init(field, t0, y0, h):
        terms = _terms(field, newtonian, imex)
        y = (y0[: y0.shape[0] // 2], y0[y0.shape[0] // 2:]) if newtonian else y0
        state = {"t": t0, "h": h, "y": y, "s": solver.init(terms, t0, t0 + h, y, None)}
        if embedded_order is not None:
            state["err"] = jnp.zeros_like(y0)
        return state

    def step(field, state):
        terms = _terms(field, newtonian, imex)
        t, h = state["t"], state["h"]
        y, err, _, s, _ = solver.step(terms, t, t + h, state["y"], None, state["s"], False)
        out = {"t": t + h, "h": h, "y": y, "s": s}
        if embedded_order is not None:
            out["err"] = err
        return out

    def read_y(state):
        import jax.numpy as jnp

        return jnp.concatenate(state["y"]) if newtonian else state["y"]

    def reverse(state):
        return {**state, "h": -state["h"]}

    error = (lambda state: state["err"]) if embedded_order is not None else None
    return StateStepper(init, step, y=read_y, reverse=reverse, name=name, order=order,
                        error=error, embedded_order=embedded_order,
                        backend="jax", form="newtonian" if newtonian else "first-order",
                        reference=f"diffrax {diffrax.__version__}: diffrax.{type(solver).__name__}",
                        **claims)


def adaptive(solver, *, name: str, order: int | None = None) -> AdaptiveStateStepper:
    """`solver` under diffrax's own PID step-size controller (rtol = atol = tol): each harness
    step is one `diffeqsolve` from t to t + h, as a user integrating to output times would."""
    import jax.numpy as jnp

    def init(field, t0, y0, h, *, tol):
        return {"t": t0, "h": h, "y": y0, "tol": tol, "steps": jnp.zeros((), dtype=jnp.int64)}

    def step(field, state):
        t, h = state["t"], state["h"]
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(lambda t, y, args: field(t, y)), solver, t0=t, t1=t + h, dt0=None,
            y0=state["y"], stepsize_controller=diffrax.PIDController(rtol=state["tol"],
                                                                     atol=state["tol"]),
            saveat=diffrax.SaveAt(t1=True), max_steps=100_000)
        return {**state, "t": t + h, "y": sol.ys[-1],
                "steps": state["steps"] + sol.stats["num_accepted_steps"]}

    return AdaptiveStateStepper(init, step, internal_steps=lambda s: s["steps"], name=name,
                                order=order, reverse=lambda s: {**s, "h": -s["h"]}, backend="jax",
                                reference=f"diffrax {diffrax.__version__}: diffrax.{type(solver).__name__}"
                                " with diffrax.PIDController")


def leapfrog_midpoint() -> StateStepper:
    """diffrax's two-step leapfrog/midpoint method, started from exact values (history=2)."""
    solver = diffrax.LeapfrogMidpoint()

    def init(field, t0, ys, h):  # ys = [y(t0), y(t0 + h)]: the state stands at t0 + h
        return {"t": t0 + h, "h": h, "y": ys[1], "s": (t0, ys[0])}

    def step(field, state):
        terms = diffrax.ODETerm(lambda t, y, args: field(t, y))
        t, h = state["t"], state["h"]
        y, _, _, s, _ = solver.step(terms, t, t + h, state["y"], None, state["s"], False)
        return {"t": t + h, "h": h, "y": y, "s": s}

    return StateStepper(init, step, name="diffrax-leapfrog-midpoint", order=2, history=2,
                        backend="jax", reference="diffrax: diffrax.LeapfrogMidpoint")


def published_tableau(solver) -> ButcherTableau:
    """diffrax's own tableau of `solver` as the harness's `ButcherTableau` (A from its lower
    part and diagonal, c with c1 first, b_hat = b_sol - b_error), so the rules derive the stage
    order, and with it the order reduction on stiff problems, from the library's coefficients."""
    t = type(solver).tableau
    s = len(t.b_sol)
    A = np.zeros((s, s))
    for i, row in enumerate(t.a_lower, start=1):
        A[i, :i] = row
    A[np.arange(s), np.arange(s)] = t.a_diagonal if t.a_diagonal is not None else 0.0
    return ButcherTableau(f"diffrax-{type(solver).__name__}", A, t.b_sol, [t.c1, *t.c],
                          b_hat=np.asarray(t.b_sol) - np.asarray(t.b_error))


def _implicit(cls):
    return cls(root_finder=diffrax.VeryChord(rtol=ROOT_TOL, atol=ROOT_TOL, norm=optimistix.max_norm),
               root_find_max_steps=20)


# (solver, documented order): diffrax's `order()` of each solver
EXPLICIT = {
    "euler": (diffrax.Euler(), 1),
    "heun": (diffrax.Heun(), 2),
    "midpoint": (diffrax.Midpoint(), 2),
    "ralston": (diffrax.Ralston(), 2),
    "bosh3": (diffrax.Bosh3(), 3),
    "tsit5": (diffrax.Tsit5(), 5),
    "dopri5": (diffrax.Dopri5(), 5),
    "dopri8": (diffrax.Dopri8(), 8),
}
# embedded orders of the pairs, from their docstrings: Heun 2(1), Bosh3 3(2), Tsit5 5(4), Dopri5 5(4)
EMBEDDED = {"heun": 1, "bosh3": 2, "tsit5": 4, "dopri5": 4}
IMPLICIT = {
    "implicit-euler": (diffrax.ImplicitEuler, 1),
    "kvaerno3": (diffrax.Kvaerno3, 3),
    "kvaerno4": (diffrax.Kvaerno4, 4),
    "kvaerno5": (diffrax.Kvaerno5, 5),
}
# IMEX additive Runge-Kutta methods, run with the whole field as the implicit part
IMEX = {"kencarp3": (diffrax.KenCarp3, 3), "kencarp4": (diffrax.KenCarp4, 4),
        "kencarp5": (diffrax.KenCarp5, 5)}


def all_steppers() -> dict[str, StateStepper]:
    out = {f"diffrax-{k}": stepper(s, order=p, name=f"diffrax-{k}", embedded_order=EMBEDDED.get(k),
                                   coefficients=published_tableau(s)
                                   if hasattr(type(s), "tableau") else None)
           for k, (s, p) in EXPLICIT.items()}
    out.update({f"{out[f'diffrax-{k}'].info.name}@embedded": out[f"diffrax-{k}"].embedded()
                for k in EMBEDDED})
    for k, (c, p) in IMPLICIT.items():
        solver = _implicit(c)
        out[f"diffrax-{k}"] = stepper(solver, order=p, name=f"diffrax-{k}", implicit=True,
                                      coefficients=published_tableau(solver)
                                      if hasattr(type(solver), "tableau") else None)
    out.update({f"diffrax-{k}": stepper(_implicit(c), order=p, name=f"diffrax-{k}", implicit=True,
                                        imex=True) for k, (c, p) in IMEX.items()})
    out["diffrax-reversible-heun"] = stepper(diffrax.ReversibleHeun(), order=2,
                                             name="diffrax-reversible-heun", symmetric=True)
    out["diffrax-semi-implicit-euler"] = stepper(diffrax.SemiImplicitEuler(), order=1,
                                                 name="diffrax-semi-implicit-euler",
                                                 newtonian=True, symplectic=True)
    out["diffrax-leapfrog-midpoint"] = leapfrog_midpoint()
    out["diffrax-tsit5-pid"] = adaptive(diffrax.Tsit5(), name="diffrax-tsit5-pid", order=5)
    return out
