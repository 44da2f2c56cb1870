"""One folder per experiment: a built-in experiment is `harness/experiments/<name>/`, measuring in
`__init__.py` and presenting in `section.py` beside it; the kit and the report's assembler name no
experiment; and adding one is the folder plus one entry line, checked on a copy of the package
with the tests/plugins experiment folder dropped in as a built-in."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from harness.experiments import EXPERIMENT_MODULES, builtin_experiments

ROOT = Path(__file__).resolve().parents[1]


def test_every_builtin_experiment_is_a_folder_with_its_section_beside_it():
    for exp in builtin_experiments():
        folder = EXPERIMENT_MODULES[exp.name]
        assert type(exp).__module__ == f"harness.experiments.{folder}", exp.name
        assert (ROOT / "harness" / "experiments" / folder / "__init__.py").is_file()
        assert exp.section is not None and exp.section.experiment == exp.name
        assert sys.modules[exp.section.build.__module__].__name__ == f"harness.experiments.{folder}.section"


def test_the_kit_and_the_assembler_name_no_experiment_folder():
    """The report finds sections through the experiments' own `section`, never by importing an
    experiment's folder; the kit sits below every experiment."""
    sys.path.insert(0, str(ROOT / "tests"))
    try:
        from test_import_layers import import_edges, project_modules
    finally:
        sys.path.remove(str(ROOT / "tests"))
    modules = project_modules()
    folders = {f"harness.experiments.{m}" for m in EXPERIMENT_MODULES.values()}
    bad = [(a, b, line) for a, b, _, line in import_edges(modules)
           if a.startswith(("harness.kit", "harness.report")) and any(
               b == f or b.startswith(f + ".") for f in folders)]
    assert not bad, bad


ADD = '''
import json
import harness
from harness.experiments import EXPERIMENT_NAMES, EXPERIMENTS, builtin_experiments
from harness.keys import measuring_modules
from harness.report.sections import section_titles
exp = EXPERIMENTS["evals-per-step"]
counted, _ = measuring_modules(exp)
print(json.dumps({"file": harness.__file__, "names": list(EXPERIMENT_NAMES),
                  "builtin": [e.name for e in builtin_experiments()],
                  "titles": section_titles(EXPERIMENT_NAMES),
                  "section_module": exp.section.build.__module__, "counted": sorted(counted)}))
'''


def test_adding_an_experiment_is_one_folder_and_one_entry_line(tmp_path):
    src = tmp_path / "src"
    shutil.copytree(ROOT / "harness", src / "harness", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "tests" / "plugins" / "evals_per_step",
                    src / "harness" / "experiments" / "evals_per_step",
                    ignore=shutil.ignore_patterns("__pycache__"))
    # a built-in registers itself on import (another package's entry point does that instead)
    folder = src / "harness" / "experiments" / "evals_per_step" / "__init__.py"
    folder.write_text(folder.read_text().replace(
        "from harness.experiments.base import Cell, Experiment, Skip",
        "from harness.experiments.base import Cell, Experiment, Skip, register_experiment")
        + "\n\nregister_experiment(EvalsPerStep())\n")
    listing = src / "harness" / "experiments" / "__init__.py"
    text = listing.read_text()
    entry = '    "side-by-side": "side_by_side",\n'
    assert text.count(entry) == 1
    listing.write_text(text.replace(entry, entry + '    "evals-per-step": "evals_per_step",\n'))
    env = {**os.environ, "PYTHONPATH": str(src)}
    out = subprocess.run([sys.executable, "-c", ADD], env=env, capture_output=True, text=True,
                         timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    seen = json.loads(out.stdout)
    assert seen["file"].startswith(str(src))  # the copy, not this checkout
    assert seen["names"][-1] == seen["builtin"][-1] == "evals-per-step"
    assert ["evals-per-step", "Evaluations per step"] in seen["titles"]
    assert seen["section_module"] == "harness.experiments.evals_per_step.section"
    # the measuring code is in the cells' key, the section is not
    assert "harness.experiments.evals_per_step" in seen["counted"]
    assert not [m for m in seen["counted"] if m.endswith(".section") or m.startswith("harness.kit")]


def test_a_folder_names_its_experiment_and_gives_its_section_unless_the_class_does(tmp_path, monkeypatch):
    body = ("from harness.experiments.base import Experiment\n"
            "SECTION = object()\n"
            "class Probe(Experiment):\n"
            "    cells = run_cell = summarize = None\n"
            "class Named(Experiment):\n"
            "    name = 'own-name'\n"
            "    section = 'own-section'\n"
            "    cells = run_cell = summarize = None\n")
    (tmp_path / "step_probe").mkdir()
    (tmp_path / "step_probe" / "__init__.py").write_text(body)
    (tmp_path / "plain_probe.py").write_text(body)
    monkeypatch.syspath_prepend(str(tmp_path))
    import plain_probe
    import step_probe

    assert (step_probe.Probe.name, step_probe.Probe.section) == ("step-probe", step_probe.SECTION)
    assert (step_probe.Named.name, step_probe.Named.section) == ("own-name", "own-section")
    assert (plain_probe.Probe.name, plain_probe.Probe.section) == ("", None)  # a module, not a folder
