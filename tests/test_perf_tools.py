"""Performance tooling: the asv configuration and suites, the regression check, the history
loader.

The regression check is shown failing for real: a throwaway git repository with a one-module
package and one asv benchmark, three commits (the second only edits a comment, the third makes
the benchmarked function five times slower), and `asv continuous --factor 1.2
--interleave-rounds` (as `make perf-check` runs it) between them:
exit code 0 for the unchanged pair, 1 for the slowed one. asv's virtual environment for it is
kept in the project's cache directory, so only the first run on a machine builds it (~30 s;
it needs the package index that `scripts/bootstrap` uses).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from harness.cache import cache_dir
from harness.errors import InputError
from harness.perf_history import HISTORY_COLUMNS, load_history

ROOT = Path(__file__).resolve().parent.parent
VENV_BIN = Path(sys.executable).parent


def _asv_conf() -> dict:
    from asv.util import load_json

    return load_json(str(ROOT / "asv.conf.json"), js_comments=True)


def _pins() -> dict[str, str]:
    pins = {}
    for line in (ROOT / "requirements.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if "==" in line:
            name, version = line.split("==", 1)
            pins[re.sub(r"[-_.]+", "-", name.lower())] = version.strip()
    return pins


# -- configuration ----------------------------------------------------------------------------
def test_asv_writes_only_under_dot_asv_and_builds_a_wheel():
    conf = _asv_conf()
    for key in ("env_dir", "results_dir", "html_dir"):
        assert Path(conf[key]).parts[0] == ".asv", key
    assert conf["build_command"] == ["python -m build --wheel -o {build_cache_dir} {build_dir}"]
    assert (ROOT / conf["benchmark_dir"] / "__init__.py").is_file()
    assert conf["pythons"] == ["3.11"]


def test_asv_environments_use_the_project_pins():
    conf = _asv_conf()
    pins = _pins()
    assert any("-r {build_dir}/requirements.txt" in c for c in conf["install_command"])
    assert any("--no-deps" in c and "{wheel_file}" in c for c in conf["install_command"])
    for key, versions in conf["matrix"]["req"].items():
        name = re.sub(r"[-_.]+", "-", key.removeprefix("pip+").lower())
        assert versions == [pins[name]], f"{key} in asv.conf.json differs from requirements.txt"


@pytest.mark.parametrize("path", ["asv.conf.json", "scripts/nightly", "scripts/bench"])
def test_no_package_index_address_in_committed_files(path):
    text = (ROOT / path).read_text()
    assert not re.search(r"(index-url|find-links|pypi\.org|/simple\b)", text), path


def test_make_targets_call_the_scripts():
    text = (ROOT / "Makefile").read_text()
    for target, command in (("nightly", "scripts/nightly"), ("perf-check", "scripts/nightly check"),
                            ("bench", "scripts/bench")):
        assert re.search(rf"^{target}: setup\n\t@{re.escape(command)}$", text, re.M), target


# -- the suites -------------------------------------------------------------------------------
def test_suites_are_parameterised_over_the_registry():
    from benchmarks import bench_accuracy, bench_steppers
    from harness.registry import steppers

    names = steppers.names(variants=True)
    assert bench_steppers.StepTime.params[0] == names
    assert bench_steppers.StepTime.params[2] == [1, 1_000, 100_000]
    assert bench_steppers.RatioToC.params[0] == names
    assert bench_accuracy.MeasuredOrder.params[0] == names
    assert {"velocity-verlet@compiled", "rk4@compiled"} <= set(names)


@pytest.mark.parametrize(
    "stepper,problem,ensemble,reason",
    [
        ("velocity-verlet", "gaussian", 1, "does not apply"),
        ("scipy-rk45", "kepler-elliptic", 1000, "timed up to 1 members"),
        ("taylor", "kepler-elliptic", 100_000, "timed up to 1000 members"),
        ("no-such-stepper", "harmonic", 1, "no-such-stepper"),
    ],
)
def test_setup_skips_pairs_that_do_not_apply(stepper, problem, ensemble, reason):
    from benchmarks.bench_steppers import StepTime

    with pytest.raises(NotImplementedError, match=reason):
        StepTime().setup(stepper, problem, ensemble)


@pytest.mark.parametrize(
    "suite,column",
    [("MeasuredOrder", "measured_order"), ("EnergyDriftSlope", "drift_slope"),
     ("MaxEnergyError", "max_rel_energy_error"), ("Reversibility", "return_error_ulps")],
)
def test_accuracy_suites_skip_in_setup_and_track_the_column(suite, column):
    """asv counts NotImplementedError as a skip only from `setup`; from the benchmark body it is
    a failure. So every missing or non-finite value must stop in `setup`."""
    from benchmarks import bench_accuracy

    bench = getattr(bench_accuracy, suite)()
    track = next(getattr(bench, n) for n in dir(bench) if n.startswith("track_"))
    results = {"summary": [{"stepper": "a", column: 2.5, "verdict": "ok"},
                           {"stepper": "b", column: float("nan"), "verdict": "bounded"}]}
    bench.setup(results, "a")
    assert track(results, "a") == 2.5
    with pytest.raises(NotImplementedError, match="not a finite number"):
        bench.setup(results, "b")
    with pytest.raises(NotImplementedError, match=f"no {column} for c"):
        bench.setup(results, "c")
    with pytest.raises(NotImplementedError, match="older commit"):
        bench.setup({"_error": "older commit: no such experiment"}, "a")


def test_the_energy_columns_share_one_run_of_the_energy_experiment():
    """asv keys a setup_cache by the function's place in the source: one function, one run."""
    from benchmarks import bench_accuracy as b

    assert b.EnergyDriftSlope.setup_cache is b.MaxEnergyError.setup_cache
    assert b.EnergyDriftSlope.setup_cache is not b.MeasuredOrder.setup_cache


