"""pytest-benchmark micro-benchmarks: the compiled step loop of every family.

Each family's representative method (the one the C baseline also runs, `benchmarks._common.
FAMILY_C_LOOPS`) through its `@compiled` variant: 1000 Kepler steps (e = 0.6, h = 1e-3) of one
trajectory and of 1000 members, through the public `integrate` (the kernel is loaded or
compiled before timing). Checked against the exact solution and against the NumPy loop of the
same method. Disabled in the normal test run (each body runs once); timed by `make bench`.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks._common import FAMILY_C_LOOPS
from harness.registry import get_problem, get_stepper

STEPS, H = 1000, 1e-3
# 1000 steps of 1e-3 over a third of an e = 0.6 orbit: every method here is within 1e-4 of the
# exact orbit (the second-order ones by ~ (h^2 / 12) |a''| t ~ 1e-6 |a| t).
ACCURACY = 1e-4


@pytest.mark.parametrize("ensemble", [1, 1000], ids=["single", "ensemble1000"])
@pytest.mark.parametrize("family", list(FAMILY_C_LOOPS))
def test_compiled_family_loop(benchmark, family, ensemble):
    method, _ = FAMILY_C_LOOPS[family]
    problem = get_problem("kepler-elliptic")
    stepper = get_stepper(method + "@compiled")
    y0 = problem.ensemble(ensemble, seed=0)
    stepper.integrate(problem, h=H, n_steps=1, y0=y0)  # kernel compiled or loaded, untimed
    trajectory = benchmark(stepper.integrate, problem, h=H, n_steps=STEPS, y0=y0)
    exact = problem.exact(problem.t0 + STEPS * H, y0, problem.t0, None)
    assert trajectory.finite
    assert np.max(np.abs(trajectory.final - exact)) < ACCURACY
    numpy_run = get_stepper(method).integrate(problem, h=H, n_steps=STEPS, y0=y0)
    assert np.max(np.abs(trajectory.final - numpy_run.final)) < 1e-12
