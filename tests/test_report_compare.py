"""What changed since the last run: two saved runs of a plugin method under the same name, the
second with one coefficient perturbed (a maintainer's nightly run after a bad edit).

Run 1: the classical RK4 tableau (Kutta 1901) as a plugin `plugin-rk4`; run 2: the same name with
a32 = 1/2 + 0.02, which leaves the method consistent but no longer of order 4. The second report
must list the convergence verdict that changed (pass -> FAIL) and the measured order that moved
beyond both confidence intervals, with both runs' provenance.
"""

from __future__ import annotations

import contextlib
import html
import re
from pathlib import Path

import pytest
from helpers import loaded_plugin

from harness import registry
from harness.report import build_report

NAME = "plugin-rk4"
PLUGIN = '''"""The classical fourth-order Runge-Kutta method (W. Kutta, Z. Math. Phys. 46 (1901) 435),
as a plugin{note}."""
from harness.coefficients import ButcherTableau
from implementations.runge_kutta import ExplicitRungeKutta

STEPPERS = [ExplicitRungeKutta(
    ButcherTableau({name!r}, [[0, 0, 0, 0], [0.5, 0, 0, 0], [0, {a32!r}, 0, 0], [0, 0, 1, 0]],
                   [1 / 6, 1 / 3, 1 / 3, 1 / 6]),
    claimed_order=4,
    reference="W. Kutta, Z. Math. Phys. 46 (1901) 435",
)]
'''
PERTURBATION = 0.02


def plugin(directory: Path, a32: float, note: str) -> contextlib.AbstractContextManager[Path]:
    """The RK4 plugin with coefficient a32, loaded for one block (unregistered afterwards)."""
    path = directory / f"rk4_plugin_{'good' if a32 == 0.5 else 'bad'}.py"
    return loaded_plugin(path, PLUGIN.format(name=NAME, a32=a32, note=note))


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("compare")
    common = dict(steppers=[NAME], problems=["harmonic"], quick=True, jobs=1,
                  output=base / "reports", cache_dir=base / "cache",
                  results_root=base / "results", progress=False)
    with plugin(base, 0.5, "") as good:
        first = build_report(plugins=(str(good),), **common)
    with plugin(base, 0.5 + PERTURBATION, ", with a32 perturbed by 0.02") as bad:
        second = build_report(plugins=(str(bad),), **common)
    text = second.read_text(encoding="utf-8")
    changes = text.split('<section id="changes"')[1].split("</section>")[0]
    return {"first": first, "second": second, "changes": changes, "html": text}


def test_the_changed_verdict_is_listed_with_the_row_it_links_to(two_runs):
    changes = two_runs["changes"]
    table = changes.split('id="changed-verdicts"')[1].split("</table>")[0]
    rows = re.findall(r"<tr[^>]*>(.*?)</tr>", table, re.DOTALL)
    conv = [r for r in rows if "<td>convergence</td>" in r]
    assert conv, table[:2000]
    assert "pass (converged)" in conv[0] and "FAIL" in conv[0]
    target = re.search(r'<a href="#([\w-]+)">', conv[0]).group(1)
    assert f'<tr id="{target}"' in two_runs["html"]


def test_the_measured_order_moved_beyond_its_confidence_interval(two_runs):
    moved = two_runs["changes"].split('id="moved-figures"')[1].split("</table>")[0]
    order = [r for r in re.findall(r"<tr[^>]*>(.*?)</tr>", moved, re.DOTALL)
             if "<td>measured order</td>" in r]
    assert order
    assert "both 95% intervals" in order[0]


def test_both_runs_provenance_is_shown(two_runs):
    changes = two_runs["changes"]
    first_id, second_id = two_runs["first"].parent.name, two_runs["second"].parent.name
    assert f"<td>{first_id}</td>" in changes and f"<td>{second_id}</td>" in changes
    assert "rk4_plugin_good.py" in changes and "rk4_plugin_bad.py" in changes
    headline = html.unescape(re.search(r'<p class="headline fail">([^<]+)</p>', changes).group(1))
    assert headline.startswith(f"Compared with run {first_id}:")


