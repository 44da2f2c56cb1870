"""The HTML accuracy report: `build_report(...)` runs every experiment (reusing cached cells),
saves the run and writes one self-contained `reports/<run id>/index.html` (inline SVG figures,
HTML tables, no script, no network), then points `reports/latest` at it.

Modules: `build` (the command), `sections` (the page's model, the table helpers and the
section registry), `experiment_sections` (one registered section per built-in experiment),
`fixed_sections` (verdicts and scoreboard, what changed, ground truth, claims, provenance,
performance history), `verdicts` (every judged claim as one table), `compare` (what changed
since an earlier run), `figures` (matplotlib to checked inline SVG), `claims` (the course
material's claims, judged), `templates/report.html.j2`.
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
