"""The runner: cache reuse and invalidation, parallel = serial, failures isolated per cell,
memory guard, argument checks, progress output.

A toy experiment (tests/toys.py) stands in for the real ones: its cells are cheap and
deterministic, and a stepper's name picks a misbehaviour (raise, wrong type, NaN, sleep, crash,
stuck). The toy steppers and problems live in a plugin file, so worker processes load them like a
user's plugin.
"""

from __future__ import annotations

import io
import json
import os
import signal
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

# the toy plugin and experiment (shared with other test files); toy_registry is re-exported here
from toys import CALLS, TOY_PLUGIN, ToyExperiment, toy_registry  # noqa: F401

from harness import registry, runner
from harness.errors import HarnessError, InputError, UnknownNameError
from harness.experiments.base import Cell
from harness.progress import Progress, choose_mode
from harness.runner import (
    CellOutputError,
    ExperimentError,
    check_memory,
    estimate_bytes,
    run_experiment,
    run_experiments,
    validate_rows,
)
from harness.store import CellCache, load_run, save_run


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    with toy_registry(tmp_path_factory.mktemp("toy")) as path:
        yield path


@pytest.fixture
def run(toy, tmp_path):
    """run_experiment with the toy plugin, a private cache and no progress output."""

    def _run(steppers=("toy-ok", "toy-alt"), problems=("toy-decay", "toy-growth"), **kw):
        kw.setdefault("jobs", 1)
        kw.setdefault("cache_dir", tmp_path / "cache")
        kw.setdefault("progress", False)
        kw.setdefault("plugins", [toy])
        return run_experiment("toy", list(steppers), list(problems), **kw)

    CALLS.clear()
    return _run


def _sorted(df: pd.DataFrame) -> pd.DataFrame:
    return df.sort_values(list(df.columns)).reset_index(drop=True)


# -- results and bookkeeping ----------------------------------------------------------------------
def test_serial_run_returns_rows_summary_skips_and_cell_records(run):
    r = run()
    # toy-ok: 2 problems x 3, toy-alt: decay only x 3 (growth skipped)
    assert (r.n_cells, r.computed_cells, r.cached_cells, r.n_failed) == (9, 9, 0, 0)
    assert len(r.rows) == 27 and len(r.summary) == 9
    assert list(r.rows.columns[:5]) == ["experiment", "cell", "stepper", "problem", "k"]
    assert r.rows.value.dtype == np.float64 and r.rows.j.dtype == np.int64
    assert r.skips.to_dict("records") == [{"experiment": "toy", "stepper": "toy-alt",
                                          "problem": "toy-growth",
                                          "reason": "toy-alt does not apply to growth"}]
    assert set(r.cells.status) == {"ok"} and not r.cells.cached.any()
    assert r.cells.key.str.fullmatch(r"[0-9a-f]{32}").all() and r.cells.key.is_unique
    # rows follow the experiment's cell order
    assert list(dict.fromkeys(r.rows.cell)) == list(r.cells.cell)
    # every cell and the run record their wall time (recorded, never compared: clocks are noisy)
    assert r.config["n"] == 3 and np.isfinite(r.wall_s) and r.wall_s >= 0
    assert r.cells.wall_s.notna().all() and (r.cells.wall_s >= 0).all()


def test_second_run_reuses_every_cell_and_equals_the_first(run):
    first = run()
    calls = sum(CALLS.values())
    second = run()
    assert (second.computed_cells, second.cached_cells) == (0, 9)
    assert sum(CALLS.values()) == calls  # run_cell was not called again
    pd.testing.assert_frame_equal(first.rows, second.rows)
    pd.testing.assert_frame_equal(first.summary, second.summary)
    assert second.cells.cached.all()


