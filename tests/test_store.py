"""The results store: atomic writes, corrupt and foreign files refused with their path, saved runs
round-tripped with their provenance, `harness.results.load`."""

from __future__ import annotations

import datetime as dt
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from harness import provenance, results, store
from harness.errors import HarnessError, InputError, OutputError, UnknownNameError
from harness.runner import RunResult
from harness.store import (
    CellCache,
    CorruptResultsError,
    ResultsError,
    atomic_write_bytes,
    list_runs,
    load_run,
    new_run_id,
    read_parquet,
    save_run,
    write_parquet,
)

ROOT = Path(__file__).resolve().parent.parent


def _result(name: str, n: int = 4, *, failed: bool = True) -> RunResult:
    """A RunResult as the runner builds it, with deterministic content."""
    rows = pd.DataFrame({
        "experiment": name,
        "cell": [f"{name}:s{i % 2}:p" for i in range(n)],
        "stepper": [f"s{i % 2}" for i in range(n)],
        "problem": "p",
        "h": 0.5 ** np.arange(n),
        "error": [1e-3, 1e-5, np.inf, np.nan][:n],
        "n_steps": np.arange(n, dtype=np.int64) + 1,
        "excluded": ["", "roundoff", "blow-up", ""][:n],
        "in_fit": [True, False, False, True][:n],
    })
    summary = pd.DataFrame({"stepper": ["s0", "s1"], "problem": "p",
                            "measured_order": [2.01, np.nan], "verdict": ["converged", "unstable"]})
    failures = pd.DataFrame([{
        "experiment": name, "cell": f"{name}:bad:p", "stepper": "bad", "problem": "p",
        "params": "{}", "key": "0" * 32, "kind": "error", "message": "RuntimeError: <b>boom</b>",
        "traceback": "Traceback ...\nRuntimeError: <b>boom</b>",
    }] if failed else [], columns=["experiment", "cell", "stepper", "problem", "params", "key",
                                   "kind", "message", "traceback"])
    skips = pd.DataFrame([{"experiment": name, "stepper": "s1", "problem": "q", "reason": "n/a"}])
    cells = pd.DataFrame([{"experiment": name, "cell": f"{name}:s0:p", "stepper": "s0",
                           "problem": "p", "params": "{}", "key": "1" * 32, "status": "ok",
                           "cached": False, "wall_s": 0.25, "n_rows": n, "worker": "host:1"}])
    return RunResult(experiment=name, description="a test experiment",
                     config={"ensemble": 4, "tol": [1e-3, 1e-6]}, rows=rows, summary=summary,
                     failures=failures, skips=skips, cells=cells, wall_s=1.5, cached_cells=0,
                     computed_cells=2)


# -- atomic writes --------------------------------------------------------------------------------
def test_a_failed_write_leaves_the_previous_file_intact(tmp_path, monkeypatch):
    target = tmp_path / "table.bin"
    atomic_write_bytes(target, b"old content")

    def crash(src, dst):
        raise OSError("disk vanished between write and rename")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OutputError, match=r"table.bin': disk vanished") as info:
        atomic_write_bytes(target, b"new content that never lands")
    assert isinstance(info.value, OSError) and "\n" not in str(info.value)
    assert target.read_bytes() == b"old content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.bin"]  # temp file removed


def test_a_process_killed_between_write_and_rename_leaves_the_old_file(tmp_path):
    """The process dies (os._exit, no cleanup) after the temporary file is complete and before
    the rename: the target keeps its old content and readers ignore the leftover."""
    cache = CellCache(tmp_path)
    key = "ab" * 16
    old = pd.DataFrame({"x": [1.0, 2.0]})
    cache.put(key, old, {"cell": "old"})
    script = textwrap.dedent(f"""
        import os, pandas as pd
        from harness.store import CellCache
        os.replace = lambda src, dst: os._exit(9)
        CellCache({str(tmp_path)!r}).put({key!r}, pd.DataFrame({{"x": [3.0]}}), {{"cell": "new"}})
    """)
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, timeout=120)
    assert proc.returncode == 9, proc.stderr.decode()
    leftovers = [p.name for p in cache.path(key).parent.iterdir() if p.name.endswith(".tmp")]
    assert len(leftovers) == 1 and leftovers[0].startswith(".")  # hidden, and never read
    rows, info = cache.get(key)
    pd.testing.assert_frame_equal(rows, old)
    assert info["cell"] == "old" and len(cache) == 1


