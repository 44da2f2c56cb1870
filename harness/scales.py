"""Time scales and ensemble perturbations derived from a problem's own dynamics.

Every experiment that runs a problem for a while needs a natural period (how long is "one
orbit"), a step size that resolves the fastest motion, and an ensemble whose members all stay
in the unperturbed start's dynamical regime. None of these is typed per problem: they follow
from the symbolic definition and a short float64 Taylor run along its span.

- The reference orbit: heyoka's Taylor integrator (float64, tolerance eps) from y0 over
  [t0, t_end], sampled at each of its adaptive steps and at `ORBIT_DENSE_POINTS` points inside
  each (dense output), so close approaches, where the steps shrink, are sampled densely.
- The fastest rate rho = max over the orbit of the Jacobian's spectral radius max|lambda(J)|.
  The long-run experiments step with h = STEP_RATE_PRODUCT / rho (h |lambda| = 0.12 resolves the
  fastest motion for every stable method; Hairer, Lubich & Wanner, GNI I.2 and I.3 use
  h omega ~ 0.1-0.2 on Kepler and Henon-Heiles).
- The natural period: declared on the problem where its definition states one; otherwise
  2 pi / max|Im lambda(J)| along the orbit (the period of the fastest linearised oscillation:
  the orbital period exactly for a circular Kepler orbit, Jupiter's for the outer solar
  system); for motion without oscillation, the shortest time in which the state changes by its
  own size, min ||y|| / ||f(y)|| along the orbit (for a stiff problem on its slow manifold this
  is the slow time, not the stiff one).
- Component scales: max |y_i(t)| along the orbit; a component that stays zero takes the scale of
  its block (positions or velocities of a Newtonian problem; the whole state otherwise).
- Perturbation size: the declared one if the problem declares it; otherwise the largest of
  ENSEMBLE_PERTURBATION, /10, /100, ... (down to MIN_ENSEMBLE_PERTURBATION) at which each of
  ENSEMBLE_SIZE probe members (the members `Problem.ensemble(size, seed=0)` draws for every
  size up to it) keeps its fastest rate along its own orbit within REGIME_RATE_FACTOR of the
  unperturbed orbit's. The fastest rate is set by the closest approach (for gravity
  rho ~ sqrt(2 G m / r^3)), so this bounds how much closer any member comes to a collision.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Any

import heyoka as hy
import numpy as np

from harness import cache
from harness import tolerances as tol
from harness.derived import remembered
from harness.flow import flow_amplification  # noqa: F401  (a scale of the problem's dynamics)

__all__ = [
    "TimeScale",
    "flow_amplification",
    "Perturbation",
    "Orbit",
    "derive_time_scale",
    "derive_perturbation",
    "sample_orbit",
    "orbit_rates",
    "component_scales",
    "draw_noise",
    "states_at",
    "fastest_times",
    "regime_end",
]


@dataclass(frozen=True)
class TimeScale:
    """A problem's natural period, fastest rate and the fixed step the long-run experiments use."""

    period: float
    fastest_rate: float
    h: float
    source: str  # "declared" or "derived"
    reason: str
    # fastest over median spectral radius along the span: ~1 for an oscillator, large where
    # close encounters come and go (a fixed step is then far finer than most of the orbit needs)
    rate_contrast: float = 1.0

    @property
    def steps_per_period(self) -> float:
        return self.period / self.h

    def as_dict(self) -> dict[str, Any]:
        return {"period": self.period, "fastest_rate": self.fastest_rate, "h": self.h,
                "rate_contrast": self.rate_contrast,
                "steps_per_period": self.steps_per_period, "source": self.source,
                "reason": self.reason}


@dataclass(frozen=True)
class Perturbation:
    """The ensemble perturbation of a problem: relative size and per-component scale."""

    size: float
    component_scale: np.ndarray = field(repr=False)
    source: str  # "declared" or "derived"
    reason: str

    def as_dict(self) -> dict[str, Any]:
        return {"size": self.size, "component_scale": self.component_scale.tolist(),
                "source": self.source, "reason": self.reason}


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

    The steps run inside heyoka (`propagate_until` with its continuous output, at most
    ORBIT_MAX_STEPS of them) and the samples come from one vectorised evaluation of that
    output: a stiff span that takes the whole step cap costs a C loop, not 200 000 Python
    iterations (20 s per orbit on the Bari problems)."""
    lock, ta = _integrator(problem)
    start = np.array(problem.y0 if y0 is None else y0, dtype=np.float64).reshape(problem.dim)
    end = float(problem.t_end if t_end is None else t_end)
    fractions = np.arange(1, tol.ORBIT_DENSE_POINTS + 1) / (tol.ORBIT_DENSE_POINTS + 1)
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


def _eigenvalues(problem, jac: np.ndarray) -> np.ndarray:
    """Eigenvalues (n, dim) of Jacobians shaped (dim, dim, n). For q'' = a(q) the Jacobian is
    [[0, I], [A, 0]], whose eigenvalues are the square roots +-sqrt(mu) of A's: half the size."""
    mats = np.transpose(jac, (2, 0, 1))
    if problem.newtonian is not None and not problem.velocity_dependent:
        nq = len(problem.newtonian.positions)
        root = np.sqrt(np.linalg.eigvals(mats[:, nq:, :nq]).astype(complex))
        return np.concatenate([root, -root], axis=1)
    return np.linalg.eigvals(mats)