def test_changed_stepper_recomputes_only_its_own_cells(run, monkeypatch):
    first = run()
    alt = registry.get_stepper("toy-alt")
    monkeypatch.setattr(alt, "fingerprint", lambda: "toy-alt, coefficients changed")
    CALLS.clear()
    second = run()
    assert (second.computed_cells, second.cached_cells) == (3, 6)
    assert CALLS == Counter({"toy-alt": 3})
    pd.testing.assert_frame_equal(first.rows, second.rows)


def test_changed_configuration_or_experiment_code_recomputes(run, monkeypatch):
    run()
    scaled = run(config={"scale": 2.0})
    assert scaled.computed_cells == 9
    monkeypatch.setattr(runner.orchestration, "experiment_fingerprint", lambda exp: "other experiment code")
    assert run().computed_cells == 9


def test_fresh_recomputes_every_cell_and_overwrites_the_cache(run, tmp_path):
    run()
    cache = CellCache(tmp_path / "cache")
    before = {p: p.stat().st_ino for p in cache.root.glob("*/*.parquet")}
    CALLS.clear()
    r = run(fresh=True)
    assert (r.computed_cells, r.cached_cells, sum(CALLS.values())) == (9, 0, 9)
    # each file was replaced (atomic rename of a new file: a new inode), not left in place
    after = {p: p.stat().st_ino for p in cache.root.glob("*/*.parquet")}
    assert set(after) == set(before) and all(after[p] != before[p] for p in before)


def test_cache_false_neither_reads_nor_writes(run, tmp_path):
    run(cache=False)
    assert len(CellCache(tmp_path / "cache")) == 0
    run()
    r = run(cache=False)
    assert r.computed_cells == 9


def test_quick_uses_the_quick_configuration(run):
    r = run(quick=True, steppers=["toy-ok"], problems=["toy-decay"])
    assert r.n_cells == 2 and r.config["n"] == 2


def test_parallel_run_equals_serial_run(run):
    serial = run(cache=False)
    parallel = run(cache=False, jobs=2)
    assert parallel.computed_cells == 9 and parallel.n_failed == 0
    pd.testing.assert_frame_equal(serial.rows, parallel.rows)
    pd.testing.assert_frame_equal(serial.summary, parallel.summary)
    pd.testing.assert_frame_equal(_sorted(serial.rows), _sorted(parallel.rows))
    assert parallel.cells.worker.nunique() >= 1
    assert not parallel.cells.worker.str.endswith(f":{os.getpid()}").any()


def test_claim_directories_of_long_killed_runs_are_removed(tmp_path, monkeypatch):
    monkeypatch.setattr(runner.workers.tempfile, "gettempdir", lambda: str(tmp_path))
    old, fresh = tmp_path / "harness-claims-old", tmp_path / "harness-claims-fresh"
    for d in (old, fresh):
        d.mkdir()
        (d / ("0" * 32)).write_text("1234\n")
    stamp = time.time() - runner.STALE_CLAIMS_S - 60
    os.utime(old, (stamp, stamp))
    runner.clean_stale_claims()
    assert not old.exists() and fresh.exists()


# -- failures stay in their cell ------------------------------------------------------------------
EXPECTED_FAILURES = {
    "toy-raise": ("error", r"RuntimeError: toy failure in run_cell"),
    "toy-wrongtype": ("invalid", r"run_cell returned list, expected a pandas DataFrame"),
    "toy-nan": ("invalid", r"column 'value' has 1 non-finite value\(s\) \(NaN/inf\) at rows \[1\]"),
    "toy-sleep": ("timeout", r"^timeout after 1 s$"),
}


