"""The report's sections, built from a saved run: tables as data, figures as checked SVG.

`build_sections(run, ...)` returns the list of `Section`s the template renders in order:
1 Scoreboard, 2 Convergence, 3 Stability, 4 Reversibility, 5 Energy drift, 6 Work-precision,
7 Ground truth, 8 Claims from the course material, 9 Provenance, 10 Performance history.
Every text here is plain text; the template escapes it. Only figure SVG is embedded as markup,
after `figures.check_svg` has passed it.

A section whose experiment is missing from the run (not registered in this build, or every
cell failed) still appears, and says so.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.report import figures as F
from harness.report.claims import AGREE, DISAGREE, check_claims

__all__ = ["Section", "Table", "Row", "TextCell", "Block", "build_sections", "SECTION_TITLES",
           "SectionTimer"]

SECTION_TITLES = (
    ("scoreboard", "Scoreboard"),
    ("convergence", "Convergence"),
    ("stability", "Stability"),
    ("reversibility", "Reversibility"),
    ("energy", "Energy drift"),
    ("work-precision", "Work–precision"),
    ("ground-truth", "Ground truth"),
    ("claims", "Claims from the course material, checked"),
    ("provenance", "Provenance"),
    ("performance-history", "Performance history"),
)

FAIL, PASS, NONE = "fail", "pass", "none"
# The scoreboard lists at most this many failing claims per stepper (the sections have them all).
MAX_FAILURES_SHOWN = 6
MARK = {FAIL: "✗ FAIL", PASS: "✓ pass", NONE: "– not measured"}


# -- the data the template renders ----------------------------------------------------------------
@dataclass
class TextCell:
    text: str
    cls: str = ""
    title: str = ""


@dataclass
class Row:
    cells: list[TextCell]
    cls: str = ""
    stepper: str = ""


@dataclass
class Table:
    caption: str
    columns: list[str]
    rows: list[Row]
    cls: str = ""
    id: str = ""


@dataclass
class Block:
    """One piece of a section: kind 'figure' (figure + caption), 'table', 'note' (a paragraph),
    'heading' (a sub-heading), 'pre' (preformatted text), 'details' (summary + pre text),
    'claim' (a ClaimResult with its table)."""

    kind: str
    text: str = ""
    figure: F.Figure | None = None
    table: Table | None = None
    summary: str = ""
    claim: Any = None
    cls: str = ""


@dataclass
class Section:
    id: str
    number: int
    title: str
    intro: str = ""
    blocks: list[Block] = field(default_factory=list)

    def note(self, text: str, cls: str = "") -> None:
        self.blocks.append(Block("note", text=text, cls=cls))

    def heading(self, text: str) -> None:
        self.blocks.append(Block("heading", text=text))

    def figure(self, fig: F.Figure | None, caption: str) -> None:
        if fig is not None:
            self.blocks.append(Block("figure", figure=fig, text=caption))

    def table(self, table: Table) -> None:
        self.blocks.append(Block("table", table=table))


class SectionTimer:
    """Seconds spent building each section (reported in the provenance section)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    def run(self, name: str, fn: Callable[[], Any]) -> Any:
        started = time.perf_counter()
        try:
            return fn()
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - started


# -- formatting -----------------------------------------------------------------------------------
def fmt(x: Any, digits: int = 3) -> str:
    """A number for a table: `digits` significant digits, 'inf' spelled out, '—' for missing."""
    if x is None:
        return "—"
    if isinstance(x, bool | np.bool_):
        return "yes" if x else "no"
    if isinstance(x, str):
        return x or "—"
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(v):
        return "—"
    if math.isinf(v):
        return "unbounded" if v > 0 else "-inf"
    if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
        return f"{v:.{max(digits - 1, 0)}e}"
    return f"{v:.{digits}g}"


def _yn(x: Any) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    return "yes" if bool(x) else "no"


def _cell(x: Any, digits: int = 3, cls: str = "") -> TextCell:
    return TextCell(fmt(x, digits), cls=cls or ("num" if isinstance(x, int | float | np.number)
                                                and not isinstance(x, bool | np.bool_) else ""))


def _status_cell(passed: Any) -> TextCell:
    if passed is None or (isinstance(passed, float) and math.isnan(passed)):
        return TextCell(MARK[NONE], cls="status none")
    if bool(passed):
        return TextCell(MARK[PASS], cls="status pass")
    return TextCell(MARK[FAIL], cls="status fail")


