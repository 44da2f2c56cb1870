"""How cells run: cached, in parallel (local processes or a Dask cluster), each failure in its cell.

`run_experiment(name, steppers, problems, ...)` lists an experiment's cells, reuses every cell
already in the cache, runs the others, and returns a `RunResult` (rows, summary, failures, skips,
per-cell records, counts, wall time). `run_experiments(...)` does the same for several
experiments with one progress display and one Dask connection.

Cache. A cell's key (`cell_key`, harness/keys.py) hashes the cell, the experiment's resolved
configuration and a code version: the fingerprints of its stepper and problem (coefficients and
class source), the measuring source of the experiment found from its import graph (judging code
and judging thresholds left out), and the harness version. A finished cell is written to the
cache (`harness.store.CellCache`, with a checksum and its schema) the moment its result reaches
this process, so a `kill -9` loses only the cells in flight; the next run reuses the rest. A
changed method changes only its own cells' keys. `fresh=True` recomputes every cell and
overwrites its cache entry. Failed cells are not cached: they run again.

Where cells run.
- `jobs=1`: in this process, one after another.
- `jobs=N>1` (default: all cores): N local worker processes (loky, joblib's process executor,
  reused across runs). Results come back in any order; rows are put in the order of the
  experiment's cell list, so the result equals a serial run.
- `scheduler='tcp://HOST:PORT'` (or a `distributed.Client`): the same cells as Dask tasks
  (`client.submit` of `_execute`, gathered with `as_completed`). Workers need the same
  environment as this process (`pip install -r requirements.txt` and this project, e.g.
  `pip install -e .`); plugin files are shipped with each task and written to the worker's temp
  directory when the worker cannot see the path. The cache stays with this process.
Each task carries the experiment object, the cell, the configuration, the plugin files and the
expected stepper/problem code version: a worker whose code differs (an older checkout on the
cluster) records the cell as failed instead of mixing results from other code into the run.

Failures stay in their cell. Each cell ends in rows or in a failure record
(`harness.experiments.base.failed_record`) of one of these kinds:
`error` (run_cell raised), `invalid` (not a DataFrame, no rows, non-scalar or complex columns,
declared dtypes or finite columns violated, not storable as Parquet; or a stepper returned a
state of the wrong shape or made NaN from a finite state: `StepperOutputError`), `timeout`, `crash` (the
worker process died: segfault, `os._exit`, out-of-memory kill), `lookup` (the stepper or problem
cannot be found or fingerprinted), `version` (a worker runs other code), `summarize` (the
experiment's summary raised; the rows are kept).

Experiments may declare (all optional):
- `row_dtypes = {"error": "float", "n_steps": "int", "verdict": "str"}`: required columns and
  their kinds (`float`, `int`, `bool`, `str`, or a tuple of them);
- `finite_columns = ("n_steps", "wall_s")`: measured columns in which NaN/inf means the cell went
  wrong (other columns may hold NaN/inf as a measurement, e.g. the error of a blow-up);
- `estimate_bytes(cell, config) -> int`: peak memory of one cell, for the memory guard.

Time limit (`cell_timeout` seconds, from the moment the cell starts):
- in a process's main thread (`jobs=1`, and every loky worker): `SIGALRM` via
  `signal.setitimer` raises `CellTimeout` (a BaseException, so `except Exception` in the cell
  cannot swallow it). It takes effect when control returns to Python, so in loky workers a
  watchdog thread also ends the worker process (`os._exit`) `HARD_TIMEOUT_GRACE_S` seconds later
  if the cell is stuck in compiled code; the pool replaces the worker and the run goes on.
- elsewhere (a Dask worker's task thread, or `jobs=1` outside the main thread): the cell runs in
  a helper thread that is abandoned at the limit; the cell is recorded as timed out, but its
  thread keeps running (Python cannot stop a thread) until it returns.

Crashes. When a loky worker dies, every cell in flight fails with it. While a worker runs a
cell it keeps a claim file holding its pid, faulthandler's traceback should a fatal signal
(SIGSEGV, SIGFPE, SIGABRT, SIGBUS, SIGILL) end it, and the watchdog's note on a hard timeout.
After the pool breaks, a claim that says why names its cell (`crash` with the fatal error, or
`timeout`) and the other cells are resubmitted; when no claim says why (`os._exit`, a SIGKILL
from the out-of-memory killer), the cells that were in flight are rerun one at a time, alone,
and the one that kills its worker again is recorded as `crash`. A Dask cluster retries a task
whose worker died and finally reports it (`KilledWorker`), which becomes a `crash` record.

Time limits, crashes and the memory guard protect the run, not the machine: `jobs=1` runs cells
in this process, so a segfault there ends the run (finished cells are in the cache).

Memory guard. Before anything runs, the runner estimates each cell's peak memory (the
experiment's `estimate_bytes` hook, else from `config['ensemble']` and the problem's dimension,
see `estimate_bytes`) and refuses, with `InputError`, a run whose `jobs` largest cells together
exceed `MEMORY_HEADROOM` of the available memory.
"""

from __future__ import annotations

import contextlib
import faulthandler
import hashlib
import json
import math
import os
import re
import shutil
import signal
import socket
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness.errors import (
    HarnessError,
    InputError,
    NoApplicableCellsError,
    StepperOutputError,
    Terminated,
    UnknownNameError,
)
from harness.experiments.base import Cell, Experiment, Skip, failed_record
from harness.keys import MEASURING_MODULES, cell_key, code_version, experiment_fingerprint
from harness.progress import Progress
from harness.store import (
    CellCache,
    atomic_write_bytes,
    encode_cell,
)

__all__ = [
    "RunResult",
    "run_experiment",
    "run_experiments",
    "cell_key",
    "code_version",
    "experiment_fingerprint",
    "validate_rows",
    "estimate_bytes",
    "check_memory",
    "available_memory",
    "default_jobs",
    "time_limit",
    "CellTimeout",
    "CellOutputError",
    "ExperimentError",
    "NoApplicableCellsError",
    "no_cells_error",
    "FAILURE_KINDS",
    "MEASURING_MODULES",
]

FAILURE_KINDS = ("error", "invalid", "timeout", "crash", "lookup", "version", "summarize")

