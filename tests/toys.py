"""The toy plugin and toy experiment the runner's tests share (test_runner, test_resume,
test_hostile_api, test_dask_cluster): cheap deterministic cells, and steppers whose names pick a
misbehaviour (raise, wrong type, NaN, sleep, crash, stuck). The toy steppers and problems live in
a plugin file, so worker processes load them like a user's plugin.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
from helpers import loaded_plugin

from harness.experiments.base import EXPERIMENTS, Cell, Experiment, Skip

TOY_PLUGIN = '''"""Toy steppers and problems for the harness's own tests: explicit Euler under several names
(Hairer, Norsett & Wanner, Solving ODEs I, I.7) and two scalar linear problems."""
import heyoka as hy

from harness.problem import Problem
from harness.stepper import Carry, Stepper, StepperInfo


class ToyEuler(Stepper):
    """Explicit Euler, y1 = y0 + h f(t0, y0) (Hairer, Norsett & Wanner, Solving ODEs I, I.7)."""

    def __init__(self, name):
        self.info = StepperInfo(
            name=name, family="toy", claimed_order=1, explicit=True, symplectic=False,
            symmetric=False, evals_per_step=1, form="first-order", velocity_dependent=True,
            reference="Hairer, Norsett & Wanner, Solving ODEs I, I.7",
        )

    def _start(self, dyn, t0, y0, h):
        return Carry(t0, h, y0)

    def _step(self, dyn, c):
        c.y = c.y + c.h * dyn.f(c.t, c.y)


x = hy.make_vars("x")
STEPPERS = [ToyEuler(n) for n in (
    "toy-ok", "toy-alt", "toy-raise", "toy-wrongtype", "toy-nan", "toy-sleep", "toy-crash",
    "toy-exit", "toy-stuck", "toy-slow",
)]
PROBLEMS = [
    Problem("toy-decay", variables=[x], rhs=[-x], y0=[1.0], t_span=(0.0, 1.0),
            reference="y' = -y, y = exp(-t)"),
    Problem("toy-growth", variables=[x], rhs=[x], y0=[1.0], t_span=(0.0, 1.0),
            reference="y' = y, y = exp(t)"),
]
'''

CALLS: Counter = Counter()  # run_cell calls made in this process, by stepper


class ToyExperiment(Experiment):
    """A cheap deterministic experiment: `n` cells per stepper x problem, three rows each."""

    name = "toy"
    description = "Toy experiment for the runner's tests."
    default_config = {"n": 3, "scale": 1.0, "sleep": 0.0, "ensemble": 4, "break_summary": False}
    quick_config = {"n": 2}
    row_dtypes = {"j": "int", "value": "float"}
    finite_columns = ("value",)

    def cells(self, steppers, problems, config):
        cells, skips = [], []
        for s in steppers:
            for p in problems:
                if s == "toy-alt" and p == "toy-growth":
                    skips.append(Skip(self.name, s, p, "toy-alt does not apply to growth"))
                    continue
                cells += [Cell(self.name, s, p, (("k", k),)) for k in range(config["n"])]
        return cells, skips

    def run_cell(self, cell, config):
        s = cell.stepper
        CALLS[s] += 1
        if config["sleep"] or s == "toy-slow":
            time.sleep(config["sleep"] or 0.3)
        if s == "toy-raise":
            raise RuntimeError("toy failure in run_cell")
        if s == "toy-wrongtype":
            return [1.0, 2.0]
        if s == "toy-sleep":
            time.sleep(60)
        if s == "toy-stuck":  # as if stuck in compiled code: the alarm cannot interrupt it
            signal.signal(signal.SIGALRM, signal.SIG_IGN)
            time.sleep(60)
        if s == "toy-crash":  # a segmentation fault, as a broken compiled plugin would cause
            ctypes.string_at(0)
        if s == "toy-exit":  # the process ends without a word (as if killed)
            os._exit(3)
        k = cell.param("k")
        sign = -1.0 if cell.problem == "toy-decay" else 1.0
        value = config["scale"] * (k + 1) * np.exp(sign * np.arange(3.0)) + len(s)
        if s == "toy-nan":
            value[1] = np.nan
        return pd.DataFrame({"j": np.arange(3), "value": value,
                             "label": [f"{s}/{i}" for i in range(3)]})

    def summarize(self, rows, config):
        if config["break_summary"]:
            raise ValueError("toy summary broke")
        g = rows.groupby(["stepper", "problem", "k"], sort=False)
        return g["value"].agg(["sum", "max"]).reset_index()


@contextlib.contextmanager
def toy_registry(directory: Path):
    """The toy plugin loaded from `directory` and the toy experiment registered; both removed
    again afterwards so later tests see the registry unchanged."""
    with loaded_plugin(Path(directory) / "toy_plugin.py", TOY_PLUGIN) as path:
        EXPERIMENTS["toy"] = ToyExperiment()
        try:
            yield path
        finally:
            EXPERIMENTS.pop("toy", None)