def _df_table(df: pd.DataFrame, columns: Sequence[tuple[str, str]], caption: str, *,
              status: str | None = "passed", stepper_key: bool = False, cls: str = "",
              digits: int = 3, sort_failing: bool = True) -> Table:
    """A Table from `df`: `columns` are (column name, header) pairs; a leading status column from
    the `status` column (failing rows first when `sort_failing`)."""
    if sort_failing and status and status in df and len(df):
        key = df[status].map(lambda v: 0 if (v is not None and not pd.isna(v) and not bool(v)) else 1)
        df = df.assign(_k=key).sort_values("_k", kind="stable").drop(columns="_k")
    headers = ([""] if status else []) + [h for _, h in columns]
    rows = []
    for rec in df.to_dict("records"):
        cells = []
        rcls = ""
        if status:
            v = rec.get(status)
            cells.append(_status_cell(v))
            if v is not None and not pd.isna(v) and not bool(v):
                rcls = "failing"
        for col, _ in columns:
            v = rec.get(col)
            if col == "message":
                cells.append(TextCell("" if v is None or (isinstance(v, float) and math.isnan(v))
                                      else str(v), cls="message"))
            else:
                cells.append(_cell(v, digits))
        rows.append(Row(cells, cls=rcls, stepper=str(rec.get("stepper", "")) if stepper_key else ""))
    return Table(caption, headers, rows, cls=cls)


# -- inputs -----------------------------------------------------------------------------------------
@dataclass
class RunView:
    """What the sections read: per-experiment rows and summaries, failures, the stepper infos."""

    rows: dict[str, pd.DataFrame]
    summaries: dict[str, pd.DataFrame]
    meta: dict
    steppers: list[str]
    problems: list[str]
    infos: dict[str, Any]
    origins: dict[str, str]
    quick: bool
    palette: F.Palette

    def gate(self) -> pd.DataFrame:
        """The CI gate's judgement of every convergence cell (computed once per report)."""
        cached = self.__dict__.get("_gate")
        if cached is None:
            from harness.gate import gate_table

            conv = self.summary("convergence")
            cached = gate_table(conv) if len(conv) and "stepper" in conv else pd.DataFrame(
                columns=["stepper", "problem", "passed", "reason", "verdict", "expected"])
            self.__dict__["_gate"] = cached
        return cached

    def has(self, name: str) -> bool:
        return name in self.summaries and name in self.meta.get("experiments", {})

    def summary(self, name: str) -> pd.DataFrame:
        return self.summaries.get(name, pd.DataFrame())

    def rowtable(self, name: str) -> pd.DataFrame:
        return self.rows.get(name, pd.DataFrame())

    def failures(self, name: str | None = None) -> list[dict]:
        exps = self.meta.get("experiments", {})
        names = [name] if name else list(exps)
        out = []
        for n in names:
            out.extend(exps.get(n, {}).get("failures", []))
        return out

    def skips(self, name: str) -> list[dict]:
        return self.meta.get("experiments", {}).get(name, {}).get("skips", [])


def _missing(section: Section, view: RunView, name: str) -> bool:
    """Add a note and return True when experiment `name` has no results in this run."""
    if not view.has(name):
        section.note(f"The {name} experiment is not part of this build of the harness, so this "
                     "section has no measurements.", cls="warning")
        return True
    fails = view.failures(name)
    if view.summary(name).empty:
        why = f" All {len(fails)} of its cells failed (see Provenance)." if fails else ""
        section.note(f"The {name} experiment produced no results for this selection.{why}",
                     cls="warning")
        return True
    if fails:
        section.note(f"{len(fails)} cell(s) of the {name} experiment failed and are missing here; "
                     "they are listed with their messages under Provenance.", cls="warning")
    return False


def _skip_note(section: Section, view: RunView, name: str) -> None:
    skips = view.skips(name)
    if skips:
        reasons: dict[str, int] = {}
        for s in skips:
            reasons[s.get("reason", "")] = reasons.get(s.get("reason", ""), 0) + 1
        section.blocks.append(Block("details", summary=f"{len(skips)} pairs not applicable "
                                                      f"to the {name} experiment, and why",
                                    text="\n".join(f"{n} x {r}" for r, n in sorted(
                                        reasons.items(), key=lambda kv: -kv[1]))))


