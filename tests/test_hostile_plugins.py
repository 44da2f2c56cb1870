"""Hostile plugin files: misbehaving at import must be reported by name, never kill, hang or
corrupt the harness process (see `harness.registry.probe_plugin`).

Each case runs the CLI in-process (`main`), so a plugin that ended or hung the importing process
would end or hang this test: the probe in a child process is what keeps it alive.
"""

from __future__ import annotations

import contextlib
import io
import json

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness import registry
from harness.cli import main
from harness.errors import PluginError

STEPPER = ("from harness.coefficients import ButcherTableau\n"
           "from implementations.runge_kutta import ExplicitRungeKutta\n"
           "STEPPERS = [ExplicitRungeKutta(ButcherTableau('probe-euler', A=[[0]], b=[1]),"
           " claimed_order=1, reference='Euler (1768)')]\n")

HOSTILE = {
    "os-exit": lambda k: f"import os\nos._exit({k})\n",
    "sys-exit": lambda k: f"import sys\nsys.exit({k})\n",
    "thread": lambda k: ("import threading, time\n"
                         f"threading.Thread(target=time.sleep, args=(3600,), name='t{k}').start()\n"),
    "raising-generator": lambda k: ("def gen():\n    yield from ()\n"
                                    f"    raise RuntimeError('generator {k} broke')\n"
                                    "STEPPERS = gen()\n"),
    "raising-problems": lambda k: (f"{STEPPER}def gen():\n    raise ValueError({k})\n    yield\n"
                                   "PROBLEMS = gen()\n"),
    "segfault": lambda k: "import ctypes\nctypes.string_at(0)\n",
    "kill-self": lambda k: "import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n",
}
EXPECTED = {
    "os-exit": r"ended the process importing it \(exit status \d+",
    "sys-exit": r"exited while importing",
    "thread": r"starts non-daemon thread\(s\) at import \(t\d+\)",
    "raising-generator": r"listing STEPPERS failed: RuntimeError: generator \d+ broke",
    "raising-problems": r"listing PROBLEMS failed: ValueError",
    "segfault": r"crashed the process importing it \(signal SIGSEGV\)",
    "kill-self": r"crashed the process importing it \(signal SIGKILL\)",
}


def _cli(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.mark.parametrize("kind", sorted(HOSTILE))
@settings(max_examples=2, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(k=st.integers(0, 255),
       command=st.sampled_from([["list", "steppers"], ["list", "problems", "--json"]]))
def test_a_plugin_misbehaving_at_import_is_named_and_the_process_survives(kind, k, command,
                                                                            plugin_file):
    if kind == "os-exit" and k == 0:
        k = 3  # exit status 0 without the probe's report is still an ended process
    path = plugin_file(f"hostile_{kind.replace('-', '_')}_{k}.py", HOSTILE[kind](k))
    code, out, err = _cli([*command, "--plugin", path])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (kind, err)
    assert len(lines) == 1 and lines[0].startswith("harness: error: plugin "), lines
    assert path in lines[0]
    import re

    assert re.search(EXPECTED[kind], lines[0]), lines[0]
    assert out == ""


def test_a_plugin_that_hangs_at_import_is_stopped_by_the_probe(plugin_file, monkeypatch):
    monkeypatch.setattr(registry, "PLUGIN_PROBE_TIMEOUT_S", 5.0)
    path = plugin_file("hangs.py", "while True:\n    pass\n")
    with pytest.raises(PluginError, match=r"hangs.py' did not finish importing within 5 s"):
        registry.load_plugin(path)


def test_a_well_behaved_plugin_still_loads_after_the_probe_and_its_print_goes_to_stderr(plugin_file):
    path = plugin_file("chatty_probe.py", "print('hello at import')\n" + STEPPER)
    code, out, err = _cli(["list", "steppers", "--json", "--plugin", path])
    assert code == 0
    assert "probe-euler" in [r["name"] for r in json.loads(out)]
    assert "hello at import" in err


def test_a_plugin_printing_while_its_cell_runs_keeps_json_stdout_clean(plugin_file, tmp_path,
                                                                        monkeypatch):
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path / "cache"))
    source = ("import numpy as np\n"
              "from harness.stepper import Carry, Stepper, StepperInfo\n\n\n"
              "class LoudEuler(Stepper):\n"
              "    info = StepperInfo(name='loud-euler', family='test', claimed_order=1,\n"
              "                       explicit=True, symplectic=False, symmetric=False,\n"
              "                       evals_per_step=1, form='first-order',\n"
              "                       velocity_dependent=True, reference='Euler (1768)')\n\n"
              "    def _start(self, dyn, t0, y0, h):\n"
              "        return Carry(t0, h, y0)\n\n"
              "    def _step(self, dyn, c):\n"
              "        print('stepping')\n"
              "        c.y = c.y + c.h * dyn.f(c.t, c.y)\n\n\n"
              "STEPPERS = [LoudEuler()]\n")
    path = plugin_file("loud.py", source)
    code, out, err = _cli(["run", "stability", "--plugin", path, "--stepper", "loud-euler",
                           "--problem", "dahlquist", "--jobs", "1", "--quick", "--json"])
    records = json.loads(out)
    assert records and all(r["stepper"] == "loud-euler" for r in records)
    assert "stepping" in err and code in (0, 1)
