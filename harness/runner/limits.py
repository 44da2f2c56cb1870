"""Time limits of a cell: SIGALRM in a main thread, an abandoned helper thread elsewhere
(see the package docstring, `harness.runner`).
"""

from __future__ import annotations

import contextlib
import math
import signal
import threading
import time
from collections.abc import Callable
from typing import Any

from harness.errors import (
    HarnessError,
    InputError,
)

# After a soft time limit fails to stop a cell (stuck in compiled code), a loky worker is ended
# this many seconds later (at least), or a fifth of the limit when that is longer.
HARD_TIMEOUT_GRACE_S = 5.0
# Largest cell time limit accepted, seconds (a week).
MAX_CELL_TIMEOUT_S = 7 * 24 * 3600.0


class CellTimeout(BaseException):
    """A cell ran past its time limit (a BaseException so that `except Exception` in the cell's
    own code does not swallow it)."""


def _alarm_possible() -> bool:
    return hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def time_limit(seconds: float | None):
    """Raise `CellTimeout` in the body after `seconds` (SIGALRM; main thread only; None: no
    limit). A limit already running outside is restored afterwards.

    Parameters
    ----------
    seconds : float or None, the limit.

    Yields
    ------
    None
    """
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


def call_limited(fn: Callable[[], Any], seconds: float | None) -> Any:
    """fn() under a time limit: SIGALRM in a main thread, else an abandoned helper thread.

    Parameters
    ----------
    fn : callable, called with no arguments.
    seconds : float or None, the limit (None: none).

    Returns
    -------
    any: what `fn` returned; `CellTimeout` after `seconds`, and `fn`'s own exception re-raised.
    """
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



def check_timeout(value: Any) -> float | None:
    """`value` as a cell time limit in seconds (None: no limit), or `InputError` naming it.

    Parameters
    ----------
    value : any, seconds, positive, finite and at most MAX_CELL_TIMEOUT_S, or None.

    Returns
    -------
    float or None
    """
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


