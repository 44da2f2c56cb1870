"""Stability intervals decided exactly on polynomials, and each coefficient kind's stability
figures (`analytic_stability`).

For Runge-Kutta methods R = P/Q with polynomials P, Q: stability on a ray is the sign of a
polynomial, decided from its coefficients rather than by comparing |R| with 1 at a tolerance.
Newtonian methods' h omega bands are decided in exact arithmetic (`harness.theory.newtonian`). A multistep
method's real interval ends where its root locus crosses the axis (`lmm_real_interval`;
Hairer & Wanner, *Solving ODEs II*, V.1).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import mpmath
import numpy as np
from scipy.optimize import brentq

from harness import tolerances as tol
from harness.theory import amplification
from harness.theory.checks import check_type, family_of
from harness.theory.newtonian import hw_bands
from harness.theory.orders import rk_linear_order, rk_stability_coefficients

if TYPE_CHECKING:  # annotations only: the theory reads coefficient objects by their `family`
    from harness.coefficients import ButcherTableau, LinearMultistep, SplittingScheme

__all__ = ["rk_stability_intervals", "splitting_trace_polynomial", "splitting_linear_order",
           "splitting_hw_limit", "exact_hw_bands", "lmm_real_interval", "analytic_stability"]


# -- exact intervals from polynomials ------------------------------------------------------
# For Runge-Kutta methods R = P/Q with polynomials P, Q, and for splitting schemes the
# propagator's trace is a polynomial in h omega: stability on a ray is the sign of a polynomial
# (Q^2 - P^2 on the real axis, |Q|^2 - |P|^2 on the imaginary axis, 4 - tr^2 for h omega), which
# is decided from its coefficients rather than by comparing |R| with 1 at a tolerance. Low-order
# coefficients that theory makes zero (|R(iy)|^2 = 1 + O(y^(p+1)) for linear order p) are set to
# zero, and the others count as zero only within the rounding of the sum of their magnitudes.
# The search has no ceiling: the last real root bounds it, and "unbounded" (inf) is returned only
# when the polynomial is non-negative for every positive argument.

def _poly_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.convolve(a, b)


def _poly_add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros(max(a.size, b.size), dtype=np.result_type(a, b))
    out[: a.size] += a
    out[: b.size] += b
    return out


def _rk_numerator_denominator(tableau: ButcherTableau) -> tuple[np.ndarray, ...]:
    """Coefficients (ascending) of P and Q in R = P/Q, with magnitudes for their rounding.
    Explicit: Q = 1 and P is the Taylor polynomial of R. Otherwise P(z) = det(I - zA + z e b^T)
    and Q(z) = det(I - zA), interpolated at roots of unity in 40-digit arithmetic."""
    s = tableau.stages
    if tableau.explicit:
        r, r_abs = rk_stability_coefficients(tableau, s)
        return r, r_abs, np.array([1.0]), np.array([1.0])

    with mpmath.workdps(40):
        A = mpmath.matrix([[mpmath.mpf(float(x)) for x in row] for row in tableau.A])
        E = mpmath.matrix([[mpmath.mpf(float(bj)) for bj in tableau.b] for _ in range(s)])
        eye = mpmath.eye(s)
        n = s + 1
        pts = [mpmath.exp(2j * mpmath.pi * k / n) for k in range(n)]
        Pv = [mpmath.det(eye - z * A + z * E) for z in pts]
        Qv = [mpmath.det(eye - z * A) for z in pts]
        P = np.array([float(mpmath.re(sum(Pv[k] * pts[k] ** (-j) for k in range(n)) / n)) for j in range(n)])
        Q = np.array([float(mpmath.re(sum(Qv[k] * pts[k] ** (-j) for k in range(n)) / n)) for j in range(n)])
    size = float(np.abs(tableau.A).sum(axis=1).max() + np.abs(tableau.b).sum())
    mags = np.array([math.comb(s, j) * size**j for j in range(n)])
    return P, mags, Q, mags


def _square_on_ray(P: np.ndarray, P_abs: np.ndarray, imaginary: bool) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients in x of P(-x)^2 (real ray) or |P(i x)|^2 (imaginary ray), with magnitudes."""
    k = np.arange(P.size)
    if imaginary:
        re = np.where(k % 4 == 0, P, np.where(k % 4 == 2, -P, 0.0))
        im = np.where(k % 4 == 1, P, np.where(k % 4 == 3, -P, 0.0))
        sq = _poly_add(_poly_mul(re, re), _poly_mul(im, im))
    else:
        neg = P * (-1.0) ** k
        sq = _poly_mul(neg, neg)
    return sq, _poly_mul(P_abs, P_abs)


