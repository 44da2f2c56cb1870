"""Hostile work and process control: unbounded references, interrupts, terminated and killed runs.

Families:
- unbounded references: any span far beyond what a reference can integrate ends quickly in one
  line naming the limit and how to raise it (generated spans); the wall-time limit and a cell's
  time limit (SIGALRM, as with --jobs 1) reach into the compiled integration;
- argument values that look like options (`--t -inf`) reach the rule that rejects them;
- process control: SIGTERM removes claim directories and worker processes; after kill -9 of a
  run its worker processes exit by themselves; a bad scheduler address is an error even when
  every cell is cached.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness import ground_truth, runner
from harness.cli import main
from harness.errors import InputError, WorkLimitError

ROOT = Path(__file__).resolve().parent.parent


def _cli(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), [ln for ln in err.getvalue().splitlines() if ln.strip()]


@settings(max_examples=12, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(exponent=st.floats(9.0, 300.0), problem=st.sampled_from(["harmonic", "kepler-elliptic",
                                                                 "pendulum"]))
def test_a_reference_over_a_huge_span_stops_at_the_work_limit(exponent, problem):
    code, out, err = _cli(["reference", problem, "--t", repr(10.0 ** exponent)])
    assert code == 2 and out == ""
    assert len(err) == 1 and err[0].startswith("harness: error: ground truth for problem"), err
    assert "HARNESS_REFERENCE_MAX_WORK" in err[0] and "Taylor steps" in err[0]


@settings(max_examples=6, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(exponent=st.floats(9.0, 300.0))
def test_a_decaying_problem_over_a_huge_span_gets_the_stiff_reference_or_one_line(exponent):
    """y' = lambda y over 1e9..1e300: stiff for the explicit Taylor reference (it would need
    e|lambda|T/p steps), so the implicit cross-check answers with its stated error, or, where a
    solver fails, one line that says which and why (SUNDIALS' own words folded in, never printed)."""
    code, out, err = _cli(["reference", "dahlquist", "--t", repr(10.0 ** exponent)])
    if code == 0:
        assert err == [] and "certified_by: radau+cvode-bdf" in out and "reference_error" in out
    else:
        assert code == 2 and out == "", (code, out)
        assert len(err) == 1 and err[0].startswith("harness: error: stiff reference for problem"), err


def test_the_work_limit_is_raised_by_its_environment_variable(monkeypatch):
    monkeypatch.setenv("HARNESS_REFERENCE_MAX_WORK", "1e4")
    with pytest.raises(WorkLimitError, match=r"more than the limit of 1e\+04 units"):
        ground_truth.reference("harmonic", 500.0)
    monkeypatch.setenv("HARNESS_REFERENCE_MAX_WORK", "lots")
    with pytest.raises(InputError, match=r"`HARNESS_REFERENCE_MAX_WORK` must be a positive number"):
        ground_truth.reference("harmonic", 500.0)


def test_the_wall_time_limit_reaches_into_the_integration(monkeypatch):
    monkeypatch.setenv("HARNESS_REFERENCE_MAX_WORK", "1e30")
    monkeypatch.setenv("HARNESS_REFERENCE_MAX_SECONDS", "1")
    with pytest.raises(WorkLimitError, match=r"more than the limit of 1 s \(`HARNESS_REFERENCE_MAX_SECONDS`"):
        ground_truth.reference("harmonic", 1e9)


def test_a_cell_time_limit_interrupts_a_reference_in_this_process(monkeypatch):
    """What --cell-timeout does with --jobs 1: SIGALRM in the main thread, between chunks."""
    monkeypatch.setenv("HARNESS_REFERENCE_MAX_WORK", "1e30")
    with pytest.raises(runner.CellTimeout):
        with runner.time_limit(1.0):
            ground_truth.reference("harmonic", 1e9)


@pytest.mark.parametrize("value,rule", [("-inf", r"`--t` must be finite"),
                                        ("-1", r"`--t` must be >= the start time"),
                                        ("-1e400", r"`--t` must be finite"),
                                        ("-0x10", r"`--t` must be a real number")])
def test_a_value_that_looks_like_an_option_reaches_its_rule(value, rule):
    import re

    code, _, err = _cli(["reference", "harmonic", "--t", value])
    assert code == 2 and len(err) == 1 and re.search(rule, err[0]), err


def test_a_bad_scheduler_is_an_error_even_when_every_cell_is_cached(tmp_path, monkeypatch):
    monkeypatch.setattr(runner.executors, "DASK_CONNECT_TIMEOUT_S", 1)
    kw = {"jobs": 1, "cache_dir": tmp_path, "progress": False}
    first = runner.run_experiment("convergence", ["euler"], ["dahlquist"], quick=True, **kw)
    assert first.computed_cells == 1
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        with pytest.raises(InputError, match=r"`scheduler` 'tcp://127.0.0.1:9': cannot connect"):
            runner.run_experiment("convergence", ["euler"], ["dahlquist"], quick=True,
                                  scheduler="tcp://127.0.0.1:9", **kw)
    assert "Exception ignored" not in err.getvalue()


# -- process control ------------------------------------------------------------------------------
SLOW_PLUGIN = '''"""Explicit Euler sleeping in every step (Hairer, Norsett & Wanner, Solving ODEs I, I.7)."""
import time

from harness.stepper import Carry, Stepper, StepperInfo


class SlowEuler(Stepper):
    info = StepperInfo(name="slow-euler", family="test", claimed_order=1, explicit=True,
                       symplectic=False, symmetric=False, evals_per_step=1, form="first-order",
                       velocity_dependent=True, reference="Hairer, Norsett & Wanner, I.7")

    def _start(self, dyn, t0, y0, h):
        return Carry(t0, h, y0)

    def _step(self, dyn, c):
        time.sleep(0.2)
        c.y = c.y + c.h * dyn.f(c.t, c.y)


STEPPERS = [SlowEuler()]
'''


def _children(pid: int) -> set[int]:
    out = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError):
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                if int(fields[1]) == pid:
                    out.add(int(entry.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _start_slow_run(tmp_path):
    plugin = tmp_path / "slow.py"
    plugin.write_text(SLOW_PLUGIN)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = dict(os.environ, TMPDIR=str(tmp), HARNESS_CACHE_DIR=str(tmp_path / "cache"),
               HARNESS_RESULTS_DIR=str(tmp_path / "results"))
    proc = subprocess.Popen([sys.executable, "-m", "harness", "run", "convergence", "--plugin",
                             str(plugin), "--stepper", "slow-euler", "--problem", "dahlquist",
                             "--problem", "gaussian", "--jobs", "2", "--quick"], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    for _ in range(1200):  # wait (up to 2 minutes) until a worker holds a claim
        claims = list(tmp.glob("harness-claims-*/*"))
        if claims or proc.poll() is not None:
            break
        time.sleep(0.1)
    assert claims, "no cell started"
    return proc, tmp


def test_sigterm_removes_claim_directories_and_workers(tmp_path):
    proc, tmp = _start_slow_run(tmp_path)
    workers = _children(proc.pid)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "harness: terminated" in err and "Traceback" not in err
    assert list(tmp.glob("harness-claims-*")) == []
    for _ in range(300):
        if not any(_alive(p) for p in workers):
            break
        time.sleep(0.1)
    assert not any(_alive(p) for p in workers)


def test_workers_of_a_killed_run_exit_by_themselves(tmp_path):
    proc, _ = _start_slow_run(tmp_path)
    workers = _children(proc.pid)
    assert workers
    proc.kill()
    proc.wait(timeout=60)
    for _ in range(600):  # they notice within ORPHAN_CHECK_S; give a loaded machine a minute
        if not any(_alive(p) for p in workers):
            break
        time.sleep(0.1)
    assert not any(_alive(p) for p in workers)


@pytest.mark.parametrize("checkpoints, work, position, end, expected", [
    ([(0, 0.0), (100, 1.0)], 200, 2.0, 10.0, 1000.0),  # a steady rate: exact
    ([(0, 0.0), (100, 1.0)], 200, 1.0, 10.0, math.inf),  # no progress over the later half
    ([(0, 0.0), (100, 9.9)], 200, 9.99, 10.0, 200 + 100 * 0.01 / 0.09),  # slow lately: its rate
    ([(0, 5.0), (100, 4.0)], 200, 3.0, -5.0, 1000.0),  # towards an end below the start
    ([(0, 0.0)], 100, 10.0, 10.0, 100.0),  # done
])
def test_projected_work_uses_the_recent_half(checkpoints, work, position, end, expected):
    from harness.work_projection import projected_work

    assert projected_work(checkpoints, work, position, end) == pytest.approx(expected)
