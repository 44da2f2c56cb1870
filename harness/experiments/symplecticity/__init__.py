"""Symplecticity: is the one-step map's Jacobian J symplectic, J^T Omega J = Omega?

Every problem q'' = a(q) whose force is a weighted gradient, a = -W^-1 grad V(q) with W diagonal
(masses; derived from da/dq, `harness.experiments.common.hamiltonian_weights`), applies: its flow
preserves dq ^ W dv, i.e. S J S^-1 is symplectic for Omega = [[0, I], [-I, 0]] in the state's own
(q, v) order, with S = diag(sqrt(W) / s_q, sqrt(W) / s_v) (s_q, s_v: the largest position and
velocity over the base states; a uniform scaling of q and of v keeps a map symplectic).
For one (stepper, problem) cell:

1. Base states: `states` points along the problem's orbit: the start and points over one
   natural period (`Problem.time_scale`; or from t0 to `t_end`) divided evenly, and half of them
   where the motion is fastest along the span (largest Jacobian spectral radius: a pericentre, a
   close encounter), so a Kepler orbit is probed at pericentre and apocentre alike
   (`harness.experiments.common.period_states`). The step is the problem's h
   (`Problem.time_scale`; or `h`).
2. J by fourth-order central differences of the stepper's one-step map
   (`Stepper.integrate(n_steps=1)`): every base state and every perturbation y +- delta e_j,
   y +- 2 delta e_j (delta = SYMPLECTIC_FD_DELTA of s_q for a position, of s_v for a velocity,
   and delta / 4, delta / 16: per state the finer of the two neighbouring steps that agree
   best, so a close encounter gets a step below its own length scale) is one member of a
   single ensemble call. Complex steps are not available: steppers
   and compiled right-hand sides work in real float64.
3. deviation = max over base states of ||J^T Omega J - Omega||_F / ||J||_F^2 for J = S J S^-1 (the finite
   difference error E in J enters as E^T Omega J + J^T Omega E, so this ratio measures it
   relative to J); `raw_deviation` is max ||J^T Omega J - Omega||_max.
4. Verdicts (thresholds in `harness.tolerances`). Claimed symplectic must stay at the cell's
   finite-difference level (`symplectic`), else `claim-false`: max(SYMPLECTIC_FD_TOL,
   SYMPLECTIC_GAP_FACTOR x the largest relative gap between the Jacobians of the two neighbouring
   difference steps), since a map with more arithmetic per step has more rounding in its
   quotients. Claimed not symplectic must be clearly above SYMPLECTIC_FD_TOL, deviation >=
   SYMPLECTIC_CLEAR_FACTOR x SYMPLECTIC_FD_TOL (`non-symplectic`), else `claim-false`, unless the
   map is itself within that of the exact flow at the base states (`step_error`, against the
   certified reference: a method this accurate at this step or tolerance cannot show a defect
   from symplecticity larger than its error), or the deviation lies between the two levels on
   every problem (inconclusive); both are `not-measurable`. A map of a
   non-symplectic method can still be symplectic on one problem (the trapezoidal rule on a
   linear problem is the Cayley transform, which is), so such a cell is `symplectic-here` and
   passes as long as the same method is clearly non-symplectic on another problem of the run.

Multistep methods (`history_length` > 1) map k past states to the next: the map from one
observed state (x_n, v_n) that `integrate(n_steps=1)` measures is their starting procedure, not
the method, and symplecticity of a multistep method is defined through its underlying one-step
method (HLW XV.4), so they are skipped with that reason. The exception is Stormer's two-step
rule with its Taylor start and central-difference velocity (`SecondOrderMultistep`): in exact
arithmetic its observed map (x_n, v_n) -> (x_{n+1}, v_{n+1}) is velocity Verlet (HLW I.1.4), a
genuine one-step map, and that is what is measured. Adaptive steppers run at a loose `adaptive_tol`
(1e-4: their defect must show far above the finite-difference level; at 1e-6 Radau IIA on the
pendulum came within a factor 1.2 of the threshold) over one natural period (an output step
caps the solver's internal step; a shorter one would leave the solver's error, and with it the
defect, below the finite-difference level) at `adaptive_states` base states (each member costs
a solver call).

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed. (2006), VI.2-VI.4
(symplectic maps; symplectic Runge-Kutta and partitioned methods), VI.3 (trapezoidal rule as a
non-symplectic but conjugate-symplectic method); course material 004_bfdbb1594143ed8b.txt
(symplectic integrators, Forest-Ruth).
"""

