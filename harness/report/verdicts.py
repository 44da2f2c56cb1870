"""Every judged claim of a run as one table: what the first screen counts and the changed-since
comparison follows.

One row per judged row of an experiment's summary (its `passed` column, or the section's own
`verdicts` function, e.g. the gate for convergence) and per claim of the course material that
was measured. Columns: experiment, stepper, problem, key (the row's identity, JSON), passed,
verdict, sentence (why, one sentence), anchor (id of the row in its section's table), judged
(the row judges a claim: it can fail; a row with no claim behind it, or one that could not be
measured, passes without evidence and is informational, so the headline does not count it).
"""

from __future__ import annotations

import json
from typing import Any

import pandas as pd

from harness.report.sections import (
    RunView,
    anchor,
    experiment_key,
    first_sentence,
    is_missing,
    section_spec,
)

__all__ = ["VERDICT_COLUMNS", "collect_verdicts", "summary_verdicts", "claim_verdicts"]

VERDICT_COLUMNS = ["experiment", "stepper", "problem", "key", "passed", "verdict", "sentence", "anchor",
                   "judged"]

# Verdicts that pass without judging a claim: no theorem or claim behind the cell (`no-claim`,
# a stability figure with neither a formula nor a declared claim, `measured`), or a cell the run
# could not measure (`not-measurable`); the gate says it in its `outcome` column instead.
INFORMATIONAL_VERDICTS = frozenset({"no-claim", "not-measurable", "measured"})
JUDGED_OUTCOMES = frozenset({"pass", "fail"})


def _judges_a_claim(rec: dict, verdict: str) -> bool:
    outcome = rec.get("outcome")
    if isinstance(outcome, str) and outcome:
        return outcome in JUDGED_OUTCOMES
    return verdict not in INFORMATIONAL_VERDICTS


def _key_text(values: list[Any]) -> str:
    return json.dumps([v if isinstance(v, str | int) else (None if is_missing(v) else float(v))
                       for v in values])


def summary_verdicts(name: str, table: pd.DataFrame, key: tuple[str, ...],
                     reason: str = "message", anchor_key: tuple[str, ...] | None = None) -> pd.DataFrame:
    """The judged rows of one summary table (rows whose `passed` is missing are not judged);
    each links to the table row identified by `anchor_key` (default `key`)."""
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
                    "problem": str(rec.get("problem", "")), "key": _key_text(values),
                    "passed": bool(passed), "verdict": verdict, "sentence": sentence,
                    "anchor": anchor(name, *(values if anchor_key is None
                                             else [rec.get(c, "") for c in anchor_key])),
                    "judged": bool(not passed or _judges_a_claim(rec, verdict))})
    return pd.DataFrame(out, columns=VERDICT_COLUMNS)


def claim_verdicts(view: RunView) -> pd.DataFrame:
    """The course material's claims that this run measured (agree = passed)."""
    from harness.report.claims import AGREE, DISAGREE, check_claims

    out = []
    for r in check_claims(dict(view.summaries)):
        if r.status not in (AGREE, DISAGREE):
            continue
        out.append({"experiment": "claims", "stepper": "", "problem": "", "key": _key_text([r.key]),
                    "passed": r.status == AGREE, "verdict": r.status,
                    "sentence": f"course claim “{first_sentence(r.claim, 140)}” — {r.status}: "
                                f"{first_sentence(r.measurement)}",
                    "anchor": anchor("claims", r.key), "judged": True})
    return pd.DataFrame(out, columns=VERDICT_COLUMNS)


def collect_verdicts(view: RunView) -> pd.DataFrame:
    """Every judged claim of the run, failing first, in section order."""
    frames = []
    for name in view.meta.get("experiments", {}):
        if not view.has(name):
            continue
        spec = section_spec(name)
        if spec.verdicts is not None:
            frames.append(spec.verdicts(view))
        else:
            frames.append(summary_verdicts(name, view.summary(name),
                                           experiment_key(name, view.summary(name)),
                                           anchor_key=spec.row_key))
    frames.append(claim_verdicts(view))
    frames = [f for f in frames if len(f)]
    if not frames:
        return pd.DataFrame(columns=VERDICT_COLUMNS)
    table = pd.concat(frames, ignore_index=True)
    table["passed"] = table["passed"].astype(bool)
    table["judged"] = table["judged"].astype(bool)
    return table.sort_values("passed", kind="stable").reset_index(drop=True)
