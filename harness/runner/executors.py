"""Executing many cells: in this process, on local loky workers, or on a Dask cluster."""

from __future__ import annotations

import contextlib
import gc
import os
import re
import shutil
import signal
import socket
import struct
import sys
import tempfile
import threading
import time
import uuid
import warnings
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from joblib.externals.loky import get_reusable_executor

from harness.errors import (
    InputError,
)
from harness.experiments.base import Cell
from harness.runner import limits
from harness.runner.workers import claim_verdict, clean_stale_claims, execute, one_line

# Seconds to wait for a Dask scheduler to answer (connection and handshake together).
DASK_CONNECT_TIMEOUT_S = 10
# A Dask scheduler's first message (its handshake: compression, Python version, pickle protocol)
# is ~60 bytes; a first length above this is another kind of server.
DASK_HANDSHAKE_MAX_BYTES = 65536
# Seconds an idle loky worker waits for work before it exits (short: a worker is cheap to start,
# and the workers of a run killed with SIGKILL should not linger).
LOKY_IDLE_TIMEOUT_S = 30
# A cell whose worker died in this many pool breakdowns is recorded as crashed, whatever the
# claim files say (guarantees the run ends).
MAX_CRASH_ROUNDS = 3


@dataclass
class Task:
    """One cell to execute: its index in the cell list, the cell, its key and the payload a worker
    receives.
    """
    index: int
    cell: Cell
    key: str
    payload: dict
    crash_rounds: int = 0


def crash_outcome(task: Task, message: str, kind: str = "crash") -> dict:
    """The outcome of a task whose worker died (or, with `kind`, another failure outside the cell).

    Parameters
    ----------
    task : Task
        The task.
    message : str
        What happened (put on one line).
    kind : str, optional
        The failure kind (default "crash").

    Returns
    -------
    dict
        An outcome as `execute` returns one, not ok, with no rows.
    """
    return {"key": task.key, "ok": False, "kind": kind, "message": one_line(message),
            "traceback": "", "rows": None, "wall_s": 0.0, "worker": ""}


def run_serial(tasks: Sequence[Task], accept: Callable[[Task, dict], None]) -> None:
    """Execute `tasks` one after another in this process, handing each outcome to `accept`.

    Parameters
    ----------
    tasks : sequence of Task
        The tasks.
    accept : callable
        ``accept(task, outcome)``, called once per task.
    """
    for t in tasks:
        accept(t, execute(t.payload))


