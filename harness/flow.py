"""How much a problem's flow amplifies a perturbation over a span: ||d Phi_span(y0)||.

Central differences of relative size REVERSIBILITY_FLOW_DELTA on float64 Taylor orbits: the
2 dim perturbed orbits run FLOW_BATCH at a time through heyoka's batch integrator (one SIMD lane
each, with the settings of the scalar orbits of `harness.scales`). The value is kept on disk per
problem definition, span, start and version of this code (`harness.derived`). The reversibility
and convergence experiments carry rounding to the end of a run with it (`harness.rules`).

Reference: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed. (2006), I.2
(the flow and its derivative); heyoka's batch mode: Biscani & Izzo, MNRAS 497 (2020) 2251.
"""

from __future__ import annotations

import heyoka as hy
import numpy as np

from harness import cache
from harness import tolerances as tol
from harness.derived import remembered

__all__ = ["flow_amplification", "FLOW_BATCH"]


def flow_amplification(problem, span: float, y0: np.ndarray | None = None) -> float:
    """||d Phi_span(y0)||_inf (the largest row sum of the flow's Jacobian): how many ulps of the
    state an error of one ulp in every component becomes after `span`. Central differences of
    relative size REVERSIBILITY_FLOW_DELTA on float64 Taylor orbits (`harness.scales`): the
    signal delta A exceeds their own error, ~eps A, by delta / eps ~ 1e9, so no certified
    reference (minutes for a many-body problem over 10^5 steps) is needed.

    Parameters
    ----------
    problem : Problem
    span : float, the time the flow runs.
    y0 : ndarray, shape (dim,), optional, the start (default `problem.y0`).

    Returns
    -------
    float: ||d Phi_span(y0)||_inf (kept on disk per problem, span, start and code version).
    """
    base = np.asarray(problem.y0 if y0 is None else y0, dtype=float).reshape(problem.dim)
    key = (problem.fingerprint(), float(span), base.tobytes())
    if key not in _amplifications:  # every stepper's cell of one (problem, N) asks for the same
        parts = (key[0], key[1], tuple(base.tolist()))
        _amplifications[key] = float(remembered("harness.flow", "flow_amplification", parts,
                                                lambda: _flow_amplification(problem, float(span), base)))
    return _amplifications[key]


def _flow_amplification(problem, span: float, base: np.ndarray) -> float:
    # the 2 dim perturbed orbits run FLOW_BATCH at a time through heyoka's batch integrator (one
    # SIMD lane each, the scalar integrator's settings): several times faster than one by one
    scale = np.where(base != 0.0, np.abs(base), 1.0)
    delta = tol.REVERSIBILITY_FLOW_DELTA * scale
    starts = np.repeat(base[:, None], 2 * problem.dim, axis=1)
    columns = np.arange(problem.dim)
    starts[columns, 2 * columns] += delta
    starts[columns, 2 * columns + 1] -= delta
    ends = _batch_states_at(problem, problem.t0 + span, starts)
    J = (ends[:, 0::2] - ends[:, 1::2]) / (2.0 * delta)
    return float(np.max(np.sum(np.abs(J), axis=1)))


FLOW_BATCH = 8  # lanes of the batch integrator: two AVX2 / one AVX-512 vector of doubles
_batch_integrators = cache.IntegratorPool()  # by problem


def _build_batch(problem):
    sys = list(zip(problem.variables, problem.rhs, strict=True))
    kwargs = cache.float64_taylor_settings(problem)
    if problem.parameters:
        kwargs["pars"] = np.repeat(np.asarray(problem.parameter_values, dtype=float)[:, None],
                                   FLOW_BATCH, axis=1)
    start = np.repeat(np.asarray(problem.y0, dtype=np.float64).reshape(-1, 1), FLOW_BATCH, axis=1)
    return hy.taylor_adaptive_batch(sys, start, **kwargs)


def _batch_states_at(problem, t: float, starts: np.ndarray) -> np.ndarray:
    """The float64 Taylor orbits from each column of `starts` (dim, m) at time `t`; NaN columns
    for orbits that could not be followed there."""
    lock, ta = _batch_integrators.get(problem.fingerprint(), lambda: _build_batch(problem))
    m = starts.shape[1]
    out = np.full_like(starts, np.nan)
    with lock:
        for k in range(0, m, FLOW_BATCH):
            chunk = starts[:, k:k + FLOW_BATCH]
            lanes = chunk.shape[1]
            ta.set_time(np.full(FLOW_BATCH, float(problem.t0)))
            ta.state[:] = np.pad(chunk, ((0, 0), (0, FLOW_BATCH - lanes)), mode="edge")
            # bounded like the scalar orbits (`ORBIT_MAX_STEPS`): on a stiff problem the Taylor
            # step stays near 1/|lambda| and an unbounded run over its span never ends (ROBER
            # over 1e11: ~1e13 steps); an orbit that stops there is a NaN column
            ta.propagate_until(np.full(FLOW_BATCH, float(t)), max_steps=tol.ORBIT_MAX_STEPS)
            done = [r[0] == hy.taylor_outcome.time_limit for r in ta.propagate_res[:lanes]]
            out[:, k:k + lanes] = np.where(done, ta.state[:, :lanes], np.nan)
    return out


_amplifications: dict[tuple[str, float, bytes], float] = {}
