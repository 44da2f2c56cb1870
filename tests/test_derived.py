"""Derived problem facts kept on disk (`harness.derived`): computed once, served again only for
the same code and arguments, recomputed when the file is damaged, never an error."""

from __future__ import annotations

import math

import pytest

from harness import derived


@pytest.fixture
def calls(tmp_path, monkeypatch):
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path))
    made: list[int] = []

    def compute():
        made.append(1)
        return [1.5, "why", math.inf]

    return made, compute


def test_a_value_is_computed_once_and_served_again(calls):
    made, compute = calls
    first = derived.remembered("harness.scales", "f", ("p", 2.0), compute)
    again = derived.remembered("harness.scales", "f", ("p", 2.0), compute)
    assert first == again == [1.5, "why", math.inf] and len(made) == 1
    derived.remembered("harness.scales", "f", ("p", 3.0), compute)  # other arguments
    derived.remembered("harness.scales", "g", ("p", 2.0), compute)  # another function
    assert len(made) == 3


def test_changed_code_is_a_new_value(calls, monkeypatch):
    made, compute = calls
    derived.remembered("harness.scales", "f", ("p",), compute)
    monkeypatch.setattr(derived, "_version", lambda module: "edited")
    derived.remembered("harness.scales", "f", ("p",), compute)
    assert len(made) == 2


def test_the_version_follows_an_edit_of_an_imported_module(tmp_path, monkeypatch):
    from harness import code_versions as keys

    before = keys.module_version("harness.scales")
    original = keys._source

    def edited(name):
        text = original(name)
        return text + "\n# edited\n" if name == "harness.cache" and text else text

    monkeypatch.setattr(keys, "_source", edited)
    assert keys.module_version("harness.scales") != before


@pytest.mark.parametrize("damage", [b"", b"{not json", b'{"key": "other", "value": 7}'])
def test_a_damaged_file_is_recomputed_and_replaced(calls, tmp_path, damage):
    made, compute = calls
    derived.remembered("harness.scales", "f", ("p",), compute)
    (path,) = (tmp_path / "derived").rglob("*.json")
    path.write_bytes(damage)
    assert derived.remembered("harness.scales", "f", ("p",), compute) == [1.5, "why", math.inf]
    assert len(made) == 2
    assert derived.remembered("harness.scales", "f", ("p",), compute) and len(made) == 2


def test_without_a_cache_directory_the_value_is_computed(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(blocker / "cache"))
    assert derived.remembered("harness.scales", "f", ("p",), lambda: 4) == 4


def _ask_slowly(cache: str, log: str, start: float) -> None:
    """One process's request for a slow fact, begun at wall-clock time `start`."""
    import os
    import time

    os.environ["HARNESS_CACHE_DIR"] = cache
    time.sleep(max(0.0, start - time.time()))

    def compute():
        with open(log, "a") as fh:
            fh.write(f"{os.getpid()}\n")
        time.sleep(0.5)
        return 42

    assert derived.remembered("harness.scales", "slow", ("p",), compute) == 42


def test_processes_asking_at_once_compute_the_value_once(tmp_path):
    """Two processes ask for the same missing fact at the same moment: one computes it while
    the other waits on the key's lock, then reads it."""
    import multiprocessing
    import time

    log = tmp_path / "computed.log"
    start = time.time() + 0.5
    context = multiprocessing.get_context("spawn")
    procs = [context.Process(target=_ask_slowly, args=(str(tmp_path), str(log), start))
             for _ in range(2)]
    for proc in procs:
        proc.start()
    for proc in procs:
        proc.join(60)
    assert [proc.exitcode for proc in procs] == [0, 0]
    assert len(log.read_text().split()) == 1
