"""Per-step cost of every registered stepper, its peak memory on ensembles, and its cost as a
ratio to the plain C loops measured in the same process.

`StepTime.time_step` times one steady-state step (after a warm-up step) of each stepper on
Kepler and the harmonic oscillator, for one trajectory and ensembles of 10^3 and 10^5 members
(scipy's steppers run one trajectory only, heyoka's Taylor stepper up to 10^3 members: see
`_common.MAX_ENSEMBLE`). asv reruns `setup` before every timed call, so each call starts from the
same state. `RatioToC.track_ratio_to_c` divides each stepper's time per trajectory-step on Kepler
by the C velocity-Verlet loop's at the same ensemble size: a machine-independent cost unit.
"""

from __future__ import annotations

import numpy as np

from ._common import (
    ENSEMBLES,
    PROBLEMS,
    STEP,
    c_seconds_per_step,
    check_ensemble,
    initial_states,
    lookup,
    prepared,
    stepper_names,
    stepper_seconds_per_step,
)


class StepTime:
    params = (stepper_names(), PROBLEMS, ENSEMBLES)
    param_names = ["stepper", "problem", "ensemble"]
    timeout = 300

    def setup(self, stepper, problem, ensemble):
        self.stepper, self.problem = lookup(stepper, problem)
        check_ensemble(self.stepper, ensemble)
        self.dyn, self.carry = prepared(self.stepper, self.problem, ensemble)

    def time_step(self, stepper, problem, ensemble):
        with np.errstate(all="ignore"):
            self.stepper._advance(self.dyn, self.carry, 1)


class EnsembleMemory:
    """Peak memory (resident set, whole process) of a 10-step ensemble run through the public
    `integrate`, which keeps the start and the end state."""

    params = (stepper_names(), [1_000, 100_000])
    param_names = ["stepper", "ensemble"]
    timeout = 300

    def setup(self, stepper, ensemble):
        self.stepper, self.problem = lookup(stepper, "kepler-elliptic")
        check_ensemble(self.stepper, ensemble)
        self.y0 = initial_states(self.problem, ensemble)

    def peakmem_integrate(self, stepper, ensemble):
        self.stepper.integrate(self.problem, h=STEP[self.problem.name], n_steps=10, y0=self.y0)


class RatioToC:
    """Seconds per trajectory-step on Kepler divided by the C velocity-Verlet loop's (`-O3`),
    both measured now, in this process (best of three calibrated runs each)."""

    params = (stepper_names(), ENSEMBLES)
    param_names = ["stepper", "ensemble"]
    unit = "x C velocity-Verlet step"
    timeout = 300

    def setup(self, stepper, ensemble):
        self.stepper, self.problem = lookup(stepper, "kepler-elliptic")
        check_ensemble(self.stepper, ensemble)
        self.c_step = c_seconds_per_step("vv", ensemble)

    def track_ratio_to_c(self, stepper, ensemble):
        return stepper_seconds_per_step(self.stepper, self.problem, ensemble) / self.c_step
