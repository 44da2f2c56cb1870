"""Stability intervals decided at rounding level, with no search ceiling.

- A stability function whose |R(iy)|^2 exceeds 1 by c y^4 with c = 2e-6 has imaginary interval
  exactly 0 (a tolerance on |R| - 1 would report (tol/c)^(1/4) ~ 1e-2).
- A damped Chebyshev method (Verwer, Hundsdorfer & Sommeijer, Numer. Math. 57 (1990) 157) of 25
  stages has real interval 2 w0 / w1 ~ 1236, beyond any fixed search limit of 1000: reported as
  that number, not as unbounded.
- An A-stable implicit method is unbounded on both axes, proven from the polynomials.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from harness.coefficients import ButcherTableau
from harness.theory import rk_stability_intervals


def _tableau_with_stability_polynomial(r: list[float]) -> ButcherTableau:
    """An explicit 4-stage tableau (classical stage matrix) whose R(z) = sum r_k z^k, r_0 = 1."""
    A = np.array([[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]])
    M = np.array([np.linalg.matrix_power(A, k) @ np.ones(4) for k in range(4)])
    b = np.linalg.solve(M, np.array(r[1:5]))
    return ButcherTableau("poly", A, b)


def test_tiny_excess_on_the_imaginary_axis_gives_a_zero_interval():
    delta = 1e-6
    tab = _tableau_with_stability_polynomial([1, 1, 1 / 2, 1 / 6, 1 / 24 + delta])
    real, imag = rk_stability_intervals(tab)
    assert imag == 0.0
    assert real > 2.5
    # Without the excess (classical RK4's R) the interval is 2 sqrt(2).
    tab = _tableau_with_stability_polynomial([1, 1, 1 / 2, 1 / 6, 1 / 24])
    assert rk_stability_intervals(tab)[1] == pytest.approx(2 * math.sqrt(2), abs=1e-9)


def _damped_chebyshev(s: int, eps: float) -> tuple[ButcherTableau, float]:
    w0 = 1 + eps / s**2
    Ts = np.polynomial.chebyshev.Chebyshev.basis(s)
    w1 = Ts(w0) / Ts.deriv()(w0)
    zeros = [(math.cos((2 * k - 1) * math.pi / (2 * s)) - w0) / w1 for k in range(1, s + 1)]
    tau = [-1.0 / z for z in zeros]
    A = np.zeros((s, s))
    for i in range(s):
        A[i, :i] = tau[:i]
    return ButcherTableau("chebyshev", A, tau), 2 * w0 / w1


def test_real_interval_beyond_a_thousand_is_a_number():
    tab, expected = _damped_chebyshev(25, 0.05)
    assert expected > 1000
    real, _ = rk_stability_intervals(tab)
    assert math.isfinite(real)
    # R evaluated in stage form at x ~ 1200 carries rounding of ~1e-3 in |R|: 1e-5 relative.
    assert real == pytest.approx(expected, rel=1e-5)


def test_a_stable_method_is_proven_unbounded():
    s3 = math.sqrt(3)
    gauss = ButcherTableau("gauss4", [[1 / 4, 1 / 4 - s3 / 6], [1 / 4 + s3 / 6, 1 / 4]], [1 / 2, 1 / 2])
    assert rk_stability_intervals(gauss) == (math.inf, math.inf)
