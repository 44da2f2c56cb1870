"""The command line: listings, the certified reference, and one-line errors with exit 2."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
from importlib import import_module

import numpy as np
import pytest

from harness.cli import main
from harness.registry import problems, steppers
from harness.stepper import Stepper


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_list_steppers_json_has_every_registered_stepper_with_its_claims(capsys):
    code, out, _ = run_cli(capsys, "list", "steppers", "--json")
    assert code == 0
    records = json.loads(out)
    # every stepper a user can name: the default ones, then those run on request (a family's
    # further published members), marked; compiled variants are implementations, not listed
    listed = [r["name"] for r in records]
    assert [r["name"] for r in records if not r["on_request"]] == steppers.names()
    on_request = [n for n in steppers.names(variants=True) if steppers.get(n).info.extra.get("on_request")
                  and "numpy_implementation" not in steppers.get(n).info.extra]
    assert on_request and set(listed) == set(steppers.names()) | set(on_request)
    required = {"name", "family", "claimed_order", "explicit", "symplectic", "symmetric",
                "evals_per_step", "form", "velocity_dependent", "reference"}
    for r in records:
        assert required <= set(r), r["name"]
        assert r["reference"], r["name"]


def test_list_problems_json(capsys):
    code, out, _ = run_cli(capsys, "list", "problems", "--json")
    assert code == 0
    names = [r["name"] for r in json.loads(out)]
    for name in ["forced-duffing", "damped-cubic", "free-fall", "gaussian", "harmonic",
                 "kepler-circular", "kepler-elliptic", "pendulum", "pendulum-small", "dahlquist"]:
        assert name in names


def test_reference_kepler_elliptic_matches_exact_solution(capsys):
    code, out, _ = run_cli(capsys, "reference", "kepler-elliptic", "--t", "100", "--json")
    assert code == 0
    (rec,) = json.loads(out)
    assert rec["problem"] == "kepler-elliptic" and rec["t"] == 100.0
    assert rec["reference_error"] <= 1e-15
    exact = np.array(rec["exact_state"])
    assert np.max(np.abs(np.array(rec["state"]) - exact)) <= 1e-13


BAD = [
    (["run", "convergence", "--stepper", "rk5"], r"unknown stepper 'rk5'.*closest: rk4"),
    (["run", "convergence", "--problem", "keppler"], r"unknown problem 'keppler'.*closest"),
    (["run", "convergnce"], r"unknown experiment 'convergnce'.*closest: convergence"),
    (["reference", "harmonic", "--t", "nan"], r"`--t` must be finite"),
    (["reference", "harmonic", "--t", "-1"], r"`--t` must be >= the start time"),
    (["reference", "harmonic", "--t", "abc"], r"`--t` must be a real number"),
    (["list", "steppers", "--plugin", "does-not-exist.py"], r"does-not-exist.py.*no such file"),
    (["gate", "--jobs", "0"], r"`jobs`"),
]


@pytest.mark.parametrize("argv,pattern", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_exits_2_with_one_line(capsys, argv, pattern):
    import re

    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("harness: error: ")
    assert re.search(pattern, lines[0]), lines[0]


def test_plugin_with_syntax_error_is_named(tmp_path, capsys):
    bad = tmp_path / "broken_plugin.py"
    bad.write_text("def oops(:\n")
    code, _, err = run_cli(capsys, "list", "steppers", "--plugin", str(bad))
    assert code == 2
    assert "broken_plugin.py" in err and "SyntaxError" in err


def test_plugin_stepper_runs_through_the_gate(tmp_path, capsys):
    plugin = tmp_path / "my_methods.py"
    plugin.write_text(
        "from harness.coefficients import ButcherTableau\n"
        "from implementations.runge_kutta import ExplicitRungeKutta\n"
        "STEPPERS = [ExplicitRungeKutta(ButcherTableau('plugin-ralston', A=[[0, 0], [2/3, 0]],"
        " b=[1/4, 3/4]), claimed_order=2, reference='Ralston (1962)')]\n"
    )
    try:
        code, out, err = run_cli(capsys, "gate", "--plugin", str(plugin), "--stepper", "plugin-ralston",
                                 "--problem", "forced-duffing", "--jobs", "1", "--json")
        assert code == 0, err
        (rec,) = json.loads(out)
        assert rec["stepper"] == "plugin-ralston" and rec["passed"] is True
        assert abs(rec["measured_order"] - 2) <= 0.2
    finally:
        steppers.unregister("plugin-ralston")


def test_help_on_every_command():
    for argv in (["--help"], ["list", "--help"], ["run", "--help"], ["reference", "--help"],
                 ["gate", "--help"], ["report", "--help"]):
        proc = subprocess.run([sys.executable, "-m", "harness", *argv], capture_output=True,
                              text=True, timeout=120)
        assert proc.returncode == 0, (argv, proc.stderr)
        assert "usage: harness" in proc.stdout


def test_a_stepper_asked_for_a_form_it_cannot_do_is_refused_by_name():
    from harness.errors import IncompatibleError

    with pytest.raises(IncompatibleError, match=r"'velocity-verlet' needs a Newtonian problem.*'gaussian'"):
        steppers.get("velocity-verlet").integrate(problems.get("gaussian"), h=0.1, n_steps=2)


def test_every_stepper_class_in_implementations_is_registered():
    """A stepper class the registry never names is dead code or a forgotten registration."""
    from implementations import FAMILY_MODULES

    registered_types = {type(s) for s in steppers.all(variants=True)}
    missing = []
    for mod_name in FAMILY_MODULES:
        try:
            module = import_module(f"implementations.{mod_name}")
        except ModuleNotFoundError:
            continue
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if (issubclass(cls, Stepper) and cls.__module__ == module.__name__
                    and not inspect.isabstract(cls) and not cls.__name__.startswith("_")):
                if not any(issubclass(t, cls) for t in registered_types):
                    missing.append(f"{module.__name__}.{cls.__name__}")
    assert not missing, f"stepper classes with no registered instance: {missing}"


def test_one_list_of_experiments_builds_the_cli_runner_and_report(capsys, tmp_path, monkeypatch):
    """Every experiment in harness/experiments/__init__.py is listed, runnable on its own, and a
    report section, in that order (roundoff used to be registered only by building a report)."""
    from harness.experiments import EXPERIMENT_NAMES, EXPERIMENTS
    from harness.report import report_experiments

    code, out, _ = run_cli(capsys, "list", "experiments", "--json")
    assert code == 0 and [r["name"] for r in json.loads(out)] == list(EXPERIMENT_NAMES)
    assert tuple(report_experiments()) == EXPERIMENT_NAMES and list(EXPERIMENTS) == list(EXPERIMENT_NAMES)
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path))
    code, out, err = run_cli(capsys, "run", "roundoff", "--stepper", "leapfrog", "--problem",
                             "harmonic", "--quick", "--jobs", "1", "--json")
    assert code == 0, err
    assert {r["stepper"] for r in json.loads(out)} == {"leapfrog"}
