"""The coefficients' own precision: how far a tableau misses its order conditions, and the error
floor that sets, whatever the arithmetic.

A record given to d digits satisfies Butcher's conditions Phi(t) = 1/gamma(t) only to about
10^-d. Its local error then carries the terms sum_t h^|t| (Phi(t) - 1/gamma(t)) F(t) / sigma(t)
for every tree of order <= p as well as the truncation terms beyond p (Hairer, Norsett & Wanner
I, II.2-II.3, Theorem 3.3), and the global error cannot fall below what those terms accumulate
over the horizon: a real128 sweep of a 16-digit record meets this floor near 1e-17, not at
real128 rounding. `condition_defects` measures the defects in 320-bit fixed-point arithmetic on
the exact form (Fractions) of the record, or on the float64 values themselves when the record
has no exact form; `defect_floor` turns them into the smallest error a sweep can show.
"""

from __future__ import annotations

from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

from harness.theory.orders import rooted_trees

if TYPE_CHECKING:  # annotations only: the theory reads coefficient objects by their `family`
    from harness.coefficients import ButcherTableau

__all__ = ["condition_defects", "defect_floor", "DEFECT_MAX_ORDER"]

# Trees beyond this order are not checked for defects: a defect of order q enters the global
# error as h^(q-1), so at the step sizes a sweep fits (h rho < 1) the low orders dominate, and
# digit-rounded records miss every order's conditions by about the same amount (286 trees).
DEFECT_MAX_ORDER = 8
_BITS = 320


def _fixed(x) -> int:
    f = x if isinstance(x, Fraction) else Fraction(float(x))
    return (f.numerator << _BITS) // f.denominator


def condition_defects(tableau: ButcherTableau, max_order: int, weights: str = "b",
                      as_run_in_float64: bool = False) -> list[tuple[float, float]]:
    """Per order q = 1..max_order (capped at DEFECT_MAX_ORDER): the sum over the trees of order q
    of |Phi(t) - 1/gamma(t)|, and the sum of the magnitudes |b|^T g_abs(t) the elementary weights
    are formed from (their rounding scale), computed exactly enough (320 bits) to see defects far
    below real128 rounding.

    Parameters
    ----------
    tableau : the method; its exact form is used where it has one, else its float64 values
    max_order : highest order whose conditions are checked
    weights : 'b' for the method, 'b_hat' for its embedded method
    as_run_in_float64 : measure the float64 values a float64 loop runs instead of the exact form
        (weights summing |b| to 1e5 lose ~1e-11 to that rounding)

    Returns
    -------
    [(defect_q, size_q)] for q = 1..min(max_order, DEFECT_MAX_ORDER)."""
    top = max(0, min(int(max_order), DEFECT_MAX_ORDER))
    exact = tableau.exact is not None and (weights == "b" or tableau.exact_b_hat is not None)
    if exact and not as_run_in_float64:
        A, b, _ = tableau.exact
        if weights == "b_hat":
            b = tableau.exact_b_hat
    else:
        A, b = tableau.A.tolist(), (tableau.b if weights == "b" else tableau.b_hat).tolist()
    s = len(b)
    Ai = np.array([[_fixed(x) for x in row] for row in A], dtype=object)
    bi = np.array([_fixed(x) for x in b], dtype=object)
    absA, absb = np.abs(np.array(A, dtype=float)), np.abs(np.array(b, dtype=float))
    one = 1 << _BITS
    g: list[np.ndarray] = []
    g_abs: list[np.ndarray] = []
    out = [[0.0, 0.0] for _ in range(top)]
    for t in rooted_trees(max(top, 1)):
        v = np.array([one] * s, dtype=object)
        v_abs = np.ones(s)
        for k in t.children:
            Ag = Ai.dot(g[k])  # scaled by 2^(2 BITS)
            v = np.array([(x * (y >> _BITS)) >> _BITS for x, y in zip(v, Ag, strict=True)], dtype=object)
            v_abs = v_abs * (absA @ g_abs[k])
        g.append(v)
        g_abs.append(v_abs)
        if t.order > top:
            continue
        phi = int(bi.dot(v)) >> _BITS
        defect = abs(Fraction(phi, one) - Fraction(1, t.gamma))
        out[t.order - 1][0] += float(defect)
        out[t.order - 1][1] += float(absb @ v_abs)
    return [(d, size) for d, size in out]


def defect_floor(defects: list[tuple[float, float]], noise: float, h: np.ndarray, *, span: float,
                 rate: float, scale: float, amplification: float = 1.0) -> np.ndarray:
    """The error the coefficients' defects alone leave at step size h over the horizon: each
    step commits sum_q d_q (h rate)^q scale (a tree's elementary differential is of size
    rate^q |y|), span / h steps carry it to the end, and the flow amplifies it. Defects within
    `noise` x their size (what rounding the coefficients to the arithmetic leaves) count as zero.

    Parameters
    ----------
    defects : `condition_defects` output
    noise : relative rounding level of the arithmetic the sweep runs in (per unit of size and order)
    h : step sizes
    span, rate, scale, amplification : horizon length, fastest rate 1/time, size of the state,
        the flow's error amplification over the horizon

    Returns
    -------
    The floor at each h (0 where every defect is rounding)."""
    h = np.asarray(h, dtype=float)
    floor = np.zeros_like(h)
    for q, (d, size) in enumerate(defects, start=1):
        if d > noise * q * max(1.0, size):
            floor = floor + d * (h * rate) ** q
    return floor * (span / h) * scale * max(1.0, amplification)
