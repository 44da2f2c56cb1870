"""Compiled steppers: the same methods, generated from the same coefficient objects, run by numba.

A second implementation of the explicit Runge-Kutta and splitting families, for long single
trajectories where a per-step NumPy loop costs ~500x a compiled loop (measured: README and the
asv suite). Nothing here holds a coefficient: each compiled stepper wraps a registered NumPy
stepper and reads the tableau (`ButcherTableau` A, b, c) or the scheme (`SplittingScheme`
drift/kick sequence) from it at run time, so one compiled kernel per family serves every table.

How the code is generated (Lam, Pitrou & Seibert, *Numba: a LLVM-based Python JIT compiler*,
LLVM-HPC 2015, for the compiler; heyoka's expression decomposition for the right-hand side):

1. The problem's right-hand side (and, for Newtonian problems, its position-only acceleration)
   is taken from heyoka's decomposition of the compiled function (`cfunc.dc`): a list of
   elementary assignments u_k = op(u_i, u_j), common subexpressions already shared. Each entry
   is printed as Python-like infix (`(u_0 * u_1)`, `div(u_3, u_7)`, `u_6**1.5000000000000000`,
   `sin(u_0)`, `p0` for a parameter, `t` for time), parsed with `ast` and emitted as numba
   source. An operation without a translation makes the problem incompatible (with the reason).
2. The generated functions and the family kernels (templates below) are written to one module
   file per problem in `harness.cache.cache_dir() / "numba"`, named by a hash of its text, and
   imported; every function is `@njit(cache=True)`, so a later process loads the machine code
   from numba's on-disk cache in milliseconds instead of compiling again (a kernel that received
   the right-hand side as an argument would be recompiled in every process).
3. A stepper overrides `Stepper._advance` (and `_step`) to run many steps of every ensemble
   member in one compiled call; start, observation and time reversal are the NumPy family's
   own. Evaluation counts are the NumPy implementation's: one right-hand-side (or force)
   evaluation per stage of the whole ensemble.

Floating-point operations follow the NumPy loops' order (a stage is y + h a_i1 k_1 + h a_i2 k_2
+ ..., zero coefficients skipped; kicks add b h a to v; times are t0 + n h), with fused
multiply-adds allowed as in the NumPy loops' BLAS updates and no other fast-math, so the two
implementations agree to rounding (tested in `tests/test_compiled.py`).
"""

from __future__ import annotations

import ast
import dataclasses
import hashlib
import importlib.util
import os
import sys
import tempfile
import threading
import time
import weakref
from collections.abc import Iterable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from harness import cache
from harness.errors import InputError
from harness.problem import Dynamics, Problem
from harness.stepper import Carry, Stepper
from implementations.runge_kutta import ExplicitRungeKutta
from implementations.splitting import SplittingStepper, StaggeredLeapfrog

__all__ = [
    "CompiledRungeKutta",
    "CompiledSplitting",
    "CompiledLeapfrog",
    "compiled_variant",
    "problem_module",
    "module_source",
    "translate_decomposition",
    "UnsupportedExpression",
    "COMPILE_LOG",
    "SUFFIX",
    "STEPPERS",
]

SUFFIX = "@compiled"

# -- expression translation -----------------------------------------------------------------------
# heyoka function name -> (numba expression template, number of arguments or None for any).
_UNARY_MATH = (
    "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "asinh", "acosh",
    "atanh", "exp", "expm1", "log", "log1p", "sqrt", "erf", "erfc",
)
_CALLS: dict[str, tuple[str, int | None]] = {name: (f"math.{name}({{0}})", 1) for name in _UNARY_MATH}
_CALLS.update({
    "div": ("({0} / {1})", 2),
    "sub": ("({0} - {1})", 2),
    "square": ("({0} * {0})", 1),
    "atan2": ("math.atan2({0}, {1})", 2),
    "sigmoid": ("(1.0 / (1.0 + math.exp(-{0})))", 1),
})
_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}


class UnsupportedExpression(InputError):
    """A right-hand side uses an operation the compiled implementation cannot translate."""


