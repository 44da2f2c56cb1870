"""How to step: the contract every stepper follows, and the bookkeeping they share.

Contract for a stepper (a subclass of `Stepper`):
1. It declares `info: StepperInfo` — name, family, claimed order, explicit/implicit, symplectic,
   symmetric, evaluations per step, the form it needs, whether it accepts velocity-dependent
   accelerations, and a literature reference. Claims are data; experiments compare them with
   measurements.
2. It advances an ensemble: states are shaped (dim, N), ensemble axis last; one call moves all
   N members together. It never modifies the caller's arrays.
3. It implements the private math only: `_start(dyn, t0, y0, h)` builds a carry (whatever the
   method remembers between steps), `_step(dyn, c)` advances the carry by one step in place,
   `_observe(dyn, c)` returns the physical state (dim, N) at the carry's time as a new array.
   `_reverse(dyn, c)` turns time around (default: h -> -h; multistep and staggered families
   also reorder their history).
4. It evaluates the problem only through `dyn` (a `harness.problem.Dynamics`), which counts
   right-hand-side, force and Jacobian evaluations.
5. It signals a failed step (an implicit solve that does not converge) by raising `StepFailure`;
   it never returns an unconverged state silently. Overflow produces inf/NaN, which the public
   methods detect and report (a blow-up is a measurement). `_observe` returns a real array
   shaped (dim, N); anything else, or NaN made in one step from a finite state far from overflow
   (a blow-up passes through large values and inf first), raises `StepperOutputError`: the cell
   fails instead of reading as "unstable" or being broadcast into a state.
6. It is registered in `implementations/__init__.py` (or through the `harness.steppers` entry
   point); `coefficients` holds its data object when it has one.
Public methods (`integrate`, `round_trip`) check their input and keep the books.

This module holds the `Stepper` base class; `records` holds the records and checks it uses.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any

import numpy as np

from harness.errors import IncompatibleError, InputError, StepperOutputError
from harness.problem import Dynamics, Problem, check_state, check_time
from harness.problem.checks import check_positive
from harness.sources import source_of
from harness.stepper.records import (
    FORMS,
    MAX_STEPS,
    Carry,
    StepFailure,
    StepperInfo,
    Trajectory,
    WorkLimitFailure,
    check_compatible,
    check_step_size,
    check_steps,
)
from harness.stepper.replay import NonfiniteReplay, made_nan

__all__ = [
    "StepperInfo",
    "Stepper",
    "Carry",
    "Trajectory",
    "StepFailure",
    "WorkLimitFailure",
    "check_compatible",
    "check_step_size",
    "check_steps",
    "FORMS",
    "MAX_STEPS",
    "AdaptiveStepper",
    "StepperOutputError",
]

class Stepper(NonfiniteReplay, ABC):
    """Base class: see the module docstring for the numbered contract."""

    info: StepperInfo
    coefficients: Any = None

    # -- optional hooks --------------------------------------------------------------------------
    def incompatibility(self, problem: Problem) -> str | None:
        """A reason this stepper cannot run `problem` beyond the declared form, or None.

        Parameters
        ----------
        problem : Problem, checked already against the declared form (`check_compatible`)

        Returns
        -------
        str or None: the reason (this base class has none; subclasses may).
        """
        return None

    def compatible(self, problem: Problem) -> bool:
        """True when this stepper can integrate `problem` (see `check_compatible`).

        Parameters
        ----------
        problem : Problem, any registered or user problem

        Returns
        -------
        bool
        """
        try:
            check_compatible(self, problem)
        except IncompatibleError:
            return False
        return True

    def reference_times(self, problem: Problem, t0: float, y0: np.ndarray, h: float) -> np.ndarray:
        """The times at which a run of `problem` from `y0` at step `h` reads the ground truth
        (starting values taken from it), so a caller about to run many step sizes can have the
        reference computed at all of them in one call; none for this base class.

        Parameters
        ----------
        problem : Problem; t0 : float, the start time; y0 : ndarray (dim, N), the start states;
        h : float, the step.

        Returns
        -------
        ndarray: the times, increasing (empty when the run does not read the reference).
        """
        return np.empty(0)

    def fingerprint(self) -> str:
        """Changes whenever the method changes: its coefficients and its class's source.

        Returns
        -------
        str
            The record's name and claims, the coefficients' fingerprint (if any) and the source of
            every class of the stepper below `Stepper`.
        """
        parts = [self.info.name, repr(sorted(self.info.as_dict().items()))]
        if self.coefficients is not None and hasattr(self.coefficients, "fingerprint"):
            parts.append(self.coefficients.fingerprint())
        for cls in type(self).__mro__:
            if cls in (object, ABC, Stepper, NonfiniteReplay):
                continue
            try:
                parts.append(source_of(cls))
            except (OSError, TypeError):
                parts.append(cls.__qualname__)
        return "\n".join(parts)

    # -- private math ----------------------------------------------------------------------------
    @abstractmethod
    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry: ...

    @abstractmethod
    def _step(self, dyn: Dynamics, c: Carry) -> None: ...

    def _observe(self, dyn: Dynamics, c: Carry) -> np.ndarray:
        return c.y.copy()

    #: How many past states the method's recurrence uses (1 for one-step methods).
    history_length: int = 1

    def _start_from_history(self, dyn: Dynamics, t0: float, h: float, history: list) -> Carry:
        """A carry at t0 + (k-1)h from exact states at t0, t0+h, ..., t0+(k-1)h (k =
        `history_length`), so the local error of the recurrence itself can be measured.
        One-step methods use the last state only; multistep families override this."""
        k = len(history)
        c = self._start(dyn, t0 + (k - 1) * h, history[-1], h)
        return c

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        c.t0 = c.t
        c.n = 0
        c.h = -c.h

    def _time(self, c: Carry) -> np.ndarray | None:
        """Physical time of each member (N,) when it is not t0 + n h (step-controlled
        steppers, whose h is a control parameter); None for uniform steps."""
        return None

    def _advance(self, dyn: Dynamics, c: Carry, n: int) -> None:
        step = self._step
        for _ in range(n):
            step(dyn, c)
            c.n += 1

    # -- checking what the private math returns --------------------------------------------------
    def _checked_observe(self, dyn: Dynamics, c: Carry, shape: tuple[int, int], when: str) -> np.ndarray:
        """`_observe` checked: a real array of `shape` (dim, N), never a scalar to broadcast."""
        y = self._observe(dyn, c)
        if not isinstance(y, np.ndarray) or y.shape != shape:
            got = f"shape {y.shape}" if isinstance(y, np.ndarray) else type(y).__name__
            raise StepperOutputError(
                f"stepper {self.info.name!r} returned a state of {got} {when}; expected an array "
                f"of shape {shape} (dim, ensemble)"
            )
        if not (np.issubdtype(y.dtype, np.floating) or np.issubdtype(y.dtype, np.integer)):
            raise StepperOutputError(
                f"stepper {self.info.name!r} returned a state of dtype {y.dtype} {when}; expected "
                "real numbers"
            )
        return y

    # -- public API ------------------------------------------------------------------------------
    def _prepare(self, problem, h, y0, t0, pars):
        if not isinstance(problem, Problem):
            raise InputError(f"`problem` must be a Problem, got {type(problem).__name__}")
        check_compatible(self, problem)
        h = check_step_size(h)
        t0 = problem.t0 if t0 is None else check_time(t0, "t0")
        y = check_state(problem.y0 if y0 is None else y0, problem.dim, "y0")
        dyn = problem.dynamics(pars, y.shape[1])
        return h, t0, y, dyn

    def integrate(
        self,
        problem: Problem,
        *,
        h: float,
        n_steps: int,
        y0: np.ndarray | None = None,
        t0: float | None = None,
        pars: np.ndarray | None = None,
        save_steps: Sequence[int] | None = None,
    ) -> Trajectory:
        """Advance `n_steps` steps of size `h` from (t0, y0); save the state at `save_steps`
        (step indices, 0..n_steps; default: the start and the end).

        Parameters
        ----------
        problem : Problem
            The problem (compatible with this stepper).
        h : float
            Step size, positive and finite.
        n_steps : int
            Number of steps, 1 to MAX_STEPS.
        y0 : array_like, optional
            Initial states, (dim,) or (dim, N) (default the problem's start).
        t0 : float, optional
            Initial time (default the problem's).
        pars : ndarray, optional
            Parameter values, as in `Problem.pars_for`.
        save_steps : sequence of int, optional
            Step indices to save.

        Returns
        -------
        Trajectory
            The saved states, times, evaluation counts and wall time; `finite` False when a state
            went non-finite (`StepperOutputError` when the stepper itself made a NaN).
        """
        h, t0, y, dyn = self._prepare(problem, h, y0, t0, pars)
        n_steps = check_steps(n_steps)
        if save_steps is None:
            save = np.array([0, n_steps])
        else:
            try:
                save = np.unique(np.asarray(save_steps, dtype=np.int64))
            except (TypeError, ValueError, OverflowError):
                raise InputError(
                    f"`save_steps` must be whole step indices, got {save_steps!r}"
                ) from None
            if save.size == 0 or save[0] < 0 or save[-1] > n_steps:
                raise InputError(f"`save_steps` must lie in [0, {n_steps}], got {save_steps!r}")
        shape = (problem.dim, y.shape[1])
        out = np.empty((save.size, *shape))
        member_t = np.repeat((t0 + save * h)[:, None], y.shape[1], axis=1)
        clocks = False
        finite = True
        started = time.perf_counter()
        with np.errstate(all="ignore"):
            c = self._start(dyn, t0, y.copy(), h)
            done = 0
            for k, target in enumerate(save):
                if target > done:
                    self._advance(dyn, c, int(target - done))
                    done = int(target)
                out[k] = self._checked_observe(dyn, c, shape, f"after step {done}")
                own = self._time(c)
                if own is not None:
                    member_t[k], clocks = own, True
                if not np.all(np.isfinite(out[k])):
                    finite = False
                    out[k + 1 :] = np.nan
                    break
        wall = time.perf_counter() - started
        if not finite:
            self._explain_nonfinite(problem, h, t0, y, pars, done)
        return Trajectory(
            stepper=self.info.name,
            problem=problem.name,
            h=h,
            steps=save,
            t=member_t[:, 0] if clocks else t0 + save * h,
            y=out,
            evals=dict(dyn.counts),
            wall_s=wall,
            finite=finite,
            member_t=member_t if clocks else None,
        )

    def round_trip(
        self,
        problem: Problem,
        *,
        h: float,
        n_steps: int,
        y0: np.ndarray | None = None,
        t0: float | None = None,
        pars: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """`n_steps` forward, time reversed (h -> -h), `n_steps` back. Returns (start, returned).

        Parameters
        ----------
        problem, h, n_steps, y0, t0, pars
            As in `integrate`.

        Returns
        -------
        (ndarray, ndarray)
            The observed start and the state after the way back, each shaped (dim, N).
        """
        h, t0, y, dyn = self._prepare(problem, h, y0, t0, pars)
        n_steps = check_steps(n_steps)
        shape = (problem.dim, y.shape[1])
        with np.errstate(all="ignore"):
            c = self._start(dyn, t0, y.copy(), h)
            start = self._checked_observe(dyn, c, shape, "at the start")
            self._advance(dyn, c, n_steps)
            self._reverse(dyn, c)
            self._advance(dyn, c, n_steps)
            back = self._checked_observe(dyn, c, shape, "after the round trip")
        if not (np.all(np.isfinite(start)) and np.all(np.isfinite(back))):
            self._explain_nonfinite(problem, h, t0, y, pars, n_steps)

            def forward(dyn, c):
                self._advance(dyn, c, n_steps)
                self._reverse(dyn, c)

            self._explain_nonfinite(problem, h, t0, y, pars, n_steps, prefix=forward)
        return start, back

    def first_steps(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float, count: int) -> list[np.ndarray]:
        """The states after each of the first `count` steps from (t0, y0), observed as
        `integrate` would (a multistep method's starting values come from here).

        Parameters
        ----------
        dyn : the run's dynamics (its counters book the evaluations).
        t0, y0, h : start time, start state (dim, N), step size.
        count : how many steps.

        Returns
        -------
        A list of `count` states, each (dim, N).
        """
        c = self._start(dyn, t0, y0.copy(), h)
        states = []
        for _ in range(count):
            self._step(dyn, c)
            c.n += 1
            states.append(self._observe(dyn, c))
        return states

    def step_from_history(
        self,
        problem: Problem,
        *,
        h: float,
        history: Sequence[np.ndarray],
        t0: float | None = None,
        pars: np.ndarray | None = None,
    ) -> np.ndarray:
        """One step of the recurrence from exact past states (oldest first; `history_length`
        of them at t0, t0+h, ...). Returns the state after that step: its difference from the
        exact state is the method's local error.

        Parameters
        ----------
        problem : Problem
            The problem.
        h : float
            Step size.
        history : sequence of ndarray
            `history_length` states, each (dim,) or (dim, N).
        t0 : float, optional
            Time of the oldest state (default the problem's start time).
        pars : ndarray, optional
            Parameter values, as in `Problem.pars_for`.

        Returns
        -------
        ndarray, shape (dim, N)
            The state at t0 + history_length h.
        """
        h = check_step_size(h)
        if not isinstance(problem, Problem):
            raise InputError(f"`problem` must be a Problem, got {type(problem).__name__}")
        check_compatible(self, problem)
        t0 = problem.t0 if t0 is None else check_time(t0, "t0")
        if len(history) != self.history_length:
            raise InputError(
                f"`history` must hold {self.history_length} states for {self.info.name!r}, "
                f"got {len(history)}"
            )
        states = [check_state(y, problem.dim, "history") for y in history]
        dyn = problem.dynamics(pars, states[0].shape[1])
        with np.errstate(all="ignore"):
            c = self._start_from_history(dyn, t0, h, [y.copy() for y in states])
            self._step(dyn, c)
            c.n += 1
            after = self._checked_observe(dyn, c, states[-1].shape, "after one step from history")
        if made_nan(np.stack(states), after):
            raise self._nan_error(1, np.stack(states))
        return after

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.info.name!r}>"


class AdaptiveStepper(Stepper):
    """A stepper that chooses its own internal steps to meet a tolerance.

    Adds to the contract:
    7. `tol` is the requested tolerance; `with_tolerance(tol)` returns a copy at another one.
    8. `_step` advances exactly to the next output time t + h with internal adaptive steps and
       adds the internal steps it took to `dyn.counts["internal_steps"]`.
    Experiments measure adaptive steppers by tolerance sweeps (error and cost against `tol`),
    not by step-size sweeps; `info.claimed_order` may be None (variable order).
    """

    tol: float = 1e-10

    def with_tolerance(self, tol: float) -> AdaptiveStepper:
        """A copy of this stepper with tolerance `tol` (a positive finite number).

        Parameters
        ----------
        tol : float
            The tolerance.

        Returns
        -------
        AdaptiveStepper
            A shallow copy with `tol` set (and its record's `extra` updated by `extra_info`).
        """
        tol = check_positive(tol, "`tol`")
        clone = copy.copy(self)
        clone.tol = tol
        extra = clone.extra_info()
        if extra is not None:
            clone.info = dataclasses.replace(clone.info, extra=extra)
        return clone

    def extra_info(self) -> dict | None:
        """The record's `extra` entries at this stepper's tolerance, or None to keep them as
        they are; `with_tolerance` puts them on the copy's record.

        Returns
        -------
        dict or None
        """
        return None