def _leading_sign(F: np.ndarray, F_abs: np.ndarray, forced_zeros: int) -> tuple[int, np.ndarray]:
    """The sign of the polynomial F (ascending coefficients, F(0) = 0) just right of 0, decided
    on its lowest coefficient that exceeds its rounding (0: every coefficient is rounding, F is
    zero), and F with the leading zeros removed."""
    F = np.array(F, dtype=float)
    F[: forced_zeros + 1] = 0.0
    F_abs = np.resize(np.asarray(F_abs, dtype=float), F.size)
    significant = np.abs(F) > tol.STABILITY_POLY_ULPS * tol.EPS * np.abs(F_abs) * F.size
    nz = np.flatnonzero(significant)
    if nz.size == 0:
        return 0, np.zeros(0)
    return (1 if F[nz[0]] > 0 else -1), F[nz[0]: int(nz[-1]) + 1]


def _proven_nonnegative(G: np.ndarray) -> bool:
    """True when the polynomial G (G(0) > 0) has no positive real root and a positive leading
    coefficient, for degrees where the roots are well determined (implicit methods' P and Q)."""
    if G.size == 1:
        return True
    if G.size > tol.STABILITY_POLY_MAX_DEGREE + 1 or G[-1] <= 0:
        return False
    roots = np.polynomial.polynomial.polyroots(G)
    return not np.any((np.abs(roots.imag) <= 1e-8 * np.maximum(1.0, np.abs(roots))) & (roots.real > 0))


def _interval_end(F: np.ndarray, F_abs: np.ndarray, forced_zeros: int,
                  excess: Callable[[float], float]) -> float:
    """Where stability on a ray from the origin ends. Near the origin the sign of the polynomial
    F (> 0: stable) decides: a negative lowest coefficient means an empty interval (0), an
    identically zero F (|R| = 1 on the ray) or one proven non-negative means unbounded. Beyond,
    `excess(x)` (> 0: unstable), a numerically stable evaluation of the amplification, is
    scanned with no ceiling (linear steps, then geometric) and its first positive value is
    refined by Brent's method."""
    sign, G = _leading_sign(F, F_abs, forced_zeros)
    if sign == 0:
        return math.inf
    if sign < 0:
        return 0.0
    if _proven_nonnegative(G):
        return math.inf
    previous = 0.0
    x = tol.STABILITY_SCAN_STEP
    while x <= tol.STABILITY_SCAN_CEILING:
        value = excess(x)
        if not value <= 0:  # NaN (a pole) counts as unstable
            if previous == 0.0:
                return 0.0
            return float(brentq(lambda u: excess(u) if np.isfinite(excess(u)) else 1.0, previous, x,
                                xtol=tol.STABILITY_XTOL, rtol=4 * tol.EPS, maxiter=200))
        previous = x
        x = x + tol.STABILITY_SCAN_STEP if x < tol.STABILITY_SCAN_LINEAR_END else x * tol.STABILITY_SCAN_RATIO
    return math.inf


def rk_stability_intervals(tableau: ButcherTableau) -> tuple[float, float]:
    """(real, imaginary) stability intervals of a Runge-Kutta method: the sign near the origin
    and unboundedness decided on the polynomials Q(-x)^2 - P(-x)^2 and |Q(iy)|^2 - |P(iy)|^2
    (exact zeros from the linear order), the end located on R evaluated in stage form.

    Parameters
    ----------
    tableau : ButcherTableau

    Returns
    -------
    (float, float): the lengths of the stable intervals [-x, 0] and [0, i y] (each 0.0, finite or inf).
    """
    check_type(tableau, "runge-kutta", "tableau")
    P, P_abs, Q, Q_abs = _rk_numerator_denominator(tableau)
    p_lin = rk_linear_order(tableau)
    out = []
    for imaginary in (False, True):
        q2, q2_abs = _square_on_ray(Q, Q_abs, imaginary)
        p2, p2_abs = _square_on_ray(P, P_abs, imaginary)
        F = _poly_add(q2, -p2)
        F_abs = _poly_add(q2_abs, p2_abs)
        direction = 1j if imaginary else -1.0

        def excess(x: float, direction=direction) -> float:
            value = abs(amplification.rk_stability_function(tableau, np.array([direction * x]))[0])
            return value - 1.0 - tol.STABILITY_AMPLIFICATION_TOL if np.isfinite(value) else math.nan

        out.append(_interval_end(F, F_abs, p_lin if imaginary else 0, excess))
    return out[0], out[1]