# Powers with a constant exponent e, 2e a whole number up to this size, are evaluated as heyoka
# evaluates them (measured against its compiled functions, bit for bit for e = +-1/2, +-3/2, 2,
# 3, 4, 5, ...): the base (sqrt(x) when 2e is odd) raised by binary exponentiation, inverted for
# e < 0. Other exponents go to the library `pow` (agreement to rounding, not to the bit).
_MAX_SMALL_POWER = 16


def _binary_power(base: str, m: int) -> str:
    result, square = None, base
    while m:
        if m & 1:
            result = square if result is None else f"({result} * {square})"
        m >>= 1
        if m:
            square = f"({square} * {square})"
    return result


def _power(base: str, exponent: ast.AST, tr: _Translator) -> str:
    value = None
    if isinstance(exponent, ast.Constant) and isinstance(exponent.value, int | float):
        value = float(exponent.value)
    elif (
        isinstance(exponent, ast.UnaryOp)
        and isinstance(exponent.op, ast.USub)
        and isinstance(exponent.operand, ast.Constant)
        and isinstance(exponent.operand.value, int | float)
    ):
        value = -float(exponent.operand.value)
    if value is not None and value != 0.0 and (2.0 * value).is_integer():
        twice = abs(int(2.0 * value))
        if twice <= _MAX_SMALL_POWER:
            if twice % 2:
                expr = _binary_power(f"math.sqrt({base})", twice)
            else:
                expr = _binary_power(base, twice // 2)
            return f"(1.0 / {expr})" if value < 0 else expr
    return f"({base} ** {tr.emit(exponent)})"


class _Translator:
    """One decomposition entry (heyoka infix text) -> numba source text."""

    def __init__(self, names: dict[str, str]):
        self.names = names  # heyoka name -> generated name

    def __call__(self, text: str) -> str:
        try:
            tree = ast.parse(text.strip(), mode="eval")
        except SyntaxError:
            raise UnsupportedExpression(f"cannot parse decomposition entry {text!r}") from None
        return self.emit(tree.body)

    def emit(self, node: ast.AST) -> str:
        if isinstance(node, ast.Constant) and isinstance(node.value, int | float):
            return repr(float(node.value))
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return self.names[node.id]
            if node.id == "t":
                return "t"
            if node.id[:1] == "p" and node.id[1:].isdigit():
                return f"p[{int(node.id[1:])}]"
            raise UnsupportedExpression(f"unknown name {node.id!r} in the decomposition")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
            sign = "-" if isinstance(node.op, ast.USub) else "+"
            return f"({sign}{self.emit(node.operand)})"
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            return _power(self.emit(node.left), node.right, self)
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            return f"({self.emit(node.left)} {_BINOPS[type(node.op)]} {self.emit(node.right)})"
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
            name = node.func.id
            args = [self.emit(a) for a in node.args]
            if name == "sum" and args:
                return "(" + " + ".join(args) + ")"
            if name == "prod" and args:
                return "(" + " * ".join(args) + ")"
            if name == "pow" and len(args) == 2:
                return _power(args[0], node.args[1], self)
            if name in _CALLS:
                template, arity = _CALLS[name]
                if arity is not None and arity != len(args):
                    raise UnsupportedExpression(f"`{name}` with {len(args)} arguments")
                return template.format(*args)
            raise UnsupportedExpression(f"operation `{name}` has no compiled translation")
        raise UnsupportedExpression(f"expression {ast.unparse(node)!r} has no compiled translation")


def translate_decomposition(
    fname: str, dc: Iterable[Any], variables: list[str], nouts: int, arg: str
) -> str:
    """Numba source of `fname(t, <arg>, p, out)` from a heyoka decomposition.

    `dc` lists the variables (u_0 .. u_{n-1}, in `variables` order), then the elementary
    assignments u_k = op(...), then the `nouts` output expressions.
    """
    entries = [str(e) for e in dc]
    nvars = len(variables)
    if len(entries) < nvars + nouts or entries[:nvars] != variables:
        raise UnsupportedExpression(
            f"decomposition does not start with the variables {variables}: {entries[:nvars]}"
        )
    names = {f"u_{i}": f"u_{i}" for i in range(len(entries))}
    tr = _Translator(names)
    lines = [f"def {fname}(t, {arg}, p, out):"]
    for i in range(nvars):
        lines.append(f"    u_{i} = {arg}[{i}]")
    for k in range(nvars, len(entries) - nouts):
        lines.append(f"    u_{k} = {tr(entries[k])}")
    for j, text in enumerate(entries[len(entries) - nouts :]):
        lines.append(f"    out[{j}] = {tr(text)}")
    return "\n".join(lines) + "\n"


# -- kernels (one per family; `rhs` / `accel` are the problem's generated functions) --------------
# a*b + c may become one fused multiply-add, as in heyoka's compiled functions (measured:
# x*x + y*y is fma(x, x, y*y) there) and in the BLAS axpy updates of the NumPy loops; no other
# fast-math licence (no reassociation, no reciprocal tricks).
_JIT = '@njit(cache=True, error_model="numpy", fastmath={"contract"})'
_JIT_RHS = _JIT

_RK_KERNEL = f'''
{_JIT}
def rk_advance(A, b, c, t0, n0, h, nsteps, Y, P):
    s = b.shape[0]
    dim = Y.shape[0]
    npar = P.shape[0]
    hA = A * h
    hb = b * h
    hc = c * h
    y = np.empty(dim)
    stage = np.empty(dim)
    K = np.empty((s, dim))
    p = np.empty(npar)
    for j in range(Y.shape[1]):
        for d in range(dim):
            y[d] = Y[d, j]
        for k in range(npar):
            p[k] = P[k, j]
        for n in range(nsteps):
            t = t0 + (n0 + n) * h
            for i in range(s):
                for d in range(dim):
                    acc = y[d]
                    for m in range(i):
                        if hA[i, m] != 0.0:
                            acc += hA[i, m] * K[m, d]
                    stage[d] = acc
                rhs(t + hc[i], stage, p, K[i])
            for d in range(dim):
                acc = y[d]
                for m in range(s):
                    if hb[m] != 0.0:
                        acc += hb[m] * K[m, d]
                y[d] = acc
        for d in range(dim):
            Y[d, j] = y[d]
    return s * nsteps
'''

_SPLIT_KERNEL = f'''
{_JIT}
def split_advance(kick, hcoef, htau, fsal, valid0, t0, n0, h, nsteps, Y, Acc, P):
    nops = kick.shape[0]
    nq = Acc.shape[0]
    npar = P.shape[0]
    q = np.empty(nq)
    v = np.empty(nq)
    a = np.empty(nq)
    p = np.empty(npar)
    evals = 0
    for j in range(Y.shape[1]):
        for d in range(nq):
            q[d] = Y[d, j]
            v[d] = Y[nq + d, j]
            a[d] = Acc[d, j]
        for k in range(npar):
            p[k] = P[k, j]
        valid = valid0
        e = 0
        for n in range(nsteps):
            t = t0 + (n0 + n) * h
            for i in range(nops):
                if kick[i]:
                    if not (i == 0 and valid):
                        accel(t + htau[i], q, p, a)
                        e += 1
                    for d in range(nq):
                        v[d] += a[d] * hcoef[i]
                else:
                    for d in range(nq):
                        q[d] += v[d] * hcoef[i]
            valid = fsal
        for d in range(nq):
            Y[d, j] = q[d]
            Y[nq + d, j] = v[d]
            Acc[d, j] = a[d]
        evals = e
    return evals
'''

_LEAPFROG_KERNEL = f'''
{_JIT}
def leapfrog_advance(hdrift, hkick, t0, n0, h, nsteps, Y, Acc, P):
    nq = Acc.shape[0]
    npar = P.shape[0]
    q = np.empty(nq)
    v = np.empty(nq)
    a = np.empty(nq)
    p = np.empty(npar)
    for j in range(Y.shape[1]):
        for d in range(nq):
            q[d] = Y[d, j]
            v[d] = Y[nq + d, j]
            a[d] = Acc[d, j]
        for k in range(npar):
            p[k] = P[k, j]
        for n in range(nsteps):
            t = t0 + (n0 + n) * h
            for d in range(nq):
                q[d] += v[d] * hdrift
            accel(t + h, q, p, a)
            for d in range(nq):
                v[d] += a[d] * hkick
        for d in range(nq):
            Y[d, j] = q[d]
            Y[nq + d, j] = v[d]
            Acc[d, j] = a[d]
    return nsteps
'''

_HEADER = '''"""Generated by implementations.compiled for problem {name!r}; do not edit.

Right-hand side{accel_note} translated from heyoka's decomposition; kernels from the templates
in implementations/compiled.py. numba {numba_version}, Python {python}.
"""
import math

import numpy as np
from numba import njit

'''


def module_source(problem: Problem) -> str:
    """The text of the generated module for `problem` (raises UnsupportedExpression)."""
    import numba

    variables = [str(v) for v in problem.variables]
    rhs_fn = problem.compiled("rhs", None)
    parts = [_JIT_RHS + "\n" + translate_decomposition("rhs", rhs_fn.dc, variables, problem.dim, "y")]
    parts.append(_RK_KERNEL)
    accel_note = ""
    if problem.newtonian is not None and not problem.velocity_dependent:
        positions = [str(v) for v in problem.newtonian.positions]
        acc_fn = problem.compiled("accel_q", None)
        parts.append(
            _JIT_RHS + "\n" + translate_decomposition("accel", acc_fn.dc, positions, len(positions), "q")
        )
        parts += [_SPLIT_KERNEL, _LEAPFROG_KERNEL]
        accel_note = " and position-only acceleration"
    header = _HEADER.format(
        name=problem.name,
        accel_note=accel_note,
        numba_version=numba.__version__,
        python=".".join(map(str, sys.version_info[:3])),
    )
    return header + "\n\n".join(p.strip("\n") + "\n" for p in parts)


# -- generated modules: written once, imported, numba-cached on disk ------------------------------
@dataclasses.dataclass
class _Entry:
    module: ModuleType | None
    reason: str | None
    path: Path | None


#: One record per kernel's first call in this process: problem, kernel, seconds, and whether
#: numba loaded it from its on-disk cache ("cached") or compiled it ("compiled").
COMPILE_LOG: list[dict[str, Any]] = []

_modules: weakref.WeakKeyDictionary[Problem, _Entry] = weakref.WeakKeyDictionary()
_lock = threading.RLock()


def _write_once(path: Path, text: str) -> None:
    """Create `path` with `text` unless it exists; never rewrite it (numba's cache index is keyed
    by the source file's time stamp, so a rewrite would force a recompile in every process)."""
    if path.exists():
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        try:
            os.link(tmp, path)
        except FileExistsError:
            pass
        except OSError:  # no hard links on this file system
            if not path.exists():
                os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _slug(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name)[:40]


def problem_module(problem: Problem) -> ModuleType:
    """The generated, imported module for `problem` (raises UnsupportedExpression)."""
    with _lock:
        entry = _modules.get(problem)
        if entry is None:
            try:
                text = module_source(problem)
            except UnsupportedExpression as exc:
                entry = _Entry(None, str(exc), None)
            else:
                digest = hashlib.sha256(text.encode()).hexdigest()[:20]
                path = cache.cache_dir() / "numba" / f"{_slug(problem.name)}_{digest}.py"
                _write_once(path, text)
                mod_name = f"_harness_numba_{digest}"
                module = sys.modules.get(mod_name)
                if module is None:
                    # Registered before it runs: numba's cache records the module by name and
                    # imports it by that name when it loads a cached kernel.
                    spec = importlib.util.spec_from_file_location(mod_name, path)
                    module = importlib.util.module_from_spec(spec)
                    sys.modules[mod_name] = module
                    try:
                        spec.loader.exec_module(module)
                    except BaseException:
                        sys.modules.pop(mod_name, None)
                        raise
                entry = _Entry(module, None, path)
            _modules[problem] = entry
    if entry.module is None:
        raise UnsupportedExpression(entry.reason)
    return entry.module


def _kernel(problem: Problem, name: str):
    return getattr(problem_module(problem), name)


def _timed_first_call(problem: Problem, name: str, kernel, args: tuple) -> Any:
    """Call `kernel`; on its first call in this process, record the compile (or load) time."""
    if kernel.signatures:
        return kernel(*args)
    start = time.perf_counter()
    result = kernel(*args)
    elapsed = time.perf_counter() - start
    stats = kernel.stats
    COMPILE_LOG.append({
        "problem": problem.name,
        "kernel": name,
        "seconds": elapsed,
        "source": "cached" if stats.cache_hits and not stats.cache_misses else "compiled",
    })
    return result


def _pars(dyn: Dynamics) -> np.ndarray:
    P = dyn.pars
    if P.ndim != 2:
        P = P.reshape(P.shape[0] if P.size else 0, dyn.size)
    return np.ascontiguousarray(P, dtype=np.float64)


# -- steppers -------------------------------------------------------------------------------------
def _compiled_info(base: Stepper, kind: str):
    return dataclasses.replace(
        base.info,
        name=base.info.name + SUFFIX,
        implementation="compiled",
        description=(
            f"{base.info.description}; compiled ({kind} kernel generated by numba from the same "
            "coefficient object)"
        ).lstrip("; "),
        extra={**base.info.extra, "numpy_implementation": base.info.name},
    )


class _CompiledMixin:
    """What the compiled families share: compatibility through code generation, a fingerprint
    that includes the kernel templates, and the `_step` = one-step `_advance` rule."""

    _templates: tuple[str, ...] = ()

    def incompatibility(self, problem: Problem) -> str | None:
        reason = super().incompatibility(problem)  # type: ignore[misc]
        if reason:
            return reason
        try:
            problem_module(problem)
        except UnsupportedExpression as exc:
            return f"no compiled right-hand side: {exc}"
        return None

    def fingerprint(self) -> str:
        return super().fingerprint() + "\n" + "\n".join(self._templates)  # type: ignore[misc]

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        self._run(dyn, c, 1)

    def _advance(self, dyn: Dynamics, c: Carry, n: int) -> None:
        if n > 0:
            self._run(dyn, c, n)
            c.n += n


class CompiledRungeKutta(_CompiledMixin, ExplicitRungeKutta):
    """An explicit Runge-Kutta method (the wrapped stepper's `ButcherTableau`) run by the compiled
    generic RK kernel: k_i = f(t + c_i h, y + h sum_j a_ij k_j), y <- y + h sum_i b_i k_i
    (Hairer, Norsett & Wanner I, Sect. II.1, eq. (1.8))."""

    _templates = (_RK_KERNEL,)

    def __init__(self, base: ExplicitRungeKutta):
        if not isinstance(base, ExplicitRungeKutta):
            raise InputError(f"`base` must be an ExplicitRungeKutta stepper, got {type(base).__name__}")
        super().__init__(
            base.coefficients,
            claimed_order=base.info.claimed_order,
            reference=base.info.reference,
            description=base.info.description,
        )
        self.info = _compiled_info(base, "explicit Runge-Kutta")

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = Carry(t0, h, np.ascontiguousarray(y0))
        self._scale(c)
        return c

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        tab = self.coefficients
        kernel = _kernel(dyn.problem, "rk_advance")
        args = (tab.A, tab.b, tab.c, float(c.t0), int(c.n), float(c.h), int(n), c.y, _pars(dyn))
        evals = _timed_first_call(dyn.problem, "rk_advance", kernel, args)
        dyn.counts["rhs"] += int(evals)


class CompiledSplitting(_CompiledMixin, SplittingStepper):
    """A drift/kick splitting scheme (the wrapped stepper's `SplittingScheme`) run by the compiled
    generic splitting kernel: drifts q += a_i h v, kicks v += b_i h a(q, t), first same as last
    when the scheme begins and ends with a kick (Hairer, Lubich & Wanner, *Geometric Numerical
    Integration*, 2nd ed., II.5)."""

    _templates = (_SPLIT_KERNEL,)

    def __init__(self, base: SplittingStepper):
        if not isinstance(base, SplittingStepper):
            raise InputError(f"`base` must be a SplittingStepper, got {type(base).__name__}")
        super().__init__(
            base.coefficients,
            claimed_order=base.info.claimed_order,
            reference=base.info.reference,
            description=base.info.description,
        )
        self.info = _compiled_info(base, "splitting")
        self._kick = np.array([is_kick for is_kick, _, _ in self._ops], dtype=np.bool_)

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        kernel = _kernel(dyn.problem, "split_advance")
        if getattr(c, "h_arrays_for", None) != c.h:
            c.hcoef_arr = np.array(c.hcoef, dtype=np.float64)
            c.htau_arr = np.array(c.htau, dtype=np.float64)
            c.h_arrays_for = c.h
        args = (
            self._kick, c.hcoef_arr, c.htau_arr, bool(self._fsal), bool(c.force_valid),
            float(c.t0), int(c.n), float(c.h), int(n), c.y, c.a, _pars(dyn),
        )
        evals = _timed_first_call(dyn.problem, "split_advance", kernel, args)
        dyn.counts["accel"] += int(evals)
        c.force_valid = self._fsal


class CompiledLeapfrog(_CompiledMixin, StaggeredLeapfrog):
    """The staggered leapfrog (velocities at half steps) built from a kick-drift-kick scheme, with
    its whole-step loop x += h v, v += h a(x) compiled (course-material files 002 and 004)."""

    _templates = (_LEAPFROG_KERNEL,)

    def __init__(self, base: StaggeredLeapfrog):
        if not isinstance(base, StaggeredLeapfrog):
            raise InputError(f"`base` must be a StaggeredLeapfrog, got {type(base).__name__}")
        super().__init__(
            base.info.name,
            base.coefficients,
            reference=base.info.reference,
            description=base.info.description,
        )
        self.info = _compiled_info(base, "staggered leapfrog")

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        kernel = _kernel(dyn.problem, "leapfrog_advance")
        args = (
            float(self._drift * c.h), float(self._kick * c.h), float(c.t0), int(c.n), float(c.h),
            int(n), c.y, c.a, _pars(dyn),
        )
        evals = _timed_first_call(dyn.problem, "leapfrog_advance", kernel, args)
        dyn.counts["accel"] += int(evals)


def compiled_variant(stepper: Stepper) -> Stepper:
    """The compiled implementation of a NumPy explicit Runge-Kutta, splitting or staggered
    leapfrog stepper (named `<name>@compiled`); users may register more with it."""
    if isinstance(stepper, _CompiledMixin):
        raise InputError(f"`stepper` {stepper.info.name!r} is already compiled")
    if isinstance(stepper, StaggeredLeapfrog):
        return CompiledLeapfrog(stepper)
    if isinstance(stepper, SplittingStepper):
        return CompiledSplitting(stepper)
    if isinstance(stepper, ExplicitRungeKutta):
        return CompiledRungeKutta(stepper)
    raise InputError(
        "`stepper` must be an explicit Runge-Kutta, splitting or staggered-leapfrog stepper, got "
        f"{type(stepper).__name__}"
    )


def _registered() -> list[Stepper]:
    from implementations import runge_kutta, splitting

    numpy_steppers = {s.info.name: s for s in [*runge_kutta.STEPPERS, *splitting.STEPPERS]}
    chosen = ("velocity-verlet", "leapfrog", "forest-ruth", "rk4", "euler", "heun")
    return [compiled_variant(numpy_steppers[name]) for name in chosen]


#: The compiled variants in the registry: the drift-run workhorses (velocity Verlet, leapfrog,
#: Forest-Ruth, RK4) and two cheap Runge-Kutta methods; `compiled_variant` makes any other.
STEPPERS: list[Stepper] = _registered()
