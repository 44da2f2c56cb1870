"""Every pair an experiment leaves out, and every sweep that ends without an order, says why.

A user who sees `insufficient-range` or a skipped pair must learn which fact or which limit
is responsible, on the terminal and in JSON: a Skip without a reason, or an
`insufficient-range` record with an empty message, is a bug.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from harness import tolerances as tol
from harness.experiments import EXPERIMENTS, get_experiment
from harness.experiments.convergence.judge import summarize_cell
from harness.registry import problems, steppers


@pytest.mark.parametrize("name", ["energy", "reversibility", "symplecticity", "work-precision",
                                  "convergence"])
def test_every_skip_has_a_reason(name):
    exp = get_experiment(name)
    assert name in EXPERIMENTS
    _, skips = exp.cells(steppers.names(), problems.names(), exp.config(quick=True))
    assert all(isinstance(s.reason, str) and s.reason.strip() for s in skips)


def _sweep(errors, excluded, t_end=6.5):
    h = 0.5 ** np.arange(len(errors))
    return pd.DataFrame({
        "kind": "global", "h": h, "error": errors, "excluded": excluded,
        "in_fit": [e == "" for e in excluded], "reference_error": 1e-30, "n_steps": (1 / h).astype(int),
        "t_end": t_end, "wall_s": 0.1, "message": "",
    })


@pytest.mark.parametrize("excluded, limit", [
    (["pre-asymptotic"] * 4 + ["", ""], "the work budget"),
    (["pre-asymptotic"] * 3 + ["", "", "roundoff"], "the float64 rounding floor"),
    (["pre-asymptotic"] * 3 + ["", "", "reference"], "the reference's certified accuracy"),
])
def test_insufficient_range_names_the_limit_and_the_horizon(excluded, limit):
    errors = np.geomspace(1.0, 1e-6, len(excluded))
    rec = summarize_cell(steppers.get("rk4"), "harmonic", _sweep(errors, excluded))
    assert rec["verdict"] == "insufficient-range"
    assert limit in rec["message"] and "horizon t_end = 6.5" in rec["message"]
    assert f"2 of {tol.MIN_FIT_POINTS} asymptotic points" in rec["message"]
