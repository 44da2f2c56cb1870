"""The HTML accuracy report: `build_report(...)` runs every experiment (reusing cached cells),
saves the run and writes one self-contained `reports/<run id>/index.html` (inline SVG figures,
HTML tables, no script, no network), then points `reports/latest` at it.

Modules: `build` (the command), `sections` (what each section shows), `figures` (matplotlib to
checked inline SVG), `claims` (the course material's claims, judged), `templates/report.html.j2`.
"""

from harness.report.build import (
    REPORT_EXPERIMENTS,
    build_report,
    render_html,
    reports_root,
    write_report,
)

__all__ = ["build_report", "write_report", "render_html", "reports_root", "REPORT_EXPERIMENTS"]