# After a soft time limit fails to stop a cell (stuck in compiled code), a loky worker is ended
# this many seconds later (at least), or a fifth of the limit when that is longer.
HARD_TIMEOUT_GRACE_S = 5.0
# A local run uses at most this many worker processes per core.
MAX_JOBS_PER_CORE = 8
# Seconds to wait for a Dask scheduler to answer.
DASK_CONNECT_TIMEOUT_S = 10
# Seconds an idle loky worker waits for work before it exits (short: a worker is cheap to start,
# and the workers of a run killed with SIGKILL should not linger).
LOKY_IDLE_TIMEOUT_S = 30
# A worker process whose parent died (kill -9 of the run) notices within this many seconds and
# exits (its parent pid changes when it is re-parented).
ORPHAN_CHECK_S = 1.0
# A cell whose worker died in this many pool breakdowns is recorded as crashed, whatever the
# claim files say (guarantees the run ends).
MAX_CRASH_ROUNDS = 3
# Working arrays a stepper keeps per state (stages, carries, temporaries) in the default
# memory estimate: 16 covers an 8-stage Runge-Kutta method with its error estimate.
WORK_ARRAYS = 16
# Claim directories of killed runs older than this (seconds) are removed by the next run.
STALE_CLAIMS_S = 24 * 3600.0
# Largest cell time limit accepted, seconds (a week).
MAX_CELL_TIMEOUT_S = 7 * 24 * 3600.0


class CellTimeout(BaseException):
    """A cell ran past its time limit (a BaseException so that `except Exception` in the cell's
    own code does not swallow it)."""


class CellOutputError(HarnessError):
    """A cell returned something other than valid tidy rows."""


class ExperimentError(HarnessError):
    """An experiment could not list its cells (the message names the experiment)."""


# -- time limits ------------------------------------------------------------------------------------
def _alarm_possible() -> bool:
    return hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def time_limit(seconds: float | None):
    """Raise `CellTimeout` in the body after `seconds` (SIGALRM; main thread only; None: no
    limit). A limit already running outside is restored afterwards."""
    if seconds is None:
        yield
        return
    if not _alarm_possible():
        raise HarnessError("`time_limit` needs the main thread of a POSIX process")

    def _handler(signum, frame):
        raise CellTimeout(f"timeout after {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, _handler)
    # setitimer counts in microseconds and reads 0 as "no timer": never pass less than 1 us
    outer_delay, outer_interval = signal.setitimer(signal.ITIMER_REAL, max(float(seconds), 1e-6))
    started = time.monotonic()
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        if outer_delay > 0:
            remaining = max(outer_delay - (time.monotonic() - started), 1e-3)
            signal.setitimer(signal.ITIMER_REAL, remaining, outer_interval)


def _call_limited(fn: Callable[[], Any], seconds: float | None) -> Any:
    """fn() under a time limit: SIGALRM in a main thread, else an abandoned helper thread."""
    if seconds is None:
        return fn()
    if _alarm_possible():
        with time_limit(seconds):
            return fn()
    box: dict[str, Any] = {}

    def target():
        try:
            box["value"] = fn()
        except BaseException as exc:  # handed to the caller below
            box["error"] = exc

    th = threading.Thread(target=target, name="harness-cell", daemon=True)
    th.start()
    th.join(seconds)
    if th.is_alive():
        raise CellTimeout(f"timeout after {seconds:g} s")
    if "error" in box:
        raise box["error"]
    return box.get("value")


# -- code versions and keys: harness/keys.py (re-exported here) ------------------------------------
# -- validating a cell's rows -----------------------------------------------------------------------
_KINDS = {
    "float": pd.api.types.is_float_dtype,
    "int": lambda s: pd.api.types.is_integer_dtype(s) and not pd.api.types.is_bool_dtype(s),
    "bool": pd.api.types.is_bool_dtype,
    "str": lambda s: pd.api.types.is_string_dtype(s) or pd.api.types.is_object_dtype(s),
}
_SCALARS = (str, bool, int, float, np.bool_, np.integer, np.floating)


def validate_rows(experiment: Experiment, rows: Any) -> pd.DataFrame:
    """Check what `run_cell` returned; raise `CellOutputError` saying what is wrong.

    Always: a non-empty DataFrame with distinct, non-empty string column names, columns of
    numbers, booleans or strings (plain scalars; no complex values, lists or objects). Declared by
    the experiment: `row_dtypes` (column -> kind) and `finite_columns` (no NaN/inf there)."""
    if not isinstance(rows, pd.DataFrame):
        raise CellOutputError(f"run_cell returned {type(rows).__name__}, expected a pandas DataFrame")
    if len(rows) == 0:
        raise CellOutputError("run_cell returned no rows")
    cols = list(rows.columns)
    bad = [c for c in cols if not isinstance(c, str) or not c]
    if bad or isinstance(rows.columns, pd.MultiIndex):
        raise CellOutputError(f"column names must be non-empty strings, got {bad[:5]!r}")
    if len(set(cols)) != len(cols):
        dup = sorted({c for c in cols if cols.count(c) > 1})
        raise CellOutputError(f"column names must be distinct, repeated: {dup}")
    for c in cols:
        s = rows[c]
        if pd.api.types.is_complex_dtype(s):
            raise CellOutputError(f"column {c!r} is complex; store real and imaginary parts apart")
        if pd.api.types.is_object_dtype(s):
            odd = [type(v).__name__ for v in s if v is not None and not isinstance(v, _SCALARS)
                   and not (isinstance(v, float) and math.isnan(v))]
            if odd:
                raise CellOutputError(
                    f"column {c!r} holds {odd[0]} values; rows must hold plain numbers or strings"
                )
    declared = getattr(experiment, "row_dtypes", None) or {}
    for c, kinds in dict(declared).items():
        kinds = (kinds,) if isinstance(kinds, str) else tuple(kinds)
        if c not in rows.columns:
            raise CellOutputError(f"column {c!r} is missing (declared in `row_dtypes`)")
        if not any(_KINDS[k](rows[c]) for k in kinds):
            raise CellOutputError(
                f"column {c!r} has dtype {rows[c].dtype}, declared {' or '.join(kinds)}"
            )
    for c in getattr(experiment, "finite_columns", None) or ():
        if c not in rows.columns:
            raise CellOutputError(f"column {c!r} is missing (declared in `finite_columns`)")
        s = rows[c]
        if pd.api.types.is_bool_dtype(s) or not pd.api.types.is_numeric_dtype(s):
            continue
        values = s.to_numpy(dtype=float, na_value=np.nan)
        where = np.flatnonzero(~np.isfinite(values))
        if where.size:
            raise CellOutputError(
                f"column {c!r} has {where.size} non-finite value(s) (NaN/inf) at rows "
                f"{where[:5].tolist()}"
            )
    return rows


# -- memory guard -----------------------------------------------------------------------------------
def estimate_bytes(*, dim: int, ensemble: int = 1, saved_states: int = 2,
                   work_arrays: int = WORK_ARRAYS) -> int:
    """Peak bytes of integrating an ensemble: float64 states of shape (dim, ensemble), times
    (saved states + working arrays)."""
    for name, v in (("dim", dim), ("ensemble", ensemble), ("saved_states", saved_states),
                    ("work_arrays", work_arrays)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer):
            raise InputError(f"`{name}` must be a whole number, got {v!r}")
        if v < (1 if name in ("dim", "ensemble") else 0):
            raise InputError(f"`{name}` must be at least {1 if name in ('dim', 'ensemble') else 0}, got {v}")
    return 8 * int(dim) * int(ensemble) * (int(saved_states) + int(work_arrays))


def available_memory() -> int:
    """Bytes of memory available to new allocations now (psutil)."""
    import psutil

    return int(psutil.virtual_memory().available)


def _fmt_bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} PB"


