"""The formula side of the stability experiment: recurrence blocks and amplification from a
method's coefficients (`harness.theory`), and their entry-by-entry comparison with a probe."""

from __future__ import annotations

from typing import Any

import numpy as np

from harness import theory
from harness.coefficients import (
    ButcherTableau,
    LinearMultistep,
    SecondOrderMultistep,
    SplittingScheme,
)
from harness.experiments.stability.probes import NewtonianProbe


def _complex_block(c: np.ndarray) -> np.ndarray:
    """Complex numbers (...) -> their real 2x2 multiplication blocks (..., 2, 2)."""
    out = np.empty((*c.shape, 2, 2))
    out[..., 0, 0] = c.real
    out[..., 0, 1] = -c.imag
    out[..., 1, 0] = c.imag
    out[..., 1, 1] = c.real
    return out


def analytic_blocks(coeffs: Any, z: np.ndarray, k: int) -> np.ndarray | None:
    """The recurrence blocks the coefficients predict at each z, shaped like the probe's, or
    None when the coefficients do not describe a first-order recurrence of length k.

    Parameters
    ----------
    coeffs : coefficient object (ButcherTableau for k = 1, LinearMultistep with k steps).
    z : ndarray of complex, the points h lambda.
    k : int, the recurrence length the probe measured.

    Returns
    -------
    ndarray or None
    """
    if isinstance(coeffs, ButcherTableau) and k == 1:
        return _complex_block(theory.rk_stability_function(coeffs, z))[:, None]
    if isinstance(coeffs, LinearMultistep) and coeffs.steps == k:
        with np.errstate(all="ignore"):
            lead = coeffs.alpha[-1] - z * coeffs.beta[-1]
            c = -(coeffs.alpha[None, :-1] - z[:, None] * coeffs.beta[None, :-1]) / lead[:, None]
        return _complex_block(c)
    return None


def first_order_analytic_amp(coeffs: Any, z: np.ndarray) -> np.ndarray | None:
    """|R(z)| (Runge-Kutta) or the largest root modulus (linear multistep) from `coeffs` for
    each complex z, or None for coefficients of another kind.

    Parameters
    ----------
    coeffs : coefficient object, a ButcherTableau or a LinearMultistep.
    z : ndarray of complex, the points h lambda.

    Returns
    -------
    ndarray of float or None: same shape as `z`.
    """
    if isinstance(coeffs, ButcherTableau):
        return np.abs(theory.rk_stability_function(coeffs, z))
    if isinstance(coeffs, LinearMultistep):
        return theory.lmm_amplification(coeffs, z)
    return None


def relative_diff(probe: np.ndarray, analytic: np.ndarray) -> tuple[float, int, int]:
    """max |probe - analytic| / max(1, |analytic|) per point over points where the analytic
    value is finite; also the number of such points where the probe failed, and the number of
    points excluded (poles of the formula).

    Parameters
    ----------
    probe, analytic : ndarray, the measured and predicted values, one leading axis over points.

    Returns
    -------
    (float, int, int): the largest difference (0 when no point is finite in both), the probe's
        failures, the poles left out.
    """
    axes = tuple(range(1, analytic.ndim))
    finite_a = np.all(np.isfinite(analytic), axis=axes)
    finite_p = np.all(np.isfinite(probe), axis=axes)
    both = finite_a & finite_p
    if both.any():
        scale = np.maximum(1.0, np.max(np.abs(analytic[both]), axis=axes))
        diff = float(np.max(np.max(np.abs(probe[both] - analytic[both]), axis=axes) / scale))
    else:
        diff = 0.0
    return diff, int(np.sum(finite_a & ~finite_p)), int(np.sum(~finite_a))