def test_write_parquet_refuses_unstorable_tables_without_touching_the_file(tmp_path):
    target = tmp_path / "t.parquet"
    write_parquet(target, pd.DataFrame({"x": [1]}))
    before = target.read_bytes()
    with pytest.raises(InputError, match="table cannot be stored as Parquet"):
        write_parquet(target, pd.DataFrame({"x": [object(), object()]}))
    with pytest.raises(InputError, match="must be a pandas DataFrame, got list"):
        write_parquet(target, [1, 2])
    assert target.read_bytes() == before


# -- corrupt and foreign files --------------------------------------------------------------------
def test_a_corrupt_parquet_file_raises_with_its_path(tmp_path):
    run = save_run([_result("convergence")], root=tmp_path)
    rows = run / "convergence.rows.parquet"
    rows.write_bytes(rows.read_bytes()[:-40])  # truncated
    with pytest.raises(CorruptResultsError, match="changed after the run was saved") as info:
        load_run(run)
    assert info.value.path == rows and str(rows) in str(info.value)
    with pytest.raises(CorruptResultsError, match="not a readable Parquet file") as info:
        read_parquet(rows)
    assert str(rows) in str(info.value)


def test_a_table_with_other_columns_is_refused_even_with_a_matching_checksum(tmp_path):
    run = save_run([_result("convergence")], root=tmp_path)
    meta = json.loads((run / "meta.json").read_text())
    digest = write_parquet(run / "convergence.summary.parquet", pd.DataFrame({"other": [1, 2]}))
    meta["experiments"]["convergence"]["tables"]["summary"]["sha256"] = digest
    (run / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(CorruptResultsError, match=r"columns \['other'\] differ from the recorded"):
        load_run(run)


def test_missing_table_file_is_named(tmp_path):
    run = save_run([_result("energy")], root=tmp_path)
    (run / "energy.summary.parquet").unlink()
    with pytest.raises(CorruptResultsError, match="energy.summary.parquet': missing"):
        load_run(run)


FOREIGN_META = [
    ("[1, 2]", r"expected a JSON object, got list"),
    ("{not json", r"not valid JSON"),
    ('{"name": "something else"}', r"not a harness meta.json \(no `schema` key\)"),
    ('{"schema": "harness-results/0"}', r"schema 'harness-results/0' is not the one this harness reads"),
    ('{"schema": "harness-results/1", "run_id": "x"}', r"missing keys \['created_utc'"),
]


@pytest.mark.parametrize(("text", "match"), FOREIGN_META)
def test_a_foreign_meta_json_raises_with_its_path(tmp_path, text, match):
    run = save_run([_result("convergence")], root=tmp_path)
    (run / "meta.json").write_text(text)
    with pytest.raises(CorruptResultsError, match=match) as info:
        load_run(run)
    assert str(run / "meta.json") in str(info.value)


def test_meta_json_with_a_broken_experiment_entry_is_refused(tmp_path):
    run = save_run([_result("convergence")], root=tmp_path)
    meta = json.loads((run / "meta.json").read_text())
    del meta["experiments"]["convergence"]["tables"]
    (run / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(CorruptResultsError, match=r"experiment 'convergence' is missing keys \['tables'\]"):
        load_run(run)


def test_a_foreign_cell_file_is_refused(tmp_path):
    cache = CellCache(tmp_path)
    key, other = "cd" * 16, "ef" * 16
    cache.put(other, pd.DataFrame({"x": [1.0]}), {})
    cache.path(key).parent.mkdir(parents=True, exist_ok=True)
    cache.path(key).write_bytes(cache.path(other).read_bytes())
    with pytest.raises(CorruptResultsError, match=f"holds cell '{other}', not '{key}'"):
        cache.get(key)
    write_parquet(cache.path(key), pd.DataFrame({"x": [1.0]}))  # no harness metadata at all
    with pytest.raises(CorruptResultsError, match="not a harness cell file"):
        cache.get(key)
    assert cache.get("00" * 16) is None


# -- saved runs -----------------------------------------------------------------------------------
def test_save_and_load_round_trip_rows_summary_and_meta(tmp_path):
    saved = [_result("convergence"), _result("energy", n=3, failed=False)]
    path = save_run(saved, root=tmp_path, config={"command": "report", "jobs": 2, "quick": True})
    assert path.parent == tmp_path and store.RUN_ID.match(path.name)
    run = load_run(root=tmp_path)
    assert run.run_id == path.name and run.experiments == ["convergence", "energy"]
    for res in saved:
        pd.testing.assert_frame_equal(run.rows[res.experiment], res.rows)
        pd.testing.assert_frame_equal(run.summaries[res.experiment], res.summary)
    meta = run.meta
    assert meta["schema"] == store.SCHEMA and meta["config"]["run"]["jobs"] == 2
    assert meta["config"]["experiments"]["convergence"] == {"ensemble": 4, "tol": [1e-3, 1e-6]}
    prov = meta["provenance"]
    assert set(prov["versions"]) >= {"python", "numpy", "scipy", "heyoka", "pandas", "matplotlib",
                                     "harness"}
    assert prov["versions"]["numpy"] == np.__version__ and prov["machine"]["cpu"]
    assert dt.datetime.fromisoformat(prov["date_utc"]).tzinfo is not None
    assert run.wall_s == {"convergence": 1.5, "energy": 1.5}
    assert meta["totals"] == {"cells": 2, "computed": 4, "cached": 0, "failed": 1, "skipped": 2,
                              "wall_s": 3.0}
    assert run.n_failed == 1 and run.failures.message.tolist() == ["RuntimeError: <b>boom</b>"]
    assert list(run.skips.columns) == ["experiment", "stepper", "problem", "reason"]


def test_a_run_loads_its_summaries_alone_or_with_rows_already_in_stored_form(tmp_path):
    saved = [_result("convergence"), _result("energy", n=3, failed=False)]
    path = save_run(saved, root=tmp_path)
    light = load_run(path, tables=("summary",))
    assert light.rows == {} and set(light.summaries) == {"convergence", "energy"}
    full = load_run(path)
    # rows decoded from Parquet are taken as they are; the others are read from their files
    given = {"energy": full.rows["energy"]}
    run = load_run(path, stored_rows=given)
    assert run.rows["energy"] is given["energy"]
    pd.testing.assert_frame_equal(run.rows["convergence"], full.rows["convergence"])
    # a frame that is not the saved table is refused like a damaged file, with the file's path
    with pytest.raises(CorruptResultsError, match="energy.rows.parquet.*has 2 rows"):
        load_run(path, stored_rows={"energy": full.rows["energy"].iloc[:2]})
    with pytest.raises(CorruptResultsError, match="columns .* differ"):
        load_run(path, stored_rows={"energy": full.rows["energy"].drop(columns="h")})
    with pytest.raises(InputError, match="`tables` must list tables among"):
        load_run(path, tables=("rows", "plots"))
    with pytest.raises(InputError, match="`tables` must list tables among"):
        load_run(path, tables="rows")


def test_results_load_returns_dataframes(tmp_path):
    saved = [_result("convergence"), _result("energy", n=3, failed=False)]
    save_run(saved, root=tmp_path)
    conv = results.load(experiment="convergence", root=tmp_path)
    pd.testing.assert_frame_equal(conv, saved[0].rows)
    both = results.load(root=tmp_path)
    assert len(both) == 7 and list(both.experiment.unique()) == ["convergence", "energy"]
    summary = results.load("latest", "energy", table="summary", root=tmp_path)
    assert summary.columns[0] == "experiment" and len(summary) == 2
    assert len(results.load(table="failures", root=tmp_path)) == 1
    assert results.load(table="cells", root=tmp_path).wall_s.tolist() == [0.25, 0.25]
    assert results.meta(root=tmp_path)["schema"] == store.SCHEMA
    assert results.runs(tmp_path) == list_runs(tmp_path)
    with pytest.raises(UnknownNameError, match=r"`experiment` 'stability' is not in run"):
        results.load(experiment="stability", root=tmp_path)
    with pytest.raises(InputError, match=r"`table` must be one of rows, summary"):
        results.load(table="everything", root=tmp_path)


def test_the_results_root_comes_from_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("HARNESS_RESULTS_DIR", str(tmp_path / "elsewhere"))
    path = save_run([_result("convergence")])
    assert path.parent == tmp_path / "elsewhere"
    assert results.load(experiment="convergence").shape == (4, 9)


def test_run_ids_sort_by_time_and_latest_is_the_newest(tmp_path):
    t0 = dt.datetime(2030, 1, 2, 3, 4, 5, tzinfo=dt.UTC)
    first = new_run_id(tmp_path, short_sha="abc1234", now=t0)
    assert first == "20300102T030405Z-abc1234"
    ids = []
    for _ in range(12):  # twelve runs in one second sort in order of creation
        rid = new_run_id(tmp_path, short_sha="abc1234", now=t0)
        save_run([_result("convergence")], root=tmp_path, run_id=rid)
        ids.append(rid)
    later = new_run_id(tmp_path, short_sha="0000000", now=t0 + dt.timedelta(seconds=1))
    save_run([_result("energy")], root=tmp_path, run_id=later)
    assert ids[1] == "20300102T030405Z-abc1234-2" and ids[11] == "20300102T030405Z-abc1234-12"
    assert list_runs(tmp_path) == ids + [later]
    assert load_run("latest", root=tmp_path).run_id == later
    assert load_run(ids[3], root=tmp_path).run_id == ids[3]


def test_a_saved_run_is_never_overwritten_and_bad_names_leave_nothing(tmp_path):
    path = save_run([_result("convergence")], root=tmp_path, run_id="baseline")
    with pytest.raises(ResultsError, match="already exists; a saved run is never overwritten"):
        save_run([_result("energy")], root=tmp_path, run_id="baseline")
    assert load_run(path).experiments == ["convergence"]
    for bad in ("../escape", "<script>", "a/b", ""):
        with pytest.raises(InputError):
            save_run([_result(bad)], root=tmp_path)
    with pytest.raises(InputError, match="names an experiment twice"):
        save_run([_result("x"), _result("x")], root=tmp_path)
    assert sorted(os.listdir(tmp_path)) == ["baseline"]


def test_a_save_that_fails_midway_leaves_no_run(tmp_path):
    bad = _result("energy")
    bad.summary = pd.DataFrame({"x": [object()]})
    with pytest.raises(InputError, match="experiment 'energy', summary: table cannot be stored"):
        save_run([_result("convergence"), bad], root=tmp_path)
    assert os.listdir(tmp_path) == []


def test_a_staging_directory_of_a_killed_save_is_cleaned_up(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".staging-20300101T000000Z-abc@{dead.pid}"
    stale.mkdir()
    (stale / "meta.json").write_text("{}")
    save_run([_result("convergence")], root=tmp_path)
    assert not stale.exists() and len(list_runs(tmp_path)) == 1


@pytest.mark.parametrize(("run", "error", "match"), [
    ("nope", UnknownNameError, r"`run` 'nope' is neither a saved run"),
    (42, InputError, r"`run` must be a run id, 'latest', or a path, got int"),
    ("", InputError, r"`run` must be a run id"),
    ("../nope/../x", UnknownNameError, r"is neither a saved run"),
])
def test_unknown_runs_are_named(tmp_path, run, error, match):
    save_run([_result("convergence")], root=tmp_path)
    with pytest.raises(error, match=match):
        load_run(run, root=tmp_path)
    plain = tmp_path / "plain"
    plain.mkdir(exist_ok=True)
    with pytest.raises(ResultsError, match=r"is a directory but not a saved run \(no meta.json\)"):
        load_run(plain, root=tmp_path)


def test_an_empty_results_directory_says_so(tmp_path):
    with pytest.raises(ResultsError, match="no saved runs under"):
        results.load(root=tmp_path / "none")


def test_foreign_directories_in_the_results_root_are_ignored(tmp_path):
    (tmp_path / "notes").mkdir()
    (tmp_path / "README.md").write_text("hi")
    path = save_run([_result("convergence")], root=tmp_path)
    assert list_runs(tmp_path) == [path.name]


# -- provenance -----------------------------------------------------------------------------------
def test_git_provenance_of_the_project_and_of_a_directory_without_git(tmp_path):
    info = provenance.git_info(tmp_path)
    assert info == {"sha": None, "short_sha": None, "dirty": None, "available": False}
    here = provenance.git_info()
    if (ROOT / ".git").exists():
        assert len(here["sha"]) == 40 and here["short_sha"] == here["sha"][:7]
        assert isinstance(here["dirty"], bool)


def test_configuration_is_stored_as_plain_json():
    value = {"a": np.float64(1.5), "b": (1, 2), "c": np.array([1, 2]), "d": float("inf"),
             "e": {np.int64(3)}, "f": Path("x")}
    assert provenance.to_jsonable(value) == {"a": 1.5, "b": [1, 2], "c": [1, 2], "d": "inf",
                                             "e": [3], "f": "x"}
    assert isinstance(HarnessError(), Exception)
