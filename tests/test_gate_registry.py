"""The gate over the whole registry: every stepper on every compatible catalogue problem.

This is the CI gate inside the test suite: it fails when any cell contradicts what the method's
and the problem's facts predict (harness.rules), when a stepper has no cell that measured its
claim, or when any cell fails. Every cell that is `not-measurable` carries the limit that
stopped it. Finished cells are cached in .cache/cells, so a rerun with unchanged code is fast.
"""

from __future__ import annotations

import pytest

from harness.gate import gate_table
from harness.registry import problems, steppers
from harness.runner import run_experiment


@pytest.mark.slow
def test_gate_passes_over_the_whole_registry():
    # In this process (jobs=1): the test suite already keeps both cores busy with its two
    # workers, and a pool here would only add its processes' own set-up (imports, loading the
    # compiled functions and kernels once more in each). The pool path is tested in test_runner.
    result = run_experiment("convergence", steppers.names(), problems.names(), jobs=1,
                            progress=False)
    failures = result.failures.to_dict("records") if len(result.failures) else []
    assert not failures, [(f["stepper"], f["problem"], f["message"][:200]) for f in failures]
    table = gate_table(result.summary)
    bad = table[~table["passed"]]
    assert bad.empty, bad[["stepper", "problem", "claimed_order", "measured_order", "verdict",
                           "reason"]].to_string()
    # ... none of them merely `not-verified` either (the CLI's exit 3): every built-in claim is
    # measured somewhere.
    assert not (table.outcome == "not-verified").any(), table[table.outcome == "not-verified"]
    # Every registered stepper was judged on at least one problem, and passed at least one.
    assert set(table["stepper"]) == set(steppers.names())
    assert set(table[table.outcome == "pass"].stepper) == set(steppers.names())
    # Every cell that could not be measured says why.
    unmeasured = table[table.outcome == "not-measurable"]
    assert unmeasured.reason.str.len().gt(20).all(), unmeasured[["stepper", "problem", "reason"]]
    # The tutorial's claim that velocity Verlet is "two orders worse" than Stormer-Verlet is
    # false: both measure global order 2 on the same problems.
    for name in ("stormer-verlet", "velocity-verlet"):
        rows = table[(table.stepper == name) & (table.verdict == "converged")]
        assert len(rows) >= 3 and (abs(rows.measured_order - 2.0) <= 0.2).all()
