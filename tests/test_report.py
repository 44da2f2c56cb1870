"""`harness report`: one self-contained HTML file with every section, one scoreboard row per
stepper, inline SVG figures, no external resource, and names from plugins shown as text.

The report is built once per module in --quick mode over a small grid (five built-in steppers, a
plugin stepper named `<script>alert(1)</script>`, the harmonic oscillator) into temporary
directories; `build_quick_report` is shared with the browser test, which reuses the cell cache.
"""

from __future__ import annotations

import base64
import contextlib
import gzip
import html
import io
import json
import math
import re
from pathlib import Path

import pandas as pd
import pytest
from helpers import loaded_plugin

from harness import tolerances as tol
from harness.errors import InputError
from harness.experiments.roundoff import RoundoffExperiment, step_sizes
from harness.kit.figure_style import MAX_LINES_PER_PANEL
from harness.kit.figure_svg import UnsafeFigureError, check_svg
from harness.report import build_report, report_experiments, write_report
from harness.report.claims import CLAIMS
from harness.report.sections import section_titles
from harness.store import load_run

HOSTILE = "<script>alert(1)</script>"
STEPPERS = ["euler", "rk4", "velocity-verlet", "stormer-verlet", "leapfrog"]
PROBLEMS = ["harmonic", "kepler-elliptic"]
HOSTILE_PLUGIN = f'''"""A plugin whose stepper name and texts are markup: the midpoint rule (Runge,
Math. Ann. 46 (1895)) under a hostile name, for the report's escaping test."""
from harness.coefficients import ButcherTableau
from implementations.runge_kutta import ExplicitRungeKutta

STEPPERS = [ExplicitRungeKutta(
    ButcherTableau({HOSTILE!r}, [[0, 0], [0.5, 0]], [0, 1]),
    claimed_order=2,
    reference="<img src=x onerror=alert(2)> C. Runge, Math. Ann. 46 (1895)",
    description="<b>bold</b> midpoint",
)]
'''


def hostile_plugin(directory: Path) -> contextlib.AbstractContextManager[Path]:
    """The hostile plugin file, loaded; unregistered again afterwards so later tests see the
    registry unchanged."""
    return loaded_plugin(directory / "hostile_plugin.py", HOSTILE_PLUGIN)


def build_quick_report(shared: Path, own: Path, plugin: Path) -> Path:
    """A --quick report of STEPPERS + the hostile plugin stepper on PROBLEMS, in process, with the
    cell cache under `shared` (reused by every test module of the session) and results and
    reports under `own`. Returns the index.html path."""
    return build_report(
        steppers=[*STEPPERS, HOSTILE], problems=PROBLEMS, quick=True, jobs=1,
        plugins=(str(plugin),), output=own / "reports", cache_dir=shared,
        results_root=own / "results", progress=False,
    )


def shared_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.getbasetemp() / "report-shared"
    d.mkdir(exist_ok=True)
    return d


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    shared = shared_dir(tmp_path_factory)
    own = tmp_path_factory.mktemp("report")
    with hostile_plugin(shared) as plugin:
        path = build_quick_report(shared, own, plugin)
        yield {"path": path, "html": path.read_text(encoding="utf-8"), "own": own,
               "plugin": plugin}


# -- the file -----------------------------------------------------------------------------------
def test_report_is_written_under_the_output_directory_and_latest_points_at_it(report):
    path, own = report["path"], report["own"]
    assert path.name == "index.html" and path.parent.parent == own / "reports"
    assert re.fullmatch(r"\d{8}T\d{6}Z-[0-9a-z]+(-\d+)?", path.parent.name)
    latest = own / "reports" / "latest"
    assert latest.is_dir() and (latest / "index.html").read_bytes() == path.read_bytes()
    # no staging directory left behind
    assert not [p for p in (own / "reports").iterdir() if p.name.startswith(".")]
    run = load_run(None, root=own / "results")
    assert run.run_id == path.parent.name
    assert run.meta["config"]["run"]["quick"] is True
    assert run.experiments == report_experiments()


