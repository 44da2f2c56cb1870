"""Built-ins through the same door as plugins: the registry's steppers and problems all come in
through the entry-point groups `harness.steppers` and `harness.problems` (harness/registry.py).

Checked on this project's installed metadata and on a fake installed distribution (a
`*.dist-info` directory on `sys.path`, as numcodecs tests its entry points): the built-ins first
and in their catalogue's order, a third party's entries after them with their origin, a broken
third-party entry recorded by name while the rest loads, a missing built-in entry point said
plainly.
"""

from __future__ import annotations

import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

import harness
from harness import entry_points
from harness.problem import Problem
from harness.registry import Registry
from harness.stepper import Stepper

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]

# (group, registry of the process, the catalogue's own list)
GROUPS = [("harness.steppers", Stepper, "implementations", "builtin_steppers"),
          ("harness.problems", Problem, "problems", "builtin_problems")]


def _name(obj) -> str:
    return obj.info.name if isinstance(obj, Stepper) else obj.name


def test_the_distribution_named_by_the_registry_is_this_project():
    assert harness.DISTRIBUTION == PYPROJECT["name"]
    assert metadata.distribution(harness.DISTRIBUTION).entry_points.select(group="harness.steppers")


@pytest.mark.parametrize(("group", "cls", "package", "function"), GROUPS)
def test_builtins_are_this_projects_entry_points_in_catalogue_order(group, cls, package, function):
    declared = PYPROJECT["entry-points"][group]
    assert declared == {"builtin": f"{package}:{function}"}
    installed = [ep for ep in metadata.entry_points(group=group) if entry_points._is_own(ep)]
    assert [(ep.name, ep.value) for ep in installed] == list(declared.items()), (
        "the installed metadata is stale: run `make setup`")
    fresh = Registry(group.split(".")[1][:-1], cls, group)
    catalogue = [_name(o) for o in getattr(__import__(package), function)()]
    builtins = [n for n in fresh.names(variants=True) if fresh.origin(n) == "builtin"]
    assert builtins == catalogue
    assert not fresh.errors


def _fake_distribution(site: Path, name: str, groups: dict[str, dict[str, str]]) -> None:
    dist = site / f"{name.replace('-', '_')}-0.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.0\n")
    (dist / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in entries.items())
        for group, entries in groups.items()))


CATALOGUE = '''
from harness.methods import method_from_record

def steppers():
    """Heun's method (Hairer, Norsett & Wanner, Solving ODEs I, II.1), under a third party's name."""
    record = {"name": "thirdparty-heun", "A": [[0, 0], [1, 0]], "b": [0.5, 0.5], "claimed_order": 2,
              "reference": "Hairer, Norsett & Wanner, Solving ODEs I, II.1"}
    return method_from_record(record).steppers()
'''


def test_a_third_party_distribution_registers_after_the_builtins(tmp_path, monkeypatch):
    site = tmp_path / "site"
    _fake_distribution(site, "thirdparty-catalogue", {
        "harness.steppers": {"heun": "thirdparty_catalogue:steppers",
                             "broken": "no_such_module_xyz:STEPPERS"},
        "harness.problems": {"quartic": "quartic:PROBLEMS"},
    })
    (site / "thirdparty_catalogue.py").write_text(CATALOGUE)
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(ROOT / "tests" / "plugins"))
    monkeypatch.delitem(sys.modules, "quartic", raising=False)
    steppers = Registry("stepper", Stepper, "harness.steppers")
    problems = Registry("problem", Problem, "harness.problems")
    names = steppers.names(variants=True)
    assert names[-1] == "thirdparty-heun"
    assert steppers.origin("thirdparty-heun") == "entry point heun (thirdparty_catalogue:steppers)"
    assert all(steppers.origin(n) == "builtin" for n in names[:-1])
    assert len(steppers.errors) == 1
    assert "'broken'" in steppers.errors[0] and "ModuleNotFoundError" in steppers.errors[0]
    assert problems.names(variants=True)[-1] == "quartic-oscillator"
    assert problems.origin("quartic-oscillator").startswith("entry point quartic")
    assert not problems.errors