from __future__ import annotations

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
    hamiltonian_reason,
    hamiltonian_weights,
    period_states,
    problem_cells,
)
from harness.experiments.symplecticity.section import SECTION
from harness.ground_truth import reference
from harness.registry import get_problem, get_stepper
from harness.step_loops import fastest
from harness.stepper import AdaptiveStepper, StepFailure, Stepper

__all__ = ["SymplecticityExperiment", "one_step_jacobians", "symplectic_deviation",
           "canonical_form", "ROW_COLUMNS", "SUMMARY_COLUMNS", "SECTION"]

ROW_COLUMNS = [
    "stepper", "problem", "state", "h", "tol", "deviation", "raw_deviation", "jacobian_norm",
    "fd_gap", "step_error", "ensemble_size", "wall_s", "message",
]
SUMMARY_COLUMNS = [
    "stepper", "problem", "h", "tol", "states", "deviation", "raw_deviation", "threshold", "step_error",
    "claimed_symplectic", "verdict", "passed", "wall_s", "message",
]


def canonical_form(dim: int) -> np.ndarray:
    """Omega = [[0, I], [-I, 0]] for a state ordered (q..., v...).

    Parameters
    ----------
    dim : int, the state's dimension (even: positions, then velocities).

    Returns
    -------
    ndarray, shape (dim, dim)
    """
    n = dim // 2
    omega = np.zeros((dim, dim))
    omega[:n, n:] = np.eye(n)
    omega[n:, :n] = -np.eye(n)
    return omega


def symplectic_deviation(J: np.ndarray) -> tuple[float, float]:
    """(||J^T Omega J - Omega||_F / ||J||_F^2, ||J^T Omega J - Omega||_max) of one Jacobian.

    Parameters
    ----------
    J : ndarray, shape (dim, dim), a one-step map's Jacobian in scaled coordinates.

    Returns
    -------
    (float, float): the relative Frobenius deviation and the largest entry's deviation.
    """
    omega = canonical_form(J.shape[0])
    D = J.T @ omega @ J - omega
    return float(np.linalg.norm(D) / np.linalg.norm(J) ** 2), float(np.max(np.abs(D)))


def one_step_jacobians(
    stepper: Stepper, problem, states: np.ndarray, h: float, *, delta_rel: float | None = None,
    delta: np.ndarray | None = None,
) -> np.ndarray:
    """Jacobians (S, dim, dim) of the stepper's one-step map at the states (dim, S), by
    fourth-order central differences, all perturbations as one ensemble. `delta` (dim,) gives
    each component's difference step; by default one step for every component.

    Parameters
    ----------
    stepper : Stepper, a one-step method.
    problem : Problem
    states : ndarray, shape (dim, S), the base states.
    h : float, the step.
    delta_rel : float, optional, the difference step relative to the states' scale (default
        SYMPLECTIC_FD_DELTA).
    delta : ndarray, shape (dim,), optional, per-component difference steps (override `delta_rel`).

    Returns
    -------
    ndarray, shape (S, dim, dim)
    """
    delta_rel = tol.SYMPLECTIC_FD_DELTA if delta_rel is None else delta_rel
    dim, S = states.shape
    if delta is None:
        # One step size for every component: the map mixes them, so rounding in any output is
        # relative to the largest component, and a near-zero component (a velocity at a turning
        # point) must not shrink its difference step to the rounding level.
        largest = float(np.max(np.abs(states)))
        delta = np.full(dim, delta_rel * (largest if largest > 0.0 else 1.0))
    offsets = (1.0, -1.0, 2.0, -2.0)
    members = np.empty((dim, S, dim, len(offsets)))
    for j in range(dim):
        for k, m in enumerate(offsets):
            y = states.copy()
            y[j] += m * delta[j]
            members[:, :, j, k] = y
    Y = members.reshape(dim, -1)
    tr = stepper.integrate(problem, h=h, n_steps=1, y0=Y)
    out = tr.final.reshape(dim, S, dim, len(offsets))
    d1 = (out[..., 0] - out[..., 1]) / 2.0  # (dim_out, S, dim_in)
    d2 = (out[..., 2] - out[..., 3]) / 4.0
    J = (4.0 * d1 - d2) / 3.0 / delta[None, None, :]
    return np.transpose(J, (1, 0, 2))