def splitting_trace_polynomial(scheme: SplittingScheme) -> tuple[np.ndarray, np.ndarray]:
    """The trace of the propagator on x'' = -x as a polynomial in h (ascending), with magnitudes.

    Parameters
    ----------
    scheme : SplittingScheme

    Returns
    -------
    tuple
        (trace coefficients, their magnitudes, the propagator's 2x2 entries as polynomials in h,
        the same over |coefficients|); the last two are nested lists of ndarrays.
    """
    check_type(scheme, "splitting", "scheme")
    M = [[np.array([1.0]), np.array([0.0])], [np.array([0.0]), np.array([1.0])]]
    Ma = [[np.array([1.0]), np.array([0.0])], [np.array([0.0]), np.array([1.0])]]
    for kind, c in scheme.sequence:
        if kind == "D":  # [[1, c h], [0, 1]] @ M
            row = [_poly_add(M[0][j], _poly_mul(np.array([0.0, c]), M[1][j])) for j in range(2)]
            row_a = [_poly_add(Ma[0][j], _poly_mul(np.array([0.0, abs(c)]), Ma[1][j])) for j in range(2)]
            M, Ma = [row, M[1]], [row_a, Ma[1]]
        else:  # [[1, 0], [-c h, 1]] @ M
            row = [_poly_add(M[1][j], _poly_mul(np.array([0.0, -c]), M[0][j])) for j in range(2)]
            row_a = [_poly_add(Ma[1][j], _poly_mul(np.array([0.0, abs(c)]), Ma[0][j])) for j in range(2)]
            M, Ma = [M[0], row], [Ma[0], row_a]
    return _poly_add(M[0][0], M[1][1]), _poly_add(Ma[0][0], Ma[1][1]), M, Ma


