"""The gate in another project's test suite: `harness.api.check` and the pytest plugin.

The example project (examples/claims-example) is run by pytest in a subprocess, with the plugin
loaded by `-p harness.pytest_plugin` and this checkout on PYTHONPATH: as written it passes; a copy
with one coefficient changed (Yoshida's w1 = 1.35: still symmetric, order 2) fails with the
measured table.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from harness.api import ClaimError, FunctionStepper, check
from harness.errors import InputError
from harness.registry import steppers

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "claims-example"


def _run_example(where: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "harness.pytest_plugin", "-p", "no:cacheprovider",
         "-q", "--rootdir", str(where), str(where / "tests")],
        cwd=where, env=env, capture_output=True, text=True, timeout=600,
    )


def test_example_passes_for_the_correct_integrator():
    out = _run_example(EXAMPLE)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "1 passed" in out.stdout


def test_example_fails_readably_for_a_mutant(tmp_path):
    copy = tmp_path / "claims-example"
    shutil.copytree(EXAMPLE, copy)
    source = (copy / "yoshida4.py").read_text()
    mutated = source.replace("W1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))", "W1 = 1.35")
    assert mutated != source, "the mutation no longer applies to the example"
    (copy / "yoshida4.py").write_text(mutated)
    out = _run_example(copy)
    assert out.returncode == 1, out.stdout + out.stderr
    text = out.stdout
    # Two measured order rows fail (the claim is contradicted, so no `not verified` row is added).
    assert "stepper 'yoshida4-example': 2 of 6 claims false" in text and "not verified" not in text
    # (pytest may print the table twice: in the failure and in its short summary)
    order_rows = {line.strip() for line in text.splitlines() if line.strip().startswith("order ")}
    assert len(order_rows) == 2 and all(line.split()[-1] == "NO" for line in order_rows), text
    assert "differs from the expected 4" in text
    assert "Traceback" not in text  # the table, not a trace into the harness


def _symplectic_euler(accel, t, q, v, h):
    v = v + h * accel(t, q)
    return q + h * v, v


def test_a_false_symmetry_claim_raises_an_assertion_with_the_table():
    stepper = FunctionStepper(_symplectic_euler, name="user-symplectic-euler", form="newtonian")
    with pytest.raises(ClaimError) as info:
        check(stepper, ["harmonic"], symmetric=True)
    assert isinstance(info.value, AssertionError)
    table = info.value.report.table
    assert table.claim.tolist() == ["symmetric"] and not table.passed.any()
    assert "claimed symmetric but the round trip misses" in str(info.value)
    assert "user-symplectic-euler" not in steppers  # the temporary registration is undone


def test_a_check_leaves_a_registered_stepper_as_it_was():
    before = steppers.get("leapfrog")
    report = check("leapfrog", ["harmonic"], symmetric=True)
    assert report.passed and steppers.get("leapfrog") is before


@pytest.mark.parametrize(
    "claims, match",
    [
        ({}, "state at least one claim"),
        ({"order": 0}, "`order` must be a positive whole number"),
        ({"order": True}, "`order` must be a positive whole number"),
        ({"energy": "flat"}, "`energy` must be one of"),
        ({"symmetric": "yes"}, "`symmetric` must be True or False"),
    ],
)
def test_bad_claims_are_one_line_input_errors(claims, match):
    with pytest.raises(InputError, match=match):
        check(_symplectic_euler, ["harmonic"], **claims)


def test_bad_problems_and_functions_are_input_errors():
    with pytest.raises(InputError, match="`problems` must be a non-empty list"):
        check(_symplectic_euler, "harmonic", order=1)
    with pytest.raises(InputError, match="`step` must be a function"):
        FunctionStepper(42)
    with pytest.raises(InputError, match="`form` must be one of"):
        FunctionStepper(_symplectic_euler, form="second")


def _fake_installed_harness(where: Path) -> Path:
    """A distribution whose metadata declares the `pytest11` entry point exactly as pyproject.toml
    does, as an installed wheel would: pytest then loads the plugin with no `-p`."""
    import tomllib

    entry = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["pytest11"]
    dist = where / "site" / "integrator_harness_entrypoint-0.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: integrator-harness-entrypoint\nVersion: 0.0\n")
    lines = "".join(f"{name} = {value}\n" for name, value in entry.items())
    (dist / "entry_points.txt").write_text(f"[pytest11]\n{lines}")
    return where / "site"


@pytest.mark.parametrize("extra_args", [[], ["-p", "harness.pytest_plugin"]])
def test_the_entry_point_loads_the_fixture_once(tmp_path, extra_args):
    site = _fake_installed_harness(tmp_path)
    (tmp_path / "test_fixture.py").write_text(
        "def test_fixture_is_there(integrator_claims):\n    assert callable(integrator_claims)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}
    out = subprocess.run(
        [sys.executable, "-m", "pytest", *extra_args, "-p", "no:cacheprovider", "-q",
         "--rootdir", str(tmp_path), str(tmp_path / "test_fixture.py")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "1 passed" in out.stdout
