"""The timing protocol: warm, repeated runs, each figure also a ratio to a baseline of the same run.

Rules (what a timed figure of the harness means):

1. Timed runs execute alone: the experiment that times (`work-precision`) declares itself
   `exclusive`, and the runner executes its cells one at a time (one worker, or this process)
   after the experiments before it have finished, so no other cell shares the cores.
2. Warm: compilation, cache loading and first-call costs are excluded. The cell's own sweep
   (which computes the errors) is the warm-up; its first run, compile time included, is kept
   apart as `first_call_s`, and every later run of the sweep (warm, alone, plus one error
   evaluation of the final state) counts as the first sample of its point (`prior`), so a
   point dearer than the budget is not run again. `measure` can add its own warm-up runs
   (`warmup`), never counted.
3. Repeated until the spread is small or a budget is spent: `measure` runs a point at least
   `min_repeats` times, stops once the relative spread (median - min) / min is at most
   `target_spread`, or at `max_repeats` runs, or when the point has spent `budget_s` seconds (a
   dear point is then timed fewer times; the repeat count and the stop reason say so). It
   records the minimum (the figure used: load only ever adds time), the median, the spread
   and the repeat count.
4. A ratio to a baseline timed in the same run: the C loop of the stepper's family on Kepler
   (`benchmarks/c_baseline/kepler.c`, compiled with the system compiler), or, for a family
   without one, the classical RK4 C loop, named in the `baseline` column. It is timed in the same
   cell with the same protocol, so a slower or busier machine moves both.
5. The machine is recorded: CPU model, logical cores, BLAS library and thread count, the load
   average before the cell.

The clock is injectable (`clock=`), so the protocol's logic is tested on fake timers.

References: SciMLBenchmarks.jl work-precision diagrams (DiffEqDevTools `WorkPrecisionSet`:
`numruns` repeated solves, minimum time); A. Georges, D. Buytaert & L. Eeckhout, "Statistically
rigorous Java performance evaluation", OOPSLA 2007 (warm-up excluded, repeat until stable).
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import os
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import threadpoolctl

from harness import tolerances as tol
from harness.coefficients import SplittingScheme
from harness.errors import InputError
from harness.provenance import cpu_model

__all__ = ["Timing", "measure", "relative_spread", "machine_info", "baseline_step",
           "time_to_target", "time_to_target_table", "method_identity",
           "same_method_groups", "PROTOCOL"]

# The timing protocol (the work-precision experiment's timed runs). A point is
# repeated until the spread (median - min) / min of its repeats is at most TIMING_TARGET_SPREAD
# (5 %: below the +-30 % load noise of a shared machine, which the minimum filters, and the
# resolution a ratio table is read at), after at least TIMING_MIN_REPEATS runs (three give a
# median that is not one of the extremes), at most TIMING_MAX_REPEATS runs (quick: fewer), or
# until the point has spent TIMING_POINT_BUDGET_S seconds (quick: less). The sweep's own warm run
# is the first sample, so a point dearer than the budget is not run again and the timing costs a
# cell at most about (points below the budget) x budget: with ~5 points per sweep in the
# 1-20 ms band, ~0.1 s a cell, ~1 minute over the registry (the report's budget: +25 %).
TIMING_TARGET_SPREAD = 0.05
TIMING_MIN_REPEATS = 3
TIMING_MAX_REPEATS = 7
TIMING_QUICK_MAX_REPEATS = 3
TIMING_POINT_BUDGET_S = 0.02
TIMING_QUICK_POINT_BUDGET_S = 0.01
# The C baseline is timed on a run of about this many seconds per repeat (its step count is
# doubled until one run takes this long), so the timer's resolution and the call's overhead are
# below 0.1 % of it.
TIMING_BASELINE_RUN_S = 0.002

PROTOCOL = (
    "Timed runs execute alone (the work-precision cells run one at a time on one worker, with no "
    "other cell beside them: the experiments before have finished, the ones after wait), warm "
    "(the sweep that measured the errors is the warm-up; its first run, compile time included, "
    "is reported apart, its later runs count as each point's first sample), repeated until the "
    "spread (median - min) / min is at most {spread:.0%} after at least {min_r} runs, or at "
    "{max_r} runs, or once a point has spent {budget:g} s; the minimum is the figure used. Each "
    "time is also given as a ratio to the C loop of the stepper's family (or the C RK4 loop) on "
    "Kepler, timed in the same cell the same way."
)


@dataclass(frozen=True)
class Timing:
    """One timed point: every sample (seconds), the statistics and why repeating stopped."""

    samples: tuple[float, ...]
    stop: str  # "spread", "max-repeats", "budget"
    warmup_s: tuple[float, ...] = field(default=())

    @property
    def repeats(self) -> int:
        return len(self.samples)

    @property
    def min_s(self) -> float:
        return min(self.samples)

    @property
    def median_s(self) -> float:
        return float(statistics.median(self.samples))

    @property
    def spread(self) -> float:
        return relative_spread(self.samples)


def relative_spread(samples: Sequence[float]) -> float:
    """(median - min) / min of `samples`; NaN for fewer than two samples or a zero minimum.

    Parameters
    ----------
    samples : sequence of float, repeated timings of one run, in seconds.

    Returns
    -------
    float: the relative spread (0 when every sample is the same).
    """
    if len(samples) < 2 or min(samples) <= 0:
        return float("nan")
    return (float(statistics.median(samples)) - min(samples)) / min(samples)


def measure(fn: Callable[[], Any], *, warmup: int = 0, min_repeats: int = TIMING_MIN_REPEATS,
            max_repeats: int = TIMING_MAX_REPEATS, target_spread: float = TIMING_TARGET_SPREAD,
            budget_s: float = TIMING_POINT_BUDGET_S, prior: Sequence[float] = (),
            clock: Callable[[], float] = time.perf_counter) -> Timing:
    """Time `fn()` by the protocol (module docstring, rule 3).

    Parameters
    ----------
    fn : callable, the run to time, called without arguments.
    warmup : int, runs made first and not counted (their times are kept in `Timing.warmup_s`).
    min_repeats, max_repeats : int
        Counted runs: at least `min_repeats` (unless the budget is spent first), at most
        `max_repeats`.
    target_spread : float, stop once (median - min) / min is at most this, after `min_repeats` runs.
    budget_s : float, stop once the counted runs have spent this many seconds (at least one run is made).
    prior : sequence of float
        Warm runs already made alone (the sweep's own run of the point): counted first, so a
        point dearer than the budget costs nothing more.
    clock : callable, the timer (seconds); injectable for tests.

    Returns
    -------
    Timing: the samples, and the stop reason: "spread", "max-repeats" or "budget".
    """
    counts = isinstance(min_repeats, int) and isinstance(max_repeats, int)
    if not (counts and 1 <= min_repeats <= max_repeats):
        raise InputError(f"`min_repeats` and `max_repeats` must be integers with 1 <= min_repeats "
                         f"<= max_repeats, got {min_repeats!r} and {max_repeats!r}")
    if not (isinstance(warmup, int) and warmup >= 0):
        raise InputError(f"`warmup` must be a non-negative integer, got {warmup!r}")
    warm = []
    for _ in range(warmup):
        start = clock()
        fn()
        warm.append(clock() - start)
    samples: list[float] = [float(x) for x in prior]
    while True:
        if samples:
            if len(samples) >= max_repeats:
                stop = "max-repeats"
                break
            if len(samples) >= min_repeats and relative_spread(samples) <= target_spread:
                stop = "spread"
                break
            if sum(samples) >= budget_s:
                stop = "budget"
                break
        start = clock()
        fn()
        samples.append(max(clock() - start, 0.0))
    return Timing(tuple(samples), stop, tuple(warm))


# -- the machine ----------------------------------------------------------------------------------
def machine_info() -> dict[str, Any]:
    """What a timing depends on besides the code (module docstring, rule 5).

    Returns
    -------
    dict
        `cpu` (model name), `cores` (logical), `blas` (library and version, or "none loaded"),
        `blas_threads` (its thread count; -1 when unknown), `load_1min` (load average, NaN
        where the platform has none).
    """
    blas, threads = "none loaded", -1
    pools = [p for p in threadpoolctl.threadpool_info() if p.get("user_api") == "blas"]
    if pools:
        blas = f"{pools[0].get('internal_api')} {pools[0].get('version') or ''}".strip()
        threads = int(pools[0].get("num_threads", -1))
    try:
        load = float(os.getloadavg()[0])
    except OSError:
        load = float("nan")
    return {"cpu": cpu_model(), "cores": int(os.cpu_count() or 1), "blas": blas,
            "blas_threads": threads, "load_1min": load}


# -- the C baseline -------------------------------------------------------------------------------
_KEPLER_H = 1e-3


@lru_cache(maxsize=1)
def _c_library() -> Any:
    """The loaded C baseline, or the reason it is unavailable (a string)."""
    build = Path(__file__).resolve().parents[1] / "benchmarks" / "c_baseline" / "build.py"
    if not build.is_file():
        return "the C baseline's source (benchmarks/c_baseline) is not in this installation"
    spec = importlib.util.spec_from_file_location("_harness_c_baseline", build)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it executes
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    try:
        return module.load()
    except module.CompilerUnavailable as exc:
        return str(exc)


def baseline_step(family: str, *, clock: Callable[[], float] = time.perf_counter,
                  **protocol: Any) -> tuple[str, Timing | None, str]:
    """Time one step of the C loop for `family` (module docstring, rule 4).

    Parameters
    ----------
    family : str, the stepper's family (`StepperInfo.family`); the C baseline's `family_loop` names its loop.
    clock : callable, the timer.
    **protocol
        `measure`'s settings (repeats, spread, budget).

    Returns
    -------
    (name, timing, reason)
        The loop's name ("C rk4 loop on Kepler"), its `Timing` per step (samples divided by the
        step count) or None, and why it is None ("" otherwise).
    """
    lib = _c_library()
    if isinstance(lib, str):
        return f"C loop of the {family} family on Kepler", None, lib
    build = sys.modules["_harness_c_baseline"]
    loop = build.family_loop(family)
    name = f"C {loop} loop on Kepler"
    state = build.kepler_start(loop, _KEPLER_H)
    n = 1000
    while True:  # a run long enough for the timer (tolerances.TIMING_BASELINE_RUN_S)
        start = clock()
        lib.run(loop, state, _KEPLER_H, n)
        if clock() - start >= TIMING_BASELINE_RUN_S or n >= 1 << 26:
            break
        n *= 2
    t = measure(lambda: lib.run(loop, state, _KEPLER_H, n), clock=clock, **protocol)
    return name, Timing(tuple(s / n for s in t.samples), t.stop), ""


# -- time to a target error -----------------------------------------------------------------------
def time_to_target(cost: Sequence[float], error: Sequence[float], target: float) -> tuple[float, str]:
    """The least cost at which a sweep reaches `target` error.

    The points are sorted by cost; the first point at or below the target and the point before
    it are joined by a straight line in log(error)-log(cost), and the cost where that line meets
    the target is returned.

    Parameters
    ----------
    cost, error : sequences of float
        One sweep's measured points (non-finite or non-positive values are left out).
    target : float, the error to reach (> 0).

    Returns
    -------
    (cost, status)
        status "interpolated"; "first point" when the cheapest point already reaches the
        target (its cost is an upper bound); "not reached" (cost NaN) otherwise.
    """
    if not (target > 0):
        raise InputError(f"`target` must be a positive error, got {target!r}")
    c = np.asarray(cost, dtype=float)
    e = np.asarray(error, dtype=float)
    ok = np.isfinite(c) & np.isfinite(e) & (c > 0) & (e > 0)
    c, e = c[ok], e[ok]
    order = np.lexsort((e, c))
    c, e = c[order], e[order]
    hit = np.flatnonzero(e <= target)
    if hit.size == 0:
        return float("nan"), "not reached"
    i = int(hit[0])
    if i == 0:
        return float(c[0]), "first point"
    lc0, lc1 = math.log(c[i - 1]), math.log(c[i])
    le0, le1 = math.log(e[i - 1]), math.log(e[i])
    frac = (math.log(target) - le0) / (le1 - le0)
    return float(math.exp(lc0 + frac * (lc1 - lc0))), "interpolated"


def time_to_target_table(rows: pd.DataFrame, targets: Sequence[float] = tol.TIMING_TARGET_ERRORS,
                         cost: str = "t_min_s") -> pd.DataFrame:
    """Per problem, target and stepper: the time to reach the target and its ratio to the fastest.

    Parameters
    ----------
    rows : DataFrame, work-precision rows with `problem`, `stepper`, `error` and the `cost` column.
    targets : sequence of float, the target errors.
    cost : str, the column to interpolate (seconds).

    Returns
    -------
    DataFrame
        Columns problem, target, stepper, time_s, status, ratio_to_fastest (1 for the fastest,
        NaN where the target was not reached), fastest (the fastest stepper's name).
    """
    cols = ["problem", "target", "stepper", "time_s", "status", "ratio_to_fastest", "fastest"]
    if rows.empty or cost not in rows:
        return pd.DataFrame(columns=cols)
    out = []
    for (problem, stepper), g in rows.groupby(["problem", "stepper"], sort=False):
        for target in targets:
            t, status = time_to_target(g[cost].to_numpy(float), g["error"].to_numpy(float), target)
            out.append({"problem": problem, "target": float(target), "stepper": stepper,
                        "time_s": t, "status": status})
    table = pd.DataFrame(out, columns=cols[:5])
    best = table.groupby(["problem", "target"])["time_s"].transform("min")
    table["ratio_to_fastest"] = table["time_s"] / best
    fastest = table.loc[table["time_s"] == best, ["problem", "target", "stepper"]]
    fastest = fastest.drop_duplicates(["problem", "target"]).rename(columns={"stepper": "fastest"})
    return table.merge(fastest, on=["problem", "target"], how="left")[cols]


# -- one method, several implementations ----------------------------------------------------------
def method_identity(stepper: Any) -> str | None:
    """The identity of the method a stepper computes, from its coefficients: the coefficient
    object's `fingerprint()` (exact data), or that of the splitting a black box declares in
    `info.extra["declared_splitting"]` ((kind, coefficient) pairs); None when neither exists
    (such a stepper is in no group).

    Parameters
    ----------
    stepper : Stepper, any registered stepper.

    Returns
    -------
    str or None: equal for two steppers exactly when their coefficients are equal.
    """
    coefficients = getattr(stepper, "coefficients", None)
    declared = stepper.info.extra.get("declared_splitting")
    if coefficients is None and declared:
        coefficients = SplittingScheme(f"{stepper.info.name} (declared)", [tuple(x) for x in declared])
    fp = getattr(coefficients, "fingerprint", None)
    if fp is None:
        return None

    return hashlib.sha256(f"{type(coefficients).__name__}:{fp()}".encode()).hexdigest()[:16]


def same_method_groups(rows: pd.DataFrame) -> pd.DataFrame:
    """Rows of implementations that share a method, side by side at equal steps.

    Parameters
    ----------
    rows : DataFrame
        Timed work-precision rows with `method_id`, `implementation`, `stepper`, `problem`,
        `n_steps`, `h`, `error`, `t_min_s`, `rounding_level` (one row per implementation and
        point; NumPy twins included).

    Returns
    -------
    DataFrame
        One row per (method_id, problem, h) with at least two implementations: the
        implementations, their errors' largest difference, whether it is within rounding
        (`tolerances.TIMING_SAME_ERROR_ULPS` / `TIMING_SAME_ERROR_RTOL`), and each
        implementation's time as a ratio to the fastest one at that point (`slowest_ratio`: the
        slowest over the fastest).
    """
    cols = ["method_id", "problem", "h", "n_steps", "implementations", "errors", "error_diff",
            "relative_diff", "agree", "times_s", "time_ratios", "slowest_ratio"]
    need = {"method_id", "implementation", "problem", "h", "error", "t_min_s"}
    if rows.empty or not need <= set(rows.columns):
        return pd.DataFrame(columns=cols)
    frame = rows[rows["method_id"].notna() & (rows["method_id"].astype(str) != "")
                 & np.isfinite(rows["h"].astype(float))]
    out = []
    for (mid, problem, h), g in frame.groupby(["method_id", "problem", "h"], sort=False):
        g = g.drop_duplicates("implementation")
        if len(g) < 2:
            continue
        err = g["error"].to_numpy(float)
        times = g["t_min_s"].to_numpy(float)
        # the same value everywhere (an overflow to inf in every implementation too) is no difference
        diff = 0.0 if np.all(err == err[0]) else float(np.max(err) - np.min(err))
        n = float(g["n_steps"].max())
        level = float(g["rounding_level"].max()) if "rounding_level" in g else tol.EPS
        bound = max(tol.TIMING_SAME_ERROR_ULPS * level,
                    tol.TIMING_SAME_ERROR_ULPS * tol.EPS * math.sqrt(max(n, 1.0)),
                    tol.TIMING_SAME_ERROR_RTOL * float(np.max(err)))
        fastest = np.nanmin(times) if np.isfinite(times).any() else float("nan")
        out.append({"method_id": mid, "problem": problem, "h": float(h), "n_steps": int(n),
                    "implementations": " / ".join(f"{s} ({i})" for s, i in
                                                  zip(g["stepper"], g["implementation"], strict=True)),
                    "errors": " / ".join(f"{x:.6e}" for x in err), "error_diff": diff,
                    "relative_diff": diff / float(np.max(err)) if np.max(err) > 0 else 0.0,
                    "agree": bool(np.isfinite(diff) and diff <= bound),
                    "times_s": " / ".join(f"{t:.3g}" for t in times),
                    "time_ratios": " / ".join(f"{t / fastest:.2f}" for t in times),
                    "slowest_ratio": float(np.nanmax(times) / fastest)})
    return pd.DataFrame(out, columns=cols)
