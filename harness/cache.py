"""Where the harness keeps what it caches: one directory it controls (`cache_dir`), the compiled
code within it (`code_dir`), and the heyoka integrators built in this process (`IntegratorPool`).

`HARNESS_CACHE_DIR` overrides the default `.cache/` at the project root (or the current
directory when the package is installed elsewhere). Compiled code (numba's family kernels in
`numba/`, heyoka's on-disk JIT cache in `heyoka/`, so compiled right-hand sides and Taylor
integrators survive across processes; the imports parsed from the project's sources for cache
keys in `keys/`) lives in the same directory unless `HARNESS_CODE_CACHE_DIR`
names another: compiled code is keyed by its own text (the family module by a hash of its source,
numba's index by that file's stamp, heyoka's by the IR it compiles), never by measured results,
so one code directory can serve any number of result caches (the test suite's private caches
share the project's compiled code this way).
"""

from __future__ import annotations

import atexit
import os
import sys
import threading
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import Any, TypeVar

import heyoka as hy

from harness import tolerances as tol
from harness.errors import OutputError, describe_os_error

T = TypeVar("T")

__all__ = ["cache_dir", "code_dir", "configure_heyoka_cache", "IntegratorPool", "interruptible",
           "set_exit_status"]

_configured: Path | None = None


def cache_dir() -> Path:
    """The harness's cache root, created when missing (`OutputError` naming the path when it
    cannot be).

    Returns
    -------
    Path: `HARNESS_CACHE_DIR` when set, else the project's (or the current directory's) `.cache`.
    """
    env = os.environ.get("HARNESS_CACHE_DIR")
    if env:
        root = Path(env)
    else:
        project = Path(__file__).resolve().parent.parent
        root = project / ".cache" if (project / "pyproject.toml").exists() else Path.cwd() / ".cache"
    return _created(root)


def code_dir() -> Path:
    """The root of the compiled-code caches (`numba/`, `heyoka/`): `HARNESS_CODE_CACHE_DIR` when
    set, else `cache_dir()`; created when missing (`OutputError` naming the path when it cannot
    be).

    Returns
    -------
    Path: the folder, existing.
    """
    env = os.environ.get("HARNESS_CODE_CACHE_DIR")
    return _created(Path(env)) if env else cache_dir()


def _created(root: Path) -> Path:
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file where the directory belongs, no permission, ...
        raise OutputError(*describe_os_error(exc, root)) from None
    return root


# heyoka's compact mode compiles the Taylor recurrences as loops instead of unrolled code: for
# right-hand sides longer than this many characters of printed form (a cheap size measure) the
# unrolled code takes far longer to compile than the run it serves (the 36-dimensional outer
# solar system at order 18: 43 s unrolled against 0.9 s compact, load 4.7; the 3-atom
# Lennard-Jones system ~20 s in real128, 7 atoms ~300 s in long double, against under 1 s).
COMPACT_MODE_SIZE = 1000


def compact_mode(problem) -> bool:
    """Whether heyoka should compile `problem`'s Taylor integrators in compact mode (its
    right-hand side is longer than COMPACT_MODE_SIZE characters printed).

    Parameters
    ----------
    problem : Problem, whose `rhs` expressions are measured.

    Returns
    -------
    bool: True for a large right-hand side.
    """
    return sum(len(str(e)) for e in problem.rhs) > COMPACT_MODE_SIZE


def float64_taylor_settings(problem) -> dict[str, Any]:
    """The settings of every float64 Taylor integrator of `problem` (orbits, time scales, flow
    amplification, the float64 ground truth): tolerance eps, high accuracy, compact mode by
    `compact_mode`; heyoka's disk cache then holds one compiled integrator per batch size.

    Parameters
    ----------
    problem : Problem, the problem integrated.

    Returns
    -------
    dict: keyword arguments 'tol', 'high_accuracy', 'compact_mode' of heyoka's integrators.
    """
    return {"tol": tol.EPS, "high_accuracy": True, "compact_mode": compact_mode(problem)}


