"""What an experiment's report section is: its spec (title, intro, builder, keys, the figures
followed across runs, scoreboard columns), the generic table section, and the judged rows of a
summary table.

Contract of a section (an experiment names it as its `section` attribute, a `SectionSpec`):
1. `build(view, section)` adds figures and tables to the given `Section`, reading only the
   `RunView`; it never measures.
2. `intro` is two sentences: what is measured and how to read it.
3. `key` names the summary columns that identify one judged row; every verdict links to the row
   of the section's table holding it (`row_key` when the table folds several judged rows).
4. `verdicts(view)`, when given, replaces the summary's own `passed` column as the judged rows.
An experiment without a section gets `generic_section`: its summary as one table.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import pandas as pd

from harness.kit.elements import HIDDEN_COLUMNS, Section, anchor, df_table, first_sentence, is_missing, yes_no
from harness.kit.view import RunView

__all__ = ["Measure", "ScoreColumn", "SectionSpec", "generic_spec", "generic_section", "generic_key",
           "missing", "skip_note", "summary_verdicts", "key_text", "claimed_measured", "VERDICT_COLUMNS"]

VERDICT_COLUMNS = ["experiment", "stepper", "problem", "key", "passed", "verdict", "sentence", "anchor",
                   "judged"]

# Verdicts that pass without judging a claim (`judged` False): no theorem or claim behind the
# cell (`no-claim`; a stability figure with neither a formula nor a declared claim, `measured`),
# or a cell the run could not measure (`not-measurable`); the gate says it in its `outcome`.
INFORMATIONAL_VERDICTS = frozenset({"no-claim", "not-measurable", "measured"})
JUDGED_OUTCOMES = frozenset({"pass", "fail"})


def _judges_a_claim(rec: dict, verdict: str) -> bool:
    outcome = rec.get("outcome")
    if isinstance(outcome, str) and outcome:
        return outcome in JUDGED_OUTCOMES
    return verdict not in INFORMATIONAL_VERDICTS


@dataclass(frozen=True)
class Measure:
    """A measured figure of an experiment's summary that the changed-since comparison follows:
    its column, how to name it, and its confidence interval (two columns), or else the relative
    change (`rtol`) or the factor (`factor`) beyond which it counts as moved."""

    column: str
    label: str
    ci: tuple[str, str] | None = None
    rtol: float | None = None
    factor: float | None = None


@dataclass(frozen=True)
class ScoreColumn:
    """A scoreboard column an experiment contributes: its header, and per stepper the cell as
    (text, anchor) parts (each number linked to the row it comes from, "" for plain text) and
    whether anything was measured."""

    header: str
    value: Callable[[RunView, str], tuple[list[tuple[str, str]], bool]]


@dataclass(frozen=True)
class SectionSpec:
    """How an experiment's section is built (see the module docstring): `experiment` its name,
    `title`, `intro`, `build(view, section)`; `key` the summary columns that identify one judged
    row; `measures` the figures the changed-since comparison follows; `verdicts(view)` overrides
    the judged rows (default: the summary's `passed` column); `score` the scoreboard columns this
    experiment fills; `row_key` the columns that identify a row of the section's table when it
    folds several judged rows into one (default: `key`)."""

    experiment: str
    title: str
    intro: str
    build: Callable[[RunView, Section], None]
    key: tuple[str, ...] = ("stepper", "problem")
    measures: tuple[Measure, ...] = ()
    verdicts: Callable[[RunView], pd.DataFrame] | None = None
    score: tuple[ScoreColumn, ...] = ()
    row_key: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        for name in ("key", "measures", "score", "row_key"):  # lists given are kept as tuples
            value = getattr(self, name)
            if value is not None and not isinstance(value, tuple):
                object.__setattr__(self, name, tuple(value))

    @property
    def anchor_key(self) -> tuple[str, ...]:
        return self.row_key or self.key


def generic_spec(experiment: str, description: str = "") -> SectionSpec:
    """The section of an experiment that names none: its summary as one table, introduced by
    the experiment's own description."""
    intro = (f"{description.rstrip('.') or 'The ' + experiment + ' experiment'}. One row per cell "
             "of the experiment; the first column is its verdict against the stepper's claim.")
    return SectionSpec(experiment, experiment.replace("-", " ").capitalize(), intro, generic_section)


def generic_section(view: RunView, sec: Section) -> None:
    """The fallback: the experiment's summary as one folded table, every column."""
    name = sec.id
    summ = view.summary(name)
    key = generic_key(summ)
    cols = [(c, c.replace("_", " ")) for c in summ.columns if c not in ("passed", *HIDDEN_COLUMNS)]
    sec.table(df_table(summ, cols, f"{name}: one row per cell", experiment=name, key=key,
                       status="passed" if "passed" in summ else None))


def generic_key(summ: pd.DataFrame) -> tuple[str, ...]:
    """The columns that identify a row of a summary no section describes: stepper and problem,
    then the first of steps, kind, quantity, h, tol that makes them unique."""
    key = [c for c in ("stepper", "problem") if c in summ]
    for extra in ("steps", "kind", "quantity", "h", "tol"):
        if key and len(summ) and summ.duplicated(key).any() and extra in summ:
            key.append(extra)
    return tuple(key)


def missing(sec: Section, view: RunView, name: str) -> bool:
    """Add a note and return True when experiment `name` has no results in this run."""
    if not view.has(name):
        sec.note(f"The {name} experiment is not part of this run, so this section has no "
                 "measurements.", cls="warning")
        return True
    fails = view.failures(name)
    if view.summary(name).empty:
        why = f" All {len(fails)} of its cells failed (see Provenance)." if fails else ""
        sec.note(f"The {name} experiment produced no results for this selection.{why}", cls="warning")
        return True
    if fails:
        sec.note(f"{len(fails)} cell(s) of the {name} experiment failed and are missing here; "
                 "they are listed with their messages under Provenance.", cls="warning")
    return False


def skip_note(sec: Section, view: RunView, name: str) -> None:
    """Fold the pairs experiment `name` did not apply to, counted by reason, into `sec`."""
    skips = view.skips(name)
    if skips:
        reasons: dict[str, int] = {}
        for s in skips:
            reasons[s.get("reason", "")] = reasons.get(s.get("reason", ""), 0) + 1
        sec.details(f"{len(skips)} pairs not applicable to the {name} experiment, and why",
                    "\n".join(f"{n} × {r}" for r, n in sorted(reasons.items(), key=lambda kv: -kv[1])))


def key_text(values: list[Any]) -> str:
    """The identity of a judged row as JSON text: its key values, numbers as floats."""
    return json.dumps([v if isinstance(v, str | int) else (None if is_missing(v) else float(v))
                       for v in values])


def summary_verdicts(name: str, table: pd.DataFrame, key: tuple[str, ...],
                     reason: str = "message", anchor_key: tuple[str, ...] | None = None) -> pd.DataFrame:
    """The judged rows of one summary table.

    Parameters
    ----------
    name : the experiment's name.
    table : its summary; rows whose `passed` is missing are not judged.
    key : the columns that identify a judged row.
    reason : the column whose first sentence says why.
    anchor_key : the columns identifying the table row each verdict links to (default `key`).

    Returns
    -------
    DataFrame with `VERDICT_COLUMNS`, one row per judged row; `judged` says whether the row
    judges a claim (a failing row always does; a passing `no-claim` or `not-measurable` row is
    informational, and the report's headline does not count it).
    """
    out = []
    if table.empty or "passed" not in table:
        return pd.DataFrame(columns=VERDICT_COLUMNS)
    for rec in table.to_dict("records"):
        passed = rec.get("passed")
        if is_missing(passed):
            continue
        values = [rec.get(c, "") for c in key]
        verdict = str(rec.get("verdict") or ("pass" if passed else "fail"))
        why = first_sentence(rec.get(reason)) if not is_missing(rec.get(reason)) else ""
        if why.startswith(f"verdict {verdict}"):  # the reason only repeats the verdict
            why = why[len(f"verdict {verdict}"):].lstrip(":; ")
        if not why and not passed and rec.get("expected") and str(rec.get("expected")) != verdict:
            why = f"the claim needs {rec.get('expected')}"
        where = " on ".join(x for x in (str(rec.get("stepper", "")), str(rec.get("problem", ""))) if x)
        extra = ", ".join(f"{c}={rec.get(c)}" for c in key if c not in ("stepper", "problem"))
        sentence = (f"{name}: {where}{f' ({extra})' if extra else ''} — {verdict}"
                    + (f": {why}" if why else "."))
        out.append({"experiment": name, "stepper": str(rec.get("stepper", "")),
                    "problem": str(rec.get("problem", "")), "key": key_text(values),
                    "passed": bool(passed), "verdict": verdict, "sentence": sentence,
                    "anchor": anchor(name, *(values if anchor_key is None
                                             else [rec.get(c, "") for c in anchor_key])),
                    "judged": bool(not passed or _judges_a_claim(rec, verdict))})
    return pd.DataFrame(out, columns=VERDICT_COLUMNS)


def claimed_measured(view: RunView, name: str, stepper: str, claimed: bool,
                      within: Iterable[tuple[bool, str]]) -> tuple[list[tuple[str, str]], bool]:
    """'claimed / measured' with the measured part linked to a row that shows it."""
    w = list(within)
    if not w:
        return [(f"{yes_no(claimed)} / —", "")], False
    n = sum(1 for ok, _ in w if ok)
    measured = "yes" if n == len(w) else ("no" if n == 0 else f"mixed ({n}/{len(w)} yes)")
    witness = next((a for ok, a in w if ok != claimed), w[0][1])  # a row against the claim, if any
    return [(f"{yes_no(claimed)} / ", ""), (measured, "#" + witness)], True
