"""The float64 Taylor orbit of a problem, and the rates along it (`harness.scales` derives a
problem's time scale and perturbation from them, and re-exports these names).

heyoka's Taylor integrator (float64, tolerance eps) runs from y0 over [t0, t_end]; the orbit is
sampled at each of its adaptive steps and at `ORBIT_DENSE_POINTS` points inside each (dense
output), so close approaches, where the steps shrink, are sampled densely. These are points on
the orbit, not a certified reference (that is `harness.ground_truth`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import heyoka as hy
import numpy as np

from harness import cache
from harness import tolerances as tol

__all__ = ["Orbit", "sample_orbit", "jacobian_eigenvalues", "states_at", "fastest_times", "orbit_rates"]


@dataclass(frozen=True)
class Orbit:
    """A float64 Taylor orbit sampled at times t (n,), states y (dim, n); `complete` is False
    when the run stopped early (non-finite state or the step cap)."""

    t: np.ndarray
    y: np.ndarray
    complete: bool
    # set when the run stopped at a singularity (a non-finite state, or a failed Taylor step):
    # what stopped it, in words
    singular: str = ""

    def thinned(self) -> tuple[np.ndarray, np.ndarray]:
        """The samples the rates are read at: every one, or ORBIT_MAX_SAMPLES evenly spread
        (the first and the last kept).

        Returns
        -------
        tuple of ndarray: times (n,) and states (dim, n), C-contiguous.
        """
        idx = np.arange(self.t.size)
        if idx.size > tol.ORBIT_MAX_SAMPLES:
            idx = np.unique(np.linspace(0, idx.size - 1, tol.ORBIT_MAX_SAMPLES).round().astype(int))
        return self.t[idx], np.ascontiguousarray(self.y[:, idx])


# -- the reference orbit --------------------------------------------------------------------------
_integrators = cache.IntegratorPool()  # by problem


def _integrator(problem) -> tuple[threading.Lock, Any]:
    return _integrators.get(problem.fingerprint(), lambda: _build(problem))


def _build(problem):
    """heyoka's float64 Taylor integrator for `problem`."""
    sys = list(zip(problem.variables, problem.rhs, strict=True))
    # The float64 ground truth's settings (harness.ground_truth): heyoka's disk cache then holds
    # one compiled integrator for both.
    kwargs = cache.float64_taylor_settings(problem)
    if problem.parameters:
        kwargs["pars"] = problem.parameter_values
    start = np.array(problem.y0, dtype=np.float64)
    return cache.interruptible(lambda: hy.taylor_adaptive(sys, start, **kwargs))


def sample_orbit(problem, y0: np.ndarray | None = None, t_end: float | None = None) -> Orbit:
    """The orbit from y0 (default: the problem's start) over [t0, t_end] (default: its span),
    sampled at every Taylor step and ORBIT_DENSE_POINTS points inside each step.

    Parameters
    ----------
    problem : Problem
    y0 : ndarray, shape (dim,), optional, the start (default `problem.y0`).
    t_end : float, optional, the end time (default `problem.t_end`).

    Returns
    -------
    Orbit: the samples; `complete` False and `singular` set when the run stopped early.
    """
    lock, ta = _integrator(problem)
    start = np.array(problem.y0 if y0 is None else y0, dtype=np.float64).reshape(problem.dim)
    end = float(problem.t_end if t_end is None else t_end)
    fractions = np.arange(1, tol.ORBIT_DENSE_POINTS + 1) / (tol.ORBIT_DENSE_POINTS + 1)
    # the steps run inside heyoka (propagate_until, its continuous output, the step cap) and the
    # samples come from one vectorised evaluation: a stiff span that takes the whole cap costs a
    # C loop, not 200 000 Python iterations (~20 s per orbit on the Bari problems)
    with lock:
        ta.time = problem.t0
        ta.state[:] = start
        if problem.parameters:
            ta.pars[:] = problem.parameter_values
        outcome, *_, c_out, _ = ta.propagate_until(end, max_steps=tol.ORBIT_MAX_STEPS, c_output=True)
        reached, state = float(ta.time), ta.state.copy()
        if c_out is not None and len(c_out.times) > 1:
            bounds = np.asarray(c_out.times, dtype=np.float64)
            a, b = bounds[:-1, None], bounds[1:, None]
            inner = np.concatenate([a + fractions[None, :] * (b - a), b], axis=1).reshape(-1)
            t = np.concatenate([[problem.t0], inner])
            y = np.concatenate([start[:, None], np.asarray(c_out(inner), dtype=np.float64).T], axis=1)
        else:
            t, y = np.array([problem.t0]), start[:, None].copy()
    complete = outcome == hy.taylor_outcome.time_limit  # the step cap: a long or stiff span
    singular = ""
    if outcome not in (hy.taylor_outcome.time_limit, hy.taylor_outcome.step_limit):
        complete = False
        singular = (f"the Taylor step failed ({outcome.name}) at t = {reached:.10g}"
                    if np.all(np.isfinite(state)) and outcome != hy.taylor_outcome.err_nf_state else
                    f"the state became non-finite at t = {reached:.10g}")
    finite = np.all(np.isfinite(y), axis=0)
    return Orbit(t[finite], y[:, finite], complete and bool(finite.all()), singular)


