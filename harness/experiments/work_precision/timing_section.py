"""The work-precision section's timed part: error against warm time per problem, the time to reach
target errors, and one method's implementations side by side.

Drawn from the work-precision rows' timing columns (`timed_runs` beside this module, protocol
in `harness.timing`): one figure per problem (each family's best by time bold, the Pareto front of
time and error marked), the time-to-target table (log-error against log-time interpolated between
measured points; "not reached" said), the same-method groups (implementations grouped by their
coefficients' identity, never by name: their errors at equal steps must agree to rounding, and
their times are given as ratios), and the spread of the repeated timings per problem.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from harness import timing
from harness.experiments.work_precision.figures import WORK_TARGET_ERROR, best_per_family
from harness.kit import RunView, Section, df_table
from harness.kit import figure_style as fs
from harness.kit.elements import Block, csv_download
from harness.kit.figure_svg import Figure, to_svg
from harness.timing import PROTOCOL, same_method_groups, time_to_target_table

__all__ = ["time_precision_figure", "add_time_sections", "twin_rows", "fastest_table", "group_summary"]

MARKERS_PER_LINE = 8


@fs.styled
def time_precision_figure(problem: str, rows: pd.DataFrame, palette: fs.Palette,
                          adaptive: Mapping[str, bool]) -> Figure | None:
    """Error against warm time (`t_min_s`) on one problem, one line per stepper: each family's
    fastest to the target error bold, the others faint, adaptive ones dashed; the Pareto front
    (`pareto_time`) as a black step line with open circles.

    Parameters
    ----------
    problem : str, the problem's name.
    rows : DataFrame, its timed rows (`t_min_s`, `error`, `pareto_time`).
    palette : Palette
    adaptive : mapping of str to bool, which steppers draw dashed.

    Returns
    -------
    Figure or None: None when no point has a finite, positive time and error.
    """
    if "t_min_s" not in rows or "error" not in rows:
        return None
    err = rows["error"].astype(float)
    cost = rows["t_min_s"].astype(float)
    frame = rows[np.isfinite(err) & (err > 0) & (err <= fs.LOG_CEILING) & np.isfinite(cost) & (cost > 0)]
    if frame.empty:
        return None
    best = best_per_family(frame, palette.families, cost="t_min_s")
    bold = set(best.values())
    longest = max([len(fs.label_text(s)) + len(f) + 8 for f, s in best.items()] + [22])
    fig, axes = fs.small_multiples(1, ncols=1, panel=(4.2, 3.0),
                                   right=longest * fs.LEGEND_CHAR_W * 0.85 + 0.5)
    ax = axes[0]
    for stepper, s in frame.groupby("stepper", sort=False):
        # joined in sweep order (coarse to fine), as SciMLBenchmarks draws it: noise in a time
        # shows as a kink, not as a reordered line
        s = s.sort_values("tol" if s["tol"].notna().any() else "h", ascending=False) \
            if "tol" in s and "h" in s else s.sort_values("t_min_s")
        peer = adaptive.get(stepper, False)
        strong = stepper in bold
        c = palette.colour(stepper)
        ax.plot(s["t_min_s"].astype(float), s["error"].astype(float), "--" if peer else "-",
                marker=palette.marker(stepper) if strong else None, ms=3.2, lw=1.6 if strong else 0.6,
                markevery=max(1, math.ceil(len(s) / MARKERS_PER_LINE)), alpha=1.0 if strong else 0.3,
                color=c, markerfacecolor="none" if peer else c, zorder=3 if strong else 2)
    if "pareto_time" in frame:
        front = frame[frame["pareto_time"].astype(bool)].sort_values("t_min_s")
        if len(front):
            ax.step(front["t_min_s"].astype(float), front["error"].astype(float), where="post",
                    color="black", lw=0.7, zorder=4)
            ax.plot(front["t_min_s"].astype(float), front["error"].astype(float), "o", ms=4.0,
                    markerfacecolor="none", markeredgecolor="black", mew=0.6, zorder=5)
    fs.loglog_axes(ax)
    ax.set_xlabel("warm time, minimum of repeats (s)", fontsize=7.5)
    ax.set_ylabel("error at the final time", fontsize=7.5)
    fs.small_ticks(ax)
    handles = [Line2D([], [], color=palette.colour(s), marker=palette.marker(s), ms=3, lw=1.6,
                      ls="--" if adaptive.get(s) else "-",
                      label=f"{fs.label_text(s)} (fastest {fam or 'method'})")
               for fam, s in best.items()]
    handles.append(Line2D([], [], color="black", lw=0.7, marker="o", markerfacecolor="none", ms=4,
                          label="Pareto front (time, error)"))
    handles.append(Line2D([], [], color="0.6", lw=0.6, alpha=0.5, label="other methods (faint)"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0,
              frameon=False, fontsize=6.5)
    fig.suptitle(f"Error against time on {fs.label_text(problem)} "
                 f"(target {WORK_TARGET_ERROR:g} for 'fastest')", fontsize=8.5)
    cols = [c for c in ("stepper", "implementation", "h", "tol", "n_steps", "error", "t_min_s",
                        "t_median_s", "t_spread", "t_repeats", "t_stop", "first_call_s", "baseline",
                        "baseline_units", "pareto_time", "load_1min") if c in frame]
    return to_svg(fig, f"time-{problem}", f"error against time on {problem}",
                  frame[cols].reset_index(drop=True))


def twin_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows in long form for `harness.timing.same_method_groups`: every timed row as it is,
    plus one row per NumPy twin measurement (its implementation, error and time at that point).

    Parameters
    ----------
    rows : DataFrame
        Work-precision rows with the timing columns.

    Returns
    -------
    DataFrame
        Columns stepper, implementation, method_id, problem, h, n_steps, error, t_min_s,
        rounding_level.
    """
    cols = ["stepper", "implementation", "method_id", "problem", "h", "n_steps", "error", "t_min_s",
            "rounding_level"]
    if rows.empty or not {"method_id", "twin_error", "t_min_s"} <= set(rows.columns):
        return pd.DataFrame(columns=cols)
    base = rows.reindex(columns=cols)
    twins = rows[rows["twin_error"].notna()]
    twin = twins.reindex(columns=cols).assign(
        implementation=twins["twin_implementation"].astype(str), error=twins["twin_error"],
        t_min_s=twins["twin_min_s"])
    return pd.concat([base, twin], ignore_index=True)


