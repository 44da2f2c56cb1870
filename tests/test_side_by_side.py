"""The side-by-side experiment (harness/experiments/side_by_side.py): every stepper on each N-body
problem at one step and final time, and its report section joining the other experiments."""

from __future__ import annotations

import importlib.util
import math

import pandas as pd
import pytest

from harness.experiments import get_experiment
from harness.experiments.base import Cell
from harness.experiments.side_by_side.section import SECTION
from harness.kit import Section

HAVE_REBOUND = importlib.util.find_spec("rebound") is not None
EXP = get_experiment("side-by-side")


def test_only_nbody_problems_get_cells_and_the_rest_say_why():
    cells, skips = EXP.cells(["leapfrog"], ["kepler-elliptic", "harmonic"], EXP.config())
    assert [(c.stepper, c.problem) for c in cells] == [("leapfrog", "kepler-elliptic")]
    assert [s.problem for s in skips] == ["harmonic"] and "N-body" in skips[0].reason


@pytest.mark.parametrize("name", ["leapfrog", "rk4"] + (["rebound-whfast"] if HAVE_REBOUND else []))
def test_a_cell_is_one_run_to_the_common_final_time(name):
    from harness.registry import get_problem

    row = EXP.run_cell(Cell("side-by-side", name, "kepler-elliptic"), EXP.config()).iloc[0]
    T = get_problem("kepler-elliptic").convergence_t_end
    assert row.t_end == pytest.approx(T) and row.steps * row.h == pytest.approx(T)
    assert 0 < row.error < 1 and row.evals >= row.steps and row.message == ""


def test_a_stepper_that_stops_is_recorded_with_its_reason():
    row = EXP.run_cell(Cell("side-by-side", "backward-euler", "planets-pair"), EXP.config()).iloc[0]
    assert math.isinf(row.error) and row.message.startswith("stopped: ")


class _View:
    """The parts of a report view the section reads."""

    def __init__(self, tables):
        self.tables = tables

    def has(self, name):
        return name in self.tables

    def summary(self, name):
        return self.tables.get(name, pd.DataFrame())

    def gate(self):
        return pd.DataFrame([{"stepper": "a", "problem": "p", "claimed_order": 2, "measured_order": 2.01,
                              "verdict": "converged", "outcome": "pass", "expected_order": 2.0}])


def test_the_section_joins_order_drift_and_round_trip_per_stepper():
    side = pd.DataFrame([{"stepper": "a", "problem": "p", "implementation": "lib", "h": 0.1, "t_end": 1.0,
                          "steps": 10, "tol": math.nan, "error": 1e-3, "evals": 10.0, "evals_unit": "",
                          "wall_s": 0.01, "message": ""}])
    energy = pd.DataFrame([{"stepper": "a", "problem": "p", "steps": 100000, "drift_class": "bounded",
                            "max_rel_energy_error": 1e-6}])
    rev = pd.DataFrame([{"stepper": "a", "problem": "p", "steps": s, "verdict": v, "return_error_ulps": u}
                        for s, v, u in ((100, "reversible", 3.0), (1000, "reversible", 9.0))])
    view = _View({"side-by-side": side, "convergence": pd.DataFrame(), "energy": energy,
                  "reversibility": rev})
    sec = Section("side-by-side", 1, "t")
    SECTION.build(view, sec)
    [table] = [b.table for b in sec.blocks if b.kind == "table"]
    text = repr(table)
    for shown in ("2.01", "bounded", "100000", "reversible", "9", "lib"):
        assert shown in text, shown
