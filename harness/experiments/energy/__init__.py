"""Long-term energy drift: the envelope of the energy error over 10^5-10^6 steps, classified.

For one (stepper, problem) cell:

1. Every problem that declares an invariant applies (the `energy` invariant where declared, else
   the first one). A small ensemble (member 0 is the problem's own start, the others perturbed
   by the problem's `ensemble_perturbation`, or `perturbation`) is integrated with the problem's
   step size (`Problem.time_scale`: h |lambda| = 0.12 for the fastest rate along its orbit, the
   same h for every stepper of the problem; or `h`) for `steps` steps (or up to `t_end`);
   implicit steppers (a Newton solve per step, 10-30 times the cost of an explicit step) take
   `implicit_steps`. Adaptive steppers choose their own steps: they run at their own tolerance
   with `adaptive_outputs` output steps over `adaptive_periods` natural periods (or up to
   `t_end`) and `adaptive_ensemble` members (each output step costs a solver call per member).
   A run past the problem's span (unless `t_end` asks for it) stops where its orbit leaves the
   span's dynamical regime (a closer encounter than any within the span, a state that runs
   off: `harness.regimes.regime_end`), and its message says where and why.
2. The state is saved on a log-spaced grid of step indices (`samples_per_decade`) merged with a
   uniform grid (`uniform_samples`). The relative energy error |E(t) - E0| / |E0| is taken as the
   maximum over members; for problems with an angular momentum invariant the relative error of
   L (largest component change over |L0|) is measured the same way.
3. The envelope is the running maximum M(n) of the error, read on the log grid. Its growth
   exponent is the Theil-Sen slope of log M against log n over the later decades: n from
   max(n_end / 10^fit_decades, FIT_MIN_PERIODS natural periods) to n_end.
   Classes (thresholds in `harness.tolerances`) follow the growth, not the size: `unstable`
   (non-finite, growth faster than linear, an implicit solve that broke down, an error risen to
   ENERGY_BLOWUP_ERROR = 10 %), `linear` (drift ~ t; `drift_slope` is the Theil-Sen slope of M
   against t), `sqrt` (random walk ~ sqrt(t), rounding's signature), `bounded` (no secular
   trend). An error that large in the first period already, within ENERGY_BOUNDED_RISE of it at
   the end, and swinging back below ENERGY_RETURN_FRACTION of its size in the fit window is a
   bounded oscillation, classified by growth: a modified energy H~ is conserved, so the error
   (H - H~)(y_n) - (H - H~)(y_0) is O(h^p) uniformly in time and returns near 0 as the orbit
   revisits its start's phase (HLW IX.8, Thm 8.1; velocity Verlet on x'' = -w^2 x keeps
   p^2 + (1 - h^2 w^2/4) w^2 q^2: at h w = 1.5 its energy error swings between 0 and 56 %).
4. Verdicts. A stepper claimed symplectic must be `bounded`, or show a secular growth within
   what rounding explains (Brouwer's law: rounding makes the energy error a random walk,
   ~ sqrt(n) eps; HLW VIII.5): `as-claimed`, else `claim-false`. Whether a method is symplectic
   comes from its coefficients (`harness.rules.energy_expectation`), never from its name. No
   other energy claim has a theorem behind it: other methods are measured without a claim
   (`no-claim`), a one-step method neither symplectic nor symmetric with the drift predicted
   from its first period beside (`harness.rules.describe_drift`). A run too short to tell a
   drift from a bounded error (less than ENCOUNTER_MIN_DECADES after the fit's start: free fall
   leaves its regime within 16 steps) is `not-measurable`; no `not-measurable` cell gets a
   drift class, unless an implicit solve broke down (that run is `unstable`).
   Close encounters: where the fastest rate along the run rises more than ENCOUNTER_RATE_RISE
   times over its start after the usual fit start, the envelope is read from where that rate is
   first reached (a bounded error ~(h rho)^p rises with each closer approach; the Pleiades'
   energy error jumps to ~4e-3 at t ~ 1.7 and stays below it). A bounded-energy claim is not
   measurable where h rho exceeds the method's h-omega limit (there, or at any orbit's fastest
   rate: the theorem needs small steps), nor with less than ENCOUNTER_MIN_DECADES of the run
   after the encounter. In a central field (each body's
   acceleration parallel to its position, `harness.facts.central_field`), steppers whose
   structure conserves quadratic invariants (symplectic Runge-Kutta, splitting and Stormer
   methods: HLW IV.2 and VI.4) must keep the angular momentum to rounding: a relative error of
   at most ANGULAR_MOMENTUM_ROUNDING_ULPS * n * eps after n steps.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed. (2006), I.2-I.3
(Kepler and the outer solar system), IX.3 and IX.8 (near-conservation of energy by symplectic
methods), VIII.5 (rounding: Brouwer's law); course material 004_bfdbb1594143ed8b.txt (symplectic
integrators conserve a modified energy while RK4 drifts; the Kepler practice session).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.experiments.base import Cell, Experiment, register_experiment
from harness.experiments.common import (
    check_config,
    fixed_plan,
    initial_ensemble,
    invariant_reason,
    long_run_steps,
    perturbation_used,
    primary_invariant,
    problem_cells,
    summary_per_cell,
)
from harness.experiments.energy.judge import (
    classify_drift,
    conserves_quadratic_invariants,
    rounding_growth,
)
from harness.experiments.energy.section import SECTION
from harness.facts import central_field, method_facts
from harness.invariant_checks import check_invariants_along_flow
from harness.regimes import fastest_approach
from harness.registry import get_problem, get_stepper
from harness.rules import describe_drift, drift_prediction, energy_expectation
from harness.step_loops import fastest
from harness.stepper import AdaptiveStepper, StepFailure, Stepper

__all__ = ["EnergyExperiment", "classify_drift", "conserves_quadratic_invariants", "ROW_COLUMNS",
           "SUMMARY_COLUMNS", "SECTION"]


ROW_COLUMNS = [
    "stepper", "problem", "quantity", "invariant", "step", "t", "error", "running_max", "h", "tol",
    "period", "perturbation", "ensemble_size", "wall_s", "message",
]
SUMMARY_COLUMNS = [
    "stepper", "problem", "invariant", "h", "tol", "steps", "t_end", "period", "perturbation",
    "claimed_symplectic", "expected_class",
    "max_rel_energy_error", "drift_class", "drift_exponent", "drift_slope", "secular_growth",
    "rounding_growth", "fit_start", "max_rel_angular_momentum_error", "angular_momentum_class",
    "angular_momentum_rounding", "angular_momentum_expected", "angular_momentum_conserved",
    "verdict", "passed", "ensemble_size", "wall_s", "message",
]


# -- the experiment -------------------------------------------------------------------------------
class EnergyExperiment(Experiment):
    finite_columns = ("step", "t", "h", "wall_s")
    description = "Long-run energy (and angular momentum) error envelope: bounded, sqrt, linear or unstable."
    default_config: Mapping[str, Any] = {
        "h": None,
        "t_end": None,
        "perturbation": None,
        "steps": 100_000,
        "implicit_steps": 10_000,
        "adaptive_outputs": 200,
        "adaptive_periods": 20,
        "adaptive_ensemble": 1,
        "ensemble": 2,
        "seed": 0,
        "fit_decades": 2.0,
        "samples_per_decade": 40,
        "uniform_samples": 2000,
    }
    quick_config: Mapping[str, Any] = {
        "steps": 10_000,
        "implicit_steps": 2_000,
        "adaptive_outputs": 50,
        "adaptive_periods": 5,
        "ensemble": 1,
    }

    def cells(self, steppers, problems, config):
        """The pairs whose problem declares an invariant, the settings checked first.

        Parameters
        ----------
        steppers, problems : sequence of str, the selection.
        config : mapping, its counts and sizes checked by `check_config`.

        Returns
        -------
        (list of Cell, list of Skip): a Skip for each problem without an invariant.
        """
        check_config(config, counts=("steps", "implicit_steps", "adaptive_outputs", "ensemble",
                                     "adaptive_ensemble", "samples_per_decade", "uniform_samples"),
                     positives=("fit_decades", "adaptive_periods"),
                     optional_positives=("h", "t_end", "perturbation"))
        return problem_cells(self.name, steppers, problems, invariant_reason)

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """The invariant errors of one long run (module items 1-2); the problem's invariants are
        first checked along its exact flow.

        Parameters
        ----------
        cell : Cell, one (stepper, problem) pair.
        config : mapping, the plan (`steps`, `h`, `t_end`, ensemble sizes, sampling).

        Returns
        -------
        DataFrame: ROW_COLUMNS, one row per saved step and quantity.
        """
        stepper = get_stepper(cell.stepper)
        problem = get_problem(cell.problem)
        check_invariants_along_flow(problem)  # a wrong invariant is the problem's fault
        return _run(stepper, problem, config)

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """Drift classes and verdicts, one row per cell (module items 3-4).

        Parameters
        ----------
        rows : DataFrame, all cells' rows (ROW_COLUMNS).
        config : mapping, read for `fit_decades`.

        Returns
        -------
        DataFrame: SUMMARY_COLUMNS, one record per cell.
        """
        return summary_per_cell(rows, SUMMARY_COLUMNS, _summarize_cell, config)


def _with_note(message: str, note: str) -> str:
    """The cell's `message` with `note` added after '; ' (either left out where empty)."""
    return "; ".join(x for x in (message, note) if x)


