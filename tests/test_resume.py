"""kill -9 in the middle of a run, then the same command again: it completes, does not recompute
the cells that had finished, and its result equals an uninterrupted run.

The script runs its cells in its own process (`jobs=1`): the cache is written by the submitting
process whatever the backend, and worker processes would only add start-up time here (the
parallel path is compared with the serial one in test_runner.py)."""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
from toys import toy_registry  # the toy plugin

from harness.runner import run_experiment
from harness.store import CellCache

ROOT = Path(__file__).resolve().parent.parent
CELLS = 16  # 2 steppers x 2 problems x 4 parameters
SCRIPT = '''
"""A run of slow toy cells (0.3 s each), with the cell cache on."""
import json
import sys
import time

import numpy as np
import pandas as pd

from harness.experiments.base import Cell, Experiment
from harness.runner import run_experiment
from harness.store import write_parquet


class SlowToy(Experiment):
    name = "slow-toy"
    default_config = {"sleep": 0.3}

    def cells(self, steppers, problems, config):
        cells = [Cell(self.name, s, p, (("k", k),)) for s in steppers for p in problems
                 for k in range(4)]
        return cells, []

    def run_cell(self, cell, config):
        time.sleep(config["sleep"])
        k = cell.param("k")
        value = (k + 1) * np.sqrt(np.arange(2.0) + len(cell.stepper) + len(cell.problem))
        return pd.DataFrame({"j": np.arange(2), "value": value})

    def summarize(self, rows, config):
        return rows.groupby("cell", sort=False)["value"].sum().reset_index()


if __name__ == "__main__":
    plugin, cache, out = sys.argv[1:4]
    r = run_experiment(SlowToy(), ["toy-ok", "toy-alt"], ["toy-decay", "toy-growth"], jobs=1,
                       plugins=[plugin], cache_dir=cache, progress="lines")
    write_parquet(out + ".rows.parquet", r.rows)
    write_parquet(out + ".summary.parquet", r.summary)
    print(json.dumps({"computed": r.computed_cells, "cached": r.cached_cells,
                      "failed": r.n_failed}))
'''


def _command(script: Path, plugin: Path, cache: Path, out: Path) -> list[str]:
    return [sys.executable, str(script), str(plugin), str(cache), str(out)]


def test_kill_9_then_rerun_completes_without_recomputing_finished_cells(tmp_path):
    with toy_registry(tmp_path) as plugin:
        script = tmp_path / "slow_run.py"
        script.write_text(SCRIPT)
        cache, out = tmp_path / "cache", tmp_path / "out"
        cells = CellCache(cache)
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        proc = subprocess.Popen(_command(script, plugin, cache, out), cwd=ROOT, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                start_new_session=True)
        try:
            deadline = time.monotonic() + 120
            while len(cells) < 4 and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.05)
            assert proc.poll() is None, "the run ended before it could be killed"
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=30)
        finally:
            _kill_group(proc.pid)  # the run, if an assertion left it running
            proc.wait(timeout=30)
        finished = len(cells)
        assert proc.returncode == -signal.SIGKILL
        assert 4 <= finished < CELLS
        assert not out.with_suffix(".rows.parquet").exists()

        again = subprocess.run(_command(script, plugin, cache, out), cwd=ROOT, env=env,
                               capture_output=True, text=True, timeout=300)
        assert again.returncode == 0, again.stderr
        counts = json.loads(again.stdout.strip().splitlines()[-1])
        assert counts == {"computed": CELLS - finished, "cached": finished, "failed": 0}
        assert "\r" not in again.stderr and f"slow-toy: {CELLS}/{CELLS} cells" in again.stderr

        # the uninterrupted run, here, without sleeping and without the cache
        spec = importlib.util.spec_from_file_location("slow_run", script)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        reference = run_experiment(module.SlowToy(), ["toy-ok", "toy-alt"],
                                   ["toy-decay", "toy-growth"], config={"sleep": 0.0}, jobs=1,
                                   cache=False, plugins=[plugin], progress=False)
        resumed_rows = pd.read_parquet(str(out) + ".rows.parquet")
        resumed_summary = pd.read_parquet(str(out) + ".summary.parquet")
        pd.testing.assert_frame_equal(reference.rows, resumed_rows)
        pd.testing.assert_frame_equal(reference.summary, resumed_summary)


def _kill_group(pgid: int) -> None:
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