def fastest_table(table: pd.DataFrame, others: int = 3) -> pd.DataFrame:
    """One row per (problem, target) of a `time_to_target_table` (with `time_c`, the time in
    C-baseline steps): the fastest stepper, its time, the next `others` with their ratios, and
    how many steppers reached the target.

    Parameters
    ----------
    table : DataFrame
        `harness.timing.time_to_target_table` output plus a `time_c` column.
    others : int
        How many runners-up to name.

    Returns
    -------
    DataFrame
        Columns problem, target, fastest, time_s, time_c, next, reached.
    """
    out = []
    for (problem, target), g in table.groupby(["problem", "target"], sort=False):
        hit = g[np.isfinite(g["time_s"].astype(float))].sort_values("time_s")
        first = hit.iloc[0] if len(hit) else None
        out.append({
            "problem": problem, "target": target,
            "fastest": first["stepper"] if first is not None else "none reached it",
            "time_s": first["time_s"] if first is not None else np.nan,
            "time_c": first["time_c"] if first is not None else np.nan,
            "next": ", ".join(f"{r.stepper} {r.ratio_to_fastest:.2g}x"
                              for r in hit.iloc[1:1 + others].itertuples()),
            "reached": f"{len(hit)} of {len(g)}"})
    return pd.DataFrame(out, columns=["problem", "target", "fastest", "time_s", "time_c", "next", "reached"])


def group_summary(groups: pd.DataFrame) -> pd.DataFrame:
    """One row per set of implementations of one method (`harness.timing.same_method_groups`
    output): problems and points compared, whether every point agreed to rounding, the largest
    relative error difference, and the median ratio of the slowest to the fastest time.

    Parameters
    ----------
    groups : DataFrame
        `same_method_groups` rows.

    Returns
    -------
    DataFrame
        Columns implementations, problems, points, agree, largest_relative_diff, time_ratio.
    """
    g = groups.groupby("method_id", sort=False)
    out = g.agg(problems=("problem", "nunique"), points=("h", "size"), agree=("agree", "all"),
                largest_relative_diff=("relative_diff", "max"),
                time_ratio=("slowest_ratio", "median")).reset_index()
    labels = g["implementations"].agg(lambda s: " / ".join(dict.fromkeys(
        part for text in s for part in str(text).split(" / "))))
    out["implementations"] = out["method_id"].map(labels)
    return out.drop(columns="method_id")


def _machine_note(rows: pd.DataFrame) -> str:
    def first(c: str) -> str:
        return str(rows[c].dropna().iloc[0]) if c in rows and rows[c].notna().any() else "unknown"

    load = rows["load_1min"].astype(float) if "load_1min" in rows else pd.Series(dtype=float)
    span = f"{load.min():.2f}-{load.max():.2f}" if load.notna().any() else "unknown"
    return (f"Machine: {first('cpu')}, {first('cores')} logical cores, BLAS {first('blas')} with "
            f"{first('blas_threads')} thread(s); 1-minute load average {span} while the cells were timed.")


