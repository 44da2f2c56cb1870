"""Test-wide settings and shared fixtures.

Saved runs go to a temporary directory, never into the repository's results/. The compiled-code
and reference caches stay in the project's .cache/ so one test run warms them for the next (they
are keyed by code and inputs, so sharing them is safe). Compiled code is shared further: a test
that gives a run a private cache (HARNESS_CACHE_DIR, to start from no cells or to break that
directory) still finds the kernels and heyoka's functions the session compiled, and the imports
parsed from the project's sources for cache keys, since HARNESS_CODE_CACHE_DIR is set here for
the session and its subprocesses (unless already set); a test of a cold compile sets it too.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from harness.cache import code_dir
from harness.problem import Problem
from harness.registry import problems, steppers

os.environ.setdefault("HARNESS_CODE_CACHE_DIR", str(code_dir()))


def pytest_collection_modifyitems(config, items):
    """Tests marked `slow` first (in collection order), then the rest: under pytest-xdist the
    short tests fill the other worker while a long one runs, instead of one worker waiting at the
    end for a long test that started late."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(autouse=True)
def _results_in_tmp(tmp_path_factory, monkeypatch):
    import os

    if "HARNESS_RESULTS_DIR" not in os.environ:
        monkeypatch.setenv("HARNESS_RESULTS_DIR", str(tmp_path_factory.mktemp("results")))


@pytest.fixture
def plugin_file(tmp_path):
    """Write a user's plugin file: `plugin_file(name, source) -> path`. Whatever it registers
    (once loaded, by the test or the CLI) is unregistered afterwards, so later tests see the
    registry unchanged."""
    from harness import registry

    before = (set(registry.steppers.names()), set(registry.problems.names()))
    written: list[Path] = []

    def write(name: str, source: str) -> str:
        path = tmp_path / name
        path.write_text(source)
        written.append(path)
        return str(path)

    yield write
    for reg, names in zip((registry.steppers, registry.problems), before, strict=True):
        for n in set(reg.names()) - names:
            reg.unregister(n)
    for path in written:
        registry._plugins.pop(str(path.resolve()), None)


@pytest.fixture
def registered():
    """Register steppers or problems for one test: `registered(stepper_or_problem) -> name`;
    unregistered afterwards, so later tests in this process see the registry unchanged."""
    added = []

    def add(obj):
        if isinstance(obj, Problem):
            reg, name = problems, obj.name
        else:
            reg, name = steppers, obj.info.name
        reg.register(obj, origin="test")
        added.append((reg, name))
        return name

    yield add
    for reg, name in reversed(added):
        reg.unregister(name)