class SymplecticityExperiment(Experiment):
    finite_columns = ("h", "wall_s")
    description = "max ||J^T Omega J - Omega|| of the one-step map's Jacobian, against the claim."
    default_config: Mapping[str, Any] = {
        "h": None,
        "t_end": None,
        "states": 8,
        "adaptive_states": 2,
        "adaptive_tol": 1e-4,
        "adaptive_output_periods": 1.0,
    }
    quick_config: Mapping[str, Any] = {"states": 4, "adaptive_states": 1}

    def cells(self, steppers, problems, config):
        """The pairs whose force is a weighted gradient, run by a one-step map (a multistep loop
        with a starter is skipped, saying why); the settings checked first.

        Parameters
        ----------
        steppers, problems : sequence of str, the names asked for.
        config : mapping, the state counts and adaptive settings (checked).

        Returns
        -------
        (list of Cell, list of Skip): kept pairs, and skipped ones with the reason.
        """
        check_config(config, counts=("states", "adaptive_states"),
                     positives=("adaptive_tol", "adaptive_output_periods"),
                     optional_positives=("h", "t_end"))
        cells, skips = problem_cells(self.name, steppers, problems, hamiltonian_reason)
        kept = []
        for c in cells:
            reason = _not_one_step(get_stepper(c.stepper))
            if reason:
                skips.append(Skip(self.name, c.stepper, c.problem, reason))
            else:
                kept.append(c)
        return kept, skips

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """The Jacobian's deviation from symplecticity at each base state (module item 1 on).

        Parameters
        ----------
        cell : Cell, a (stepper, problem) pair.
        config : mapping, `states`, `h` and the adaptive settings.

        Returns
        -------
        DataFrame: one row per base state.
        """
        return _measure(get_stepper(cell.stepper), get_problem(cell.problem), config)

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """The largest deviation per cell against its threshold, and the verdict on the
        method's symplecticity claim.

        Parameters
        ----------
        rows : DataFrame, one row per base state of every cell.
        config : mapping, unused.

        Returns
        -------
        DataFrame: one row per cell.
        """
        if rows.empty:
            return pd.DataFrame(columns=SUMMARY_COLUMNS)
        cells = []
        for (s, p), g in rows.groupby(["stepper", "problem"], sort=False):
            dev = g.deviation.to_numpy(dtype=float)
            gap = g["fd_gap"].to_numpy(dtype=float) if "fd_gap" in g else np.array([np.nan])
            gap = float(np.max(gap[np.isfinite(gap)])) if np.isfinite(gap).any() else 0.0
            step_error = float(g["step_error"].max()) if "step_error" in g else float("nan")
            cells.append({
                "stepper": s, "problem": p, "h": float(g.h.iloc[0]), "tol": float(g.tol.iloc[0]),
                "states": int(len(g)),
                "deviation": float(np.max(np.where(np.isnan(dev), np.inf, dev))),
                "raw_deviation": float(np.max(g.raw_deviation.fillna(np.inf))),
                "threshold": max(tol.SYMPLECTIC_FD_TOL, tol.SYMPLECTIC_GAP_FACTOR * gap),
                "wall_s": float(g.wall_s.iloc[0]),
                "message": str(g.message.iloc[0] or ""), "step_error": step_error,
            })
        clear = tol.SYMPLECTIC_CLEAR_FACTOR * tol.SYMPLECTIC_FD_TOL
        shown = {c["stepper"] for c in cells if c["deviation"] >= clear}
        out = []
        for c in cells:
            info = get_stepper(c["stepper"]).info
            c["claimed_symplectic"] = bool(info.symplectic)
            d = c["deviation"]
            notes = [c["message"]] if c["message"] else []
            if info.symplectic:
                level = c["threshold"]
                c["verdict"] = "symplectic" if d <= level else "claim-false"
                if c["verdict"] == "claim-false":
                    notes.append(f"claimed symplectic but ||J^T Omega J - Omega|| / ||J||^2 = {d:.3g} "
                                 f"exceeds the finite-difference level {level:.3g}")
            else:
                c["threshold"] = tol.SYMPLECTIC_FD_TOL
                if d >= clear:
                    c["verdict"] = "non-symplectic"
                elif c["stepper"] in shown:
                    c["verdict"] = "symplectic-here"
                    notes.append(f"the map is symplectic on this problem to {d:.3g} (below {clear:.3g}); "
                                 "the method is clearly non-symplectic on another problem of this run")
                elif np.isfinite(c["step_error"]) and c["step_error"] < clear:
                    c["verdict"] = "not-measurable"
                    notes.append(f"not measurable: the map is within {c['step_error']:.3g} of the exact "
                                 f"flow at this step or tolerance, below what the difference quotients "
                                 f"resolve ({clear:.3g}), so it cannot show a defect from symplecticity")
                elif d > tol.SYMPLECTIC_FD_TOL:
                    c["verdict"] = "not-measurable"
                    notes.append(f"not measurable: the deviation {d:.3g} is above the finite-difference "
                                 f"level {tol.SYMPLECTIC_FD_TOL:.3g} but not clearly ({clear:.3g}) on any "
                                 "problem of this run")
                else:
                    c["verdict"] = "claim-false"
                    notes.append(f"claimed not symplectic but the deviation {d:.3g} is not clearly above "
                                 f"the finite-difference level ({clear:.3g}) on any problem of this run")
            c["passed"] = c["verdict"] != "claim-false"
            c["message"] = "; ".join(notes)
            out.append(c)
        return pd.DataFrame(out, columns=SUMMARY_COLUMNS)