def test_missing_builtin_entry_points_are_said_plainly(monkeypatch):
    monkeypatch.setattr(entry_points, "DISTRIBUTION", "not-this-project")
    fresh = Registry("problem", Problem, "harness.problems")
    fresh.names()
    assert fresh.errors[0] == (
        "no built-in problems: the 'harness.problems' entry points of not-this-project are not "
        "installed; install the project (`make setup`, or `pip install -e .`)")


def test_a_failing_builtin_entry_point_raises(monkeypatch):
    """A built-in that cannot load is an error, never a silently smaller registry."""
    import problems

    monkeypatch.setattr(problems, "PROBLEM_MODULES", (*problems.PROBLEM_MODULES, "renamed_family"))
    fresh = Registry("problem", Problem, "harness.problems")
    with pytest.raises(ModuleNotFoundError, match="renamed_family"):
        fresh.names()


# -- experiments through the same door ----------------------------------------------------------------
EXPERIMENT_SCRIPT = '''
import json
from harness.experiments import EXPERIMENT_NAMES, EXPERIMENTS
from harness.experiments.base import EXPERIMENT_ERRORS
from harness.report import report_experiments
from harness.report.sections import section_titles
print(json.dumps({"listed": list(EXPERIMENTS), "builtin": list(EXPERIMENT_NAMES),
                  "report": report_experiments(), "titles": section_titles(report_experiments()),
                  "errors": EXPERIMENT_ERRORS}))
'''


def _experiment_site(tmp_path: Path) -> dict:
    import os

    site = tmp_path / "site"
    _fake_distribution(site, "thirdparty-experiments", {"harness.experiments": {
        "evals": "evals_per_step:EvalsPerStep", "broken": "no_such_module_xyz:EXPERIMENT"}})
    path = os.pathsep.join([str(site), str(ROOT / "tests" / "plugins"), str(ROOT)])
    return {**os.environ, "PYTHONPATH": path}


def test_an_experiment_from_another_distribution_is_listed_run_and_reported(tmp_path):
    """The tests/plugins experiment (one folder, as a built-in's), registered only by a fake
    installed distribution's entry point: listed after the built-ins, run by the CLI, and in the
    report with the section it names and its scoreboard column; a broken entry point is a
    warning naming it."""
    import json
    import subprocess

    env = _experiment_site(tmp_path)
    out = subprocess.run([sys.executable, "-c", EXPERIMENT_SCRIPT], env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    seen = json.loads(out.stdout)
    assert seen["listed"] == [*seen["builtin"], "evals-per-step"]
    assert seen["report"] == [*seen["builtin"], "evals-per-step"]
    assert ["evals-per-step", "Evaluations per step"] in seen["titles"]  # its own section
    assert len(seen["errors"]) == 1 and "'broken'" in seen["errors"][0]
    harness_cli = str(Path(sys.executable).with_name("harness"))
    listed = subprocess.run([harness_cli, "list", "experiments"], env=env, capture_output=True,
                            text=True, timeout=300)
    assert listed.returncode == 0 and "evals-per-step" in listed.stdout.splitlines()[-1]
    assert "warning: entry point 'broken'" in listed.stderr
    env.update(HARNESS_CACHE_DIR=str(tmp_path / "cache"), HARNESS_RESULTS_DIR=str(tmp_path / "results"),
               HARNESS_REPORTS_DIR=str(tmp_path / "reports"))
    ran = subprocess.run([harness_cli, "run", "evals-per-step", "--stepper", "rk4", "--stepper",
                          "leapfrog", "--problem", "harmonic", "--quick", "--jobs", "1", "--json"],
                         env=env, capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    rows = {r["stepper"]: r for r in json.loads(ran.stdout)}
    assert rows["rk4"]["evals"] == 80 and rows["leapfrog"]["evals"] == 21
    assert all(r["passed"] for r in rows.values())
    report = subprocess.run([harness_cli, "report", "--from", "latest"], env=env, capture_output=True,
                            text=True, timeout=600)
    assert report.returncode == 0, report.stderr
    page = Path(report.stdout.strip().splitlines()[-1]).read_text(encoding="utf-8")
    section = page.split('<section id="evals-per-step"', 1)[1].split("</section>", 1)[0]
    assert "Evaluations per step" in section and "evaluations counted" in section
    assert "could not be built" not in section
    assert all(f">{name}<" in section for name in ("rk4", "leapfrog"))
    assert "evaluations per step (counted)" in page  # its scoreboard column