# -- 1 scoreboard ---------------------------------------------------------------------------------
def _order_summary(view: RunView, stepper: str) -> tuple[str, list[str], bool]:
    """(measured-order text, failing claims, measured at all)."""
    conv = view.summary("convergence")
    if conv.empty or "stepper" not in conv:
        return "—", [], False
    s = conv[conv["stepper"] == stepper]
    if s.empty:
        return "—", [], False
    gate = view.gate()
    gate = gate[gate["stepper"] == stepper]
    failing = [_order_failure(r) for r in gate.to_dict("records") if not bool(r["passed"])]
    info = view.infos.get(stepper)
    if info is not None and info.claimed_order is None:
        ok = int((s["verdict"] == "meets-tolerance").sum())
        return f"meets tolerance on {ok}/{len(s)}", failing, True
    m = s.loc[s["verdict"] == "converged", "measured_order"].astype(float)
    m = m[np.isfinite(m)]
    others = s.loc[s["verdict"] != "converged", "verdict"].value_counts()
    extra = ", ".join(f"{v} ×{n}" for v, n in others.items())
    if m.empty:
        return f"— ({extra})" if extra else "—", failing, True
    text = (f"{m.median():.2f} (range {m.min():.2f}–{m.max():.2f}, {len(m)} "
            f"problem{'s' if len(m) != 1 else ''})")
    if extra:
        text += f"; {extra}"
    return text, failing, True


def _order_failure(r: Mapping[str, Any]) -> str:
    """One gate failure, short: the section's table has the full reason."""
    if r.get("verdict") == "converged" and r.get("expected") == "converged":
        return (f"order {fmt(r.get('measured_order'), 3)} on {r['problem']} "
                f"(claimed {fmt(r.get('claimed_order'))})")
    if r.get("verdict") == r.get("expected"):
        return f"order on {r['problem']}: {r.get('reason') or r.get('verdict')}"
    return f"order on {r['problem']}: {r.get('verdict')}"


def _stability_summary(view: RunView, stepper: str) -> tuple[str, list[str], bool]:
    st = view.summary("stability")
    if st.empty or "stepper" not in st:
        return "—", [], False
    s = st[st["stepper"] == stepper]
    if s.empty:
        return "—", [], False
    r = s.iloc[0]
    if r.get("form") == "newtonian":
        text = f"hω ≤ {fmt(r.get('hw_limit'), 4)}"
    else:
        re_iv, im_iv = r.get("real_interval"), r.get("imag_interval")
        re_t = "unbounded" if np.isinf(float(re_iv)) else f"[−{fmt(re_iv, 4)}, 0]"
        im_t = "unbounded" if np.isinf(float(im_iv)) else f"±{fmt(im_iv, 4)}"
        text = f"real {re_t}; imag {im_t}"
    failing = [] if bool(r.get("passed", True)) else [
        f"stability: {r.get('verdict')} ({r.get('message') or 'see Stability'})"]
    return text, failing, True


def _claimed_measured(claimed: bool, within: Iterable[bool]) -> str:
    w = list(within)
    if not w:
        return f"{_yn(claimed)} / —"
    n = sum(w)
    measured = "yes" if n == len(w) else ("no" if n == 0 else f"mixed ({n}/{len(w)} yes)")
    return f"{_yn(claimed)} / {measured}"


def _reversible_summary(view: RunView, stepper: str) -> tuple[str, list[str], bool]:
    info = view.infos.get(stepper)
    rv = view.summary("reversibility")
    claimed = bool(info.symmetric) if info is not None else False
    if rv.empty or "stepper" not in rv:
        return _claimed_measured(claimed, []), [], False
    s = rv[rv["stepper"] == stepper]
    if s.empty:
        return _claimed_measured(claimed, []), [], False
    within = [bool(np.isfinite(u) and u <= b) for u, b in
              zip(s["return_error_ulps"].astype(float), s["rounding_bound_ulps"].astype(float), strict=True)]
    bad = s[~s["passed"].astype(bool)]
    failing = [f"reversibility on {r['problem']} (N={r['steps']}): {r['verdict']}"
               for r in bad.to_dict("records")]
    return _claimed_measured(claimed, within), failing, True


def _symplectic_summary(view: RunView, stepper: str) -> tuple[str, list[str], bool]:
    info = view.infos.get(stepper)
    sy = view.summary("symplecticity")
    claimed = bool(info.symplectic) if info is not None else False
    if sy.empty or "stepper" not in sy:
        return _claimed_measured(claimed, []), [], False
    s = sy[sy["stepper"] == stepper]
    if s.empty:
        return _claimed_measured(claimed, []), [], False
    within = [bool(np.isfinite(d) and d <= t) for d, t in
              zip(s["deviation"].astype(float), s["threshold"].astype(float), strict=True)]
    bad = s[~s["passed"].astype(bool)]
    failing = [f"symplecticity on {r['problem']}: {r['verdict']}" for r in bad.to_dict("records")]
    return _claimed_measured(claimed, within), failing, True


