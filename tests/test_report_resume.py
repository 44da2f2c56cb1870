"""`kill -9` in the middle of `harness report`, then the same command again: it completes, does
not recompute the cells that had finished, and its results equal an uninterrupted run's.

The command runs as a user would start it (a subprocess, `--quick`, a small grid of several
cells per experiment, one worker so the kill leaves no orphan), with the cell cache and the
results in temporary directories.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

from harness.store import load_run

ROOT = Path(__file__).resolve().parent.parent
GRID = ["--stepper", "euler", "--stepper", "velocity-verlet", "--stepper", "leapfrog",
        "--problem", "harmonic"]
# Kill once this many cells are in the cache: enough to prove reuse, far from the end.
KILL_AFTER_CELLS = 3
RUN_TIMEOUT_S = 300


def _env(base: Path) -> dict[str, str]:
    env = dict(os.environ)
    env.update(HARNESS_CACHE_DIR=str(base / "cache"), HARNESS_RESULTS_DIR=str(base / "results"),
               CI="1", PYTHONPATH=str(ROOT) + os.pathsep + env.get("PYTHONPATH", ""))
    return env


def _command(base: Path) -> list[str]:
    return [sys.executable, "-m", "harness", "report", "--quick", "--jobs", "1", *GRID,
            "--output", str(base / "reports")]


def _cached_cells(base: Path) -> int:
    root = base / "cache" / "cells"
    return sum(1 for _ in root.glob("??/*.parquet")) if root.is_dir() else 0


def _run_to_end(base: Path) -> Path:
    proc = subprocess.run(_command(base), env=_env(base), cwd=ROOT, capture_output=True, text=True,
                          timeout=RUN_TIMEOUT_S)
    assert proc.returncode == 0, proc.stderr[-3000:]
    path = Path(proc.stdout.strip().splitlines()[-1])
    assert path.is_file() and path.name == "index.html"
    return path


def _comparable(df: pd.DataFrame) -> pd.DataFrame:
    """A table without the columns that measure time (wall clock differs between runs), the timed
    columns of the timing protocol and the Pareto marks of time among them."""
    from harness.experiments.work_precision.timed_runs import TIMING_COLUMNS

    timed = {*TIMING_COLUMNS, "pareto_time"}
    drop = [c for c in df.columns if "wall" in c or c in timed]
    return df.drop(columns=drop).reset_index(drop=True)


def test_killed_report_resumes_without_recomputing_and_equals_an_uninterrupted_run(tmp_path):
    killed = tmp_path / "killed"
    proc = subprocess.Popen(_command(killed), env=_env(killed), cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + RUN_TIMEOUT_S
        while _cached_cells(killed) < KILL_AFTER_CELLS:
            assert proc.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "no cell finished in time"
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be killed"
        proc.send_signal(signal.SIGKILL)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    finished = _cached_cells(killed)
    assert not list((killed / "reports").glob("*/index.html")), "a killed run wrote a report"
    assert not list((killed / "results").glob("2*")), "a killed run saved results"

    path = _run_to_end(killed)
    resumed = load_run(None, root=killed / "results")
    totals = resumed.meta["totals"]
    assert totals["failed"] == 0
    assert finished < totals["cells"], "every cell had finished before the kill"
    # every cell finished before the kill came from the cache; only the others ran
    assert totals["cached"] == finished
    assert totals["computed"] == totals["cells"] - finished
    assert _cached_cells(killed) == totals["cells"]
    assert path.parent.name == resumed.run_id

    clean = tmp_path / "clean"
    _run_to_end(clean)
    reference = load_run(None, root=clean / "results")
    assert reference.meta["totals"]["cached"] == 0
    assert resumed.experiments == reference.experiments
    for name in reference.experiments:
        pd.testing.assert_frame_equal(_comparable(resumed.summaries[name]),
                                      _comparable(reference.summaries[name]), obj=f"{name} summary")
        pd.testing.assert_frame_equal(_comparable(resumed.rows[name]),
                                      _comparable(reference.rows[name]), obj=f"{name} rows")
