"""Why a run went non-finite: a replay that tells a stepper's own NaN from a genuine blow-up.

`Stepper` inherits `NonfiniteReplay`; the replay steps the stepper's private math (`_start`,
`_advance`, `_checked_observe`) again, first in chunks and then one step at a time, to find the
first non-finite step and judge it (`made_nan`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from harness.errors import StepperOutputError

if TYPE_CHECKING:
    from harness.problem import Problem

__all__ = ["NAN_FROM_FINITE_LIMIT", "NonfiniteReplay", "made_nan"]

# A step that turns a finite state no larger than this into NaN (with no inf anywhere) is the
# stepper's fault, not a blow-up: overflow gives inf first, and NaN needs inf - inf, 0 * inf or
# 0 / 0 -- unless the step overflowed on the way (checked by replaying it with overflow trapped).
NAN_FROM_FINITE_LIMIT = 1e100
# A non-finite trajectory is replayed to find its first non-finite step: the run is cut into
# this many chunks first, then the failing chunk is stepped one step at a time.
_REPLAY_CHUNKS = 64


def made_nan(before: np.ndarray, after: np.ndarray) -> bool:
    """True when one step turned the finite, moderate state `before` into NaN in every member
    (at least one NaN per column) with no inf anywhere: not a blow-up (see
    NAN_FROM_FINITE_LIMIT).

    Parameters
    ----------
    before : ndarray, shape (dim, N), the state before the step.
    after : ndarray, shape (dim, N), the state after it.

    Returns
    -------
    bool
    """
    if not np.all(np.isfinite(before)) or np.any(np.isinf(after)):
        return False
    if before.size and np.max(np.abs(before)) > NAN_FROM_FINITE_LIMIT:
        return False
    return bool(after.size) and bool(np.all(np.any(np.isnan(after), axis=0)))


class NonfiniteReplay:
    """The replay of a non-finite run, mixed into `Stepper` (it uses the stepper's `_start`,
    `_advance`, `_checked_observe` and `info`)."""

    def _nan_error(self, step: int, before: np.ndarray) -> StepperOutputError:
        return StepperOutputError(
            f"stepper {self.info.name!r} turned a finite state (max |y| = "
            f"{float(np.max(np.abs(before), initial=0.0)):.3g}) into NaN in one step (step {step}); "
            "a blow-up passes through large values and inf first, so this is the stepper's fault"
        )

    def _explain_nonfinite(self, problem: Problem, h: float, t0: float, y: np.ndarray, pars,
                           upto: int, prefix=None) -> None:
        """Replay a run that ended non-finite within `upto` steps (after `prefix(dyn, c)` when
        given) and raise `StepperOutputError` when its first non-finite step made NaN from a
        finite, moderate state; return quietly for a genuine blow-up, and when the replay itself
        fails (an adaptive stepper stepped in other chunks may refuse a non-finite state): the
        run's own result, flagged non-finite, stands."""
        try:
            self._replay_nonfinite(problem, h, t0, y, pars, upto, prefix)
        except StepperOutputError:
            raise
        except Exception:  # the diagnosis is best effort; the measurement is already flagged
            return

    def _replay_nonfinite(self, problem, h, t0, y, pars, upto, prefix) -> None:
        shape = (problem.dim, y.shape[1])

        def fresh():
            dyn = problem.dynamics(pars, y.shape[1])
            c = self._start(dyn, t0, y.copy(), h)
            if prefix is not None:
                prefix(dyn, c)
            return dyn, c

        with np.errstate(all="ignore"):
            dyn, c = fresh()
            before = self._checked_observe(dyn, c, shape, "at the start")
            if prefix is None and made_nan(y, before):
                raise self._nan_error(0, y)
            chunk = max(1, -(-upto // _REPLAY_CHUNKS))
            done, start = 0, 0
            while done < upto:  # coarse pass: the first chunk that ends non-finite
                n = min(chunk, upto - done)
                self._advance(dyn, c, n)
                done += n
                if not np.all(np.isfinite(self._checked_observe(dyn, c, shape, f"after step {done}"))):
                    break
                start = done
            else:
                return
            dyn, c = fresh()
            if start:
                self._advance(dyn, c, start)
            before = self._checked_observe(dyn, c, shape, f"after step {start}")
            for k in range(start + 1, done + 1):  # fine pass through that chunk
                self._advance(dyn, c, 1)
                after = self._checked_observe(dyn, c, shape, f"after step {k}")
                if not np.all(np.isfinite(after)):
                    if made_nan(before, after) and not self._overflows(fresh, k):
                        raise self._nan_error(k, before)
                    return
                before = after

    def _overflows(self, fresh, k: int) -> bool:
        """True when step `k`, replayed with floating-point overflow trapped, overflows on the
        way: a large step (a high-order composition's substeps, a cubic force) can reach 1e308
        inside one step, and inf - inf then gives NaN with no inf in the state. A compiled loop
        traps nothing; it mirrors a NumPy loop that is checked itself, so it gets the benefit of
        the doubt."""
        if self.info.implementation == "compiled":
            return True
        dyn, c = fresh()
        with np.errstate(all="ignore"):
            if k > 1:
                self._advance(dyn, c, k - 1)
        for name in ("f", "accel"):  # a compiled right-hand side overflows without NumPy seeing it
            setattr(dyn, name, _inf_raises(getattr(dyn, name)))
        try:
            with np.errstate(over="raise", invalid="ignore", divide="ignore", under="ignore"):
                self._advance(dyn, c, 1)
        except FloatingPointError:
            return True
        return False


def _inf_raises(evaluate):
    """`evaluate` (a problem's f or acceleration), raising FloatingPointError when it returns inf:
    the problem's compiled function overflowed, which `np.errstate` cannot trap."""

    def checked(*args, **kwargs):
        out = evaluate(*args, **kwargs)
        if np.any(np.isinf(out)):
            raise FloatingPointError("overflow in the problem's compiled function")
        return out

    return checked
