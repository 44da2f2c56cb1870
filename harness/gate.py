"""The CI gate: every stepper's measured convergence against what its facts predict.

A cell (stepper x problem) is judged by `harness.rules` from the method's facts (coefficients,
or the claims of a black box) and the problem's facts (its symbolic definition): it passes when
the verdict and order match the expectation, fails when they contradict it, and is
`not-measurable` (reported with the limit that stopped it, neither pass nor fail) for a
tolerated verdict. A slope above the expected order of a Runge-Kutta method is `not-measurable`
when the predicted leading error term (`harness.prediction`) is too small to show in the fitted
points, and stays a failure otherwise. Every cell whose expected verdict is an h^p law of a
Runge-Kutta tableau carries that predicted leading error constant C (err ~ C h^p at the final
time) beside the measured one (the error at the smallest fitted step over h^p); every other cell
says in `prediction_note` why none is given (no tableau, an adaptive or exact cell, a stiff order
range, a problem too large for symbolic differentials). The constant is information, never a
verdict: only the slope is judged. Besides the cells, a stepper fails when
- the order computed from its coefficients differs from its claimed order, or its claimed
  symmetry or symplecticity contradicts what its coefficients say (a mislabelled table fails even
  if a measurement happens to look right);
- none of its cells measured the claim and none contradicted it (a stepper judged on nothing
  does not pass): a row of its own, problem `(any)`, outcome `not-verified` (not `fail`: on
  other problems the claim may well hold), which the CLI reports with its own exit status.
A map that declares an error law in the perturbation (eps^a h^b terms) on an N-body problem is
judged by `harness.perturbation_law` from that law and the problem's masses instead.
No stepper is named here: the same coefficients get the same verdicts under any name.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.coefficients import ButcherTableau
from harness.facts import MethodFacts, method_facts, problem_facts
from harness.perturbation_law import judge_split_map
from harness.prediction import explain_slope, predicted_error
from harness.registry import get_problem, get_stepper
from harness.rules import convergence_expectation, judge_convergence

__all__ = ["judge", "gate_table", "stiff_span_flag", "claim_contradictions", "GATE_COLUMNS", "NOT_VERIFIED"]

# The outcome of a stepper's `(any)` row when no cell measured its claim.
NOT_VERIFIED = "not-verified"

GATE_COLUMNS = [
    "stepper", "problem", "claimed_order", "coefficient_order", "measured_order",
    "order_ci_low", "order_ci_high", "fit_points", "fit_h_min", "fit_h_max", "t_end", "verdict",
    "expected", "expected_order", "predicted_coefficient", "measured_coefficient",
    "prediction_note", "outcome", "passed", "reason",
]


def claim_contradictions(stepper) -> list[str]:
    """Declared claims that the stepper's coefficients contradict (empty for a black box).

    Parameters
    ----------
    stepper : Stepper, with its declared `info` and, when it has one, its coefficient object.

    Returns
    -------
    list of str: one sentence per contradicted claim (order, symmetry, symplecticity).
    """
    facts = method_facts(stepper)
    if facts.source != "coefficients":
        return []
    info = stepper.info
    out = []
    if info.claimed_order is not None and facts.order != info.claimed_order:
        out.append(f"coefficients give order {facts.order}, the stepper claims {info.claimed_order}")
    for prop in ("symmetric", "symplectic"):
        derived = getattr(stepper.coefficients, prop, None)
        claimed = bool(getattr(info, prop))
        if derived is not None and bool(derived) != claimed:
            out.append(f"claims {'' if claimed else 'not '}{prop}, its coefficients say "
                       f"{'it is' if derived else 'it is not'}")
    return out


def judge(record: Mapping, facts: MethodFacts | None = None,
          problem=None) -> tuple[str, str, str, float | None]:
    """(outcome, expected verdict, reason, expected order) for one convergence summary record.

    Parameters
    ----------
    record : mapping, the record (its `stepper` and `problem` names are looked up in the
    registry); facts : MethodFacts or None, the stepper's facts (derived when None);
    problem : Problem or None, the problem run (looked up when None).

    Returns
    -------
    tuple: (outcome, expected verdict, reason, expected order or None).
    """
    return _judge(record, facts, problem)[:4]


def _judge(record: Mapping, facts: MethodFacts | None = None,
           problem=None) -> tuple[str, str, str, float | None, float, str]:
    """`judge`, the predicted leading error coefficient and why none is given (NaN and a sentence
    where the theory does not apply)."""
    stepper = get_stepper(record["stepper"])
    facts = facts or method_facts(stepper)
    problem = problem if problem is not None else get_problem(record["problem"])
    split = judge_split_map(record, stepper, problem)  # a declared error law in eps h^p
    if split is not None:
        return (*split, np.nan, "not predicted: judged by its declared error law in the perturbation")
    pfacts = problem_facts(problem)
    expectation = convergence_expectation(facts, pfacts)
    outcome, reason = judge_convergence(dict(record), expectation)
    if outcome == "fail" and _slope_above(record, expectation):
        outcome, reason, predicted = _explain_slope(record, stepper, problem, expectation, reason)
        note = "" if np.isfinite(predicted) else _leading_term(stepper, problem, expectation)[1]
    else:
        predicted, note = _leading_term(stepper, problem, expectation)
    flag = stiff_span_flag(pfacts.stiffness, problem.t0, problem.t_end, record.get("t_end"))
    return (outcome, expectation.verdict, "; ".join(x for x in (reason, flag) if x), expectation.order,
            predicted, note)


def stiff_span_flag(stiffness: float, t0: float, t_end: float, measured_end) -> str:
    """The flag of a problem stiff over its declared span (stiffness x span above STIFF_STEP_COUNT:
    an explicit step of stability interval ~1 needs that many steps) whose measured span is not:
    its points test nothing stiff. '' when the flag does not apply.

    Parameters
    ----------
    stiffness : float
        The largest -Re(lambda) along the reference (`ProblemFacts.stiffness`).
    t0, t_end : float
        The problem's declared span.
    measured_end : float or None
        The end of the span the cell measured (its summary's `t_end`).

    Returns
    -------
    str
        The flag with its numbers, or ''.
    """
    try:
        T = float(measured_end)
    except (TypeError, ValueError):
        return ""
    if not (np.isfinite(T) and np.isfinite(stiffness) and stiffness > 0):
        return ""
    span, measured = stiffness * (t_end - t0), stiffness * (T - t0)
    if span <= tol.STIFF_STEP_COUNT or measured > tol.STIFF_STEP_COUNT:
        return ""
    return (f"stiff problem not stiff over the measured span: -Re(lambda) x span = {measured:.3g} "
            f"over t <= {T:.6g} (at most {tol.STIFF_STEP_COUNT:g}), {span:.3g} over the declared "
            f"span to {t_end:.6g}")


def _leading_term(stepper, problem, expectation) -> tuple[float, str]:
    """(C, '') of the predicted leading global error C h^p (`harness.prediction`) where its
    theorem applies (HNW I, II.8, Theorem 8.1: a Runge-Kutta tableau, a fixed step, the
    non-stiff h^p law expected), else (NaN, why not)."""
    coeffs = getattr(stepper, "coefficients", None)
    if not isinstance(coeffs, ButcherTableau):
        kind = type(coeffs).__name__ if coeffs is not None else "a black box without coefficients"
        return np.nan, (f"not predicted: the leading term is derived from a Runge-Kutta tableau's "
                        f"B-series (HNW I, II.8); this method is {kind}")
    if expectation.verdict != "converged" or expectation.order is None:
        return np.nan, f"not predicted: the expected verdict is {expectation.verdict}, not an h^p law"
    if expectation.order_low is not None:
        return np.nan, ("not predicted: stiff over the horizon, the non-stiff h^p expansion's "
                        "constant does not describe the fitted steps (any order in "
                        f"[{expectation.order_low:g}, {expectation.order:g}] is expected)")
    try:
        prediction = predicted_error(coeffs, problem, int(expectation.order), next_term=False,
                                     max_work=tol.PREDICTION_ROUTINE_MAX_WORK)
    except Exception as exc:  # a definition heyoka cannot differentiate or integrate
        return np.nan, f"not predicted ({type(exc).__name__}: {exc})"[:500]
    return float(prediction["coefficient"]), prediction["why"]


def _measured_coefficient(record: Mapping, order: float | None) -> float:
    """The measured error constant: the smallest fitted error (at the smallest fitted step, where
    the asymptotic law holds best among the fitted points) over that step^p; NaN without a fit
    or an order."""
    if record.get("verdict") != "converged" or order is None:
        return np.nan
    h, err = float(record.get("fit_h_min", np.nan)), float(record.get("fit_error_min", np.nan))
    return err / h**order if np.isfinite(h) and np.isfinite(err) and h > 0 else np.nan


def _slope_above(record: Mapping, expectation) -> bool:
    measured = float(record.get("measured_order", np.nan))
    return (record.get("verdict") == "converged" and expectation.order is not None
            and expectation.order_low is None and np.isfinite(measured)
            and measured > expectation.order + tol.GATE_ORDER_TOL)


def _explain_slope(record: Mapping, stepper, problem, expectation, reason: str
                   ) -> tuple[str, str, float]:
    """A slope above the expected order of a Runge-Kutta method: the predicted leading error
    term (`harness.prediction`) says whether the fitted points could show the order at all.
    Explained (a tiny or cancelling leading term) is `not-measurable`, otherwise the fail
    stands with the prediction's numbers. Returns (outcome, reason, predicted C)."""
    coeffs = getattr(stepper, "coefficients", None)
    if not isinstance(coeffs, ButcherTableau):
        return "fail", reason, np.nan
    try:
        prediction = predicted_error(coeffs, problem, int(expectation.order))
    except Exception as exc:  # a definition heyoka cannot differentiate or integrate: no verdict change
        return "fail", f"{reason}; no predicted error ({type(exc).__name__}: {exc})"[:2000], np.nan
    explained, why = explain_slope(
        float(record["measured_order"]), expectation.order, prediction,
        (float(record["fit_h_min"]), float(record["fit_h_max"])),
        (float(record["fit_error_min"]), float(record["fit_error_max"])))
    C = float(prediction["coefficient"])
    return ("not-measurable", why, C) if explained else ("fail", f"{reason}; {why}", C)


def gate_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Judge every convergence summary record; failing rows first. A stepper whose claims its
    coefficients contradict fails on every row; one with neither a passing nor a failing row
    gets a row of its own (problem `(any)`, outcome `not-verified`, not passed).

    Parameters
    ----------
    summary : pandas.DataFrame
        The convergence experiment's summary.

    Returns
    -------
    pandas.DataFrame
        One row per cell and per unverified stepper, columns GATE_COLUMNS.
    """
    rows = []
    per_stepper: dict[str, tuple[MethodFacts, list[str]]] = {}
    for rec in summary.to_dict("records"):
        name = rec["stepper"]
        if name not in per_stepper:
            stepper = get_stepper(name)
            per_stepper[name] = (method_facts(stepper), claim_contradictions(stepper))
        facts, contradictions = per_stepper[name]
        outcome, expected, why, expected_order, predicted, note = _judge(rec, facts)
        if contradictions:
            outcome, why = "fail", "; ".join(contradictions)
        row = {k: rec.get(k) for k in GATE_COLUMNS if k in rec}
        row.update({
            "coefficient_order": facts.order if facts.source == "coefficients" else None,
            "expected": expected, "expected_order": expected_order, "outcome": outcome,
            "predicted_coefficient": predicted, "prediction_note": note,
            "measured_coefficient": _measured_coefficient(rec, expected_order),
            "passed": outcome != "fail", "reason": why,
        })
        rows.append(row)
    table = pd.DataFrame(rows, columns=GATE_COLUMNS)
    for name, (facts, _) in per_stepper.items():
        mine = table[table.stepper == name]
        if not mine.outcome.isin(["pass", "fail"]).any():  # nothing verified, nothing contradicted
            table.loc[len(table)] = {
                "stepper": name, "problem": "(any)", "claimed_order": mine.claimed_order.iloc[0],
                "coefficient_order": facts.order if facts.source == "coefficients" else None,
                "measured_order": np.nan, "verdict": "", "expected": "a measured claim",
                "expected_order": None, "outcome": NOT_VERIFIED, "passed": False,
                "predicted_coefficient": np.nan, "measured_coefficient": np.nan,
                "prediction_note": "",
                "reason": f"not verified: no cell measured the claim ({len(mine)} cell(s), none passing: "
                          + ", ".join(sorted(set(mine.outcome))) + ")",
            }
    if len(table):
        table = table.sort_values(["passed", "stepper", "problem"], kind="stable")
    return table.reset_index(drop=True)
