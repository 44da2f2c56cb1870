"""The gate over the whole registry: every stepper on every compatible catalogue problem.

This is the CI gate inside the test suite: it fails when any measured order misses its claim
(beyond the expectations table in harness/gate.py, each entry with its reason) or any cell
fails. Finished cells are cached in .cache/cells, so a rerun with unchanged code is fast.
"""

from __future__ import annotations

from harness.gate import gate_table
from harness.registry import problems, steppers
from harness.runner import run_experiment


def test_gate_passes_over_the_whole_registry():
    result = run_experiment("convergence", steppers.names(), problems.names(), jobs=2,
                            progress=False)
    failures = result.failures.to_dict("records") if len(result.failures) else []
    assert not failures, [(f["stepper"], f["problem"], f["message"][:200]) for f in failures]
    table = gate_table(result.summary)
    bad = table[~table["passed"]]
    assert bad.empty, bad[["stepper", "problem", "claimed_order", "measured_order", "verdict",
                           "reason"]].to_string()
    # Every registered stepper was judged on at least one problem.
    assert set(table["stepper"]) == set(steppers.names())
    # The tutorial's claim that velocity Verlet is "two orders worse" than Stormer-Verlet is
    # false: both measure global order 2 on the same problems.
    for name in ("stormer-verlet", "velocity-verlet"):
        rows = table[(table.stepper == name) & (table.verdict == "converged")]
        assert len(rows) >= 3 and (abs(rows.measured_order - 2.0) <= 0.2).all()
