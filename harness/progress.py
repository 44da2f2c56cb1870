"""Progress of a run: a tqdm bar on a terminal, sparse plain lines in logs.

`Progress(total, desc)` picks its style from where it writes (`mode='auto'`): a tqdm bar when
the stream is a terminal and the `CI` environment variable is unset; otherwise plain lines such
as ``convergence: 12/40 cells (30%), 8.1 s elapsed, 1 failed`` — one when another tenth of the
cells is done (at most one per second) or when `interval` seconds passed since the last line,
and a final one on `close()`. Plain lines never contain carriage returns.
"""

from __future__ import annotations

import os
import sys
import time
from typing import IO, Any

from tqdm.auto import tqdm

from harness.errors import InputError

__all__ = ["Progress", "choose_mode", "MODES"]

MODES = ("auto", "bar", "lines", "off")

# Plain-line mode: the longest silence between lines, and the shortest gap between two lines
# written for reaching another tenth of the cells.
LINE_INTERVAL_S = 10.0
LINE_MIN_GAP_S = 1.0


def choose_mode(stream: IO[str] | None = None) -> str:
    """'bar' on an interactive terminal outside CI, else 'lines'.

    Parameters
    ----------
    stream : the text stream progress is written to (default: standard error).

    Returns
    -------
    str: 'bar' or 'lines'.
    """
    stream = sys.stderr if stream is None else stream
    try:
        tty = bool(stream.isatty())
    except (AttributeError, ValueError):
        tty = False
    return "bar" if tty and not os.environ.get("CI") else "lines"


class Progress:
    """Counts finished cells (`update`) of a run whose size may grow (`add_total`)."""

    def __init__(
        self,
        total: int = 0,
        desc: str = "cells",
        *,
        stream: IO[str] | None = None,
        mode: str = "auto",
        interval: float = LINE_INTERVAL_S,
    ):
        if mode not in MODES:
            raise InputError(f"`mode` must be one of {', '.join(MODES)}, got {mode!r}")
        if isinstance(total, bool) or not isinstance(total, int) or total < 0:
            raise InputError(f"`total` must be a whole number >= 0, got {total!r}")
        self.stream = sys.stderr if stream is None else stream
        self.mode = choose_mode(self.stream) if mode == "auto" else mode
        self.desc = str(desc)
        self.total = total
        self.done = 0
        self.failed = 0
        self.cached = 0
        self.interval = float(interval)
        self.started = time.monotonic()
        self._last_line = -float("inf")
        self._last_tenth = 0
        self._last_done = -1
        self._closed = False
        self._bar: Any = None
        if self.mode == "bar":
            self._bar = tqdm(total=total, desc=self.desc, file=self.stream, unit="cell",
                             mininterval=0.2, dynamic_ncols=True, leave=True)

    # -- counting ---------------------------------------------------------------------------------
    def add_total(self, n: int) -> None:
        """Announce `n` more cells (a run over several experiments grows as each is listed).

        Parameters
        ----------
        n : int, the number of cells added.
        """
        self.total += int(n)
        if self._bar is not None:
            self._bar.total = self.total
            self._bar.refresh()

    def set_description(self, desc: str) -> None:
        """Set the label shown before the counts.

        Parameters
        ----------
        desc : str, the label.
        """
        self.desc = str(desc)
        if self._bar is not None:
            self._bar.set_description_str(self.desc)

    def update(self, n: int = 1, *, failed: int = 0, cached: int = 0) -> None:
        """`n` more cells finished, of which `failed` failed and `cached` came from the cache.

        Parameters
        ----------
        n : int, cells finished; failed : int, of them failed; cached : int, of them taken from the
        cache.
        """
        self.done += int(n)
        self.failed += int(failed)
        self.cached += int(cached)
        if self._bar is not None:
            if failed or self.failed:
                self._bar.set_postfix_str(f"{self.failed} failed", refresh=False)
            self._bar.update(n)
        elif self.mode == "lines":
            self._maybe_line()

    # -- plain lines ------------------------------------------------------------------------------
    def line(self) -> str:
        """The progress as one line of text.

        Returns
        -------
        str: label, cells done of the total (and percent), seconds elapsed, failures, cached cells.
        """
        elapsed = time.monotonic() - self.started
        pct = f" ({100.0 * self.done / self.total:.0f}%)" if self.total else ""
        extra = f", {self.cached} cached" if self.cached else ""
        return (f"{self.desc}: {self.done}/{self.total} cells{pct}, {elapsed:.1f} s elapsed, "
                f"{self.failed} failed{extra}")

    def _write(self) -> None:
        self.stream.write(self.line() + "\n")
        self.stream.flush()
        self._last_line = time.monotonic()
        self._last_done = self.done

    def _maybe_line(self) -> None:
        now = time.monotonic()
        tenth = (10 * self.done) // self.total if self.total else 0
        if now - self._last_line >= self.interval or (
            tenth > self._last_tenth and now - self._last_line >= LINE_MIN_GAP_S
        ):
            self._last_tenth = tenth
            self._write()

    # -- ending -----------------------------------------------------------------------------------
    def close(self) -> None:
        """Close the bar, or write the last line when it is not written yet; a second call does nothing."""
        if self._closed:
            return
        self._closed = True
        if self._bar is not None:
            self._bar.close()
        elif self.mode == "lines" and self._last_done != self.done:
            self._write()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
