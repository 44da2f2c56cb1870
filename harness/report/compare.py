"""What changed since an earlier run: verdicts that differ and measured figures that moved.

`load_previous(run, ...)` reads an earlier saved run (`harness.store`) and the verdicts its own
report recorded (`verdicts.csv` beside its index.html; without one they are judged again from
its summaries, with this build's rules). `compare_runs(view, verdicts, previous)` matches rows by
(experiment, stepper, problem, key) and lists
- every verdict that changed (pass -> fail, fail -> pass, or a different verdict word), and
- every measured figure (the `Measure`s of each section's registration) that moved: outside the
  earlier run's confidence interval and the earlier value outside this run's (where the figure
  has one), else beyond the relative tolerance or factor the registration states;
with both runs' provenance. Rows measured in only one run are counted, not listed.
"""

from __future__ import annotations

import io
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from harness.kit import RunView, anchor, is_missing
from harness.report.specs import experiment_key, section_spec
from harness.report.verdicts import VERDICT_COLUMNS, collect_verdicts
from harness.store import list_runs, load_run
from harness.store.files import read_bounded

__all__ = ["Previous", "Comparison", "load_previous", "compare_runs", "VERDICTS_FILE"]

# Written beside each report's index.html: the verdicts as that report judged them.
VERDICTS_FILE = "verdicts.csv"


@dataclass
class Previous:
    run_id: str
    meta: dict
    summaries: dict[str, pd.DataFrame]
    verdicts: pd.DataFrame
    verdicts_source: str


@dataclass
class Comparison:
    headline: str
    verdicts: pd.DataFrame
    moved: pd.DataFrame
    provenance: list[tuple[str, str, str]]
    notes: list[str] = field(default_factory=list)


def load_previous(run: str | os.PathLike | None, *, results_root: str | os.PathLike | None,
                  reports_root: str | os.PathLike | None, current: str,
                  view_factory: Any) -> Previous | None:
    """The run to compare with: `run` (an id or path), else the newest saved run older than
    `current` (None when there is none). `view_factory(stored)` builds its RunView when its
    verdicts have to be judged again.

    Parameters
    ----------
    run : str, path or None, the earlier run asked for.
    results_root : path or None, the results directory (None: the default).
    reports_root : path or None, where the earlier run's report (and its recorded verdicts) may be.
    current : str, this run's id (never compared with itself).
    view_factory : callable, StoredRun -> RunView.

    Returns
    -------
    Previous or None
    """
    if run is None:
        ids = [r for r in list_runs(results_root) if r != current]
        ids = [r for r in ids if r < current] or []
        if not ids:
            return None
        run = ids[-1]
    # the summaries and meta.json are what a comparison reads; the rows only when the run's
    # verdicts have to be judged again
    stored = load_run(run, root=results_root, tables=("summary",))
    if stored.run_id == current:
        return None
    saved = Path(reports_root) / stored.run_id / VERDICTS_FILE if reports_root else None
    verdicts, damaged = (_read_verdicts(saved) if saved is not None and saved.exists()
                         else (None, ""))
    if verdicts is not None:
        source = f"recorded by its report ({saved})"
    else:
        stored = load_run(stored.path)
        verdicts = collect_verdicts(view_factory(stored))
        source = "judged again from its saved summaries with this build's rules"
        if damaged:
            source += f" (its report's {saved} is damaged: {damaged})"
    return Previous(stored.run_id, stored.meta, dict(stored.summaries), verdicts, source)