def test_every_section_heading_is_present_in_order(report):
    """One section per experiment of the registry (symplecticity included), in its order,
    between the fixed ones; each experiment section opens with its two-sentence intro."""
    titles = section_titles(report_experiments())
    headings = re.findall(r'<h2 id="h-([\w-]+)">(\d+) ([^<]+)</h2>', report["html"])
    assert [(k, int(n)) for k, n, _ in headings] == [(k, i + 1) for i, (k, _) in enumerate(titles)]
    for (_, _, text), (_, title) in zip(headings, titles, strict=True):
        assert html.unescape(text) == title
    assert "symplecticity" in [k for k, _, _ in headings]
    assert "could not be built" not in report["html"]
    for name in report_experiments():
        body = report["html"].split(f'<section id="{name}"')[1].split("</section>")[0]
        intro = re.search(r'<p class="intro">([^<]+)</p>', body)
        assert intro and intro.group(1).count(". ") >= 1, name


def test_first_screen_leads_with_the_verdict_count_and_each_failing_claim(report):
    """The page opens with the verdicts: how many claims were checked and failed, each failing
    one in a sentence linking to its row, before the scoreboard; counts match the run's."""
    from harness.report import run_view
    from harness.report.verdicts import collect_verdicts

    text = report["html"]
    head = text.split('<section id="verdicts"')[1].split("</section>")[0]
    verdicts = collect_verdicts(run_view(load_run(None, root=report["own"] / "results")))
    n_bad = int((~verdicts["passed"]).sum())
    m = re.search(r'<p class="headline (?:fail|pass)">(\d+) claims checked in (\d+) experiments', head)
    judged = verdicts[verdicts["judged"]]
    assert m and int(m.group(1)) == len(judged) and len(judged) > 20
    assert f": {n_bad} failed." in head
    # only rows that judge a claim are counted: a passing no-claim or not-measurable row is
    # informational, and the headline says how many there are
    info = verdicts[~verdicts["judged"]]
    assert info["passed"].all() and not judged["verdict"].isin(["no-claim", "measured"]).any()
    if len(info):
        assert f"{len(info)} further cells are informational" in head
    assert head.index('class="headline') < head.index('id="scoreboard-table"')
    listed = [a for a in re.findall(r'<li><a href="#([\w-]+)">', head) if a != "changes"]
    assert len(listed) == n_bad
    ids = set(re.findall(r'<tr id="([\w-]+)"', text))
    assert set(listed) <= ids


def test_every_scoreboard_link_points_at_a_row_of_the_page(report):
    table = report["html"].split('id="scoreboard-table"')[1].split("</table>")[0]
    links = re.findall(r'<a href="#([\w-]+)">', table)
    ids = set(re.findall(r'\bid="([\w-]+)"', report["html"]))
    assert len(links) >= 4 * len([*STEPPERS, HOSTILE])
    assert set(links) <= ids, set(links) - ids


def test_every_link_of_the_page_finds_its_target(report):
    """Row ids no link points to are dropped and figure ids shortened: every in-page link
    (scoreboard, verdict list, notes, figure markers and clip paths) still finds one target."""
    text = report["html"]
    ids = re.findall(r'\bid="([^"]+)"', text)
    assert len(ids) == len(set(ids))
    targets = re.findall(r'(?:href="#|url\(#)([^")]+)', text)
    assert targets and set(targets) <= set(ids), set(targets) - set(ids)


def test_reasons_are_numbered_notes_written_once_per_table(report):
    text = report["html"]
    tables = re.findall(r'<table class="[^"]*" id="([\w-]+)">(.*?)</table>\s*</div>\s*'
                        r'(<ol class="notes">.*?</ol>)?', text, re.DOTALL)
    assert tables
    n_notes = 0
    for tid, body, notes in tables:
        refs = set(re.findall(rf'href="#{tid}-n(\d+)"', body))
        items = re.findall(rf'<li id="{tid}-n(\d+)">([^<]*)</li>', notes or "")
        assert refs == {n for n, _ in items}, tid
        # the list numbers its items 1, 2, ...: each note's number is its place in the list
        assert [int(n) for n, _ in items] == list(range(1, len(items) + 1)), tid
        assert len({t for _, t in items}) == len(items), tid  # each reason once
        n_notes += len(items)
    # Every reason shown is a note reference: a table cell never holds the reason text itself.
    referenced = len(re.findall(r'href="#[\w-]+-n\d+"', text))
    assert (n_notes > 0) == (referenced > 0)


