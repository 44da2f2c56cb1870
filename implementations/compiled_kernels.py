"""Loading the compiled family kernels (`implementations.kernels`) and calling them: the kernel
package imported on first use (so numba is imported only by a process that runs a compiled
stepper, not by every process that lists the steppers), each kernel compiled (or loaded from
numba's disk cache) under a file lock on its first call, and the problem's functions as
addresses.

Per problem nothing is generated: its functions are heyoka's own compiled code, called through
the addresses `implementations.native_functions` gives (`rhs`, its strided form `rhs_cols`, for
Newtonian problems whose acceleration ignores the velocity `accel` and `accel_cols`, and the
row-major Jacobian `jac` for the Newton-solved families). heyoka has already compiled them for the
NumPy steppers (or loads them from its disk cache), so the compiled and NumPy implementations
evaluate every right-hand side with the same machine code, and a cold run compiles no
per-problem code of its own.

A compile holds a file lock (`_compile_lock`), so processes started together compile each kernel
once and the others load it. `COMPILE_LOG` records, per process, what was compiled or loaded and
how long it took (wall and CPU seconds).
"""

from __future__ import annotations

import contextlib
import threading
import time
from typing import Any

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

from harness import cache
from harness.errors import InputError
from harness.problem import Problem
from implementations.native_functions import (
    NativeFunction,
    UnsupportedExpression,
    function_address,
    native_function,
)

__all__ = [
    "UnsupportedExpression",
    "problem_functions",
    "address",
    "call_kernel",
    "KERNELS",
    "COMPILE_LOG",
    "PARTS",
]

#: The family kernels (and helpers) the compiled steppers call (`implementations.kernels.KERNELS`).
KERNELS = (
    "rk_advance", "rk_advance_cols", "split_advance", "split_advance_cols", "leapfrog_advance",
    "leapfrog_advance_cols", "stormer_advance", "lmm_explicit_advance", "irk_advance",
    "lmm_implicit_advance", "controlled_advance", "rhs_all", "accel_all", "lmm2_explicit_advance",
    "lmm2_implicit_advance",
)
#: Per problem: 'functions' (rhs, rhs_cols, and accel, accel_cols for accelerations of the
#: positions only) and 'jacobian' (jac, for the Newton-solved families).
PARTS = ("functions", "jacobian")

#: One record per first use of a kernel in this process: what, seconds (wall and CPU), and
#: whether numba compiled it or loaded it from its disk cache.
COMPILE_LOG: list[dict[str, Any]] = []

_lock = threading.RLock()


@contextlib.contextmanager
def _compile_lock(stem: str):
    """Hold an exclusive lock on `stem`.lock in the numba cache directory while compiling (or
    loading) what `stem` names: workers started together (the gate's, the report's) compile each
    kernel and problem module once between them; the others wait and load it from numba's disk
    cache. Without `fcntl` (not POSIX) every process compiles for itself."""
    if fcntl is None:  # pragma: no cover - not POSIX
        yield
        return
    path = cache.code_dir() / "numba" / f"{stem}.lock"
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def problem_functions(problem: Problem, part: str = "functions") -> dict[str, NativeFunction]:
    """`problem`'s loaded functions of `part`: 'functions' (rhs, rhs_cols, and accel, accel_cols
    for an acceleration of the positions alone) or 'jacobian' (jac); raises UnsupportedExpression.

    Parameters
    ----------
    problem : the problem; part : 'functions' or 'jacobian'.

    Returns
    -------
    dict: function name -> NativeFunction. Raises InputError for another `part`.
    """
    if part not in PARTS:
        raise InputError(f"`part` must be one of {PARTS}, got {part!r}")
    if part == "jacobian":
        names = ["jac"]
    else:
        names = ["rhs", "rhs_cols"]
        if problem.newtonian is not None and not problem.velocity_dependent:
            names += ["accel", "accel_cols"]
    return {name: native_function(problem, name) for name in names}


def address(problem: Problem, name: str) -> int:
    """The address of `problem`'s function `name` ('rhs', 'rhs_cols', 'accel', 'accel_cols' or
    'jac'); raises UnsupportedExpression.

    Parameters
    ----------
    problem : the problem; name : the function's name.

    Returns
    -------
    int: the compiled function's address.
    """
    return function_address(problem, name)


def call_kernel(name: str, *args: Any) -> Any:
    """Call the family kernel `name` with `args`; its first call in this process records its
    compile (or cache load) time in COMPILE_LOG.

    Parameters
    ----------
    name : str, a key of KERNELS (InputError otherwise); args : the kernel's arguments.

    Returns
    -------
    Whatever the kernel returns (its evaluation count, or None).
    """
    if name not in KERNELS:
        raise InputError(f"`name` must be one of {list(KERNELS)}, got {name!r}")
    with _lock:
        from implementations.kernels import CACHE_DIRECTORY
        from implementations.kernels import kernel as family_kernel

        kernel = family_kernel(name)
    if kernel.signatures:
        return kernel(*args)
    start, cpu = time.perf_counter(), time.process_time()
    with _compile_lock(f"{CACHE_DIRECTORY.name}_{name}"):  # compiled (or loaded) only, not run
        kernel.compile(tuple(kernel.typeof_pyval(a) for a in args))
    result = kernel(*args)
    stats = kernel.stats
    COMPILE_LOG.append({
        "what": name,
        "seconds": time.perf_counter() - start,
        "cpu_seconds": time.process_time() - cpu,
        "source": "cached" if stats.cache_hits and not stats.cache_misses else "compiled",
    })
    return result