def check_memory(needed: int, *, argument: str, detail: str = "",
                 available: int | None = None) -> None:
    """Raise `InputError` naming `argument` when `needed` bytes exceed MEMORY_HEADROOM of the
    available memory (`available`, default: measured now)."""
    from harness.tolerances import MEMORY_HEADROOM

    avail = available_memory() if available is None else int(available)
    limit = int(MEMORY_HEADROOM * avail)
    if needed > limit:
        what = f"{detail}: " if detail else ""
        raise InputError(
            f"`{argument}`: {what}needs an estimated {_fmt_bytes(needed)}, more than the "
            f"{_fmt_bytes(limit)} available ({MEMORY_HEADROOM:.0%} of {_fmt_bytes(avail)} free); "
            f"lower `{argument}`"
        )


def _cell_estimate(experiment: Experiment, cell: Cell, config: Mapping[str, Any]) -> tuple[int, str]:
    hook = getattr(experiment, "estimate_bytes", None)
    if callable(hook):
        return int(hook(cell, config)), "config"
    size = config.get("ensemble")
    if isinstance(size, bool) or not isinstance(size, int | np.integer) or not cell.problem:
        return 0, "ensemble"
    from harness.registry import get_problem

    try:
        dim = get_problem(cell.problem).dim
    except HarnessError:
        return 0, "ensemble"
    if size < 1:
        raise InputError(f"`ensemble` must be at least 1, got {size}")
    return estimate_bytes(dim=dim, ensemble=int(size)), "ensemble"


def _guard_memory(experiment: Experiment, cells: Sequence[Cell], config: Mapping[str, Any],
                  jobs: int) -> None:
    estimates = []
    for cell in cells:
        b, arg = _cell_estimate(experiment, cell, config)
        estimates.append((b, arg, cell))
    if not estimates:
        return
    estimates.sort(key=lambda e: e[0], reverse=True)
    top = estimates[: max(1, jobs)]
    needed = sum(e[0] for e in top)
    b, arg, cell = top[0]
    detail = f"{experiment.name} cell {cell.label} ({_fmt_bytes(b)} each"
    detail += f", {len(top)} at once)" if len(top) > 1 else ")"
    if arg == "ensemble":
        detail = f"{config.get('ensemble')}, " + detail
        argument = "ensemble"
    else:
        argument = "config"
    check_memory(needed, argument=argument, detail=detail)


# -- one cell, wherever it runs ---------------------------------------------------------------------
def _short_traceback(exc: BaseException, frames: int = 6) -> str:
    te = traceback.TracebackException.from_exception(exc, limit=-frames)
    text = "".join(te.format()).strip()
    return text if len(text) <= 4000 else "..." + text[-3997:]


