"""The README's plugin example, as a new user runs it: the user's method passes the gate on
every catalogue problem with no entry added for it anywhere, the user's problem loads, and a
plugin with one bad record loads the others and names the bad one."""

from __future__ import annotations

import re
from pathlib import Path

from harness.gate import gate_table
from harness.registry import get_problem, load_plugin, plugin_errors, problems, steppers
from harness.runner import run_experiment

README = Path(__file__).resolve().parent.parent / "README.md"


def _plugin_source() -> str:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    plugin = [b for b in blocks if "my_plugin.py" in b]
    assert len(plugin) == 1, "the README shows one plugin file"
    return plugin[0]


def test_readme_plugin_passes_the_gate_on_every_catalogue_problem(tmp_path):
    path = tmp_path / "my_plugin.py"
    path.write_text(_plugin_source())
    catalogue = problems.names()
    names = load_plugin(path)
    try:
        assert set(names) == {"my-rk", "my-quartic"}
        assert get_problem("my-quartic").invariants
        result = run_experiment("convergence", ["my-rk"], [*catalogue, "my-quartic"], jobs=1,
                                progress=False)
        assert result.failures.empty, result.failures.to_dict("records")
        table = gate_table(result.summary)
        assert table.passed.all(), table[["problem", "verdict", "reason"]].to_string()
        assert set(table.problem) >= set(catalogue)
        assert (table.outcome == "pass").sum() >= len(catalogue) - 1
        free_fall = table[table.problem == "free-fall"].iloc[0]
        assert free_fall.verdict == "exact" and free_fall.outcome == "pass"
        # The user's problem gets every experiment that applies to it: it has an energy
        # invariant and a velocity-free Newtonian form.
        from harness.experiments import EXPERIMENTS

        for name in ("energy", "reversibility", "symplecticity", "work-precision"):
            exp = EXPERIMENTS[name]
            cells, skips = exp.cells(["velocity-verlet", "my-rk"], ["my-quartic"], exp.config(quick=True))
            assert {c.stepper for c in cells} == {"velocity-verlet", "my-rk"}, (
                name, [s.reason for s in skips])
    finally:
        for n in names:
            (steppers if n in steppers else problems).unregister(n)


def test_a_bad_record_is_named_and_the_others_load(tmp_path):
    path = tmp_path / "records.py"
    path.write_text(
        "METHODS = [\n"
        "  {'name': 'good-rk', 'A': [[0, 0], [0.5, 0]], 'b': [0, 1], 'claimed_order': 2,\n"
        "   'reference': 'explicit midpoint'},\n"
        "  {'name': 'typo-rk', 'A': [[0, 0], [0.5, 0]], 'b': [0, 0.9], 'claimed_order': 2,\n"
        "   'reference': 'a weight typed wrong'},\n"
        "  {'name': 'good-split', 'sequence': [('D', 0.5), ('K', 1.0), ('D', 0.5)],\n"
        "   'claimed_order': 2, 'reference': 'position Verlet'},\n"
        "]\n"
    )
    names = load_plugin(path)
    try:
        assert names == ["good-rk", "good-split"]
        errors = [e for e in plugin_errors() if "typo-rk" in e]
        assert errors and "must sum to 1" in errors[0]
        # Same coefficients as a built-in, same derived facts.
        assert steppers.get("good-split").info.symmetric is True
    finally:
        for n in names:
            steppers.unregister(n)
