"""Figures of the report: matplotlib (Agg) drawn to inline SVG text, one module per job.

- `figure_style`: the drawing style every figure shares (matplotlib settings, `Palette` — one
  colour and marker per method in every figure —, small-multiple `panels`, log axes, legends);
- `figure_svg`: `Figure`, `to_svg` (deterministic, compact SVG) and `check_svg` (nothing but a
  drawing is embedded);
- `figures_convergence` (convergence, roundoff), `figures_stability` (stability regions, hω
  limits, symplecticity), `figures_long_runs` (reversibility, energy, angular momentum),
  `figures_work` (work–precision, performance history).

Each figure function takes tidy rows/summary tables of one experiment and returns a `Figure`
(its SVG text, caption-free; the section supplies the caption) with the tidy table it draws.
This module re-exports them all.
"""

from harness.report.figure_style import (
    EXCLUSION_STYLE,
    LOG_CEILING,
    LOG_FLOOR,
    MAX_LINES_PER_PANEL,
    MAX_POINTS_PER_LINE,
    Palette,
    finite_or_none,
    panels,
)
from harness.report.figure_svg import SVG_DECIMALS, Figure, UnsafeFigureError, check_svg, to_svg
from harness.report.figures_convergence import (
    SAME_CURVE_DIGITS,
    convergence_figure,
    roundoff_figure,
    same_curves,
)
from harness.report.figures_long_runs import angular_momentum_figure, energy_figure, reversibility_figure
from harness.report.figures_stability import hw_limits_figure, stability_overlay_figure, symplecticity_figure
from harness.report.figures_work import (
    WORK_TARGET_ERROR,
    best_per_family,
    perf_history_figure,
    work_precision_figure,
)

__all__ = [
    "Figure", "Palette", "check_svg", "to_svg", "panels", "MAX_LINES_PER_PANEL", "MAX_POINTS_PER_LINE",
    "EXCLUSION_STYLE", "LOG_FLOOR", "LOG_CEILING", "SVG_DECIMALS", "SAME_CURVE_DIGITS",
    "WORK_TARGET_ERROR", "convergence_figure", "stability_overlay_figure", "hw_limits_figure",
    "reversibility_figure", "energy_figure", "angular_momentum_figure", "work_precision_figure",
    "best_per_family", "same_curves", "roundoff_figure", "symplecticity_figure", "perf_history_figure",
    "finite_or_none", "UnsafeFigureError",
]
