"""Cache keys come from the import graph: editing measuring code recomputes exactly the cells that
depend on it; editing judging code or a judging threshold recomputes nothing and changes verdicts.
"""

from __future__ import annotations

import importlib.util
import sys
import textwrap

import numpy as np
import pytest

from harness import code_versions, keys
from harness import tolerances as tol
from harness.experiments import EXPERIMENTS
from harness.runner import run_experiment


def _fingerprints() -> dict[str, str]:
    return {name: keys.experiment_fingerprint(exp) for name, exp in EXPERIMENTS.items()}


def _edited(monkeypatch, module: str, edit):
    real = code_versions._source

    def source(name):
        text = real(name)
        return edit(text) if name == module else text

    monkeypatch.setattr(code_versions, "_source", source)


def _importers(module: str) -> set[str]:
    return {n for n, e in EXPERIMENTS.items() if module in keys.measuring_modules(e)[0]}


@pytest.mark.parametrize("module", ["harness.theory", "harness.experiments.energy",
                                    "harness.ground_truth", "harness.experiments.convergence"])
def test_editing_an_imported_helper_changes_only_the_experiments_that_import_it(module, monkeypatch):
    importers = _importers(module)
    assert importers and importers != set(EXPERIMENTS)  # the case separates experiments
    before = _fingerprints()
    _edited(monkeypatch, module, lambda text: text + "\n\ndef _helper_added_in_a_test():\n    return 1\n")
    after = _fingerprints()
    assert {n for n in EXPERIMENTS if before[n] != after[n]} == importers


def test_the_stale_cache_cases_of_the_issue_are_covered():
    """The shared sweep and time-scale helpers (once in energy.py, now in experiments/common.py
    and harness/scales.py) are in the keys of every experiment that uses them, and the
    stability measurement's theory package is in its key."""
    for name in ("symplecticity", "reversibility", "energy"):
        counted = keys.measuring_modules(EXPERIMENTS[name])[0]
        assert "harness.experiments.common" in counted, name
        assert "harness.scales" in counted, name
    assert "harness.theory" in keys.measuring_modules(EXPERIMENTS["stability"])[0]


def test_judging_modules_and_thresholds_are_not_in_any_key(monkeypatch):
    before = _fingerprints()
    for name, exp in EXPERIMENTS.items():
        counted, names = keys.measuring_modules(exp)
        assert not {"harness.gate", "harness.experiments.convergence.judge"} & set(counted), name
        assert "GATE_ORDER_TOL" not in names, name
    monkeypatch.setattr(tol, "GATE_ORDER_TOL", tol.GATE_ORDER_TOL * 3)
    _edited(monkeypatch, "harness.gate", lambda text: text + "\n# a new verdict rule\n")
    assert _fingerprints() == before


def test_editing_only_summarize_leaves_the_key_alone(monkeypatch):
    exp = EXPERIMENTS["energy"]
    before = keys.experiment_fingerprint(exp)
    marker = "    def summarize(self, rows"
    assert marker in code_versions._source("harness.experiments.energy")
    _edited(monkeypatch, "harness.experiments.energy",
            lambda text: text.replace(marker, "    def summarize(self, rows_renamed=None, *, rows", 1))
    assert keys.experiment_fingerprint(exp) == before
    _edited(monkeypatch, "harness.experiments.energy",
            lambda text: text.replace("    def run_cell(self, cell", "    def run_cell(self, cell_", 1))
    assert keys.experiment_fingerprint(exp) != before


TOY = '''
"""A toy experiment for the cache-key test: it measures with one threshold and judges with
another (Hairer, Norsett & Wanner, Solving ODEs I, I.7 for the Euler step it takes)."""
import pandas as pd

from harness import tolerances as tol
from harness.experiments.base import Cell, Experiment


def _measure(k):
    return (1.0 + tol.SWEEP_RATIO) ** k


def _judge(value):
    return "good" if value < 10 * tol.GATE_ORDER_TOL else "bad"


class KeyToy(Experiment):
    name = "key-toy"
    default_config = {"n": 3}

    def cells(self, steppers, problems, config):
        return [Cell(self.name, "", "", (("k", k),)) for k in range(config["n"])], []

    def run_cell(self, cell, config):
        return pd.DataFrame({"value": [_measure(cell.param("k"))]})

    def summarize(self, rows, config):
        return rows.assign(verdict=[_judge(v) for v in rows.value])
'''