def _energy_summary(view: RunView, stepper: str) -> tuple[str, list[str], bool]:
    en = view.summary("energy")
    if en.empty or "stepper" not in en:
        return "—", [], False
    s = en[en["stepper"] == stepper]
    if s.empty:
        return "—", [], False
    counts = s["drift_class"].value_counts()
    text = ", ".join(f"{c} ×{n}" if n > 1 else str(c) for c, n in counts.items())
    bad = s[~s["passed"].astype(bool)]
    failing = [f"energy on {r['problem']}: {r['verdict']} ({r['drift_class']})"
               for r in bad.to_dict("records")]
    return text, failing, True


def _evals_summary(view: RunView, stepper: str) -> str:
    info = view.infos.get(stepper)
    declared = fmt(info.evals_per_step, 3) if info is not None else "—"
    rows = view.rowtable("convergence")
    measured = "—"
    if not rows.empty and {"kind", "stepper", "n_steps"} <= set(rows.columns):
        g = rows[(rows["stepper"] == stepper) & (rows["kind"] == "global")]
        if "message" in g:  # a failed step counts no evaluations
            g = g[g["message"].fillna("").astype(str) == ""]
        if "error" in g:
            g = g[np.isfinite(g["error"].astype(float))]
        if len(g):
            evals = sum(g[c].fillna(0).astype(float) for c in ("rhs_evals", "force_evals") if c in g)
            per = (evals / g["n_steps"].astype(float)).replace([np.inf, -np.inf], np.nan).dropna()
            if len(per):
                lo, hi = per.min(), per.max()
                measured = fmt(per.median(), 3) if abs(hi - lo) < 1e-9 * max(1.0, hi) else \
                    f"{fmt(per.median(), 3)} ({fmt(lo, 3)}–{fmt(hi, 3)})"
    return f"{declared} / {measured}"


def scoreboard(view: RunView) -> tuple[Section, dict[str, str]]:
    sec = Section("scoreboard", 1, "Scoreboard")
    sec.intro = ("One row per stepper of this report: each claim it makes beside what the harness "
                 "measured. Rows with a failing claim come first and are marked ✗ FAIL; the last "
                 "column says which claims failed. Details and figures are in the sections below.")
    failed_cells: dict[str, dict[str, int]] = {}
    for f in view.failures():
        per = failed_cells.setdefault(f.get("stepper", ""), {})
        per[f.get("experiment", "")] = per.get(f.get("experiment", ""), 0) + 1
    records = []
    for i, name in enumerate(view.steppers):
        info = view.infos.get(name)
        order_text, f1, m1 = _order_summary(view, name)
        stab_text, f2, m2 = _stability_summary(view, name)
        rev_text, f3, m3 = _reversible_summary(view, name)
        sym_text, f4, m4 = _symplectic_summary(view, name)
        en_text, f5, m5 = _energy_summary(view, name)
        failing = f1 + f2 + f3 + f4 + f5
        for exp, n in failed_cells.get(name, {}).items():
            failing.append(f"{n} failed {exp} cell{'s' if n != 1 else ''} (see Provenance)")
        measured = m1 or m2 or m3 or m4 or m5
        status = FAIL if failing else (PASS if measured else NONE)
        records.append((0 if status == FAIL else (1 if status == PASS else 2), i, name, status, [
            TextCell(MARK[status], cls=f"status {status}"),
            TextCell(name, cls="name", title=view.origins.get(name, "")),
            TextCell(info.family if info is not None else "—"),
            TextCell("adaptive" if info is not None and info.claimed_order is None
                     else str(info.claimed_order if info is not None else "—"), cls="num"),
            TextCell(order_text),
            TextCell(stab_text),
            TextCell(rev_text),
            TextCell(sym_text),
            TextCell(en_text),
            TextCell(_evals_summary(view, name)),
            TextCell("; ".join(failing[:MAX_FAILURES_SHOWN])
                     + (f"; and {len(failing) - MAX_FAILURES_SHOWN} more (see the sections)"
                        if len(failing) > MAX_FAILURES_SHOWN else ""), cls="message"),
        ]))
    records.sort(key=lambda r: (r[0], r[1]))
    statuses = {r[2]: r[3] for r in records}
    rows = [Row(cells, cls=f"stepper-row {status}", stepper=name)
            for _, _, name, status, cells in records]
    n_fail = sum(1 for s in statuses.values() if s == FAIL)
    headers = ["verdict", "stepper", "family", "claimed order", "measured order (median over problems)",
               "stability (probe)", "reversible claimed / measured",
               "symplectic claimed / measured", "energy drift class", "evaluations per step "
               "declared / measured", "failing claims"]
    sec.table(Table(f"{len(rows)} steppers, {n_fail} with a failing claim", headers, rows,
                    cls="scoreboard", id="scoreboard-table"))
    sec.note("Measured order: least-squares slope over the asymptotic range (see Convergence); "
             "reversible measured = returns to within what rounding explains; symplectic measured "
             "= ‖JᵀΩJ − Ω‖ at the finite-difference level; evaluations per step measured from the "
             "convergence runs' counters (implicit methods count Newton iterations).")
    return sec, statuses


