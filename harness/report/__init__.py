"""The HTML accuracy report: `build_report(...)` runs every experiment (reusing cached cells),
saves the run and writes one self-contained `reports/<run id>/index.html` (inline SVG figures,
HTML tables, no script, no network), then points `reports/latest` at it.

The assembler only: `build` (the command), `sections` (every section in order, the experiment
sections built in forked workers), `specs` (the section each experiment names, or the generic
table), `fixed_sections` (verdicts and scoreboard, what changed, ground truth, claims, gate
trust, provenance, performance history), `verdicts` (every judged claim as one table),
`compare` (what changed since an earlier run), `claims` (the course material's claims,
judged), `test_sets`, `history_figure`, `templates/report.html.j2`. An experiment's section and
figures live in its folder (`harness/experiments/<name>/`), over the presentation kit
`harness.kit`.
"""

from harness.report.build import (
    build_report,
    render_html,
    report_experiments,
    reports_root,
    rerender_report,
    run_view,
    write_report,
)

__all__ = ["build_report", "write_report", "rerender_report", "render_html", "reports_root",
           "report_experiments", "run_view"]