def test_per_cell_tables_are_folded(report):
    text = report["html"]
    for name in ("convergence", "stability", "reversibility", "energy", "symplecticity"):
        body = text.split(f'<section id="{name}"')[1].split("</section>")[0]
        assert '<details class="table"><summary>Per ' in body, name


def test_every_figure_offers_its_data_as_an_embedded_csv(report):
    figures = re.findall(r"<figure>(.*?)</figure>", report["html"], re.DOTALL)
    assert figures
    for fig in figures:
        m = re.search(r'<a class="data" download="([\w.-]+\.csv\.gz)" '
                      r'href="data:application/gzip;base64,([A-Za-z0-9+/=]*)"', fig)
        assert m, fig[-300:]
        frame = pd.read_csv(io.BytesIO(gzip.decompress(base64.b64decode(m.group(2)))))
        assert len(frame) > 0
        assert "stepper" in frame.columns or "benchmark" in frame.columns


def test_small_multiples_hold_at_most_eight_methods_a_panel_and_every_method_once():
    """Panels per family: a large family is cut into parts of at most MAX_LINES_PER_PANEL,
    small families share a panel while they fit, no method is lost or repeated."""
    from harness.kit.figure_style import panels

    family = {f"s{i}": "splitting" for i in range(15)}
    family.update({"bdf2": "multistep", "ab2": "multistep", "taylor": "taylor", "gl4": "implicit-rk"})
    groups = panels(list(family), family)
    assert MAX_LINES_PER_PANEL == 8
    assert all(0 < len(members) <= MAX_LINES_PER_PANEL for _, members in groups)
    assert sorted(m for _, members in groups for m in members) == sorted(family)
    titles = [title for title, _ in groups]
    assert titles[:2] == ["splitting (1/2)", "splitting (2/2)"]
    assert titles[2] == "multistep, taylor, implicit-rk"  # small families packed into one panel
    # energy panels (one per drift class) are never packed together
    assert len(panels(["a", "b"], {"a": "bounded", "b": "linear"}, pack=False)) == 2


def test_every_registered_experiment_names_its_section():
    """Built-in experiments each name their section (a new one without falls back to the
    generic table, which works but is not what a reader should get for a built-in), and the
    report takes that one."""
    from harness.experiments import EXPERIMENTS, builtin_experiments
    from harness.kit import SectionSpec
    from harness.report.specs import section_spec

    for exp in builtin_experiments():
        assert isinstance(exp.section, SectionSpec), exp.name
        assert exp.section.experiment == exp.name
        assert section_spec(exp.name) is exp.section is EXPERIMENTS[exp.name].section


def test_scoreboard_has_one_row_per_stepper_failing_first_and_marked_in_text(report):
    table = report["html"].split('id="scoreboard-table"')[1].split("</table>")[0]
    rows = re.findall(r'<tr id="[\w-]+" class="stepper-row (fail|pass|none)" data-stepper="([^"]*)">', table)
    assert sorted(html.unescape(s) for _, s in rows) == sorted([*STEPPERS, HOSTILE])
    statuses = [s for s, _ in rows]
    order = {"fail": 0, "pass": 1, "none": 2}
    assert statuses == sorted(statuses, key=order.get)
    for status, marker in (("fail", "✗ FAIL"), ("pass", "✓ pass")):
        n = statuses.count(status)
        assert table.count(f'<td class="status {status}">{marker}</td>') == n


def test_figures_are_inline_svg_with_a_size(report):
    svgs = re.findall(r"<svg\b[^>]*>", report["html"])
    slugs = {re.search(r'data-slug="([^"]*)"', t).group(1) for t in svgs}
    expected = {"stability-overlay", "stability-hw", "roundoff", "symplecticity", "reversibility",
                "angular_momentum-kepler-elliptic", "work-kepler-elliptic"}
    expected |= {f"{kind}-{p}" for kind in ("convergence", "energy")
                 for p in PROBLEMS}
    assert expected <= slugs
    assert len(svgs) == report["html"].count("<figure>")
    for tag in svgs:
        w = re.search(r'\bwidth="([\d.]+)"', tag)
        h = re.search(r'\bheight="([\d.]+)"', tag)
        assert w and h and float(w.group(1)) > 0 and float(h.group(1)) > 0, tag
    assert "<img" not in report["html"].split("<body>")[1].replace("&lt;img", "")


