"""Hostile plugin files: misbehaving at import must be reported by name, never kill, hang or
corrupt the harness process (see `harness.registry.probe_plugin`).

Each case runs the CLI in-process (`main`), so a plugin that ended or hung the importing process
would end or hang this test: the probe in a child process is what keeps it alive.
"""

from __future__ import annotations

import contextlib
import io
import json
import re

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


# -- hostile definitions: one validation layer for problems and one for method records ----------------
_HEAD = ("import heyoka as hy\nfrom harness.problem import NewtonianForm, Problem\n"
         "x, v, w = hy.make_vars('x', 'v', 'w')\n")
_OK = "rhs=[v, -x], y0=[1.0, 0.0], t_span=(0.0, 1.0)"
HOSTILE_PROBLEMS = {  # plugin body -> the rule the one error line states
    "empty-state": ("Problem('empty', variables=[], rhs=[], y0=[], t_span=(0.0, 1.0))",
                    r"at least one state variable"),
    "complex-y0": ("Problem('cplx', variables=[x, v], rhs=[v, -x], y0=[1 + 2j, 0.0], t_span=(0, 1))",
                   r"`y0` must be real numbers \(complex values are not cast"),
    "complex-zero-imag": ("Problem('cplx0', variables=[x, v], rhs=[v, -x], y0=[1 + 0j, 0j], "
                          "t_span=(0, 1))", r"`y0` must be real numbers"),
    "bool-y0": ("Problem('booly', variables=[x, v], rhs=[v, -x], y0=[True, False], t_span=(0, 1))",
                r"`y0` must be numbers"),
    "string-y0": ("Problem('stry', variables=[x, v], rhs=[v, -x], y0=['1', '0'], t_span=(0, 1))",
                  r"`y0` must be numbers"),
    "one-position-two-velocities": (
        "Problem('n12', variables=[x, v, w], newtonian=NewtonianForm(positions=(x,), "
        "velocities=(v, w), acceleration=(-x,)), y0=[1.0, 0.0, 0.0], t_span=(0, 1))",
        r"one velocity per position, got 1 position\(s\) and 2"),
    "two-positions-one-velocity": (
        "Problem('n21', variables=[x, v, w], newtonian=NewtonianForm(positions=(x, v), "
        "velocities=(w,), acceleration=(-x, -v)), y0=[1.0, 0.0, 0.0], t_span=(0, 1))",
        r"one velocity per position, got 2 position\(s\) and 1"),
    "long-name": (f"Problem('{'p' * 230}', variables=[x, v], {_OK})", r"at most 120 characters"),
    "ansi-name": (f"Problem('ansi\\x1b[31mred', variables=[x, v], {_OK})", r"control characters"),
    "newline-name": (f"Problem('two\\nlines', variables=[x, v], {_OK})", r"control characters"),
    "bidi-name": (f"Problem('abc\\u202edcba', variables=[x, v], {_OK})", r"control characters"),
    "expression-as-variable": (f"Problem('expr-var', variables=[x + v, v], {_OK})",
                               r"must be heyoka variables"),
    "name-not-a-string": (f"Problem(42, variables=[x, v], {_OK})", r"non-empty string"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_PROBLEMS))
def test_a_hostile_problem_definition_is_one_line_naming_the_rule(case, plugin_file):
    body, rule = HOSTILE_PROBLEMS[case]
    path = plugin_file(f"hostile_problem_{case.replace('-', '_')}.py", f"{_HEAD}PROBLEMS = [{body}]\n")
    code, out, err = _cli(["list", "problems", "--plugin", path])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and out == "", (case, err)
    assert re.search(rule, lines[0]) and "\x1b" not in err and "Traceback" not in err, lines[0]


