"""The command line's one output layer: the collected stdout of a command, its writing at the end,
one-line errors with sysexits-style statuses (JSON and table printing: `harness.cli.tables`). (A
compiled library's C-level stdout is kept off the command's stdout by `harness.c_streams`.)"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import unicodedata

from harness.errors import describe_os_error

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2
EXIT_CANTCREAT, EXIT_IOERR, EXIT_NOPERM, EXIT_PIPE = 73, 74, 77, 141
EXIT_NOT_VERIFIED = 3  # the gate: no claim contradicted, but one was measured on no cell
# A run's footer lists at most this many pairs that do not apply (all are in the saved run).
SHOWN_SKIPS = 10

# The command's stdout while it runs (see the module docstring); `print(..., file=output_buffer())`.
OUTPUT: list[io.StringIO] = []


def output_buffer() -> io.StringIO:
    """The buffer collecting the running command's output (written to stdout at the end).

    Returns
    -------
    io.StringIO
    """
    if not OUTPUT:
        OUTPUT.append(io.StringIO())
    return OUTPUT[-1]


def report_error(message: str, code: int) -> int:
    """Print `message` as one error line on stderr and return `code`.

    Parameters
    ----------
    message : str, the message (put on one line).
    code : int, the exit status.

    Returns
    -------
    int: `code`.
    """
    print(f"harness: error: {one_line(message)}", file=sys.stderr)
    return code


def os_error_status(exc: OSError) -> tuple[str, int]:
    """(one-line message, exit status) for an OS error (`harness.errors.describe_os_error`).

    Parameters
    ----------
    exc : OSError, the error.

    Returns
    -------
    (str, int)
    """
    return describe_os_error(exc)


def _stdout_name() -> str:
    try:
        target = os.readlink(f"/proc/self/fd/{sys.stdout.fileno()}")
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        return "stdout"
    return f"stdout ({target})" if target.startswith("/") else "stdout"


def write_stdout(text: str) -> int:
    """Write the command's output and flush it; an OS error becomes one line on stderr.

    Parameters
    ----------
    text : str, the output (control characters escaped).

    Returns
    -------
    int: EXIT_OK, or the OS error's exit status.
    """
    try:
        if text:
            sys.stdout.write(escape_controls(text))
        sys.stdout.flush()
    except OSError as exc:
        exc.filename = _stdout_name()
        _silence_stdout()
        return report_error(*os_error_status(exc))
    return EXIT_OK


def _silence_stdout() -> None:
    """After a failed write, point the real stdout at /dev/null so the interpreter's own flush
    at exit does not print a second error (only for the process's real stdout)."""
    if sys.stdout is not sys.__stdout__:
        return
    with contextlib.suppress(OSError, ValueError, AttributeError, io.UnsupportedOperation):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def one_line(text: str) -> str:
    """`text` on one line, whitespace collapsed, control characters escaped, cut to 500
    characters.

    Parameters
    ----------
    text : str, the text.

    Returns
    -------
    str
    """
    line = escape_controls(" ".join(text.split()))
    return line if len(line) <= 500 else line[:497] + "..."


_KEPT = {"\n", "\t", "\r"}  # \r: a progress bar redraws its line


def escape_controls(text: str) -> str:
    """`text` with every control or format character but newline, tab and carriage return
    written as its escape (``, `‮`): a name or message from a plugin or a
    saved run can never move the cursor, recolour, retitle or reorder the user's terminal.

    Parameters
    ----------
    text : str

    Returns
    -------
    str: `text` itself when it has nothing to escape.
    """
    if text.isprintable() or all(c in _KEPT or c.isprintable() or c == " " for c in text):
        return text
    out = []
    for c in text:
        if c in _KEPT or unicodedata.category(c) not in ("Cc", "Cf", "Cs", "Co", "Zl", "Zp"):
            out.append(c)
        else:
            out.append(repr(c)[1:-1])
    return "".join(out)


class EscapingStream(io.TextIOBase):
    """A text stream writing to `target` with control characters escaped (`escape_controls`):
    the command's chatter (stdout redirected to stderr while it runs) and stderr pass through it."""

    def __init__(self, target):
        self._target = target

    def write(self, text: str) -> int:
        """Write `text` to the target stream with control characters escaped.

        Parameters
        ----------
        text : str (any characters).

        Returns
        -------
        int: len(text), as `io.TextIOBase.write` counts what it was given.
        """
        self._target.write(escape_controls(text))
        return len(text)

    def flush(self) -> None:
        """Flush the target stream."""
        self._target.flush()

    def isatty(self) -> bool:
        """Returns
        -------
        bool
            Whether the target stream is a terminal.
        """
        return bool(getattr(self._target, "isatty", lambda: False)())

    def fileno(self) -> int:
        """Returns
        -------
        int
            The target stream's file descriptor.
        """
        return self._target.fileno()

    def writable(self) -> bool:
        """Returns
        -------
        bool
            True.
        """
        return True