def states_at(problem, times: np.ndarray, y0: np.ndarray | None = None) -> np.ndarray:
    """States (dim, len(times)) of the float64 Taylor orbit from y0 (default: the problem's) at
    increasing `times` >= t0: points on the orbit, not a certified reference."""
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
    largest, at least 1 % of the span apart (the close approaches), increasing."""
    orbit = sample_orbit(problem)
    rate = orbit_rates(problem, orbit)["spectral"]
    idx = np.arange(orbit.t.size)
    if idx.size > tol.ORBIT_MAX_SAMPLES:
        idx = np.unique(np.linspace(0, idx.size - 1, tol.ORBIT_MAX_SAMPLES).round().astype(int))
    t = orbit.t[idx]
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
    read 0."""
    idx = np.arange(orbit.t.size)
    if idx.size > tol.ORBIT_MAX_SAMPLES:
        idx = np.unique(np.linspace(0, idx.size - 1, tol.ORBIT_MAX_SAMPLES).round().astype(int))
    t, y = orbit.t[idx], np.ascontiguousarray(orbit.y[:, idx])
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
    lam = _eigenvalues(problem, jac[:, :, pick])
    spectral[pick] = np.max(np.abs(lam), axis=1)
    oscillation[pick] = np.max(np.abs(lam.imag), axis=1)
    return {"spectral": spectral, "oscillation": oscillation,
            "change": np.where(np.isfinite(change), change, 0.0)}


# -- time scale -------------------------------------------------------------------------------------
def derive_time_scale(problem) -> TimeScale:
    """The time scale of `problem` (see the module docstring for the rules), derived once per
    definition and code version (`harness.derived`): every process of a run asks for it."""
    fields = remembered("harness.scales", "time_scale", [problem.fingerprint()],
                        lambda: _derive_time_scale(problem).__dict__)
    return TimeScale(**fields)


def _derive_time_scale(problem) -> TimeScale:
    orbit = sample_orbit(problem)
    if orbit.singular:
        from harness.errors import ProblemError

        raise ProblemError(
            f"problem {problem.name!r}: its solution is singular within its span "
            f"[{problem.t0:g}, {problem.t_end:g}]: {orbit.singular} (heyoka's float64 Taylor "
            "orbit from y0); shorten `t_span` to end before it")
    rates = orbit_rates(problem, orbit)
    rho = float(np.max(rates["spectral"]))
    omega = float(np.max(rates["oscillation"]))
    change = float(np.max(rates["change"]))
    span = problem.t_end - problem.t0
    if problem.period is not None:
        period, source = float(problem.period), "declared"
        why = f"declared period {period:.6g}"
    elif omega > 0.0:
        period, source = 2.0 * math.pi / omega, "derived"
        why = (f"2 pi / max|Im lambda(J)| = 2 pi / {omega:.4g} along the orbit (the fastest "
               "linearised oscillation)")
    elif change > 0.0:
        period, source = 1.0 / change, "derived"
        why = f"min ||y|| / ||f(y)|| = {period:.4g} along the orbit (no oscillation)"
    else:
        period, source = span, "derived"
        why = "the state does not move: the span"
    if rho > 0.0:
        h = tol.STEP_RATE_PRODUCT / rho
        why += f"; h = {tol.STEP_RATE_PRODUCT:g} / max|lambda(J)| = {tol.STEP_RATE_PRODUCT:g} / {rho:.4g}"
    else:
        h = tol.STEP_RATE_PRODUCT * period
        why += f"; J is nilpotent along the orbit: h = {tol.STEP_RATE_PRODUCT:g} x that time"
    if not orbit.complete:
        why += f"; the orbit sample stopped at t = {orbit.t[-1]:.6g} before the span's end"
    median = float(np.median(rates["spectral"]))
    contrast = rho / median if median > 0.0 else (1.0 if rho == 0.0 else math.inf)
    return TimeScale(period=period, fastest_rate=rho, h=h, source=source, reason=why,
                     rate_contrast=contrast)


# -- perturbation -----------------------------------------------------------------------------------
def component_scales(problem, orbit: Orbit) -> np.ndarray:
    """max |y_i(t)| along the orbit; a component that stays zero takes its block's scale
    (positions or velocities of a Newtonian problem, the whole state otherwise), then 1."""
    scale = np.max(np.abs(orbit.y), axis=1)
    if problem.newtonian is not None:
        nq = len(problem.newtonian.positions)
        blocks = [slice(0, nq), slice(nq, problem.dim)]
    else:
        blocks = [slice(0, problem.dim)]
    for b in blocks:
        part = scale[b]
        fill = float(np.max(part)) if part.size and np.max(part) > 0.0 else 1.0
        scale[b] = np.where(part > 0.0, part, fill)
    return scale