def _plan(stepper: Stepper, problem, config: Mapping[str, Any]) -> tuple[float, int, float]:
    """(h, n_steps, tolerance or NaN) for this stepper on this problem."""
    if isinstance(stepper, AdaptiveStepper):
        n = int(config["adaptive_outputs"])
        t_end = config.get("t_end")
        span = (float(t_end) - problem.t0 if t_end is not None
                else float(config["adaptive_periods"]) * problem.time_scale.period)
        return span / n, n, float(stepper.tol)
    return (*fixed_plan(problem, config, int(config["steps" if stepper.info.explicit
                                                       else "implicit_steps"])), float("nan"))


def save_grid(n: int, per_decade: int, uniform: int) -> np.ndarray:
    """Step indices 0..n: log-spaced (`per_decade` per decade) merged with `uniform` even ones.

    Parameters
    ----------
    n : int, the last step index.
    per_decade : int, log-spaced indices per decade.
    uniform : int, evenly spaced intervals (at most n).

    Returns
    -------
    ndarray of int64: sorted and unique, 0 and n included.
    """
    logs = np.round(np.logspace(0.0, math.log10(n), max(2, int(per_decade * math.log10(max(n, 10))))))
    even = np.round(np.linspace(0, n, min(uniform, n) + 1))
    return np.unique(np.concatenate([[0, n], logs, even]).astype(np.int64))


