"""A problem's functions as JAX code, derived from its one symbolic (heyoka) definition.

`jax_functions(problem)` returns a `JaxFunctions`: the right-hand side f(t, y), the acceleration
a(t, q, v) of a Newtonian problem and the Jacobian J(t, y) = df/dy, each a jit-compiled
`jax.numpy` function of states shaped (dim, N) (ensemble axis last, as everywhere in the harness),
with the problem's parameters given as an array (P, N) or left at their defaults.

How: heyoka's own `to_sympy` hands over the expression tree (heyoka's Python objects expose no
structure of their own, and its printed form is shortened with "..." for long expressions); each
node of that tree (Add, Mul, Pow, Symbol, Number, sin, ...) becomes the `jax.numpy` operation of
the same meaning; `par[i]` is the i-th parameter, `heyoka_time()` the time. An operation with no
JAX counterpart (heyoka's `select`, `kepE`, ...) is refused with its name. SymPy distributes a
number over a sum (3(x - y) -> 3x - 3y), so the JAX functions agree with heyoka's compiled ones
to rounding, not bit for bit; the tests compare every catalogue problem's at random states.

JAX computes in float32 unless 64-bit mode is on; the harness measures float64 steppers, so
`jax_functions` refuses to build in 32-bit mode (one line saying how to turn 64-bit on) rather
than measure float32 rounding as method error.
Reference: heyoka expression system, https://bluescarni.github.io/heyoka.py (expressions,
`cfunc`); JAX, `jax.config.update("jax_enable_x64", True)`.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import heyoka as hy
import numpy as np

from harness.errors import InputError
from harness.problem import Problem
from harness.registry import get_problem

__all__ = ["JaxFunctions", "jax_functions", "require_x64", "expression_to_jax"]

# sympy function class name -> jax.numpy function name
_FUNCTIONS = {
    "sin": "sin", "cos": "cos", "tan": "tan", "asin": "arcsin", "acos": "arccos", "atan": "arctan",
    "sinh": "sinh", "cosh": "cosh", "tanh": "tanh", "asinh": "arcsinh", "acosh": "arccosh",
    "atanh": "arctanh", "exp": "exp", "log": "log", "atan2": "arctan2",
}


def require_x64() -> Any:
    """The `jax` module, after checking 64-bit mode is on; `InputError` otherwise.

    Returns
    -------
    The imported `jax` module.
    """
    try:
        import jax
    except ImportError:
        raise InputError("the JAX path needs `jax` (pip install 'integrator-harness[jax]')") from None
    if not jax.config.read("jax_enable_x64"):
        raise InputError(
            "JAX is in 32-bit mode: the harness measures float64 steppers; call "
            "jax.config.update('jax_enable_x64', True) before building JAX functions"
        )
    return jax


def _compile(node: Any, names: dict[str, Callable], jnp: Any) -> Callable:
    """A function env -> value for one sympy expression node."""
    import sympy

    if node.is_Number:
        value = float(node)
        return lambda env: value
    if node.is_Symbol:
        if node.name not in names:
            raise InputError(f"the expression reads {node.name!r}, which is neither a variable, a "
                             "parameter nor the time")
        return names[node.name]
    args = [_compile(a, names, jnp) for a in node.args]
    if node.is_Add:
        return lambda env: _fold(jnp.add, [a(env) for a in args])
    if node.is_Mul:
        return lambda env: _fold(jnp.multiply, [a(env) for a in args])
    if node.is_Pow:
        base, power = args
        exponent = node.args[1]
        if exponent == sympy.Rational(1, 2):
            return lambda env: jnp.sqrt(base(env))
        if exponent.is_Integer and abs(int(exponent)) <= 64:
            k = int(exponent)  # integer powers by multiplication, as heyoka's own code does
            return lambda env: jnp.power(base(env), k)
        return lambda env: jnp.power(base(env), power(env))
    fname = type(node).__name__
    if fname == "heyoka_time" and not node.args:
        return names["t"]
    if fname in _FUNCTIONS and len(args) in (1, 2):
        fn = getattr(jnp, _FUNCTIONS[fname])
        return lambda env: fn(*(a(env) for a in args))
    if fname == "erf" and len(args) == 1:
        from jax.scipy.special import erf

        return lambda env: erf(args[0](env))
    raise InputError(f"the expression uses {fname} with {len(args)} arguments, which has no JAX "
                     "counterpart here")


def _fold(op: Callable, values: list) -> Any:
    out = values[0]
    for v in values[1:]:
        out = op(out, v)
    return out


def expression_to_jax(expr: Any, variables: Sequence[str]) -> Callable:
    """One heyoka expression as a function `(t, values, pars) -> array` of `jax.numpy` code.

    Parameters
    ----------
    expr : a heyoka expression.
    variables : the variable names, in the order of `values`.

    Returns
    -------
    fn(t, values, pars): `values` a sequence of arrays (one per variable), `pars` an array whose
    row i is parameter `p<i>`; the result broadcasts over the arrays' shape.
    """
    import jax.numpy as jnp

    try:
        tree = hy.to_sympy(expr)
    except Exception as exc:  # heyoka names the function it cannot convert
        raise InputError(f"the JAX path cannot translate {str(expr)[:60]!r}: {exc}") from None
    index = {name: i for i, name in enumerate(variables)}
    names: dict[str, Callable] = {n: (lambda env, i=i: env[0][i]) for n, i in index.items()}
    names["t"] = lambda env: env[1]
    for symbol in tree.free_symbols:
        found = re.fullmatch(r"par\[(\d+)\]", symbol.name)
        if found and symbol.name not in names:
            k = int(found.group(1))
            names[symbol.name] = lambda env, k=k: env[2][k]
    body = _compile(tree, names, jnp)
    return lambda t, values, pars: body((values, t, pars))


@dataclass(frozen=True)
class JaxFunctions:
    """A problem's JAX functions (see the module docstring). States are (dim, N) or (dim,).

    `f(t, y, pars=None)`, `accel(t, q, v=None, pars=None)` (Newtonian problems) and
    `jac(t, y, pars=None)` -> (dim, dim, ...) are jit-compiled; `pars` defaults to the problem's
    parameter values. `y0` is the initial state (dim, 1), `ensemble(size, seed)` the harness's
    ensemble of starts, both as JAX float64 arrays.
    """

    problem: Any
    f: Callable
    jac: Callable
    accel: Callable | None

    @property
    def y0(self) -> Any:
        import jax.numpy as jnp

        return jnp.asarray(self.problem.y0[:, None], dtype=jnp.float64)

    def ensemble(self, size: int, seed: int = 0) -> Any:
        """The problem's start ensemble as a JAX float64 array.

        Parameters
        ----------
        size : int, the number of members; seed : int, the random seed.

        Returns
        -------
        jax.Array: the states, as `Problem.ensemble` gives them.
        """
        import jax.numpy as jnp

        return jnp.asarray(self.problem.ensemble(size, seed=seed), dtype=jnp.float64)

    def bind(self, pars: np.ndarray | None) -> tuple[Callable, Callable, Callable | None]:
        """(f, jac, accel) with `pars` (P, N) fixed: functions of (t, y) or (t, q, v).

        Parameters
        ----------
        pars : (P, N) parameter values, or None for the problem's own.

        Returns
        -------
        tuple: (f, jac, accel), accel None without a Newtonian form.
        """
        import jax.numpy as jnp

        p = self._pars(pars)
        pj = jnp.asarray(p, dtype=jnp.float64)
        f = lambda t, y: self.f(t, y, pj)  # noqa: E731
        jac = lambda t, y: self.jac(t, y, pj)  # noqa: E731
        accel = None if self.accel is None else (lambda t, q, v=None: self.accel(t, q, v, pj))
        return f, jac, accel

    def _pars(self, pars):
        if pars is None:
            return self.problem.parameter_values[:, None]
        return np.asarray(pars, dtype=np.float64)


_built: dict[str, JaxFunctions] = {}
_lock = threading.Lock()


def jax_functions(problem: Any) -> JaxFunctions:
    """The JAX functions of `problem` (a `Problem` or a registered name), built once per
    definition (keyed on the problem's fingerprint).

    Parameters
    ----------
    problem : a `harness.problem.Problem` or the name of a registered problem.

    Returns
    -------
    A `JaxFunctions`. Raises `InputError` when JAX is missing or in 32-bit mode, or when the
    definition uses an operation with no JAX counterpart.
    """
    jax = require_x64()
    import jax.numpy as jnp

    if isinstance(problem, str):
        problem = get_problem(problem)
    if not isinstance(problem, Problem):
        raise InputError(f"`problem` must be a Problem or a problem name, got {type(problem).__name__}")
    key = problem.fingerprint()
    with _lock:
        if key in _built:
            return _built[key]
    names = [str(v) for v in problem.variables]
    defaults = jnp.asarray(problem.parameter_values[:, None], dtype=jnp.float64)

    def vector(exprs, variables):
        fns = [expression_to_jax(e, variables) for e in exprs]

        def evaluate(t, values, pars):
            shape = jnp.shape(values[0])
            return jnp.stack([jnp.broadcast_to(jnp.asarray(fn(t, values, pars), jnp.float64), shape)
                              for fn in fns])

        return evaluate

    rhs = vector(problem.rhs, names)
    jac_rows = vector(problem.jacobian_expressions, names)
    dim = problem.dim

    def f(t, y, pars=None):
        p = defaults if pars is None else pars
        return rhs(t, [y[i] for i in range(dim)], p)

    def jac(t, y, pars=None):
        p = defaults if pars is None else pars
        out = jac_rows(t, [y[i] for i in range(dim)], p)
        return out.reshape((dim, dim, *jnp.shape(y)[1:]))

    accel_fn = None
    if problem.newtonian is not None:
        nq = len(problem.newtonian.positions)
        acc = vector(problem.newtonian.acceleration, names)

        def accel(t, q, v=None, pars=None):
            p = defaults if pars is None else pars
            vv = jnp.zeros_like(q) if v is None else v
            return acc(t, [q[i] for i in range(nq)] + [vv[i] for i in range(nq)], p)

        accel_fn = jax.jit(accel)
    built = JaxFunctions(problem=problem, f=jax.jit(f), jac=jax.jit(jac), accel=accel_fn)
    with _lock:
        _built[key] = built
    return built