def jacobian_eigenvalues(problem, jac: np.ndarray) -> np.ndarray:
    """Eigenvalues (n, dim) of Jacobians shaped (dim, dim, n). For q'' = a(q) the Jacobian is
    [[0, I], [A, 0]], whose eigenvalues are the square roots +-sqrt(mu) of A's: half the size.

    Parameters
    ----------
    problem : Problem, the problem the Jacobians belong to (for its Newtonian structure).
    jac : ndarray, shape (dim, dim, n), jacobians, one per sample.

    Returns
    -------
    ndarray, complex, shape (n, dim): their eigenvalues.
    """
    mats = np.transpose(jac, (2, 0, 1))
    if problem.newtonian is not None and not problem.velocity_dependent:
        nq = len(problem.newtonian.positions)
        root = np.sqrt(np.linalg.eigvals(mats[:, nq:, :nq]).astype(complex))
        return np.concatenate([root, -root], axis=1)
    return np.linalg.eigvals(mats)


def states_at(problem, times: np.ndarray, y0: np.ndarray | None = None) -> np.ndarray:
    """States (dim, len(times)) of the float64 Taylor orbit from y0 (default: the problem's) at
    increasing `times` >= t0: points on the orbit, not a certified reference.

    Parameters
    ----------
    problem : Problem
    times : array_like, shape (m,), increasing times >= t0.
    y0 : ndarray, shape (dim,), optional, the start (default `problem.y0`).

    Returns
    -------
    ndarray, shape (dim, m): the states.
    """
    lock, ta = _integrator(problem)
    times = np.asarray(times, dtype=np.float64)
    start = np.array(problem.y0 if y0 is None else y0, dtype=np.float64).reshape(problem.dim)
    with lock:
        ta.time = problem.t0
        ta.state[:] = start
        if problem.parameters:
            ta.pars[:] = problem.parameter_values
        lead = bool(times.size == 0 or times[0] != problem.t0)  # the grid starts at t0
        grid = np.concatenate([[problem.t0], times]) if lead else times
        out = ta.propagate_grid(grid)[-1]
    return np.ascontiguousarray((out[1:] if lead else out).T)


def fastest_times(problem, n: int) -> np.ndarray:
    """Up to n times along the orbit over the span where the Jacobian's spectral radius is
    largest, at least 1 % of the span apart (the close approaches), increasing.

    Parameters
    ----------
    problem, n : Problem, int, the problem (its orbit over its own span) and how many times at most.

    Returns
    -------
    ndarray: the chosen times, increasing.
    """
    orbit = sample_orbit(problem)
    rate = orbit_rates(problem, orbit)["spectral"]
    t, _ = orbit.thinned()
    gap = 0.01 * (problem.t_end - problem.t0)
    chosen: list[float] = []
    for k in np.argsort(rate)[::-1]:
        if all(abs(t[k] - c) > gap for c in chosen):
            chosen.append(float(t[k]))
        if len(chosen) == n:
            break
    return np.sort(np.array(chosen))


def orbit_rates(problem, orbit: Orbit, *, candidates: int | None = None) -> dict[str, np.ndarray]:
    """Along an orbit: spectral radius max|lambda(J)| and max|Im lambda(J)| of the Jacobian, and
    the rate ||f(y)|| / ||y|| at which the state changes relative to its size (each shaped (n,)).
    With `candidates`, the spectrum is taken only at that many samples of largest ||J||_F (an
    upper bound of the spectral radius, so the fastest samples are among them); the others
    read 0.

    Parameters
    ----------
    problem : Problem
    orbit : Orbit, an orbit of it (`sample_orbit`); thinned to ORBIT_MAX_SAMPLES samples.
    candidates : int, optional, how many samples get their spectrum taken (default all).

    Returns
    -------
    dict of ndarray: 'spectral', 'oscillation' and 'change' rates, one per (thinned) sample.
    """
    t, y = orbit.thinned()
    n = t.size
    pars = problem.pars_for(n)
    jac = problem.compiled("jac", None)(y, pars=pars, time=t).reshape(problem.dim, problem.dim, n)
    f = problem.compiled("rhs", None)(y, pars=pars, time=t)
    with np.errstate(all="ignore"):
        change = np.linalg.norm(f, axis=0) / np.linalg.norm(y, axis=0)
    spectral, oscillation = np.zeros(n), np.zeros(n)
    pick = np.arange(n)
    if candidates is not None and n > candidates:
        pick = np.argsort(np.sqrt(np.sum(jac * jac, axis=(0, 1))))[-candidates:]
    lam = jacobian_eigenvalues(problem, jac[:, :, pick])
    spectral[pick] = np.max(np.abs(lam), axis=1)
    oscillation[pick] = np.max(np.abs(lam.imag), axis=1)
    return {"spectral": spectral, "oscillation": oscillation,
            "change": np.where(np.isfinite(change), change, 0.0)}