def draw_noise(dim: int, size: int, seed: int) -> np.ndarray:
    """Uniform draws in [-1, 1] shaped (dim, size), member 0 zero; member j's draws do not depend
    on `size`, so a smaller ensemble is the start of a larger one."""
    rng = np.random.default_rng(seed)
    noise = rng.uniform(-1.0, 1.0, size=(size, dim)).T.copy()
    noise[:, 0] = 0.0
    return noise


def _fastest_rate(problem, y0: np.ndarray) -> float:
    orbit = sample_orbit(problem, y0)
    if not orbit.complete:
        return math.inf
    return float(np.max(orbit_rates(problem, orbit, candidates=tol.REGIME_CANDIDATES)["spectral"]))


def _ratio(rate: float, base: float) -> float:
    if rate == base:
        return 1.0
    if base > 0.0 and rate > 0.0 and math.isfinite(rate):
        return max(rate / base, base / rate)
    return math.inf


def derive_perturbation(problem) -> Perturbation:
    """The ensemble perturbation of `problem` (see the module docstring for the rules); derived
    once per problem definition and version of this code (`harness.derived`)."""
    size, scale, source, reason = remembered(
        "harness.scales", "derive_perturbation", (problem.fingerprint(),),
        lambda: list(_derive_perturbation(problem).as_dict().values()))
    return Perturbation(float(size), np.asarray(scale, dtype=float), str(source), str(reason))


def _derive_perturbation(problem) -> Perturbation:
    orbit = sample_orbit(problem)
    scale = component_scales(problem, orbit)
    if problem.perturbation is not None:
        return Perturbation(float(problem.perturbation), scale, "declared",
                            f"declared relative size {problem.perturbation:g}")
    base = float(np.max(orbit_rates(problem, orbit)["spectral"]))
    noise = draw_noise(problem.dim, tol.ENSEMBLE_SIZE, seed=0)[:, 1:]
    size = tol.ENSEMBLE_PERTURBATION
    while True:
        worst = 1.0
        for j in range(noise.shape[1]):  # stop at the first member outside the regime
            worst = max(worst, _ratio(_fastest_rate(problem, problem.y0 + size * noise[:, j] * scale), base))
            if worst > tol.REGIME_RATE_FACTOR:
                break
        if worst <= tol.REGIME_RATE_FACTOR or size / 10.0 < tol.MIN_ENSEMBLE_PERTURBATION:
            break
        size /= 10.0
    held = worst <= tol.REGIME_RATE_FACTOR
    reason = (f"relative size {size:g} of each component's scale along the orbit: "
              f"{tol.ENSEMBLE_SIZE - 1} probe members keep their fastest rate within a factor "
              f"{worst:.3g} of the unperturbed orbit's {base:.4g}")
    if size < tol.ENSEMBLE_PERTURBATION:
        reason += f" (a larger size left a member outside a factor {tol.REGIME_RATE_FACTOR:g})"
    if not held:
        reason += (f"; even the smallest size tried leaves a member outside a factor "
                   f"{tol.REGIME_RATE_FACTOR:g}: members may not share one dynamical regime")
    return Perturbation(size, scale, "derived", reason)


_regime_ends: dict[tuple[str, float], tuple[float, str]] = {}


def regime_end(problem, t_end: float) -> tuple[float, str]:
    """(t_stop, reason): how far past its span a long run of `problem` towards `t_end` stays in
    the dynamical regime of the span. The float64 orbit is followed to `t_end`; where its
    fastest rate first exceeds REGIME_RATE_FACTOR x the span's (a closer encounter than any
    within the span: beyond its span the Pleiades collides; the run stops LONG_RUN_MARGIN
    fastest-time units earlier), where the state first grows past REGIME_SIZE_FACTOR x its size
    over the span (a dropped ball keeps falling), or where the orbit stops (non-finite, step
    cap), whichever comes first, and never before the span's end. t_stop = t_end and reason ""
    when the regime holds throughout."""
    key = (problem.fingerprint(), float(t_end))
    if key not in _regime_ends:
        stop, reason = remembered("harness.scales", "regime_end", key,
                                  lambda: list(_regime_end(problem, float(t_end))))
        _regime_ends[key] = (float(stop), str(reason))
    return _regime_ends[key]


def _regime_end(problem, t_end: float) -> tuple[float, str]:
    base = problem.time_scale.fastest_rate
    orbit = sample_orbit(problem, t_end=t_end)
    idx = np.arange(orbit.t.size)
    if idx.size > tol.ORBIT_MAX_SAMPLES:
        idx = np.unique(np.linspace(0, idx.size - 1, tol.ORBIT_MAX_SAMPLES).round().astype(int))
    t, y = orbit.t[idx], np.ascontiguousarray(orbit.y[:, idx])
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
        rate = np.max(np.abs(_eigenvalues(problem, jac[:, :, chunk])), axis=1)
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
    within ENCOUNTER_RATE_FRACTION of its maximum `rate`; None when the orbit cannot be had."""
    key = (problem.fingerprint(), float(t_end))
    if key not in _approaches:
        found = remembered("harness.scales", "fastest_approach", key,
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