def test_the_first_screen_says_what_changed(two_runs):
    head = two_runs["html"].split('<section id="verdicts"')[1].split('id="scoreboard-table"')[0]
    since = re.search(r'<ol class="verdict-list since"><li><a href="#changes">([^<]+)</a>', head)
    assert since and html.unescape(since.group(1)).startswith("Compared with run ")
    failing = re.search(r"\((\d+) now failing\)", html.unescape(since.group(1)))
    assert failing and int(failing.group(1)) >= 1


def test_the_first_report_says_there_was_nothing_to_compare_with(two_runs):
    text = two_runs["first"].read_text(encoding="utf-8")
    changes = text.split('<section id="changes"')[1].split("</section>")[0]
    assert "No earlier run to compare with" in changes


def test_a_report_compared_with_itself_lists_no_change(two_runs, tmp_path):
    from harness.report import write_report
    from harness.store import load_run

    base = two_runs["second"].parent.parent.parent
    run = load_run(two_runs["second"].parent.name, root=base / "results")
    with plugin(base, 0.5 + PERTURBATION, ", with a32 perturbed by 0.02"):  # loaded by the caller
        again = write_report(run, output=tmp_path / "reports", compare=str(run.path))
    changes = again.read_text(encoding="utf-8").split('<section id="changes"')[1].split("</section>")[0]
    assert "No earlier run to compare with" in changes  # a run is not "earlier" than itself


def test_cli_compare_with_an_unknown_run_fails_in_one_line_before_running(tmp_path, capsys, monkeypatch):
    from harness.cli import main

    monkeypatch.setenv("HARNESS_RESULTS_DIR", str(tmp_path / "results"))
    code = main(["report", "--quick", "--stepper", "euler", "--problem", "harmonic",
                 "--compare", "no-such-run", "--output", str(tmp_path / "reports")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "`run` 'no-such-run'" in err[0]
    assert not (tmp_path / "reports").exists()


def test_cli_from_rerenders_a_saved_run_without_measuring(two_runs, tmp_path, capsys, monkeypatch):
    from harness.cli import main

    results = two_runs["second"].parent.parent.parent / "results"
    run_id = two_runs["second"].parent.name
    monkeypatch.setenv("HARNESS_RESULTS_DIR", str(results))
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path / "empty-cache"))  # nothing to reuse
    runs_before = sorted(p.name for p in results.iterdir())
    try:
        # the same reports directory: the earlier report's recorded verdicts are found there
        reports = str(two_runs["second"].parent.parent)
        code = main(["report", "--from", run_id, "--output", reports])
        refused = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(refused) == 1 and "never imported" in refused[0]  # opt in:
        plugin = two_runs["second"].parent.parent.parent / "rk4_plugin_bad.py"
        code = main(["report", "--from", run_id, "--output", reports, "--plugin", str(plugin)])
    finally:  # the re-render loaded the plugin given to it
        for path in list(registry._plugins):
            if "rk4_plugin" in path:
                for n in [NAME] if NAME in registry.steppers else []:
                    registry.steppers.unregister(n)
                registry._plugins.pop(path, None)
    out = capsys.readouterr().out.strip()
    assert code == 0 and out.endswith("index.html")
    text = Path(out).read_text(encoding="utf-8")
    assert f"Run <code>{run_id}</code>" in text and Path(out).parent.name == f"{run_id}-2"
    assert not (tmp_path / "empty-cache" / "cells").exists()  # no cell was run
    assert sorted(p.name for p in results.iterdir()) == runs_before  # no new run saved
    changes = text.split('<section id="changes"')[1].split("</section>")[0]
    assert 'id="changed-verdicts"' in changes  # compared with the newest older run, as `report` does


def test_cli_from_refuses_measuring_options(tmp_path, capsys):
    from harness.cli import main

    code = main(["report", "--from", "latest", "--stepper", "euler", "--quick",
                 "--output", str(tmp_path / "reports")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "`--from`" in err[0] and "--stepper" in err[0] and "--quick" in err[0]
    assert not (tmp_path / "reports").exists()
