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


@pytest.mark.parametrize("stepper", IMPLICIT, ids=[s.info.name for s in IMPLICIT])
def test_the_times_a_start_reads_are_named_before_the_run(stepper, monkeypatch):
    """`reference_times` names exactly the times `integrate` reads from the ground truth: the k - 1
    starting times where the starter would be unstable, none where it runs."""
    import implementations.multistep as module

    read: list[float] = []
    real = module.reference

    def recorded(problem, times, *args, **kwargs):
        read.extend(float(t) for t in np.atleast_1d(times))
        return real(problem, times, *args, **kwargs)

    monkeypatch.setattr(module, "reference", recorded)
    interval = method_facts(get_stepper(stepper.starter_name)).real_interval
    y0 = DECAY.ensemble(2, seed=0)
    for h in (4 * interval / RATE, interval / (2 * RATE)):
        read.clear()
        named = stepper.reference_times(DECAY, 0.0, y0, h)
        stepper.integrate(DECAY, h=h, n_steps=stepper.coefficients.steps, y0=y0, t0=0.0)
        assert read == [float(t) for t in named]
    assert read == []  # the fine step: the declared starter ran


def test_a_sweep_on_the_stiff_reference_asks_for_every_time_it_reads_in_one_call(monkeypatch):
    """Where the reference is the stiff path's (one implicit solve per member per call), the
    convergence sweep asks for every time its runs' starts and its local sweep will read, and its
    horizon, in one call before the first run (`plan.read_references_once`; its first member
    alone first, to learn the path); every later read is one of them."""
    from types import SimpleNamespace

    import harness.experiments.convergence as conv
    import harness.experiments.convergence.plan as plan
    import implementations.multistep as module
    from harness.ground_truth.stiff import IMPLICIT_LEVEL

    asked: list[tuple[np.ndarray, int]] = []
    read: set[float] = set()
    real_start, real_local = module.reference, conv.reference

    def reads(real):
        def wrapped(problem, times, *args, **kwargs):
            read.update(float(t) for t in np.atleast_1d(times))
            return real(problem, times, *args, **kwargs)
        return wrapped

    def stiff_path(problem, times, y0, **kwargs):  # as if the stiff path had answered
        asked.append((times, y0.shape[1]))
        return SimpleNamespace(precision=IMPLICIT_LEVEL)

    monkeypatch.setattr(plan, "reference", stiff_path)
    monkeypatch.setattr(module, "reference", reads(real_start))
    monkeypatch.setattr(conv, "reference", reads(real_local))
    monkeypatch.setattr(conv, "fastest", lambda stepper, problem: stepper)  # the NumPy loop
    stepper = get_stepper("bdf2")
    config = {**conv.ConvergenceExperiment.default_config, "ensemble": 2, "work_budget": 1024,
              "t_end": DECAY.t_end}
    rows = conv.step_sweep(stepper, DECAY, config)
    assert [members for _, members in asked] == [1, 2]
    grid = {float(t) for t in asked[1][0]}
    assert read and read <= grid and float(DECAY.t_end) in grid
    counts = set(rows[rows.kind == "global"].n_steps.astype(int))
    assert counts <= set(plan.planned_counts(4, 4, config["ratio"], conv.step_budget(stepper, config)))
