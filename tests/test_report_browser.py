"""The report as a user sees it: rendered by a real browser (Debian's chromium, headless).

Chromium is driven over the DevTools protocol on a pipe (`--remote-debugging-pipe`: fd 3 carries
commands in, fd 4 replies and events out, each message JSON ending in a NUL byte), which lets the
test
- record every network request the page makes (`Network.requestWillBeSent`; the page's
  Content-Security-Policy is bypassed for this, so a reference to anything outside the file would
  show up as a request instead of being blocked silently), with `--host-resolver-rules` mapping
  every host name to nothing as a second guard;
- read the rendered DOM and layout (`Runtime.evaluate` of the test's own expression; the report
  itself has no script): the section headings, the scoreboard rows, and the laid-out size and
  visibility of every figure;
- keep a screenshot as a test artefact (`test-artifacts/report-browser.png`, gitignored).

Chromium is installed by `scripts/test-deps` (run by `make test`). Without it the test is skipped
with the reason, except in CI (`CI` set), where a missing browser is a failure.
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from pathlib import Path

import pytest
from test_report import HOSTILE, PROBLEMS, STEPPERS, build_quick_report, hostile_plugin, shared_dir

from harness.report import report_experiments
from harness.report.browser import DevTools, chromium_binary
from harness.report.sections import section_titles

ROOT = Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "test-artifacts"


PAGE_FACTS = """(() => {
  const svgs = Array.from(document.querySelectorAll('svg'));
  return {
    headings: Array.from(document.querySelectorAll('h2')).map(h => [h.id, h.textContent.trim()]),
    rows: Array.from(document.querySelectorAll('#scoreboard-table tbody tr.stepper-row'))
      .map(r => [r.dataset.stepper, r.cells[0].textContent.trim(), r.cells[1].textContent]),
    figures: svgs.map(s => {
      const b = s.getBoundingClientRect();
      return {slug: s.dataset.slug || '', width: b.width, height: b.height,
              visible: s.checkVisibility({checkOpacity: true, checkVisibilityCSS: true}),
              shapes: s.querySelectorAll('path, use, text').length};
    }),
    scripts: document.querySelectorAll('script').length,
    external: Array.from(document.querySelectorAll('[src], [href]'))
      .map(e => e.getAttribute('src') || e.getAttribute('href'))
      .filter(u => !u.startsWith('#') && !u.startsWith('data:')),
    pageWidth: document.documentElement.scrollWidth,
    title: document.title,
    viewport: window.innerHeight,
    headline: (() => { const h = document.querySelector('#verdicts p.headline');
      return h ? {text: h.textContent.trim(), top: h.getBoundingClientRect().top,
                  bottom: h.getBoundingClientRect().bottom} : null; })(),
    failingListed: document.querySelectorAll('#verdicts ol.verdict-list:not(.since) li').length,
    scoreboardTop: document.querySelector('#scoreboard-table').getBoundingClientRect().top,
    dataLinks: Array.from(document.querySelectorAll('figure a.data'))
      .map(a => a.getAttribute('href').slice(0, 30)),
  };
})()"""


# The first screen a reader sees (CSS pixels of a laptop window).
FIRST_SCREEN_HEIGHT = 900
# The first scoreboard link whose row sits in a folded (closed) per-cell table.
FOLDED_TARGET = """(() => {
  for (const a of document.querySelectorAll('#scoreboard-table a[href^="#"]')) {
    const el = document.getElementById(a.getAttribute('href').slice(1));
    const d = el && el.closest('details');
    if (d && !d.open) return el.id;
  }
  return null;
})()"""


@pytest.fixture(scope="module")
def browser_report(tmp_path_factory):
    binary = chromium_binary()
    if binary is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is not installed (scripts/test-deps installs it); the browser "
                        "test must run in CI")
        pytest.skip("chromium is not installed: run `scripts/test-deps` as root (or `make test`) "
                    "to render the report in a real browser")
    shared = shared_dir(tmp_path_factory)
    own = tmp_path_factory.mktemp("browser-report")
    with hostile_plugin(shared) as plugin:
        path = build_quick_report(shared, own, plugin)
    profile = Path(tempfile.mkdtemp(prefix="chromium-profile-", dir=own))
    tools = DevTools(binary, profile)
    try:
        # the first screen: a laptop-sized window
        tools.open(path.resolve().as_uri(), width=1280, height=FIRST_SCREEN_HEIGHT)
        facts = tools.evaluate(PAGE_FACTS)
        requests = tools.requests()
        ARTIFACTS.mkdir(exist_ok=True)
        shot = ARTIFACTS / "report-browser.png"
        tools.screenshot(shot)
        # a link from the scoreboard to a row inside a folded table
        target = tools.evaluate(FOLDED_TARGET)
        tools.send("Page.navigate", {"url": path.resolve().as_uri() + "#" + target})
        time.sleep(0.5)
        opened = tools.evaluate(f"(() => {{ const r = document.getElementById({target!r}); "
                                "const d = r.closest('details'); const b = r.getBoundingClientRect(); "
                                "return {open: d ? d.open : null, top: b.top, height: b.height}; })()")
        yield {"path": path, "facts": facts, "requests": requests, "screenshot": shot,
               "target": target, "opened": opened}
    finally:
        tools.close()


def test_page_made_no_network_request_but_loading_itself(browser_report):
    url = browser_report["path"].resolve().as_uri()
    assert browser_report["requests"] == [url]
    assert browser_report["facts"]["external"] == []
    assert browser_report["facts"]["scripts"] == 0


def test_every_section_heading_is_rendered(browser_report):
    headings = browser_report["facts"]["headings"]
    titles = section_titles(report_experiments())
    assert [h[0] for h in headings] == [f"h-{key}" for key, _ in titles]
    assert [h[1] for h in headings] == [f"{i + 1} {title}" for i, (_, title) in enumerate(titles)]


def test_scoreboard_has_one_row_per_stepper_of_the_report(browser_report):
    rows = browser_report["facts"]["rows"]
    assert sorted(r[0] for r in rows) == sorted([*STEPPERS, HOSTILE])
    # the plugin's name is text in the cell, not markup
    assert [r[2] for r in rows if r[0] == HOSTILE] == [HOSTILE]
    assert all(r[1] in ("✗ FAIL", "✓ pass", "– not measured") for r in rows)


def test_every_figure_is_visible_with_a_size(browser_report):
    figures = browser_report["facts"]["figures"]
    assert len(figures) >= 2 * len(PROBLEMS) + 3
    page = browser_report["facts"]["pageWidth"]
    for f in figures:
        assert f["visible"], f["slug"]
        assert f["width"] > 100 and f["height"] > 100, f
        assert f["width"] <= page, f  # scaled to the page, not cut off
        assert f["shapes"] > 10, f  # drawn, not an empty frame


def test_screenshot_is_kept_as_an_artefact(browser_report):
    data = browser_report["screenshot"].read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_first_screen_shows_the_verdict_summary(browser_report):
    """The count of claims checked and failed is on the first screen, above the scoreboard,
    with each failing claim listed (the screenshot is kept as an artefact)."""
    facts = browser_report["facts"]
    head = facts["headline"]
    assert head is not None
    assert re.fullmatch(r"\d+ claims checked in \d+ experiments( and the course material)?: \d+ failed\..*",
                        head["text"]), head["text"]
    assert 0 <= head["top"] and head["bottom"] <= facts["viewport"]
    assert head["bottom"] <= facts["scoreboardTop"]
    n_failed = int(re.search(r": (\d+) failed", head["text"]).group(1))
    assert facts["failingListed"] == n_failed


def test_every_figure_has_its_data_link(browser_report):
    facts = browser_report["facts"]
    assert len(facts["dataLinks"]) == len(facts["figures"])
    assert all(u.startswith("data:application/gzip;base64,") for u in facts["dataLinks"])


def test_a_scoreboard_link_opens_the_folded_table_it_points_into(browser_report):
    assert browser_report["target"], "no scoreboard link points into a folded table"
    opened = browser_report["opened"]
    assert opened["open"] is True
    assert opened["height"] > 0