@pytest.mark.parametrize("jobs", [1, 2])
def test_each_failure_is_recorded_in_its_cell_and_the_others_complete(run, jobs):
    r = run(steppers=["toy-ok", *EXPECTED_FAILURES], problems=["toy-decay"], jobs=jobs,
            config={"n": 1}, cell_timeout=1.0)
    assert r.n_cells == 5 and r.n_failed == 4
    assert list(r.rows.stepper.unique()) == ["toy-ok"] and len(r.summary) == 1
    assert not r.rows_stored  # a run with failures has no pack: its rows are read back when saved
    failures = r.failures.set_index("stepper")
    for stepper, (kind, message) in EXPECTED_FAILURES.items():
        assert failures.loc[stepper, "kind"] == kind
        assert pd.Series([failures.loc[stepper, "message"]]).str.contains(message).all(), stepper
    assert "run_cell" in failures.loc["toy-raise", "traceback"]
    assert "\n" not in "".join(r.failures.message)
    assert (r.cells.set_index("stepper").status == "failed").sum() == 4
    timed = r.cells.set_index("stepper").loc["toy-sleep"]
    assert timed.status == "failed" and timed.n_rows == 0 and not timed.cached
    # failed cells are not cached: a rerun tries them again and reuses the good one
    again = run(steppers=["toy-ok", "toy-raise"], problems=["toy-decay"], config={"n": 1})
    assert (again.cached_cells, again.computed_cells, again.n_failed) == (1, 1, 1)


def test_a_crashing_or_stuck_worker_fails_only_its_cell(run, monkeypatch):
    """Real worker processes: a segfault and a cell stuck past its limit (deaf to the alarm) are
    named by their claim files; the pool is replaced and the other cells complete."""
    monkeypatch.setattr(runner.limits, "HARD_TIMEOUT_GRACE_S", 0.5)
    steppers = ["toy-ok", "toy-crash", "toy-stuck", "toy-alt"]
    r = run(steppers=steppers, problems=["toy-decay"], jobs=2, config={"n": 1}, cell_timeout=1.0)
    failures = r.failures.set_index("stepper")
    assert set(failures.index) == {"toy-crash", "toy-stuck"}
    assert failures.loc["toy-crash", "kind"] == "crash"
    assert "Fatal Python error: Segmentation fault" in failures.loc["toy-crash", "message"]
    assert failures.loc["toy-stuck", "kind"] == "timeout"
    assert failures.loc["toy-stuck", "message"].startswith("timeout after 1 s")
    assert sorted(r.rows.stepper.unique()) == ["toy-alt", "toy-ok"]
    serial = run(steppers=["toy-ok", "toy-alt"], problems=["toy-decay"], config={"n": 1})
    pd.testing.assert_frame_equal(serial.rows, r.rows)


class _FakePool:
    """Stands in for `loky_batch`: runs a batch 'on' `n` workers, where a cell named in
    `silent` kills its worker without a word (like `os._exit`) and takes the whole pool down."""

    def __init__(self, silent):
        self.silent = set(silent)
        self.batches = []

    def __call__(self, batch, n, accept):
        self.batches.append(([t.cell.stepper for t in batch], n))
        claim_dir = batch[0].payload["claim_dir"]
        for start in range(0, len(batch), n):
            in_flight = batch[start:start + n]
            for t in in_flight:
                Path(claim_dir, t.key).write_text("1234\n")
            if any(t.cell.stepper in self.silent for t in in_flight):
                return RuntimeError("exit codes of the workers are {EXIT(3)}"), list(batch[start:])
            for t in in_flight:
                Path(claim_dir, t.key).unlink()
                accept(t, {"key": t.key, "ok": True, "stepper": t.cell.stepper})
        return None, []


def test_a_silent_worker_death_is_pinned_on_its_cell_by_rerunning_alone(monkeypatch):
    pool = _FakePool(silent={"bad"})
    monkeypatch.setattr(runner.executors, "loky_batch", pool)
    names = ["a", "bad", "b", "c", "d"]
    tasks = [runner.Task(i, Cell("toy", n, "p"), f"{i:032x}", {"timeout": None})
             for i, n in enumerate(names)]
    outcomes = {}
    runner.run_loky(tasks, 2, lambda t, out: outcomes.__setitem__(t.cell.stepper, out))
    assert set(outcomes) == set(names)
    assert outcomes["bad"]["kind"] == "crash" and "EXIT(3)" in outcomes["bad"]["message"]
    assert all(outcomes[n]["ok"] for n in names if n != "bad")
    # a and bad were in flight: both rerun alone; b, c, d never started: resubmitted together
    assert pool.batches == [(names, 2), (["b", "c", "d"], 2), (["a"], 1), (["bad"], 1)]