def interruptible(build: Callable[[], T]) -> T:
    """`build()` (a heyoka compile: `hy.cfunc`, `hy.taylor_adaptive`), run so that Ctrl-C and
    SIGTERM still reach this process while it compiles.

    1. heyoka releases the GIL while LLVM works, so in the main thread the compile runs in a
       daemon thread joined in short slices, and a signal handler (KeyboardInterrupt, the CLI's
       Terminated) runs between them. Elsewhere `build()` is called directly.
    2. An interrupted compile cannot be cancelled: it goes on in its thread. The process then
       ends through `os._exit` at interpreter exit (`_exit_past_the_compile`), with the status
       given to `set_exit_status` (130 after Ctrl-C, 143 after SIGTERM unless told otherwise):
       a normal exit would run LLVM's static destructors under the running compile, which
       crashes the process (SIGSEGV, seen about one time in four when the signal lands as the
       compile starts).

    Parameters
    ----------
    build : the compile, called without arguments.

    Returns
    -------
    What `build()` returned; what it raised is raised here.
    """
    if threading.current_thread() is not threading.main_thread():
        return build()
    box: dict[str, Any] = {}

    def work() -> None:
        try:
            box["value"] = build()
        except BaseException as exc:  # handed to the waiting thread
            box["error"] = exc

    worker = threading.Thread(target=work, name="harness-compile", daemon=True)
    try:
        worker.start()
        while worker.is_alive():
            worker.join(0.1)
    except BaseException as exc:  # a signal while the compile runs: it is abandoned
        _abandon(130 if isinstance(exc, KeyboardInterrupt) else 143)
        raise
    if "error" in box:
        raise box["error"]
    return box["value"]


_exit_status: list[int] = []  # set once a compile has been abandoned


def _abandon(status: int) -> None:
    if not _exit_status:
        _exit_status.append(status)
        atexit.register(_exit_past_the_compile)


def set_exit_status(status: int) -> None:
    """The status the process ends with if a compile was abandoned (`interruptible`, rule 2);
    without an abandoned compile the process ends normally and this does nothing.

    Parameters
    ----------
    status : int, the exit status.
    """
    if _exit_status:
        _exit_status[0] = status


def _exit_past_the_compile() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    os._exit(_exit_status[0])


def configure_heyoka_cache() -> Path:
    """Point heyoka's on-disk JIT cache at `code_dir() / "heyoka"` (again only when that
    changed).

    Returns
    -------
    Path: the cache folder heyoka now uses.
    """
    global _configured
    target = code_dir() / "heyoka"
    if _configured != target:
        target.mkdir(parents=True, exist_ok=True)
        hy.llvm_state.set_diskcache_path(str(target))
        _configured = target
    return target


class IntegratorPool:
    """heyoka integrators built once per key in this process, each with the lock its users hold
    while they set its time and state and propagate it (an integrator is stateful). Building
    (a compile, or a load from heyoka's disk cache) happens outside the pool's own lock."""

    def __init__(self):
        self._entries: dict[Hashable, tuple[threading.Lock, Any]] = {}
        self._lock = threading.Lock()

    def get(self, key: Hashable, build: Callable[[], Any]) -> tuple[threading.Lock, Any]:
        """(lock, integrator) for `key`; the integrator is `build()` on first use.

        Parameters
        ----------
        key : hashable, what identifies the integrator (problem, settings, batch size);
        build : callable with no argument, making the integrator.

        Returns
        -------
        tuple (threading.Lock, integrator): hold the lock while using the integrator; on a race the
        first one built is kept.
        """
        with self._lock:
            found = self._entries.get(key)
        if found is not None:
            return found
        configure_heyoka_cache()
        entry = (threading.Lock(), build())
        with self._lock:
            return self._entries.setdefault(key, entry)

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Forget every integrator (benchmarks time a cold start)."""
        with self._lock:
            self._entries.clear()