def quiet_worker_signals() -> None:
    """A loky worker's signal dispositions: Ctrl-C at a terminal reaches the whole process
    group, but only the parent decides (it stops the pool and prints one line), so workers
    ignore SIGINT; SIGTERM ends a worker at once and silently. Never a worker's traceback.
    Workers started by `loky_batch` ignore SIGINT from birth already (`workers_born_deaf`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


@contextlib.contextmanager
def workers_born_deaf(signals: Sequence[int] = ()):
    """`signals` (default SIGINT) ignored in this process while it starts pool workers: an
    ignored signal stays ignored through fork and exec, and Python then installs no handler,
    so a Ctrl-C to the process group while a worker is still importing (up to seconds on a
    loaded machine, before `quiet_worker_signals` runs) cannot print its traceback (it did:
    "Fatal Python error: init_import_site", or KeyboardInterrupt from joblib's import; a forked
    worker raised the parent's Terminated in an at-fork hook). The worker's initializer sets
    its own dispositions. The cost: a signal within the few milliseconds of starting the
    workers is not seen by this process either (send it again). Outside the main thread a
    no-op.

    Parameters
    ----------
    signals : sequence of int
        The signal numbers to ignore while the block runs (empty: SIGINT alone).

    Yields
    ------
    None
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    saved = [(s, signal.signal(s, signal.SIG_IGN)) for s in (signals or (signal.SIGINT,))]
    try:
        yield
    finally:
        for sig, handler in saved:
            signal.signal(sig, handler)


def _quiet_loky() -> None:
    """Drop loky's "A worker stopped while some jobs were given to the executor" warning: it
    comes when an idle worker times out (LOKY_IDLE_TIMEOUT_S) just as a batch arrives; loky
    starts a replacement and loses nothing, and a worker that really dies is found by its
    claim file and reported in its cell. Other warnings pass."""
    warnings.filterwarnings("ignore", message="A worker stopped while some jobs were given",
                            category=UserWarning)


def loky_batch(batch: Sequence[Task], n: int, accept) -> tuple[BaseException | None, list[Task]]:
    """Run `batch` on `n` loky workers. Returns (the pool's breakdown or None, unfinished tasks).

    Parameters
    ----------
    batch : sequence of Task
        The tasks.
    n : int
        Number of workers.
    accept : callable
        ``accept(task, outcome)``, called as outcomes arrive.

    Returns
    -------
    (BaseException or None, list of Task)
    """
    _quiet_loky()
    executor, futures = None, {}
    try:
        with workers_born_deaf():  # workers start in submit, or in the manager thread it starts
            executor = get_reusable_executor(max_workers=n, timeout=LOKY_IDLE_TIMEOUT_S,
                                             initializer=quiet_worker_signals)
            for t in batch:
                futures[executor.submit(execute, t.payload)] = t
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
                    accept(t, crash_outcome(t, f"could not run in a worker process: "
                                                f"{type(exc).__name__}: {exc}", kind="error"))
                else:
                    accept(t, fut.result())
    except BaseException:  # Ctrl-C, SIGTERM (the CLI raises Terminated), anything unexpected
        if executor is not None:
            _stop_pool(executor, futures)
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


def _stop_pool(executor: Any, futures: Mapping[Any, Task]) -> None:
    """Stop a loky pool at once after Ctrl-C or SIGTERM: further Ctrl-C/SIGTERM are ignored
    while it stops (the run is already ending), pending futures are cancelled, and the pool's
    manager thread, which can trip over the killed workers' queue (a KeyError in loky), is
    joined with its exception dropped: the user sees one line, `harness: interrupted`."""
    main = threading.current_thread() is threading.main_thread()
    saved = [(s, signal.signal(s, signal.SIG_IGN)) for s in (signal.SIGINT, signal.SIGTERM)] \
        if main else []
    hook = threading.excepthook
    threading.excepthook = lambda args: None if args.thread is not None and \
        args.thread.name.startswith("ExecutorManagerThread") else hook(args)
    try:
        for fut in futures:
            fut.cancel()
        executor.shutdown(wait=True, kill_workers=True)
    except Exception:  # noqa: BLE001  (stopping is best effort; the interruption is re-raised)
        pass
    finally:
        threading.excepthook = hook
        for sig, handler in saved:
            signal.signal(sig, handler)


def run_loky(tasks: Sequence[Task], jobs: int, accept) -> None:
    """Execute `tasks` on `jobs` local loky workers, handing each outcome to `accept` as it
    arrives; a crashed worker's cells are identified by their claim files (package docstring).

    Parameters
    ----------
    tasks : sequence of Task
        The tasks.
    jobs : int
        Number of workers.
    accept : callable
        ``accept(task, outcome)``, called once per task.
    """
    clean_stale_claims()
    claim_dir = tempfile.mkdtemp(prefix="harness-claims-")
    try:
        for t in tasks:
            t.payload["claim_dir"] = claim_dir
            t.payload["parent_pid"] = os.getpid()
            t.payload["hard_kill"] = True
            t.payload["hard_grace"] = max(limits.HARD_TIMEOUT_GRACE_S, 0.2 * (t.payload["timeout"] or 0))
        normal: list[Task] = list(tasks)
        suspects: list[Task] = []
        while normal or suspects:
            alone = not normal
            batch, normal = ([suspects.pop(0)], normal) if alone else (normal, [])
            broken, unfinished = loky_batch(batch, 1 if alone else min(jobs, len(batch)), accept)
            if broken is None:
                continue
            claims: dict[str, str] = {}
            for name in os.listdir(claim_dir):
                with contextlib.suppress(OSError):
                    claims[name] = Path(claim_dir, name).read_text(errors="replace")
                    os.unlink(os.path.join(claim_dir, name))
            codes = re.search(r"exit codes of the workers are (\{[^}]*\})", str(broken))
            reason = f"exit codes {codes.group(1)}" if codes else one_line(str(broken), 200)
            verdicts = {t.key: claim_verdict(claims[t.key]) for t in unfinished if t.key in claims}
            known_culprit = any(v is not None for v in verdicts.values())
            for t in unfinished:
                t.crash_rounds += 1
                verdict = verdicts.get(t.key)
                if verdict is not None:
                    accept(t, crash_outcome(t, verdict[1], verdict[0]))
                elif alone or t.crash_rounds >= MAX_CRASH_ROUNDS:
                    accept(t, crash_outcome(t, f"worker process died running this cell ({reason})"))
                elif t.key in claims and not known_culprit:
                    suspects.append(t)  # in flight when an unknown cell killed the pool
                elif verdicts:
                    normal.append(t)  # never started, or the victim of a known culprit
                else:
                    suspects.append(t)  # no claim at all tells who it was: try each alone
    finally:
        shutil.rmtree(claim_dir, ignore_errors=True)


def dask_client(scheduler: Any) -> tuple[Any, bool]:
    """(client, owned) for `scheduler` (an address or a client); `owned` says this call made it.

    Parameters
    ----------
    scheduler : str or Client
        An address or a connected client.

    Returns
    -------
    (Client, bool)
    """
    from distributed import Client

    if isinstance(scheduler, Client):
        return scheduler, False
    _handshake(scheduler)
    failure = None
    hook = sys.unraisablehook
    sys.unraisablehook = lambda unraisable: None  # a half-built Client's destructor complains
    try:
        try:
            client = Client(scheduler, timeout=f"{DASK_CONNECT_TIMEOUT_S}s", set_as_default=False)
        except Exception as exc:  # noqa: BLE001  (whatever the peer makes distributed raise)
            failure = f"{type(exc).__name__}: {one_line(str(exc), 200)}"
        if failure is not None:
            gc.collect()  # the half-built client goes now, while its complaint is silenced
    finally:
        sys.unraisablehook = hook
    if failure is not None:
        raise InputError(
            f"`scheduler` {scheduler!r}: cannot connect within {DASK_CONNECT_TIMEOUT_S} s ({failure})"
        )
    return client, True


def _handshake(address: str) -> None:
    """Check, within DASK_CONNECT_TIMEOUT_S in all, that `address` (tcp://HOST:PORT) answers as
    a Dask scheduler does on connection: its first message is a small length-prefixed msgpack
    handshake naming its Python and pickle protocol. A port that accepts and never answers, or
    answers with something else (an HTTP or SSH server), is one `InputError` line, before
    distributed reads a garbage length and tries to allocate it."""
    host, _, port = address.removeprefix("tcp://").rpartition(":")
    host = host.strip("[]")
    deadline = time.monotonic() + DASK_CONNECT_TIMEOUT_S
    where = f"`scheduler` {address!r}"
    try:
        port_number = int(port)
        with socket.create_connection((host, port_number), timeout=DASK_CONNECT_TIMEOUT_S) as so:
            data = b""
            while len(data) < 8 or len(data) < 8 + struct.unpack("<Q", data[:8])[0]:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError
                so.settimeout(left)
                chunk = so.recv(4096)
                if not chunk:
                    raise InputError(f"{where}: closed the connection without a Dask handshake")
                data += chunk
                if len(data) >= 8 and struct.unpack("<Q", data[:8])[0] > DASK_HANDSHAKE_MAX_BYTES:
                    break
    except InputError:
        raise
    except TimeoutError:
        raise InputError(f"{where}: no Dask handshake within {DASK_CONNECT_TIMEOUT_S} s (not a "
                         "Dask scheduler, or not reachable)") from None
    except (OSError, ValueError, OverflowError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise InputError(f"{where}: cannot connect "
                         f"({type(exc).__name__}: {one_line(reason, 200)})") from None
    size = struct.unpack("<Q", data[:8])[0]
    if size > DASK_HANDSHAKE_MAX_BYTES or b"pickle-protocol" not in data[8:8 + size]:
        raise InputError(f"{where}: answers, but not as a Dask scheduler (its first bytes: "
                         f"{data[:16]!r})")


def run_dask(tasks: Sequence[Task], client: Any, accept) -> None:
    """Execute `tasks` as Dask tasks on `client`, handing each outcome to `accept` as it completes.

    Parameters
    ----------
    tasks : sequence of Task
        The tasks.
    client : distributed.Client
        The connected client.
    accept : callable
        ``accept(task, outcome)``, called once per task.
    """
    from distributed import as_completed

    tag = uuid.uuid4().hex[:8]
    futures = {}
    try:
        for t in tasks:
            fut = client.submit(execute, t.payload, key=f"harness-cell-{t.key}-{tag}", pure=False)
            futures[fut] = t
        for fut in as_completed(list(futures), loop=client.loop):
            t = futures[fut]
            try:
                out = fut.result()
            except Exception as exc:  # KilledWorker, a lost connection, an unpicklable result
                out = crash_outcome(t, f"Dask task failed: {type(exc).__name__}: {exc}")
            accept(t, out)
    except KeyboardInterrupt:
        client.cancel(list(futures))
        raise