def splitting_linear_order(scheme: SplittingScheme) -> int:
    """The order of the propagator on x'' = -x against the exact rotation [[cos h, sin h],
    [-sin h, cos h]]: the method's order on linear problems q'' = -K q (K diagonalisable).

    Parameters
    ----------
    scheme : SplittingScheme

    Returns
    -------
    int: the largest p such that the propagator matches the rotation through h^p.
    """
    _, _, M, Ma = splitting_trace_polynomial(scheme)
    top = max(m.size for row in M for m in row)
    exact = [[lambda k: (-1) ** (k // 2) / math.factorial(k) if k % 2 == 0 else 0.0,
              lambda k: (-1) ** (k // 2) / math.factorial(k) if k % 2 == 1 else 0.0],
             [lambda k: -((-1) ** (k // 2)) / math.factorial(k) if k % 2 == 1 else 0.0,
              lambda k: (-1) ** (k // 2) / math.factorial(k) if k % 2 == 0 else 0.0]]
    for k in range(1, top + 2):
        for i in range(2):
            for j in range(2):
                m = M[i][j][k] if k < M[i][j].size else 0.0
                ma = Ma[i][j][k] if k < Ma[i][j].size else 0.0
                want = exact[i][j](k)
                allowed = max(tol.ORDER_CONDITION_ULPS * tol.EPS * k * ma,
                              tol.ORDER_CONDITION_TOL * abs(want), tol.ORDER_CONDITION_FLOOR)
                if abs(m - want) > allowed:
                    return k - 1
    return top


def splitting_hw_limit(scheme: SplittingScheme) -> float:
    """The first instability of a splitting on x'' = -omega^2 x: the largest h omega with
    |tr M| < 2 on (0, h omega), decided exactly on the trace polynomial (every band:
    `harness.theory.newtonian.splitting_hw_bands`).

    Parameters
    ----------
    scheme : SplittingScheme

    Returns
    -------
    float: the limit (inf when stable up to the search bound of the exact bands).
    """
    check_type(scheme, "splitting", "scheme")
    return exact_hw_bands(scheme).limit


def exact_hw_bands(coefficients: Any):
    """`harness.theory.newtonian.hw_bands` of a Newtonian coefficient object, computed once per
    coefficients (exact root isolation takes up to seconds for 15-stage compositions).

    Parameters
    ----------
    coefficients : SplittingScheme or SecondOrderMultistep
        A Newtonian coefficient object (anything with `fingerprint()` that `hw_bands` knows).

    Returns
    -------
    HwBands or None: its exact stability bands, None for another family.
    """
    return _bands_cached(coefficients.fingerprint(), (coefficients,))


@lru_cache(maxsize=256)
def _bands_cached(fingerprint: str, box: tuple):
    return hw_bands(box[0], tol.STABILITY_HW_SEARCH_LIMIT)


def lmm_real_interval(method: LinearMultistep, scanned: float) -> float:
    """The real stability interval of a multistep method without a search ceiling.

    The boundary of the stability region lies on the root locus z(theta) = rho(e^(i theta)) /
    sigma(e^(i theta)) (Hairer & Wanner II, V.1): the interval on the negative real axis can only
    end where the locus crosses it. Crossings are found on a fine theta grid and refined; the
    first crossing beyond which the method is unstable ends the interval. When the scan found
    the method stable up to its limit (`scanned` = inf) and the locus never crosses the negative
    real axis beyond it, while every root of sigma lies inside the unit disc (the roots as
    z -> -inf), the whole axis is stable: inf, proven. Otherwise the scanned figure stands.

    Parameters
    ----------
    method : LinearMultistep
    scanned : float, the interval found by scanning the amplification (`real_stability_interval`).

    Returns
    -------
    float
        The interval length x of [-x, 0]: `scanned` when finite; otherwise the first locus
        crossing beyond which the method is unstable, inf when proven, else `scanned`.
    """
    alpha, beta = method.alpha, method.beta

    def z_of(theta: np.ndarray) -> np.ndarray:
        zeta = np.exp(1j * np.asarray(theta))
        with np.errstate(all="ignore"):
            return np.polyval(alpha[::-1], zeta) / np.polyval(beta[::-1], zeta)

    theta = np.linspace(1e-6, np.pi, 200001)
    z = z_of(theta)
    im = z.imag
    crossings = []
    for i in np.flatnonzero(np.sign(im[:-1]) * np.sign(im[1:]) < 0):
        t = brentq(lambda x: float(z_of(x).imag), theta[i], theta[i + 1], xtol=1e-15)
        crossings.append(float(z_of(t).real))
    crossings.append(float(z_of(np.pi).real))
    negative = sorted(-x for x in crossings if np.isfinite(x) and x < 0)

    def amp(x: float) -> float:
        return float(amplification.lmm_amplification(method, np.array([-x + 0j]))[0])

    if math.isfinite(scanned):
        return scanned
    beyond = [x for x in negative if x > 0 and amp(x * (1 + 1e-6)) > 1 + tol.STABILITY_AMPLIFICATION_TOL]
    if beyond:
        return float(beyond[0])
    sigma_roots = np.roots(beta[::-1]) if np.any(beta[:-1]) or beta[-1] != 0 else np.array([])
    if sigma_roots.size and np.max(np.abs(sigma_roots)) >= 1.0:
        return scanned
    return math.inf


def analytic_stability(coefficients: Any, *, limit: float = tol.STABILITY_SEARCH_LIMIT) -> dict | None:
    """Stability figures from a coefficient object, or None when it has none (or an unknown
    kind). First-order families: {'kind': 'first-order', 'amplification': z -> |R|,
    'real_interval', 'imag_interval'}; Newtonian: {'kind': 'newtonian', 'amplification':
    hw -> spectral radius, 'hw_limit'}.

    Parameters
    ----------
    coefficients : coefficient object, any object; read by the `family` it declares.
    limit : float, optional, the scan limit of the multistep intervals (STABILITY_SEARCH_LIMIT).

    Returns
    -------
    dict or None: the figures described above; Newtonian ones also carry 'hw_bands'.
    """
    family = family_of(coefficients)
    if family == "runge-kutta":
        def amp(z):
            return np.abs(amplification.rk_stability_function(coefficients, z))
        real, imag = rk_stability_intervals(coefficients)
        return {"kind": "first-order", "amplification": amp, "real_interval": real,
                "imag_interval": imag}
    if family == "multistep":
        def amp(z):
            return amplification.lmm_amplification(coefficients, z)
        real = amplification.real_stability_interval(amp, limit=limit)
        return {"kind": "first-order", "amplification": amp,
                "real_interval": lmm_real_interval(coefficients, real),
                "imag_interval": amplification.imag_stability_interval(amp, limit=limit)}
    if family in ("splitting", "second-order multistep"):
        if family == "splitting":
            def hw_amp(hw):
                return amplification.splitting_amplification(coefficients, hw)
        else:
            def hw_amp(hw):
                return amplification.second_order_lmm_amplification(coefficients, hw)
        bands = exact_hw_bands(coefficients)
        return {"kind": "newtonian", "amplification": hw_amp, "hw_limit": bands.limit,
                "hw_bands": bands}
    return None
