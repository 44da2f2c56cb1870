"""The sections every report has besides the experiments': the verdicts and scoreboard that
open it, what changed since the last run, ground truth, the course material's claims,
provenance and performance history."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness import perf_history
from harness import tolerances as tol
from harness.ground_truth import reference
from harness.kit import (
    FAIL,
    MARK,
    NONE,
    PASS,
    Block,
    Row,
    RunView,
    Section,
    SectionTimer,
    Table,
    TextCell,
    anchor,
    df_table,
    fmt,
    text_cell,
)
from harness.problem.validation import exact_state
from harness.provenance import PROJECT_ROOT
from harness.registry import get_problem
from harness.report.claims import AGREE, DISAGREE, check_claims
from harness.report.compare import compare_runs
from harness.report.history_figure import perf_history_figure
from harness.report.specs import section_spec
from harness.store import list_runs, load_run

__all__ = ["verdicts_section", "changes_section", "ground_truth", "claims", "gate_trust", "provenance",
           "performance_history"]

# The first screen lists at most this many failing claims; the rest are one click away, folded.
MAX_FAILURES_LISTED = 12


# -- verdicts and scoreboard ------------------------------------------------------------------------
def verdicts_section(view: RunView, verdicts: pd.DataFrame, experiments: list[str]
                     ) -> tuple[Section, dict[str, str]]:
    """How many claims were checked and failed, the failing ones in a sentence each (linked to
    their rows), then the scoreboard: one row per stepper, every number linked to its row.

    Parameters
    ----------
    view : RunView, the run.
    verdicts : DataFrame, one row per judged cell (experiment, judged, passed, ...).
    experiments : list of str, the experiments of the report, in section order.

    Returns
    -------
    (Section, dict of str to str): the section, and each stepper's scoreboard status.
    """
    sec = Section("verdicts", 1, "Verdicts")
    judged = verdicts[verdicts["judged"].astype(bool)] if len(verdicts) else verdicts
    n, bad = len(judged), verdicts[~verdicts["passed"]] if len(verdicts) else verdicts
    exps = set(judged["experiment"]) - {"claims"} if n else set()
    fails = view.failures()
    course = " and the course material" if n and (judged["experiment"] == "claims").any() else ""
    text = f"{n} claims checked in {len(exps)} experiments{course}: {len(bad)} failed."
    if len(verdicts) > n:
        text += (f" {len(verdicts) - n} further cells are informational (no claim behind them, or "
                 "not measurable on this run) and are not counted.")
    if fails:
        text += f" {len(fails)} cells could not be measured (see Provenance)."
    sec.blocks.append(Block("headline", text=text, cls="fail" if len(bad) or fails else "pass"))
    items = [(s, "#" + a) for s, a in zip(bad["sentence"], bad["anchor"], strict=True)]
    if items:
        sec.blocks.append(Block("list", items=items[:MAX_FAILURES_LISTED], cls="failing"))
        if len(items) > MAX_FAILURES_LISTED:
            sec.blocks.append(Block("list", items=items[MAX_FAILURES_LISTED:], cls="failing folded",
                                    text=str(MAX_FAILURES_LISTED + 1),
                                    summary=f"{len(items) - MAX_FAILURES_LISTED} more failing claims"))
    by_stepper: dict[str, list[tuple[str, str]]] = {}
    for rec in bad.to_dict("records"):
        if rec["stepper"]:
            by_stepper.setdefault(rec["stepper"], []).append(
                (f"{rec['experiment']} on {rec['problem']}" if rec["problem"] else rec["experiment"],
                 "#" + rec["anchor"]))
    failed_cells: dict[str, int] = {}
    for f in fails:
        failed_cells[f.get("stepper", "")] = failed_cells.get(f.get("stepper", ""), 0) + 1
    columns = [c for e in experiments for c in section_spec(e).score]
    records = []
    for i, name in enumerate(view.steppers):
        info = view.infos.get(name)
        cells, measured = [], False
        for col in columns:
            try:
                parts, m = col.value(view, name)
            except Exception as exc:  # one odd row must not cost the scoreboard
                parts, m = [(f"could not summarise: {type(exc).__name__}", "")], False
            measured = measured or m
            cells.append(TextCell("".join(p for p, _ in parts), parts=parts))
        failing = by_stepper.get(name, [])
        parts = []
        for k, (text, href) in enumerate(failing[:4]):
            parts += [("; " if k else "", ""), (text, href)]
        if len(failing) > 4:
            parts.append((f"; and {len(failing) - 4} more", ""))
        if failed_cells.get(name):
            parts.append((f"{'; ' if parts else ''}{failed_cells[name]} failed cell(s), see ", ""))
            parts.append(("Provenance", "#provenance"))
        status = FAIL if parts else (PASS if measured else NONE)
        claimed = "adaptive" if info is not None and info.claimed_order is None else \
            str(info.claimed_order if info is not None else "—")
        row_cells = [TextCell(MARK[status], cls=f"status {status}"),
                     TextCell(name, cls="name", title=view.origins.get(name, ""),
                              swatch=view.palette.colour(name)),
                     TextCell(info.family if info is not None else "—"),
                     TextCell(claimed, cls="num"), *cells,
                     TextCell("".join(p for p, _ in parts), cls="message", parts=parts)]
        records.append(({FAIL: 0, PASS: 1, NONE: 2}[status], i, name, status, row_cells))
    records.sort(key=lambda r: (r[0], r[1]))
    statuses = {r[2]: r[3] for r in records}
    rows = [Row(cells, cls=f"stepper-row {status}", stepper=name, id=anchor("scoreboard", name))
            for _, _, name, status, cells in records]
    n_fail = sum(1 for s in statuses.values() if s == FAIL)
    headers = ["verdict", "stepper", "family", "claimed order", *[c.header for c in columns],
               "failing claims"]
    sec.table(Table(f"Scoreboard: {len(rows)} steppers, {n_fail} with a failing claim", headers, rows,
                    cls="scoreboard", id="scoreboard-table"))
    sec.note("Every number links to the table row it comes from. Measured order: least-squares "
             "slope over the asymptotic range; reversible measured = returns within what "
             "rounding explains; symplectic measured = ‖JᵀΩJ − Ω‖ at the finite-difference level; "
             "evaluations per step from the convergence runs' counters.")
    return sec, statuses


# -- what changed -------------------------------------------------------------------------------------
def changes_section(view: RunView, verdicts: pd.DataFrame, previous: Any) -> Section:
    """Verdicts that changed and measured figures that moved since `previous` (a
    `harness.report.compare.Previous`, or None).

    Parameters
    ----------
    view : RunView, this run.
    verdicts : DataFrame, this run's verdicts.
    previous : Previous or None, the earlier run.

    Returns
    -------
    Section: tables of the changed verdicts and moved figures, or a note.
    """
    sec = Section("changes", 2, "What changed since the last run")
    sec.intro = ("Every verdict that differs from the earlier run's, and every measured figure "
                 "that moved beyond its confidence interval (or, for a figure without one, its "
                 "stated tolerance). Pairs measured in only one of the runs are counted, not listed.")
    if previous is None:
        sec.note("No earlier run to compare with: this is the first run in the results directory "
                 "(or `harness report --compare RUN` names one).")
        return sec
    diff = compare_runs(view, verdicts, previous)
    prov = Table("The two runs", ["", "earlier run", "this run"], [
        Row([TextCell(k, cls="key"), TextCell(a), TextCell(b)]) for k, a, b in diff.provenance],
        cls="kv")
    sec.table(prov)
    sec.blocks.append(Block("headline", text=diff.headline,
                            cls="fail" if len(diff.verdicts) or len(diff.moved) else "pass"))
    def row_col(df: pd.DataFrame) -> list[tuple[str, str]]:
        return [("where", "row")] if (df["where"].astype(str) != "").any() else []

    if len(diff.verdicts):
        sec.table(df_table(diff.verdicts, [("experiment", "experiment"), ("stepper", "stepper"),
                                           ("problem", "problem"), *row_col(diff.verdicts),
                                           ("before", "earlier verdict"), ("after", "verdict now"),
                                           ("sentence", "now")],
                           f"{len(diff.verdicts)} verdict(s) changed", status="passed_now",
                           folded=False, id="changed-verdicts", links={"where": "href", "stepper": "href"}))
    if len(diff.moved):
        sec.table(df_table(diff.moved, [("experiment", "experiment"), ("stepper", "stepper"),
                                        ("problem", "problem"), *row_col(diff.moved), ("figure", "figure"),
                                        ("before", "earlier"), ("after", "now"), ("bound", "moved beyond")],
                           f"{len(diff.moved)} measured figure(s) moved", status=None, folded=False,
                           id="moved-figures", digits=4, links={"stepper": "href"}))
    for text in diff.notes:
        sec.note(text)
    return sec


def ground_truth(view: RunView) -> Section:
    """Per problem: the reference used by the convergence cells (the same call, so the disk cache
    answers), its precision and certified error, and its difference from the exact solution.

    Parameters
    ----------
    view : RunView, the run (its convergence configuration and summary).

    Returns
    -------
    Section: per problem, the reference's precision and certified error.
    """
    sec = Section("ground-truth", 0, "Ground truth")
    sec.intro = ("Every error in this report is measured against heyoka's Taylor integrator "
                 "(tolerance at the unit roundoff of its precision, high_accuracy on), whose own "
                 "error is certified by a rerun one precision level higher. Where a problem has "
                 "an exact solution, the reference is checked against it here.")
    conv_cfg = view.meta.get("config", {}).get("experiments", {}).get("convergence")
    summ = view.summary("convergence")
    used = set(summ["problem"]) if len(summ) else set()
    records = []
    for name in view.problems:
        problem = get_problem(name)
        rec: dict[str, Any] = {"problem": name, "exact": problem.exact is not None}
        if name not in used or conv_cfg is None:
            rec.update(method="—", message="not used by this report's convergence cells")
            records.append(rec)
            continue
        try:
            y0 = problem.ensemble(int(conv_cfg["ensemble"]), seed=int(conv_cfg["seed"]))
            scale0 = max(1.0, float(np.max(np.abs(y0))))
            T = problem.convergence_t_end
            ref = reference(problem, np.array([T]), y0, required_error=tol.EPS * scale0)
            rec.update(method="heyoka taylor_adaptive", precision=ref.precision,
                       certified_by=ref.certified_by, t=T, members=y0.shape[1],
                       certified_error=ref.max_error, compute_s=ref.compute_s,
                       cached="yes" if ref.cached else "no")
            if problem.exact is not None:
                diff = float(np.max(np.abs(exact_state(problem, T, y0) - ref.y[-1])))
                scale = max(1.0, float(np.max(np.abs(ref.y[-1]))))
                allowed = ref.max_error + tol.GROUND_TRUTH_EXACT_ULPS * tol.EPS * scale
                rec.update(exact_difference=diff, allowed=allowed, passed=diff <= allowed,
                           check="consistent" if diff <= allowed else "INCONSISTENT")
            else:
                rec.update(check="no exact solution")
        except Exception as exc:  # a reference that cannot be built is reported, not fatal
            rec.update(method="—", passed=False, message=f"{type(exc).__name__}: {exc}")
        records.append(rec)
    df = pd.DataFrame(records)
    for c in ("passed", "message", "check", "precision", "certified_by", "t", "members",
              "certified_error", "compute_s", "cached", "exact_difference", "allowed"):
        if c not in df:
            df[c] = None
    cols = [("problem", "problem"), ("method", "reference method"), ("precision", "precision"),
            ("certified_by", "certified by"), ("t", "at t"), ("members", "members"),
            ("certified_error", "certified error"), ("compute_s", "compute time (s)"),
            ("cached", "from disk cache"), ("exact", "exact solution"),
            ("exact_difference", "|reference − exact|"), ("allowed", "allowed"),
            ("check", "check"), ("message", "message")]
    sec.table(df_table(df, cols, "References used by the convergence experiment", digits=3))
    sec.note(f"Allowed difference: the certified error plus {tol.GROUND_TRUTH_EXACT_ULPS:g} ulps "
             "of the state for the float64 evaluation of the exact formula.")
    return sec


# -- 8 claims -------------------------------------------------------------------------------------
def claims(view: RunView) -> Section:
    """The course material's claims, each with its source and what this run measured.

    Parameters
    ----------
    view : RunView, the run (all summaries are passed to `check_claims`).

    Returns
    -------
    Section
    """
    sec = Section("claims", 0, "Claims from the course material, checked")
    sec.intro = ("Statements from the four course texts the project grew from "
                 "(../shared/course-material/), paraphrased, each with its source and what this "
                 "run measured.")
    tables = {k: v for k, v in view.summaries.items()}
    results = check_claims(tables)
    rows = []
    for r in results:
        cls = {AGREE: "pass", DISAGREE: "fail"}.get(r.status, "none")
        mark = {AGREE: "✓ agree", DISAGREE: "✗ disagree"}.get(r.status, "– not measured")
        src = r.source + (f", line {r.line}" if r.line else "")
        rows.append(Row([TextCell(mark, cls=f"status {cls}"), TextCell(r.claim),
                         TextCell(src, cls="source"), TextCell(r.measurement)], cls=f"claim {cls}",
                        id=anchor("claims", r.key)))
    sec.table(Table("Claims and measurements", ["verdict", "claim (paraphrased)", "source",
                                                "measurement"], rows, cls="claims"))
    for r in results:
        if r.values:
            cols = list(r.values[0].keys())
            sec.table(Table(f"{r.key}: measured values ({len(r.values)} rows)", cols,
                            [Row([TextCell(str(v.get(c, ""))) for c in cols]) for v in r.values],
                            folded=True))
    return sec


# -- how much to trust the gate ------------------------------------------------------------------
def gate_trust(view: RunView, results_dir: Any) -> Section:
    """The gate's own error rates from the newest `harness population` run saved beside this
    run: per family of generated methods, false alarms on correct ones and misses on mutants.

    Parameters
    ----------
    view : RunView, this run.
    results_dir : path, the results directory searched for population runs.

    Returns
    -------
    Section: a note saying so when no population run is saved.
    """
    sec = Section("gate-population", 0, "How much to trust the gate")
    sec.intro = ("The gate judged on generated methods whose truth is known: random correct "
                 "members of parametric families (every one must pass) and mutants with one "
                 "coefficient broken (every one must fail). A false alarm is a correct method "
                 "failed, a miss a mutant passed; both rates should be zero.")
    found = None
    for run_id in reversed(list_runs(results_dir)):
        try:
            meta = json.loads((Path(results_dir) / run_id / "meta.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if "gate-population" in meta.get("experiments", {}):
            found = run_id
            break
    if found is None:
        sec.note("No population run in the results directory: `harness population` measures "
                 "the gate's false alarms and misses and saves them there.")
        return sec
    stored = load_run(found, root=results_dir)
    summ = stored.summaries["gate-population"]
    cfg = stored.meta.get("config", {}).get("run", {})
    sec.note(f"From run {found} ({cfg.get('size', '?')} correct methods per family, seed "
             f"{cfg.get('seed', '?')}).")
    cols = [(c, c.replace("_", " ")) for c in ("family", "correct_methods", "mutants", "gate_false_alarms",
                                               "gate_misses", "measurement_false_alarms",
                                               "measurement_misses") if c in summ]
    sec.table(df_table(summ, cols, "False alarms and misses per family of generated methods",
                       status=None, sort_failing=False, folded=False))
    return sec


# -- 9 provenance ---------------------------------------------------------------------------------
def provenance(view: RunView, *, run_id: str, results_path: str, timer: SectionTimer,
               build_s: Mapping[str, float]) -> Section:
    """Where the run comes from and how it went: run id, commit, machine, the time per
    experiment and per build step, the failed cells, the full configuration.

    Parameters
    ----------
    view : RunView, the run (its meta.json).
    run_id : str, the run's id.
    results_path : str, the run's directory, as shown.
    timer : SectionTimer, the time each section took to build.
    build_s : mapping of str to float, other build phases' seconds.

    Returns
    -------
    Section
    """
    sec = Section("provenance", 0, "Provenance")
    meta = view.meta
    prov = meta.get("provenance", {})
    git = prov.get("git", {})
    machine = prov.get("machine", {})
    dirty = git.get("dirty")
    info_rows = [
        ("run id", run_id),
        ("results", results_path),
        ("date (UTC)", str(prov.get("date_utc", ""))),
        ("git commit", str(git.get("sha") or "not a git checkout")),
        ("working tree", "—" if dirty is None else ("dirty (uncommitted changes)" if dirty else "clean")),
        ("CPU", str(machine.get("cpu", ""))),
        ("logical cores", str(machine.get("logical_cores", ""))),
        ("memory", fmt((machine.get("memory_bytes") or 0) / 2**30, 3) + " GiB"),
        ("operating system", str(machine.get("os", ""))),
        ("mode", "quick (CI-sized settings)" if view.quick else "full"),
    ]
    for k, v in (prov.get("versions") or {}).items():
        info_rows.append((f"version: {k}", str(v)))
    sec.table(Table("Where these numbers come from", ["", ""],
                    [Row([TextCell(k, cls="key"), TextCell(v)]) for k, v in info_rows], cls="kv"))
    exp_rows = []
    for name, e in meta.get("experiments", {}).items():
        exp_rows.append(Row([TextCell(name), text_cell(e.get("wall_s"), 3), text_cell(e.get("n_cells")),
                             text_cell(e.get("computed_cells")), text_cell(e.get("cached_cells")),
                             text_cell(e.get("failed_cells")), text_cell(len(e.get("skips", [])))]))
    totals = meta.get("totals", {})
    exp_rows.append(Row([TextCell("total", cls="key"), text_cell(totals.get("wall_s"), 3),
                         text_cell(totals.get("cells")), text_cell(totals.get("computed")),
                         text_cell(totals.get("cached")), text_cell(totals.get("failed")),
                         text_cell(totals.get("skipped"))], cls="total"))
    sec.table(Table("Time per experiment (wall seconds of this run; cached cells cost only their "
                    "loading)", ["experiment", "wall s", "cells", "computed", "from cache",
                                 "failed", "not applicable"], exp_rows))
    build_rows = [Row([TextCell(k), text_cell(v, 3)]) for k, v in build_s.items()]
    build_rows += [Row([TextCell(f"section: {k}"), text_cell(v, 3)]) for k, v in timer.seconds.items()]
    sec.table(Table("Time spent building the report (seconds)", ["step", "s"], build_rows))
    fails = view.failures()
    if fails:
        rows = [Row([TextCell(str(f.get("experiment", ""))), TextCell(str(f.get("cell", ""))),
                     TextCell(str(f.get("kind", ""))), TextCell(str(f.get("message", "")), cls="message")],
                    cls="failing") for f in fails]
        sec.table(Table(f"{len(fails)} failed cell(s)", ["experiment", "cell", "kind", "message"],
                        rows, cls="failures"))
        for f in fails:
            if f.get("traceback"):
                sec.details(f"traceback: {f.get('cell', '')}", str(f["traceback"]))
    else:
        sec.note("No cell failed.")
    sec.details("full configuration (JSON)", json.dumps(meta.get("config", {}), indent=2, sort_keys=True))
    return sec


# -- 10 performance history -----------------------------------------------------------------------
def performance_history() -> Section:
    """Speed and tracked accuracy over commits, from asv's result files.

    Returns
    -------
    Section: a note instead when there are no asv results or they cannot be read.
    """
    sec = Section("performance-history", 0, "Performance history")
    sec.intro = ("Speed and tracked accuracy over commits, from asv's result files "
                 "(drawn here because asv's own dashboard loads its scripts from the internet).")
    try:
        history = perf_history.load_history(PROJECT_ROOT / ".asv" / "results")
    except Exception as exc:
        sec.note(f"The asv results could not be read: {type(exc).__name__}: {exc}", cls="warning")
        return sec
    if history is None or len(history) == 0:
        sec.note("No asv results yet (run `make nightly`).")
        return sec
    sec.figure(perf_history_figure(history),
               "Benchmark values against commit date (one panel per benchmark, one line per "
               "parameter set; at most 12 panels).")
    latest = history.sort_values("date").groupby(["benchmark", "params"], sort=False).tail(1)
    rows = [Row([TextCell(str(r["benchmark"])), TextCell(str(r["params"])), text_cell(r["value"], 4),
                 TextCell(str(r["unit"])), TextCell(str(r["commit"])[:10]), TextCell(str(r["date"]))])
            for r in latest.head(200).to_dict("records")]
    sec.table(Table("Latest value of each benchmark", ["benchmark", "params", "value", "unit",
                                                        "commit", "date"], rows, folded=True))
    return sec


