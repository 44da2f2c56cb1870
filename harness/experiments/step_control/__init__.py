"""Step control on Newtonian problems: fixed steps against naive and time-reversible control.

The course's Kepler practice session (course material 004_bfdbb1594143ed8b.txt, Practice
Session #3) asks for a step control with Delta theta ~ const that keeps orbits bounded. For one
(step-controlled stepper, problem) cell, with the fixed-step stepper of the same splitting
coefficients found in the registry (by coefficients, never by name):

1. energy: the controlled stepper runs `energy_steps` steps of control parameter
   `energy_control`; the fixed stepper runs as many steps over the same physical time (its h is
   the controlled run's elapsed clock over the step count: equal work). The relative energy error
   is sampled on the energy experiment's grid and classified by its `classify_drift` (fit window
   from `fit_decades`; the first FIT_MIN_STEPS steps are never fitted).
2. order: a sweep of the control parameter eps = span/n, n = n_start, 2 n_start, ... (span =
   the problem's convergence span, read as fictive time) until at least `sweep_points` points
   are taken and the error is a tenth of the work target, or n exceeds `control_budget`; one
   member, error at the member's own clock against the certified ground truth; points are
   classified and fitted by the
   convergence experiment's `classify_points` and `fit_order` (the gate's fit).
3. work: to reach the final-time accuracy `target_error` x |y| the controlled stepper needs
   (log-log interpolation along its sweep) N_c force evaluations; the fixed stepper, run to the
   same physical time with m = 2^k steps until its error is below the target (or `fixed_budget`
   steps are spent), needs N_f. The work ratio is N_f / N_c (a lower bound when the budget ran
   out first).

References: Hairer, Lubich & Wanner, Geometric Numerical Integration, 2nd ed. (2006), VIII.2-3
(variable steps, reversible time transformations); W. Huang & B. Leimkuhler, SIAM J. Sci.
Comput. 18 (1997) 239-256.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.coefficients import SplittingScheme
from harness.experiments.base import Cell, Experiment, register_experiment
from harness.experiments.common import problem_cells, summary_per_cell
from harness.experiments.convergence import classify_points, fit_order
from harness.experiments.energy import check_config, classify_drift, rounding_growth, save_grid
from harness.experiments.step_control.section import SECTION
from harness.ground_truth import reference
from harness.registry import get_problem, get_stepper, steppers
from harness.registry import problems as problem_registry
from harness.registry import steppers as stepper_registry
from harness.step_loops import fastest

__all__ = ["StepControlExperiment", "fixed_peer", "is_step_controlled", "ROW_COLUMNS",
           "SUMMARY_COLUMNS", "SECTION"]

ROW_COLUMNS = [
    "stepper", "problem", "role", "kind", "h", "n_steps", "step", "t", "error", "reference_error",
    "force_evals", "excluded", "in_fit",
]
SUMMARY_COLUMNS = [
    "stepper", "problem", "fixed_peer", "controller", "symmetric", "keeps_constant",
    "energy_control", "energy_steps", "t_end", "drift_class", "drift_exponent", "drift_slope",
    "max_rel_energy_error", "fixed_drift_class", "fixed_drift_exponent", "fixed_max_rel_energy_error",
    "bounded", "claimed_order", "measured_order", "order_ci_low", "order_ci_high", "fit_points",
    "order_verdict", "target_error", "controlled_evals", "fixed_evals", "work_ratio",
    "work_ratio_is_lower_bound", "verdict", "message",
]
# The first steps hold the initial transient of the error envelope (one orbit at most for the
# default control parameter): never in the drift fit.
FIT_MIN_STEPS = 1000


def is_step_controlled(stepper) -> bool:
    """A stepper whose h is a control parameter: its clock is its own (`uniform_time` False)
    and its record wraps a splitting scheme.

    Parameters
    ----------
    stepper : Stepper

    Returns
    -------
    bool
    """
    scheme = getattr(getattr(stepper, "record", None), "scheme", None)
    return (not stepper.info.extra.get("uniform_time", True)) and isinstance(scheme, SplittingScheme)


def fixed_peer(stepper):
    """The registered fixed-step stepper with the same splitting coefficients, or None.

    Parameters
    ----------
    stepper : Stepper, a step-controlled one (its record holds the scheme).

    Returns
    -------
    Stepper or None: found by the scheme's fingerprint, never by name.
    """
    fingerprint = stepper.record.scheme.fingerprint()
    for other in steppers.all():
        coeffs = getattr(other, "coefficients", None)
        if (isinstance(coeffs, SplittingScheme) and coeffs.fingerprint() == fingerprint
                and other.info.extra.get("uniform_time", True)):
            return other
    return None


def _with_related(steppers: list[str], problems: list[str], config) -> tuple[list[str], list[str]]:
    """The step-controlled steppers and the orbits of this experiment's problem set are listed on
    request only (see `harness.registry`): asked for the fixed-step method a controller runs, or
    for one problem of the set, the experiment adds the related entries: the controlled versions
    of the requested fixed-step schemes, and the rest of its problem set."""
    names = set(steppers)
    for other in stepper_registry.all(variants=True):
        if other.info.name in names or not is_step_controlled(other):
            continue
        if other.info.implementation == "compiled":  # the same method: `fastest` runs it
            continue
        peer = fixed_peer(other)
        if peer is not None and peer.info.name in names:
            steppers.append(other.info.name)
    if set(problems) & set(config["problems"]):
        problems += [p for p in config["problems"] if p not in problems and p in problem_registry]
    return steppers, problems


class StepControlExperiment(Experiment):
    description = ("Fixed steps against naive and reversible step control: energy drift, order in "
                   "the control parameter, work to reach an accuracy.")
    default_config: Mapping[str, Any] = {
        "problems": ["kepler-elliptic", "kepler-e0.9", "kepler-e0.99"],
        # 1024 steps per turn of theta for Delta theta control (measured on kepler-e0.99 over 20
        # orbits: naive 3.7e-2, reversible 1.7e-2; 512 gives 0.32 and 0.067), and 10^6 steps
        # (~1000 orbits): a drift must outgrow the error's oscillation within each orbit
        # (largest at pericentre) before the running maximum shows it; at 10^5 steps with 2048
        # per turn the naive drift stayed hidden under it on every eccentricity.
        "energy_control": 2.0 * math.pi / 1024.0,
        "energy_steps": 1_000_000,
        "fit_decades": 1.5,
        "samples_per_decade": 40,
        "uniform_samples": 1000,
        "n_start": 16,
        "sweep_points": 7,
        "control_budget": 2**18,
        "target_error": 1e-4,
        "fixed_budget": 2**21,
    }
    quick_config: Mapping[str, Any] = {
        "problems": ["kepler-elliptic"],
        "energy_steps": 50_000,
        "sweep_points": 6,
        "control_budget": 2**15,
        "fixed_budget": 2**18,
    }

    def cells(self, steppers, problems, config):
        """One cell per step-controlled stepper with a registered fixed-step peer, on each
        conservative problem of the config's `problems`; every other pair a `Skip` with its reason.

        Parameters
        ----------
        steppers, problems : sequence of str, the names asked for.
        config : mapping, the budgets and targets (checked), and the problem set `problems`.

        Returns
        -------
        (list of Cell, list of Skip): with the reason of each pair left out.
        """
        check_config(config, counts=("energy_steps", "samples_per_decade", "uniform_samples",
                                     "n_start", "sweep_points", "control_budget", "fixed_budget"),
                     positives=("energy_control", "fit_decades", "target_error"),
                     name_lists=("problems",))
        steppers, problems = _with_related(list(steppers), list(problems), config)

        def pair_reason(stepper, problem) -> str | None:
            if not is_step_controlled(stepper):
                return "not step-controlled (its h is a physical step, not a control parameter)"
            if problem.name not in config["problems"]:
                return f"problem {problem.name!r} is not in this experiment's problem set (config `problems`)"
            if not problem.conservative or "energy" not in problem.invariants:
                return f"problem {problem.name!r} is not conservative (no energy to follow)"
            if fixed_peer(stepper) is None:
                return "no fixed-step stepper with the same splitting coefficients is registered"
            return None

        return problem_cells(self.name, steppers, problems, lambda problem: None, pair_reason)

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """The energy rows of the controlled stepper and its fixed peer at equal work, and the
        controlled stepper's order sweep (module items 1-2).

        Parameters
        ----------
        cell : Cell, a step-controlled stepper and its problem.
        config : mapping, the energy run's and the sweep's settings.

        Returns
        -------
        DataFrame: ROW_COLUMNS and `peer`.
        """
        stepper = get_stepper(cell.stepper)
        problem = get_problem(cell.problem)
        peer = fixed_peer(stepper)
        runner, peer_runner = fastest(stepper, problem), fastest(peer, problem)
        frames = _energy_rows(runner, peer_runner, problem, config)
        sweep = _order_rows(runner, problem, config)
        frames.append(sweep)
        frames.append(_work_rows(runner, peer_runner, problem, sweep, config))
        out = pd.concat(frames, ignore_index=True)
        out["peer"] = out["peer"].replace(peer_runner.info.name, peer.info.name)
        out["stepper"] = stepper.info.name
        out["problem"] = problem.name
        for c in ROW_COLUMNS:
            if c not in out:
                out[c] = np.nan
        return out[ROW_COLUMNS + ["peer"]]

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """Drift classes of both runs and the measured order, one row per cell.

        Parameters
        ----------
        rows : DataFrame, energy and sweep rows of all cells.
        config : mapping, read for the fit window, the control and the target error.

        Returns
        -------
        DataFrame: SUMMARY_COLUMNS.
        """
        return summary_per_cell(rows, SUMMARY_COLUMNS, _summarize_cell, config)


# -- measuring --------------------------------------------------------------------------------------
def _rel_energy(problem, states: np.ndarray) -> np.ndarray:
    """|E - E0|/|E0| of member 0 along states shaped (nt, dim, N); inf where non-finite."""
    y = np.ascontiguousarray(states[:, :, 0].T)
    with np.errstate(all="ignore"):
        E = problem.invariant_values(np.nan_to_num(y, nan=0.0, posinf=0.0, neginf=0.0))["energy"]
        rel = np.abs(E - E[0]) / max(abs(float(E[0])), tol.EPS)
    return np.where(np.all(np.isfinite(y), axis=0), rel, np.inf)


def _energy_rows(stepper, peer, problem, config) -> list[pd.DataFrame]:
    n = int(config["energy_steps"])
    eps = float(config["energy_control"])
    save = save_grid(n, int(config["samples_per_decade"]), int(config["uniform_samples"]))
    tr = stepper.integrate(problem, h=eps, n_steps=n, save_steps=save)
    rel = _rel_energy(problem, tr.y)
    frames = [_energy_frame("controlled", tr, eps, rel)]
    # The fixed run takes as many steps per unit time as the controlled run did while its
    # energy error stayed below the blow-up level (a runaway clock says nothing about work).
    good = np.flatnonzero((rel < tol.ENERGY_BLOWUP_ERROR) & np.isfinite(tr.t) & (tr.steps > 0))
    if good.size:
        k = good[-1]
        h = (float(tr.t[k]) - problem.t0) / float(tr.steps[k])
        fixed = peer.integrate(problem, h=h, n_steps=n, save_steps=save)
        frames.append(_energy_frame("fixed", fixed, h, _rel_energy(problem, fixed.y)))
    for f in frames:
        f["peer"] = peer.info.name
    return frames


def _energy_frame(role: str, tr, h: float, err: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame({"role": role, "kind": "energy", "h": h, "n_steps": int(tr.steps[-1]),
                         "step": tr.steps, "t": tr.t, "error": err,
                         "force_evals": float(tr.evals.get("accel", 0))})


def _state_error(problem, tr) -> tuple[float, float, float]:
    """(max-norm error of member 0 at its own final clock, certified reference error, |y|)."""
    if not tr.finite:
        return float("inf"), float("nan"), float("nan")
    t_end = float(tr.t[-1])
    if not problem.t0 < t_end <= problem.t0 + tol.CLOCK_LIMIT_SPANS * (problem.t_end - problem.t0):
        return float("inf"), float("nan"), float("nan")  # the clock ran away: a blow-up
    ref = reference(problem, np.array([t_end]), problem.y0)
    y_ref = ref.y[-1][:, 0]
    return (float(np.max(np.abs(tr.final[:, 0] - y_ref))), float(np.max(ref.error[-1])),
            float(max(tol.SCALE_FLOOR, np.max(np.abs(y_ref)), np.max(np.abs(problem.y0)))))


def _order_rows(stepper, problem, config) -> pd.DataFrame:
    span = problem.convergence_t_end - problem.t0
    target = float(config["target_error"]) * _state_scale(problem)
    records = []
    n = int(config["n_start"])
    while n <= int(config["control_budget"]):
        if len(records) >= int(config["sweep_points"]) and records[-1]["error"] <= target / 10.0:
            break
        tr = stepper.integrate(problem, h=span / n, n_steps=n)
        err, ref_err, scale = _state_error(problem, tr)
        records.append({"role": "controlled", "kind": "order", "h": span / n, "n_steps": n,
                        "step": n, "t": float(tr.t[-1]), "error": err, "reference_error": ref_err,
                        "force_evals": float(tr.evals.get("accel", 0)),
                        "rounding_level": math.sqrt(n) * tol.EPS * _state_scale(problem)})
        n *= 2
    frame = pd.DataFrame(records)
    frame["excluded"] = classify_points(frame.h.values, frame.error.values,
                                        frame.reference_error.fillna(0.0).values,
                                        frame.rounding_level.values,
                                        tol.SWEEP_START_ERROR * _state_scale(problem))
    frame["in_fit"] = frame.excluded == ""
    frame["peer"] = ""
    return frame.drop(columns=["rounding_level"])


def _state_scale(problem) -> float:
    return max(tol.SCALE_FLOOR, float(np.max(np.abs(problem.y0))))


def _target_cost(frame: pd.DataFrame, target: float) -> tuple[float, float] | None:
    """Force evaluations and clock at which the error first falls to `target`, interpolated in
    log-log between the bracketing points of a sweep ordered by growing cost; None if never."""
    f = frame[np.isfinite(frame.error)].sort_values("force_evals")
    prev = None
    for _, r in f.iterrows():
        if r.error <= target:
            if prev is None or not (prev.error > target):
                return float(r.force_evals), float(r.t)
            w = math.log(prev.error / target) / math.log(prev.error / r.error)
            cost = math.exp(math.log(prev.force_evals) + w * math.log(r.force_evals / prev.force_evals))
            return cost, float(r.t)
        prev = r
    return None


def _work_rows(stepper, peer, problem, sweep: pd.DataFrame, config) -> pd.DataFrame:
    target = float(config["target_error"]) * _state_scale(problem)
    found = _target_cost(sweep, target)
    if found is None:
        return pd.DataFrame([{"role": "fixed", "kind": "work", "error": np.nan, "peer": peer.info.name,
                              "reference_error": target}])
    _, t_end = found
    records = []
    m = int(config["n_start"])
    while m <= int(config["fixed_budget"]):
        tr = peer.integrate(problem, h=(t_end - problem.t0) / m, n_steps=m)
        err, ref_err, _ = _state_error(problem, tr)
        records.append({"role": "fixed", "kind": "work", "h": (t_end - problem.t0) / m, "n_steps": m,
                        "step": m, "t": float(tr.t[-1]), "error": err,
                        "reference_error": target, "force_evals": float(tr.evals.get("accel", 0))})
        if np.isfinite(err) and err <= target:
            break
        m *= 2
    frame = pd.DataFrame(records)
    frame["peer"] = peer.info.name
    return frame


# -- judging ----------------------------------------------------------------------------------------
def _classify(energy: pd.DataFrame, config) -> dict:
    energy = energy.sort_values("step")
    n_end = int(energy.step.iloc[-1])
    fit_start = max(n_end / 10.0 ** float(config["fit_decades"]), FIT_MIN_STEPS)
    return classify_drift(energy.step.values, energy.t.values, energy.error.values,
                          fit_start=int(min(fit_start, n_end / 10.0)))


def _summarize_cell(stepper, problem: str, g: pd.DataFrame, config) -> dict:
    info = stepper.info
    rec: dict[str, Any] = {c: np.nan for c in SUMMARY_COLUMNS}
    peer = str(g.peer.dropna().iloc[0]) if g.peer.notna().any() else ""
    rec.update(stepper=info.name, problem=problem, fixed_peer=peer,
               controller=info.extra.get("controller", ""), symmetric=bool(info.symmetric),
               keeps_constant=info.extra.get("keeps_constant", ""),
               energy_control=float(config["energy_control"]), claimed_order=info.claimed_order,
               target_error=float(config["target_error"]), message="")
    ctrl = g[(g.kind == "energy") & (g.role == "controlled")]
    fixed = g[(g.kind == "energy") & (g.role == "fixed")]
    e = _classify(ctrl, config)
    rec.update(energy_steps=int(ctrl.step.max()), t_end=float(ctrl.t.iloc[-1]),
               drift_class=e["drift_class"], drift_exponent=e["drift_exponent"],
               drift_slope=e["drift_slope"], max_rel_energy_error=e["max_error"])
    if len(fixed):
        f = _classify(fixed, config)
        rec.update(fixed_drift_class=f["drift_class"], fixed_drift_exponent=f["drift_exponent"],
                   fixed_max_rel_energy_error=f["max_error"])
    else:
        rec["fixed_drift_class"] = ""
    limit = rounding_growth(rec["energy_steps"])
    rec["bounded"] = bool(e["drift_class"] == "bounded" or (
        e["drift_class"] in ("sqrt", "linear") and e["secular_growth"] <= limit))
    order = g[g.kind == "order"].sort_values("h", ascending=False)
    kept = order[order.in_fit.astype(bool)]
    if len(kept) >= tol.MIN_FIT_POINTS:
        fit = fit_order(kept.h.values, kept.error.values)
        rec.update(measured_order=fit["order"], order_ci_low=fit["ci_low"],
                   order_ci_high=fit["ci_high"], fit_points=len(kept))
        ok = info.claimed_order is not None and abs(fit["order"] - info.claimed_order) <= tol.GATE_ORDER_TOL
        rec["order_verdict"] = "as-claimed" if ok else "claim-false"
    else:
        rec.update(fit_points=len(kept), order_verdict="insufficient-range")
    target = float(config["target_error"])
    work = g[g.kind == "work"]
    found = None
    if len(work) and work.error.notna().any():
        target_abs = float(work.reference_error.iloc[0])
        found = _target_cost(order, target_abs)
        fixed_done = work[np.isfinite(work.error) & (work.error <= target_abs)]
        if found is not None:
            rec["controlled_evals"] = found[0]
            if len(fixed_done):
                fixed_cost = _target_cost(work, target_abs)
                rec["fixed_evals"] = fixed_cost[0] if fixed_cost else float(fixed_done.force_evals.min())
                rec["work_ratio_is_lower_bound"] = False
            else:
                rec["fixed_evals"] = float(work.force_evals.max())
                rec["work_ratio_is_lower_bound"] = True
            rec["work_ratio"] = rec["fixed_evals"] / rec["controlled_evals"]
    if found is None:
        rec["message"] = f"the controlled sweep never reached the target accuracy {target:g} x |y|"
        rec["work_ratio_is_lower_bound"] = False
    # Verdict on the course's question: bounded orbits means a bounded energy error.
    rec["verdict"] = "bounded" if rec["bounded"] else f"not-bounded ({e['drift_class']})"
    return rec


register_experiment(StepControlExperiment())