def test_no_script_and_no_external_resource(report):
    text = report["html"]
    assert re.search(r"<script\b", text, re.IGNORECASE) is None
    assert re.search(r"<link\b", text, re.IGNORECASE) is None
    assert re.search(r"""(?:src|href)\s*=\s*["']?\s*(?:https?:)?//""", text, re.IGNORECASE) is None
    assert re.search(r"url\(\s*['\"]?\s*(?:https?:)?//", text, re.IGNORECASE) is None
    assert "@import" not in text and "@font-face" not in text
    assert "Content-Security-Policy" in text and "default-src 'none'" in text


def test_plugin_named_with_markup_is_shown_as_text(report):
    text = report["html"]
    assert HOSTILE not in text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text
    assert "<img src=x" not in text and "<b>bold</b>" not in text
    # in the figures too: matplotlib writes the legend entry as escaped SVG text
    svg = re.findall(r"<svg\b.*?</svg>", text, re.DOTALL)
    assert any("&lt;script&gt;alert(1)&lt;/script&gt;" in s for s in svg)


def test_claims_section_lists_every_claim_with_its_course_source(report):
    claims = report["html"].split('id="claims"')[1].split("</section>")[0]
    for spec in CLAIMS:
        assert spec.source in claims
    verdicts = re.findall(r'<td class="status (pass|fail|none)">', claims.split("</table>")[0])
    assert len(verdicts) == len(CLAIMS)


def test_provenance_lists_each_experiment_with_its_time_and_the_configuration(report):
    prov = report["html"].split('id="provenance"')[1].split("</section>")[0]
    for name in report_experiments():
        assert f"<td>{name}</td>" in prov
    assert "full configuration (JSON)" in prov
    run = load_run(None, root=report["own"] / "results")
    assert run.provenance["git"]["sha"] is None or run.provenance["git"]["sha"][:7] in report["html"]


def test_rewriting_a_saved_run_gives_the_same_sections(report, tmp_path):
    run = load_run(None, root=report["own"] / "results")
    again = write_report(run, output=tmp_path / "reports").read_text(encoding="utf-8")
    heads = re.compile(r'<h2 id="h-[\w-]+">[^<]+</h2>')
    assert heads.findall(again) == heads.findall(report["html"])
    rows = re.compile(r'<tr id="[\w-]+" class="stepper-row[^"]*" data-stepper="[^"]*">')
    assert rows.findall(again) == rows.findall(report["html"])


# -- the roundoff experiment (the claims section's rounding claim) ------------------------------
def test_roundoff_experiment_separates_the_two_step_form_from_leapfrog(report):
    run = load_run(None, root=report["own"] / "results")
    s = run.summaries["roundoff"].set_index("stepper")
    assert set(s.index) == {"stormer-verlet", "leapfrog", "velocity-verlet"}
    two = s.loc["stormer-verlet", "floor_error"]
    one = max(s.loc["leapfrog", "floor_error"], s.loc["velocity-verlet", "floor_error"])
    assert math.isfinite(two) and math.isfinite(one)
    assert two >= tol.ROUNDOFF_CLAIM_RATIO * one
    assert bool(s.loc["stormer-verlet", "rounding_limited"])
    skips = pd.DataFrame(run.meta["experiments"]["roundoff"]["skips"])
    assert "euler" in set(skips.stepper) and "rk4" in set(skips.stepper)


BAD_SWEEPS = [
    ((0.0, 1e-6, 2), r"`h_max` must be a positive finite number, got 0\.0"),
    ((1e-2, float("nan"), 2), r"`h_min` must be a positive finite number"),
    ((1e-6, 1e-2, 2), r"`h_min` must be smaller than `h_max`"),
    ((1e-2, 1e-6, 0), r"`points_per_decade` must be a whole number >= 1, got 0"),
]


@pytest.mark.parametrize(("args", "message"), BAD_SWEEPS)
def test_roundoff_sweep_rejects_bad_settings(args, message):
    with pytest.raises(InputError, match=message):
        step_sizes(*args)


