"""pytest-benchmark micro-benchmarks: each family's step loop, single trajectory and ensemble.

Disabled in the normal test run (`--benchmark-disable` in pyproject.toml: each body runs once,
so its assertions count); `make bench` (scripts/bench) runs them timed, saves JSON and can
compare with a saved run. One representative stepper per family (the first registered), plus
the compiled implementation; 20 steps of Kepler (e = 0.6) with h = 1e-3 through the public
`integrate`, checked against the exact solution.
"""

from __future__ import annotations

import numpy as np
import pytest

from harness.registry import get_problem, steppers

STEPS, H = 20, 1e-3
# 20 steps of 1e-3 from pericentre: every consistent method is within 1e-6 of the exact orbit
# (the first-order ones by ~h^2 n |a| / 2 ~ 6e-5 |a| with |a| = 6.25, the rest far below).
ACCURACY = 1e-3


def _representatives() -> list:
    chosen: dict[str, object] = {}
    for s in steppers.all():
        key = "compiled" if s.info.implementation == "compiled" else s.info.family
        chosen.setdefault(key, s)
    return list(chosen.values())


REPRESENTATIVES = _representatives()


@pytest.mark.parametrize("ensemble", [1, 1000], ids=["single", "ensemble1000"])
@pytest.mark.parametrize("stepper", REPRESENTATIVES, ids=lambda s: f"{s.info.family}-{s.info.name}")
def test_step_loop(benchmark, stepper, ensemble):
    problem = get_problem("kepler-elliptic")
    if ensemble > 1 and stepper.info.family in ("external",):
        pytest.skip("scipy's steppers integrate member by member: ensembles take seconds per step")
    y0 = problem.ensemble(ensemble, seed=0) if ensemble > 1 else problem.y0
    trajectory = benchmark(stepper.integrate, problem, h=H, n_steps=STEPS, y0=y0)
    exact = problem.exact(problem.t0 + STEPS * H, np.atleast_2d(y0.T).T, problem.t0, None)
    assert trajectory.finite
    assert np.max(np.abs(trajectory.final - exact)) < ACCURACY
    if stepper.info.adaptive:  # counts its internal steps
        assert sum(trajectory.evals.values()) >= 1
    else:
        counted = trajectory.evals["accel"] + trajectory.evals["rhs"]
        assert counted >= STEPS * min(1.0, stepper.info.evals_per_step)
