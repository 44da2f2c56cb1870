"""The records a stepper works with: its claims (`StepperInfo`), its carry between steps (`Carry`),
what `integrate` returns (`Trajectory`), a failed step (`StepFailure`), and the checks of step
size, step count and stepper/problem compatibility."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from harness.errors import HarnessError, IncompatibleError, InputError
from harness.method_checks import check_claimed_order
from harness.names import check_name
from harness.problem import Problem
from harness.problem.checks import check_count, check_time

if TYPE_CHECKING:
    from harness.stepper import Stepper

__all__ = ["FORMS", "MAX_STEPS", "StepFailure", "WorkLimitFailure", "StepperInfo", "Carry", "Trajectory",
           "check_step_size", "check_steps", "check_compatible"]


FORMS = ("first-order", "newtonian")
MAX_STEPS = 100_000_000

class StepFailure(HarnessError):
    """A step could not be completed (an implicit stage solve did not converge)."""


class WorkLimitFailure(StepFailure):
    """The harness's own evaluation cap stopped a black box's solve (its projected cost is over
    the cap): the solver did not fail, the harness would not pay for the run."""


@dataclass(frozen=True)
class StepperInfo:
    """What a stepper claims about itself. Every field is reported beside its measurement."""

    name: str
    family: str
    claimed_order: int | None
    explicit: bool
    symplectic: bool
    symmetric: bool
    evals_per_step: float
    form: str
    velocity_dependent: bool
    reference: str
    description: str = ""
    adaptive: bool = False
    implementation: str = "numpy"
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        check_name(self.name, "stepper `name`")
        if self.form not in FORMS:
            raise InputError(f"stepper {self.name!r}: `form` must be one of {FORMS}, got {self.form!r}")
        check_claimed_order(self.claimed_order, f"stepper {self.name!r}: `claimed_order`",
                            optional=True)
        if not self.reference:
            raise InputError(f"stepper {self.name!r}: `reference` (literature source) is required")

    def as_dict(self) -> dict[str, Any]:
        """The claims as one flat dict (the `extra` entries merged in).

        Returns
        -------
        dict
        """
        d = asdict(self)
        d.update(d.pop("extra"))
        return d


class Carry:
    """What a stepper remembers between steps. `t` is derived from the step count, not summed."""

    __slots__ = ("t0", "h", "n", "y", "__dict__")

    def __init__(self, t0: float, h: float, y: np.ndarray, **extra: Any):
        self.t0 = t0
        self.h = h
        self.n = 0
        self.y = y
        self.__dict__.update(extra)

    @property
    def t(self) -> float:
        """The carry's current time, t0 + n h."""
        return self.t0 + self.n * self.h


@dataclass
class Trajectory:
    """States saved at chosen step indices: `y[k]` is the state (dim, N) after `steps[k]` steps."""

    stepper: str
    problem: str
    h: float
    steps: np.ndarray
    t: np.ndarray
    y: np.ndarray
    evals: dict
    wall_s: float
    finite: bool
    member_t: np.ndarray | None = None  # (saves, N) physical times when members' clocks differ

    @property
    def final(self) -> np.ndarray:
        """The state at the last output time, shaped (dim, N)."""
        return self.y[-1]


def check_step_size(h: Any) -> float:
    """`h` as a positive finite float, or `InputError` naming `h`.

    Parameters
    ----------
    h : any
        The step size.

    Returns
    -------
    float
    """
    x = check_time(h, "h")
    if x <= 0.0:
        raise InputError(f"`h` must be positive, got {x!r}")
    return x


def check_steps(n: Any, name: str = "n_steps") -> int:
    """`n` as a step count in [1, MAX_STEPS], or `InputError` naming `name`.

    Parameters
    ----------
    n : any
        The step count.
    name : str, optional
        The argument's name in the message (default "n_steps").

    Returns
    -------
    int
    """
    return check_count(n, f"`{name}`", MAX_STEPS)


def check_compatible(stepper: Stepper, problem: Problem) -> None:
    """Raise IncompatibleError when `stepper` cannot integrate `problem` (with the reason).

    Parameters
    ----------
    stepper : Stepper
        The stepper: its declared form and velocity dependence, and `incompatibility`.
    problem : Problem
        The problem.
    """
    info = stepper.info
    if info.form == "newtonian" and problem.newtonian is None:
        raise IncompatibleError(
            f"stepper {info.name!r} needs a Newtonian problem (q'' = a(q, t)); "
            f"problem {problem.name!r} is a first-order system"
        )
    if info.form == "newtonian" and problem.velocity_dependent and not info.velocity_dependent:
        raise IncompatibleError(
            f"stepper {info.name!r} needs an acceleration independent of velocity; "
            f"problem {problem.name!r} has a(q, v, t)"
        )
    reason = stepper.incompatibility(problem)
    if reason:
        raise IncompatibleError(f"stepper {info.name!r} cannot run problem {problem.name!r}: {reason}")
