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


def test_the_c_family_loops_compute_the_harness_methods():
    """The C loops the family ratios divide by run the same methods: 1000 Kepler steps of each
    from the same start agree with the harness's compiled stepper (states at step 1000; the
    implicit midpoint's and AB4's to the Newton tolerance and the starting values' accuracy)."""
    from benchmarks._common import c_family_state
    from benchmarks.c_baseline.build import CompilerUnavailable, load

    try:
        baseline = load()
    except CompilerUnavailable as exc:
        pytest.skip(f"no C compiler on this machine: {exc}")
    problem = get_problem("kepler-elliptic")
    n = 1000
    for family, (method, c_method) in FAMILY_C_LOOPS.items():
        stepper = get_stepper(method + "@compiled")
        if c_method == "stormer":  # the harness's Taylor start gives x_1
            y0 = problem.y0
            a0 = -y0[:2] / np.hypot(y0[0], y0[1]) ** 3
            x1 = y0[:2] + H * y0[2:] + 0.5 * H * H * a0
            c_out = baseline.run(c_method, np.concatenate([y0[:2], x1]), H, n)[:2]  # (x_n, x_n+1)
        steps = n
        if c_method == "ab4":  # the same exact starting values; C starts at y_3
            c_out = baseline.run(c_method, c_family_state(c_method), H, n)[12:14]
            stepper = type(stepper)(get_stepper(method).with_starter("reference"))
            steps = n + 3
        elif c_method != "stormer":
            c_out = baseline.run(c_method, c_family_state(c_method), H, n)[:2]
        harness_out = stepper.integrate(problem, h=H, n_steps=steps).final[:2, 0]
        assert np.max(np.abs(c_out - harness_out)) < 1e-9, family


@pytest.mark.parametrize("controller", ["naive", "reversible"])
def test_compiled_step_controlled_loop(benchmark, controller):
    """The step-controlled splitting (velocity Verlet under the Delta-theta controller; no C loop
    runs it): 1000 steps of control parameter 1e-3 on Kepler e = 0.6, one trajectory, against the
    NumPy loop of the same record (to rounding: the compiled loop repeats its operations)."""
    problem = get_problem("kepler-elliptic")
    name = f"velocity-verlet+dtheta-{controller}"
    stepper = get_stepper(name + "@compiled")
    stepper.integrate(problem, h=H, n_steps=1)  # kernel compiled or loaded, untimed
    trajectory = benchmark(stepper.integrate, problem, h=H, n_steps=STEPS)
    numpy_run = get_stepper(name).integrate(problem, h=H, n_steps=STEPS)
    assert trajectory.finite
    assert np.max(np.abs(trajectory.final - numpy_run.final)) < 1e-12
    assert np.max(np.abs(trajectory.t - numpy_run.t)) < 1e-12
