"""Report section "Step control: bounded orbits?" from the `step-control` experiment.

Answers the course's Kepler question (course material 004_bfdbb1594143ed8b.txt, Practice
Session #3: control the step so that Delta theta ~ const, and make sure the orbits stay
bounded): the energy error against time for fixed, naive and reversible control (log axes),
the work saved at each eccentricity, and the verdict on bounded orbits, all read from the run.

`SECTION` is the spec the experiment names; two more entry points: `section(view)` returns a
`harness.kit.Section` (the convention of
the other section builders), `build_section(run_tables)` an HTML fragment from a mapping
{"rows": DataFrame, "summary": DataFrame} (or a `RunView`) for pluggable section registries.
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from harness.kit import Section, SectionSpec, df_table
from harness.kit.figure_style import (
    clip_log,
    label_text,
    legend_outside,
    loglog_axes,
    new_figure,
    styled,
    thin_line,
)
from harness.kit.figure_svg import Figure, check_svg, to_svg

__all__ = ["EXPERIMENT", "TITLE", "SECTION", "section", "build_section", "energy_control_figure"]

EXPERIMENT = "step-control"
TITLE = "Step control: bounded orbits?"
_STYLE = {"fixed": "-", "naive": "--", "reversible": "-."}


@styled
def energy_control_figure(problem: str, rows: pd.DataFrame) -> Figure | None:
    """Relative energy error against t (log-log) of the fixed-step peer and each controlled
    stepper on one problem; the fixed peer is drawn once. The figure's data is what it draws
    (each line thinned to the envelope of log-spaced bins)."""
    g = rows[(rows["problem"] == problem) & (rows["kind"] == "energy")]
    if g.empty:
        return None
    fig, axes = new_figure(size=(7.4, 4.4))
    ax = axes[0][0]
    drawn_fixed = False
    data = []
    for stepper, s in g.groupby("stepper", sort=False):
        for role, r in s.groupby("role", sort=False):
            if role == "fixed" and drawn_fixed:
                continue
            label = (f"fixed steps ({r['peer'].iloc[0]})" if role == "fixed" else stepper)
            kind = "fixed" if role == "fixed" else str(r["controller"].iloc[0] if "controller" in r else "")
            t = r["t"].astype(float).to_numpy()
            x, y = thin_line(t - float(np.nanmin(t)), r["error"].astype(float).to_numpy())
            data.append(pd.DataFrame({"stepper": stepper, "role": role, "controller": kind, "t": x,
                                      "error": y}))
            ax.plot(x, clip_log(y), _STYLE.get(kind, "-"), lw=1.0, label=label_text(label))
            drawn_fixed = drawn_fixed or role == "fixed"
    loglog_axes(ax)
    ax.set_xlabel("t")
    ax.set_ylabel("relative energy error")
    ax.set_title(f"Energy error on {label_text(problem)}: fixed, naive and reversible control")
    legend_outside(ax)
    return to_svg(fig, f"step-control-{problem}", f"relative energy error against time on {problem}",
                  pd.concat(data, ignore_index=True) if data else None)


def _with_controller(rows: pd.DataFrame, summary: pd.DataFrame) -> pd.DataFrame:
    ctrl = dict(zip(summary["stepper"], summary["controller"], strict=False)) if len(summary) else {}
    return rows.assign(controller=rows["stepper"].map(ctrl).fillna(""))


def _verdict_text(summary: pd.DataFrame) -> str:
    parts = []
    for rec in summary.to_dict("records"):
        parts.append(f"{rec['stepper']} on {rec['problem']}: energy error {rec['drift_class']} "
                     f"(growth exponent {rec['drift_exponent']:.2g}); "
                     f"{'bounded' if rec['bounded'] else 'NOT bounded'}")
    bounded = summary[summary["bounded"].astype(bool)]
    sym = summary[summary["symmetric"].astype(bool)]
    naive = summary[~summary["symmetric"].astype(bool)]
    head = (f"Bounded orbits (a bounded energy error over the run): {len(bounded)} of {len(summary)} "
            f"controlled runs; symmetric (reversible) controllers bounded in "
            f"{int(sym['bounded'].astype(bool).sum())} of {len(sym)}, naive ones in "
            f"{int(naive['bounded'].astype(bool).sum())} of {len(naive)}.")
    return head + " " + "; ".join(parts) + "."


INTRO = ("Each step-controlled stepper (Δθ ≈ const, the course's Kepler practice session, course "
         "file 004, Practice Session #3) runs against the fixed-step stepper with the same splitting "
         "coefficients at equal work: the energy error's growth is classified by the energy "
         "experiment's classifier, and the work ratio is the fixed stepper's force evaluations over "
         "the controlled one's to reach the same final-time accuracy. A flat energy error in the "
         "figure means bounded orbits, which a reversible controller should keep and a naive one "
         "lose; a work ratio above 1 means the control saves work.")


def build(view: Any, sec: Section) -> None:
    """Figures and tables of the step-control experiment into `sec`."""
    rows = view.rowtable(EXPERIMENT) if hasattr(view, "rowtable") else pd.DataFrame()
    summ = view.summary(EXPERIMENT) if hasattr(view, "summary") else pd.DataFrame()
    if summ is None or summ.empty:
        sec.note("The step-control experiment has no results in this run.", cls="warning")
        return
    rows = _with_controller(rows, summ)
    for problem in dict.fromkeys(summ["problem"]):
        sec.figure(energy_control_figure(problem, rows),
                   f"Relative energy error against time on {problem} (log axes).")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("controller", "controller"),
            ("drift_class", "drift class"), ("drift_exponent", "growth exponent"),
            ("drift_slope", "drift slope (per unit t)"), ("max_rel_energy_error", "max rel. energy error"),
            ("fixed_drift_class", "fixed: drift class"),
            ("fixed_max_rel_energy_error", "fixed: max rel. energy error"),
            ("claimed_order", "claimed order"), ("measured_order", "order in control parameter"),
            ("order_verdict", "order verdict"), ("verdict", "verdict")]
    sec.table(df_table(summ, cols, "Energy drift and order in the control parameter",
                       experiment=EXPERIMENT, status="bounded"))
    work = [("stepper", "stepper"), ("problem", "problem"), ("target_error", "target error (x |y|)"),
            ("controlled_evals", "controlled force evals"), ("fixed_evals", "fixed force evals"),
            ("work_ratio", "work ratio (fixed / controlled)"),
            ("work_ratio_is_lower_bound", "lower bound"), ("message", "message")]
    sec.table(df_table(summ, work, "Work saved at each eccentricity", experiment=EXPERIMENT,
                       status=None))
    sec.note(_verdict_text(summ))


def section(view: Any, number: int = 0) -> Section:
    """The section from a `RunView` (rows and summary of the step-control experiment)."""
    sec = Section("step-control", number, TITLE)
    sec.intro = INTRO
    build(view, sec)
    return sec


class _Tables:
    def __init__(self, rows: pd.DataFrame, summary: pd.DataFrame):
        self._rows, self._summary = rows, summary

    def rowtable(self, name: str) -> pd.DataFrame:
        return self._rows if name == EXPERIMENT else pd.DataFrame()

    def summary(self, name: str) -> pd.DataFrame:
        return self._summary if name == EXPERIMENT else pd.DataFrame()


def build_section(run_tables: Mapping[str, pd.DataFrame] | Any) -> str:
    """The section as an HTML fragment; `run_tables` is {"rows": ..., "summary": ...} of the
    step-control experiment, or a RunView. Text is escaped; figures are checked SVG."""
    if isinstance(run_tables, Mapping):
        view = _Tables(run_tables.get("rows", pd.DataFrame()), run_tables.get("summary", pd.DataFrame()))
    else:
        view = run_tables
    sec = section(view)
    e = html.escape
    out = [f'<section id="{e(sec.id)}"><h2>{e(sec.title)}</h2><p class="intro">{e(sec.intro)}</p>']
    for b in sec.blocks:
        if b.kind == "figure" and b.figure is not None:
            out.append(f"<figure>{check_svg(b.figure.standalone())}<figcaption>{e(b.text)}</figcaption></figure>")
        elif b.kind == "table" and b.table is not None:
            t = b.table
            head = "".join(f"<th>{e(c)}</th>" for c in t.columns)
            body = "".join("<tr>" + "".join(f"<td>{e(c.text)}</td>" for c in r.cells) + "</tr>"
                           for r in t.rows)
            out.append(f"<table><caption>{e(t.caption)}</caption><thead><tr>{head}</tr></thead>"
                       f"<tbody>{body}</tbody></table>")
        else:
            out.append(f'<p class="{e(b.cls)}">{e(b.text)}</p>')
    out.append("</section>")
    return "\n".join(out)


SECTION = SectionSpec(EXPERIMENT, title=TITLE, intro=INTRO, build=build)
