"""Step loops asked of the registry (harness/step_loops.py): the loop that runs a method record,
the fastest implementation of a stepper, and the cache key that covers every implementation a
cell may run. The built-in loops come through the entry-point group `harness.step_loops` like a
third party's (checked with a fake installed distribution, as tests/test_registry_entry_points.py
does for steppers).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from harness import code_versions, keys, step_loops
from harness.coefficients import ButcherTableau
from harness.errors import InputError
from harness.methods import Method
from harness.registry import get_problem, get_stepper, steppers

ROOT = Path(__file__).resolve().parents[1]


def test_the_builtin_loops_are_this_projects_entry_point():
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    assert declared[step_loops.GROUP] == {"builtin": "implementations.builder:builtin_step_loops"}
    names = [loop.name for loop in step_loops.step_loops()]
    assert "explicit Runge-Kutta" in names and "compiled" in names
    assert not step_loops.STEP_LOOP_ERRORS


@pytest.mark.parametrize("name", [n for n in steppers.names() if type(
    getattr(get_stepper(n), "coefficients", None)).__name__ in {"ButcherTableau", "SplittingScheme"}])
def test_a_registered_coefficient_method_is_rebuilt_by_its_familys_loop(name):
    """Every registered Runge-Kutta and splitting stepper: the registry's loop, given its
    coefficients again, builds a stepper of the same class with the same fingerprint."""
    original = get_stepper(name)
    method = Method(original.coefficients, original.info.claimed_order, original.info.reference,
                    original.info.description, original.info.extra.get("stability"))
    if type(original).__name__ == "StaggeredLeapfrog":
        method = Method(method.coefficients, method.claimed_order, method.reference,
                        method.description, method.stability, {"loop": "staggered"})
    rebuilt = step_loops.build_stepper(method)
    assert type(rebuilt) is type(original)


def test_no_loop_for_unknown_coefficients_is_said_by_name():
    class Foreign:
        name = "foreign-method"

        def fingerprint(self):
            return "foreign"

    with pytest.raises(InputError, match=r"method 'foreign-method': no registered step loop runs "
                                         r"coefficients of type Foreign"):
        Method(Foreign(), 2, "none").stepper()


def test_fastest_is_the_compiled_loop_where_it_applies_else_the_stepper():
    rk4, taylor = get_stepper("rk4"), get_stepper("taylor")
    harmonic = get_problem("harmonic")
    assert step_loops.fastest(rk4, harmonic).info.name == "rk4@compiled"
    assert step_loops.implementations_of(taylor) == (taylor,)  # no coefficient object
    assert step_loops.fastest(taylor, harmonic) is taylor
    compiled = get_stepper("rk4@compiled")
    assert step_loops.implementations_of(compiled) == (compiled,)  # never compiled twice


def test_a_kernel_change_changes_the_key_of_every_cell_it_could_have_measured(monkeypatch):
    """The cache key of a NumPy stepper's cell covers its compiled variant's code (experiments
    run `fastest`), so editing a compiled kernel recomputes those cells; a stepper without a
    compiled variant keeps its key."""
    before = {n: keys.code_version(n, "harmonic") for n in ("rk4", "rk4@compiled", "taylor")}
    kernels = "implementations.kernels.one_step"
    read = code_versions._source

    def edited(name):
        text = read(name)
        return text + "\n# edited\n" if name == kernels and text is not None else text

    monkeypatch.setattr(code_versions, "_source", edited)
    after = {n: keys.code_version(n, "harmonic") for n in before}
    assert after["rk4"] != before["rk4"] and after["rk4@compiled"] != before["rk4@compiled"]
    assert after["taylor"] == before["taylor"]


def test_a_family_modules_helper_is_in_the_key_of_its_steppers_only(monkeypatch):
    """A stepper's key covers the module its class is defined in (module-level helpers of its
    loop) and what that imports: editing the second-order multistep module changes the key of
    its steppers, not taylor's (another family's module)."""
    module = type(get_stepper("stormer3")).__module__
    before = {n: keys.code_version(n, "kepler-elliptic") for n in ("stormer3", "taylor")}
    read = code_versions._source
    monkeypatch.setattr(code_versions, "_source", lambda name: read(name) + "\n# edited\n"
                        if name == module else read(name))
    after = {n: keys.code_version(n, "kepler-elliptic") for n in before}
    assert after["stormer3"] != before["stormer3"] and after["taylor"] == before["taylor"]


def test_a_third_party_loop_is_asked_after_the_builtins(tmp_path, monkeypatch):
    """A distribution's `harness.step_loops` entry: its loop builds the records of its own
    coefficient class and offers a faster implementation after the built-in compiled one; a
    broken entry is recorded by name while the rest loads."""
    site = tmp_path / "site"
    dist = site / "thirdparty_loops-0.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: thirdparty-loops\nVersion: 0.0\n")
    (dist / "entry_points.txt").write_text(
        "[harness.step_loops]\nmine = thirdparty_loops:LOOPS\nbroken = no_such_module_xyz:LOOPS\n")
    (site / "thirdparty_loops.py").write_text(
        "from harness.step_loops import StepLoop\n"
        "from implementations.runge_kutta import ExplicitRungeKutta\n\n"
        "class Twin(ExplicitRungeKutta):\n    pass\n\n"
        "def faster(stepper):\n"
        "    return Twin(stepper.coefficients, claimed_order=stepper.info.claimed_order,\n"
        "                reference='twin') if type(stepper) is ExplicitRungeKutta else None\n\n"
        "LOOPS = [StepLoop('twin', faster=faster)]\n")
    monkeypatch.syspath_prepend(str(site))
    for name, value in (("_loaded", []), ("_loops", []), ("STEP_LOOP_ERRORS", [])):
        monkeypatch.setattr(step_loops, name, value)
    monkeypatch.setattr(step_loops, "_variants", type(step_loops._variants)())
    assert [loop.name for loop in step_loops.step_loops()][-1] == "twin"
    assert len(step_loops.STEP_LOOP_ERRORS) == 1 and "'broken'" in step_loops.STEP_LOOP_ERRORS[0]
    table = ButcherTableau("thirdparty-heun", [[0, 0], [1, 0]], [0.5, 0.5])
    heun = Method(table, 2, "Hairer, Norsett & Wanner, Solving ODEs I, II.1").stepper()
    found = [type(s).__name__ for s in step_loops.implementations_of(heun)]
    assert found == ["ExplicitRungeKutta", "CompiledRungeKutta", "Twin"]
    assert step_loops.fastest(heun, get_problem("harmonic")).info.implementation == "compiled"