# -- 2 convergence --------------------------------------------------------------------------------
def convergence(view: RunView) -> Section:
    sec = Section("convergence", 2, "Convergence")
    sec.intro = ("Global error at the final time against the step size h, per problem, for every "
                 "fixed-step stepper. Filled markers are the points the order fit used; hollow "
                 "markers are excluded points (the legend says why: roundoff floor, too close to "
                 "the reference error, or pre-asymptotic). The dashed line is the fitted slope "
                 "over the points it used; the dotted black line is the reference's certified "
                 "error. Adaptive steppers are measured against tolerance instead (table).")
    if _missing(sec, view, "convergence"):
        return sec
    rows = view.rowtable("convergence")
    summ = view.summary("convergence")
    gate = view.gate()
    judged = summ.merge(gate[["stepper", "problem", "passed", "reason"]], on=["stepper", "problem"],
                        how="left") if len(gate) else summ.assign(passed=None, reason="")
    cols = [("stepper", "stepper"), ("claimed_order", "claimed"), ("measured_order", "measured"),
            ("order_ci_low", "95% CI low"), ("order_ci_high", "95% CI high"),
            ("fit_points", "fit points"), ("fit_h_min", "fit h min"), ("fit_h_max", "fit h max"),
            ("local_exponent", "local exponent"), ("local_exponent_q", "local exp. (positions)"),
            ("verdict", "verdict"), ("reference_error", "reference error"), ("reason", "message")]
    for problem in [p for p in view.problems if p in set(summ["problem"])]:
        sec.heading(problem)
        g = rows[rows["problem"] == problem] if "problem" in rows else pd.DataFrame()
        ref = judged.loc[judged["problem"] == problem, "reference_error"].astype(float)
        ref_err = float(ref.max()) if len(ref) and np.isfinite(ref).any() else None
        if len(g):
            sec.figure(F.convergence_figure(problem, g, view.palette, ref_err),
                       f"Error against h on {problem}.")
        sec.table(_df_table(judged[judged["problem"] == problem], cols,
                            f"Convergence summary on {problem}", digits=4))
    _skip_note(sec, view, "convergence")
    return sec


# -- 3 stability ------------------------------------------------------------------------------------
def stability(view: RunView) -> Section:
    sec = Section("stability", 3, "Stability")
    sec.intro = ("Linear stability measured from the outside: one step of y' = λy over a grid of "
                 "complex z = hλ (first-order methods) or of x'' = −ω²x (Newtonian methods), "
                 "compared with the formula from the coefficients. Intervals and hω limits are "
                 "root-found, not read off the grid.")
    if _missing(sec, view, "stability"):
        return sec
    rows = view.rowtable("stability")
    summ = view.summary("stability")
    first = rows[rows["kind"] == "grid"] if "kind" in rows else pd.DataFrame()
    if len(first):
        sec.figure(F.stability_overlay_figure(first, view.palette),
                   "Boundaries |R(hλ)| = 1 of all first-order methods, overlaid (stable inside "
                   "the curve that contains a neighbourhood of the negative real axis near 0).")
        sec.figure(F.stability_multiples_figure(first, view.palette),
                   "The stable set |R(hλ)| ≤ 1 of each first-order method (shaded).")
    sec.figure(F.hw_limits_figure(summ, view.palette),
               "Largest stable hω of each Newtonian stepper on the harmonic oscillator; hatched "
               "bars are unbounded within the search limit.")
    s = summ.copy()
    s["analytic_agrees_text"] = s["analytic_agrees"].map(
        lambda v: "—" if v is None or (isinstance(v, float) and math.isnan(v)) else ("yes" if v else "NO"))
    cols = [("stepper", "stepper"), ("form", "form"), ("real_interval", "real interval (probe)"),
            ("analytic_real_interval", "real (formula)"), ("imag_interval", "imag interval (probe)"),
            ("analytic_imag_interval", "imag (formula)"), ("hw_limit", "hω limit (probe)"),
            ("analytic_hw_limit", "hω (formula)"), ("analytic_agrees_text", "probe = formula"),
            ("max_probe_analytic_diff", "max difference"), ("claimed", "claimed"),
            ("verdict", "verdict"), ("message", "message")]
    sec.table(_df_table(s, cols, "Stability intervals: probe against formula (real interval "
                        "[−x, 0], imaginary interval [−y, y])", digits=8))
    _skip_note(sec, view, "stability")
    return sec


