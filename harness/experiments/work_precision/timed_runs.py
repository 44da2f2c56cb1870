"""The work-precision sweep's points timed by the protocol of `harness.timing`.

`time_points` takes the rows of one (stepper, problem) sweep (which computed the errors and so
warmed every cache and compiled every kernel) and times each point again: the same call, the
same initial state, the same step count or tolerance, repeated by `harness.timing.measure`. It
adds, per row, the timing statistics, the C baseline of the stepper's family timed in the same
cell, the machine, the method's identity (from its coefficients) and, where the sweep ran the
compiled loop of a NumPy method, that NumPy loop timed at a few points with its own error: the
same coefficients in two implementations, side by side.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from harness import timing
from harness import tolerances as tol
from harness.errors import ReferenceError_
from harness.ground_truth import reference
from harness.step_loops import fastest
from harness.stepper import AdaptiveStepper, StepFailure
from harness.timing import baseline_step, machine_info, measure, method_identity

__all__ = ["time_points", "TIMING_COLUMNS", "protocol_settings"]

TIMING_COLUMNS = [
    "t_min_s", "t_median_s", "t_spread", "t_repeats", "t_stop", "first_call_s", "method_id",
    "baseline", "baseline_step_s", "baseline_units", "per_step_ratio", "twin_implementation",
    "twin_error", "twin_min_s", "twin_spread", "twin_repeats", "cpu", "cores", "blas",
    "blas_threads", "load_1min", "timing_cell_s",
]


def protocol_settings(config: Mapping[str, Any]) -> dict[str, Any]:
    """`harness.timing.measure`'s settings from an experiment configuration.

    Parameters
    ----------
    config : mapping
        The work-precision configuration (`timing_max_repeats`, `timing_budget_s`).

    Returns
    -------
    dict
        min_repeats, max_repeats, target_spread, budget_s.
    """
    max_r = int(config.get("timing_max_repeats", timing.TIMING_MAX_REPEATS))
    return {"min_repeats": min(timing.TIMING_MIN_REPEATS, max_r), "max_repeats": max_r,
            "target_spread": timing.TIMING_TARGET_SPREAD,
            "budget_s": float(config.get("timing_budget_s", timing.TIMING_POINT_BUDGET_S))}


def _reference_state(problem, T: float, y0: np.ndarray) -> np.ndarray:
    """The certified state at T (float64 rounding where heyoka's levels allow, else the best)."""
    scale = max(tol.SCALE_FLOOR, float(np.max(np.abs(y0))))
    try:
        return reference(problem, np.array([T]), y0, required_error=tol.EPS * scale).y[-1]
    except ReferenceError_:
        return reference(problem, np.array([T]), y0).y[-1]


def time_points(stepper, problem, frame: pd.DataFrame, config: Mapping[str, Any], *,
                clock=None) -> pd.DataFrame:
    """Time every point of one work-precision sweep (module docstring).

    Parameters
    ----------
    stepper, problem
        The cell's stepper and problem.
    frame : DataFrame
        The sweep's rows (`n_steps`, `h` or `tol`, `t_end`, `wall_s`, `error`).
    config : mapping
        The experiment's configuration (ensemble, seed, perturbation, timing settings).
    clock : callable, optional
        The timer (tests pass a fake one); default `time.perf_counter`.

    Returns
    -------
    DataFrame
        `frame` with the `TIMING_COLUMNS` added (a point that failed in the sweep is not timed:
        NaN); `timing_cell_s` is the wall time the timing took in this cell (the budget's
        measure), the same on every row of the cell.
    """
    started = time.perf_counter()
    clock = clock or time.perf_counter
    settings = protocol_settings(config)
    out = frame.reset_index(drop=True).copy()
    adaptive = isinstance(stepper, AdaptiveStepper)
    T0 = problem.t0
    members = int(config["ensemble"])
    if adaptive:
        members = min(members, tol.TOLERANCE_SWEEP_ENSEMBLE)
    y0 = problem.ensemble(members, seed=int(config["seed"]), scale=config.get("perturbation"))
    runner = stepper if adaptive else fastest(stepper, problem)
    machine = machine_info()

    def call(s, i: int):
        T = float(out.at[i, "t_end"]) if "t_end" in out and np.isfinite(out.at[i, "t_end"]) \
            else float(config.get("t_end") or problem.convergence_t_end)
        if adaptive:
            s = s.with_tolerance(float(out.at[i, "tol"]))
            return lambda: s.integrate(problem, h=T - T0, n_steps=1, y0=y0, t0=T0)
        n = int(out.at[i, "n_steps"])
        return lambda: s.integrate(problem, h=(T - T0) / n, n_steps=n, y0=y0, t0=T0)

    stats = {c: np.full(len(out), np.nan) for c in ("t_min_s", "t_median_s", "t_spread", "t_repeats")}
    stops = [""] * len(out)
    ran = out["error"].notna().to_numpy() & (out.get("n_steps", pd.Series(1, index=out.index)) > 0).to_numpy()
    first = np.flatnonzero(ran)
    sweep_s = out["wall_s"].to_numpy(float)
    with np.errstate(all="ignore"):
        for i in first:
            # the sweep's run of a point is a warm sample, except the cell's first (it compiled)
            prior = (sweep_s[i],) if i != first[0] and np.isfinite(sweep_s[i]) else ()
            t = measure(call(runner, int(i)), clock=clock, prior=prior, **settings)
            stats["t_min_s"][i], stats["t_median_s"][i] = t.min_s, t.median_s
            stats["t_spread"][i], stats["t_repeats"][i] = t.spread, t.repeats
            stops[i] = t.stop
    for c, v in stats.items():
        out[c] = v
    out["t_stop"] = stops
    # the sweep's first run paid for compiling and loading; its warm repeats did not
    out["first_call_s"] = (float(out.at[first[0], "wall_s"]) if len(first) else np.nan)
    out["method_id"] = method_identity(stepper) or ""
    few = min(settings["max_repeats"], timing.TIMING_MIN_REPEATS)  # the baseline is cheap and steady
    name, base, why = baseline_step(stepper.info.family, clock=clock,
                                    **{**settings, "min_repeats": few, "max_repeats": few})
    out["baseline"] = name if base is not None else f"none: {why}"
    step = base.min_s if base is not None else np.nan
    out["baseline_step_s"] = step
    out["baseline_units"] = out["t_min_s"] / step
    out["per_step_ratio"] = out["t_min_s"] / out["n_steps"].where(out["n_steps"] > 0) / step
    _time_twin(stepper, runner, problem, out, y0, call, settings, clock)
    for key, value in machine.items():
        out[key] = value
    out["timing_cell_s"] = time.perf_counter() - started  # what the timing cost this cell
    return out


def _time_twin(stepper, runner, problem, out: pd.DataFrame, y0: np.ndarray, call, settings,
               clock) -> None:
    """Where the sweep ran a compiled loop in place of `stepper`'s NumPy loop: time the NumPy
    loop at the largest point of at most TIMING_TWIN_WORK work (steps x evaluations per step,
    implicit steps weighted by IMPLICIT_STEP_COST) and measure its error there (the same
    reference as the sweep's); it is warmed up by one run of the cell's first point. A NumPy
    step that fails where the compiled loop's did not (its own Newton iterates) leaves the twin
    untimed at that point, with the failure in the row's message: the cell stands."""
    for c in ("twin_error", "twin_min_s", "twin_spread", "twin_repeats"):
        out[c] = np.nan
    out["twin_implementation"] = ""
    if runner is stepper or out.empty:
        return
    per_step = max(1.0, float(stepper.info.evals_per_step))
    if not stepper.info.explicit:
        per_step *= tol.IMPLICIT_STEP_COST
    ok = (out["error"].notna() & np.isfinite(out["t_min_s"])
          & (out["n_steps"] * per_step <= tol.TIMING_TWIN_WORK))
    chosen = out[ok].sort_values("n_steps").index[-1:]
    if not len(chosen):
        return
    T = float(out.at[chosen[0], "t_end"])
    target = _reference_state(problem, T, y0)
    with np.errstate(all="ignore"):
        try:
            call(stepper, int(out[ok].sort_values("n_steps").index[0]))()  # the NumPy loop's warm-up
        except StepFailure:
            pass  # a warm-up only: the timed point below says whether the NumPy loop runs there
        for i in chosen:
            run, last = call(stepper, int(i)), {}
            try:
                t = measure(lambda run=run, last=last: last.update(tr=run()), clock=clock, **settings)
            except StepFailure as exc:
                note = f"NumPy twin not timed: {exc}"
                said = out.at[i, "message"] if isinstance(out.at[i, "message"], str) else ""
                out.at[i, "message"] = "; ".join(x for x in (said, note) if x)
                continue
            d = np.abs(last["tr"].final - target)
            out.at[i, "twin_error"] = float(np.max(d)) if np.all(np.isfinite(d)) else np.inf
            out.at[i, "twin_min_s"], out.at[i, "twin_spread"] = t.min_s, t.spread
            out.at[i, "twin_repeats"] = t.repeats
            out.at[i, "twin_implementation"] = stepper.info.implementation
