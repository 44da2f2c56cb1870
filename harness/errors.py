"""Exceptions the harness raises on purpose. Each message names the argument and the rule."""

__all__ = [
    "HarnessError",
    "InputError",
    "CoefficientError",
    "UnknownNameError",
    "IncompatibleError",
    "PluginError",
    "ReferenceError_",
    "NoApplicableCellsError",
    "StepperOutputError",
    "WorkLimitError",
    "OutputError",
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


class StepperOutputError(HarnessError):
    """A stepper returned a state that is not a state: the wrong shape, or NaN made in one step
    from a finite, moderate state (a blow-up passes through large values and inf first)."""


class WorkLimitError(HarnessError):
    """A computation would exceed a stated work or time bound; the message names the bound and
    how to raise it."""


class OutputError(HarnessError):
    """Writing output failed for an ordinary OS reason (full disk, no permission, a file where a
    directory belongs, a closed pipe); the message names the path and the problem."""
