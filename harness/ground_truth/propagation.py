"""Propagating a reference with heyoka's Taylor integrator at one precision level: integrators
built once per process, and bounded work (every reference has a work and time budget)."""

from __future__ import annotations

import math
import os
import threading
import time
from typing import Any

import heyoka as hy
import numpy as np

from harness import cache
from harness.errors import InputError, ReferenceError_, StiffReferenceError, WorkLimitError
from harness.ground_truth.levels import SOFTWARE_LEVELS, Level
from harness.problem import Problem
from harness.tolerances import (
    CERTIFIER_TOL_FACTOR,
    REFERENCE_STIFF_SHARE,
    REFERENCE_STIFF_STEPS,
    REFERENCE_TOL_FACTOR,
)
from harness.work_projection import projected_work

# -- work bounds ----------------------------------------------------------------------------------
# Every reference integration is bounded and interruptible. heyoka runs in compiled code, so it is
# driven in chunks (`propagate_grid(max_steps=...)`, resumed where it stopped: the same steps as
# one uninterrupted call); between chunks Python runs, so Ctrl-C and a cell's time limit
# (SIGALRM, also with --jobs 1) take effect, and the work so far is checked. Work is counted in
# float64-step units: a Taylor step costs `REFERENCE_STEP_COST[level]` of them (measured on this
# machine type for Kepler: long double ~10x, real128 ~300x a float64 step). After each chunk the
# work the whole span needs is projected from the rate of the recent steps
# (`harness.work_projection`), so a run whose steps shrink without end (a finite-time blow-up,
# where time stops advancing) stops a few chunks after it begins to stall instead of after the
# whole budget; a run projected or found
# to exceed `REFERENCE_MAX_WORK` units per member and precision, or running longer than
# `REFERENCE_MAX_SECONDS`, stops with `WorkLimitError` naming the limit and the environment
# variable that raises it. 1e8 units (~1e7 long double or ~3e5 real128 steps) is ~100x the
# largest catalogue reference; 900 s is ~100x all catalogue references together.
REFERENCE_STEP_COST = {"float64": 1.0, "longdouble": 10.0, "real128": 300.0, "real192": 1000.0}
REFERENCE_MAX_WORK = 1e8
REFERENCE_MAX_SECONDS = 900.0
# A chunk is this much work (~10 ms to ~1 s of compiled code between checks).
REFERENCE_CHUNK_WORK = 20_000


