"""Certified ground truth: heyoka's Taylor integrator at a chosen precision, checked by a rerun
one precision level higher.

A reference is computed at one *level* (float64, long double, real128) with tolerance equal to
that level's unit roundoff and `high_accuracy=True`, and *certified* by the next level up
(long double, real128, then 192-bit multiprecision `hy.real`). heyoka's tolerance bounds each
step's Taylor remainder, not the global error, so the error is measured, never assumed:

    error[t, n] = max over components of ( |y_level - y_next| + |fl64(y_level) - y_level| ),

the difference with the next level (computed exactly in the higher precision) plus the rounding
of the stored float64 value. The certifying run uses the tolerance max(its own unit roundoff,
the certified level's x `CERTIFIER_TOL_FACTOR` = 2^-16): its error is then ~1e-5 of the
certified level's, so the difference measures the level's error (on Kepler e = 0.6 at t = 100
the float64 level's certified 2.04e-12 matches its true error, from the exact solution, to 0.01 %).

Level policy (`required_error`):
- None (default): long double certified by real128 (the best available pair without real128).
  Measured on this machine type: all 15 catalogue problems, a 16-member ensemble each, at their
  convergence final times cost ~2 s of CPU in total (~90 % in the real128 certifier; the most
  expensive are `lennard-jones` and `outer-solar-system`, ~0.45 s each), with certified errors
  at the float64 rounding of the state (<= 1.2e-16 relative). A fresh heyoka JIT cache adds a
  one-time ~7 s of compilation; a cached reference loads in ~1-10 ms.
- a number: the cheapest level whose certified error (max over times and members) meets it;
  `ReferenceError_` names the required and the best achieved error when none does. When the
  float64 rounding of the state alone already exceeds the requirement, the dearer levels are
  skipped (their error includes that same rounding).

Integrators are compiled once per (problem, level, tolerance) and process and reset per ensemble
member (parameters are runtime values); heyoka's on-disk JIT cache lives in the harness cache
directory. References are cached on disk under `cache_dir()/references`, keyed by a hash of the
problem's fingerprint, times, t0, initial states, parameters, level, tolerance factors and heyoka
version; files are written atomically, and a corrupt file is ignored and recomputed.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
import threading
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import heyoka as hy
import numpy as np

from harness import cache
from harness.errors import InputError, ReferenceError_, WorkLimitError
from harness.problem import Problem, check_state, check_time
from harness.tolerances import CERTIFIER_TOL_FACTOR, REFERENCE_TOL_FACTOR

__all__ = [
    "Reference",
    "reference",
    "LEVELS",
    "DEFAULT_LEVEL",
    "available_levels",
    "certifier_of",
    "references_dir",
]

# Bump when the stored format or the error formula changes: old cache files are then ignored.
_SCHEMA = 1

# heyoka's compact mode compiles the Taylor recurrences as loops instead of unrolled code. It is
# used for every software-emulated level (real128, real192): there it compiles 3-5x faster
# (pendulum: 0.24 s instead of 0.73 s cold) for 10-25 % more time per step; and at any level
# for right-hand sides longer than this many characters of printed form (a cheap size measure):
# the unrolled 3-atom Lennard-Jones system takes ~20 s to compile in real128, 7 atoms ~300 s in
# long double, against under 1 s in compact mode.
_COMPACT_MODE_SIZE = 1000
_SOFTWARE_LEVELS = ("real128", "real192")


@dataclass(frozen=True)
class _Level:
    name: str
    fp_type: Any
    bits: int  # significand bits
    prec: int = 0  # only for hy.real

    @property
    def parts(self) -> int:
        """float64 terms needed to hold one value exactly."""
        return -(-self.bits // 53) + 1

    @property
    def eps(self) -> float:
        """Unit roundoff (machine epsilon) as a float."""
        return 2.0 ** (1 - self.bits)

    def scalar(self, x: float) -> Any:
        x = float(x)
        if self.name == "float64":
            return x
        if self.name == "longdouble":
            return np.longdouble(x)
        if self.name == "real128":
            return hy.real128(x)
        return hy.real(x, self.prec)

    def array(self, a: np.ndarray) -> np.ndarray:
        """float64 values converted (exactly) to this level."""
        a = np.asarray(a, dtype=np.float64)
        if self.name == "float64":
            return a.copy()
        if self.name == "longdouble":
            return a.astype(np.longdouble)
        if self.name == "real128":
            return a.astype(hy.real128)
        flat = [hy.real(float(v), self.prec) for v in a.ravel()]
        return np.array(flat).reshape(a.shape)


_ALL_LEVELS = (
    _Level("float64", float, 53),
    _Level("longdouble", np.longdouble, int(np.finfo(np.longdouble).nmant) + 1),
    _Level("real128", getattr(hy, "real128", None), 113),
    _Level("real192", getattr(hy, "real", None), 192, prec=192),
)
_BY_NAME = {lv.name: lv for lv in _ALL_LEVELS}

#: Levels a reference can be computed at, cheapest first (each certified by the next one).
LEVELS = ("float64", "longdouble", "real128")


def _level_available(lv: _Level) -> bool:
    if lv.name == "float64":
        return True
    if lv.name == "longdouble":
        return lv.bits > 53
    if lv.name == "real128":
        return lv.fp_type is not None and bool(hy._with_real128())
    return lv.fp_type is not None and bool(hy._with_real())


def _chain() -> list[_Level]:
    """Available levels of strictly increasing precision (where long double is IEEE quad, it
    replaces real128 rather than being certified by an equally precise level)."""
    chain: list[_Level] = []
    for lv in _ALL_LEVELS:
        if _level_available(lv) and (not chain or lv.bits > chain[-1].bits):
            chain.append(lv)
    return chain


def available_levels() -> list[str]:
    """Levels that can be computed *and* certified on this installation, cheapest first."""
    chain = _chain()
    return [lv.name for lv in chain[:-1] if lv.name in LEVELS]


def certifier_of(level: str) -> str:
    chain = _chain()
    names = [lv.name for lv in chain]
    if level not in names[:-1]:
        raise InputError(f"`level` must be one of {available_levels()}, got {level!r}")
    return names[names.index(level) + 1]


def _default_level() -> str:
    levels = available_levels()
    if "longdouble" in levels:
        return "longdouble"
    return levels[-1] if levels else "float64"


#: The level used when no `required_error` is given.
DEFAULT_LEVEL = _default_level()


@dataclass
class Reference:
    """The ground truth at `t` for an ensemble, with its certified error.

    `y` is shaped (nt, dim, N): the extended-precision result rounded to float64. `error` is
    shaped (nt, N): per time and member, the max over components of the difference with the
    certifying level plus the float64 rounding of the stored value.
    """

    problem: str
    t: np.ndarray
    y: np.ndarray
    error: np.ndarray
    precision: str
    certified_by: str
    wall_s: float
    cached: bool = False
    compute_s: float = 0.0
    cost: dict = field(default_factory=dict)

    @property
    def max_error(self) -> float:
        return float(np.max(self.error)) if self.error.size else 0.0


# -- work bounds ----------------------------------------------------------------------------------
# Every reference integration is bounded and interruptible. heyoka runs in compiled code, so it is
# driven in chunks (`propagate_grid(max_steps=...)`, resumed where it stopped: the same steps as
# one uninterrupted call); between chunks Python runs, so Ctrl-C and a cell's time limit
# (SIGALRM, also with --jobs 1) take effect, and the work so far is checked. Work is counted in
# float64-step units: a Taylor step costs `REFERENCE_STEP_COST[level]` of them (measured on this
# machine type for Kepler: long double ~10x, real128 ~300x a float64 step). After the first
# chunk the work the whole span needs is projected from the rate so far; a run projected or found
# to exceed `REFERENCE_MAX_WORK` units per member and precision, or running longer than
# `REFERENCE_MAX_SECONDS`, stops with `WorkLimitError` naming the limit and the environment
# variable that raises it. 1e8 units (~1e7 long double or ~3e5 real128 steps) is ~100x the
# largest catalogue reference; 900 s is ~100x all catalogue references together.
REFERENCE_STEP_COST = {"float64": 1.0, "longdouble": 10.0, "real128": 300.0, "real192": 1000.0}
REFERENCE_MAX_WORK = 1e8
REFERENCE_MAX_SECONDS = 900.0
# A chunk is this much work (~10 ms to ~1 s of compiled code between checks).
REFERENCE_CHUNK_WORK = 20_000


def _limit(env: str, default: float) -> float:
    raw = os.environ.get(env)
    if raw is None or raw == "":
        return default
    try:
        value = float(raw)
    except ValueError:
        raise InputError(f"`{env}` must be a positive number, got {raw!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"`{env}` must be a positive number, got {raw!r}")
    return value


def _propagate_bounded(problem: Problem, level: _Level, ta: Any, grid: np.ndarray, member: int,
                       started: float) -> tuple[Any, np.ndarray]:
    """`ta.propagate_grid(grid)` in chunks, within the work bounds (see above); returns
    (outcome, states at the grid points)."""
    max_work = _limit("HARNESS_REFERENCE_MAX_WORK", REFERENCE_MAX_WORK)
    max_seconds = _limit("HARNESS_REFERENCE_MAX_SECONDS", REFERENCE_MAX_SECONDS)
    cost = REFERENCE_STEP_COST.get(level.name, max(REFERENCE_STEP_COST.values()))
    chunk = max(20, int(REFERENCE_CHUNK_WORK / cost))
    t_start, t_end = float(grid[0]), float(grid[-1])
    rows: list[np.ndarray] = []
    remaining = grid
    steps = 0
    while True:
        result = ta.propagate_grid(remaining, max_steps=chunk)
        outcome, states = result[0], result[-1]
        rows.extend(states if not rows else states[1:])  # a resumed grid starts at the stop time
        steps += int(result[3])
        if outcome != hy.taylor_outcome.step_limit:
            return outcome, np.array(rows)
        done = float(ta.time) - t_start
        projected = cost * steps * (t_end - t_start) / done if done > 0 else math.inf
        where = (f"ground truth for problem {problem.name!r} failed in {level.name} at "
                 f"t = {float(ta.time):.17g} (member {member}): reaching t = {t_end:.6g}")
        if projected > max_work:
            raise WorkLimitError(
                f"{where} needs about {projected / cost:.3g} Taylor steps ({projected:.3g} work "
                f"units), more than the limit of {max_work:.3g} units "
                "(`HARNESS_REFERENCE_MAX_WORK`; set it higher to allow this)")
        elapsed = time.perf_counter() - started
        if elapsed > max_seconds:
            raise WorkLimitError(
                f"{where} took over {elapsed:.0f} s, more than the limit of {max_seconds:g} s "
                "(`HARNESS_REFERENCE_MAX_SECONDS`; set it higher to allow this)")
        remaining = np.concatenate([np.array([ta.time], dtype=grid.dtype), grid[len(rows):]])


# -- integrators ---------------------------------------------------------------------------------
_integrators: dict[tuple[str, str], tuple[threading.Lock, Any]] = {}
_integrators_lock = threading.Lock()


def _integrator(problem: Problem, level: _Level, tol: float) -> tuple[threading.Lock, Any]:
    key = (problem.fingerprint(), level.name, tol)
    with _integrators_lock:
        found = _integrators.get(key)
    if found is not None:
        return found
    cache.configure_heyoka_cache()
    sys = list(zip(problem.variables, problem.rhs, strict=True))
    kwargs: dict[str, Any] = {
        "tol": level.scalar(tol),
        "high_accuracy": True,
        "compact_mode": level.name in _SOFTWARE_LEVELS
        or sum(len(str(e)) for e in problem.rhs) > _COMPACT_MODE_SIZE,
    }
    if level.name != "float64":
        kwargs["fp_type"] = level.fp_type
    if problem.parameters:
        kwargs["pars"] = level.array(problem.parameter_values)
    ta = hy.taylor_adaptive(sys, level.array(problem.y0), **kwargs)
    entry = (threading.Lock(), ta)
    with _integrators_lock:
        return _integrators.setdefault(key, entry)


def _reference_tol(level: _Level) -> float:
    return level.eps * REFERENCE_TOL_FACTOR


def _certifier_tol(cert: _Level, level: _Level) -> float:
    return max(cert.eps, _reference_tol(level) * CERTIFIER_TOL_FACTOR)


def _propagate(
    problem: Problem,
    level: _Level,
    tol: float,
    times: np.ndarray,
    y0: np.ndarray,
    t0: float,
    pars: np.ndarray,
) -> tuple[np.ndarray, float]:
    """States at `times` for every member, shaped (nt, dim, N), in the level's number type."""
    lock, ta = _integrator(problem, level, tol)
    prepend = times[0] > t0
    grid = level.array(np.concatenate([[t0], times]) if prepend else times)
    n_members = y0.shape[1]
    out = []
    start = time.perf_counter()
    with lock:
        for n in range(n_members):
            ta.state[:] = level.array(y0[:, n])
            ta.time = level.scalar(t0)
            if pars.shape[0]:
                ta.pars[:] = level.array(pars[:, n])
            outcome, states = _propagate_bounded(problem, level, ta, grid, n, start)
            if outcome != hy.taylor_outcome.time_limit:
                raise ReferenceError_(
                    f"ground truth for problem {problem.name!r} failed in {level.name} at "
                    f"t = {float(ta.time):.17g} (member {n}): heyoka stopped with {outcome} "
                    "(the solution blows up or becomes non-finite)"
                )
            states = states[1:] if prepend else states
            check = states.astype(np.float64)
            if not np.all(np.isfinite(check)):
                bad = int(np.argmax(~np.all(np.isfinite(check), axis=1)))
                raise ReferenceError_(
                    f"ground truth for problem {problem.name!r} is not finite in {level.name} at "
                    f"t = {times[bad]:.17g} (member {n})"
                )
            out.append(states)
    return np.stack(out, axis=-1), time.perf_counter() - start