@pytest.fixture
def key_toy(tmp_path):
    path = tmp_path / "key_toy_experiment.py"
    path.write_text(textwrap.dedent(TOY))
    spec = importlib.util.spec_from_file_location("key_toy_experiment", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["key_toy_experiment"] = module
    spec.loader.exec_module(module)
    yield module.KeyToy(), path
    sys.modules.pop("key_toy_experiment", None)


def test_a_judging_threshold_changes_verdicts_without_recomputing(key_toy, tmp_path, monkeypatch):
    exp, path = key_toy
    run = lambda: run_experiment(exp, [], [], jobs=1, cache_dir=tmp_path / "cache",  # noqa: E731
                                 progress=False)
    first = run()
    assert first.computed_cells == 3
    monkeypatch.setattr(tol, "GATE_ORDER_TOL", 10.0)  # judging only
    second = run()
    assert (second.computed_cells, second.cached_cells) == (0, 3)
    assert list(first.summary.verdict) != list(second.summary.verdict)
    monkeypatch.setattr(tol, "SWEEP_RATIO", 3.0)  # measuring
    third = run()
    assert third.computed_cells == 3
    monkeypatch.undo()
    # a comment in the experiment's module is not code; editing the measuring helper recomputes;
    # editing the judging helper does not
    path.write_text(path.read_text().replace("return (1.0 + tol.SWEEP_RATIO) ** k",
                                             "return (1.0 + tol.SWEEP_RATIO) ** k  # a comment"))
    assert run().computed_cells == 0
    path.write_text(path.read_text().replace("return (1.0 + tol.SWEEP_RATIO) ** k",
                                             "return (1.0 + tol.SWEEP_RATIO) ** k + 0.0"))
    assert run().computed_cells == 3
    path.write_text(path.read_text().replace('"good" if', '"fine" if'))
    assert run().computed_cells == 0


@pytest.mark.parametrize("module", ["harness.stepper.records", "harness.problem.dynamics"])
def test_a_measuring_package_counts_with_its_submodules(module, monkeypatch):
    """`harness.stepper` and `harness.problem` are packages: every cell steps through their
    submodules, so editing one recomputes every experiment's cells."""
    before = _fingerprints()
    _edited(monkeypatch, module, lambda text: text + "\n\ndef _helper_added_in_a_test():\n    return 1\n")
    after = _fingerprints()
    assert all(before[n] != after[n] for n in EXPERIMENTS)


def test_an_experiment_that_imports_no_stepper_still_counts_the_measuring_packages(key_toy):
    """The toy imports neither `harness.stepper` nor `harness.problem`; every cell still steps
    through their submodules (a stepper's carry, a problem's dynamics), so they are in its key."""
    exp, _ = key_toy
    counted = keys.measuring_modules(exp)[0]
    wanted = {"harness.stepper.records", "harness.problem.dynamics", "harness.problem.definition"}
    assert wanted <= set(counted)


def test_a_packed_run_caches_its_summary_until_a_rule_or_threshold_changes(key_toy, tmp_path,
                                                                          monkeypatch):
    """A run whose cells are all cached reads its summary from the cache too; changing a
    threshold or the judging code recomputes the summary (never the cells)."""
    exp, path = key_toy
    calls = []
    real = type(exp).summarize
    monkeypatch.setattr(type(exp), "summarize",
                        lambda self, rows, config: calls.append(1) or real(self, rows, config))
    run = lambda: run_experiment(exp, [], [], jobs=1, cache_dir=tmp_path / "cache",  # noqa: E731
                                 progress=False)
    first = run()
    again = run()
    assert len(calls) == 1 and again.computed_cells == 0
    assert again.summary.equals(first.summary)
    monkeypatch.setattr(tol, "COEFFICIENT_ULPS", tol.COEFFICIENT_ULPS * 2)  # one it does not read
    run()
    assert len(calls) == 2  # every threshold is part of the judging version
    path.write_text(path.read_text().replace('"good" if', '"fine" if'))
    changed = run()  # the judging code's source changed (the loaded module is the old one)
    assert len(calls) == 3 and changed.computed_cells == 0


def test_parsed_imports_kept_on_disk_are_read_back_and_a_damaged_file_is_parsed_again(tmp_path,
                                                                                        monkeypatch):
    # kept with the compiled code (they follow from the source text alone), not with the results
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path / "results-cache"))
    monkeypatch.setenv("HARNESS_CODE_CACHE_DIR", str(tmp_path))
    exp = EXPERIMENTS["energy"]
    code_versions._read_once.cache_clear()
    code_versions._module_imports.cache_clear()
    first = keys.measuring_modules(exp)
    stored = sorted((tmp_path / "keys").rglob("*.json"))
    assert len(stored) > 10  # one file per module text read
    assert not (tmp_path / "results-cache" / "keys").exists()
    code_versions._read_once.cache_clear()
    code_versions._module_imports.cache_clear()
    assert keys.measuring_modules(exp) == first  # read back from disk
    for f in stored:
        f.write_text("{not json")
    code_versions._read_once.cache_clear()
    code_versions._module_imports.cache_clear()
    assert keys.measuring_modules(exp) == first  # parsed again and rewritten
    assert all(f.read_text().startswith('{"key"') for f in stored)


