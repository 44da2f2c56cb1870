"""A library's printed output kept off the command's stdout: `library_output_captured` collects
what a library (SUNDIALS through scikit-sundae) prints from C or Python while it runs, so its
warnings never land in a command's `--json` output and its reason for a failure reaches the
caller's one-line message instead."""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
import tempfile
import threading

__all__ = ["Captured", "library_output_captured"]

_redirect_lock = threading.Lock()
_redirect_depth = 0
_saved_stdout_fd: int | None = None
_capture_file = None


def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers, so text SUNDIALS wrote lands on the fd it was meant
    for before fd 1 is switched."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C library to ask (a platform without dlopen(NULL))
        pass


class Captured:
    """What a library printed inside `library_output_captured` (filled when the block ends)."""

    def __init__(self) -> None:
        self.text = ""

    def last_line(self) -> str:
        """The last non-empty line printed (SUNDIALS' reason for a failure), or ''.

        Returns
        -------
        str: the line, stripped.
        """
        lines = [ln.strip() for ln in self.text.splitlines() if ln.strip()]
        return lines[-1] if lines else ""


@contextlib.contextmanager
def library_output_captured():
    """Collect what a library prints to stdout while it runs, from C (stdio's buffer or straight
    to file descriptor 1) and from Python (`print` to `sys.stdout`, as scikit-sundae reports
    SUNDIALS' errors), so none of it lands in a command's output (`--json`) or between its
    lines; the caller folds it into its own message (`Captured.last_line`) or drops it.
    Nested blocks and threads share one capture: the outermost block collects the text.

    Returns
    -------
    A context manager yielding a `Captured`, whose `text` is set when the block ends.
    """
    global _redirect_depth, _saved_stdout_fd, _capture_file
    holder = Captured()
    with _redirect_lock:
        outer = _redirect_depth == 0
        if outer:
            try:
                sys.stdout.flush()
            except (OSError, ValueError):
                pass
            _flush_c_stdio()
            _capture_file = tempfile.TemporaryFile()
            _saved_stdout_fd = os.dup(1)
            os.dup2(_capture_file.fileno(), 1)
        _redirect_depth += 1
    python_text = io.StringIO()
    try:
        with contextlib.redirect_stdout(python_text):
            yield holder
    finally:
        with _redirect_lock:
            _redirect_depth -= 1
            c_text = ""
            if outer and _saved_stdout_fd is not None and _capture_file is not None:
                _flush_c_stdio()
                os.dup2(_saved_stdout_fd, 1)
                os.close(_saved_stdout_fd)
                _saved_stdout_fd = None
                _capture_file.seek(0)
                c_text = _capture_file.read().decode("utf-8", errors="replace")
                _capture_file.close()
                _capture_file = None
        holder.text = python_text.getvalue() + c_text