def test_one_step_benchmark_advances_one_step():
    from benchmarks.bench_steppers import StepTime

    bench = StepTime()
    bench.setup("velocity-verlet@compiled", "kepler-elliptic", 1_000)
    before = bench.carry.y.copy()
    n = bench.carry.n
    bench.time_step("velocity-verlet@compiled", "kepler-elliptic", 1_000)
    assert bench.carry.n == n + 1
    assert not np.array_equal(before, bench.carry.y)


def test_ratio_to_the_c_loop_is_measured_in_one_run():
    from benchmarks.bench_steppers import RatioToC
    from benchmarks.c_baseline.build import CompilerUnavailable, load

    try:
        baseline = load()
    except CompilerUnavailable as exc:
        pytest.skip(f"no C compiler on this machine: {exc}")
    assert "-O3" in baseline.flags and not any(f.startswith("-march") for f in baseline.flags)
    bench = RatioToC()
    bench.setup("velocity-verlet@compiled", 1)
    ratio = bench.track_ratio_to_c("velocity-verlet@compiled", 1)
    assert np.isfinite(ratio) and ratio > 0


def test_c_loops_compute_the_harness_methods():
    """The baseline times the same arithmetic: its velocity Verlet equals the compiled stepper's
    to rounding and its RK4 the NumPy RK4's (on Kepler, 1000 steps)."""
    from benchmarks.c_baseline.build import CompilerUnavailable, load
    from harness.registry import get_problem, get_stepper

    try:
        baseline = load()
    except CompilerUnavailable as exc:
        pytest.skip(f"no C compiler on this machine: {exc}")
    problem = get_problem("kepler-elliptic")
    y0 = problem.ensemble(3, seed=2)
    for method, stepper in (("vv", "velocity-verlet@compiled"), ("rk4", "rk4")):
        harness_run = get_stepper(stepper).integrate(problem, h=1e-3, n_steps=1000, y0=y0).final
        assert np.allclose(baseline.run(method, y0, 1e-3, 1000), harness_run, rtol=0, atol=1e-12)
        assert np.allclose(baseline.run(method, y0[:, 1], 1e-3, 1000), harness_run[:, 1], atol=1e-12)


def test_c_baseline_reports_a_missing_compiler(monkeypatch):
    from benchmarks import _common
    from benchmarks.c_baseline import build

    monkeypatch.setenv("CC", "no-such-compiler-anywhere")
    monkeypatch.setattr(build, "_loaded", {})
    with pytest.raises(build.CompilerUnavailable, match="no C compiler found"):
        build.load()
    with pytest.raises(NotImplementedError, match="no C compiler found"):
        _common.c_baseline()


# -- history ----------------------------------------------------------------------------------
def test_history_of_nothing_is_an_empty_table(tmp_path):
    for where in (tmp_path / "missing", tmp_path):
        history = load_history(where)
        assert history.empty and list(history.columns) == HISTORY_COLUMNS
    with pytest.raises(InputError, match="`results_dir` must be a path"):
        load_history(42)


def test_history_reads_asv_result_files(tmp_path):
    machine = tmp_path / "box"
    machine.mkdir()
    (machine / "machine.json").write_text(json.dumps({"machine": "box", "version": 1}))
    (tmp_path / "benchmarks.json").write_text(json.dumps({
        "s.T.time_step": {"type": "time", "unit": "seconds", "param_names": ["stepper", "n"]},
        "s.A.track_order": {"type": "track", "unit": "order", "param_names": []},
        "version": 2,
    }))
    for k, (commit, scale) in enumerate((("a" * 40, 1.0), ("b" * 40, 2.0))):
        (machine / f"{commit[:8]}-env.json").write_text(json.dumps({
            "commit_hash": commit, "env_name": "env", "date": 1_700_000_000_000 + k * 86_400_000,
            "params": {"machine": "box"}, "python": "3.11", "requirements": {}, "env_vars": {},
            "result_columns": ["result", "params", "version"],
            "results": {
                "s.T.time_step": [[1e-6 * scale, None, 3e-6 * scale, 4e-6 * scale],
                                  [["'rk4'", "'euler'"], ["1", "10"]], "v"],
                "s.A.track_order": [3.9 + k * 0.1, [], "v"],
            },
            "durations": {}, "version": 2,
        }))
    (machine / "broken-env.json").write_text("{not json")
    history = load_history(tmp_path)
    assert list(history.columns) == HISTORY_COLUMNS
    assert len(history) == 2 * (3 + 1)  # the null result (rk4, n=10) is left out
    row = history[(history.commit == "b" * 40) & (history.params == "stepper='euler', n=10")]
    assert row.value.tolist() == [8e-6] and row.unit.tolist() == ["seconds"]
    order = history[history.benchmark == "s.A.track_order"]
    assert order.value.tolist() == [3.9, 4.0] and set(order.unit) == {"order"}
    assert (order.params == "").all() and (history.machine == "box").all()
    assert history.date.is_monotonic_increasing and str(history.date.dt.tz) == "UTC"


