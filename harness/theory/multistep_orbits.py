"""What the characteristic polynomial of a second-order multistep method predicts on orbits.

For sum_j alpha_j x_(n+j) = h^2 sum_j beta_j a_(n+j) with rho(zeta) = sum alpha_j zeta^j and
sigma(zeta) = sum beta_j zeta^j:

- Parasitic roots (`parasitic_angles`): rho has the double root 1 (consistency); a symmetric
  method's other roots lie on the unit circle at angles +-theta_j (Quinlan & Tremaine, AJ 100
  (1990) 1694, sec. 2; Hairer, Lubich & Wanner, GNI, ch. XV). They carry the parasitic solution
  components zeta_j^n z_j(t) of the numerical solution.
- Resonances (`combination_resonances`): on a nonlinear problem the parasitic components are
  coupled through the Jacobian of the force along the orbit. Where that Jacobian oscillates with
  the harmonic m omega of the orbit's frequency omega, two parasitic components +-theta_i and
  +-theta_j are coupled at first order when theta_i + theta_j or |theta_i - theta_j| equals
  m h omega (mod 2 pi): a parametric (combination) resonance, whose energy error stands far
  above its neighbours' or grows (Quinlan, "Resonances and instabilities in symmetric multistep
  methods", astro-ph/9901136 (1999); HLW ch. XV: the expansion of the
  parasitic components stays bounded only away from such step sizes). On a circular Kepler orbit
  the Jacobian 3 r r^T / r^5 - I / r^3 has the harmonics 0 and 2 omega only, so few step sizes
  are resonant; an eccentric orbit's Jacobian has every harmonic, and the resonances crowd.
  At h omega > 0 the parasitic roots move by O((h omega)^2): the angles are taken as those of
  rho - (h omega)^2 c sigma, c omega^2 an eigenvalue of the orbit's mean Jacobian (QT8 on the
  circular orbit: pi/30 = 0.10472 at h = 0, 0.10512 so moved; band measured 0.1042-0.1060).
- Spiralling (`principal_growth`): on x'' = -omega^2 x the principal root zeta_1(h omega) of
  rho(zeta) + (h omega)^2 sigma(zeta), near exp(i h omega), has |zeta_1| = exp(g h) with g = 0
  for a symmetric method (its roots come in pairs zeta, 1/zeta) and g = O(omega (h omega)^p)
  otherwise. To leading order the numerical solution then obeys x'' = -omega^2 x + 2 g x'
  (the modified equation of the linear recurrence; Quinlan 1999, sec. 1, after Gautschi (1961)
  and Stiefel & Bettis (1969): Stormer-Cowell methods with k > 2 spiral in or out on circular
  orbits), whose work 2 g |v|^2 changes the energy secularly: on a circular orbit of a central
  field the relative energy drifts at 2 g |v|^2 / |E| per unit time (Kepler: 4 g).
  The principal root's error is c (i h omega)^(p+1) + ... with c real (p the order), whose
  modulus changes at that order only when p + 1 is even: g / omega ~ (h omega)^p for odd p and
  (h omega)^(p+1) for even p (measured on the circular orbit: stormer3..8 3.0, 5.0, 5.0, 7.0,
  6.9, 9.0; Cowell p = 5..9: 5.0, 7.0, 6.9, 8.9, 8.6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import mpmath
import numpy as np

from harness.coefficients import SecondOrderMultistep
from harness.errors import InputError
from harness.tolerances import PARASITIC_UNIT_CIRCLE

__all__ = ["parasitic_angles", "principal_growth", "combination_resonances", "Resonance"]

_DIGITS = 60  # mpmath precision for the principal root: |zeta_1| - 1 ~ (h omega)^(p+1) >= 1e-30


def _exact(method: SecondOrderMultistep) -> tuple[list[Fraction], list[Fraction]]:
    if not isinstance(method, SecondOrderMultistep):
        raise InputError(f"`method` must be a SecondOrderMultistep, got {type(method).__name__}")
    if method.exact is not None:
        return list(method.exact[0]), list(method.exact[1])
    return [Fraction(a) for a in method.alpha], [Fraction(b) for b in method.beta]


def parasitic_angles(method: SecondOrderMultistep, shift: float = 0.0) -> list[float]:
    """Angles theta in (0, pi] of the parasitic roots on the unit circle of rho(zeta) - shift
    sigma(zeta) (shift = h^2 mu for a mean force gradient mu; 0: rho itself).

    The two roots nearest 1 (the principal pair, a double root at shift = 0) are left out; a
    root counts as on the circle when its modulus is within PARASITIC_UNIT_CIRCLE of 1 (float64
    root finding; Stormer-Cowell methods with k > 2 have their parasitic roots at 0, so none).

    Parameters
    ----------
    method : SecondOrderMultistep
    shift : float, optional, h^2 mu (default 0).

    Returns
    -------
    list of float: distinct angles, increasing (each stands for the pair +-theta).
    """
    alpha, beta = _exact(method)
    coeffs = np.array([float(a - Fraction(shift) * b) for a, b in zip(alpha, beta, strict=True)])
    roots = np.roots(coeffs[::-1])
    roots = roots[np.argsort(np.abs(roots - 1.0))][2:]
    on_circle = roots[np.abs(np.abs(roots) - 1.0) <= PARASITIC_UNIT_CIRCLE]
    angles = sorted({round(abs(float(np.angle(r))), 12) for r in on_circle})
    return [a for a in angles if a > 0.0]


def principal_growth(method: SecondOrderMultistep, h_omega: float) -> float:
    """ln |zeta_1| / (h omega): the growth rate g / omega of the principal root of
    rho(zeta) + (h omega)^2 sigma(zeta) (the root nearest exp(i h omega)), in 60 digits.

    Parameters
    ----------
    method : SecondOrderMultistep
    h_omega : float, positive.

    Returns
    -------
    float: g / omega (0 for a symmetric method, to the working precision).
    """
    if not (isinstance(h_omega, int | float) and math.isfinite(h_omega) and h_omega > 0):
        raise InputError(f"`h_omega` must be a positive finite number, got {h_omega!r}")
    alpha, beta = _exact(method)
    with mpmath.workdps(_DIGITS):
        z2 = mpmath.mpf(h_omega) ** 2
        coeffs = [mpmath.mpf(a.numerator) / a.denominator + z2 * mpmath.mpf(b.numerator) / b.denominator
                  for a, b in zip(alpha, beta, strict=True)][::-1]
        roots = mpmath.polyroots(coeffs, maxsteps=400, extraprec=4 * _DIGITS)
        target = mpmath.expj(mpmath.mpf(h_omega))
        root = min(roots, key=lambda r: abs(r - target))
        return float(mpmath.log(abs(root)) / mpmath.mpf(h_omega))


@dataclass(frozen=True)
class Resonance:
    """A predicted resonant h omega: theta_i (+ or -) theta_j + 2 pi l = m h omega."""

    h_omega: float
    theta_i: float
    theta_j: float
    combination: str  # "sum" or "difference"
    harmonic: int  # m

    def describe(self) -> str:
        """One line: the angles (in units of pi), the combination and the harmonic.

        Returns
        -------
        str
        """
        sign = "+" if self.combination == "sum" else "-"
        return (f"{self.theta_i / math.pi:.4g}pi {sign} {self.theta_j / math.pi:.4g}pi = "
                f"{self.harmonic} h omega (mod 2 pi)")


def combination_resonances(method: SecondOrderMultistep, harmonics: list[int],
                           curvatures: list[float], h_omega_min: float,
                           h_omega_max: float) -> list[Resonance]:
    """Every h omega in [h_omega_min, h_omega_max] where theta_i + theta_j or |theta_i - theta_j|
    (plus 2 pi l) equals m h omega for a harmonic m of the Jacobian along the orbit, with the
    parasitic angles taken at that h: those of rho - (h omega)^2 c sigma for each eigenvalue
    c omega^2 of the orbit's mean Jacobian (the circular Kepler orbit: c = 1/2), found by
    fixed-point iteration from the h = 0 angles (it drops a prediction whose roots leave the
    circle or that does not settle).

    Parameters
    ----------
    method : SecondOrderMultistep
    harmonics : list of int, the harmonics m >= 1 present in the Jacobian along the orbit.
    curvatures : list of float, the mean Jacobian's eigenvalues over omega^2.
    h_omega_min, h_omega_max : float, the range (0 < min < max).

    Returns
    -------
    list of Resonance, by h omega (one per distinct h omega, the lowest harmonic kept).
    """
    if not (0 < h_omega_min < h_omega_max):
        raise InputError(f"`h_omega_min` and `h_omega_max` must satisfy 0 < min < max, got "
                         f"{h_omega_min!r}, {h_omega_max!r}")
    if any(not isinstance(m, int | np.integer) or m < 1 for m in harmonics):
        raise InputError(f"`harmonics` must be whole numbers >= 1, got {list(harmonics)!r}")
    base = parasitic_angles(method)
    found: dict[float, Resonance] = {}
    for c in sorted(set(float(x) for x in curvatures)) or [0.0]:
        for i in range(len(base)):
            for j in range(i, len(base)):
                for kind in ("sum", "difference"):
                    for m in sorted(set(int(x) for x in harmonics)):
                        for turns in range(0, int(m * h_omega_max / (2 * math.pi)) + 2):
                            hw = _settle(method, base, i, j, kind, m, turns, c)
                            if hw is not None and h_omega_min <= hw <= h_omega_max:
                                key = round(hw, 9)
                                if key not in found or found[key].harmonic > m:
                                    found[key] = Resonance(hw, base[j], base[i], kind, m)
    return [found[k] for k in sorted(found)]


def _settle(method, base: list[float], i: int, j: int, kind: str, m: int, turns: int,
            curvature: float) -> float | None:
    """The fixed point hw = (theta_j(hw) +- theta_i(hw) + 2 pi turns) / m, or None."""
    angles = base
    hw = math.nan
    for _ in range(30):
        if len(angles) != len(base):
            return None  # roots left the circle (or met): no pair to follow
        combo = angles[j] + angles[i] if kind == "sum" else angles[j] - angles[i]
        if combo <= 0.0:
            return None
        new = (combo + 2 * math.pi * turns) / m
        if abs(new - hw) <= 1e-12 * new:
            return new
        hw = new
        angles = parasitic_angles(method, hw * hw * curvature)
    return None