def test_a_stepper_that_cannot_be_fingerprinted_is_a_failed_cell(run, monkeypatch):
    def broken():
        raise RuntimeError("no source")

    monkeypatch.setattr(registry.get_stepper("toy-alt"), "fingerprint", broken)
    r = run()
    assert r.n_failed == 3 and set(r.failures.kind) == {"lookup"}
    assert r.failures.message.str.contains("RuntimeError: no source").all()
    assert r.computed_cells == 6 and set(r.rows.stepper) == {"toy-ok"}


def test_a_summary_that_raises_is_a_failure_and_keeps_the_rows(run):
    r = run(config={"break_summary": True})
    assert len(r.rows) == 27 and r.summary.empty
    assert r.failures.to_dict("records")[0]["kind"] == "summarize"
    assert "toy summary broke" in r.failures.message[0]


def test_an_experiment_that_cannot_list_its_cells_raises_experiment_error(run, monkeypatch):
    def broken(self, steppers, problems, config):
        raise KeyError("missing setting")

    monkeypatch.setattr(ToyExperiment, "cells", broken)
    with pytest.raises(ExperimentError, match="experiment 'toy' could not list its cells: KeyError"):
        run()


def _pack_of(result, cache_dir: Path) -> Path:
    cache = CellCache(cache_dir)
    return cache.pack_path(cache.pack_key(result.experiment, list(result.cells.key)))


@pytest.mark.parametrize("damaged", ["cell", "pack"])
def test_a_corrupt_cache_file_is_discarded_with_a_warning_and_recomputed(run, tmp_path, damaged,
                                                                        capsys):
    """A damaged cell file (read when the run is not one whole pack) or a damaged pack is only a
    damaged copy: named in one warning line, removed, its cells computed again; the next run is
    served from the cache."""
    first = run()
    pack = _pack_of(first, tmp_path / "cache")
    assert pack.is_file()
    if damaged == "cell":
        victim = CellCache(tmp_path / "cache").path(first.cells.key[0])
        pack.unlink()  # the cells are read one by one
    else:
        victim = pack
    victim.write_bytes(b"not parquet at all")
    capsys.readouterr()
    repaired = run()
    err = capsys.readouterr().err
    warned = [ln for ln in err.splitlines() if "damaged cache entry" in ln]
    assert len(warned) == 1 and str(victim) in warned[0] and "not a readable Parquet file" in warned[0]
    assert repaired.computed_cells == (1 if damaged == "cell" else 0)  # a pack: its cells remain
    pd.testing.assert_frame_equal(first.rows, repaired.rows)
    again = run()
    assert again.cached_cells == 9 and again.computed_cells == 0
    pd.testing.assert_frame_equal(first.rows, again.rows)


def test_a_run_of_cached_cells_reads_one_pack_and_equals_the_fresh_run(run, tmp_path):
    first = run()
    cells = CellCache(tmp_path / "cache").root
    for f in cells.rglob("*.parquet"):  # only the pack remains: the run must not need the cells
        f.unlink()
    again = run()
    assert again.cached_cells == 9 and again.computed_cells == 0
    pd.testing.assert_frame_equal(first.rows, again.rows)
    pd.testing.assert_frame_equal(first.summary, again.summary)
    assert list(again.cells.wall_s) == list(first.cells.wall_s)
    # a packed run's rows are in their stored form: the saved file decodes to an equal frame
    assert first.rows_stored and again.rows_stored
    saved = save_run([again], root=tmp_path / "runs")
    pd.testing.assert_frame_equal(load_run(saved).rows[again.experiment], again.rows, check_exact=True)
    # one cell fewer is another pack: read cell by cell (and the cells are gone: recomputed)
    fewer = run(problems=("toy-decay",))
    assert fewer.computed_cells == len(fewer.cells) > 0


