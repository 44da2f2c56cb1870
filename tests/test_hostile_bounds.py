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
import json
import math
import os
import re
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


def _slow_setup(tmp_path):
    # the slow plugin, a private TMPDIR (where workers leave their claims) and an environment
    # with its own cache and results
    plugin = tmp_path / "slow.py"
    plugin.write_text(SLOW_PLUGIN)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = dict(os.environ, TMPDIR=str(tmp), HARNESS_CACHE_DIR=str(tmp_path / "cache"),
               HARNESS_RESULTS_DIR=str(tmp_path / "results"))
    return plugin, tmp, env


def _start_slow_run(tmp_path):
    plugin, tmp, env = _slow_setup(tmp_path)
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


# -- a scheduler handshake with a deadline ----------------------------------------------------------------
def _server(behaviour: str):
    """A local TCP server that is not a Dask scheduler: returns (address, stop)."""
    import socket
    import threading

    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    sock.listen(8)
    sock.settimeout(0.2)
    held, stop = [], threading.Event()

    def serve():
        while not stop.is_set():
            try:
                conn, _ = sock.accept()
            except OSError:
                continue
            if behaviour == "silent":
                held.append(conn)  # accepts, never answers
                continue
            with contextlib.suppress(OSError):
                conn.sendall({"garbage": b"\xff" * 100,
                              "http": b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n",
                              "huge-length": (3 << 60).to_bytes(8, "little") + b"\x00" * 64,
                              "ssh": b"SSH-2.0-OpenSSH_9.2p1 Debian-2\r\n",
                              "closes": b""}[behaviour])
            conn.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()

    def close():
        stop.set()
        thread.join(5)
        for c in held:
            c.close()
        sock.close()

    return f"tcp://127.0.0.1:{sock.getsockname()[1]}", close


SCHEDULER_CASES = {
    "silent": r"no Dask handshake within 1 s",
    "garbage": r"answers, but not as a Dask scheduler",
    "http": r"answers, but not as a Dask scheduler",
    "huge-length": r"answers, but not as a Dask scheduler",
    "ssh": r"answers, but not as a Dask scheduler",
    "closes": r"closed the connection without a Dask handshake",
}


@pytest.mark.parametrize("behaviour", sorted(SCHEDULER_CASES))
def test_a_scheduler_that_is_not_dask_is_one_line_within_the_deadline(behaviour, tmp_path,
                                                                      monkeypatch):
    monkeypatch.setattr(runner.executors, "DASK_CONNECT_TIMEOUT_S", 1)
    address, close = _server(behaviour)
    try:
        err = io.StringIO()
        with contextlib.redirect_stderr(err), pytest.raises(InputError) as info:
            runner.run_experiment("stability", ["euler"], ["dahlquist"], quick=True, jobs=1,
                                  cache_dir=tmp_path, progress=False, scheduler=address)
    finally:
        close()
    assert re.search(SCHEDULER_CASES[behaviour], str(info.value)), str(info.value)
    assert "\n" not in str(info.value) and "Traceback" not in err.getvalue()


@pytest.mark.parametrize("address", ["tls://127.0.0.1:8786", "ucx://127.0.0.1:8786",
                                     "ws://127.0.0.1:8786", "wss://host:1", "inproc://127.0.0.1"])
def test_scheduler_protocols_that_need_more_than_an_address_are_one_line(address):
    code, err = _cli_err(["gate", "--stepper", "euler", "--problem", "dahlquist", "--scheduler",
                          address])
    assert code == 2 and len(err) == 1 and "only tcp://HOST:PORT addresses" in err[0], err


def _cli_err(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, [ln for ln in err.getvalue().splitlines() if ln.strip()]


# -- signals with worker pools ------------------------------------------------------------------------------
def _loky_workers(pid: int) -> set[int]:
    out = set()
    for child in _children(pid):
        with contextlib.suppress(OSError):
            if b"LokyProcess" in Path(f"/proc/{child}/cmdline").read_bytes():
                out.add(child)
    return out


@pytest.mark.parametrize("sig,status,line,when", [
    (signal.SIGINT, 130, "harness: interrupted", "cell"),
    (signal.SIGTERM, 143, "harness: terminated", "cell"),
    # the race a loaded machine widens: the group's Ctrl-C reaches a worker still importing,
    # before its initializer ran (the first case met it too when the second worker was slow to
    # import): workers are born ignoring SIGINT
    (signal.SIGINT, 130, "harness: interrupted", "spawn"),
])
def test_a_double_signal_to_the_group_during_a_pool_run_is_one_line_and_its_status(sig, status,
                                                                                  line, when, tmp_path):
    plugin, tmp, env = _slow_setup(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "harness", "gate", "--plugin", str(plugin),
                             "--stepper", "slow-euler", "--problem", "dahlquist", "--problem",
                             "gaussian", "--jobs", "2"], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,  # a terminal's Ctrl-C reaches the group
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    for _ in range(1200 if when == "cell" else 24000):
        started = list(tmp.glob("harness-claims-*/*")) if when == "cell" else _loky_workers(proc.pid)
        if started or proc.poll() is not None:
            break
        time.sleep(0.1 if when == "cell" else 0.005)
    assert started, "no worker started"
    # into the worker's own imports (0.15-0.6 s after its exec all printed a traceback under
    # load before workers were born ignoring SIGINT)
    time.sleep(0.2 if when == "spawn" else 0.0)
    os.killpg(proc.pid, sig)
    time.sleep(0.2)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, sig)  # the impatient second Ctrl-C
    _, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("convergence:")]
    assert proc.returncode == status, err
    assert lines == [line], err