def test_roundoff_sweep_is_geometric_from_h_max_to_h_min():
    hs = step_sizes(1e-2, 1e-6, 2)
    assert len(hs) == 9 and hs[0] == pytest.approx(1e-2) and hs[-1] == pytest.approx(1e-6)
    assert max(abs(r - 10 ** -0.5) for r in hs[1:] / hs[:-1]) < 1e-12


def test_roundoff_cells_only_for_its_steppers_and_problems():
    exp = RoundoffExperiment()
    cells, skips = exp.cells(["rk4", "leapfrog", "stormer-verlet"], ["harmonic", "gaussian"],
                             exp.config(quick=True))
    assert [(c.stepper, c.problem) for c in cells] == [("leapfrog", "harmonic"),
                                                      ("stormer-verlet", "harmonic")]
    reasons = {(s.stepper, s.problem): s.reason for s in skips}
    assert "not in this experiment's stepper set" in reasons[("rk4", "")]
    assert "not in this experiment's problem set" in reasons[("", "gaussian")]


# -- building blocks ----------------------------------------------------------------------------
UNSAFE_SVG = [
    ('<svg xmlns="http://www.w3.org/2000/svg"><script>alert(1)</script></svg>', r"<script>"),
    ('<svg xmlns="http://www.w3.org/2000/svg"><g onload="alert(1)"/></svg>', r"event attribute"),
    ('<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink">'
     '<use xlink:href="http://example.com/a.svg#x"/></svg>', r"links outside itself"),
    ('<svg xmlns="http://www.w3.org/2000/svg"><path style="fill:url(http://e.com/x)"/></svg>',
     r"outside resource"),
    ('<svg xmlns="http://www.w3.org/2000/svg"><foreignObject/></svg>', r"<foreignObject>"),
    ("<svg", r"not well-formed"),
    ('<html xmlns="http://www.w3.org/1999/xhtml"/>', r"root is <html>"),
]


@pytest.mark.parametrize(("svg", "message"), UNSAFE_SVG)
def test_check_svg_rejects_anything_but_a_plain_drawing(svg, message):
    with pytest.raises(UnsafeFigureError, match=message):
        check_svg(svg)


def test_check_svg_accepts_internal_references():
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink">'
           '<defs><clipPath id="c"><rect/></clipPath><path id="m"/></defs>'
           '<g clip-path="url(#c)"><use xlink:href="#m"/></g></svg>')
    assert check_svg(svg) == svg


def test_output_that_is_a_file_is_refused(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(InputError, match=r"`output` must be a directory"):
        build_report(["euler"], ["harmonic"], quick=True, output=f, progress=False)


def test_bad_flags_are_refused_before_anything_runs(tmp_path):
    with pytest.raises(InputError, match=r"`quick` must be True or False, got 'yes'"):
        build_report(["euler"], ["harmonic"], quick="yes", output=tmp_path)  # type: ignore[arg-type]


def test_cli_report_prints_the_path(report, tmp_path, monkeypatch, capsys):
    """The command line passes its arguments through and prints the index.html path (the cells
    come from the module's cache, so this is quick)."""
    from harness.cli import main

    monkeypatch.setenv("HARNESS_RESULTS_DIR", str(tmp_path / "results"))
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(report["plugin"].parent))
    code = main(["report", "--quick", "--jobs", "1", "--stepper", "euler", "--problem", "harmonic",
                 "--output", str(tmp_path / "reports")])
    out = capsys.readouterr().out.strip().splitlines()
    assert code == 0
    path = Path(out[-1])
    assert path.is_file() and path.parent.parent == tmp_path / "reports"
    meta = json.loads((tmp_path / "results" / path.parent.name / "meta.json").read_text())
    assert meta["config"]["run"]["steppers"] == ["euler"]
    assert meta["totals"]["computed"] == 0  # every cell came from the module's cache