# -- arguments ------------------------------------------------------------------------------------
BAD_ARGUMENTS = [
    ({"jobs": 0}, InputError, r"`jobs` must be between 1 and"),
    ({"jobs": "2"}, InputError, r"`jobs` must be a whole number"),
    ({"jobs": True}, InputError, r"`jobs` must be a whole number"),
    ({"jobs": 10**6}, InputError, r"`jobs` must be between 1 and"),
    ({"cell_timeout": -1}, InputError, r"`cell_timeout` must be positive"),
    ({"cell_timeout": float("nan")}, InputError, r"`cell_timeout` must be positive"),
    ({"cell_timeout": "soon"}, InputError, r"`cell_timeout` must be a number"),
    ({"scheduler": "http://example.org"}, InputError, r"`scheduler` must be a Dask scheduler"),
    ({"scheduler": 8786}, InputError, r"`scheduler` must be a Dask scheduler"),
    ({"config": {"bogus": 1}}, InputError, r"`config` sets 'bogus', not settings of experiment"),
    ({"config": [("n", 1)]}, InputError, r"`config` must be a mapping"),
    ({"steppers": [""]}, InputError, r"`steppers` must hold non-empty names"),
    ({"steppers": ["<b>nope</b>"]}, UnknownNameError, r"unknown stepper '<b>nope</b>'"),
    ({"problems": [3]}, InputError, r"`problems` must hold non-empty names"),
    ({"fresh": "yes"}, InputError, r"`fresh` must be True or False"),
    ({"progress": 5}, InputError, r"`progress` must be None"),
    ({"plugins": [""]}, InputError, r"`plugins` must hold \.py file paths"),
]


@pytest.mark.parametrize(("kwargs", "error", "match"), BAD_ARGUMENTS,
                         ids=[next(iter(k)) + "-" + str(i) for i, (k, _, _) in enumerate(BAD_ARGUMENTS)])
def test_bad_arguments_raise_before_any_cell_runs(run, kwargs, error, match):
    with pytest.raises(error, match=match):
        run(**kwargs)
    assert sum(CALLS.values()) == 0


@pytest.mark.parametrize(("experiment", "match"), [
    ("nope", r"unknown experiment 'nope'"),
    ("", r"`experiment` must be an experiment name"),
    (None, r"`experiment` must be an experiment name"),
])
def test_unknown_experiment_names(toy, experiment, match):
    with pytest.raises(HarnessError, match=match):
        run_experiment(experiment, progress=False)


def test_unreachable_scheduler_is_an_input_error(run, monkeypatch):
    monkeypatch.setattr(runner.executors, "DASK_CONNECT_TIMEOUT_S", 1)
    with pytest.raises(InputError, match=r"`scheduler` 'tcp://127.0.0.1:9': cannot connect"):
        run(scheduler="tcp://127.0.0.1:9")


# -- memory guard ---------------------------------------------------------------------------------
def test_a_run_that_would_exceed_memory_is_refused_up_front(run):
    with pytest.raises(InputError, match=r"`ensemble`: 1000000000000, toy cell .* needs an "
                                         r"estimated .* more than the .* available"):
        run(config={"ensemble": 10**12})
    assert sum(CALLS.values()) == 0