# -- exact comparison of levels ---------------------------------------------------------------------
def _expansion(values: np.ndarray, level: _Level) -> list[np.ndarray]:
    """`values` as a sum of float64 arrays, largest first (exact; the first is the rounding)."""
    if level.name == "float64":
        return [np.asarray(values, dtype=np.float64)]
    parts, rest = [], values
    for _ in range(level.parts):
        p = rest.astype(np.float64)
        parts.append(p)
        rest = rest - level.array(p)
    return parts


def _lift(parts: list[np.ndarray], level: _Level) -> np.ndarray:
    """Sum float64 parts exactly in a higher level (its precision exceeds the source's)."""
    acc = level.array(parts[0])
    for p in parts[1:]:
        acc = acc + level.array(p)
    return acc


def _certify(values: np.ndarray, level: _Level, higher: np.ndarray, cert: _Level):
    """Check `values` (nt, dim, N) against the certifying level's `higher`.

    Returns the float64 rounding y, the certified error (nt, N), and a lower bound (nt, N) on the
    error any level at least as accurate as `values` can reach: the float64 rounding distance of
    `higher`, less the spread between the two levels.
    """
    parts = _expansion(values, level)
    y = parts[0]
    rounding = np.zeros_like(y)
    for p in parts[1:]:
        rounding += np.abs(p)
    diff = np.abs(higher - _lift(parts, cert)).astype(np.float64)
    error = np.max(diff + rounding, axis=1)
    higher_rounding = np.zeros_like(y)
    for p in _expansion(higher, cert)[1:]:
        higher_rounding += np.abs(p)
    floor = np.max(higher_rounding - diff, axis=1)
    return y, error, floor