def _read_verdicts(path: Path) -> tuple[pd.DataFrame | None, str]:
    """(the verdicts an earlier report recorded, "") or (None, why the file cannot be used): a
    damaged file is judged again from the saved run, never a crash."""
    try:
        text = read_bounded(path).decode("utf-8")
        verdicts = pd.read_csv(io.StringIO(text), dtype={"key": str, "stepper": str, "problem": str},
                               keep_default_na=False)
    except Exception as exc:  # noqa: BLE001  (any damage: unreadable, not CSV, not UTF-8)
        return None, " ".join(f"{type(exc).__name__}: {exc}".split())[:200]
    # a report stores all but anchors; `judged` is newer than some stored reports
    written = [c for c in VERDICT_COLUMNS if c not in ("anchor", "judged")]
    missing = [c for c in written if c not in verdicts.columns]
    if missing:
        return None, f"columns {missing} missing"
    verdicts["passed"] = verdicts["passed"].astype(str).str.lower().isin(("true", "1"))
    verdicts["judged"] = (verdicts["judged"].astype(str).str.lower().isin(("true", "1"))
                          if "judged" in verdicts else True)
    return verdicts, ""


def _provenance(meta: dict) -> dict[str, str]:
    prov = meta.get("provenance", {})
    git = prov.get("git", {})
    machine = prov.get("machine", {})
    cfg = meta.get("config", {}).get("run", {})
    dirty = git.get("dirty")
    return {
        "run id": str(meta.get("run_id", "")),
        "date (UTC)": str(prov.get("date_utc") or meta.get("created_utc", "")),
        "git commit": str(git.get("sha") or "not a git checkout")
        + ("" if dirty is None else (" (uncommitted changes)" if dirty else "")),
        "machine": f"{machine.get('cpu', '')}, {machine.get('logical_cores', '')} cores",
        "mode": "quick" if cfg.get("quick") else "full",
        "steppers × problems": f"{len(cfg.get('steppers') or [])} × {len(cfg.get('problems') or [])}",
        "plugins": ", ".join(os.path.basename(str(p)) for p in cfg.get("plugins") or []) or "none",
    }


def _id(df: pd.DataFrame) -> pd.Series:
    return df["experiment"].astype(str) + "\x1f" + df["key"].astype(str)


def _where(key: str) -> str:
    try:
        values = json.loads(key)
    except (TypeError, ValueError):
        return str(key)
    return ", ".join(str(v) for v in values[2:]) if isinstance(values, list) else str(values)