def newtonian_pair(coeffs: Any, probe: NewtonianProbe, hw: float, matrix: np.ndarray):
    """(measured, predicted) arrays to compare at step `hw`, in the probe's coordinates, or None
    when the coefficients say nothing about what this probe sees.

    Parameters
    ----------
    coeffs : coefficient object, a SplittingScheme or a SecondOrderMultistep.
    probe : NewtonianProbe, what the probe measured (its mode and history length).
    hw : float, h omega on x'' = -omega^2 x.
    matrix : ndarray, the measured propagator or recurrence.

    Returns
    -------
    (ndarray, ndarray) or None
    """
    if isinstance(coeffs, SplittingScheme) and probe.mode == "one-step":
        return matrix, theory.splitting_propagator(coeffs, hw)
    if not isinstance(coeffs, SecondOrderMultistep):
        return None
    w2 = hw * hw
    k = coeffs.steps
    c = -(coeffs.alpha[:k] + w2 * coeffs.beta[:k]) / (coeffs.alpha[k] + w2 * coeffs.beta[k])
    if probe.mode == "position-recurrence" and k == 2:
        return matrix, np.array([[0.0, 1.0], [c[0], c[1]]])
    if probe.mode == "history" and probe.k == k and probe.last_blocks is not None:
        # the position row of each block: x_k = sum_j c_j x_j, no dependence on the velocities
        measured = probe.last_blocks[:, 0, :]
        return measured, np.stack([c, np.zeros(k)], axis=1)
    return None


def coefficient_size(coeffs: Any) -> float:
    """The sum of the magnitudes of the coefficients that enter one step (at least 1): the
    rounding of a step grows with it (a weighted sum sum b_i k_i rounds to eps sum |b_i| |k_i|),
    so the probe-formula agreement is judged relative to it.

    Parameters
    ----------
    coeffs : coefficient object (tableau, multistep or splitting; any other kind gives 1).

    Returns
    -------
    float
    """
    if isinstance(coeffs, ButcherTableau):
        return max(1.0, float(np.abs(coeffs.A).sum() + np.abs(coeffs.b).sum()))
    if isinstance(coeffs, LinearMultistep | SecondOrderMultistep):
        return max(1.0, float(np.abs(coeffs.alpha).sum() + np.abs(coeffs.beta).sum()))
    if isinstance(coeffs, SplittingScheme):
        return max(1.0, float(sum(abs(c) for _, c in coeffs.sequence)))
    return 1.0


def newtonian_rounding_scale(coeffs: Any, hw: float, predicted: np.ndarray) -> float:
    """How much larger than one rounding of an O(1) number the rounding of the propagator (or
    recurrence) entries can be at step `hw`, relative to max(1, |predicted|): for a splitting
    the entries of |D_1| |K_1| ... (the product of the factors' magnitudes, which bounds the
    rounding of the product), for a multistep recurrence (|alpha_j| + hw^2 |beta_j|) /
    |alpha_k + hw^2 beta_k|; at least 1.

    Parameters
    ----------
    coeffs : coefficient object, a SplittingScheme or a SecondOrderMultistep (else 1).
    hw : float, h omega.
    predicted : ndarray, the predicted propagator or recurrence.

    Returns
    -------
    float
    """
    big = max(1.0, float(np.max(np.abs(predicted))))
    if isinstance(coeffs, SplittingScheme):
        mag = np.eye(2)
        for kind, c in coeffs.sequence:
            factor = np.eye(2)
            factor[(0, 1) if kind == "D" else (1, 0)] = abs(c) * hw
            mag = factor @ mag
        return max(1.0, float(np.max(mag)) / big)
    if isinstance(coeffs, SecondOrderMultistep):
        w2 = hw * hw
        lead = float(abs(coeffs.alpha[-1] + w2 * coeffs.beta[-1]))
        if lead == 0:
            return 1.0
        return max(1.0, float(np.sum(np.abs(coeffs.alpha) + w2 * np.abs(coeffs.beta))) / lead / big)
    return 1.0


def newtonian_analytic_amp(coeffs: Any, hw: np.ndarray) -> np.ndarray | None:
    """The spectral radius of the propagator on x'' = -x from `coeffs` for each h omega in `hw`,
    or None for coefficients of another kind.

    Parameters
    ----------
    coeffs : coefficient object, a SplittingScheme or a SecondOrderMultistep.
    hw : ndarray, the values of h omega.

    Returns
    -------
    ndarray of float or None: same shape as `hw`.
    """
    if isinstance(coeffs, SplittingScheme):
        return theory.splitting_amplification(coeffs, hw)
    if isinstance(coeffs, SecondOrderMultistep):
        return theory.second_order_lmm_amplification(coeffs, hw)
    return None
