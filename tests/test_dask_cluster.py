"""The same grid on a Dask cluster: a scheduler and two worker processes on loopback, started by
the test, run the toy experiment through `scheduler=tcp://...`; the result equals a serial run,
failures stay in their cells, and the cache stays with the submitting process."""

from __future__ import annotations

import logging
import os

import pandas as pd
import pytest
from test_runner import toy_registry  # the toy plugin and experiment

from harness.runner import run_experiment, run_experiments

distributed = pytest.importorskip("distributed", reason="dask.distributed is in requirements.txt")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    with toy_registry(tmp_path_factory.mktemp("toy")) as plugin:
        with distributed.LocalCluster(
            host="127.0.0.1", n_workers=2, threads_per_worker=1, processes=True,
            dashboard_address=None, silence_logs=logging.ERROR,
        ) as lc:
            yield lc, plugin


def test_a_grid_on_a_dask_cluster_equals_the_serial_run(cluster, tmp_path):
    lc, plugin = cluster
    grid = (["toy-ok", "toy-alt"], ["toy-decay", "toy-growth"])
    serial = run_experiment("toy", *grid, jobs=1, cache=False, plugins=[plugin], progress=False)
    on_cluster = run_experiment("toy", *grid, scheduler=lc.scheduler_address, plugins=[plugin],
                                cache_dir=tmp_path, progress=False)
    assert (on_cluster.computed_cells, on_cluster.n_failed) == (9, 0)
    pd.testing.assert_frame_equal(serial.rows, on_cluster.rows)
    pd.testing.assert_frame_equal(serial.summary, on_cluster.summary)
    # the work ran on the cluster's worker processes, not here
    workers = {w.rsplit(":", 1)[1] for w in on_cluster.cells.worker}
    with distributed.Client(lc.scheduler_address, set_as_default=False) as client:
        cluster_pids = {str(p) for p in client.run(os.getpid).values()}
    assert workers <= cluster_pids and str(os.getpid()) not in workers
    # the cache is the submitting process's: a rerun sends nothing to the cluster
    again = run_experiment("toy", *grid, scheduler=lc.scheduler_address, plugins=[plugin],
                           cache_dir=tmp_path, progress=False)
    assert (again.computed_cells, again.cached_cells) == (0, 9)
    pd.testing.assert_frame_equal(serial.rows, again.rows)


def test_failures_and_time_limits_stay_in_their_cells_on_a_cluster(cluster):
    lc, plugin = cluster
    with distributed.Client(lc.scheduler_address, set_as_default=False) as client:
        out = run_experiments(["toy"], ["toy-ok", "toy-raise", "toy-sleep"], ["toy-decay"],
                              configs={"toy": {"n": 1}}, scheduler=client, cache=False,
                              plugins=[plugin], cell_timeout=1.0, progress=False)
    r = out["toy"]
    kinds = dict(zip(r.failures.stepper, r.failures.kind, strict=True))
    assert kinds == {"toy-raise": "error", "toy-sleep": "timeout"}
    assert r.rows.stepper.unique().tolist() == ["toy-ok"]
