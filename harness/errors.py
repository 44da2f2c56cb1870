"""Exceptions the harness raises on purpose. Each message names the argument and the rule."""

import errno
import os

__all__ = [
    "HarnessError",
    "InputError",
    "CoefficientError",
    "UnknownNameError",
    "IncompatibleError",
    "PluginError",
    "ReferenceError_",
    "NoApplicableCellsError",
    "ProblemError",
    "StepperOutputError",
    "WorkLimitError",
    "StiffReferenceError",
    "OutputError",
    "describe_os_error",
    "Terminated",
]


class HarnessError(Exception):
    """Base of every error the harness raises deliberately (the CLI prints it as one line)."""


class InputError(HarnessError, ValueError):
    """An argument breaks a stated rule (`h` must be positive, got -0.1)."""


class CoefficientError(HarnessError, ValueError):
    """A coefficient object failed its self-check on creation."""


class UnknownNameError(HarnessError, KeyError):
    """A stepper or problem name the registry does not know; the message lists the closest names."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class IncompatibleError(HarnessError, ValueError):
    """A stepper was asked for a form it cannot do (a Newtonian-only stepper on a first-order problem)."""


class PluginError(HarnessError):
    """A plugin file or entry point could not be loaded; the message names it."""


class ReferenceError_(HarnessError):
    """The ground truth could not be certified accurate enough for the comparison asked of it."""


class NoApplicableCellsError(HarnessError):
    """A run or gate over zero applicable cells: nothing was measured, so nothing may pass.
    `skips` holds one record per requested pair (experiment, stepper, problem, reason)."""

    def __init__(self, message: str, skips: list[dict] | None = None):
        super().__init__(message)
        self.skips = list(skips or [])


class ProblemError(HarnessError):
    """A problem's definition contradicts its own exact flow (a declared invariant the flow does
    not conserve, a singularity within its span): the problem is at fault, not a method run on
    it; its cells fail with this message instead of a verdict on the method."""


class StepperOutputError(HarnessError):
    """A stepper returned a state that is not a state: the wrong shape, or NaN made in one step
    from a finite, moderate state (a blow-up passes through large values and inf first)."""


class WorkLimitError(ReferenceError_):
    """A computation (a reference integration) would exceed a stated work or time bound; the
    message names the bound and how to raise it. A reference that cannot be computed within
    its bounds is a `ReferenceError_`."""


class StiffReferenceError(ReferenceError_):
    """The problem is stiff for the explicit Taylor reference: its step is held near p/(e |lambda|)
    by the Jacobian's eigenvalues, not by the solution's variation, so the span needs more steps
    than the reference's bound; the message names the eigenvalue and the steps."""


class OutputError(HarnessError, OSError):
    """Writing output failed for an ordinary OS reason (full disk, no permission, a file where a
    directory belongs, a closed pipe); the message names the path and the problem, and
    `exit_status` is the sysexits-style status the CLI exits with."""

    def __init__(self, message: str, exit_status: int = 74):
        super().__init__(message)
        self.exit_status = exit_status


def describe_os_error(exc: OSError, path: object = None) -> tuple[str, int]:
    """(one line naming the path and the problem, sysexits-style exit status) for an ordinary OS
    error: a file where a directory belongs or the reverse (73), a full disk or another I/O error
    (74), no permission (77), a closed pipe (141, as a SIGPIPE death would give).

    Parameters
    ----------
    exc : OSError, the error; path : the path meant, used when `exc` names none.

    Returns
    -------
    tuple (str, int): the message and the exit status.
    """
    where = exc.filename if exc.filename is not None else path
    where = os.fsdecode(where) if isinstance(where, bytes | os.PathLike) else where
    shown = repr(str(where)) if where is not None else "a file"
    reason = exc.strerror or (" ".join(str(exc.args[0]).split()) if exc.args else "")
    reason = reason or type(exc).__name__
    if isinstance(exc, BrokenPipeError) or exc.errno == errno.EPIPE:
        return f"{where or 'stdout'}: the reader closed the pipe; output cut short", 141
    if exc.errno in (errno.EEXIST, errno.ENOTDIR) and where is not None:
        blocker = _first_non_directory(str(where))
        return (f"{blocker!r} is a file where a directory belongs (needed for {str(where)!r}); "
                "move it away", 73)
    if exc.errno == errno.EISDIR:
        return f"{shown} is a directory where a file belongs ({reason})", 73
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return f"{shown}: no permission to write there ({reason})", 77
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return f"{shown}: no space left on the device (nothing half-written was kept)", 74
    return f"{shown}: {reason}", 74


def _first_non_directory(path: str) -> str:
    """The first component of `path` that exists and is not a directory (else `path`)."""
    parts = os.path.abspath(path).split(os.sep)
    for i in range(2, len(parts) + 1):
        head = os.sep.join(parts[:i])
        if os.path.lexists(head) and not os.path.isdir(head):
            return head
    return path


class Terminated(BaseException):  # noqa: N818 - a signal, like KeyboardInterrupt
    """SIGTERM, raised by the CLI's handler so that every `finally` runs (claim directories,
    worker pools, staging directories); never swallowed by a cell's failure handling."""
