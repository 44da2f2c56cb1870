"""Convergence order: global error against step size, fitted only where the asymptotic law holds.

For one (stepper, problem) cell:

1. An ensemble of `ensemble` perturbed initial conditions (member 0 is the problem's own start)
   is integrated to the problem's `convergence_t_end` with n = n0, 2 n0, 4 n0, ... steps. The
   sweep starts where the error first falls below `start_error` and continues until the error
   reaches the roundoff floor or the step budget is spent; it is chosen per pair, so a
   high-order method does not waste steps below its floor and a first-order method reaches its
   asymptotic range.
2. The error of a point is the max-norm over components and ensemble members of the difference
   from the certified ground truth (`harness.ground_truth.reference`).
3. Points are excluded from the fit, each with its reason: `blow-up` (non-finite or huge),
   `reference` (error not at least REFERENCE_MARGIN x the reference's certified error),
   `roundoff` (error within ROUNDOFF_MARGIN x the rounding level sqrt(n) eps |y|),
   `pre-asymptotic` (outside the longest run of points whose local slopes agree).
4. The order is the least-squares slope of log(error) against log(h) over the points kept, with
   its residual and a 95 % confidence interval. With fewer than MIN_FIT_POINTS points the sweep
   widens itself (intermediate step sizes, then smaller ones) before giving up.
5. Verdicts: `converged`, `exact` (errors at rounding for every step size), `unstable` (blows
   up at every step size within the budget), `insufficient-range`, `failed` (a step failure).
6. The local (one-step) error is measured as well, from exact history for multistep methods:
   `local_exponent` q in error ~ h^q (q = p + 1 for a one-step method of order p), on the whole
   state and, for Newtonian problems, on positions alone (`local_exponent_q`).
7. Where the float64 floor ends the sweep with too few asymptotic points (an order 8-10 method
   whose local slopes still drift when the floor arrives), the same coefficients run again in
   real128 from the problem's start against a 192-bit reference (`harness.extended`) and those
   points replace the float64 ones, with a message saying so; a method whose coefficients are
   given only to float64 (or a black box, an implicit or multistep method) keeps its float64
   verdict, and the message says why it was not rerun.

Adaptive steppers are measured by a tolerance sweep instead: error against requested tolerance;
the verdict says whether the error stays within the allowance `harness.rules.tolerance_allowance`
derives from the accepted steps and the flow's amplification over the horizon.
Reference: Hairer, Norsett & Wanner, *Solving ODEs I*, II.1 and II.4 (order, error constants).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.coefficient_floors import coefficient_floor, coefficient_rounding_floor
from harness.experiments.base import Cell, Experiment, register_experiment
from harness.experiments.common import perturbation_used, problem_cells, summary_per_cell
from harness.experiments.convergence.extended import extended_if_floor_bound
from harness.experiments.convergence.judge import summarize_cell
from harness.experiments.convergence.plan import least_count, local_step_sizes, read_references_once
from harness.experiments.convergence.reference_error import (
    best_reference,
    error_amplification,
    max_error,
    reference_at_clocks,
    state_scale,
)
from harness.experiments.convergence.section import SECTION
from harness.ground_truth import reference
from harness.order_fit import classify_points, fit_order
from harness.registry import get_problem, get_stepper
from harness.step_loops import fastest
from harness.stepper import AdaptiveStepper, StepFailure, Stepper, WorkLimitFailure

__all__ = [
    "ConvergenceExperiment",
    "fit_order",
    "classify_points",
    "ROW_COLUMNS",
    "SUMMARY_COLUMNS",
    "SECTION",
]

ROW_COLUMNS = [
    "stepper", "problem", "kind", "h", "tol", "n_steps", "t_end", "error", "reference_error",
    "rounding_level", "excluded", "in_fit", "rhs_evals", "force_evals", "wall_s",
    "ensemble_size", "perturbation", "implementation",
]
SUMMARY_COLUMNS = [
    "stepper", "problem", "claimed_order", "measured_order", "order_ci_low", "order_ci_high",
    "fit_residual", "fit_points", "fit_h_min", "fit_h_max", "fit_error_min", "fit_error_max",
    "local_exponent", "local_exponent_q", "verdict", "reference_error", "reference_precision",
    "points", "total_steps", "perturbation", "implementation", "wall_s", "message", "finest_h", "t_end",
]


# -- fitting ----------------------------------------------------------------------------------
class ConvergenceExperiment(Experiment):
    description = "Global and local error order against step size (tolerance for adaptive steppers)."
    default_config: Mapping[str, Any] = {
        "ensemble": tol.ENSEMBLE_SIZE,
        "seed": 0,
        "start_error": tol.SWEEP_START_ERROR,
        "ratio": tol.SWEEP_RATIO,
        "work_budget": tol.SWEEP_WORK_BUDGET,
        "n_start": 4,
        "target_points": tol.TARGET_FIT_POINTS,
        # Five tolerances over eight decades: enough for the proportionality fit; the pure-Python
        # scipy peers make tighter ones cost minutes per cell for little information.
        "tolerances": [10.0**-k for k in range(3, 12, 2)],
        "local": True,
        "t_end": None,  # None: the problem's convergence horizon
        "perturbation": None,  # None: the problem's ensemble perturbation
    }
    quick_config: Mapping[str, Any] = {"ensemble": 8, "work_budget": tol.SWEEP_WORK_BUDGET // 4}

    def cells(self, steppers, problems, config):
        """Every pair the stepper can run: no problem is left out for its kind.

        Parameters
        ----------
        steppers, problems : sequence of str, the registered names of the selection.
        config : mapping, unused here (the sweeps read it).

        Returns
        -------
        (list of Cell, list of Skip): a Skip only for a pair the stepper cannot run.
        """
        return problem_cells(self.name, steppers, problems, lambda problem: None)

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """The step sweep (module items 1-4, 6-7), or an adaptive stepper's tolerance sweep.

        Parameters
        ----------
        cell : Cell, the (stepper, problem) pair.
        config : mapping, the sweep's settings (`ensemble`, `work_budget`, `tolerances`, ...).

        Returns
        -------
        DataFrame: one row per step size and kind ('global', 'local', 'local-q') or tolerance.
        """
        stepper = get_stepper(cell.stepper)
        problem = get_problem(cell.problem)
        if isinstance(stepper, AdaptiveStepper):
            return _tolerance_sweep(stepper, problem, config)
        return _shrinking_sweep(stepper, problem, config)

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """The fitted order and verdict per cell (`judge.summarize_cell`, module item 5).

        Parameters
        ----------
        rows : DataFrame, the sweeps' rows of every cell.
        config : mapping, not read: the verdict follows from the rows.

        Returns
        -------
        DataFrame: SUMMARY_COLUMNS.
        """
        return summary_per_cell(rows, SUMMARY_COLUMNS, summarize_cell)


def step_budget(stepper: Stepper, config: Mapping[str, Any]) -> int:
    """Steps a sweep may spend: the work budget (right-hand-side evaluations) over the
    stepper's declared cost per step; implicit steps also pay for Newton's linear solves.
    Deterministic, so a verdict never depends on how busy the machine was.

    Parameters
    ----------
    stepper : Stepper, its declared evaluations per step and whether it is explicit.
    config : mapping, `step_budget` (an explicit count that wins) or `work_budget`.

    Returns
    -------
    int: the number of steps.
    """
    if config.get("step_budget") is not None:  # an explicit step count wins
        return int(config["step_budget"])
    info = stepper.info
    per_step = max(1.0, float(info.evals_per_step))
    if not info.explicit:
        per_step *= tol.IMPLICIT_STEP_COST
    return int(float(config["work_budget"]) / per_step)


def _step_sweep(stepper: Stepper, problem, config) -> pd.DataFrame:
    """The sweep over the configured horizon (`t_end`, else the problem's convergence horizon),
    the same for every stepper (work-precision compares them at one final time)."""
    return _step_sweep_at(stepper, problem, config, config.get("t_end") or problem.convergence_t_end)


def _shrinking_sweep(stepper: Stepper, problem, config) -> pd.DataFrame:
    """The convergence sweep over the problem's convergence horizon; where the work budget ends it before
    MIN_FIT_POINTS points reach the asymptotic range while the error is still far above the
    floor (a low-order method on a long orbit), the same sweep runs again over a horizon
    HORIZON_SHRINK times shorter, at most MAX_HORIZON_SHRINKS times: the order does not depend
    on the horizon, and the rows say which one was used and why. A horizon the user set
    (`t_end`) is kept as it is."""
    if config.get("t_end"):
        return _step_sweep(stepper, problem, config)
    T0, T = problem.t0, problem.convergence_t_end
    notes: list[str] = []
    horizons = [T]  # the loop's horizons, each computed as the loop does
    for _ in range(tol.MAX_HORIZON_SHRINKS):
        horizons.append(T0 + (horizons[-1] - T0) / tol.HORIZON_SHRINK)
    for attempt in range(tol.MAX_HORIZON_SHRINKS + 1):  # the reads of every horizon asked at once
        frame = _step_sweep_at(stepper, problem, config, T, horizons if attempt == 0 else ())
        g = frame[frame.kind == "global"]
        budget_bound = bool(frame.attrs.get("budget_ended"))
        enough = int(g.in_fit.sum()) >= tol.MIN_FIT_POINTS
        if enough or not budget_bound or attempt == tol.MAX_HORIZON_SHRINKS:
            break
        new_T = T0 + (T - T0) / tol.HORIZON_SHRINK
        notes.append(f"work budget spent with {int(g.in_fit.sum())} asymptotic point(s) up to t = {T:.6g}; "
                     f"horizon shortened to t = {new_T:.6g}")
        T = new_T
    frame = extended_if_floor_bound(
        stepper, problem, frame, config,
        amplification=lambda T: error_amplification(problem, T - problem.t0, problem.y0))
    if notes:
        frame["message"] = frame["message"].fillna("").astype(str)
        frame.loc[frame.kind == "global", "message"] = [
            "; ".join([*notes, m] if m else notes) for m in frame.loc[frame.kind == "global", "message"]
        ]
    return frame


def _step_sweep_at(stepper: Stepper, problem, config, T: float, horizons=None) -> pd.DataFrame:
    runner = fastest(stepper, problem)
    T0 = problem.t0
    span = T - T0
    y0 = problem.ensemble(int(config["ensemble"]), seed=int(config["seed"]), scale=config.get("perturbation"))
    budget = step_budget(stepper, config)
    read_references_once(runner, problem, y0, T0, [T] if horizons is None else horizons, budget, config)
    ref = best_reference(problem, T, y0)
    y_ref = ref.y[-1]
    ref_err = float(np.max(ref.error[-1]))
    scale = state_scale(y0, y_ref)
    records: dict[int, dict] = {}
    spent = 0
    # Rounding committed along the way is carried to T by the flow: the floor is sqrt(n) eps |y|
    # times the flow's sensitivity over the horizon (at least 1), as in the reversibility bound.
    amplification = error_amplification(problem, T - T0, y0[:, 0])
    # The error the record's own digits leave (None where its defects are float64 rounding).
    floor_of = coefficient_floor(getattr(stepper, "coefficients", None), problem, span=span,
                                 scale=scale, noise=tol.EPS)
    # ... and what rounding its coefficients to float64 leaves (large coefficients only): a part
    # of the rounding level, so a sweep that reaches it is floor-bound and rerun in real128.
    rounded_of = coefficient_rounding_floor(getattr(stepper, "coefficients", None), problem,
                                            span=span, scale=scale)

    def run(n: int) -> dict:
        nonlocal spent
        if n in records:
            return records[n]
        spent += n
        started = time.perf_counter()
        target_err = ref_err
        try:
            tr = runner.integrate(problem, h=span / n, n_steps=n, y0=y0, t0=T0)
            target, target_err = y_ref, ref_err
            finite = tr.finite
            if tr.member_t is not None and finite:  # h is a control parameter: own clocks
                clocks = tr.member_t[-1]
                finite = bool(np.all((clocks >= T0) & (clocks <= problem.t0 + tol.CLOCK_LIMIT_SPANS
                                                        * (problem.t_end - problem.t0))))
                if finite:
                    target, target_err = reference_at_clocks(problem, clocks, y0, T0)
            err = max_error(tr.final, target) if finite else float("inf")
            evals = tr.evals
            msg = ""
        except StepFailure as exc:
            err, evals, msg = float("nan"), {}, str(exc)
        rec = {
            "n_steps": n, "h": span / n, "error": err, "reference_error": target_err,
            "rounding_level": max(math.sqrt(n) * tol.EPS * scale * amplification,
                                  _first_or_zero(rounded_of(np.array([span / n])))),
            "rhs_evals": float(evals.get("rhs", 0)), "force_evals": float(evals.get("accel", 0)),
            "wall_s": time.perf_counter() - started, "message": msg,
        }
        records[n] = rec
        return rec

    start_error = float(config["start_error"]) * scale
    target = int(config["target_points"])

    def classified() -> tuple[pd.DataFrame, np.ndarray]:
        frame = _frame(records)
        return frame, classify_points(frame.h.values, frame.error.values,
                                      frame.reference_error.values, frame.rounding_level.values,
                                      start_error, floor_of(frame.h.values))

    def at_floor(rec: dict) -> bool:
        return rec["error"] < tol.ROUNDOFF_MARGIN * rec["rounding_level"] or (
            rec["error"] < tol.REFERENCE_MARGIN * ref_err) or (
            floor_of(np.array([rec["h"]])) is not None
            and rec["error"] < tol.COEFFICIENT_FLOOR_MARGIN * float(floor_of(np.array([rec["h"]]))[0]))

    n_min = least_count(stepper)  # a multistep method's k - 1 first values come from its starter
    # Phase 0: a start that is already below the start error (a high-order method on a smooth
    # span) is coarsened first, down to n_min steps, so the sweep sees the error fall.
    n = max(int(config["n_start"]), n_min)
    rec = run(n)
    while n > n_min and np.isfinite(rec["error"]) and rec["error"] < start_error:
        n = max(n_min, n // 2)
        rec = run(n)
    n = max(int(config["n_start"]), n_min)
    # Phase 1 and 2: from coarse to fine (ratio 2) until the error has fallen below the start
    # error and either the asymptotic window holds `target` points or the floor is reached;
    # the budget ends it in any case.
    budget_ended = True
    while spent + n <= budget:
        rec = run(n)
        if np.isfinite(rec["error"]) and rec["error"] < start_error:
            if at_floor(rec):
                budget_ended = False
                break
            _, reasons = classified()
            if int((reasons == "").sum()) >= target:
                budget_ended = False
                break
        n = int(math.ceil(n * float(config["ratio"])))
    # Phase 3: widen. Where the floor (or the budget) came before `target` points, fill in step
    # sizes between the measured ones (ratio sqrt 2), twice at most.
    for _ in range(2):
        frame, reasons = classified()
        if int((reasons == "").sum()) >= target:
            break
        below = [i for i in range(len(frame)) if np.isfinite(frame.error.values[i])
                 and frame.error.values[i] < start_error]
        if not below:
            break
        ns = [int(v) for v in frame.n_steps.values[below[0]:]]
        new = [int(round(math.sqrt(x * y))) for x, y in zip(ns, ns[1:], strict=False)]
        new = [m for m in new if m not in records]
        if not new:
            break
        for m in new:
            if spent + m <= budget:
                run(m)
    frame = _frame(records)
    frame["excluded"] = classify_points(frame.h.values, frame.error.values,
                                        frame.reference_error.values, frame.rounding_level.values,
                                        start_error, floor_of(frame.h.values))
    frame["in_fit"] = frame["excluded"] == ""
    frame["kind"] = "global"
    frame["tol"] = np.nan
    frame["reference_precision"] = ref.precision
    rows = [frame]
    # The local sweep compares one step with the truth at t0 + h: not defined for a stepper
    # whose h is a control parameter (`uniform_time` False); its global sweep measures it.
    if config.get("local", True) and stepper.info.extra.get("uniform_time", True):
        rows.append(_local_sweep(runner, problem, y0, frame, config))
    out = pd.concat(rows, ignore_index=True)
    out["stepper"] = stepper.info.name
    out["problem"] = problem.name
    out["t_end"] = T
    out["implementation"] = runner.info.implementation
    out["ensemble_size"] = y0.shape[1]
    out["perturbation"] = perturbation_used(problem, config) if y0.shape[1] > 1 else 0.0
    out.attrs["budget_ended"] = budget_ended
    return out


def _first_or_zero(values: np.ndarray | None) -> float:
    return 0.0 if values is None else float(values[0])


def _frame(records: dict[int, dict]) -> pd.DataFrame:
    return pd.DataFrame([records[k] for k in sorted(records)])


def _local_sweep(stepper: Stepper, problem, y0: np.ndarray, global_frame: pd.DataFrame, config):
    """One step of the recurrence from exact history, for h from the global fit range down."""
    k = stepper.history_length
    fit = global_frame[global_frame.in_fit]
    h_max = float(fit.h.max()) if len(fit) else float(global_frame.h.min())
    hs = local_step_sizes(h_max, problem, k)
    records = []
    nq = len(problem.newtonian.positions) if problem.newtonian is not None else None
    # One reference call for every time any step size needs: t0 + j h for j = 1..k.
    times = np.unique(np.concatenate([problem.t0 + h * np.arange(1, k + 1) for h in hs]))
    ref = reference(problem, times, y0, t0=problem.t0)

    def at(t: float) -> tuple[np.ndarray, float]:
        i = int(np.argmin(np.abs(times - t)))
        return ref.y[i], float(np.max(ref.error[i]))

    for h in hs:
        history = [y0] + [at(problem.t0 + j * h)[0] for j in range(1, k)]
        try:
            y1 = stepper.step_from_history(problem, h=float(h), history=history, t0=problem.t0)
        except StepFailure as exc:
            records.append({"h": h, "error": np.nan, "message": str(exc)})
            continue
        exact, exact_err = at(problem.t0 + k * h)
        scale = state_scale(y0, exact)
        rec = {
            "h": float(h), "n_steps": 1, "error": max_error(y1, exact),
            "reference_error": exact_err,
            "rounding_level": tol.EPS * scale, "message": "",
        }
        if nq:
            rec["error_q"] = max_error(y1[:nq], exact[:nq])
        records.append(rec)
    frame = pd.DataFrame(records)
    frame["excluded"] = classify_points(frame.h.values, frame.error.values,
                                        frame.reference_error.values, frame.rounding_level.values)
    frame["in_fit"] = frame["excluded"] == ""
    frame["kind"] = "local"
    if nq:
        qf = frame.copy()
        qf["error"] = qf["error_q"]
        qf["excluded"] = classify_points(qf.h.values, qf.error.values,
                                         qf.reference_error.values, qf.rounding_level.values)
        qf["in_fit"] = qf["excluded"] == ""
        qf["kind"] = "local-q"
        frame = pd.concat([frame, qf], ignore_index=True)
    return frame.drop(columns=["error_q"], errors="ignore")


def _tolerance_sweep(stepper: AdaptiveStepper, problem, config) -> pd.DataFrame:
    T0, T = problem.t0, config.get("t_end") or problem.convergence_t_end
    members = min(int(config["ensemble"]), tol.TOLERANCE_SWEEP_ENSEMBLE)
    y0 = problem.ensemble(members, seed=int(config["seed"]), scale=config.get("perturbation"))
    ref = best_reference(problem, T, y0)
    y_ref = ref.y[-1]
    scale = state_scale(y0, y_ref)
    records = []
    spent, costs = 0.0, []  # internal steps per member: summed, and per tolerance run
    for tolerance in config["tolerances"]:
        predicted = costs[-1] * costs[-1] / costs[-2] if len(costs) >= 2 and costs[-2] > 0 else 0.0
        if spent + predicted > tol.TOLERANCE_SWEEP_STEPS:
            records.append({
                "tol": tolerance, "h": np.nan, "n_steps": 0, "error": np.nan,
                "reference_error": float(np.max(ref.error[-1])), "rounding_level": tol.EPS * scale,
                "rhs_evals": 0.0, "force_evals": 0.0, "wall_s": 0.0, "message": "", "not_run": True,
            })
            continue
        outside = _outside_documented_range(stepper, tolerance)
        if outside:
            records.append({
                "tol": tolerance, "h": np.nan, "n_steps": 0, "error": np.nan,
                "reference_error": float(np.max(ref.error[-1])), "rounding_level": tol.EPS * scale,
                "rhs_evals": 0.0, "force_evals": 0.0, "wall_s": 0.0, "message": outside,
                "not_run": True,
            })
            continue
        started = time.perf_counter()
        s = stepper.with_tolerance(tolerance)
        try:
            tr = s.integrate(problem, h=T - T0, n_steps=1, y0=y0, t0=T0)
            err = max_error(tr.final, y_ref) if tr.finite else float("inf")
            evals, msg, capped = tr.evals, "", False
        except StepFailure as exc:  # the harness's own evaluation cap: a tolerance not run, with why
            err, evals, msg, capped = float("nan"), {}, str(exc), isinstance(exc, WorkLimitFailure)
        records.append({
            "tol": tolerance, "h": np.nan, "n_steps": int(evals.get("internal_steps", 0)),
            "error": err, "reference_error": float(np.max(ref.error[-1])),
            "rounding_level": tol.EPS * scale, "rhs_evals": float(evals.get("rhs", 0)),
            "force_evals": float(evals.get("accel", 0)),
            "wall_s": time.perf_counter() - started, "message": msg, "not_run": capped,
        })
        costs.append(int(evals.get("internal_steps", 0)) / members)
        spent += costs[-1]
    frame = pd.DataFrame(records)
    frame["excluded"] = np.where(~np.isfinite(frame.error), "blow-up",
                                 np.where(frame.error < tol.REFERENCE_MARGIN * frame.reference_error,
                                          "reference", ""))
    frame["in_fit"] = frame["excluded"] == ""
    frame["kind"] = "tolerance"
    # A tolerance the cost cap left out is a row of its own kind, with the reason, so the verdict
    # judges only the tolerances that ran and the tables say which were not run and why.
    skipped = frame.pop("not_run").astype(bool)
    frame.loc[skipped, "excluded"] = np.where(frame.loc[skipped, "message"] != "", "tol-range",
                                              "cost-cap")
    frame.loc[skipped, "in_fit"] = False
    frame.loc[skipped, "kind"] = "tolerance-not-run"
    # how much the flow amplifies an error over the horizon: the rules' allowance for the
    # global error of a locally controlled run (`harness.rules.tolerance_allowance`)
    frame["flow_amplification"] = error_amplification(problem, T - T0, y0[:, 0])
    frame["reference_precision"] = ref.precision
    frame["stepper"] = stepper.info.name
    frame["problem"] = problem.name
    frame["t_end"] = T
    frame["ensemble_size"] = y0.shape[1]
    frame["perturbation"] = perturbation_used(problem, config) if y0.shape[1] > 1 else 0.0
    return frame


def _outside_documented_range(stepper: AdaptiveStepper, tolerance: float) -> str:
    """Why `tolerance` is not measurable for `stepper` (outside the range its library documents,
    `info.extra['tol_range']` = [low or None, high or None]), else ''."""
    low, high = (list(stepper.info.extra.get("tol_range") or []) + [None, None])[:2]
    if (low is not None and tolerance < low) or (high is not None and tolerance > high):
        bounds = f"[{'0' if low is None else f'{low:.3g}'}, {'inf' if high is None else f'{high:.3g}'}]"
        return (f"not measurable: tol = {tolerance:.3g} is outside the range {bounds} that "
                f"{stepper.info.name}'s library documents")
    return ""


# The sweeps under public names: work-precision runs them too (through experiments.common).
step_sweep, tolerance_sweep = _step_sweep, _tolerance_sweep

register_experiment(ConvergenceExperiment())