# -- 4 reversibility --------------------------------------------------------------------------------
def reversibility(view: RunView) -> Section:
    sec = Section("reversibility", 4, "Reversibility")
    sec.intro = ("N steps forward, time reversed, N steps back: the distance from the start in "
                 "units of rounding (ulps of the state). A symmetric method must stay within what "
                 "rounding explains; a method not claimed symmetric must miss by more.")
    if _missing(sec, view, "reversibility"):
        return sec
    summ = view.summary("reversibility")
    symmetric = {n: bool(i.symmetric) for n, i in view.infos.items()}
    for problem in [p for p in view.problems if p in set(summ["problem"])]:
        g = summ[summ["problem"] == problem]
        sec.figure(F.reversibility_figure(problem, g, view.palette, symmetric),
                   f"Return error against N on {problem}: steppers claimed symmetric solid, "
                   "others dashed; the dotted line is N ulps.")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("steps", "N"), ("h", "h"),
            ("return_error", "return error"), ("return_error_ulps", "ulps"),
            ("rounding_bound_ulps", "rounding bound (ulps)"), ("claimed_symmetric", "claimed symmetric"),
            ("growth_exponent", "growth exponent"), ("verdict", "verdict"), ("message", "message")]
    sec.table(_df_table(summ, cols, "Round trips"))
    _skip_note(sec, view, "reversibility")
    return sec


# -- 5 energy -------------------------------------------------------------------------------------
def energy(view: RunView) -> Section:
    sec = Section("energy", 5, "Energy drift")
    sec.intro = ("Relative energy error against time over long runs (log–log), the same step size "
                 "for every stepper of a problem. Symplectic steppers are drawn solid, the others "
                 "dashed. Lines show the largest error in each of ~300 log-spaced time bins. The "
                 "drift class comes from the growth of the error's running maximum.")
    if _missing(sec, view, "energy"):
        return sec
    rows = view.rowtable("energy")
    summ = view.summary("energy")
    symplectic = {n: bool(i.symplectic) for n, i in view.infos.items()}
    for problem in [p for p in view.problems if p in set(summ["problem"])]:
        g = rows[rows["problem"] == problem]
        sec.figure(F.energy_figure(problem, g, view.palette, symplectic),
                   f"Relative energy error on {problem}.")
        if (g["quantity"] == "angular_momentum").any():
            sec.figure(F.angular_momentum_figure(problem, g, view.palette, symplectic),
                       f"Relative change of the angular momentum on {problem}, with the rounding "
                       f"bound of a method that conserves it exactly "
                       f"({tol.ANGULAR_MOMENTUM_ROUNDING_ULPS:g} ulp per step).")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("h", "h"), ("steps", "steps"),
            ("claimed_symplectic", "claimed symplectic"), ("drift_class", "drift class"),
            ("drift_exponent", "growth exponent"), ("drift_slope", "drift slope (per unit t)"),
            ("max_rel_energy_error", "max rel. energy error"), ("expected_class", "expected"),
            ("max_rel_angular_momentum_error", "max rel. L error"),
            ("angular_momentum_conserved", "L conserved"), ("verdict", "verdict"),
            ("message", "message")]
    sec.table(_df_table(summ, cols, "Drift classes"))
    _skip_note(sec, view, "energy")
    return sec


# -- 6 work-precision -------------------------------------------------------------------------------
def work_precision(view: RunView) -> Section:
    sec = Section("work-precision", 6, "Work–precision")
    sec.intro = ("Error at the final time against the work spent: right-hand-side (or force) "
                 "evaluations and wall time, for fixed-step steppers (step-size sweep) and "
                 "adaptive peers (heyoka's Taylor integrator, scipy's solvers; tolerance sweep, "
                 "dashed with hollow markers).")
    name = "work-precision"
    if _missing(sec, view, name):
        return sec
    rows = view.rowtable(name)
    summ = view.summary(name)
    adaptive = {n: bool(i.adaptive) for n, i in view.infos.items()}
    err_col = "error" if "error" in rows else None
    if err_col is None:
        sec.note("The work-precision rows have no `error` column; nothing to draw.", cls="warning")
    else:
        for problem in [p for p in view.problems if p in set(rows.get("problem", []))]:
            g = rows[rows["problem"] == problem]
            sec.figure(F.work_precision_figure(problem, g, view.palette, adaptive, "evals"),
                       f"Error against evaluations on {problem}.")
            if "wall_s" in g:
                sec.figure(F.work_precision_figure(problem, g, view.palette, adaptive, "wall_s"),
                           f"Error against wall time on {problem}: one trajectory, compile time "
                           "excluded; wall times depend on this machine and its load during the "
                           "run (see Provenance).")
    if len(summ) and {"stepper", "problem", "error"} <= set(summ.columns):
        sec.table(_df_table(_work_table(summ), [
            ("stepper", "stepper"), ("problem", "problem"), ("kind", "sweep"),
            ("points", "points"), ("lowest_error", "lowest error"),
            ("evals_at_lowest", "evaluations there"), ("evals_to_target", f"evaluations to reach "
                                                     f"{WORK_TARGET_ERROR:g}"),
            ("wall_to_target", f"wall s to reach {WORK_TARGET_ERROR:g}"),
            ("pareto", "points on the evaluations Pareto front"), ("unit", "evaluation unit")],
            "Work–precision summary per stepper and problem (all points are in the results "
            "tables)", status=None, sort_failing=False))
    _skip_note(sec, view, name)
    return sec