def _forked_children(pid: int) -> set[int]:
    """Children that are forks of `pid` (same command line): the report's section workers."""
    with contextlib.suppress(OSError):
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
        out = set()
        for child in _children(pid):
            with contextlib.suppress(OSError):
                if Path(f"/proc/{child}/cmdline").read_bytes() == cmdline:
                    out.add(child)
        return out
    return set()


def test_sigterm_to_the_group_while_the_report_builds_its_sections_is_one_line(tmp_path):
    """SIGTERM to the process group of `harness report` (a quick run of one stepper on one
    problem, several experiments) once its forked section workers exist: status 143, the one
    line `harness: terminated`, no worker's traceback, no worker left, no report written."""
    env = dict(os.environ, HARNESS_CACHE_DIR=str(tmp_path / "cache"),
               HARNESS_RESULTS_DIR=str(tmp_path / "results"))
    out_dir = tmp_path / "reports"
    proc = subprocess.Popen([sys.executable, "-m", "harness", "report", "--quick", "--stepper", "euler",
                             "--problem", "harmonic", "--jobs", "1", "--output", str(out_dir)],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    seen = []
    for line in proc.stderr:  # the measurements (a few seconds), then the run is saved
        seen.append(line)
        if line.startswith("report: results saved in"):
            break
    workers: set[int] = set()
    for _ in range(5000):  # the section workers are forked next
        workers = _forked_children(proc.pid)
        if workers or proc.poll() is not None:
            break
        time.sleep(0.002)
    assert workers, "no section worker started: " + "".join(seen)
    os.killpg(proc.pid, signal.SIGTERM)
    time.sleep(0.2)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("report:")]
    assert proc.returncode == 143, err
    assert "harness: terminated" in err.splitlines() and "Traceback" not in err, err
    assert lines == ["harness: terminated"], err
    assert not list(out_dir.glob("*/index.html")), out
    for _ in range(300):
        if not any(_alive(p) for p in workers):
            break
        time.sleep(0.1)
    assert not any(_alive(p) for p in workers)


# -- listing compiles nothing; a compile is interruptible ---------------------------------------------------
def test_listing_problems_compiles_nothing(plugin_file, monkeypatch):
    import heyoka

    path = plugin_file("timed.py", "import heyoka as hy\nfrom harness.problem import Problem\n"
                                   "x, v = hy.make_vars('x', 'v')\n"
                                   "PROBLEMS = [Problem('forced-listed', variables=[x, v], "
                                   "rhs=[v, -x + hy.cos(hy.time)], y0=[1.0, 0.0], "
                                   "t_span=(0.0, 1.0))]\n")

    def refuse(*args, **kwargs):
        raise AssertionError("listing compiled a problem")

    monkeypatch.setattr(heyoka, "cfunc", refuse)
    monkeypatch.setattr(heyoka, "taylor_adaptive", refuse)
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main(["list", "problems", "--json", "--plugin", path]) == 0
    record = next(r for r in json.loads(out.getvalue()) if r["name"] == "forced-listed")
    assert record["time_dependent"] is True and record["dim"] == 2


@pytest.mark.parametrize("delay", [0.0, 0.002, 0.02, 1.0])
def test_a_large_compile_is_interrupted_by_ctrl_c(tmp_path, delay):
    """heyoka compiles with the GIL released; run through `cache.interruptible` the main thread
    still takes Ctrl-C, and the process ends with its own status although the abandoned compile
    still runs (a normal exit ran LLVM's static destructors under it: SIGSEGV or SIGABRT in 2 of
    24 runs with the signal sent within 20 ms of the compile's start). The compile alone takes
    minutes here, so the child ends long before. The child compiles into its own empty code
    directory (`configure_heyoka_cache`), never into heyoka's default per-user cache: a compile
    that ever finished there (a run whose SIGINT was ignored) would be loaded within the delay
    by every later run, which then exits 0."""
    source = ("import heyoka as hy, sys\nfrom harness import cache\n"
              "cache.configure_heyoka_cache()\n"
              "xs = hy.make_vars(*[f'x{i}' for i in range(5000)])\n"
              "exprs = [xs[i] * xs[(i + 1) % 5000] + hy.sin(xs[i - 1]) for i in range(5000)]\n"
              "print('compiling', flush=True)\n"
              "try:\n    cache.interruptible(lambda: hy.cfunc(exprs, list(xs)))\n"
              "except KeyboardInterrupt:\n    print('interrupted', flush=True)\n    sys.exit(130)\n")
    env = dict(os.environ, HARNESS_CODE_CACHE_DIR=str(tmp_path / "code"))
    proc = subprocess.Popen([sys.executable, "-c", source], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "compiling"
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=90)
    assert proc.returncode == 130 and "interrupted" in out, err
