"""Test-wide settings: saved runs go to a temporary directory, never into the repository's
results/. The compiled-code and reference caches stay in the project's .cache/ so one test run
warms them for the next (they are keyed by code and inputs, so sharing them is safe)."""

import pytest


@pytest.fixture(autouse=True)
def _results_in_tmp(tmp_path_factory, monkeypatch):
    import os

    if "HARNESS_RESULTS_DIR" not in os.environ:
        monkeypatch.setenv("HARNESS_RESULTS_DIR", str(tmp_path_factory.mktemp("results")))