# A precision every method of the catalogue reaches on the work-precision problems; the table
# says what reaching it costs.
WORK_TARGET_ERROR = 1e-6


def _work_table(summ: pd.DataFrame) -> pd.DataFrame:
    out = []
    for (stepper, problem), g in summ.groupby(["stepper", "problem"], sort=False):
        err = g["error"].astype(float)
        evals = g["rhs_evals"].astype(float) if "rhs_evals" in g else pd.Series(np.nan, index=g.index)
        wall = g["wall_s"].astype(float) if "wall_s" in g else pd.Series(np.nan, index=g.index)
        finite = np.isfinite(err)
        rec = {"stepper": stepper, "problem": problem,
               "kind": str(g["kind"].iloc[0]) if "kind" in g else "",
               "points": int(len(g)), "lowest_error": math.nan, "evals_at_lowest": math.nan,
               "evals_to_target": math.nan, "wall_to_target": math.nan,
               "pareto": int(g["pareto_evals"].astype(bool).sum()) if "pareto_evals" in g else None,
               "unit": str(g["evals_unit"].iloc[0]) if "evals_unit" in g else ""}
        if finite.any():
            k = err[finite].idxmin()
            rec.update(lowest_error=float(err[k]), evals_at_lowest=float(evals[k]))
            hit = g[finite & (err <= WORK_TARGET_ERROR)]
            if len(hit):
                j = evals[hit.index].idxmin()
                rec.update(evals_to_target=float(evals[j]), wall_to_target=float(wall[j]))
        out.append(rec)
    return pd.DataFrame(out)


# -- 7 ground truth -------------------------------------------------------------------------------
def ground_truth(view: RunView) -> Section:
    """Per problem: the reference used by the convergence cells (the same call, so the disk cache
    answers), its precision and certified error, and its difference from the exact solution."""
    from harness.ground_truth import reference
    from harness.registry import get_problem

    sec = Section("ground-truth", 7, "Ground truth")
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
                exact = problem.exact(T, y0, problem.t0, problem.pars_for(y0.shape[1]))
                diff = float(np.max(np.abs(np.asarray(exact) - ref.y[-1])))
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
    sec.table(_df_table(df, cols, "References used by the convergence experiment", digits=3))
    sec.note(f"Allowed difference: the certified error plus {tol.GROUND_TRUTH_EXACT_ULPS:g} ulps "
             "of the state for the float64 evaluation of the exact formula.")
    return sec


# -- 8 claims -------------------------------------------------------------------------------------
def claims(view: RunView) -> Section:
    sec = Section("claims", 8, "Claims from the course material, checked")
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
                         TextCell(src, cls="source"), TextCell(r.measurement)], cls=f"claim {cls}"))
    sec.table(Table("Claims and measurements", ["verdict", "claim (paraphrased)", "source",
                                                "measurement"], rows, cls="claims"))
    for r in results:
        if r.values:
            cols = list(r.values[0].keys())
            sec.table(Table(f"{r.key}: measured values", cols,
                            [Row([TextCell(str(v.get(c, ""))) for c in cols]) for v in r.values]))
    ro = view.rowtable("roundoff")
    if len(ro):
        sec.figure(F.roundoff_figure(ro, view.palette),
                   "Roundoff experiment: relative position error after a fixed number of steps "
                   "as h shrinks. The truncation error falls like h³ at fixed N (dotted); below it "
                   "only rounding is left, and the two-step Verlet form keeps far more of it.")
    return sec