# -- disk cache ------------------------------------------------------------------------------------
def references_dir() -> Path:
    d = cache.cache_dir() / "references"
    d.mkdir(parents=True, exist_ok=True)
    return d


def _code_hash() -> str:
    """This module's source: a change to how references are computed or certified invalidates
    every cached reference, with no schema number to remember to bump."""
    import inspect
    import sys

    global _CODE_HASH
    if _CODE_HASH is None:
        _CODE_HASH = hashlib.sha256(inspect.getsource(sys.modules[__name__]).encode()).hexdigest()
    return _CODE_HASH


_CODE_HASH: str | None = None


def _key(problem: Problem, level: str, times, t0, y0, pars) -> str:
    h = hashlib.sha256()
    for part in (
        f"schema={_SCHEMA}",
        _code_hash(),
        f"heyoka={hy.__version__}",
        f"tol={REFERENCE_TOL_FACTOR!r},{CERTIFIER_TOL_FACTOR!r}",
        problem.fingerprint(),
        level,
        repr(float(t0)),
    ):
        h.update(part.encode())
        h.update(b"\0")
    for arr in (times, y0, pars):
        a = np.ascontiguousarray(arr, dtype=np.float64)
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:40]


def _cache_path(problem: Problem, level: str, key: str) -> Path:
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in problem.name)
    return references_dir() / f"{safe}-{level}-{key}.npz"


