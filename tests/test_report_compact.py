"""What keeps the full report small and quick to rebuild, checked on small inputs: the figure
cache draws a figure once per distinct input, every in-page link still finds its target once
unlinked row ids are dropped, folded tables keep every value, and the grouped work table equals
the row-by-row one.

The full report's own size and build time are measured on a saved full run
(`python -m harness.report.sizes`), not here: it takes a minute.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

from harness.experiments.reversibility.section import fold_per_n
from harness.experiments.work_precision.figures import WORK_TARGET_ERROR
from harness.experiments.work_precision.section import _work_table
from harness.kit import figure_cache
from harness.kit.elements import Block, Row, Section, TextCell, df_table, drop_unlinked_row_ids
from harness.kit.figure_style import styled
from harness.kit.figure_svg import short_ids

CALLS: list[float] = []


@styled
def _line_figure(slope: float):
    from matplotlib.figure import Figure as MplFigure

    from harness.kit.figure_svg import to_svg

    CALLS.append(slope)
    fig = MplFigure(figsize=(2, 2))
    ax = fig.subplots()
    ax.plot([1, 2, 3], [1, 1 + slope, 1 + 2 * slope])
    return to_svg(fig, f"line-{slope}", "a line", pd.DataFrame({"x": [1, 2, 3]}))


def test_a_figure_is_drawn_once_per_distinct_input(tmp_path, monkeypatch):
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path))
    CALLS.clear()
    first = _line_figure(0.5)
    again = _line_figure(0.5)
    other = _line_figure(0.25)
    assert CALLS == [0.5, 0.25]  # the repeat came from the cache
    assert again.svg == first.svg and again.data.equals(first.data)
    assert other.svg != first.svg
    assert len(list((tmp_path / "figures").glob("*.json"))) == 2
    assert not list((tmp_path / "figures").glob("*.pkl"))  # data formats, never a pickle


def test_an_unreadable_cache_entry_is_drawn_again(tmp_path, monkeypatch):
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path))
    CALLS.clear()
    _line_figure(0.75)
    for entry in (tmp_path / "figures").glob("*.*"):
        entry.write_bytes(b"not json, not parquet")
    assert _line_figure(0.75) is not None
    assert CALLS == [0.75, 0.75]


def test_a_pickle_planted_in_the_figure_cache_is_never_loaded(tmp_path, monkeypatch):
    import pickle

    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path))
    CALLS.clear()
    _line_figure(0.375)
    marker = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (marker.write_text, ("code from the cache ran",))

    for entry in (tmp_path / "figures").glob("*.json"):
        entry.with_suffix(".pkl").write_bytes(pickle.dumps(Payload()))
        entry.write_bytes(pickle.dumps(Payload()))
    assert _line_figure(0.375) is not None
    assert not marker.exists() and CALLS == [0.375, 0.375]


def test_the_cache_can_be_switched_off(tmp_path, monkeypatch):
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("HARNESS_FIGURE_CACHE", "off")
    CALLS.clear()
    _line_figure(0.125)
    _line_figure(0.125)
    assert CALLS == [0.125, 0.125]
    assert figure_cache.figure_cache_dir() is None


def _table_section() -> Section:
    df = pd.DataFrame({"stepper": ["a", "b", "c", "d"], "problem": ["p", "p", "p", "q"],
                       "value": [1.0, 2.0, math.nan, 4.0], "passed": [True, False, True, None]})
    sec = Section("exp", 1, "Experiment")
    sec.table(df_table(df, [("stepper", "stepper"), ("problem", "problem"), ("value", "value")],
                       "rows", experiment="exp"))
    return sec


def test_only_linked_rows_keep_their_ids_and_every_link_finds_its_row():
    sec = _table_section()
    table = sec.blocks[0].table
    target = table.rows[2].id
    assert target and all(r.id for r in table.rows)
    board = Section("verdicts", 0, "Verdicts")
    board.blocks.append(Block("list", items=[("c on p", "#" + target)]))
    board.table(df_table(pd.DataFrame({"x": [1]}), [("x", "x")], "board", status=None, folded=False))
    board.blocks[-1].table.rows.append(Row([TextCell("link", href="#" + table.rows[3].id)]))
    cleared = drop_unlinked_row_ids([board, sec])
    kept = [r.id for r in table.rows if r.id]
    assert cleared == 2 and set(kept) == {target, table.rows[3].id}


def test_folded_tables_blank_only_repeats_and_missing_values():
    sec = _table_section()
    table = sec.blocks[0].table
    drop_unlinked_row_ids([sec])  # nothing links here: every repeat is blanked
    problem = table.columns.index("problem")
    assert "a blank problem cell: as in the row above" in table.caption
    shown = [r.cells[problem].text for r in table.rows]
    # failing row first (b, p), then a (p: repeated), c (p: repeated), d (q)
    assert [r.cells[1].text for r in table.rows] == ["b", "a", "c", "d"]
    assert shown == ["p", "", "", "q"]
    assert [r.cells[3].text for r in table.rows] == ["2", "1", "", "4"]  # NaN: an empty cell
    assert [r.cells[0].text for r in table.rows] == ["✗ FAIL", "✓", "✓", "–"]


def test_a_row_a_link_points_to_shows_its_problem():
    sec = _table_section()
    table = sec.blocks[0].table
    board = Section("verdicts", 0, "Verdicts")
    board.blocks.append(Block("list", items=[("a", "#" + table.rows[1].id)]))
    drop_unlinked_row_ids([board, sec])
    problem = table.columns.index("problem")
    assert table.rows[1].id and table.rows[1].cells[problem].text == "p"


def test_short_figure_ids_stay_unique_and_keep_every_reference():
    page = ('<tr id="y0"><td><a href="#y0">row</a>'
            '<svg><defs><path id="fabc12i0" d="M0 0"/><clipPath id="fabc12i1"/></defs>'
            '<use href="#fabc12i0"/><g clip-path="url(#fabc12i1)"/></svg>'
            '<svg><defs><path id="f99999i0" d="M0 0"/></defs><use href="#f99999i0"/></svg>')
    short = short_ids(page)
    ids = re.findall(r'\bid="([^"]+)"', short)
    assert len(ids) == len(set(ids)) == 4
    refs = re.findall(r'(?:href="#|url\(#)([^")]+)', short)
    assert set(refs) <= set(ids)
    assert "fabc12" not in short and "f99999" not in short


def test_reversibility_rows_fold_per_stepper_and_problem_keeping_every_value():
    summ = pd.DataFrame({
        "stepper": ["s"] * 3 + ["t"] * 2, "problem": ["p"] * 5, "steps": [1000, 100, 10000, 100, 1000],
        "h": [0.1] * 5, "return_error_ulps": [2.0, 1.0, 3.0, 50.0, 500.0],
        "rounding_bound_ulps": [20.0, 10.0, 30.0, 10.0, 20.0], "claimed_symmetric": [True] * 3 + [False] * 2,
        "growth_exponent": [0.5] * 3 + [1.0] * 2,
        "verdict": ["reversible", "reversible", "claim-false", "irreversible", "irreversible"],
        "passed": [True, True, False, True, True],
        "message": ["", "", "misses by 3", "", ""]})
    folded = fold_per_n(summ).set_index("stepper")
    assert folded.loc["s", "steps"] == "10², 10³, 10⁴"  # in the order of N
    assert folded.loc["s", "return_error_ulps"] == "1, 2, 3"
    assert folded.loc["s", "verdict"] == "reversible, reversible, claim-false"
    assert not folded.loc["s", "passed"] and folded.loc["t", "passed"]
    assert folded.loc["s", "message"] == "N = 10⁴: misses by 3"
    assert folded.loc["t", "verdict"] == "irreversible"


def _work_table_by_rows(summ: pd.DataFrame) -> pd.DataFrame:
    out = []
    for (stepper, problem), g in summ.groupby(["stepper", "problem"], sort=False):
        err, evals, wall = (g[c].astype(float) for c in ("error", "rhs_evals", "wall_s"))
        rec = {"stepper": stepper, "problem": problem, "points": len(g)}
        fin = g[np.isfinite(err)]
        if len(fin):
            k = err[fin.index].idxmin()
            rec.update(lowest_error=err[k], evals_at_lowest=evals[k])
            hit = fin[err[fin.index] <= WORK_TARGET_ERROR]
            if len(hit):
                j = evals[hit.index].idxmin()
                rec.update(evals_to_target=evals[j], wall_to_target=wall[j])
        out.append(rec)
    return pd.DataFrame(out)


def test_the_grouped_work_table_equals_the_row_by_row_one():
    rng = np.random.default_rng(5)
    n = 300
    summ = pd.DataFrame({
        "stepper": rng.choice(["a", "b", "c"], n), "problem": rng.choice(["p", "q"], n),
        "kind": "step-size", "evals_unit": "f-or-force",
        "error": np.where(rng.random(n) < 0.1, np.nan, 10.0 ** rng.uniform(-12, 0, n)),
        "rhs_evals": rng.integers(10, 10_000, n).astype(float), "wall_s": rng.random(n)})
    mine = _work_table(summ).set_index(["stepper", "problem"]).sort_index()
    ref = _work_table_by_rows(summ).set_index(["stepper", "problem"]).sort_index()
    for col in ("points", "lowest_error", "evals_at_lowest", "evals_to_target", "wall_to_target"):
        assert np.allclose(mine[col].astype(float), ref[col].astype(float), equal_nan=True), col


@pytest.mark.parametrize("value, text", [(4.63e-4, "4.63e-4"), (1.31e5, "1.31e5"), (1e-10, "1e-10"),
                                          (10000.0, "1e4"), (0.0581, "0.0581"), (16, "16")])
def test_numbers_are_written_short(value, text):
    from harness.kit.elements import fmt

    assert fmt(value) == text
