"""Helpers the experiments' and steppers' tests share: running an experiment in this process (with
or without the runner), the coverage check every experiment owes the registry, loading a plugin
file for one block of code, a problem that defeats every solver, and deliberately mislabelled
steppers whose claims are false (the experiment that checks a claim must say so).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import importlib.util
from collections.abc import Iterator
from functools import partial
from pathlib import Path

import heyoka as hy
import pandas as pd

from harness import registry
from harness.experiments.base import Experiment
from harness.problem import Problem
from harness.registry import problems, steppers
from harness.runner import run_experiment
from harness.stepper import Carry, Stepper

__all__ = [
    "BLOWUP",
    "PlainEulerLabelledSymplectic",
    "cells_or_reasons",
    "loaded_plugin",
    "plugin_problem",
    "relabelled",
    "run_direct",
    "run_through_runner",
    "runners",
]


def run_direct(exp: Experiment, stepper_names, problem_names, **overrides) -> pd.DataFrame:
    """The experiment's own cells, run_cell and summarize in this process (no runner, quick
    settings), for the large registry tables: the runner's per-cell bookkeeping would dominate
    their time."""
    config = exp.config(overrides, quick=True)
    cells, _ = exp.cells(stepper_names, problem_names, config)
    rows = pd.concat([exp.run_cell(c, config) for c in cells], ignore_index=True)
    return exp.summarize(rows, config)


def run_through_runner(exp: Experiment, stepper_names, problem_names, **overrides) -> pd.DataFrame:
    """The summary of a quick run through the runner (in this process, no cache), as `harness
    run` does; no cell may fail."""
    result = run_experiment(exp, stepper_names, problem_names, quick=True, config=overrides,
                            jobs=1, cache=False, progress=False)
    assert not len(result.failures), result.failures
    return result.summary


def runners(exp: Experiment):
    """(`run_direct`, `run_through_runner`) bound to `exp`, each called as (steppers, problems,
    **overrides)."""
    return partial(run_direct, exp), partial(run_through_runner, exp)


def cells_or_reasons(exp: Experiment, name: str, config: dict | None = None):
    """The cells and skips of stepper `name` on every registered problem, after checking that
    each problem gets a cell or a skip and every skip gives its reason. Returns (cells, skips)."""
    cells, skips = exp.cells([name], problems.names(), exp.config() if config is None else config)
    covered = {c.problem for c in cells} | {s.problem for s in skips}
    assert covered == set(problems.names())
    assert all(s.reason for s in skips)
    return cells, skips


@contextlib.contextmanager
def loaded_plugin(path: Path, source: str) -> Iterator[Path]:
    """Write the plugin file `path` with `source` and load it; whatever it registered is
    unregistered again afterwards, so later tests see the registry unchanged."""
    path = Path(path)
    path.write_text(source)
    names = registry.load_plugin(path)
    try:
        yield path
    finally:
        for n in names:
            registry.steppers.unregister(n)
            registry.problems.unregister(n)
        registry._plugins.pop(str(path.resolve()), None)


PLUGINS = Path(__file__).parent / "plugins"


def plugin_problem(file: str, name: str) -> Problem:
    """The problem `name` of the plugin file `tests/plugins/<file>`, imported as a user's file
    would be, and not registered."""
    spec = importlib.util.spec_from_file_location(f"test_plugin_{Path(file).stem}", PLUGINS / file)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return next(p for p in module.PROBLEMS if p.name == name)


_y = hy.make_vars("y")
# y' = y^2, y(0) = 1 blows up at t = 1: a step across t = 1 leaves the stage equations of every
# implicit method without a real solution (backward Euler with h = 1: x - x^2 = 1), and an
# adaptive solver's step size collapses.
BLOWUP = Problem(
    "test-blowup",
    variables=[_y],
    rhs=[_y * _y],
    y0=[1.0],
    t_span=(0.0, 1.0),
    reference="y' = y^2: exact solution 1/(1 - t), finite-time blow-up at t = 1",
)


class PlainEulerLabelledSymplectic(Stepper):
    """Explicit Euler on (q, v): q1 = q0 + h v0, v1 = v0 + h a(q0), carrying the label of the
    symplectic Euler method (GNI I.1.2), which kicks with the new position. It has the right
    order, but the label "symplectic" is false: the deliberate mislabel the experiments must
    catch."""

    def __init__(self, name: str = "mislabelled-symplectic-euler"):
        self.info = dataclasses.replace(
            steppers.get("symplectic-euler-a").info, name=name, description="plain Euler",
            reference="Hairer, Lubich & Wanner, Geometric Numerical Integration, I.1.2 (mislabelled)",
        )

    def _start(self, dyn, t0, y0, h):
        return Carry(t0, h, y0)

    def _step(self, dyn, c):
        q, v = c.y[: dyn.nq], c.y[dyn.nq :]
        a = dyn.accel(c.t, q)
        q += c.h * v
        v += c.h * a


def relabelled(name: str, **claims) -> Stepper:
    """A copy of the registered stepper `name`, named `<name>-relabelled`, with `claims`
    replacing its declared properties (same step, different label)."""
    original = steppers.get(name)
    clone = copy.copy(original)
    clone.info = dataclasses.replace(original.info, name=f"{name}-relabelled", **claims)
    return clone


def adapter_without(monkeypatch, package: str, adapter_path, module_name: str):
    """The adapter module at `adapter_path`, executed afresh as `module_name` while importing
    `package` (or any of its submodules) fails as if it were not installed; it is also put in
    `sys.modules`, so `implementations.unavailable_steppers()` reads it (monkeypatch undoes both)."""
    import importlib.util
    import sys

    for mod in [m for m in sys.modules if m == package or m.startswith(package + ".")]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setitem(sys.modules, package, None)  # what the import system reads as "not installed"
    spec = importlib.util.spec_from_file_location(module_name, adapter_path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setitem(sys.modules, module_name, module)
    return module