def test_performance_history_is_drawn_from_asv_results_when_there_are_any(monkeypatch):
    from harness import perf_history
    from harness.report.fixed_sections import performance_history

    monkeypatch.setattr(perf_history, "load_history",
                        lambda *a, **k: pd.DataFrame(columns=perf_history.HISTORY_COLUMNS))
    empty = performance_history()
    assert [b.kind for b in empty.blocks] == ["note"]
    assert "No asv results yet (run `make nightly`)" in empty.blocks[0].text

    history = pd.DataFrame({
        "benchmark": ["bench_steppers.Step.time_step"] * 4 + ["bench_accuracy.Order.track_order"] * 2,
        "params": ["stepper='rk4'", "stepper='rk4'", "stepper='euler'", "stepper='euler'",
                   "stepper='rk4'", "stepper='rk4'"],
        "commit": ["a" * 40, "b" * 40] * 3,
        "date": pd.to_datetime(["2026-01-01", "2026-01-02"] * 3, utc=True),
        "value": [1e-5, 1.1e-5, 3e-6, 2.9e-6, 4.0, 4.01],
        "unit": ["seconds"] * 4 + ["order"] * 2,
        "machine": ["ci"] * 6,
    })
    monkeypatch.setattr(perf_history, "load_history", lambda *a, **k: history)
    drawn = performance_history()
    kinds = [b.kind for b in drawn.blocks]
    assert kinds == ["figure", "table"]
    assert drawn.blocks[0].figure.svg.startswith("<svg")
    assert len(drawn.blocks[1].table.rows) == 3  # latest value per (benchmark, params)


# -- the section registry -------------------------------------------------------------------------
def _view_with_extra_experiment(report, name: str):
    """The module's run, plus an experiment no section was registered for (as a helper adding
    a new experiment would leave it): its summary judges two cells, one failing."""
    from harness.report import run_view

    view = run_view(load_run(None, root=report["own"] / "results"))
    view.summaries[name] = pd.DataFrame({
        "stepper": ["euler", "rk4"], "problem": ["harmonic", "harmonic"],
        "accepted_steps": [120, 40], "verdict": ["too-many-steps", "as-claimed"],
        "passed": [False, True], "message": ["took 3x the steps of its order's estimate", ""]})
    view.meta = dict(view.meta, experiments=dict(view.meta["experiments"], **{name: {}}))
    return view


def test_an_experiment_without_a_registered_section_gets_the_generic_table(report):
    from harness.experiments import EXPERIMENTS
    from harness.kit import generic_section
    from harness.report.sections import _experiment_section, section_spec
    from harness.report.verdicts import collect_verdicts

    name = "made-up-step-control"
    view = _view_with_extra_experiment(report, name)
    assert name not in EXPERIMENTS and section_spec(name).build is generic_section
    sec = _experiment_section(view, name, 99)
    assert sec.title == section_spec(name).title and sec.intro
    tables = [b.table for b in sec.blocks if b.kind == "table"]
    assert len(tables) == 1 and len(tables[0].rows) == 2
    assert "accepted steps" in tables[0].columns
    assert [r.cells[0].text for r in tables[0].rows] == ["✗ FAIL", "✓"]  # failing first
    verdicts = collect_verdicts(view)
    mine = verdicts[verdicts["experiment"] == name]
    assert list(mine["passed"]) == [False, True] or sorted(mine["passed"]) == [False, True]
    assert any("too-many-steps" in s for s in mine["sentence"])


def test_the_section_an_experiment_names_is_its_section_and_scoreboard_column(report, monkeypatch):
    """An experiment's `section` attribute is all it takes: its title, builder and scoreboard
    column appear in the report."""
    from harness.experiments import EXPERIMENTS
    from harness.experiments.roundoff import RoundoffExperiment
    from harness.kit import ScoreColumn, SectionSpec
    from harness.report.fixed_sections import verdicts_section
    from harness.report.sections import _experiment_section
    from harness.report.verdicts import collect_verdicts

    name = "made-up-step-control"
    view = _view_with_extra_experiment(report, name)

    def steps(view, stepper):
        s = view.summary(name)
        s = s[s["stepper"] == stepper]
        return ([(str(int(s["accepted_steps"].iloc[0])), "")], True) if len(s) else ([("—", "")], False)

    def build(view, sec):
        sec.note("built by the experiment's own section")

    class MadeUp(RoundoffExperiment):
        section = SectionSpec(name, title="Step-size control", intro="Accepted steps. Fewer is better.",
                              build=build, score=[ScoreColumn("accepted steps", steps)])

    made_up = MadeUp()
    made_up.name = name
    monkeypatch.setitem(EXPERIMENTS, name, made_up)
    sec = _experiment_section(view, name, 99)
    assert sec.title == "Step-size control"
    assert [b.text for b in sec.blocks if b.kind == "note"] == ["built by the experiment's own section"]
    head, _ = verdicts_section(view, collect_verdicts(view), [*view.meta["experiments"]])
    board = next(b.table for b in head.blocks if b.kind == "table")
    assert "accepted steps" in board.columns
    col = board.columns.index("accepted steps")
    cells = {r.stepper: r.cells[col].text for r in board.rows}
    assert cells["euler"] == "120" and cells["rk4"] == "40"