def _invariant_errors(problem, y: np.ndarray) -> dict[str, np.ndarray]:
    """Relative errors (nt,) of the primary invariant (as "energy") and, where declared, angular
    momentum, max over members."""
    nt, dim, N = y.shape
    flat = np.ascontiguousarray(np.transpose(y, (1, 0, 2)).reshape(dim, nt * N))
    values = problem.invariant_values(flat)
    out: dict[str, np.ndarray] = {}
    with np.errstate(all="ignore"):
        E = values[primary_invariant(problem)].reshape(nt, N)
        E0 = E[0]
        rel = np.abs(E - E0) / np.maximum(np.abs(E0), tol.EPS)
        out["energy"] = _max_members(rel)
        keys = sorted(k for k in values if k.startswith("angular_momentum"))
        if keys:
            L = np.stack([values[k].reshape(nt, N) for k in keys])  # (components, nt, N)
            L0 = L[:, :1, :]
            norm0 = np.sqrt(np.sum(L0 * L0, axis=0))
            dev = np.max(np.abs(L - L0), axis=0) / np.maximum(norm0, tol.EPS)
            out["angular_momentum"] = _max_members(dev)
    return out


def _max_members(rel: np.ndarray) -> np.ndarray:
    bad = ~np.isfinite(rel)
    m = np.max(np.where(bad, 0.0, rel), axis=1)
    return np.where(bad.any(axis=1), np.inf, m)


