"""An implicit multistep table whose explicit starter would step outside its real stability
interval (h x the fastest decay rate at y_0 beyond it: a stiff problem at a coarse step) takes its
starting values from the certified reference instead; inside the interval the starter runs as
declared. Swept over the implicit tables of the registry on y' = -lambda (y - 1), whose exact
solution 1 - e^(-lambda t) makes a blown-up start visible."""

from __future__ import annotations

import heyoka as hy
import numpy as np
import pytest

from harness.facts import method_facts
from harness.problem import Problem
from harness.registry import get_stepper, steppers
from implementations.multistep import LinearMultistepStepper

RATE = 1e4
_y = hy.make_vars("y")
DECAY = Problem("stiff-linear-decay", variables=[_y], rhs=[-RATE * (_y - 1.0)], y0=[0.0],
                t_span=(0.0, 0.01), reference="y' = -1e4 (y - 1), y = 1 - exp(-1e4 t)")
IMPLICIT = [s for s in steppers.all() if isinstance(s, LinearMultistepStepper)
            and not s.coefficients.explicit and s.coefficients.steps > 1]


@pytest.mark.parametrize("stepper", IMPLICIT, ids=[s.info.name for s in IMPLICIT])
def test_an_unstable_explicit_start_is_replaced_by_the_reference(stepper):
    interval = method_facts(get_stepper(stepper.starter_name)).real_interval
    assert IMPLICIT and np.isfinite(interval)
    coarse = 4 * interval / RATE  # h lambda = 4 x the starter's interval: unstable there
    run = stepper.integrate(DECAY, h=coarse, n_steps=stepper.coefficients.steps - 1)
    assert run.evals.get("reference_start") == 1
    exact = 1.0 - np.exp(-RATE * coarse * (stepper.coefficients.steps - 1))
    assert abs(run.y[-1][0, 0] - exact) < 1e-10  # the starter alone would be off by ~R(-4 x)^1 > 1
    fine = interval / (2 * RATE)  # inside the interval: the declared starter
    run = stepper.integrate(DECAY, h=fine, n_steps=stepper.coefficients.steps - 1)
    assert "reference_start" not in run.evals
