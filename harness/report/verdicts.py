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

import pandas as pd

from harness.kit import VERDICT_COLUMNS, RunView, anchor, first_sentence, summary_verdicts
from harness.kit.section import key_text
from harness.report.claims import AGREE, DISAGREE, check_claims
from harness.report.specs import experiment_key, section_spec

__all__ = ["VERDICT_COLUMNS", "collect_verdicts", "summary_verdicts", "claim_verdicts"]


def claim_verdicts(view: RunView) -> pd.DataFrame:
    """The course material's claims that this run measured (agree = passed).

    Parameters
    ----------
    view : RunView, the run (its summaries).

    Returns
    -------
    DataFrame: one judged row per claim that agreed or disagreed.
    """
    out = []
    for r in check_claims(dict(view.summaries)):
        if r.status not in (AGREE, DISAGREE):
            continue
        out.append({"experiment": "claims", "stepper": "", "problem": "", "key": key_text([r.key]),
                    "passed": r.status == AGREE, "verdict": r.status,
                    "sentence": f"course claim “{first_sentence(r.claim, 140)}” — {r.status}: "
                                f"{first_sentence(r.measurement)}",
                    "anchor": anchor("claims", r.key), "judged": True})
    return pd.DataFrame(out, columns=VERDICT_COLUMNS)


def collect_verdicts(view: RunView) -> pd.DataFrame:
    """Every judged claim of the run, failing first, in section order.

    Parameters
    ----------
    view : RunView, the run.

    Returns
    -------
    DataFrame: one row per verdict (experiment, stepper, problem, key, passed, verdict, sentence,
        anchor, judged).
    """
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