def test_memory_estimate_and_check():
    assert estimate_bytes(dim=4, ensemble=1000, saved_states=2, work_arrays=16) == 8 * 4 * 1000 * 18
    check_memory(10**6, argument="ensemble", available=10**9)
    with pytest.raises(InputError, match=r"`ensemble`: needs an estimated 9\.3 GB, more than the "
                                         r"800\.0 MB available \(80% of 1000\.0 MB free\)"):
        check_memory(10 * 10**9, argument="ensemble", available=1000 * 2**20)
    with pytest.raises(InputError, match=r"`ensemble` must be at least 1, got 0"):
        estimate_bytes(dim=2, ensemble=0)
    with pytest.raises(InputError, match=r"`dim` must be a whole number, got 2.5"):
        estimate_bytes(dim=2.5)


# -- rows validation ------------------------------------------------------------------------------
GOOD = pd.DataFrame({"j": [0, 1], "value": [1.0, 2.0], "label": ["a", "b"]})
BAD_ROWS = [
    ({"a": 1}, r"run_cell returned dict, expected a pandas DataFrame"),
    (GOOD.iloc[:0], r"run_cell returned no rows"),
    (pd.DataFrame({0: [1.0]}), r"column names must be non-empty strings"),
    (pd.DataFrame([[1.0, 2.0]], columns=["j", "j"]), r"column names must be distinct, repeated: \['j'\]"),
    (GOOD.assign(z=[1j, 2j]), r"column 'z' is complex"),
    (GOOD.assign(obj=[[1, 2], [3]]), r"column 'obj' holds list values"),
    (GOOD.drop(columns="j"), r"column 'j' is missing \(declared in `row_dtypes`\)"),
    (GOOD.assign(j=["0", "1"]), r"column 'j' has dtype .*, declared int"),
    (GOOD.assign(value=[1.0, np.inf]), r"column 'value' has 1 non-finite value"),
]


@pytest.mark.parametrize(("rows", "match"), BAD_ROWS)
def test_validate_rows_names_what_is_wrong(rows, match):
    with pytest.raises(CellOutputError, match=match):
        validate_rows(ToyExperiment(), rows)


def test_validate_rows_accepts_plain_tidy_rows_and_undeclared_nan():
    rows = GOOD.assign(error=[np.nan, np.inf], ok=[True, False])
    assert validate_rows(ToyExperiment(), rows) is rows


# -- time limit -----------------------------------------------------------------------------------
def test_time_limit_interrupts_and_restores_an_outer_limit():
    with runner.time_limit(600.0):
        with pytest.raises(runner.CellTimeout, match="timeout after 0.2 s"):
            with runner.time_limit(0.2):
                time.sleep(60)
        remaining = signal.getitimer(signal.ITIMER_REAL)[0]
        assert 0.0 < remaining <= 600.0  # the outer limit is running again, never extended
    assert signal.getitimer(signal.ITIMER_REAL)[0] == 0.0


# -- progress -------------------------------------------------------------------------------------
def test_progress_lines_are_sparse_plain_and_end_with_the_totals(run, monkeypatch):
    monkeypatch.setattr("harness.progress.LINE_MIN_GAP_S", 0.0)
    stream = io.StringIO()
    bar = Progress(0, "toy", stream=stream, mode="lines")
    run(steppers=["toy-ok", "toy-raise"], problems=["toy-decay", "toy-growth"], progress=bar)
    bar.close()
    text = stream.getvalue()
    lines = text.splitlines()
    assert "\r" not in text
    assert 1 <= len(lines) <= 11  # one per tenth at most, plus the first
    assert lines[-1].startswith("toy: 12/12 cells (100%), ") and lines[-1].endswith(", 6 failed")


def test_progress_lines_respect_the_interval_between_tenths():
    stream = io.StringIO()
    with Progress(1000, "grid", stream=stream, mode="lines", interval=3600) as bar:
        for _ in range(1000):
            bar.update(1)
    lines = stream.getvalue().splitlines()
    assert 1 <= len(lines) <= 3  # the first update, maybe one tenth, and the close
    assert lines[-1].startswith("grid: 1000/1000 cells (100%)")


