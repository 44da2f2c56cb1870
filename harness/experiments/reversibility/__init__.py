"""Time reversibility: N steps forward, time reversed, N steps back; how far from the start?

A symmetric method (Phi_{-h} = Phi_h^{-1}) returns to its start exactly in exact arithmetic, on
any problem; only rounding remains. A method that is not symmetric misses by about its
truncation error, ~h^p T, far above rounding. One cell is one (stepper, problem, N):

1. Every problem whose flow is reversible applies: q'' = a(q) (autonomous, velocity-free force),
   or declared conservative (`harness.experiments.common.reversible_reason`). An ensemble
   (member 0 is the problem's own start, the others perturbed by the problem's
   `ensemble_perturbation`, or `perturbation`) takes `Stepper.round_trip`: N steps of the
   problem's step size h (`Problem.time_scale`, the same h for every stepper; or `h`), h -> -h
   (the stepper's own `_reverse`, which also reorders a multistep history), N steps back. A
   `t_end` setting replaces the list of N by the one N that reaches it. An N whose span would
   leave the dynamical regime of the problem's span is cut to the largest N that does not
   (`harness.regimes.regime_end`), and that cell's message says why.
2. The return error is the max-norm of (returned - start) over components and members; in
   ulps it is divided by eps * max|y_start| per member (the largest over members is reported).
3. What rounding explains. Each step of a symmetric method adds about one ulp of rounding, and
   the flow carries it along: on integrable problems with shear (Kepler, the pendulum) a
   perturbation grows linearly in time. The flow's sensitivity A(N) = ||dPhi_t(y0)||_inf over
   the span t = N h is measured once per (problem, N) by central differences along every
   coordinate on float64 Taylor orbits (`flow_amplification`). The
   rounding bound is REVERSIBILITY_ULPS_PER_STEP * N * max(1, A(N)) ulps: growth no faster
   than N eps where the flow does not amplify (harmonic), and the flow's own amplification
   where it does.
4. Verdicts. Claimed symmetric: within the bound (`reversible`), else `claim-false`. Not
   claimed symmetric: above the bound (`irreversible`, the claim verified); within it,
   `reversible-here` (passes) when the same method is irreversible in another cell of the run
   (another N or problem: a problem whose h resolves its fastest moment, a close encounter,
   leaves a method's truncation below rounding on its slow stretches), else `claim-false` (the
   method behaves symmetrically although it says it is not).
   `growth_exponent` is the log-log slope of the return error (ulps) against N over a
   (stepper, problem)'s cells.

Adaptive steppers run at `adaptive_tol` (their truncation must show above rounding) with
`adaptive_steps` output steps of `adaptive_output_periods` natural periods each (an output step
caps the solver's internal step) and `adaptive_ensemble` members (each output step costs a
solver call per member).
References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed. (2006), II.3
(the adjoint Phi_h^* = Phi_{-h}^{-1}; symmetric methods), V.1 (reversibility); course material
004_bfdbb1594143ed8b.txt (the time-reversibility of symplectic integrators, run n steps forward
and back to the start; the palindromic Forest-Ruth step).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.coefficients import SecondOrderMultistep
from harness.experiments.base import Cell, Experiment, Skip, register_experiment
from harness.experiments.common import (
    check_config,
    fixed_plan,
    initial_ensemble,
    long_run_steps,
    perturbation_used,
    problem_cells,
    reversible_reason,
)
from harness.experiments.reversibility.section import SECTION
from harness.flow import flow_amplification
from harness.registry import get_problem, get_stepper
from harness.step_loops import fastest
from harness.stepper import AdaptiveStepper, StepFailure, Stepper

__all__ = ["ReversibilityExperiment", "flow_amplification", "rounding_bound_ulps", "ROW_COLUMNS",
           "SUMMARY_COLUMNS", "one_sided_reason", "SECTION"]

ROW_COLUMNS = [
    "stepper", "problem", "steps", "h", "tol", "t_span", "return_error", "return_error_ulps",
    "flow_amplification", "rounding_bound_ulps", "perturbation", "ensemble_size", "wall_s", "message",
]
SUMMARY_COLUMNS = [
    "stepper", "problem", "steps", "h", "tol", "return_error", "return_error_ulps",
    "rounding_bound_ulps", "flow_amplification", "claimed_symmetric", "growth_exponent",
    "verdict", "passed", "perturbation", "ensemble_size", "wall_s", "message",
]


def rounding_bound_ulps(n_steps: int, amplification: float) -> float:
    """What rounding explains for a symmetric method's N-step round trip, in ulps of the state:
    REVERSIBILITY_ULPS_PER_STEP ulps per step, carried by the flow's sensitivity A(N) >= 1.

    Parameters
    ----------
    n_steps : int, N, the steps each way.
    amplification : float, the flow's sensitivity A(N) (non-finite read as 1).

    Returns
    -------
    float: ulps of the state.
    """
    a = amplification if np.isfinite(amplification) else 1.0
    return tol.REVERSIBILITY_ULPS_PER_STEP * n_steps * max(1.0, a)




def one_sided_reason(stepper) -> str | None:
    """Why a round trip judges only the positions of a symmetric multistep recurrence run with a
    starter: its observed velocities are reconstructed from past points only (one-sided in time),
    so the observed (x, v) map is not the symmetric recurrence, and a full-state round trip would
    measure the reconstruction (its error ~ h^(p+1)). The recurrence itself is reversible as a
    map of its k-point position history (a symmetric table, alpha_j = alpha_(k-j), beta_j =
    beta_(k-j), is its own adjoint: run with -h from the reversed history it retraces it; HNW I,
    III.10; HLW XV.1), so the positions come back to rounding.

    Parameters
    ----------
    stepper : Stepper

    Returns
    -------
    str or None: the reason, for a symmetric second-order multistep stepper with a starter; None
        for any other.
    """
    if (getattr(stepper, "history_length", 1) > 1 and getattr(stepper, "starter", None) is not None
            and stepper.info.symmetric and isinstance(stepper.coefficients, SecondOrderMultistep)):
        return (f"positions only: stepper {stepper.info.name!r} reconstructs its velocities from past "
                f"positions ({stepper.info.extra.get('velocity', 'one-sided')}), so its observed state "
                "is not the symmetric recurrence's; the recurrence is reversible on its position "
                "history")
    return None


class ReversibilityExperiment(Experiment):
    finite_columns = ("steps", "h", "t_span", "flow_amplification", "rounding_bound_ulps", "wall_s")
    description = "Return error of N steps forward and N back (ulps), against the symmetry claim."
    default_config: Mapping[str, Any] = {
        "h": None,
        "t_end": None,
        "perturbation": None,
        "steps": [100, 1_000, 10_000, 100_000],
        "implicit_steps": [100, 1_000, 10_000],
        # Two spans a factor ~3 apart give the growth exponent; a per-member black-box solver at
        # tol 1e-8 costs ~1 ms a step here, so 30 periods made these cells most of the run's time.
        "adaptive_steps": [3, 10],
        "adaptive_tol": 1e-8,
        "adaptive_output_periods": 1.0,
        "adaptive_ensemble": 1,
        "ensemble": 8,
        "seed": 0,
    }
    quick_config: Mapping[str, Any] = {
        "steps": [100, 1_000],
        "implicit_steps": [100],
        "adaptive_steps": [3],
        "ensemble": 4,
    }

    def cells(self, steppers, problems, config):
        """One cell per reversible pair and step count N; a one-sided stepper that starts more
        positions than its steps is skipped, saying why.

        Parameters
        ----------
        steppers, problems : sequence of str, the selection asked for.
        config : mapping, the step-count lists and ensemble sizes (checked).

        Returns
        -------
        (list of Cell, list of Skip): one cell per N, each with its `steps`.
        """
        check_config(config, counts=("ensemble", "adaptive_ensemble"),
                     count_lists=("steps", "implicit_steps", "adaptive_steps"),
                     positives=("adaptive_tol", "adaptive_output_periods"),
                     optional_positives=("h", "t_end", "perturbation"))
        pairs, skips = problem_cells(self.name, steppers, problems, reversible_reason)
        cells = []
        for c in pairs:
            stepper = get_stepper(c.stepper)
            kept = getattr(stepper, "kept_points", stepper.history_length)
            if one_sided_reason(stepper) and kept > stepper.history_length:
                skips.append(Skip(self.name, c.stepper, c.problem, (
                    f"stepper {c.stepper!r} starts {kept} positions for its velocity formula, more "
                    f"than its {stepper.history_length} steps: the starting values are not linked by "
                    "the recurrence, so the way back misses x_0 by the recurrence's local error "
                    "(h^(p+2)), not by rounding")))
                continue
            for n in _step_counts(get_stepper(c.stepper), get_problem(c.problem), config):
                cells.append(Cell(self.name, c.stepper, c.problem, (("steps", int(n)),)))
        return cells, skips

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """One round trip of N steps each way (module item 1).

        Parameters
        ----------
        cell : Cell, with its `steps` parameter N.
        config : mapping, `h`, ensemble and adaptive settings.

        Returns
        -------
        DataFrame: ROW_COLUMNS, one row (return error, relative and in ulps, the flow's
            amplification, the rounding bound).
        """
        stepper = get_stepper(cell.stepper)
        problem = get_problem(cell.problem)
        return _round_trip(stepper, problem, int(cell.param("steps")), config)

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """One row per (stepper, problem, N) with the growth exponent over N and the verdict
        on the symmetry claim.

        Parameters
        ----------
        rows : DataFrame, one row per round trip.
        config : mapping, unused.

        Returns
        -------
        DataFrame: SUMMARY_COLUMNS, a row per (stepper, problem, N).
        """
        if rows.empty:
            return pd.DataFrame(columns=SUMMARY_COLUMNS)
        out = []
        for (s, _p), g in rows.groupby(["stepper", "problem"], sort=False):
            stepper = get_stepper(s)
            g = g.sort_values("steps")
            exponent = _growth_exponent(g.steps.values, g.return_error_ulps.values)
            for _, r in g.iterrows():
                out.append(_judge(stepper, r, exponent))
        shown = {o["stepper"] for o in out if o["verdict"] == "irreversible"}
        for o in out:
            if o["verdict"] == "claim-false" and not o["claimed_symmetric"] and o["stepper"] in shown:
                o["verdict"], o["passed"] = "reversible-here", True
                o["message"] = (f"at {o['steps']} steps the round trip stays within rounding "
                                f"({o['return_error_ulps']:.3g} <= {o['rounding_bound_ulps']:.3g} ulps): "
                                "the truncation is below rounding here; the method is irreversible "
                                "in another cell of this run")
        return pd.DataFrame(out, columns=SUMMARY_COLUMNS)


def _step_counts(stepper: Stepper, problem, config: Mapping[str, Any]) -> list[int]:
    if isinstance(stepper, AdaptiveStepper):
        return list(config["adaptive_steps"])
    if config.get("t_end") is not None:
        return [fixed_plan(problem, config, 1)[1]]
    counts = list(config["steps"] if stepper.info.explicit else config["implicit_steps"])
    h = fixed_plan(problem, config, 1)[0]
    longest = long_run_steps(problem, h, max(counts))[0]  # within the span's dynamical regime
    return sorted({min(n, longest) for n in counts})


def _round_trip(stepper: Stepper, problem, n: int, config: Mapping[str, Any]) -> pd.DataFrame:
    h = fixed_plan(problem, config, n)[0]
    tolerance = float("nan")
    if isinstance(stepper, AdaptiveStepper):
        # An output step caps the solver's internal step: one natural period per output step
        # leaves the solver free to take the steps its tolerance allows.
        stepper = stepper.with_tolerance(float(config["adaptive_tol"]))
        tolerance = float(config["adaptive_tol"])
        h = float(config["adaptive_output_periods"]) * problem.time_scale.period
    size = int(config["adaptive_ensemble" if isinstance(stepper, AdaptiveStepper) else "ensemble"])
    y0 = initial_ensemble(problem, config, size)
    amplification = flow_amplification(problem, n * h)

    runner = fastest(stepper, problem)
    message = ""
    if not isinstance(stepper, AdaptiveStepper) and config.get("t_end") is None:
        longest = max(config["steps"] if stepper.info.explicit else config["implicit_steps"])
        capped, why = long_run_steps(problem, h, longest)
        message = why if capped == n else ""  # why the longest round trip is shorter
    started = time.perf_counter()
    try:
        start, back = runner.round_trip(problem, h=h, n_steps=n, y0=y0)
        positions_only = one_sided_reason(stepper)
        if positions_only:
            nq = len(problem.newtonian.positions)
            start, back = start[:nq], back[:nq]
            message = "; ".join(filter(None, [message, positions_only]))
        with np.errstate(all="ignore"):
            diff = np.abs(back - start)
        per_member = np.max(diff, axis=0)
        per_member = np.where(np.all(np.isfinite(diff), axis=0), per_member, np.inf)
        scale = np.max(np.abs(start), axis=0)
        error = float(np.max(per_member))
        ulps = float(np.max(per_member / (tol.EPS * np.maximum(scale, tol.EPS))))
        if not math.isfinite(error):
            message = "; ".join(filter(None, [message, "the state overflowed (non-finite) during "
                                                       "the round trip"]))
    except StepFailure as exc:
        error = ulps = float("inf")
        message = "; ".join(filter(None, [message, f"step failure: {exc}"]))
    wall = time.perf_counter() - started
    return pd.DataFrame([{
        "stepper": stepper.info.name, "problem": problem.name, "steps": n, "h": h, "tol": tolerance,
        "t_span": n * h, "return_error": error, "return_error_ulps": ulps,
        "flow_amplification": amplification,
        "rounding_bound_ulps": rounding_bound_ulps(n, amplification),
        "perturbation": perturbation_used(problem, config) if size > 1 else 0.0,
        "ensemble_size": int(y0.shape[1]), "wall_s": wall, "message": message,
        "implementation": runner.info.name,
    }], columns=[*ROW_COLUMNS, "implementation"])


def _growth_exponent(steps: np.ndarray, ulps: np.ndarray) -> float:
    ok = np.isfinite(ulps) & (ulps > 0)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(steps[ok].astype(float)), np.log(ulps[ok]), 1)[0])


def _judge(stepper: Stepper, r: pd.Series, exponent: float) -> dict:
    info = stepper.info
    bound = float(r.rounding_bound_ulps)
    ulps = float(r.return_error_ulps)
    within = math.isfinite(ulps) and ulps <= bound
    message = str(r.message or "")
    # The flow's amplification is a central difference of step REVERSIBILITY_FLOW_DELTA: once it
    # amplifies that step to the state's own size (A delta >= 1, sensitive dependence over this
    # span) the difference has left the linear regime, A is only a lower bound, and so is the
    # rounding bound built on it: a miss then says nothing about the method's symmetry.
    saturated = float(r.flow_amplification) * tol.REVERSIBILITY_FLOW_DELTA >= 1.0
    if not within and saturated:
        verdict = "not-measurable"
        message = "; ".join(filter(None, [message, (
            f"not measurable: over this span the flow amplifies a perturbation of "
            f"{tol.REVERSIBILITY_FLOW_DELTA:g} to the state's size (A = {float(r.flow_amplification):.3g}), "
            f"so the rounding bound ({bound:.3g} ulps) is only a lower bound and the return error "
            f"({ulps:.3g} ulps) cannot tell a symmetric method from one that is not")]))
    elif info.symmetric:
        verdict = "reversible" if within else "claim-false"
        if not within:
            message = "; ".join(filter(None, [message, (
                f"claimed symmetric but the round trip misses by {ulps:.3g} ulps, above the "
                f"{bound:.3g} ulps rounding explains")]))
    else:
        verdict = "irreversible" if not within else "claim-false"
        if within:
            message = "; ".join(filter(None, [message, (
                f"claimed not symmetric but the round trip returns within rounding ({ulps:.3g} <= "
                f"{bound:.3g} ulps): the method is symmetric or h is too small to show it")]))
    return {
        "stepper": info.name, "problem": r.problem, "steps": int(r.steps), "h": float(r.h),
        "tol": float(r.tol), "return_error": float(r.return_error), "return_error_ulps": ulps,
        "rounding_bound_ulps": bound, "flow_amplification": float(r.flow_amplification),
        "claimed_symmetric": bool(info.symmetric), "growth_exponent": exponent,
        "verdict": verdict, "passed": verdict != "claim-false",
        "perturbation": float(r.perturbation), "ensemble_size": int(r.ensemble_size),
        "wall_s": float(r.wall_s), "message": message,
    }


register_experiment(ReversibilityExperiment())