# -- exact and float64 records of the same method --------------------------------------------------
_KUTTA3 = ([[0, 0, 0], ["1/2", 0, 0], [-1, 2, 0]], ["1/6", "2/3", "1/6"])


def _kutta3(exact: bool):
    from fractions import Fraction

    from harness.coefficients import ButcherTableau
    from harness.methods import Method

    as_number = (lambda x: Fraction(x)) if exact else (lambda x: float(Fraction(x)))
    A = [[as_number(x) for x in row] for row in _KUTTA3[0]]
    table = ButcherTableau("kutta3-cache-twin", A, [as_number(x) for x in _KUTTA3[1]])
    return Method(table, 3, "W. Kutta, Z. Math. Phys. 46 (1901) 435").stepper()


def test_an_exact_record_and_its_float64_twin_never_share_a_cell_key():
    """Same floats, same name: only the exact one can be rerun in real128 (and has no error floor
    of its digits), so a cell cached for one must never be served for the other."""
    from harness import registry

    keys_by_kind = {}
    for exact in (True, False, True):
        stepper = _kutta3(exact)
        registry.steppers.register(stepper, replace=True)
        try:
            keys_by_kind.setdefault(exact, set()).add(keys.code_version(stepper.info.name, "harmonic"))
        finally:
            registry.steppers.unregister(stepper.info.name)
    assert _kutta3(True).coefficients.exact is not None and _kutta3(False).coefficients.exact is None
    assert np.array_equal(_kutta3(True).coefficients.b, _kutta3(False).coefficients.b)
    assert len(keys_by_kind[True]) == 1  # the same record keeps its key
    assert keys_by_kind[True].isdisjoint(keys_by_kind[False])


def test_every_registered_exact_record_shares_its_fingerprint_with_a_float64_twin_only_when_equal():
    """A twin built from a record's float64 values alone is the same record (same fingerprint)
    exactly when its exact form is the record's (dyadic coefficients), and never otherwise."""
    from harness.coefficients import ButcherTableau, SplittingScheme
    from harness.registry import get_stepper, steppers

    seen = {ButcherTableau: 0, SplittingScheme: 0}
    for name in steppers.names():
        c = getattr(get_stepper(name), "coefficients", None)
        if type(c) not in seen or c.exact is None:
            continue
        if isinstance(c, ButcherTableau):
            twin = ButcherTableau(c.name, c.A, c.b, c.c, c.b_hat)
            same = twin.exact == c.exact and twin.exact_b_hat == c.exact_b_hat
        else:
            twin = SplittingScheme(c.name, list(c.sequence))
            same = twin.exact == c.exact
        assert twin.float_fingerprint() == c.float_fingerprint(), name
        assert (twin.fingerprint() == c.fingerprint()) == same, name
        seen[type(c)] += not same
    assert all(n >= 1 for n in seen.values()), seen  # exact records that float64 cannot hold


def test_a_course_claim_matches_a_method_however_precisely_its_record_is_given():
    """The course's RK4 is written in float64 (1/6 rounded); the catalogue's rk4 is exact. They
    key different cells, yet the claim about the method applies to it."""
    from harness.registry import get_stepper
    from harness.report.claims import RK4, steppers_with

    record = get_stepper("rk4").coefficients
    assert RK4.exact is None and record.exact is not None
    assert RK4.fingerprint() != record.fingerprint()
    assert "rk4" in steppers_with(RK4)
