"""Roundoff floors at very small steps: the position-only (two-step) Verlet form against leapfrog.

The claim checked (course-material file 002_b3abae41bf42a307.txt, the lecture on Verlet and
leapfrog): the original Verlet recurrence x_(n+1) = 2 x_n - x_(n-1) + h^2 a_n adds the tiny
h^2 a_n to numbers of the size of the positions, so it loses more to rounding than leapfrog, which
only ever adds h v to x and h a to v.

A rounding error d made in x_n propagates through the two-step recurrence as through a double
integrator (its characteristic polynomial has the double root 1), so n steps accumulate about
n^(3/2) eps |x| as a random walk; in leapfrog a rounding error in x stays put (~ n^(1/2) eps |x|)
and one in v is multiplied by h before it reaches x (~ h n^(3/2) eps |v|). At fixed n and h -> 0
the first stays while the second vanishes with h: the floors differ by about 1/(h omega).

For one (stepper, problem) cell: an ensemble of `ensemble` starts (member 0 is the problem's own)
is integrated for `n_steps` steps of each size h in a geometric sweep from `h_max` down to `h_min`
(`points_per_decade` per decade). At fixed n the truncation error falls like h^(p+1) (global error
C T h^p with T = n h, p the method's order from its coefficients), so at the small end only
rounding is left. Each point records the position error relative to max |q| (max over
components and members) against the certified ground truth (`harness.ground_truth.reference`)
at t0 + n h, and the truncation error predicted at that h from the largest step
(error(h_max) (h / h_max)^(p+1)). A second series (`series` 'growth') follows the error along
the run at the smallest step, at `growth_points` step counts from n / 100 to n: its log-log
slope is the rounding error's growth exponent. A double integrator of independent rounding
errors gives n^(3/2), a one-step form on a linear problem n^(1/2); measured at h = 1e-6 over
10^2-10^4 steps the two-step forms grow like n^2 (harmonic, circular Kepler: 2.00-2.05): the
increment h^2 a_n is ~1e-12 of x_n and changes slowly, so the rounding of x_n + increment keeps
its sign over many steps and is integrated twice as a constant bias, not as a random walk.

Summary per cell: `floor_error`, the smallest error over the sweep (the best accuracy any h
reaches: below it rounding wins) and the h where it occurs; `error_at_h_min`; whether the
smallest step is rounding-limited (its error more than ROUNDOFF_TRUNCATION_FACTOR times the
predicted truncation); the floor in units of eps; the growth exponent (Theil-Sen slope of log
error against log n over the growth series).

The default steppers are the course's three (two-step Verlet, leapfrog, velocity Verlet) and two
k-step members of the same two-step form, sum alpha_j x_(n+j) = h^2 sum beta_j a_(n+j): an
explicit Stormer method (k = 4, order 4) and Quinlan & Tremaine's symmetric SL8 (order 8), which add
h^2 sum beta_j a_(n+j) to the positions the same way and, their rho having the double root 1,
integrate its rounding twice like the two-step rule (QT8's other roots lie on the unit circle
and add bounded parts).

References: Verlet, Phys. Rev. 159, 98 (1967) (the two-step form); Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, 2nd ed., VIII.5 (rounding errors, Brouwer's law);
course-material file 002_b3abae41bf42a307.txt (the rounding argument about h^2).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from harness import tolerances as tol
from harness.errors import IncompatibleError, InputError
from harness.experiments.base import Cell, Experiment, Skip, register_experiment
from harness.experiments.roundoff.section import SECTION
from harness.facts import method_facts
from harness.ground_truth import reference
from harness.registry import get_problem, get_stepper
from harness.stepper import AdaptiveStepper, StepFailure, check_compatible

__all__ = ["RoundoffExperiment", "ROW_COLUMNS", "SUMMARY_COLUMNS", "step_sizes", "SECTION"]

ROW_COLUMNS = [
    "stepper", "problem", "h", "n_steps", "t_end", "error", "state_error", "reference_error",
    "truncation_estimate", "ensemble_size", "wall_s", "message", "series",
]
SUMMARY_COLUMNS = [
    "stepper", "problem", "n_steps", "h_min", "h_max", "floor_error", "floor_h", "floor_eps",
    "error_at_h_min", "truncation_at_h_min", "rounding_limited", "reference_error",
    "growth_exponent", "verdict", "wall_s", "message",
]


def step_sizes(h_max: float, h_min: float, points_per_decade: int) -> np.ndarray:
    """Geometric step sizes from `h_max` down to `h_min`, `points_per_decade` per decade.

    Parameters
    ----------
    h_max, h_min : float, the largest and smallest step (positive, h_min < h_max).
    points_per_decade : int, at least 1.

    Returns
    -------
    ndarray of float: decreasing; `InputError` for an argument that breaks its rule.
    """
    for name, v in (("h_max", h_max), ("h_min", h_min)):
        if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
            raise InputError(f"`{name}` must be a positive finite number, got {v!r}")
    if h_min >= h_max:
        raise InputError(f"`h_min` must be smaller than `h_max` ({h_max!r}), got {h_min!r}")
    if isinstance(points_per_decade, bool) or not isinstance(points_per_decade, int) or points_per_decade < 1:
        raise InputError(f"`points_per_decade` must be a whole number >= 1, got {points_per_decade!r}")
    decades = math.log10(h_max / h_min)
    count = int(round(decades * points_per_decade)) + 1
    return np.geomspace(h_max, h_min, count)


class RoundoffExperiment(Experiment):
    description = ("Roundoff floor at very small steps (fixed step count): two-step Verlet "
                   "against leapfrog and velocity Verlet.")
    default_config: Mapping[str, Any] = {
        "steppers": ["stormer-verlet", "leapfrog", "velocity-verlet", "stormer4", "quinlan-tremaine8"],
        "problems": ["harmonic", "kepler-circular"],
        "n_steps": 10_000,
        "h_max": 1e-2,
        "h_min": 1e-6,
        "points_per_decade": 2,
        "ensemble": 4,
        "seed": 0,
        "growth_points": 9,
    }
    quick_config: Mapping[str, Any] = {"n_steps": 5_000, "points_per_decade": 1}
    finite_columns = ("h", "n_steps", "t_end")

    def cells(
        self, steppers: Sequence[str], problems: Sequence[str], config: Mapping[str, Any]
    ) -> tuple[list[Cell], list[Skip]]:
        """Cells for the configured steppers x problems among those selected; one `Skip` per
        other selected stepper or problem, saying why.

        Parameters
        ----------
        steppers, problems : sequence of str, the selection.
        config : mapping, with the `steppers` and `problems` the experiment compares.

        Returns
        -------
        (list of Cell, list of Skip)
        """
        want_s, want_p = list(config["steppers"]), list(config["problems"])
        cells: list[Cell] = []
        skips: list[Skip] = []
        for s in steppers:
            if s not in want_s:
                skips.append(Skip(self.name, s, "", f"stepper {s!r} is not in this experiment's "
                                  f"stepper set ({', '.join(want_s)}; config `steppers`)"))
        for p in problems:
            if p not in want_p:
                skips.append(Skip(self.name, "", p, f"problem {p!r} is not in this experiment's "
                                  f"problem set ({', '.join(want_p)}; config `problems`)"))
        for s in steppers:
            if s not in want_s:
                continue
            stepper = get_stepper(s)
            for p in problems:
                if p not in want_p:
                    continue
                problem = get_problem(p)
                if isinstance(stepper, AdaptiveStepper):
                    skips.append(Skip(self.name, s, p, "adaptive stepper: it chooses its own steps"))
                    continue
                if problem.newtonian is None:
                    skips.append(Skip(self.name, s, p, f"problem {p!r} has no positions "
                                      "(not Newtonian)"))
                    continue
                try:
                    check_compatible(stepper, problem)
                except IncompatibleError as exc:
                    skips.append(Skip(self.name, s, p, str(exc)))
                    continue
                cells.append(Cell(self.name, s, p))
        return cells, skips

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """The error at `n_steps` steps for each step size of `step_sizes`, measured against the
        certified reference.

        Parameters
        ----------
        cell : Cell, a configured (stepper, problem) pair.
        config : mapping, `n_steps` (< 2 is an `InputError`), `h_max`, `h_min`, `points_per_decade`.

        Returns
        -------
        DataFrame: one row per step size.
        """
        stepper = get_stepper(cell.stepper)
        problem = get_problem(cell.problem)
        n = int(config["n_steps"])
        if n < 2:
            raise InputError(f"`n_steps` must be at least 2, got {n}")
        hs = step_sizes(float(config["h_max"]), float(config["h_min"]),
                        int(config["points_per_decade"]))
        y0 = problem.ensemble(int(config["ensemble"]), seed=int(config["seed"]))
        nq = len(problem.newtonian.positions)
        growth_n = np.unique(np.geomspace(max(n // 100, 1), n,
                                          int(config.get("growth_points", 9))).astype(np.int64))
        times = np.unique(np.concatenate([problem.t0 + n * hs, problem.t0 + growth_n * hs[-1]]))
        ref = reference(problem, times, y0)
        records = []
        for h in hs:
            i = int(np.argmin(np.abs(times - (problem.t0 + n * h))))
            exact = ref.y[i]
            q_scale = max(float(np.max(np.abs(exact[:nq]))), tol.EPS)
            y_scale = max(float(np.max(np.abs(exact))), tol.EPS)
            started = time.perf_counter()
            message = ""
            try:
                tr = stepper.integrate(problem, h=float(h), n_steps=n, y0=y0)
                with np.errstate(all="ignore"):
                    d = np.abs(tr.final - exact)
                err = float(np.max(d[:nq])) / q_scale if np.all(np.isfinite(d)) else math.inf
                state_err = float(np.max(d)) / y_scale if np.all(np.isfinite(d)) else math.inf
            except StepFailure as exc:
                err = state_err = math.nan
                message = f"step failure: {exc}"
            records.append({
                "h": float(h), "n_steps": n, "t_end": float(problem.t0 + n * h), "error": err,
                "state_error": state_err, "reference_error": float(np.max(ref.error[i])) / q_scale,
                "wall_s": time.perf_counter() - started, "message": message,
            })
        rows = pd.DataFrame(records)
        first = rows.error.iloc[0]
        rows["truncation_estimate"] = first * (rows.h / rows.h.iloc[0]) ** (_order(stepper) + 1)
        rows["series"] = "sweep"
        rows = pd.concat([rows, _growth(stepper, problem, float(hs[-1]), growth_n, y0, ref, times, nq)],
                         ignore_index=True)
        rows["stepper"] = stepper.info.name
        rows["problem"] = problem.name
        rows["ensemble_size"] = y0.shape[1]
        return rows[ROW_COLUMNS]

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """The roundoff floor per cell (the smallest error and its step) and whether the smallest
        step is rounding-limited; verdict 'measured', or 'failed' when no error is finite.

        Parameters
        ----------
        rows : DataFrame, one row per step size of each cell.
        config : mapping, not read.

        Returns
        -------
        DataFrame: SUMMARY_COLUMNS.
        """
        if rows.empty:
            return pd.DataFrame(columns=SUMMARY_COLUMNS)
        out = []
        series = rows["series"] if "series" in rows else pd.Series("sweep", index=rows.index)
        for (s, p), g_all in rows.groupby(["stepper", "problem"], sort=False):
            g = g_all[series.loc[g_all.index].fillna("sweep") == "sweep"].sort_values("h", ascending=False)
            grow = g_all[series.loc[g_all.index] == "growth"]
            finite = g[np.isfinite(g.error)]
            messages = [m for m in g.message.fillna("") if m]
            rec: dict[str, Any] = {
                "stepper": s, "problem": p, "n_steps": int(g.n_steps.iloc[0]),
                "h_min": float(g.h.min()), "h_max": float(g.h.max()),
                "floor_error": math.nan, "floor_h": math.nan, "floor_eps": math.nan,
                "error_at_h_min": float(g.error.iloc[-1]),
                "truncation_at_h_min": float(g.truncation_estimate.iloc[-1]),
                "rounding_limited": False,
                "reference_error": float(g.reference_error.max()),
                "growth_exponent": _growth_exponent(grow),
                "verdict": "failed" if finite.empty else "measured",
                "wall_s": float(g.wall_s.sum()), "message": "; ".join(messages[:1]),
            }
            if not finite.empty:
                k = int(np.argmin(finite.error.values))
                rec.update(floor_error=float(finite.error.iloc[k]), floor_h=float(finite.h.iloc[k]),
                           floor_eps=float(finite.error.iloc[k]) / tol.EPS)
                last = g.iloc[-1]
                rec["rounding_limited"] = bool(
                    np.isfinite(last.error)
                    and last.error > tol.ROUNDOFF_TRUNCATION_FACTOR * last.truncation_estimate
                )
            out.append(rec)
        return pd.DataFrame(out, columns=SUMMARY_COLUMNS)


def _order(stepper) -> int:
    """The method's order from its coefficients (`harness.facts`), else its claimed order."""
    order = method_facts(stepper).order
    return int(order if order is not None else stepper.info.claimed_order or 2)