def _load(path: Path, times: np.ndarray, shape: tuple[int, int, int]):
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            y, error, floor, t = data["y"], data["error"], data["floor"], data["t"]
            certified_by = str(data["certified_by"])
            compute_s = float(data["compute_s"])
        if (
            y.shape != shape
            or error.shape != (shape[0], shape[2])
            or floor.shape != error.shape
            or not np.array_equal(t, times)
        ):
            return None
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(error)) and np.all(error >= 0)):
            return None
        return y, error, floor, certified_by, compute_s
    except Exception:  # a truncated or corrupt file is recomputed, never trusted
        return None


def _store(path: Path, **arrays: Any) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem[:40] + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


# -- public entry point ----------------------------------------------------------------------------
def _check_times(times: Any, t0: float) -> np.ndarray:
    try:
        arr = np.array(times, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"`times` must be a number or a 1-D array of numbers, got {times!r}") from None
    if arr.ndim == 0:
        arr = arr[None]
    if arr.ndim != 1 or arr.size == 0:
        raise InputError(f"`times` must be a number or a non-empty 1-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError("`times` must be finite (no NaN or inf)")
    if np.any(np.diff(arr) <= 0):
        raise InputError("`times` must be strictly increasing")
    if arr[0] < t0:
        raise InputError(f"`times` must be >= t0 = {t0!r}, got {arr[0]!r}")
    return arr


def _check_required(required_error: Any) -> float | None:
    if required_error is None:
        return None
    try:
        r = float(required_error)
    except (TypeError, ValueError):
        raise InputError(f"`required_error` must be a positive number, got {required_error!r}") from None
    if not (math.isfinite(r) and r > 0):
        raise InputError(f"`required_error` must be positive and finite, got {required_error!r}")
    return r


def reference(
    problem: Problem | str,
    times: Any,
    y0: Any = None,
    *,
    t0: float | None = None,
    pars: np.ndarray | Mapping[str, float] | None = None,
    required_error: float | None = None,
) -> Reference:
    """Certified ground truth of `problem` at `times` (scalar or increasing 1-D array >= t0) from
    initial states `y0` ((dim,) or (dim, N); default the problem's) with parameters `pars` (as in
    `Problem.pars_for`). See the module docstring for the level policy."""
    start = time.perf_counter()
    if isinstance(problem, str):
        from harness.registry import get_problem

        problem = get_problem(problem)
    if not isinstance(problem, Problem):
        raise InputError(f"`problem` must be a Problem or a registered name, got {type(problem).__name__}")
    t0 = problem.t0 if t0 is None else check_time(t0, "t0")
    times = _check_times(times, t0)
    y = check_state(problem.y0 if y0 is None else y0, problem.dim, "y0")
    n_members = y.shape[1]
    P = problem.pars_for(n_members, pars)
    required = _check_required(required_error)
    if not available_levels():
        raise ReferenceError_(
            f"ground truth for problem {problem.name!r} cannot be certified: no precision above "
            "float64 is available (long double is double here and heyoka lacks real128)"
        )
    chain = _chain()
    names = [lv.name for lv in chain]
    candidates = [DEFAULT_LEVEL] if required is None else available_levels()
    shape = (times.size, problem.dim, n_members)

    runs: dict[tuple[str, float], tuple[np.ndarray, float]] = {}

    def run(lv: _Level, tol: float) -> tuple[np.ndarray, float]:
        if (lv.name, tol) not in runs:
            runs[lv.name, tol] = _propagate(problem, lv, tol, times, y, t0, P)
        return runs[lv.name, tol]

    best: tuple[float, str] | None = None
    for name in candidates:
        level = _BY_NAME[name]
        cert = chain[names.index(name) + 1]
        key = _key(problem, name, times, t0, y, P)
        path = _cache_path(problem, name, key)
        loaded = _load(path, times, shape)
        if loaded is not None:
            y_ref, error, floor, certified_by, compute_s = loaded
            ref = Reference(
                problem.name,
                times,
                y_ref,
                error,
                name,
                certified_by,
                time.perf_counter() - start,
                cached=True,
                compute_s=compute_s,
            )
        else:
            values, cost_level = run(level, _reference_tol(level))
            higher, cost_cert = run(cert, _certifier_tol(cert, level))
            y_ref, error, floor = _certify(values, level, higher, cert)
            compute_s = cost_level + cost_cert
            try:
                _store(
                    path,
                    y=y_ref,
                    error=error,
                    floor=floor,
                    t=times,
                    certified_by=np.array(cert.name),
                    compute_s=np.array(compute_s),
                )
            except OSError as exc:  # the cache is an optimisation: a read-only disk is no error
                warnings.warn(f"reference cache not written ({path}): {exc}", stacklevel=2)
            ref = Reference(
                problem.name,
                times,
                y_ref,
                error,
                name,
                cert.name,
                time.perf_counter() - start,
                cached=False,
                compute_s=compute_s,
                cost={name: cost_level, cert.name: cost_cert},
            )
        if required is None or ref.max_error <= required:
            ref.wall_s = time.perf_counter() - start
            return ref
        if best is None or ref.max_error < best[0]:
            best = (ref.max_error, name)
        # The stored float64 value's own rounding is part of every level's error: when it alone
        # exceeds the requirement (less the spread between this level and its certifier), no
        # dearer level can succeed.
        if float(np.max(floor)) > required:
            break
    assert best is not None
    raise ReferenceError_(
        f"ground truth for problem {problem.name!r} cannot meet `required_error` = {required:.3g}: "
        f"the best certified error achieved is {best[0]:.3g} ({best[1]}, certified by "
        f"{certifier_of(best[1])}); levels available: {', '.join(available_levels())}"
    )
