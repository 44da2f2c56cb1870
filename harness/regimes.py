"""How far a long run stays in the dynamical regime of its problem's span, and where along
the float64 Taylor orbit the fastest approach comes (`harness.scales` samples the orbit).

- `regime_end`: where a run past the span first leaves the span's regime (a closer encounter,
  a state running off, an orbit that cannot be followed), for the long-run experiments.
- `fastest_approach`: when the fastest rate along the orbit first comes near its maximum.

Both are kept on disk per problem definition and version of this code (`harness.derived`).
"""

from __future__ import annotations

import numpy as np

from harness import tolerances as tol
from harness.derived import remembered
from harness.scales import jacobian_eigenvalues, orbit_rates, sample_orbit

__all__ = ["regime_end", "fastest_approach"]


_regime_ends: dict[tuple[str, float], tuple[float, str]] = {}


def regime_end(problem, t_end: float) -> tuple[float, str]:
    """(t_stop, reason): how far past its span a long run of `problem` towards `t_end` stays in
    the dynamical regime of the span. The float64 orbit is followed to `t_end`; where its
    fastest rate first exceeds REGIME_RATE_FACTOR x the span's (a closer encounter than any
    within the span: beyond its span the Pleiades collides; the run stops LONG_RUN_MARGIN
    fastest-time units earlier), where the state first grows past REGIME_SIZE_FACTOR x its size
    over the span (a dropped ball keeps falling), or where the orbit stops (non-finite, step
    cap), whichever comes first, and never before the span's end. t_stop = t_end and reason ""
    when the regime holds throughout.

    Parameters
    ----------
    problem : Problem
    t_end : float, where the long run is meant to end (past the span or not).

    Returns
    -------
    (float, str): t_stop in [min(t_end, span end), t_end] and the reason ("" when the regime holds).
    """
    key = (problem.fingerprint(), float(t_end))
    if key not in _regime_ends:
        stop, reason = remembered("harness.regimes", "regime_end", key,
                                  lambda: list(_regime_end(problem, float(t_end))))
        _regime_ends[key] = (float(stop), str(reason))
    return _regime_ends[key]


def _regime_end(problem, t_end: float) -> tuple[float, str]:
    base = problem.time_scale.fastest_rate
    orbit = sample_orbit(problem, t_end=t_end)
    t, y = orbit.thinned()
    jac = problem.compiled("jac", None)(y, pars=problem.pars_for(t.size), time=t)
    jac = jac.reshape(problem.dim, problem.dim, t.size)
    limit = tol.REGIME_RATE_FACTOR * base
    # ||J||_F bounds the spectral radius: only samples above the limit can leave the regime;
    # their spectra are taken in time order until one does.
    maybe = np.flatnonzero(np.sqrt(np.sum(jac * jac, axis=(0, 1))) > limit) if base > 0 else []
    stop, reason = float(t_end), ""
    # The state's size, per block (positions, velocities; the whole state for a first-order
    # problem): beyond its span the orbit may run off (a dropped ball falls forever).
    span_part = orbit.t <= problem.t_end
    nq = len(problem.newtonian.positions) if problem.newtonian is not None else problem.dim
    blocks = [b for b in (slice(0, nq), slice(nq, problem.dim)) if b.stop > b.start]
    grown = np.zeros(orbit.t.size, dtype=bool)
    for b in blocks:
        size = np.max(np.abs(orbit.y[b]), axis=0)
        grown |= size > tol.REGIME_SIZE_FACTOR * max(float(np.max(size[span_part])), tol.SCALE_FLOOR)
    if grown.any():
        k = int(np.argmax(grown))
        stop = float(orbit.t[max(k - 1, 0)])  # the last sample still inside
        reason = (f"the orbit leaves the regime of the problem's span by t = {orbit.t[k]:.6g} (the "
                  f"state grows past {tol.REGIME_SIZE_FACTOR:g} x its size over the span)")
    for start in range(0, len(maybe), tol.REGIME_CANDIDATES):
        chunk = maybe[start:start + tol.REGIME_CANDIDATES]
        rate = np.max(np.abs(jacobian_eigenvalues(problem, jac[:, :, chunk])), axis=1)
        over = np.flatnonzero(rate > limit)
        if over.size and float(t[chunk[over[0]]]) - tol.LONG_RUN_MARGIN / float(rate[over[0]]) < stop:
            k, r = int(chunk[over[0]]), float(rate[over[0]])
            stop = float(t[k]) - tol.LONG_RUN_MARGIN / r
            reason = (f"the orbit leaves the regime of the problem's span at t = {t[k]:.6g} (fastest "
                      f"rate {r:.4g}, over {tol.REGIME_RATE_FACTOR:g} x the span's {base:.4g})")
            break
    if not reason and not orbit.complete:
        stop = float(orbit.t[-1])
        reason = f"the orbit could not be followed past t = {stop:.6g}"
    stop = max(stop, problem.t_end) if stop < t_end else stop
    return (min(stop, float(t_end)), reason)


def fastest_approach(problem, t_end: float) -> tuple[float, float, float] | None:
    """(t, rate, rate at the start) where the fastest rate rho (the Jacobian's spectral radius,
    `orbit_rates`) along the float64 orbit from the problem's start over [t0, t_end] first comes
    within ENCOUNTER_RATE_FRACTION of its maximum `rate`; None when the orbit cannot be had.

    Parameters
    ----------
    problem : Problem
    t_end : float, the end of the orbit followed.

    Returns
    -------
    (float, float, float) or None: (t, rate, rate at the start), or None.
    """
    key = (problem.fingerprint(), float(t_end))
    if key not in _approaches:
        found = remembered("harness.regimes", "fastest_approach", key,
                           lambda: _fastest_approach(problem, float(t_end)))
        _approaches[key] = None if found is None else tuple(float(v) for v in found)
    return _approaches[key]


def _fastest_approach(problem, t_end: float) -> list[float] | None:
    try:
        orbit = sample_orbit(problem, t_end=t_end)
        rate = np.asarray(orbit_rates(problem, orbit)["spectral"], dtype=float)
        t = orbit.t if orbit.t.size == rate.size else np.linspace(problem.t0, t_end, rate.size)
        top = float(np.max(rate))
        k = int(np.argmax(rate >= tol.ENCOUNTER_RATE_FRACTION * top))
        return [float(t[k]), top, float(rate[0])]
    except Exception:  # no float64 orbit
        return None


_approaches: dict[tuple[str, float], tuple[float, float, float] | None] = {}