def _limit(env: str, default: float) -> float:
    raw = os.environ.get(env)
    if raw is None or raw == "":
        return default
    try:
        value = float(raw)
    except ValueError:
        raise InputError(f"`{env}` must be a positive number, got {raw!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"`{env}` must be a positive number, got {raw!r}")
    return value


# -- stiffness ------------------------------------------------------------------------------------
# A Taylor step of order p is stable only while h |lambda| stays below about p / e (its stability
# region grows like the order); on a stiff problem that bound, not the solution, sets the step,
# and the span needs about e |lambda| T / p steps (`REFERENCE_STIFF_STEPS`).
def _decay_rate(problem: Problem, t: float, y: np.ndarray, pars: np.ndarray) -> float:
    """The largest -Re(lambda) of the Jacobian at the float64 state `y` (0 when none decays)."""
    dyn = problem.dynamics(pars.reshape(-1, 1).astype(np.float64), size=1)
    jac = dyn.jac(float(t), np.ascontiguousarray(y, dtype=np.float64).reshape(-1, 1))[:, :, 0]
    with np.errstate(all="ignore"):
        lam = np.linalg.eigvals(jac) if np.all(np.isfinite(jac)) else np.array([np.nan])
    if not np.all(np.isfinite(lam)):
        return 0.0
    return max(0.0, float(np.max(-lam.real)))


def stiff_check(problem: Problem, level: Level, ta: Any, t_end: float, member: int,
                step: float | None = None) -> None:
    """Raise `StiffReferenceError` when, from the integrator's current state, the rest of the span
    needs more than `REFERENCE_STIFF_STEPS` steps held by the Jacobian's eigenvalue: the mean
    `step` of the last chunk (at the start, the solution's own time scale |y|/|y'|, the step
    accuracy alone would allow) reaches `REFERENCE_STIFF_SHARE` of the stability bound p/(e |lambda|).

    Parameters
    ----------
    problem : Problem
    level : Level, the integrator's precision level (for the message).
    ta : heyoka taylor_adaptive, the integrator, at its current time and state.
    t_end : float, the end of the span.
    member : int, the ensemble member (for the message).
    step : float, optional, the mean step of the last chunk (None at the start).
    """
    now = float(ta.time)
    pars = np.array([float(v) for v in ta.pars]) if len(ta.pars) else np.zeros(0)
    state = np.array([float(v) for v in ta.state])
    rate = _decay_rate(problem, now, state, pars)
    order = int(ta.order)
    steps = math.e * rate * max(t_end - now, 0.0) / order
    if rate <= 0 or steps <= REFERENCE_STIFF_STEPS:
        return
    if step is None:
        slope = problem.dynamics(pars.reshape(-1, 1), size=1).f(now, state.reshape(-1, 1))[:, 0]
        step = float(np.linalg.norm(state) / np.linalg.norm(slope)) if np.any(slope) else math.inf
    if not step * math.e * rate / order >= REFERENCE_STIFF_SHARE:
        return
    raise StiffReferenceError(
        f"problem {problem.name!r} is stiff for the explicit Taylor reference: at t = {now:.6g} "
        f"(member {member}, {level.name}) the Jacobian has an eigenvalue with real part "
        f"{-rate:.3g}, so Taylor steps of order {order} stay near p/(e |lambda|) = "
        f"{order / (math.e * rate):.3g} and reaching t = {t_end:.6g} needs about {steps:.3g} of "
        f"them (more than {REFERENCE_STIFF_STEPS:.0e}); a stiff problem's ground truth is its "
        "published end values, where the problem has them")


def _propagate_bounded(problem: Problem, level: Level, ta: Any, grid: np.ndarray, member: int,
                       started: float) -> tuple[Any, np.ndarray]:
    """`ta.propagate_grid(grid)` in chunks, within the work bounds (see above); returns
    (outcome, states at the grid points)."""
    max_work = _limit("HARNESS_REFERENCE_MAX_WORK", REFERENCE_MAX_WORK)
    max_seconds = _limit("HARNESS_REFERENCE_MAX_SECONDS", REFERENCE_MAX_SECONDS)
    cost = REFERENCE_STEP_COST.get(level.name, max(REFERENCE_STEP_COST.values()))
    chunk = max(20, int(REFERENCE_CHUNK_WORK / cost))
    t_start, t_end = float(grid[0]), float(grid[-1])
    rows: list[np.ndarray] = []
    remaining = grid
    stiff_check(problem, level, ta, t_end, member)
    steps = 0
    checkpoints = [(0, t_start)]  # (steps taken, time reached) after each chunk
    while True:
        result = ta.propagate_grid(remaining, max_steps=chunk)
        outcome, states = result[0], result[-1]
        rows.extend(states if not rows else states[1:])  # a resumed grid starts at the stop time
        steps += int(result[3])
        if outcome != hy.taylor_outcome.step_limit:
            return outcome, np.array(rows)
        now = float(ta.time)
        projected = cost * projected_work(checkpoints, steps, now, t_end)
        stiff_check(problem, level, ta, t_end, member, step=(now - checkpoints[-1][1]) / chunk)
        checkpoints.append((steps, now))
        where = (f"ground truth for problem {problem.name!r} failed in {level.name} at "
                 f"t = {now:.17g} (member {member}): reaching t = {t_end:.6g}")
        if math.isinf(projected):
            raise WorkLimitError(
                f"{where}: time stopped advancing over the later half of its {steps} Taylor "
                "steps (the step size fell below the time's resolution: a singularity or a "
                "finite-time blow-up of the solution)")
        if projected > max_work:
            raise WorkLimitError(
                f"{where} needs about {projected / cost:.3g} Taylor steps ({projected:.3g} work "
                f"units), more than the limit of {max_work:.3g} units "
                "(`HARNESS_REFERENCE_MAX_WORK`; set it higher to allow this)")
        elapsed = time.perf_counter() - started
        if elapsed > max_seconds:
            raise WorkLimitError(
                f"{where} took over {elapsed:.0f} s, more than the limit of {max_seconds:g} s "
                "(`HARNESS_REFERENCE_MAX_SECONDS`; set it higher to allow this)")
        remaining = np.concatenate([np.array([ta.time], dtype=grid.dtype), grid[len(rows):]])


# -- integrators ---------------------------------------------------------------------------------
integrators = cache.IntegratorPool()  # by (problem, level, tolerance)


def _integrator(problem: Problem, level: Level, tol: float) -> tuple[threading.Lock, Any]:
    return integrators.get((problem.fingerprint(), level.name, tol), lambda: _build(problem, level, tol))


def _build(problem: Problem, level: Level, tol: float):
    """heyoka's Taylor integrator for `problem` at `level` and tolerance `tol`."""
    sys = list(zip(problem.variables, problem.rhs, strict=True))
    kwargs: dict[str, Any] = {
        "tol": level.scalar(tol),
        "high_accuracy": True,
        "compact_mode": level.name in SOFTWARE_LEVELS or cache.compact_mode(problem),
    }
    if level.name != "float64":
        kwargs["fp_type"] = level.fp_type
    if problem.parameters:
        kwargs["pars"] = level.array(problem.parameter_values)
    start = level.array(problem.y0)
    return cache.interruptible(lambda: hy.taylor_adaptive(sys, start, **kwargs))


def reference_tol(level: Level) -> float:
    """heyoka's tolerance for a reference at `level`: its epsilon times REFERENCE_TOL_FACTOR.

    Parameters
    ----------
    level : Level (its `eps` is read).

    Returns
    -------
    float: the tolerance.
    """
    return level.eps * REFERENCE_TOL_FACTOR


def certifier_tol(cert: Level, level: Level) -> float:
    """heyoka's tolerance for the certifying rerun at `cert` of a reference at `level`.

    Parameters
    ----------
    cert : Level, the certifying level.
    level : Level, the level certified.

    Returns
    -------
    float: max(cert's epsilon, `reference_tol(level)` x CERTIFIER_TOL_FACTOR).
    """
    return max(cert.eps, reference_tol(level) * CERTIFIER_TOL_FACTOR)


def propagate(
    problem: Problem,
    level: Level,
    tol: float,
    times: np.ndarray,
    y0: np.ndarray,
    t0: float,
    pars: np.ndarray,
    published: bool = False,
) -> tuple[np.ndarray, float]:
    """States at `times` for every member, shaped (nt, dim, N), in the level's number type.
    With `published`, every member starts from the problem's exact published start values and
    constants (`Problem.published`, rounded once to the level), and a time equal to the published
    end time's float64 rounding is the exact published end time.

    Parameters
    ----------
    problem : Problem
    level : Level, the precision level.
    tol : float, heyoka's tolerance.
    times : ndarray, output times, increasing, > t0 or starting at t0.
    y0 : ndarray, shape (dim, N), initial states (float64).
    t0 : float, initial time.
    pars : ndarray, shape (P, N), parameter values.
    published : bool, optional, start from the published exact values (see above).

    Returns
    -------
    (ndarray, float): the states (nt, dim, N) in the level's type, and the wall time in seconds.
    """
    lock, ta = _integrator(problem, level, tol)
    prepend = times[0] > t0
    grid = level.array(np.concatenate([[t0], times]) if prepend else times)
    pub = problem.published if published else None
    if pub is not None and pub.t_end is not None:
        grid[grid.astype(np.float64) == pub.t_end_float] = level.exact([pub.t_end])[0]
    n_members = y0.shape[1]
    out = []
    start = time.perf_counter()
    with lock:
        for n in range(n_members):
            ta.state[:] = level.array(y0[:, n]) if pub is None else level.exact(pub.y0)
            ta.time = level.scalar(t0)
            if pars.shape[0]:
                ta.pars[:] = (level.array(pars[:, n]) if pub is None
                              else level.exact(list(pub.parameters.values())))
            outcome, states = _propagate_bounded(problem, level, ta, grid, n, start)
            if outcome != hy.taylor_outcome.time_limit:
                raise ReferenceError_(
                    f"ground truth for problem {problem.name!r} failed in {level.name} at "
                    f"t = {float(ta.time):.17g} (member {n}): heyoka stopped with {outcome} "
                    "(the solution blows up or becomes non-finite)"
                )
            states = states[1:] if prepend else states
            check = states.astype(np.float64)
            if not np.all(np.isfinite(check)):
                bad = int(np.argmax(~np.all(np.isfinite(check), axis=1)))
                raise ReferenceError_(
                    f"ground truth for problem {problem.name!r} is not finite in {level.name} at "
                    f"t = {times[bad]:.17g} (member {n})"
                )
            out.append(states)
    return np.stack(out, axis=-1), time.perf_counter() - start
