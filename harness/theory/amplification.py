"""Linear stability functions from the coefficients, and stability intervals found by a scan.

- Runge-Kutta: R(z) = 1 + z b^T (I - zA)^{-1} e (`rk_stability_function`).
- Linear multistep: the largest root modulus of rho(zeta) - z sigma(zeta) (the root condition,
  `lmm_amplification`). Hairer & Wanner, *Solving ODEs II*, V.1.
- Newtonian methods on x'' = -omega^2 x: the one-step propagator as a function of h*omega
  (`splitting_propagator`, `second_order_lmm_amplification`).
- Intervals (`real_stability_interval`, `imag_stability_interval`, `stability_boundary`): the
  first crossing of |R| = 1 on a scan, refined by root finding (never read off a grid).

Arguments shared by the functions below: `method` or `scheme` is a coefficient object of the
family its annotation names; `z` holds complex points h lambda and `hw` values of h omega, of
any shape, and a result over them keeps that shape.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.optimize import brentq

from harness import tolerances as tol
from harness.errors import InputError
from harness.problem.checks import check_positive
from harness.theory.checks import check_type

if TYPE_CHECKING:  # annotations only: the theory reads coefficient objects by their `family`
    from harness.coefficients import ButcherTableau, LinearMultistep, SecondOrderMultistep, SplittingScheme

__all__ = ["rk_stability_function", "lmm_amplification", "second_order_lmm_amplification",
           "splitting_propagator", "spectral_radius", "splitting_amplification",
           "stability_boundary", "real_stability_interval", "imag_stability_interval",
           "hw_stability_limit"]


def rk_stability_function(tableau: ButcherTableau, z: Any) -> np.ndarray:
    """R(z) = 1 + z b^T (I - zA)^{-1} e for an array of complex z (poles give inf or nan).

    Parameters
    ----------
    tableau : ButcherTableau; z : complex array_like.

    Returns
    -------
    ndarray, complex, shape of `z`: R(z).
    """
    check_type(tableau, "runge-kutta", "tableau")
    z = np.asarray(z, dtype=complex)
    with np.errstate(all="ignore"):
        try:
            return tableau.stability_function(z)
        except np.linalg.LinAlgError:  # a z exactly at a pole: evaluate point by point
            flat = z.reshape(-1)
            out = np.empty(flat.shape, dtype=complex)
            for i, zi in enumerate(flat):
                try:
                    out[i] = tableau.stability_function(np.array([zi]))[0]
                except np.linalg.LinAlgError:
                    out[i] = complex(np.inf, 0.0)
            return out.reshape(z.shape)


def _max_root_modulus(coeffs: np.ndarray) -> np.ndarray:
    """Largest root modulus of polynomials sum_j coeffs[..., j] zeta^j (ascending order), in a
    batch; inf where the leading coefficient vanishes (a root at infinity)."""
    k = coeffs.shape[-1] - 1
    lead = coeffs[..., -1]
    flat = coeffs.reshape(-1, k + 1)
    lead_flat = lead.reshape(-1)
    out = np.full(flat.shape[0], np.inf)
    ok = np.abs(lead_flat) > 0.0
    if k == 0:
        out[ok] = 0.0
        return out.reshape(lead.shape)
    with np.errstate(all="ignore"):
        monic = flat[ok] / lead_flat[ok, None]
        comp = np.zeros((monic.shape[0], k, k), dtype=complex)
        comp[:, 0, :] = -monic[:, k - 1 :: -1][:, :k]
        if k > 1:
            idx = np.arange(k - 1)
            comp[:, idx + 1, idx] = 1.0
        finite = np.all(np.isfinite(comp.reshape(comp.shape[0], -1)), axis=1)
        vals = np.full(monic.shape[0], np.inf)
        if finite.any():
            vals[finite] = np.max(np.abs(np.linalg.eigvals(comp[finite])), axis=-1)
    out[ok] = vals
    return out.reshape(lead.shape)


def lmm_amplification(method: LinearMultistep, z: Any) -> np.ndarray:
    """The largest modulus of the roots of rho(zeta) - z sigma(zeta) for each complex z: the
    method is stable at z when it is <= 1 (with simple roots on the unit circle).

    Parameters
    ----------
    method : LinearMultistep; z : complex array_like (h lambda).

    Returns
    -------
    ndarray, shape of `z`: the largest root modulus at each point.
    """
    check_type(method, "multistep", "method")
    z = np.asarray(z, dtype=complex)
    coeffs = method.alpha[None, :] - z.reshape(-1, 1) * method.beta[None, :]
    return _max_root_modulus(coeffs).reshape(z.shape)


def second_order_lmm_amplification(method: SecondOrderMultistep, hw: Any) -> np.ndarray:
    """For x'' = -omega^2 x: the largest root modulus of sum_j (alpha_j + (h omega)^2 beta_j)
    zeta^j, for each h*omega in `hw`.

    Parameters
    ----------
    method : SecondOrderMultistep; hw : array_like.

    Returns
    -------
    ndarray, shape of `hw`: the largest root modulus at each value.
    """
    check_type(method, "second-order multistep", "method")
    hw = np.asarray(hw, dtype=float)
    coeffs = method.alpha[None, :] + (hw.reshape(-1, 1) ** 2) * method.beta[None, :]
    return _max_root_modulus(coeffs.astype(complex)).reshape(hw.shape)


def splitting_propagator(scheme: SplittingScheme, hw: Any) -> np.ndarray:
    """The one-step matrix of `scheme` on (x, v) for x'' = -x with step h*omega (omega = 1):
    a drift a is [[1, a h], [0, 1]], a kick b is [[1, 0], [-b h, 1]], applied in sequence order.
    Shape hw.shape + (2, 2).

    Parameters
    ----------
    scheme : SplittingScheme, the composition; hw : array_like.

    Returns
    -------
    ndarray, shape hw.shape + (2, 2): the one-step matrices.
    """
    check_type(scheme, "splitting", "scheme")
    hw = np.asarray(hw, dtype=float)
    flat = hw.reshape(-1)
    M = np.broadcast_to(np.eye(2), (flat.size, 2, 2)).copy()
    for kind, c in scheme.sequence:
        S = np.broadcast_to(np.eye(2), (flat.size, 2, 2)).copy()
        if kind == "D":
            S[:, 0, 1] = c * flat
        else:
            S[:, 1, 0] = -c * flat
        M = S @ M
    return M.reshape(*hw.shape, 2, 2)


def spectral_radius(M: np.ndarray) -> np.ndarray:
    """Largest eigenvalue modulus of a batch of square matrices (..., k, k); inf if not finite.

    Parameters
    ----------
    M : array_like, shape (..., k, k)

    Returns
    -------
    ndarray, shape M.shape[:-2]
        max |eigenvalue| of each matrix.
    """
    M = np.asarray(M)
    flat = M.reshape(-1, M.shape[-2], M.shape[-1])
    out = np.full(flat.shape[0], np.inf)
    finite = np.all(np.isfinite(flat.reshape(flat.shape[0], -1)), axis=1)
    if finite.any():
        out[finite] = np.max(np.abs(np.linalg.eigvals(flat[finite])), axis=-1)
    return out.reshape(M.shape[:-2])


def splitting_amplification(scheme: SplittingScheme, hw: Any) -> np.ndarray:
    """Spectral radius of `splitting_propagator(scheme, hw)`.

    Parameters
    ----------
    scheme, hw : as for `splitting_propagator`.

    Returns
    -------
    ndarray, shape of `hw`: the spectral radius of the one-step matrix at each value.
    """
    return spectral_radius(splitting_propagator(scheme, hw))


# -- intervals --------------------------------------------------------------------------------
def _scan_grid(limit: float, step: float) -> np.ndarray:
    linear_end = min(limit, tol.STABILITY_SCAN_LINEAR_END)
    grid = np.arange(1, max(1, int(round(linear_end / step))) + 1) * step
    if limit > grid[-1]:
        start = grid[-1]
        ratio = max(tol.STABILITY_SCAN_RATIO, 1.0 + step)
        n = int(math.ceil(math.log(limit / start) / math.log(ratio)))
        grid = np.concatenate([grid, start * ratio ** np.arange(1, n + 1)])
        grid[-1] = min(grid[-1], limit)
    return grid


def stability_boundary(
    amplification: Callable[[np.ndarray], np.ndarray],
    *,
    limit: float = tol.STABILITY_SEARCH_LIMIT,
    scan_step: float = tol.STABILITY_SCAN_STEP,
    amplification_tol: float = tol.STABILITY_AMPLIFICATION_TOL,
    xtol: float = tol.STABILITY_XTOL,
) -> float:
    """The largest x in (0, `limit`] with amplification(s) <= 1 + `amplification_tol` for every
    s in (0, x]: the end of the stable interval starting at the origin.

    `amplification` maps a float array of positions along the ray to amplification factors (|R|
    or a spectral radius); it is called once on the whole scan (so a black-box probe can run the
    scan as one ensemble) and then on single points by Brent's method. The scan is linear with
    step `scan_step` up to STABILITY_SCAN_LINEAR_END and geometric beyond; the first
    scan point outside the stable set brackets the crossing, which `scipy.optimize.brentq`
    refines to `xtol`. Returns 0.0 when the first scan point is already unstable (the interval
    is empty: e.g. explicit Euler on the imaginary axis) and +inf when no scan point up to
    `limit` is unstable (reported as unbounded up to `limit`). An unstable gap narrower than the
    scan step is not seen.

    Parameters
    ----------
    amplification : callable, positions x (float array) -> amplification factors (array of the same shape).
    limit : float, optional, the end of the search (STABILITY_SEARCH_LIMIT).
    scan_step : float, optional, the linear scan's step, in (0, min(limit, 1)] (STABILITY_SCAN_STEP).
    amplification_tol : float, optional
        How far above 1 a factor may be and still count as stable (STABILITY_AMPLIFICATION_TOL).
    xtol : float, optional, the bracket width at which Brent's method stops (STABILITY_XTOL).

    Returns
    -------
    float: the end of the stable interval: 0.0, a finite x, or +inf.
    """
    limit = check_positive(limit, "`limit`")
    if not (isinstance(scan_step, int | float) and 0 < scan_step <= min(limit, 1.0)):
        raise InputError(f"`scan_step` must lie in (0, min(limit, 1)], got {scan_step!r}")
    grid = _scan_grid(limit, float(scan_step))
    with np.errstate(all="ignore"):
        amp = np.asarray(amplification(grid), dtype=float).reshape(-1)
    if amp.shape != grid.shape:
        raise InputError(
            f"`amplification` must return one value per point, got {amp.shape} for {grid.shape}"
        )
    unstable = ~(amp <= 1.0 + amplification_tol)  # NaN counts as unstable
    if not unstable.any():
        return math.inf
    k = int(np.argmax(unstable))
    if k == 0:
        return 0.0

    def g(x: float) -> float:
        with np.errstate(all="ignore"):
            v = float(np.asarray(amplification(np.array([x])), dtype=float).reshape(-1)[0])
        return v - 1.0 - amplification_tol if np.isfinite(v) else math.inf

    return float(brentq(g, grid[k - 1], grid[k], xtol=xtol, rtol=4 * tol.EPS, maxiter=200))


def real_stability_interval(R: Callable[[np.ndarray], np.ndarray], **kwargs: Any) -> float:
    """x such that [-x, 0] is the stable interval on the negative real axis of the amplification
    function `R` (complex z array -> R(z) or |R(z)|); see `stability_boundary`.

    Parameters
    ----------
    R : callable, complex z array -> R(z) or |R(z)|.
    **kwargs
        Passed to `stability_boundary` (limit, scan_step, amplification_tol, xtol).

    Returns
    -------
    float: the length x of the stable interval [-x, 0] (0.0, finite, or inf).
    """
    return stability_boundary(lambda x: np.abs(R(-np.asarray(x) + 0j)), **kwargs)


def imag_stability_interval(R: Callable[[np.ndarray], np.ndarray], **kwargs: Any) -> float:
    """The largest y with |R(i s)| <= 1 for s in [0, y]; see `stability_boundary`.

    Parameters
    ----------
    R : callable, complex z array -> R(z) or |R(z)|.
    **kwargs
        Passed to `stability_boundary`.

    Returns
    -------
    float: y (0.0, finite, or inf).
    """
    return stability_boundary(lambda y: np.abs(R(1j * np.asarray(y))), **kwargs)


def hw_stability_limit(amplification: Callable[[np.ndarray], np.ndarray], **kwargs: Any) -> float:
    """The largest h*omega with spectral radius <= 1 on (0, h*omega]; see `stability_boundary`.

    Parameters
    ----------
    amplification : callable, h omega array -> spectral radius of the one-step map (array of the same shape).
    **kwargs
        Passed to `stability_boundary`.

    Returns
    -------
    float: the limit (0.0, finite, or inf).
    """
    return stability_boundary(amplification, **kwargs)
