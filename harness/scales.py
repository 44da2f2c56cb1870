"""Time scales and ensemble perturbations derived from a problem's own dynamics.

Every experiment that runs a problem for a while needs a natural period (how long is "one
orbit"), a step size that resolves the fastest motion, and an ensemble whose members all stay
in the unperturbed start's dynamical regime. None of these is typed per problem: they follow
from the symbolic definition and a short float64 Taylor run along its span.

- The reference orbit (`harness.orbit`, whose names this module re-exports): heyoka's Taylor
  integrator (float64, tolerance eps) from y0 over [t0, t_end], sampled densely.
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
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from harness import tolerances as tol
from harness.derived import remembered
from harness.errors import ProblemError
from harness.orbit import Orbit, fastest_times, jacobian_eigenvalues, orbit_rates, sample_orbit, states_at

__all__ = [
    "TimeScale",
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
    "jacobian_eigenvalues",
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
    # the first time T at which (T - t0) x the largest spectral radius up to T reaches
    # STIFF_HORIZON_STEPS (None: the span never does): where the span turns stiff
    stiff_onset: float | None = None

    @property
    def steps_per_period(self) -> float:
        return self.period / self.h

    def as_dict(self) -> dict[str, Any]:
        """The time scale as plain values (for JSON and the report).

        Returns
        -------
        dict : every field and `steps_per_period`.
        """
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
        """The perturbation as plain values (for JSON and the on-disk cache).

        Returns
        -------
        dict : size, component_scale (a list), source, reason.
        """
        return {"size": self.size, "component_scale": self.component_scale.tolist(),
                "source": self.source, "reason": self.reason}


# -- time scale -------------------------------------------------------------------------------------
def derive_time_scale(problem) -> TimeScale:
    """The time scale of `problem` (see the module docstring for the rules), derived once per
    definition and code version (`harness.derived`): every process of a run asks for it.

    Parameters
    ----------
    problem : Problem, the definition whose flow is sampled (its fingerprint keys the memo)

    Returns
    -------
    TimeScale: its period, fastest rate, step size h and rate contrast, with source and reason.
    """
    fields = remembered("harness.scales", "time_scale", [problem.fingerprint()],
                        lambda: _derive_time_scale(problem).__dict__)
    return TimeScale(**fields)


def _derive_time_scale(problem) -> TimeScale:
    orbit = sample_orbit(problem)
    if orbit.singular:
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
                     rate_contrast=contrast, stiff_onset=_stiff_onset(problem.t0, orbit, rates["spectral"]))


def _stiff_onset(t0: float, orbit: Orbit, spectral: np.ndarray) -> float | None:
    """The first T with (T - t0) x max(spectral radius over [t0, T]) >= STIFF_HORIZON_STEPS, on
    the orbit's (thinned) samples: past sample k the radius is at least its running maximum M_k,
    so T = min_k max(t_k, t0 + STIFF_HORIZON_STEPS / M_k); None when no sample reaches it."""
    t, _ = orbit.thinned()  # the samples orbit_rates read
    running = np.maximum.accumulate(np.where(np.isfinite(spectral), spectral, 0.0))
    with np.errstate(divide="ignore"):
        reach = np.maximum(t, t0 + tol.STIFF_HORIZON_STEPS / running)
    reach = reach[running > 0.0]
    reach = reach[reach <= t[-1]]
    return float(np.min(reach)) if reach.size else None


# -- perturbation -----------------------------------------------------------------------------------
def component_scales(problem, orbit: Orbit) -> np.ndarray:
    """max |y_i(t)| along the orbit; a component that stays zero takes its block's scale
    (positions or velocities of a Newtonian problem, the whole state otherwise), then 1.

    Parameters
    ----------
    problem, orbit : Problem, Orbit
        The problem (for its Newtonian blocks) and an orbit of it.

    Returns
    -------
    ndarray, shape (dim,)
        Positive scales, one per component.
    """
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
    on `size`, so a smaller ensemble is the start of a larger one.

    Parameters
    ----------
    dim, size, seed : int
        State dimension, ensemble size, seed of the random generator.

    Returns
    -------
    ndarray, shape (dim, size)
        The draws (column 0 all zero).
    """
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
    once per problem definition and version of this code (`harness.derived`).

    Parameters
    ----------
    problem : Problem, the definition whose ensemble members are to be perturbed

    Returns
    -------
    Perturbation: the relative size and per-component scale, with their source and reason.
    """
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