def _run(stepper: Stepper, problem, config: Mapping[str, Any]) -> pd.DataFrame:
    h, n, tolerance = _plan(stepper, problem, config)
    capped = ""
    if config.get("t_end") is None:  # a final time the user asked for is honoured as given
        n, capped = long_run_steps(problem, h, n)
    size = int(config["adaptive_ensemble" if isinstance(stepper, AdaptiveStepper) else "ensemble"])
    y0 = initial_ensemble(problem, config, size)
    period = problem.time_scale.period
    save = save_grid(n, int(config["samples_per_decade"]), int(config["uniform_samples"]))

    runner = fastest(stepper, problem)
    started = time.perf_counter()
    message = capped
    try:
        tr = runner.integrate(problem, h=h, n_steps=n, y0=y0, save_steps=save)
        steps, times, states = tr.steps, tr.t, tr.y
        if not tr.finite:
            message = "; ".join(filter(None, [capped, "the state overflowed (non-finite)"]))
    except StepFailure as exc:
        steps, times = np.array([0, n]), problem.t0 + np.array([0, n]) * h
        states = np.stack([y0, np.full_like(y0, np.nan)])
        message = "; ".join(filter(None, [capped, f"step failure: {exc}"]))
    wall = time.perf_counter() - started
    errors = _invariant_errors(problem, states)
    frames = []
    for quantity, err in errors.items():
        frames.append(pd.DataFrame({
            "quantity": quantity, "step": steps, "t": times, "error": err,
            "running_max": np.maximum.accumulate(np.where(np.isfinite(err), err, np.inf)),
        }))
    out = pd.concat(frames, ignore_index=True)
    out["stepper"] = stepper.info.name
    out["problem"] = problem.name
    out["h"] = h
    out["tol"] = tolerance
    out["invariant"] = primary_invariant(problem)
    out["period"] = period
    out["perturbation"] = perturbation_used(problem, config) if size > 1 else 0.0
    out["ensemble_size"] = size
    out["wall_s"] = wall
    out["message"] = message
    out["steps_per_period"] = period / h
    out["implementation"] = runner.info.name
    return out[ROW_COLUMNS + ["steps_per_period", "implementation"]]