def _growth(stepper, problem, h: float, steps: np.ndarray, y0: np.ndarray, ref, times: np.ndarray,
            nq: int) -> pd.DataFrame:
    """The growth series: the relative position error after each of `steps` steps of size h."""
    started = time.perf_counter()
    message = ""
    try:
        tr = stepper.integrate(problem, h=h, n_steps=int(steps[-1]), y0=y0, save_steps=steps)
    except StepFailure as exc:
        tr, message = None, f"step failure: {exc}"
    records = []
    for k, n_k in enumerate(steps):
        i = int(np.argmin(np.abs(times - (problem.t0 + n_k * h))))
        exact = ref.y[i]
        q_scale = max(float(np.max(np.abs(exact[:nq]))), tol.EPS)
        err = math.nan
        if tr is not None:
            with np.errstate(all="ignore"):
                d = np.abs(tr.y[k] - exact)
            err = float(np.max(d[:nq])) / q_scale if np.all(np.isfinite(d)) else math.inf
        records.append({"h": h, "n_steps": int(n_k), "t_end": float(problem.t0 + n_k * h),
                        "error": err, "state_error": math.nan, "truncation_estimate": math.nan,
                        "reference_error": float(np.max(ref.error[i])) / q_scale,
                        "wall_s": 0.0, "message": message, "series": "growth"})
    rows = pd.DataFrame(records)
    rows.loc[rows.index[-1], "wall_s"] = time.perf_counter() - started
    rows["stepper"] = stepper.info.name
    rows["problem"] = problem.name
    rows["ensemble_size"] = y0.shape[1]
    return rows[ROW_COLUMNS]


def _growth_exponent(grow: pd.DataFrame) -> float:
    """Theil-Sen slope of log error against log n over the growth series (NaN below 3 points)."""
    g = grow[np.isfinite(grow["error"].astype(float)) & (grow["error"].astype(float) > 0)]
    if len(g) < 3:
        return math.nan

    return float(stats.theilslopes(np.log(g["error"].astype(float)), np.log(g["n_steps"].astype(float)))[0])


register_experiment(RoundoffExperiment())