def _not_one_step(stepper: Stepper) -> str | None:
    # Stormer's two-step rule with its Taylor start is velocity Verlet written in positions; a
    # multistep loop with a starter (`starter`) is not one map of phase space
    started = getattr(stepper, "starter", None) is not None
    if stepper.history_length > 1 and (started or not isinstance(stepper.coefficients, SecondOrderMultistep)):
        return (f"stepper {stepper.info.name!r} is a {stepper.history_length}-step method: the map "
                "from one observed state measures its starting procedure, not the method, and a "
                "multistep method's symplecticity is defined through its underlying one-step "
                "method (HLW XV.4)")
    return None


def _base_states(problem, n: int, config: Mapping[str, Any]) -> np.ndarray:
    """The start and n - 1 states along the orbit (`common.period_states`)."""
    return period_states(problem, n, config.get("t_end"))


def _measure(stepper: Stepper, problem, config: Mapping[str, Any]) -> pd.DataFrame:
    h = fixed_plan(problem, {"h": config.get("h")}, 1)[0]
    tolerance, n_states = float("nan"), int(config["states"])
    if isinstance(stepper, AdaptiveStepper):
        tolerance = float(config["adaptive_tol"])
        stepper = stepper.with_tolerance(tolerance)
        h = float(config["adaptive_output_periods"]) * problem.time_scale.period
        n_states = int(config["adaptive_states"])
    states = _base_states(problem, n_states, config)
    nq = len(problem.newtonian.positions)
    block = [float(np.max(np.abs(states[:nq]))), float(np.max(np.abs(states[nq:])))]
    block = [b if b > 0.0 else 1.0 for b in block]
    delta = tol.SYMPLECTIC_FD_DELTA * np.repeat(block, nq)
    weights = hamiltonian_weights(problem, states)
    if weights is None:  # checked when the cells were listed, at fewer states
        weights = np.ones(nq)
    S = np.concatenate([np.sqrt(weights) / block[0], np.sqrt(weights) / block[1]])

    runner = fastest(stepper, problem)
    started = time.perf_counter()
    message = ""
    try:
        # Difference steps delta, delta/4, delta/16: per state, the finer of the two neighbours
        # that agree best (truncation falls as delta^4 until rounding takes over). A close
        # approach needs a step far below the state's overall scale.
        tries = [one_step_jacobians(runner, problem, states, h, delta=delta / 4.0**k)
                 for k in range(tol.SYMPLECTIC_FD_REFINEMENTS + 1)]
        tries = [S[None, :, None] * J / S[None, None, :] for J in tries]
        with np.errstate(all="ignore"):
            gaps = np.stack([np.linalg.norm(tries[k + 1] - tries[k], axis=(1, 2))
                             for k in range(len(tries) - 1)])
        best = np.argmin(np.where(np.isfinite(gaps), gaps, np.inf), axis=0) + 1
        Js = np.stack([tries[best[i]][i] for i in range(states.shape[1])])
        fd_gaps = [float(gaps[best[i] - 1, i]) for i in range(states.shape[1])]
    except StepFailure as exc:
        Js = np.full((states.shape[1], problem.dim, problem.dim), np.nan)
        fd_gaps = [float("nan")] * states.shape[1]
        message = f"step failure: {exc}"
    step_error = _one_step_error(runner, problem, states, h) if not message else float("nan")
    wall = time.perf_counter() - started
    records = []
    for k, J in enumerate(Js):
        if np.all(np.isfinite(J)):
            dev, raw = symplectic_deviation(J)
            norm = float(np.linalg.norm(J))
        else:
            dev = raw = norm = float("nan")
        records.append({
            "stepper": stepper.info.name, "problem": problem.name, "state": k, "h": h,
            "tol": tolerance, "deviation": dev, "raw_deviation": raw, "jacobian_norm": norm,
            "fd_gap": fd_gaps[k] / norm if norm > 0.0 else float("nan"), "step_error": step_error,
            "ensemble_size": int(states.shape[1] * problem.dim * 4), "wall_s": wall,
            "message": message, "implementation": runner.info.name,
        })
    return pd.DataFrame(records, columns=[*ROW_COLUMNS, "implementation"])


def _one_step_error(runner: Stepper, problem, states: np.ndarray, h: float) -> float:
    """max |map(y) - flow_h(y)| / max |y| over the base states, against the certified reference:
    how far the map is from the exact (symplectic) flow. A map this close to it can only be as
    far from symplectic as that, which finite differences may not resolve."""
    try:
        with np.errstate(all="ignore"):
            mapped = runner.integrate(problem, h=h, n_steps=1, y0=states).final
        exact = reference(problem, np.array([problem.t0 + h]), states).y[-1]
    except (StepFailure, ValueError, ArithmeticError):
        return float("nan")
    return float(np.max(np.abs(mapped - exact)) / max(float(np.max(np.abs(states))), tol.SCALE_FLOOR))


register_experiment(SymplecticityExperiment())