def compare_runs(view: RunView, verdicts: pd.DataFrame, previous: Previous) -> Comparison:
    """What changed between `previous` and this run: the verdicts that differ (pairs judged in
    both runs) and the measured figures that moved beyond their confidence interval or tolerance.

    Parameters
    ----------
    view : RunView, this run.
    verdicts : DataFrame, this run's verdicts (`collect_verdicts`).
    previous : Previous, the earlier run with its verdicts.

    Returns
    -------
    Comparison: a headline, the changed verdicts, the moved figures, both runs' provenance side
        by side, and notes.
    """
    now_p, then_p = _provenance(view.meta), _provenance(previous.meta)
    provenance = [(k, then_p[k], now_p[k]) for k in now_p]
    provenance.append(("verdicts", previous.verdicts_source, "judged by this report"))

    # verdicts
    a = previous.verdicts.assign(_id=lambda d: _id(d)).drop_duplicates("_id").set_index("_id")
    b = verdicts.assign(_id=lambda d: _id(d)).drop_duplicates("_id").set_index("_id")
    common = a.index.intersection(b.index)
    then, now = a.loc[common], b.loc[common]
    differs = ((then["passed"].astype(bool) != now["passed"].astype(bool))
               | (then["verdict"].astype(str) != now["verdict"].astype(str)))
    changed = []
    for i in common[differs.to_numpy()]:
        before, after = a.loc[i], b.loc[i]
        changed.append({"experiment": after["experiment"], "stepper": after["stepper"],
                        "problem": after["problem"], "where": _where(after["key"]),
                        "before": f"{'pass' if bool(before['passed']) else 'FAIL'} ({before['verdict']})",
                        "after": f"{'pass' if bool(after['passed']) else 'FAIL'} ({after['verdict']})",
                        "passed_now": bool(after["passed"]), "sentence": after["sentence"],
                        "href": "#" + str(after["anchor"])})
    changed_df = pd.DataFrame(changed, columns=["experiment", "stepper", "problem", "where", "before",
                                                "after", "passed_now", "sentence", "href"])
    if len(changed_df):
        changed_df = changed_df.sort_values(["passed_now", "experiment", "stepper"], kind="stable")

    # measured figures
    moved = []
    compared = 0
    for name in view.meta.get("experiments", {}):
        spec = section_spec(name)
        new, old = view.summary(name), previous.summaries.get(name, pd.DataFrame())
        if not spec.measures or new.empty or old.empty:
            continue
        key = [c for c in experiment_key(name, new) if c in new and c in old]
        if not key:
            continue
        merged = new.merge(old, on=key, how="inner", suffixes=("", "__old"))
        for m in spec.measures:
            if m.column not in new or m.column not in old:
                continue
            for rec in merged.to_dict("records"):
                x, x0 = _num(rec.get(m.column)), _num(rec.get(m.column + "__old"))
                if math.isnan(x) and math.isnan(x0):
                    continue
                compared += 1
                bound = _moved(m, rec, x, x0)
                if bound:
                    values = [rec.get(c) for c in key]
                    row = [rec.get(c) for c in spec.row_key] if spec.row_key else values
                    moved.append({"experiment": name, "stepper": rec.get("stepper", ""),
                                  "problem": rec.get("problem", ""),
                                  "where": ", ".join(str(v) for v in values[2:]), "figure": m.label,
                                  "before": x0, "after": x, "bound": bound,
                                  "href": "#" + anchor(name, *row)})
    moved_df = pd.DataFrame(moved, columns=["experiment", "stepper", "problem", "where", "figure",
                                            "before", "after", "bound", "href"])
    only_then, only_now = len(a.index.difference(b.index)), len(b.index.difference(a.index))
    headline = (f"Compared with run {previous.run_id}: {len(changed_df)} of {len(common)} verdicts "
                f"measured in both runs changed "
                f"({int((~changed_df['passed_now']).sum()) if len(changed_df) else 0} now failing); "
                f"{len(moved_df)} of {compared} measured figures moved.")
    notes = []
    if only_then or only_now:
        notes.append(f"Not compared: {only_now} verdicts only in this run, {only_then} only in the "
                     "earlier one (different steppers, problems or experiments).")
    return Comparison(headline, changed_df, moved_df, provenance, notes)


def _num(x: Any) -> float:
    if is_missing(x):
        return math.nan
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def _moved(m: Any, rec: dict, x: float, x0: float) -> str:
    """'' when the figure did not move, else the bound it moved beyond, in words."""
    if math.isnan(x) != math.isnan(x0):
        return "measured in one run only"
    if math.isinf(x) or math.isinf(x0):
        return "" if x == x0 else "finite in one run only"
    if m.ci is not None:
        lo, hi = _num(rec.get(m.ci[0])), _num(rec.get(m.ci[1]))
        lo0, hi0 = _num(rec.get(m.ci[0] + "__old")), _num(rec.get(m.ci[1] + "__old"))
        if not any(math.isnan(v) for v in (lo, hi, lo0, hi0)):
            if (x < lo0 or x > hi0) and (x0 < lo or x0 > hi):
                return f"both 95% intervals ([{lo0:.4g}, {hi0:.4g}] then, [{lo:.4g}, {hi:.4g}] now)"
            return ""
    if m.factor is not None:
        a, b = abs(x), abs(x0)
        if a == b:
            return ""
        tiny = 1e-300
        if max(a, b) / max(min(a, b), tiny) > m.factor:
            return f"a factor {m.factor:g}"
        return ""
    rtol = m.rtol if m.rtol is not None else 0.0
    if abs(x - x0) > rtol * max(abs(x), abs(x0)):
        return f"relative change {rtol:g}"
    return ""