class _FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_mode_is_a_bar_on_a_terminal_outside_ci(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    assert choose_mode(_FakeTerminal()) == "bar"
    assert choose_mode(io.StringIO()) == "lines"
    monkeypatch.setenv("CI", "true")
    assert choose_mode(_FakeTerminal()) == "lines"
    monkeypatch.delenv("CI")
    stream = _FakeTerminal()
    with Progress(3, "toy", stream=stream) as bar:
        bar.update(2, failed=1)
        bar.update(1)
    assert bar.mode == "bar" and "3/3" in stream.getvalue() and "1 failed" in stream.getvalue()


def test_run_experiments_shares_one_progress_and_returns_each_result(toy, tmp_path):
    stream = io.StringIO()
    bar = Progress(0, "all", stream=stream, mode="lines")
    out = run_experiments(["toy"], ["toy-ok"], ["toy-decay"], configs={"toy": {"n": 2}}, jobs=1,
                          cache_dir=tmp_path, plugins=[toy], progress=bar)
    bar.close()
    assert list(out) == ["toy"] and out["toy"].n_cells == 2 and bar.total == 2
    assert stream.getvalue().splitlines()[-1].startswith("[1/1] toy: 2/2 cells (100%)")
    with pytest.raises(UnknownNameError, match="`configs` names experiments not being run"):
        run_experiments(["toy"], configs={"other": {}}, progress=False)


def test_failed_record_has_the_documented_columns(run):
    r = run(steppers=["toy-raise"], problems=["toy-decay"], config={"n": 1})
    assert list(r.failures.columns) == runner.FAILURE_COLUMNS
    rec = r.failures.iloc[0]
    assert rec.cell == "toy:toy-raise:toy-decay[k=0]" and json.loads(rec.params) == {"k": 0}
    assert set(r.failures.kind) <= set(runner.FAILURE_KINDS)


def test_one_options_object_equals_the_keywords(run, toy):
    by_keywords = run(cache=False)
    options = runner.RunOptions(jobs=1, cache=False, plugins=(str(toy),))
    by_object = run_experiment("toy", ["toy-ok", "toy-alt"], ["toy-decay", "toy-growth"],
                               options=options, progress=False)
    pd.testing.assert_frame_equal(by_keywords.rows, by_object.rows)
    assert by_object.options["cache"] is False and by_object.options["jobs"] == 1
    with pytest.raises(InputError, match=r"`options` must be a RunOptions, got dict"):
        run(options={"jobs": 1})


def test_workers_take_the_problems_in_turn_and_results_keep_the_cell_order():
    from harness.runner.orchestration import interleaved

    cells = [Cell("toy", s, p) for p in ("p", "q", "r") for s in ("a", "b", "c", "d")][:-1]
    tasks = [runner.Task(i, c, f"{i:032x}", {}) for i, c in enumerate(cells)]
    order = [(t.cell.stepper, t.cell.problem) for t in interleaved(tasks)]
    # the problems in turn, every other one's list started halfway: neighbours differ in both
    assert order == [("a", "p"), ("c", "q"), ("a", "r"), ("b", "p"), ("d", "q"), ("b", "r"),
                     ("c", "p"), ("a", "q"), ("c", "r"), ("d", "p"), ("b", "q")]
    assert sorted(t.index for t in interleaved(tasks)) == list(range(len(tasks)))
    assert interleaved([]) == []


def test_a_parallel_run_equals_the_serial_one_whatever_order_workers_took(run):
    serial = run(jobs=1)
    parallel = run(jobs=2, fresh=True)
    pd.testing.assert_frame_equal(serial.rows.drop(columns="wall_s", errors="ignore"),
                                  parallel.rows.drop(columns="wall_s", errors="ignore"))
    assert list(parallel.cells.cell) == list(serial.cells.cell)


def test_run_experiments_names_an_unknown_run_option():
    with pytest.raises(InputError, match="unknown keyword.*jbos"):
        run_experiments(["toy"], ["toy-ok"], ["toy-decay"], jbos=1, progress=False)