def add_time_sections(view: RunView, sec: Section) -> None:
    """Append the timed part to the work-precision section `sec` (module docstring).

    Parameters
    ----------
    view : RunView, the run (its work-precision summary, else its rows).
    sec : Section, the work-precision section, appended to.
    """
    name = "work-precision"
    rows = view.summary(name)  # every row, with the Pareto marks (`pareto_time`)
    if "t_min_s" not in rows:
        rows = view.rowtable(name)
    if "t_min_s" not in rows or not np.isfinite(rows["t_min_s"].astype(float)).any():
        sec.note("This run has no timed work-precision points (its rows predate the timing "
                 "protocol); error against time is not drawn.", cls="warning")
        return
    cfg = view.meta.get("experiments", {}).get(name, {}).get("config", {}) or {}
    sec.heading("Error against time")
    sec.note(PROTOCOL.format(spread=timing.TIMING_TARGET_SPREAD, min_r=timing.TIMING_MIN_REPEATS,
                             max_r=cfg.get("timing_max_repeats", timing.TIMING_MAX_REPEATS),
                             budget=cfg.get("timing_budget_s", timing.TIMING_POINT_BUDGET_S))
             + " " + _machine_note(rows))
    cost = rows.groupby(["stepper", "problem"])["timing_cell_s"].first() if "timing_cell_s" in rows \
        else pd.Series(dtype=float)
    if cost.notna().any():
        sec.note(f"The timing took {cost.sum():.1f} s over {int(cost.notna().sum())} cells in this run "
                 f"(cells from the cache keep the timings of the run that measured them).")
    adaptive = view.flag("adaptive")
    for problem in [p for p in view.problems if p in set(rows["problem"])]:
        part = rows[rows["problem"] == problem]
        sec.figure(time_precision_figure(problem, part, view.palette, adaptive),
                   f"Error against warm time on {problem}; the black line is the Pareto front.")
    table = time_to_target_table(rows)
    base = rows.groupby(["problem", "stepper"])["baseline_step_s"].median().rename("b").reset_index()
    table = table.merge(base, on=["problem", "stepper"], how="left")
    table["time_c"] = table["time_s"] / table.pop("b")
    if len(table):
        sec.table(df_table(fastest_table(table), [
            ("problem", "problem"), ("target", "target error"), ("fastest", "fastest"),
            ("time_s", "its time (s)"), ("time_c", "in C-baseline steps"), ("next", "next (x fastest)"),
            ("reached", "reached it")],
            "Time to reach each target error: the fastest stepper and the next three (log-error "
            "against log-time interpolated between measured points; every stepper's time and how "
            "it was found in time-to-target.csv)", experiment=name, key=("problem", "target"),
            status=None, sort_failing=False))
    groups = same_method_groups(twin_rows(rows))
    if len(groups):
        sec.table(df_table(group_summary(groups), [
            ("implementations", "implementations"), ("problems", "problems"), ("points", "points"),
            ("largest_relative_diff", "largest relative error difference"),
            ("time_ratio", "slowest / fastest time (median)")],
            "One method, several implementations (grouped by the identity of their coefficients, "
            "never by name): their errors at equal steps agree to rounding (the check) and only their "
            "times differ; every point in same-method.csv", experiment=name,
            key=("implementations",), status="agree"))
    else:
        sec.note("No two implementations of one method (equal coefficients) were timed at the same "
                 "points in this run.")
    sec.blocks.append(Block("downloads", downloads=[d for d in (
        csv_download(table, "time-to-target.csv"), csv_download(groups, "same-method.csv")) if d]))
    spread = rows[np.isfinite(rows["t_min_s"].astype(float))].groupby("problem").agg(
        points=("t_min_s", "size"), median_spread=("t_spread", "median"), worst_spread=("t_spread", "max"),
        repeats=("t_repeats", "median"), baseline_step_ns=("baseline_step_s", "median")).reset_index()
    spread["baseline_step_ns"] *= 1e9
    sec.table(df_table(spread, [("problem", "problem"), ("points", "timed points"),
                                ("median_spread", "median spread"), ("worst_spread", "largest spread"),
                                ("repeats", "median repeats"), ("baseline_step_ns", "C baseline step (ns)")],
                       "Spread (median - min) / min of the repeated timings, per problem",
                       experiment=name, key=("problem",), status=None, sort_failing=False))