def _summarize_cell(stepper: Stepper, problem: str, g: pd.DataFrame, config) -> dict:
    info = stepper.info
    first = g.iloc[0]
    steps_per_period = float(first["steps_per_period"])
    message = str(first["message"] or "")
    energy = g[g.quantity == "energy"].sort_values("step")
    n_end = int(energy.step.iloc[-1])
    fit_start = max(n_end / 10.0 ** float(config["fit_decades"]),
                    tol.FIT_MIN_PERIODS * steps_per_period)
    encounter = _last_closest_approach(_problem(problem), energy, float(first["h"]))
    min_decades = 1.0
    if encounter is not None and not encounter["step"] > fit_start:
        encounter = None  # met within the usual fit start: nothing to correct
    if encounter is not None:
        # A bounded error of size ~(h rho)^p rises with each closer approach: the envelope is
        # read only after the run's fastest rate has been reached.
        fit_start = encounter["step"]
        min_decades = min(1.0, math.log10(n_end / max(fit_start, 1.0)))
    e = classify_drift(energy.step.values, energy.t.values, energy.error.values,
                       fit_start=int(fit_start), min_decades=max(min_decades, 1e-3),
                       period_steps=steps_per_period)
    if "step failure: " in message:
        e["drift_class"] = "unstable"  # an implicit solve broke down: the motion is destroyed

    facts = method_facts(stepper)
    expected_class, expected_reason = energy_expectation(facts, bool(info.symplectic))
    prediction = "" if expected_class else drift_prediction(facts)
    limit = rounding_growth(n_end)
    rec = {
        "stepper": info.name, "problem": problem, "invariant": str(first["invariant"]),
        "h": float(first["h"]), "tol": float(first["tol"]),
        "steps": n_end, "t_end": float(energy.t.iloc[-1]), "period": float(first["period"]),
        "perturbation": float(first["perturbation"]),
        "claimed_symplectic": bool(facts.symplectic),
        "expected_class": expected_class,
        "max_rel_energy_error": e["max_error"], "drift_class": e["drift_class"],
        "drift_exponent": e["drift_exponent"], "drift_slope": e["drift_slope"],
        "secular_growth": e["secular_growth"], "rounding_growth": limit,
        "fit_start": e["fit_start"],
        "max_rel_angular_momentum_error": np.nan, "angular_momentum_class": "",
        "angular_momentum_rounding": np.nan, "angular_momentum_expected": False,
        "angular_momentum_conserved": None,
        "ensemble_size": int(first["ensemble_size"]), "wall_s": float(first["wall_s"]),
        "message": message,
    }
    reasons: list[str] = []
    passed = True
    why_not = _not_measurable(expected_class, expected_reason or prediction, encounter, n_end,
                              fit_start, facts.hw_limit,
                              float(first["h"]) * _problem(problem).time_scale.fastest_rate)
    if why_not:
        verdict = "not-measurable"
        rec["message"] = _with_note(message, why_not)
    elif expected_class == "bounded":
        ok = e["drift_class"] == "bounded" or (e["drift_class"] in ("sqrt", "linear")
                                               and e["secular_growth"] <= limit)
        verdict = "as-claimed" if ok else "claim-false"
        if encounter is not None:
            rec["message"] = _with_note(message, f"envelope read after it: {_encounter_note(encounter)}")
        if not ok:
            passed = False
            reasons.append(
                f"{expected_reason}, but it is {e['drift_class']} (growth "
                f"{e['secular_growth']:.3g} over the fit window, rounding explains {limit:.3g})"
            )
    elif prediction:
        m = max(1.0, steps_per_period)
        first = energy[(energy.step > 0) & (energy.step <= math.ceil(m))]
        first_err = float(first.error.max()) if len(first) else float("nan")
        verdict, why = describe_drift(
            prediction, e["drift_class"], e["max_error"], first_err,
            periods_in_fit=(n_end - e["fit_start"]) / m, periods_total=n_end / m,
            rounding_fit=limit, rounding_period=rounding_growth(m))
        rec["message"] = _with_note(message, why)
    else:
        verdict = "no-claim"
    if verdict == "not-measurable" and "step failure: " not in message:
        rec["drift_class"] = ""  # a class drawn from a run that cannot show one would mislead
    L = g[g.quantity == "angular_momentum"].sort_values("step")
    problem_obj = _problem(problem)
    if len(L):
        lc = classify_drift(L.step.values, L.t.values, L.error.values, fit_start=int(fit_start),
                            period_steps=steps_per_period)
        L_limit = tol.ANGULAR_MOMENTUM_ROUNDING_ULPS * n_end * tol.EPS
        rec.update(max_rel_angular_momentum_error=lc["max_error"],
                   angular_momentum_class=lc["drift_class"], angular_momentum_rounding=L_limit)
        conserved = bool(np.isfinite(lc["max_error"]) and lc["max_error"] <= L_limit)
        rec["angular_momentum_conserved"] = conserved
        if central_field(problem_obj) and conserves_quadratic_invariants(stepper):
            rec["angular_momentum_expected"] = True
            if not conserved:
                passed = False
                verdict = "claim-false"
                reasons.append(
                    f"angular momentum error {lc['max_error']:.3g} exceeds the rounding bound "
                    f"{L_limit:.3g} of a method that conserves quadratic invariants"
                )
    rec["verdict"] = verdict
    rec["passed"] = passed
    if reasons:
        rec["message"] = "; ".join([m for m in [message] if m] + reasons)
    return rec


