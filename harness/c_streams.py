"""A library's C-level stdout kept off the command's stdout: `c_stdout_to_stderr` points file
descriptor 1 at stderr while a C library (SUNDIALS) runs, so its warnings never land in a
command's `--json` output."""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading

__all__ = ["c_stdout_to_stderr"]

_redirect_lock = threading.Lock()
_redirect_depth = 0
_saved_stdout_fd: int | None = None


def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers, so text SUNDIALS wrote lands on the fd it was meant
    for before fd 1 is switched."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C library to ask (a platform without dlopen(NULL))
        pass


@contextlib.contextmanager
def c_stdout_to_stderr():
    """Point file descriptor 1 at stderr while CVODE runs: SUNDIALS writes its warnings with C
    stdio to stdout, where they would land before a command's `--json` output. Python's own
    `sys.stdout` is not touched; nesting and threads share one redirection."""
    global _redirect_depth, _saved_stdout_fd
    with _redirect_lock:
        if _redirect_depth == 0:
            try:
                sys.stdout.flush()
            except (OSError, ValueError):
                pass
            _flush_c_stdio()
            _saved_stdout_fd = os.dup(1)
            os.dup2(2, 1)
        _redirect_depth += 1
    try:
        yield
    finally:
        with _redirect_lock:
            _redirect_depth -= 1
            if _redirect_depth == 0 and _saved_stdout_fd is not None:
                _flush_c_stdio()
                os.dup2(_saved_stdout_fd, 1)
                os.close(_saved_stdout_fd)
                _saved_stdout_fd = None
