"""One cell, wherever it runs: plugins, code-version check, claim file, time limit, rows.

`execute(task)` is the entry point of every worker (this process, loky, Dask); it never raises.
"""

from __future__ import annotations

import contextlib
import faulthandler
import hashlib
import os
import shutil
import socket
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import cloudpickle

from harness.errors import (
    InputError,
    StepperOutputError,
    Terminated,
)
from harness.experiments.base import Cell
from harness.keys import code_version
from harness.registry import load_plugin, problems, steppers
from harness.runner.limits import HARD_TIMEOUT_GRACE_S, CellTimeout, call_limited
from harness.runner.validation import CellOutputError, validate_rows
from harness.stepper import Stepper
from harness.store import (
    atomic_write_bytes,
)

# A worker process whose parent died (kill -9 of the run) notices within this many seconds and
# exits (its parent pid changes when it is re-parented).
ORPHAN_CHECK_S = 1.0
# Claim directories of killed runs older than this (seconds) are removed by the next run.
STALE_CLAIMS_S = 24 * 3600.0


def short_traceback(exc: BaseException, frames: int = 6) -> str:
    """The last `frames` frames of `exc`'s traceback as text, at most 4000 characters.

    Parameters
    ----------
    exc : BaseException, the exception.
    frames : int, optional, how many of the innermost frames (default 6).

    Returns
    -------
    str
    """
    te = traceback.TracebackException.from_exception(exc, limit=-frames)
    text = "".join(te.format()).strip()
    return text if len(text) <= 4000 else "..." + text[-3997:]


def one_line(text: str, limit: int = 500) -> str:
    """`text` on one line, whitespace collapsed, cut to `limit` characters.

    Parameters
    ----------
    text : str, the text.
    limit : int, optional, the longest result (default 500), "..." marking a cut.

    Returns
    -------
    str
    """
    line = " ".join(str(text).split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def plugin_spec(path: str | os.PathLike) -> dict:
    """A plugin file as data a worker can rebuild it from: path, name, sha256 and source bytes.

    Parameters
    ----------
    path : str or PathLike, the plugin file.

    Returns
    -------
    dict
    """
    p = Path(path).resolve()
    data = p.read_bytes()
    return {"path": str(p), "name": p.name, "sha256": hashlib.sha256(data).hexdigest(), "source": data}


def _ensure_plugins(specs: Sequence[dict]) -> None:
    """Load the run's plugin files in this process: from their path when it holds the same
    content, else from a copy written to the temp directory."""
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


SHIPPED_ORIGIN = "harness.api.check"  # the registry origin of objects `check` registered
_shipped: dict[str, list] = {}


def shipped_objects(stepper_names: Sequence[str], problem_names: Sequence[str]) -> bytes | None:
    """The steppers and problems of a run that a worker cannot import (registered in this process
    by `harness.api.check`: a user's function stepper, a `Problem` object), cloudpickled, or
    None when there are none.

    Parameters
    ----------
    stepper_names : sequence of str, the run's steppers.
    problem_names : sequence of str, the run's problems.

    Returns
    -------
    bytes or None
    """
    objs = [reg.get(n) for reg, names in ((steppers, stepper_names), (problems, problem_names))
            for n in sorted(set(names)) if n in reg and reg.origin(n) == SHIPPED_ORIGIN]
    if not objs:
        return None

    try:
        return cloudpickle.dumps(objs)
    except Exception as exc:  # a closure over a lock, an open file, ...
        raise InputError(f"`jobs` > 1 ships {', '.join(map(repr, objs))} to worker processes, but "
                         f"cloudpickle cannot pickle it: {type(exc).__name__}: {exc}; use jobs=1") from None


def _ensure_objects(data: bytes | None, submitter: int | None) -> None:
    """Register the objects shipped with a task (`shipped_objects`) in this worker process."""
    if data is None or submitter == os.getpid():
        return
    key = hashlib.sha256(data).hexdigest()
    if key in _shipped:
        return

    objs = cloudpickle.loads(data)
    for obj in objs:
        (steppers if isinstance(obj, Stepper) else problems).register(
            obj, origin=SHIPPED_ORIGIN, replace=True)
    _shipped[key] = objs


def _worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _hard_exit(claim: str | None, seconds: float) -> None:  # pragma: no cover - ends the process
    if claim:
        with contextlib.suppress(OSError), open(claim, "a") as fh:
            fh.write(f"{_HARD_TIMEOUT_MARK} {seconds:g}\n")
    os._exit(70)


_HARD_TIMEOUT_MARK = "harness: hard timeout after"
_FATAL_MARK = "Fatal Python error:"


def claim_verdict(text: str) -> tuple[str, str] | None:
    """(failure kind, message) when a claim file says why its worker died, else None.

    Parameters
    ----------
    text : str, the claim file's content.

    Returns
    -------
    (str, str) or None
    """
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
        _ensure_objects(task.get("objects"), task.get("submitter"))
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


def execute(task: Mapping[str, Any]) -> dict:
    """Run one cell and return its outcome; never raises (a worker's entry point). The time
    limit and `wall_s` cover `run_cell` and the check of its rows, not the worker's set-up.

    Parameters
    ----------
    task : mapping
        The task's payload: cell, key, experiment, config, and optionally timeout, claim_dir,
        parent_pid, hard_kill, plugins, objects and the version to match.

    Returns
    -------
    dict: key, ok, kind, message, traceback, rows (the checked DataFrame or None), wall_s, worker.
    """
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
            out.update(kind=problem[0], message=one_line(problem[1]))
            return out
        if timeout is not None and task.get("hard_kill"):
            grace = float(task.get("hard_grace", HARD_TIMEOUT_GRACE_S))
            watchdog = threading.Timer(timeout + grace, _hard_exit, (claim, timeout))
            watchdog.daemon = True
            watchdog.start()
        experiment = task["experiment"]
        started = time.perf_counter()
        with contextlib.redirect_stdout(sys.stderr):
            rows = call_limited(
                lambda: validate_rows(experiment, experiment.run_cell(cell, task["config"])), timeout
            )
        out.update(ok=True, kind="", rows=rows)
    except CellTimeout:
        out.update(kind="timeout", message=f"timeout after {timeout:g} s")
    except (CellOutputError, StepperOutputError) as exc:
        out.update(kind="invalid", message=one_line(str(exc)))
    except (KeyboardInterrupt, Terminated):
        raise
    except BaseException as exc:  # the cell's own failure, whatever it is
        out.update(kind="error", message=one_line(f"{type(exc).__name__}: {exc}"),
                   traceback=short_traceback(exc))
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



def clean_stale_claims() -> None:
    """Remove claim directories left by runs killed long ago (their process ended before its
    `finally`); a live run touches its directory with every cell."""
    base = Path(tempfile.gettempdir())
    cutoff = time.time() - STALE_CLAIMS_S
    for d in base.glob("harness-claims-*"):
        with contextlib.suppress(OSError):
            if d.is_dir() and d.stat().st_mtime < cutoff:
                shutil.rmtree(d, ignore_errors=True)