def _encounter_note(encounter: dict) -> str:
    return (f"the fastest rate along the run, {encounter['rate']:.4g} (h rho = {encounter['h_rho']:.3g}), "
            f"is first reached at t = {encounter['t']:.4g} (step {encounter['step']:.0f}; at the start the "
            f"rate is {encounter['rate_start']:.3g})")


def _not_measurable(expected_class: str, expected_reason: str, encounter: dict | None, n_end: int,
                    fit_start: float, hw_limit: float | None, h_rho: float) -> str | None:
    """Why this run cannot tell the energy error's class, or None (the module docstring, item 4):
    too short; a bounded claim's h rho beyond `hw_limit`; a close `encounter`."""
    beyond = hw_limit is not None and math.isfinite(hw_limit) and h_rho > hw_limit
    if expected_class == "bounded" and beyond and encounter is None:
        return (f"not measurable at this step: h omega_max = {h_rho:.3g} exceeds the method's "
                f"limit {hw_limit:.4g} (the near-conservation of energy holds for small steps only)")
    if encounter is None:
        span_decades = math.log10(n_end / max(fit_start, 1.0)) if n_end > 0 else -math.inf
        if span_decades >= tol.ENCOUNTER_MIN_DECADES:
            return None
        return (f"not measurable on this run: it ends at step {n_end}, less than "
                f"{tol.ENCOUNTER_MIN_DECADES:g} decade after the fit's start (step {fit_start:.3g}: "
                f"{tol.FIT_MIN_PERIODS:g} natural periods at least), too short to tell a drift from a "
                "bounded error")
    if not expected_reason:
        return None
    note = _encounter_note(encounter)
    decades_after = math.log10(n_end / max(encounter["step"], 1.0))
    if expected_class != "bounded":
        return (f"{expected_reason}, but not measurable on this run: {note}; the error's jump there "
                f"dominates the envelope and {decades_after:.2g} decade(s) of steps after it cannot "
                "resolve a drift proportional to t")
    if hw_limit is not None and math.isfinite(hw_limit) and encounter["h_rho"] > hw_limit:
        return (f"not measurable at this step: h omega_max = {encounter['h_rho']:.3g} exceeds the "
                f"method's limit {hw_limit:.4g} during close encounters; {note}")
    if decades_after < tol.ENCOUNTER_MIN_DECADES:
        return (f"not measurable on this run: {note}, leaving less than "
                f"{tol.ENCOUNTER_MIN_DECADES:g} decade of steps after it to tell drift from the "
                "error's rise with closer approaches")
    return None


def _last_closest_approach(problem, energy: pd.DataFrame, h: float) -> dict | None:
    """Where the fastest rate rho (the Jacobian's spectral radius, `harness.scales.orbit_rates`)
    along the run's orbit from the problem's start first comes within ENCOUNTER_RATE_FRACTION of
    its maximum over the run, when that is more than ENCOUNTER_RATE_RISE times the rate at the
    start (a close encounter the run meets late); None otherwise (an oscillator, a Kepler orbit
    whose pericentre comes within the first period) or when the orbit cannot be had."""
    found = fastest_approach(problem, float(energy.t.iloc[-1]))
    if found is None:  # no float64 orbit: no correction
        return None
    t_fast, top, start = found
    if not (top > tol.ENCOUNTER_RATE_RISE * max(start, 1e-300)):
        return None
    step = float(energy.step.values[min(np.searchsorted(energy.t.values, t_fast), len(energy) - 1)])
    return {"t": t_fast, "rate": top, "rate_start": start, "step": step, "h_rho": h * top}


def _problem(name: str):
    return get_problem(name)


register_experiment(EnergyExperiment())