def test_methods_with_the_same_error_curve_are_drawn_once_whatever_their_row_order():
    from harness.experiments.convergence.figures import same_curves

    h = [0.1, 0.05, 0.025]
    err = [1e-3, 1.25e-4, 1.5625e-5]
    rows = pd.DataFrame({
        "stepper": ["a"] * 3 + ["b"] * 3 + ["c"] * 3 + ["d"] * 3,
        "h": h + h[::-1] + h + h,
        "error": err + err[::-1] + [e * (1 + 1e-9) for e in err] + [e * 1.01 for e in err],
        "in_fit": [True] * 12,
    })
    # b: the same points listed the other way round; c: equal to 6 digits; d: another curve
    assert same_curves(rows) == {"a": ["b", "c"], "d": []}
    rows.loc[rows.stepper == "c", "in_fit"] = [True, False, True]
    assert same_curves(rows) == {"a": ["b"], "c": [], "d": []}
    assert same_curves(rows.iloc[:0]) == {}


# -- experiment sections built in forked processes -----------------------------------------------------
def _experiment_bodies(page: str) -> dict[str, str]:
    return {name: page.split(f'<section id="{name}"')[1].split("</section>")[0]
            for name in report_experiments()}


def test_forked_sections_equal_the_ones_built_in_process_and_a_dead_worker_costs_nothing(
        report, tmp_path, monkeypatch):
    """The experiment sections come from forked workers; built in this process instead (no
    fork), or with every worker dying (each section then built here), the sections are the
    same."""
    import os

    from harness.report import sections

    run = load_run(None, root=report["own"] / "results")
    forked = _experiment_bodies(write_report(run, output=tmp_path / "forked").read_text("utf-8"))
    assert forked == _experiment_bodies(report["html"])
    monkeypatch.setattr(sections, "_start_experiment_sections", lambda *args: None)
    here = _experiment_bodies(write_report(run, output=tmp_path / "here").read_text("utf-8"))
    monkeypatch.undo()
    monkeypatch.setattr(sections, "_section_in_worker", lambda *args: os._exit(3))
    dead = _experiment_bodies(write_report(run, output=tmp_path / "dead").read_text("utf-8"))
    assert forked == here == dead
    assert all("could not be built" not in body for body in forked.values())


@pytest.mark.parametrize("row, judged", [
    ({"verdict": "as-claimed", "passed": True}, True),
    ({"verdict": "claim-false", "passed": False}, True),
    ({"verdict": "no-claim", "passed": True}, False),
    ({"verdict": "not-measurable", "passed": True}, False),
    ({"verdict": "measured", "passed": True}, False),  # a stability figure with no formula or claim
    ({"verdict": "agrees", "passed": True}, True),
    ({"verdict": "converged", "passed": True, "outcome": "pass"}, True),
    ({"verdict": "unstable", "passed": True, "outcome": "not-measurable"}, False),
    ({"verdict": "converged", "passed": False, "outcome": "fail"}, True),
    ({"verdict": "no-claim", "passed": False}, True),  # a failing row is always counted
])
def test_the_headline_counts_only_rows_that_judge_a_claim(row, judged):
    from harness.report.verdicts import summary_verdicts

    table = pd.DataFrame([{"stepper": "s", "problem": "p", "message": "", **row}])
    out = summary_verdicts("energy", table, ("stepper", "problem"))
    assert out["judged"].tolist() == [judged]