# -- the regression check, for real ---------------------------------------------------------------
_TINY_CONF = {
    "version": 1,
    "project": "tinybench",
    "repo": ".",
    "branches": ["main"],
    "environment_type": "virtualenv",
    "pythons": [f"{sys.version_info[0]}.{sys.version_info[1]}"],
    "matrix": {"req": {"pip+build": ["1.6.1"], "pip+asv_runner": ["0.3.2"], "pip+pympler": ["1.1"]}},
    "build_command": [],
    "install_command": [
        "python -c \"import shutil, sysconfig; "
        "shutil.copy('{build_dir}/tinybench.py', sysconfig.get_paths()['purelib'])\""
    ],
    "uninstall_command": [],
    "benchmark_dir": "benchmarks",
    "results_dir": ".asv/results",
    "html_dir": ".asv/html",
}
_MODULE = 'import time\n\n\ndef work():\n    # {comment}\n    time.sleep({seconds})\n'
_BENCH = textwrap.dedent(
    """
    import tinybench


    class Work:
        repeat = (5, 10, 10.0)
        number = 1
        warmup_time = 0.0

        def time_work(self):
            tinybench.work()
    """
)


def _git(repo: Path, *args: str, env: dict) -> str:
    done = subprocess.run(["git", *args], cwd=repo, env=env, capture_output=True, text=True, check=True)
    return done.stdout.strip()


@pytest.mark.slow
def test_regression_check_fails_on_a_slowed_commit(tmp_path):
    if shutil.which("git") is None:
        pytest.skip("git is not installed: asv benchmarks commits of a git repository")
    repo = tmp_path / "repo"
    (repo / "benchmarks").mkdir(parents=True)
    env = dict(
        os.environ,
        HOME=str(tmp_path),  # asv keeps its machine file in ~/.asv-machine.json
        PATH=f"{VENV_BIN}{os.pathsep}{os.environ.get('PATH', '')}",
        GIT_AUTHOR_NAME="bench", GIT_AUTHOR_EMAIL="bench@example.invalid",
        GIT_COMMITTER_NAME="bench", GIT_COMMITTER_EMAIL="bench@example.invalid",
    )
    conf = dict(_TINY_CONF, env_dir=str(cache_dir() / "asv-selftest" / "env"))
    (repo / "asv.conf.json").write_text(json.dumps(conf, indent=1))
    (repo / "benchmarks" / "__init__.py").write_text("")
    (repo / "benchmarks" / "bench_work.py").write_text(_BENCH)
    _git(repo, "init", "-q", "-b", "main", env=env)
    commits = []
    for comment, seconds in (("first", 0.01), ("only this comment changes", 0.01), ("slowed", 0.05)):
        (repo / "tinybench.py").write_text(_MODULE.format(comment=comment, seconds=seconds))
        _git(repo, "add", "-A", env=env)
        _git(repo, "commit", "-q", "-m", comment, env=env)
        commits.append(_git(repo, "rev-parse", "HEAD", env=env))

    asv = [sys.executable, "-m", "asv"]
    subprocess.run([*asv, "machine", "--machine", "selftest", "--yes"], cwd=repo, env=env,
                   capture_output=True, check=True, timeout=120)

    def continuous(base: str, head: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [*asv, "continuous", "--factor", "1.2", "--machine", "selftest", "--interleave-rounds",
             base, head],
            cwd=repo, env=env, capture_output=True, text=True, timeout=900,
        )

    same = continuous(commits[0], commits[1])
    assert same.returncode == 0, same.stdout + same.stderr
    slowed = continuous(commits[1], commits[2])
    assert slowed.returncode == 1, slowed.stdout + slowed.stderr
    assert "PERFORMANCE DECREASED" in slowed.stdout

    history = load_history(repo / ".asv" / "results")
    times = history[history.benchmark == "bench_work.Work.time_work"].set_index("commit").value
    assert set(times.index) == set(commits)
    assert times[commits[2]] > 3 * times[commits[1]]
    assert isinstance(history.date.iloc[0], pd.Timestamp)
