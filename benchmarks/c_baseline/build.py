"""Compile the C reference loops (`kepler.c`) with the system compiler and load them with ctypes.

`load()` compiles once per source/compiler/flags combination into
`harness.cache.code_dir() / "c_baseline"` (a later call or process reuses the library) and
returns a `CBaseline`. Flags: `-O3` plus what a shared library needs (`-fPIC -shared`, `-lm`);
no machine-specific flags (no `-march=native`), so the baseline is the code any distribution's
compiler produces. `CompilerUnavailable` says why when no compiler works (asv setups turn it
into a skip with that message). `CC` chooses the compiler; default: the first of cc, gcc, clang.

The timing helpers return the best of several runs in seconds per trajectory-step, so a
stepper's time divided by it is the ratio the asv suite tracks.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["CompilerUnavailable", "CBaseline", "load", "find_compiler", "FLAGS", "SOURCE", "SINGLE_FAMILY",
           "FAMILY_LOOPS", "family_loop", "kepler_start"]

SOURCE = Path(__file__).with_name("kepler.c")
FLAGS = ("-O3", "-fPIC", "-shared")
LIBS = ("-lm",)

#: Single-trajectory loops of the other families: method -> number of state values they take.
SINGLE_FAMILY = {"leapfrog": 4, "stormer": 4, "ab4": 16, "midpoint": 4}
# The harness's Newton settings (harness.tolerances.NEWTON_TOL / NEWTON_MAX_ITER), as numbers so
# the C baseline loads without the harness.
NEWTON_TOL = 1e-14
NEWTON_MAX_ITER = 20

#: A stepper family (`StepperInfo.family`) -> the loop of its representative method here; a family
#: not listed is compared with the classical RK4 loop.
FAMILY_LOOPS = {"explicit-rk": "rk4", "splitting": "vv", "stormer": "stormer", "multistep": "ab4",
                "implicit-rk": "midpoint"}


def family_loop(family: str) -> str:
    """The loop a stepper of `family` is compared with (`FAMILY_LOOPS`, else the RK4 loop)."""
    return FAMILY_LOOPS.get(family, "rk4")


def kepler_start(loop: str, h: float) -> np.ndarray:
    """The input of `loop` for one Kepler trajectory (e = 0.6, GM = 1) from pericentre at step `h`:
    the state, with the half-kick (leapfrog), the second position (Stormer) or four copies of the
    state as a start history (AB4) those loops take."""
    e = 0.6
    x, v = 1.0 - e, float(np.sqrt((1.0 + e) / (1.0 - e)))
    y0 = np.array([x, 0.0, 0.0, v])
    if loop == "leapfrog":
        return np.concatenate([y0[:2], y0[2:] - 0.5 * h * y0[:2] / x**3])
    if loop == "stormer":
        return np.concatenate([y0[:2], y0[:2] + h * y0[2:] - 0.5 * h**2 * y0[:2] / x**3])
    if loop == "ab4":
        return np.concatenate([y0] * 4)
    return y0


_loaded: dict[str, CBaseline] = {}


class CompilerUnavailable(RuntimeError):
    """No working C compiler: the C baseline (and every ratio to it) is skipped."""


def find_compiler() -> str | None:
    """The compiler to use: `$CC` when set, else the first of cc, gcc, clang on the PATH."""
    wanted = os.environ.get("CC")
    for name in ([wanted] if wanted else ["cc", "gcc", "clang"]):
        path = shutil.which(name)
        if path:
            return path
    return None


def _version(compiler: str) -> str:
    try:
        out = subprocess.run([compiler, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError) as exc:
        raise CompilerUnavailable(f"C compiler {compiler!r} does not run: {exc}") from None
    first = (out.stdout or out.stderr).strip().splitlines()
    return first[0] if first else compiler


@dataclass
class CBaseline:
    """The loaded library with the compiler, its version and the flags it was built with."""

    path: Path
    compiler: str
    version: str
    flags: tuple[str, ...]
    lib: ctypes.CDLL

    def __post_init__(self):
        dp = ctypes.POINTER(ctypes.c_double)
        for name in ("vv_single", "rk4_single"):
            fn = getattr(self.lib, name)
            fn.argtypes = [dp, ctypes.c_double, ctypes.c_long]
            fn.restype = None
        for name in ("vv_ensemble", "rk4_ensemble"):
            fn = getattr(self.lib, name)
            fn.argtypes = [dp, dp, ctypes.c_long, ctypes.c_double, ctypes.c_long]
            fn.restype = None
        for name in ("leapfrog_single", "stormer_single", "ab4_single"):
            fn = getattr(self.lib, name)
            fn.argtypes = [dp, ctypes.c_double, ctypes.c_long]
            fn.restype = None
        midpoint = self.lib.midpoint_single
        midpoint.argtypes = [dp, ctypes.c_double, ctypes.c_long, ctypes.c_double, ctypes.c_long]
        midpoint.restype = ctypes.c_long

    @property
    def command(self) -> str:
        return " ".join([Path(self.compiler).name, *self.flags, *LIBS])

    @staticmethod
    def _ptr(a: np.ndarray):
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def run(self, method: str, y: np.ndarray, h: float, n_steps: int) -> np.ndarray:
        """Advance states `y` shaped (4,) or (4, N) by `n_steps` steps of `method` ('vv' or
        'rk4'), or one trajectory's state of a single-trajectory family loop (`SINGLE_FAMILY`:
        'leapfrog' (x, v_1/2), 'stormer' (x_{n-1}, x_n), 'ab4' (y_{n-3} .. y_n), 'midpoint'
        (x, v; Newton tolerance NEWTON_TOL, NEWTON_MAX_ITER iterations)); returns the new
        states (the input is not modified)."""
        if method in SINGLE_FAMILY:
            out = np.array(y, dtype=np.float64, order="C", copy=True).reshape(-1)
            if out.size != SINGLE_FAMILY[method]:
                raise ValueError(
                    f"`y` for {method!r} must hold {SINGLE_FAMILY[method]} values, got {out.size}"
                )
            if method == "midpoint":
                taken = self.lib.midpoint_single(
                    self._ptr(out), float(h), int(n_steps), NEWTON_TOL, NEWTON_MAX_ITER
                )
                if taken < 0:
                    raise RuntimeError("the C implicit midpoint loop's Newton iteration did not converge")
            else:
                getattr(self.lib, f"{method}_single")(self._ptr(out), float(h), int(n_steps))
            return out
        if method not in ("vv", "rk4"):
            raise ValueError(
                f"`method` must be 'vv', 'rk4' or one of {sorted(SINGLE_FAMILY)}, got {method!r}"
            )
        out = np.array(y, dtype=np.float64, order="C", copy=True)
        if out.ndim == 1:
            getattr(self.lib, f"{method}_single")(self._ptr(out), float(h), int(n_steps))
            return out
        n = out.shape[1]
        work = np.empty((2 if method == "vv" else 20) * n)
        getattr(self.lib, f"{method}_ensemble")(self._ptr(out), self._ptr(work), n, float(h), int(n_steps))
        return out

    def seconds_per_step(self, method: str, y: np.ndarray, h: float, n_steps: int, repeats: int = 3) -> float:
        """Best of `repeats` runs, in seconds per trajectory-step."""
        members = 1 if np.ndim(y) == 1 else np.shape(y)[1]
        best = np.inf
        for _ in range(repeats):
            start = time.perf_counter()
            self.run(method, y, h, n_steps)
            best = min(best, time.perf_counter() - start)
        return best / (n_steps * members)


def load(cache_root: Path | None = None) -> CBaseline:
    """Compile (if needed) and load the C baseline; raises CompilerUnavailable."""
    compiler = find_compiler()
    if compiler is None:
        raise CompilerUnavailable(
            "no C compiler found (set CC or install cc/gcc/clang); the C baseline and the ratios "
            "to it are skipped"
        )
    version = _version(compiler)
    text = SOURCE.read_bytes()
    key = hashlib.sha256(text + "\0".join([compiler, version, *FLAGS, *LIBS]).encode()).hexdigest()[:16]
    if key in _loaded:
        return _loaded[key]
    if cache_root is None:
        from harness.cache import code_dir

        cache_root = code_dir()
    lib_path = Path(cache_root) / "c_baseline" / f"kepler_{key}.so"
    if not lib_path.exists():
        lib_path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=lib_path.parent, suffix=".so")
        os.close(fd)
        cmd = [compiler, *FLAGS, "-o", tmp, str(SOURCE), *LIBS]
        try:
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        except (OSError, subprocess.SubprocessError) as exc:
            os.unlink(tmp)
            raise CompilerUnavailable(f"`{' '.join(cmd)}` failed to run: {exc}") from None
        if done.returncode != 0:
            os.unlink(tmp)
            raise CompilerUnavailable(f"`{' '.join(cmd)}` failed:\n{done.stderr.strip()}")
        os.replace(tmp, lib_path)
    baseline = CBaseline(lib_path, compiler, version, FLAGS, ctypes.CDLL(str(lib_path)))
    _loaded[key] = baseline
    return baseline
