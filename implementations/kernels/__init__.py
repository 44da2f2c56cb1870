"""The compiled family kernels: one numba function per family step loop, fed the method's
coefficients as arrays and the problem's functions as addresses, the same for every problem
and method.

Kernels: explicit Runge-Kutta, splitting, the staggered leapfrog, Stormer's two-step rule and a
splitting under a step controller, with column forms of the first three for ensembles
(`one_step`); explicit and implicit linear multistep (`multistep`); implicit Runge-Kutta by
Newton's method (`implicit_rk`); explicit and implicit second-order multistep (`second_order_multistep`);
what they share (`common`). A kernel reads its method from
arrays (A, b, c; the drift/kick sequence; alpha, beta) and calls the problem's functions through
their addresses (`implementations.kernel_calls`: an indirect call, as a C loop through a function
pointer), so a cold run compiles each kernel once, whatever the problems and methods, and later
processes load it from numba's disk cache. They are plain Python functions that ruff, coverage
and a reader see; they run as compiled code only (Lam, Pitrou & Seibert, *Numba: a LLVM-based
Python JIT compiler*, LLVM-HPC 2015).

Caching: importing this package imports numba and the kernel modules with numba's cache
directory set to `harness.cache.code_dir() / "numba" / "kernels-<digest>"`, where the digest
hashes the text of every kernel module, of the call intrinsics, the Newton stop's thresholds
(compiled in as constants) and the numba and Python versions:
numba's own index checks only the stamp of the file a function is defined in, so a change to a
helper in another module, or to the intrinsics, must start a new directory. Nothing else in the
process is affected (numba reads the setting when a function is decorated).

Why the NumPy, compiled and real128 loops of a family are not derived from one description of
the step: each is written for what its backend does fast, and the differences are the point of
having it. The NumPy loops advance an ensemble with whole-array operations (and BLAS axpy
updates); the kernels run member by member with the state in registers and padded rows (or in
column blocks), calling the problem's compiled functions; the real128 loops (`harness.extended`)
substitute the problem's symbolic right-hand side into the stages with the exact coefficients
and let heyoka compile one step as one function. A shared description would have to be an
interpreter (a list of stage operations walked at run time, costing the kernels their speed) or
a code generator (source text again). What ties the NumPy and compiled loops together instead is
tested agreement: compiled == NumPy to rounding for every registered method and compatible
problem, with the same operations in the same order (tests/test_compiled.py).
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numba
from numba.core import config

from harness import cache, tolerances

__all__ = ["KERNELS", "MODULES", "CACHE_DIRECTORY", "cache_directory", "kernel"]

#: The kernel modules, in import order.
MODULES = ("common", "one_step", "multistep", "implicit_rk", "second_order_multistep")
#: Each kernel (or helper the compiled steppers call directly) -> its module.
KERNELS = {
    "rk_advance": "one_step", "rk_advance_cols": "one_step", "split_advance": "one_step",
    "split_advance_cols": "one_step", "leapfrog_advance": "one_step",
    "leapfrog_advance_cols": "one_step", "stormer_advance": "one_step",
    "controlled_advance": "one_step", "lmm_explicit_advance": "multistep",
    "lmm_implicit_advance": "multistep", "irk_advance": "implicit_rk", "rhs_all": "common",
    "accel_all": "common", "lmm2_explicit_advance": "second_order_multistep",
    "lmm2_implicit_advance": "second_order_multistep", "newton_converged": "common",
}


def cache_directory() -> Path:
    """numba's cache directory for the kernels: named by a digest of every kernel module's text,
    the call intrinsics', the Newton rule's (compiled from `implementations.newton_rule`) and the
    numba and Python versions.

    Returns
    -------
    Path under `harness.cache.code_dir() / "numba"`.
    """
    here = Path(__file__).resolve().parent
    texts = [(here / f"{m}.py").read_bytes() for m in ("__init__", *MODULES)]
    texts.append((here.parent / "kernel_calls.py").read_bytes())
    texts.append((here.parent / "newton_rule.py").read_bytes())  # compiled as newton_converged
    # the thresholds the kernels read from harness.tolerances are compiled in as constants
    texts.append(f"newton stop {tolerances.NEWTON_STALL_CONTRACTION!r} "
                 f"{tolerances.NEWTON_ROUNDING_ULPS!r} {tolerances.EPS!r}".encode())
    texts.append(f"numba {numba.__version__}, Python {sys.version_info[:3]}".encode())
    digest = hashlib.sha256(b"\0".join(texts)).hexdigest()[:16]
    return cache.code_dir() / "numba" / f"kernels-{digest}"


def _import_modules(directory: Path) -> dict:
    before = config.CACHE_DIR
    config.CACHE_DIR = str(directory)
    try:
        from implementations.kernels import common, implicit_rk, multistep, one_step, second_order_multistep

        return {"common": common, "one_step": one_step, "multistep": multistep,
                "implicit_rk": implicit_rk, "second_order_multistep": second_order_multistep}
    finally:
        config.CACHE_DIR = before


#: Where this process's kernels are cached (decided when the package is imported).
CACHE_DIRECTORY = cache_directory()
_modules = _import_modules(CACHE_DIRECTORY)


def kernel(name: str):
    """The numba dispatcher of kernel `name` (one of KERNELS).

    Parameters
    ----------
    name : str

    Returns
    -------
    numba dispatcher, compiled on its first call (or loaded from the disk cache).
    """
    return getattr(_modules[KERNELS[name]], name)