def _one_line(text: str, limit: int = 500) -> str:
    line = " ".join(str(text).split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _plugin_spec(path: str | os.PathLike) -> dict:
    p = Path(path).resolve()
    data = p.read_bytes()
    return {"path": str(p), "name": p.name, "sha256": hashlib.sha256(data).hexdigest(), "source": data}


def _ensure_plugins(specs: Sequence[dict]) -> None:
    """Load the run's plugin files in this process: from their path when it holds the same
    content, else from a copy written to the temp directory."""
    from harness.registry import load_plugin

    for spec in specs:
        path = Path(spec["path"])
        try:
            same = path.is_file() and hashlib.sha256(path.read_bytes()).hexdigest() == spec["sha256"]
        except OSError:
            same = False
        if not same:
            path = Path(tempfile.gettempdir()) / "harness-plugins" / spec["sha256"][:16] / spec["name"]
            if not path.is_file():
                atomic_write_bytes(path, spec["source"])
        load_plugin(path, probe=False)  # the submitting process probed it


def _worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _hard_exit(claim: str | None, seconds: float) -> None:  # pragma: no cover - ends the process
    if claim:
        with contextlib.suppress(OSError), open(claim, "a") as fh:
            fh.write(f"{_HARD_TIMEOUT_MARK} {seconds:g}\n")
    os._exit(70)


_HARD_TIMEOUT_MARK = "harness: hard timeout after"
_FATAL_MARK = "Fatal Python error:"


def _claim_verdict(text: str) -> tuple[str, str] | None:
    """(failure kind, message) when a claim file says why its worker died, else None."""
    for line in text.splitlines():
        if line.startswith(_HARD_TIMEOUT_MARK):
            seconds = line[len(_HARD_TIMEOUT_MARK):].strip()
            return ("timeout", f"timeout after {seconds} s (stuck in compiled code; worker "
                               "process ended)")
    if _FATAL_MARK in text:
        fatal = text[text.index(_FATAL_MARK):]
        first = fatal.splitlines()[0]
        return ("crash", f"worker process crashed: {first}")
    return None


def _prepare_worker(task: Mapping[str, Any]) -> tuple[str, str] | None:
    """Load the run's plugins here and check this process's stepper/problem code against the
    submitter's. Returns (failure kind, message) or None."""
    cell: Cell = task["cell"]
    try:
        _ensure_plugins(task.get("plugins", ()))
        if task.get("sp_version") is not None:
            here = code_version(cell.stepper, cell.problem)
            if here != task["sp_version"]:
                return ("version", f"this worker's code for stepper {cell.stepper!r} / problem "
                        f"{cell.problem!r} differs from the submitting process's (install the "
                        "same harness and plugins on every worker; a fingerprint must not "
                        "contain memory addresses)")
    except Exception as exc:
        return ("lookup", f"{type(exc).__name__}: {exc}")
    return None


_orphan_watch: list[int] = []


def _watch_for_orphaning(parent: int) -> None:
    """In a worker process: exit when the process that started it is gone (re-parented), so the
    workers of a run killed with SIGKILL do not linger. Started once per process."""
    if _orphan_watch or parent == os.getpid():
        return
    _orphan_watch.append(parent)

    def watch():  # pragma: no cover - ends the process
        while True:
            time.sleep(ORPHAN_CHECK_S)
            if os.getppid() != parent:
                os._exit(75)

    threading.Thread(target=watch, name="harness-orphan-watch", daemon=True).start()


def _execute(task: Mapping[str, Any]) -> dict:
    """Run one cell and return its outcome; never raises (a worker's entry point). The time
    limit and `wall_s` cover `run_cell` and the check of its rows, not the worker's set-up."""
    cell: Cell = task["cell"]
    timeout = task.get("timeout")
    out: dict[str, Any] = {"key": task["key"], "ok": False, "kind": "error", "message": "",
                           "traceback": "", "rows": None, "wall_s": 0.0, "worker": _worker_id()}
    claim = os.path.join(task["claim_dir"], task["key"]) if task.get("claim_dir") else None
    if task.get("parent_pid") is not None:
        _watch_for_orphaning(task["parent_pid"])
    watchdog = None
    claim_fh = None
    faults_were_on = faulthandler.is_enabled()
    started = time.perf_counter()
    try:
        if claim:
            # While the cell runs, its claim file holds this process's pid and, should the
            # process die of a fatal signal (SIGSEGV, SIGFPE, SIGABRT, SIGBUS, SIGILL), the
            # Python traceback faulthandler writes: the runner then knows which cell it was.
            # Without a claim (its directory gone) the cell still runs; a crash is then found
            # by rerunning the cells in flight alone.
            try:
                claim_fh = open(claim, "w")  # noqa: SIM115 - kept open for faulthandler
                claim_fh.write(f"{os.getpid()}\n")
                claim_fh.flush()
                faulthandler.enable(file=claim_fh)
            except OSError:
                claim_fh, claim = None, None
        with contextlib.redirect_stdout(sys.stderr):  # a plugin's print() stays off stdout
            problem = _prepare_worker(task)
        if problem is not None:
            out.update(kind=problem[0], message=_one_line(problem[1]))
            return out
        if timeout is not None and task.get("hard_kill"):
            grace = float(task.get("hard_grace", HARD_TIMEOUT_GRACE_S))
            watchdog = threading.Timer(timeout + grace, _hard_exit, (claim, timeout))
            watchdog.daemon = True
            watchdog.start()
        experiment = task["experiment"]
        started = time.perf_counter()
        with contextlib.redirect_stdout(sys.stderr):
            rows = _call_limited(
                lambda: validate_rows(experiment, experiment.run_cell(cell, task["config"])), timeout
            )
        out.update(ok=True, kind="", rows=rows)
    except CellTimeout:
        out.update(kind="timeout", message=f"timeout after {timeout:g} s")
    except (CellOutputError, StepperOutputError) as exc:
        out.update(kind="invalid", message=_one_line(str(exc)))
    except (KeyboardInterrupt, Terminated):
        raise
    except BaseException as exc:  # the cell's own failure, whatever it is
        out.update(kind="error", message=_one_line(f"{type(exc).__name__}: {exc}"),
                   traceback=_short_traceback(exc))
    finally:
        if watchdog is not None:
            watchdog.cancel()
        if claim_fh is not None:
            faulthandler.disable()
            if faults_were_on:
                faulthandler.enable()
            claim_fh.close()
        if claim:
            with contextlib.suppress(OSError):
                os.unlink(claim)
        out["wall_s"] = time.perf_counter() - started
    return out


# -- the result of a run ----------------------------------------------------------------------------
FAILURE_COLUMNS = ["experiment", "cell", "stepper", "problem", "params", "key", "kind", "message",
                   "traceback"]
SKIP_COLUMNS = ["experiment", "stepper", "problem", "reason"]
CELL_COLUMNS = ["experiment", "cell", "stepper", "problem", "params", "key", "status", "cached",
                "wall_s", "n_rows", "worker"]
ID_COLUMNS = ["experiment", "cell", "stepper", "problem"]


@dataclass
class RunResult:
    """One experiment's run.

    `rows`: tidy rows of every successful cell in the order of the experiment's cell list, with
    `experiment`, `cell` (label), `stepper`, `problem` and scalar cell parameters added as
    columns when the experiment's rows lack them. `summary`: `experiment.summarize(rows)`.
    `failures`: one record per failed cell (FAILURE_COLUMNS; `kind` in FAILURE_KINDS).
    `skips`: pairs the experiment does not apply to, with the reason. `cells`: one record per
    cell (status 'ok' or 'failed', whether cached, compute wall time, row count, worker).
    """

    experiment: str
    description: str
    config: dict
    rows: pd.DataFrame
    summary: pd.DataFrame
    failures: pd.DataFrame
    skips: pd.DataFrame
    cells: pd.DataFrame
    wall_s: float
    cached_cells: int
    computed_cells: int
    options: dict = field(default_factory=dict)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    @property
    def n_failed(self) -> int:
        return len(self.failures)

    @property
    def ok(self) -> bool:
        return self.n_failed == 0


# -- argument checks --------------------------------------------------------------------------------
def default_jobs() -> int:
    """All cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _check_jobs(jobs: Any) -> int:
    if jobs is None:
        return default_jobs()
    if isinstance(jobs, bool) or not isinstance(jobs, int | np.integer):
        raise InputError(f"`jobs` must be a whole number >= 1, got {jobs!r}")
    limit = MAX_JOBS_PER_CORE * default_jobs()
    if jobs < 1 or jobs > limit:
        raise InputError(f"`jobs` must be between 1 and {limit} ({MAX_JOBS_PER_CORE} per core), got {jobs}")
    return int(jobs)


def _check_timeout(value: Any) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool):
        raise InputError(f"`cell_timeout` must be a number of seconds, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"`cell_timeout` must be a number of seconds, got {value!r}") from None
    if not math.isfinite(x) or x <= 0 or x > MAX_CELL_TIMEOUT_S:
        raise InputError(
            f"`cell_timeout` must be positive, finite and at most {MAX_CELL_TIMEOUT_S:g} s, got {x!r}"
        )
    return x


_SCHEDULER = re.compile(r"^(tcp|tls|ucx|ws|wss|inproc)://[^\s/]+$")


def _check_scheduler(value: Any) -> Any:
    if value is None:
        return None
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - dask is in the pinned requirements
        Client = ()  # type: ignore[assignment]
    if Client and isinstance(value, Client):
        return value
    if not isinstance(value, str) or not _SCHEDULER.match(value):
        raise InputError(
            f"`scheduler` must be a Dask scheduler address like tcp://HOST:PORT, got {str(value)[:80]!r}"
        )
    return value


def _check_names(kind: str, names: Any) -> list[str]:
    from harness import registry

    reg = registry.steppers if kind == "steppers" else registry.problems
    if names is None:
        return reg.names()
    if isinstance(names, str):
        names = [names]
    if not isinstance(names, Iterable):
        raise InputError(f"`{kind}` must be a list of names, got {type(names).__name__}")
    out = []
    for n in names:
        if not isinstance(n, str) or not n:
            raise InputError(f"`{kind}` must hold non-empty names (strings), got {n!r}")
        reg.get(n)  # UnknownNameError with the closest names
        out.append(n)
    return list(dict.fromkeys(out))


def _check_plugins(plugins: Any) -> list[str]:
    if plugins is None:
        return []
    if isinstance(plugins, str | os.PathLike):
        plugins = [plugins]
    if not isinstance(plugins, Iterable):
        raise InputError(f"`plugins` must be a list of .py file paths, got {type(plugins).__name__}")
    out = []
    for p in plugins:
        if not isinstance(p, str | os.PathLike) or not os.fspath(p):
            raise InputError(f"`plugins` must hold .py file paths, got {p!r}")
        out.append(os.fspath(p))
    return out


def _resolve_experiment(experiment: Any) -> Experiment:
    from harness.experiments.base import get_experiment

    if isinstance(experiment, Experiment):
        return experiment
    if not isinstance(experiment, str) or not experiment:
        raise InputError(f"`experiment` must be an experiment name, got {experiment!r}")
    return get_experiment(experiment)


def _resolve_config(exp: Experiment, config: Any, quick: bool) -> dict:
    if config is not None and not isinstance(config, Mapping):
        raise InputError(f"`config` must be a mapping of settings, got {type(config).__name__}")
    if config and exp.default_config:
        unknown = [k for k in config if k not in exp.default_config]
        if unknown:
            raise InputError(
                f"`config` sets {', '.join(map(repr, unknown))}, not settings of experiment "
                f"{exp.name!r}; known: {', '.join(sorted(exp.default_config))}"
            )
    return exp.config(dict(config or {}), quick=bool(quick))


def _progress(progress: Any, desc: str) -> tuple[Progress, bool]:
    """(progress display, whether this call owns and closes it)."""
    if isinstance(progress, Progress):
        return progress, False
    if progress is None or progress is True:
        return Progress(0, desc), True
    if progress is False:
        return Progress(0, desc, mode="off"), True
    if isinstance(progress, str):
        return Progress(0, desc, mode=progress), True
    raise InputError(f"`progress` must be None, a bool, a mode name or a Progress, got {progress!r}")


# -- executing many cells ---------------------------------------------------------------------------
@dataclass
class _Task:
    index: int
    cell: Cell
    key: str
    payload: dict
    crash_rounds: int = 0


def _crash_outcome(task: _Task, message: str, kind: str = "crash") -> dict:
    return {"key": task.key, "ok": False, "kind": kind, "message": _one_line(message),
            "traceback": "", "rows": None, "wall_s": 0.0, "worker": ""}


def _run_serial(tasks: Sequence[_Task], accept: Callable[[_Task, dict], None]) -> None:
    for t in tasks:
        accept(t, _execute(t.payload))


def _loky_batch(batch: Sequence[_Task], n: int, accept) -> tuple[BaseException | None, list[_Task]]:
    """Run `batch` on `n` loky workers. Returns (the pool's breakdown or None, unfinished tasks)."""
    from joblib.externals.loky import get_reusable_executor

    executor = get_reusable_executor(max_workers=n, timeout=LOKY_IDLE_TIMEOUT_S)
    futures = {}
    try:
        for t in batch:
            futures[executor.submit(_execute, t.payload)] = t
        pending = set(futures)
        broken: BaseException | None = None
        while pending and broken is None:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                t = futures[fut]
                exc = fut.exception()
                if isinstance(exc, BrokenProcessPool):
                    broken = exc
                    pending.add(fut)
                elif exc is not None:  # the task could not be sent or its result returned
                    accept(t, _crash_outcome(t, f"could not run in a worker process: "
                                                f"{type(exc).__name__}: {exc}", kind="error"))
                else:
                    accept(t, fut.result())
    except BaseException:  # Ctrl-C, SIGTERM (the CLI raises SystemExit), anything unexpected
        executor.shutdown(wait=False, kill_workers=True)
        raise
    if broken is None:
        return None, []
    wait(pending)  # the pool fails every pending future when it breaks
    unfinished = []
    for fut in pending:
        t = futures[fut]
        if fut.exception() is None:
            accept(t, fut.result())
        else:
            unfinished.append(t)
    return broken, unfinished


def _clean_stale_claims() -> None:
    """Remove claim directories left by runs killed long ago (their process ended before its
    `finally`); a live run touches its directory with every cell."""
    base = Path(tempfile.gettempdir())
    cutoff = time.time() - STALE_CLAIMS_S
    for d in base.glob("harness-claims-*"):
        with contextlib.suppress(OSError):
            if d.is_dir() and d.stat().st_mtime < cutoff:
                shutil.rmtree(d, ignore_errors=True)


def _run_loky(tasks: Sequence[_Task], jobs: int, accept) -> None:
    _clean_stale_claims()
    claim_dir = tempfile.mkdtemp(prefix="harness-claims-")
    try:
        for t in tasks:
            t.payload["claim_dir"] = claim_dir
            t.payload["parent_pid"] = os.getpid()
            t.payload["hard_kill"] = True
            t.payload["hard_grace"] = max(HARD_TIMEOUT_GRACE_S, 0.2 * (t.payload["timeout"] or 0))
        normal: list[_Task] = list(tasks)
        suspects: list[_Task] = []
        while normal or suspects:
            alone = not normal
            batch, normal = ([suspects.pop(0)], normal) if alone else (normal, [])
            broken, unfinished = _loky_batch(batch, 1 if alone else min(jobs, len(batch)), accept)
            if broken is None:
                continue
            claims: dict[str, str] = {}
            for name in os.listdir(claim_dir):
                with contextlib.suppress(OSError):
                    claims[name] = Path(claim_dir, name).read_text(errors="replace")
                    os.unlink(os.path.join(claim_dir, name))
            codes = re.search(r"exit codes of the workers are (\{[^}]*\})", str(broken))
            reason = f"exit codes {codes.group(1)}" if codes else _one_line(str(broken), 200)
            verdicts = {t.key: _claim_verdict(claims[t.key]) for t in unfinished if t.key in claims}
            known_culprit = any(v is not None for v in verdicts.values())
            for t in unfinished:
                t.crash_rounds += 1
                verdict = verdicts.get(t.key)
                if verdict is not None:
                    accept(t, _crash_outcome(t, verdict[1], verdict[0]))
                elif alone or t.crash_rounds >= MAX_CRASH_ROUNDS:
                    accept(t, _crash_outcome(t, f"worker process died running this cell ({reason})"))
                elif t.key in claims and not known_culprit:
                    suspects.append(t)  # in flight when an unknown cell killed the pool
                elif verdicts:
                    normal.append(t)  # never started, or the victim of a known culprit
                else:
                    suspects.append(t)  # no claim at all tells who it was: try each alone
    finally:
        shutil.rmtree(claim_dir, ignore_errors=True)


def _dask_client(scheduler: Any) -> tuple[Any, bool]:
    from distributed import Client

    if isinstance(scheduler, Client):
        return scheduler, False
    failure = None
    hook = sys.unraisablehook
    sys.unraisablehook = lambda unraisable: None  # a half-built Client's destructor complains
    try:
        try:
            client = Client(scheduler, timeout=f"{DASK_CONNECT_TIMEOUT_S}s", set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            failure = f"{type(exc).__name__}: {_one_line(str(exc), 200)}"
        if failure is not None:
            import gc

            gc.collect()  # the half-built client goes now, while its complaint is silenced
    finally:
        sys.unraisablehook = hook
    if failure is not None:
        raise InputError(
            f"`scheduler` {scheduler!r}: cannot connect within {DASK_CONNECT_TIMEOUT_S} s ({failure})"
        )
    return client, True


def _run_dask(tasks: Sequence[_Task], client: Any, accept) -> None:
    import uuid

    from distributed import as_completed

    tag = uuid.uuid4().hex[:8]
    futures = {}
    try:
        for t in tasks:
            fut = client.submit(_execute, t.payload, key=f"harness-cell-{t.key}-{tag}", pure=False)
            futures[fut] = t
        for fut in as_completed(list(futures), loop=client.loop):
            t = futures[fut]
            try:
                out = fut.result()
            except Exception as exc:  # KilledWorker, a lost connection, an unpicklable result
                out = _crash_outcome(t, f"Dask task failed: {type(exc).__name__}: {exc}")
            accept(t, out)
    except KeyboardInterrupt:
        client.cancel(list(futures))
        raise


# -- the runner -------------------------------------------------------------------------------------
def _skip_records(skips: Iterable[Skip]) -> list[dict]:
    return [{"experiment": s.experiment, "stepper": s.stepper, "problem": s.problem,
             "reason": s.reason} for s in skips]


def no_cells_error(experiments: Sequence[str], skips: Sequence[Skip] | pd.DataFrame,
                   steppers: Sequence[str], problems: Sequence[str]) -> NoApplicableCellsError:
    """The error for a run over zero applicable cells: one line saying why each requested pair
    does not apply (the experiments' skip reasons); every record is kept in `.skips`."""
    records = (skips.to_dict("records") if isinstance(skips, pd.DataFrame)
               else _skip_records(skips))
    what = ", ".join(map(repr, experiments))
    head = (f"no cell of {what} applies to the requested stepper(s) "
            f"{_few(steppers)} x problem(s) {_few(problems)}")
    if not records:
        return NoApplicableCellsError(head + " (the experiment lists no pairs for them)", records)
    reasons = [f"{r['stepper'] or '-'} x {r['problem'] or '-'}: {r['reason']}" for r in records[:4]]
    more = f"; and {len(records) - 4} more pairs" if len(records) > 4 else ""
    return NoApplicableCellsError(f"{head}: " + "; ".join(reasons) + more, records)


def _few(names: Sequence[str], n: int = 4) -> str:
    shown = ", ".join(names[:n]) if names else "(none)"
    return shown + (f" (+{len(names) - n} more)" if len(names) > n else "")


def _params_json(cell: Cell) -> str:
    return json.dumps({str(k): v for k, v in cell.params}, sort_keys=True, default=repr)


def _with_ids(rows: pd.DataFrame, cell: Cell) -> pd.DataFrame:
    rows = rows.reset_index(drop=True)
    front = {"experiment": cell.experiment, "cell": cell.label, "stepper": cell.stepper,
             "problem": cell.problem}
    for k, v in cell.params:
        if isinstance(k, str) and k and isinstance(v, _SCALARS):
            front.setdefault(k, v.item() if isinstance(v, np.generic) else v)
    add = {k: v for k, v in front.items() if k not in rows.columns}
    if not add:
        return rows
    ids = pd.DataFrame({k: [v] * len(rows) for k, v in add.items()})
    return pd.concat([ids, rows], axis=1)


def _roundtrip(key: str, rows: pd.DataFrame, info: Mapping[str, Any]) -> tuple[pd.DataFrame, bytes]:
    """Rows as they come back from the cell file (so fresh and cached cells are identical), and
    the file's bytes for the cache (`harness.store.encode_cell`)."""
    try:
        return encode_cell(key, rows, info)
    except InputError as exc:
        raise CellOutputError(f"rows {exc}") from None


def run_experiment(
    experiment: str | Experiment,
    steppers: Sequence[str] | None = None,
    problems: Sequence[str] | None = None,
    *,
    config: Mapping[str, Any] | None = None,
    quick: bool = False,
    jobs: int | None = None,
    scheduler: str | Any | None = None,
    fresh: bool = False,
    cache: bool = True,
    cache_dir: str | os.PathLike | None = None,
    plugins: Sequence[str | os.PathLike] = (),
    cell_timeout: float | None = None,
    progress: Progress | bool | str | None = None,
    allow_empty: bool = False,
    _client: Any = None,
    _counted: bool = False,
) -> RunResult:
    """Run one experiment over `steppers` x `problems` (None: the whole registry).

    Arguments: `config` overrides the experiment's settings (`quick` starts from its quick
    settings); `jobs` worker processes (None: all cores; 1: in this process); `scheduler` a Dask
    scheduler address (`tcp://HOST:PORT`) or `distributed.Client`, instead of local processes;
    `fresh` recomputes cached cells; `cache=False` neither reads nor writes the cache;
    `cache_dir` the cache root (default `harness.cache.cache_dir()`); `plugins` .py files loaded
    here and on every worker before names are looked up; `cell_timeout` seconds per cell;
    `progress` None/True (bar on a terminal, plain lines otherwise), False (silent), a mode
    ('bar', 'lines', 'off') or a shared `Progress`; `allow_empty=True` returns an empty result
    instead of raising when no cell applies.

    Raises `InputError` / `UnknownNameError` / `PluginError` (all `HarnessError`) for bad
    arguments before any cell runs, `NoApplicableCellsError` (with every skip reason) when no
    requested pair applies, `ExperimentError` when the experiment cannot list its
    cells, `CorruptResultsError` for a damaged cache file. Failures of single cells never raise:
    they are in `RunResult.failures`.
    """
    started = time.perf_counter()
    exp = _resolve_experiment(experiment)
    jobs_n = _check_jobs(jobs)
    timeout = _check_timeout(cell_timeout)
    sched = _check_scheduler(scheduler)
    plugin_paths = _check_plugins(plugins)
    for name, flag in (("quick", quick), ("fresh", fresh), ("cache", cache)):
        if not isinstance(flag, bool | np.bool_):
            raise InputError(f"`{name}` must be True or False, got {flag!r}")
    store = CellCache(cache_dir) if cache else None
    from harness.registry import load_plugin

    for p in plugin_paths:
        load_plugin(p)
    plugin_specs = [_plugin_spec(p) for p in plugin_paths]
    stepper_names = _check_names("steppers", steppers)
    problem_names = _check_names("problems", problems)
    cfg = _resolve_config(exp, config, quick)

    try:
        listed = exp.cells(stepper_names, problem_names, cfg)
        cells, skips = listed
        cells, skips = list(cells), list(skips)
    except HarnessError:
        raise
    except Exception as exc:
        raise ExperimentError(
            f"experiment {exp.name!r} could not list its cells: "
            f"{type(exc).__name__}: {_one_line(str(exc), 300)}"
        ) from None
    bad = [c for c in cells if not isinstance(c, Cell)] + [s for s in skips if not isinstance(s, Skip)]
    if bad:
        raise ExperimentError(f"experiment {exp.name!r} listed {type(bad[0]).__name__} objects "
                              "where Cell and Skip objects belong")
    if not cells and not allow_empty:
        raise no_cells_error([exp.name], skips, stepper_names, problem_names)
    if sched is None and _client is None:
        _guard_memory(exp, cells, cfg, jobs_n)
    own_client = None
    if sched is not None and _client is None:
        # connect before looking at the cache: a bad address is an error even when every cell
        # is cached
        _client, own_client = _dask_client(sched)

    exp_version = experiment_fingerprint(exp)
    versions: dict[tuple[str, str], Any] = {}
    failures: dict[int, dict] = {}
    records: dict[int, dict] = {}
    frames: dict[int, pd.DataFrame] = {}
    tasks: list[_Task] = []
    seen: dict[str, int] = {}
    cached = 0
    bar, own_bar = _progress(progress, exp.name)
    if not _counted:
        bar.add_total(len(cells))
        if not own_bar:
            bar.set_description(exp.name)

    def record(i: int, cell: Cell, key: str, status: str, was_cached: bool, wall: float,
               n_rows: int, worker: str) -> None:
        records[i] = {"experiment": exp.name, "cell": cell.label, "stepper": cell.stepper,
                      "problem": cell.problem, "params": _params_json(cell), "key": key,
                      "status": status, "cached": was_cached, "wall_s": float(wall),
                      "n_rows": int(n_rows), "worker": worker}

    def fail(i: int, cell: Cell, key: str, kind: str, message: str, tb: str = "",
             wall: float = 0.0, worker: str = "") -> None:
        failures[i] = failed_record(cell, message, kind=kind, traceback=tb, key=key)
        record(i, cell, key, "failed", False, wall, 0, worker)

    try:
        for i, cell in enumerate(cells):
            pair = (cell.stepper, cell.problem)
            if pair not in versions:
                try:
                    versions[pair] = code_version(*pair)
                except Exception as exc:  # unknown name, or a fingerprint() that raises
                    versions[pair] = exc
            v = versions[pair]
            if isinstance(v, Exception):
                fail(i, cell, "", "lookup", _one_line(f"{type(v).__name__}: {v}"))
                bar.update(1, failed=1)
                continue
            key = cell_key(cell, cfg, exp_version, v)
            if key in seen:
                raise ExperimentError(
                    f"experiment {exp.name!r} lists cell {cell.label} twice"
                )
            seen[key] = i
            hit = store.get(key) if (store is not None and not fresh) else None
            if hit is not None:
                rows, info = hit
                frames[i] = rows
                record(i, cell, key, "ok", True, float(info.get("wall_s", 0.0)), len(rows),
                       str(info.get("worker", "")))
                cached += 1
                continue
            payload = {"key": key, "cell": cell, "config": cfg, "experiment": exp,
                       "plugins": plugin_specs, "timeout": timeout, "sp_version": v}
            tasks.append(_Task(i, cell, key, payload))
        if cached:
            bar.update(cached, cached=cached)

        def accept(t: _Task, out: dict) -> None:
            if out["ok"]:
                try:
                    rows = _with_ids(out["rows"], t.cell)
                    info = {"key": t.key, "experiment": exp.name, "cell": t.cell.label,
                            "wall_s": out["wall_s"], "worker": out["worker"]}
                    rows, data = _roundtrip(t.key, rows, info)
                except CellOutputError as exc:
                    fail(t.index, t.cell, t.key, "invalid", str(exc), wall=out["wall_s"],
                         worker=out["worker"])
                    bar.update(1, failed=1)
                    return
                if store is not None:
                    store.put_encoded(t.key, data)  # atomic; OutputError names the file
                frames[t.index] = rows
                record(t.index, t.cell, t.key, "ok", False, out["wall_s"], len(rows), out["worker"])
                bar.update(1)
            else:
                fail(t.index, t.cell, t.key, out["kind"], out["message"], out["traceback"],
                     out["wall_s"], out["worker"])
                bar.update(1, failed=1)

        if tasks:
            if _client is not None:
                _run_dask(tasks, _client, accept)
            elif jobs_n == 1:
                _run_serial(tasks, accept)
            else:
                _run_loky(tasks, jobs_n, accept)
    finally:
        if own_client:
            _client.close()
        if own_bar:
            bar.close()

    order = sorted(frames)
    if order:
        with_rows = [frames[i] for i in order if len(frames[i].columns)]
        rows_df = pd.concat(with_rows, ignore_index=True) if with_rows else pd.DataFrame(columns=ID_COLUMNS)
    else:
        rows_df = pd.DataFrame(columns=ID_COLUMNS)
    summary = pd.DataFrame()
    if order:
        try:
            summary = exp.summarize(rows_df.copy(), cfg)
            if not isinstance(summary, pd.DataFrame):
                raise CellOutputError(
                    f"summarize returned {type(summary).__name__}, expected a pandas DataFrame"
                )
            summary = summary.reset_index(drop=True)
        except Exception as exc:
            summary = pd.DataFrame()
            rec = failed_record(Cell(exp.name, "", ""), _one_line(f"{type(exc).__name__}: {exc}"),
                                kind="summarize", traceback=_short_traceback(exc))
            rec["cell"] = f"{exp.name}:summarize"
            failures[len(cells)] = rec
    fail_df = pd.DataFrame([failures[i] for i in sorted(failures)], columns=FAILURE_COLUMNS)
    skip_df = pd.DataFrame(_skip_records(skips), columns=SKIP_COLUMNS)
    cell_df = pd.DataFrame([records[i] for i in sorted(records)], columns=CELL_COLUMNS)
    return RunResult(
        experiment=exp.name,
        description=str(getattr(exp, "description", "")),
        config=cfg,
        rows=rows_df,
        summary=summary,
        failures=fail_df,
        skips=skip_df,
        cells=cell_df,
        wall_s=time.perf_counter() - started,
        cached_cells=cached,
        computed_cells=len(tasks),
        options={"jobs": jobs_n if sched is None and _client is None else None,
                 "scheduler": scheduler if isinstance(scheduler, str) else None,
                 "fresh": bool(fresh), "cache": bool(cache), "quick": bool(quick),
                 "cell_timeout": timeout, "plugins": plugin_paths,
                 "steppers": stepper_names, "problems": problem_names},
    )


def run_experiments(
    experiments: Sequence[str | Experiment] | None = None,
    steppers: Sequence[str] | None = None,
    problems: Sequence[str] | None = None,
    *,
    configs: Mapping[str, Mapping[str, Any]] | None = None,
    quick: bool = False,
    jobs: int | None = None,
    scheduler: str | Any | None = None,
    fresh: bool = False,
    cache: bool = True,
    cache_dir: str | os.PathLike | None = None,
    plugins: Sequence[str | os.PathLike] = (),
    cell_timeout: float | None = None,
    progress: Progress | bool | str | None = None,
) -> dict[str, RunResult]:
    """`run_experiment` for several experiments (None: every registered one), in order, with one
    progress display and one Dask connection; `configs` maps experiment name -> overrides.
    Returns {experiment name: RunResult}; pass it to `harness.store.save_run`."""
    from harness.experiments import EXPERIMENTS

    if experiments is None:
        experiments = list(EXPERIMENTS)
    if isinstance(experiments, str | Experiment):
        experiments = [experiments]
    exps = [_resolve_experiment(e) for e in experiments]
    if configs is not None and not isinstance(configs, Mapping):
        raise InputError(f"`configs` must map experiment names to settings, got {type(configs).__name__}")
    unknown = [k for k in (configs or {}) if k not in {e.name for e in exps}]
    if unknown:
        raise UnknownNameError(f"`configs` names experiments not being run: {unknown}")
    sched = _check_scheduler(scheduler)
    from harness.registry import load_plugin

    for p in _check_plugins(plugins):
        load_plugin(p)
    stepper_names = _check_names("steppers", steppers)
    problem_names = _check_names("problems", problems)
    bar, own_bar = _progress(progress, "cells")
    sizes = []
    for exp in exps:  # the whole run's size first, so the display's total does not grow
        try:
            cfg = _resolve_config(exp, (configs or {}).get(exp.name), quick)
            sizes.append(len(list(exp.cells(stepper_names, problem_names, cfg)[0])))
        except Exception:  # run_experiment reports it properly below
            sizes = None
            break
    counted = sizes is not None
    if counted:
        bar.add_total(sum(sizes))
    client = None
    own_client = False
    out: dict[str, RunResult] = {}
    try:
        if sched is not None:
            client, own_client = _dask_client(sched)
        for i, exp in enumerate(exps, 1):
            bar.set_description(f"[{i}/{len(exps)}] {exp.name}")
            out[exp.name] = run_experiment(
                exp, stepper_names, problem_names, config=(configs or {}).get(exp.name),
                quick=quick, jobs=jobs, fresh=fresh, cache=cache, cache_dir=cache_dir,
                plugins=plugins, cell_timeout=cell_timeout, progress=bar, _client=client,
                _counted=counted, allow_empty=True,
            )
            if sched is not None:
                out[exp.name].options["scheduler"] = sched if isinstance(sched, str) else None
    finally:
        if own_client and client is not None:
            client.close()
        if own_bar:
            bar.close()
    if out and not any(r.n_cells for r in out.values()):
        raise no_cells_error(list(out), pd.concat([r.skips for r in out.values()], ignore_index=True),
                             stepper_names, problem_names)
    return out