# -- 9 provenance ---------------------------------------------------------------------------------
def provenance(view: RunView, *, run_id: str, results_path: str, timer: SectionTimer,
               build_s: Mapping[str, float]) -> Section:
    sec = Section("provenance", 9, "Provenance")
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
        exp_rows.append(Row([TextCell(name), _cell(e.get("wall_s"), 3), _cell(e.get("n_cells")),
                             _cell(e.get("computed_cells")), _cell(e.get("cached_cells")),
                             _cell(e.get("failed_cells")), _cell(len(e.get("skips", [])))]))
    totals = meta.get("totals", {})
    exp_rows.append(Row([TextCell("total", cls="key"), _cell(totals.get("wall_s"), 3),
                         _cell(totals.get("cells")), _cell(totals.get("computed")),
                         _cell(totals.get("cached")), _cell(totals.get("failed")),
                         _cell(totals.get("skipped"))], cls="total"))
    sec.table(Table("Time per experiment (wall seconds of this run; cached cells cost only their "
                    "loading)", ["experiment", "wall s", "cells", "computed", "from cache",
                                 "failed", "not applicable"], exp_rows))
    build_rows = [Row([TextCell(k), _cell(v, 3)]) for k, v in build_s.items()]
    build_rows += [Row([TextCell(f"section: {k}"), _cell(v, 3)]) for k, v in timer.seconds.items()]
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
                sec.blocks.append(Block("details", summary=f"traceback: {f.get('cell', '')}",
                                        text=str(f["traceback"])))
    else:
        sec.note("No cell failed.")
    sec.blocks.append(Block("details", summary="full configuration (JSON)",
                            text=json.dumps(meta.get("config", {}), indent=2, sort_keys=True)))
    return sec


# -- 10 performance history -----------------------------------------------------------------------
def performance_history() -> Section:
    sec = Section("performance-history", 10, "Performance history")
    sec.intro = ("Speed and tracked accuracy over commits, from asv's result files "
                 "(drawn here because asv's own dashboard loads its scripts from the internet).")
    try:
        from harness import perf_history  # type: ignore[attr-defined]
    except ImportError:
        sec.note("No asv results yet (run `make nightly`).")
        return sec
    from harness.provenance import PROJECT_ROOT

    try:
        history = perf_history.load_history(PROJECT_ROOT / ".asv" / "results")
    except Exception as exc:
        sec.note(f"The asv results could not be read: {type(exc).__name__}: {exc}", cls="warning")
        return sec
    if history is None or len(history) == 0:
        sec.note("No asv results yet (run `make nightly`).")
        return sec
    sec.figure(F.perf_history_figure(history),
               "Benchmark values against commit date (one panel per benchmark, one line per "
               "parameter set; at most 12 panels).")
    latest = history.sort_values("date").groupby(["benchmark", "params"], sort=False).tail(1)
    rows = [Row([TextCell(str(r["benchmark"])), TextCell(str(r["params"])), _cell(r["value"], 4),
                 TextCell(str(r["unit"])), TextCell(str(r["commit"])[:10]), TextCell(str(r["date"]))])
            for r in latest.head(200).to_dict("records")]
    sec.table(Table("Latest value of each benchmark", ["benchmark", "params", "value", "unit",
                                                        "commit", "date"], rows))
    return sec


# -- all ----------------------------------------------------------------------------------------
def build_sections(view: RunView, *, run_id: str, results_path: str,
                   build_s: Mapping[str, float], progress: Callable[[str], None] | None = None
                   ) -> tuple[list[Section], dict[str, str]]:
    """Every section in order, and each stepper's scoreboard status."""
    timer = SectionTimer()
    say = progress or (lambda _msg: None)
    out: list[Section] = []
    say("scoreboard")
    sb, statuses = timer.run("scoreboard", lambda: scoreboard(view))
    out.append(sb)
    for name, fn in (("convergence", convergence), ("stability", stability),
                     ("reversibility", reversibility), ("energy", energy),
                     ("work-precision", work_precision), ("ground-truth", ground_truth),
                     ("claims", claims)):
        say(name)
        out.append(timer.run(name, lambda fn=fn, name=name: _guarded(fn, view, name)))
    say("performance history")
    perf = timer.run("performance-history", performance_history)
    out.append(provenance(view, run_id=run_id, results_path=results_path, timer=timer,
                          build_s=build_s))
    out.append(perf)
    return out, statuses


def _guarded(fn: Callable[[RunView], Section], view: RunView, name: str) -> Section:
    """A section whose building fails still appears, with the error, so the report is written."""
    try:
        return fn(view)
    except Exception as exc:
        import traceback

        number, title = next((i + 1, t) for i, (k, t) in enumerate(SECTION_TITLES) if k == name)
        sec = Section(name, number, title)
        sec.note(f"This section could not be built: {type(exc).__name__}: {exc}", cls="warning")
        sec.blocks.append(Block("details", summary="traceback", text=traceback.format_exc(limit=-6)))
        return sec
