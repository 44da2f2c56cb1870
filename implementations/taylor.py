"""heyoka's adaptive Taylor integrator as a stepper (`taylor`).

Each `_step` advances every ensemble member from t to t + h with heyoka's own adaptive steps
(variable order, tolerance `tol`, `high_accuracy=True`): F. Biscani & D. Izzo, Revisiting
high-order Taylor methods for astrodynamics and celestial mechanics, MNRAS 504 (2021) 2614-2628.
The integrator is compiled once per problem and tolerance (heyoka's on-disk cache under the
harness's cache directory) and reused: each member sets its own state, time and parameters.
"""

from __future__ import annotations

import copy
import dataclasses

import heyoka as hy
import numpy as np

from harness import cache
from harness.problem import Dynamics, Problem
from harness.stepper import AdaptiveStepper, Carry, StepFailure, Stepper, StepperInfo
from harness.tolerances import ADAPTIVE_MAX_EVALS, EPS
from implementations import ProblemCache

__all__ = ["TaylorStepper", "STEPPERS"]


class TaylorStepper(AdaptiveStepper):
    """heyoka `taylor_adaptive` advancing each member to the next output time.

    Counts the internal steps in `dyn.counts["internal_steps"]`: those of the member that took
    the most, so the count is a per-trajectory cost like a fixed-step method's step count (one
    internal step is one evaluation of the Taylor coefficients, the jet, of the right-hand side).
    """

    def __init__(self, tol: float = EPS, *, high_accuracy: bool = True):
        self.tol = float(tol)
        self.high_accuracy = high_accuracy
        self._templates = ProblemCache()  # key: (problem fingerprint, tol, high_accuracy)
        self.info = StepperInfo(
            name="taylor",
            family="taylor",
            claimed_order=None,
            explicit=True,
            symplectic=False,
            symmetric=False,
            evals_per_step=1.0,
            form="first-order",
            velocity_dependent=True,
            reference=(
                "F. Biscani & D. Izzo, Revisiting high-order Taylor methods for astrodynamics and "
                "celestial mechanics, MNRAS 504 (2021) 2614-2628 (heyoka)"
            ),
            description=(
                "heyoka adaptive Taylor integrator (variable order, tol = float64 epsilon by "
                "default, high_accuracy=True); evaluations are counted as internal steps, one "
                "Taylor-coefficient (jet) evaluation each"
            ),
            adaptive=True,
            implementation="heyoka",
            extra={"tol": self.tol, "evals_unit": "internal Taylor steps"},
        )

    def with_tolerance(self, tol: float) -> TaylorStepper:
        """A copy with tolerance `tol`, recorded in its `info.extra['tol']` too.

        Parameters
        ----------
        tol : float, a positive finite tolerance.

        Returns
        -------
        TaylorStepper: the copy.
        """
        clone = super().with_tolerance(tol)
        clone.info = dataclasses.replace(clone.info, extra={**clone.info.extra, "tol": clone.tol})
        return clone

    def _template(self, problem: Problem) -> hy.taylor_adaptive:
        def build() -> hy.taylor_adaptive:
            cache.configure_heyoka_cache()
            return hy.taylor_adaptive(
                list(zip(problem.variables, problem.rhs, strict=True)),
                problem.y0.tolist(),
                tol=self.tol,
                high_accuracy=self.high_accuracy,
                pars=problem.parameter_values.tolist(),
                compact_mode=cache.compact_mode(problem),  # compiles in ~1 s, not ~40 s, when large
            )

        return self._templates.get((problem.fingerprint(), self.tol, self.high_accuracy), build)

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = Carry(t0, h, y0)
        c.ta = copy.copy(self._template(dyn.problem))  # a private integrator for this run
        c.pars = dyn.pars
        c.counted_before = dyn.counts.setdefault("internal_steps", 0)
        c.member_steps = np.zeros(y0.shape[1], dtype=np.int64)
        return c

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        ta, y = c.ta, c.y
        t, target = c.t, c.t0 + (c.n + 1) * c.h
        has_pars = c.pars.size > 0
        for j in range(y.shape[1]):
            if not np.all(np.isfinite(y[:, j])):
                continue
            ta.time = t
            ta.state[:] = y[:, j]
            if has_pars:
                ta.pars[:] = c.pars[:, j]
            outcome, _, _, n_steps, *_ = ta.propagate_until(target, max_steps=ADAPTIVE_MAX_EVALS)
            c.member_steps[j] += n_steps
            if outcome == hy.taylor_outcome.time_limit:
                y[:, j] = ta.state
            elif outcome == hy.taylor_outcome.err_nf_state:
                y[:, j] = np.nan  # overflow: reported by the public methods as non-finite
            elif outcome == hy.taylor_outcome.step_limit:
                raise StepFailure(
                    f"stepper 'taylor': more than {ADAPTIVE_MAX_EVALS} internal steps for "
                    f"ensemble member {j} between t={t!r} and t={target!r} (stopped at "
                    f"t={float(ta.time)!r}); the span is too long for tol={self.tol:g}"
                )
            else:
                raise StepFailure(
                    f"stepper 'taylor': heyoka stopped at t={float(ta.time)!r} before "
                    f"t={target!r} with outcome {outcome}"
                )
        dyn.counts["internal_steps"] = c.counted_before + int(c.member_steps.max())


STEPPERS: list[Stepper] = [TaylorStepper()]