_RK = '"A": [[0]], "b": [1], "reference": "Euler (1768)"'
HOSTILE_RECORDS = {  # one bad record beside a good one: the bad one named, the good one loads
    "bool-order": (f'{{"name": "r-bool", {_RK}, "claimed_order": True}}', r"whole number, got True"),
    "float-order": (f'{{"name": "r-float", {_RK}, "claimed_order": 2.0}}', r"whole number, got 2.0"),
    "huge-order": (f'{{"name": "r-huge", {_RK}, "claimed_order": 10**30}}', r"between 1 and 50"),
    "zero-order": (f'{{"name": "r-zero", {_RK}, "claimed_order": 0}}', r"between 1 and 50"),
    "huge-fraction": ('{"name": "r-frac", "A": [[0]], "b": [Fraction(10**100000)], '
                      '"claimed_order": 1, "reference": "Euler"}', r"too large or too finely divided"),
    "huge-int": ('{"name": "r-int", "A": [[0]], "b": [10**400], "claimed_order": 1, '
                 '"reference": "Euler"}', r"float64"),
    "bool-coefficient": ('{"name": "r-boolc", "A": [[0]], "b": [True], "claimed_order": 1, '
                         '"reference": "Euler"}', r"must be a real number, got True"),
    "too-many-stages": ('{"name": "r-wide", "A": [[0] * 300] * 300, "b": [1] + [0] * 299, '
                        '"claimed_order": 1, "reference": "Euler"}', r"at most 256 entries"),
    "nan-coefficient": ('{"name": "r-nan", "A": [[0]], "b": [float("nan")], "claimed_order": 1, '
                        '"reference": "Euler"}', r"must be finite"),
    "reference-not-text": ('{"name": "r-ref", "A": [[0]], "b": [1], "claimed_order": 1, '
                           '"reference": 5}', r"`reference` must be a string"),
    "ansi-name": (f'{{"name": "r-\\x1b[2J", {_RK}, "claimed_order": 1}}', r"control characters"),
    "long-name": (f'{{"name": "{"r" * 200}", {_RK}, "claimed_order": 1}}', r"at most 120 characters"),
    "builtin-name": (f'{{"name": "rk4", {_RK}, "claimed_order": 1}}',
                     r"'rk4' is already registered \(by builtin\)"),
    "inconsistent": ('{"name": "r-sum", "A": [[0]], "b": [2], "claimed_order": 1, "reference": "E"}',
                     r"must sum to 1"),
    "not-a-mapping": ('["r-list", 1]', r"must be a mapping"),
}
_GOOD = f'{{"name": "r-good-euler", {_RK}, "claimed_order": 1}}'


@pytest.mark.parametrize("case", sorted(HOSTILE_RECORDS))
def test_a_bad_record_is_refused_alone_and_the_others_load(case, plugin_file):
    record, rule = HOSTILE_RECORDS[case]
    source = f"from fractions import Fraction\nMETHODS = [{record}, {_GOOD}]\n"
    path = plugin_file(f"hostile_record_{case.replace('-', '_')}.py", source)
    code, out, err = _cli(["list", "steppers", "--json", "--plugin", path])
    assert code == 0, (case, err)
    assert "r-good-euler" in [r["name"] for r in json.loads(out)]
    warnings = [ln for ln in err.splitlines()  # (earlier tests' plugins are warned about too)
                if ln.startswith("harness: warning: ") and path in ln]
    assert len(warnings) == 1 and re.search(rule, warnings[0]), (case, err)
    assert "\x1b" not in err and "Traceback" not in err


@pytest.mark.parametrize("case", sorted(HOSTILE_RECORDS))
def test_a_plugin_whose_only_record_is_bad_shows_that_records_reason(case, plugin_file):
    record, rule = HOSTILE_RECORDS[case]
    path = plugin_file(f"only_{case.replace('-', '_')}.py",
                       f"from fractions import Fraction\nMETHODS = [{record}]\n")
    code, out, err = _cli(["list", "steppers", "--plugin", path])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and re.search(rule, lines[0]), (case, err)
    assert "defines no Stepper" not in lines[0]


def test_a_stepper_object_claiming_order_true_is_refused():
    from harness.errors import InputError
    from harness.stepper import StepperInfo

    with pytest.raises(InputError, match=r"`claimed_order` must be a whole number, got True"):
        StepperInfo(name="s", family="t", claimed_order=True, explicit=True, symplectic=False,
                    symmetric=False, evals_per_step=1, form="first-order", velocity_dependent=True,
                    reference="r")


def test_control_characters_in_descriptions_and_chatter_are_escaped_on_every_stream(plugin_file):
    source = ("print('chatter \\x1b[2J\\x1b]0;title\\x07')\n"
              "METHODS = [{'name': 'esc-euler', 'A': [[0]], 'b': [1], 'claimed_order': 1,\n"
              "            'reference': 'Euler \\x1b[31m(1768)', 'description': 'x \\u202e y'}]\n")
    path = plugin_file("escapes.py", source)
    code, out, err = _cli(["list", "steppers", "--plugin", path])
    assert code == 0 and "esc-euler" in out
    for stream in (out, err):
        assert not any(c in stream for c in "\x1b\x07\u202e"), repr(stream[:300])
    assert "chatter \\x1b[2J" in err
