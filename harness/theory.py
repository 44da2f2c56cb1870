"""Order and linear stability from the coefficients alone: what a method *should* do.

Everything here is a pure function of a coefficient object of `harness.coefficients`; nothing
integrates a registered problem. The experiments measure the same properties from the outside
and compare.

Order
-----
- Runge-Kutta (`rk_order`): Butcher's order conditions, one per rooted tree t with |t| <= p:
  the elementary weight Phi(t) = b^T g(t), with g(leaf) = e and g([t_1 ... t_m]) the
  component-wise product of A g(t_i), must equal 1/gamma(t) (the tree's density).
  Hairer, Norsett & Wanner, *Solving ODEs I*, II.2 (Theorem 2.13); Butcher, *Numerical Methods
  for ODEs* (2016), 3.1-3.2. There are 1, 1, 2, 4, 9, 20, 48, 115 trees of order 1..8.
- Linear multistep (`lmm_order`): the error constants C_q = sum_j j^q alpha_j / q! -
  sum_j j^(q-1) beta_j / (q-1)! vanish for q <= p. Hairer, Norsett & Wanner I, III.2.
- Second-order multistep for x'' = a (`second_order_lmm_order`): C_q = sum_j j^q alpha_j / q! -
  sum_j j^(q-2) beta_j / (q-2)! vanish for q <= p + 1. Hairer, Norsett & Wanner I, III.10.
- Splitting / composition (`splitting_order`): the local error of the scheme, expanded as an
  exact power series in h on a generic separable Hamiltonian problem (see `splitting_order`).
  Hairer, Lubich & Wanner, *Geometric Numerical Integration*, III.3 and V.3.

Linear stability
----------------
- Runge-Kutta: R(z) = 1 + z b^T (I - zA)^{-1} e (`rk_stability_function`).
- Linear multistep: the largest root modulus of rho(zeta) - z sigma(zeta) (the root condition,
  `lmm_amplification`). Hairer & Wanner, *Solving ODEs II*, V.1.
- Newtonian methods on x'' = -omega^2 x: the one-step propagator as a function of h*omega
  (`splitting_propagator`, `second_order_lmm_amplification`).
- Intervals (`real_stability_interval`, `imag_stability_interval`, `stability_boundary`): the
  first crossing of |R| = 1 on a scan, refined by root finding (never read off a grid).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache, lru_cache
from typing import Any

import numpy as np

from harness import tolerances as tol
from harness.coefficients import (
    ButcherTableau,
    LinearMultistep,
    SecondOrderMultistep,
    SplittingScheme,
)
from harness.errors import InputError

__all__ = [
    "RootedTree",
    "OrderCondition",
    "rooted_trees",
    "rk_order",
    "rk_order_conditions",
    "rk_order_series",
    "lmm_error_constants",
    "lmm_order",
    "second_order_lmm_error_constants",
    "second_order_lmm_order",
    "splitting_order",
    "splitting_local_error_series",
    "order_from_coefficients",
    "rk_stability_function",
    "lmm_amplification",
    "second_order_lmm_amplification",
    "splitting_propagator",
    "splitting_amplification",
    "spectral_radius",
    "stability_boundary",
    "real_stability_interval",
    "imag_stability_interval",
    "hw_stability_limit",
    "analytic_stability",
    "rk_linear_order",
    "lmm_real_interval",
    "rk_stability_coefficients",
    "rk_stability_intervals",
    "splitting_linear_order",
    "splitting_hw_limit",
    "MAX_TREE_ORDER",
]

MAX_TREE_ORDER = 12  # 7813 trees up to order 12 (4766 of order 12)


def _check_int(value: Any, name: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise InputError(f"`{name}` must be a whole number, got {value!r}")
    if not lo <= value <= hi:
        raise InputError(f"`{name}` must lie in [{lo}, {hi}], got {value}")
    return int(value)


def _check_type(obj: Any, cls: type, name: str) -> None:
    if not isinstance(obj, cls):
        raise InputError(f"`{name}` must be a {cls.__name__}, got {type(obj).__name__}")


# =============================================================================================
# Rooted trees and the Runge-Kutta order conditions
# =============================================================================================
@dataclass(frozen=True)
class RootedTree:
    """A rooted tree: `children` are indices into the same `rooted_trees` tuple (non-increasing,
    so each tree has one canonical form). `gamma` is the density, `label` Butcher's bracket
    notation with `*` for the single vertex ([*] has two vertices, [**] and [[*]] three)."""

    index: int
    children: tuple[int, ...]
    order: int
    gamma: int
    label: str


@cache
def rooted_trees(max_order: int = 8) -> tuple[RootedTree, ...]:
    """All rooted trees with at most `max_order` vertices, ordered by order.

    A tree of order n is a multiset of subtrees whose orders sum to n - 1, grafted on a new root;
    multisets are enumerated as non-increasing index sequences, so every tree appears once.
    """
    max_order = _check_int(max_order, "max_order", 1, MAX_TREE_ORDER)
    trees: list[RootedTree] = [RootedTree(0, (), 1, 1, "*")]

    def multisets(remaining: int, max_index: int):
        if remaining == 0:
            yield ()
            return
        for i in range(max_index, -1, -1):
            o = trees[i].order
            if o <= remaining:
                for rest in multisets(remaining - o, i):
                    yield (i, *rest)

    for n in range(2, max_order + 1):
        new = []
        for kids in multisets(n - 1, len(trees) - 1):
            gamma = n * math.prod(trees[k].gamma for k in kids)
            label = "[" + "".join(trees[k].label for k in kids) + "]"
            new.append((kids, gamma, label))
        for kids, gamma, label in new:
            trees.append(RootedTree(len(trees), kids, n, gamma, label))
    return tuple(trees)


@dataclass(frozen=True)
class OrderCondition:
    """One order condition: elementary weight Phi(t) against 1/gamma(t)."""

    tree: str
    order: int
    elementary_weight: float
    expected: float
    residual: float
    satisfied: bool


def _elementary_weights(tableau: ButcherTableau, max_order: int,
                        weights: np.ndarray | None = None) -> tuple[list[float], list[float]]:
    """Phi(t) = b^T g(t) for every tree up to `max_order`, and the same sum taken over the
    magnitudes |b|, |A| (the size the rounding of Phi(t) scales with)."""
    trees = rooted_trees(max_order)
    A, b = tableau.A, tableau.b if weights is None else weights
    absA, absb = np.abs(A), np.abs(b)
    g: list[np.ndarray] = []
    g_abs: list[np.ndarray] = []
    for t in trees:
        v = np.ones(tableau.stages)
        v_abs = np.ones(tableau.stages)
        for k in t.children:
            v = v * (A @ g[k])
            v_abs = v_abs * (absA @ g_abs[k])
        g.append(v)
        g_abs.append(v_abs)
    return [float(b @ gk) for gk in g], [float(absb @ gk) for gk in g_abs]


def _condition_tol(t: RootedTree, size: float) -> float:
    """How far Phi(t) may sit from 1/gamma(t) through rounding alone: ORDER_CONDITION_ULPS
    roundings per vertex of the sum of magnitudes, and never less than ORDER_CONDITION_TOL
    relative to the condition's value 1/gamma(t) nor ORDER_CONDITION_FLOOR (tableaux published
    with 13-14 digits)."""
    return max(tol.ORDER_CONDITION_ULPS * tol.EPS * t.order * size,
               tol.ORDER_CONDITION_TOL / t.gamma, tol.ORDER_CONDITION_FLOOR)


def rk_order_conditions(tableau: ButcherTableau, order: int) -> list[OrderCondition]:
    """The order conditions of exactly `order` (one per rooted tree with `order` vertices),
    with residual Phi(t) - 1/gamma(t); satisfied when |residual| is within rounding
    (`_condition_tol`)."""
    _check_type(tableau, ButcherTableau, "tableau")
    order = _check_int(order, "order", 1, MAX_TREE_ORDER)
    trees = rooted_trees(order)
    phi, size = _elementary_weights(tableau, order)
    out = []
    for t in trees:
        if t.order != order:
            continue
        expected = 1.0 / t.gamma
        r = phi[t.index] - expected
        out.append(OrderCondition(t.label, t.order, phi[t.index], expected, r,
                                  abs(r) <= _condition_tol(t, size[t.index])))
    return out


def rk_order(tableau: ButcherTableau, max_order: int | None = None,
             weights: np.ndarray | None = None) -> int:
    """The order of a Butcher tableau: the largest p <= `max_order` such that every order
    condition of order <= p holds to rounding (`_condition_tol`, scaled by the size of the
    coefficients). By default `max_order` is the highest order the tableau could have (s for
    an explicit s-stage method, 2s otherwise), capped at MAX_TREE_ORDER; a result equal to
    MAX_TREE_ORDER means "at least that". `weights` replaces b (an embedded method)."""
    _check_type(tableau, ButcherTableau, "tableau")
    if max_order is None:
        max_order = min(MAX_TREE_ORDER, tableau.stages if tableau.explicit else 2 * tableau.stages)
    max_order = _check_int(max_order, "max_order", 1, MAX_TREE_ORDER)
    phi, size = _elementary_weights(tableau, max_order, weights)
    failed = [t.order for t in rooted_trees(max_order)
              if abs(phi[t.index] - 1.0 / t.gamma) > _condition_tol(t, size[t.index])]
    return min(failed) - 1 if failed else max_order


def rk_stability_coefficients(tableau: ButcherTableau, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Taylor coefficients r_k = b^T A^(k-1) e of R(z) for k = 0..degree (r_0 = 1), and the same
    products over |b|, |A| (their rounding scale)."""
    r, r_abs = [1.0], [1.0]
    v, v_abs = np.ones(tableau.stages), np.ones(tableau.stages)
    for _ in range(degree):
        r.append(float(tableau.b @ v))
        r_abs.append(float(np.abs(tableau.b) @ v_abs))
        v, v_abs = tableau.A @ v, np.abs(tableau.A) @ v_abs
    return np.array(r), np.array(r_abs)


def rk_linear_order(tableau: ButcherTableau) -> int:
    """The order of R(z) against e^z: the largest p with r_k = 1/k! for k <= p. It is the
    method's order on linear constant-coefficient problems, at least its order and higher for
    some methods (several SSP methods, Merson's). Checked up to 2s + 2 (beyond any s-stage
    order) and capped there."""
    _check_type(tableau, ButcherTableau, "tableau")
    top = min(2 * tableau.stages + 2, 40)
    r, r_abs = rk_stability_coefficients(tableau, top)
    for k in range(1, top + 1):
        exact = 1.0 / math.factorial(k)
        allowed = max(tol.ORDER_CONDITION_ULPS * tol.EPS * k * r_abs[k], tol.ORDER_CONDITION_TOL * exact)
        if abs(r[k] - exact) > allowed:
            return k - 1
    return top


# =============================================================================================
# Multistep order
# =============================================================================================
def _constants(alpha: np.ndarray, beta: np.ndarray, q_max: int, shift: int):
    j = np.arange(alpha.size, dtype=float)
    C, scale = [], []
    for q in range(q_max + 1):
        a_terms = j**q * alpha / math.factorial(q)
        if q >= shift:
            b_terms = j ** (q - shift) * beta / math.factorial(q - shift)
        else:
            b_terms = np.zeros_like(beta)
        C.append(float(a_terms.sum() - b_terms.sum()))
        scale.append(float(np.abs(a_terms).sum() + np.abs(b_terms).sum()))
    return np.array(C), np.array(scale)


def lmm_error_constants(method: LinearMultistep, q_max: int | None = None) -> np.ndarray:
    """C_0 ... C_{q_max} of a linear multistep method (default q_max = 2k + 1, beyond the
    highest order any k-step method reaches)."""
    _check_type(method, LinearMultistep, "method")
    q_max = 2 * method.steps + 1 if q_max is None else _check_int(q_max, "q_max", 0, 40)
    return _constants(method.alpha, method.beta, q_max, 1)[0]


def _order_from_constants(C: np.ndarray, scale: np.ndarray, offset: int) -> int:
    bad = np.abs(C) > tol.ORDER_CONDITION_TOL * np.maximum(1.0, scale)
    first = int(np.argmax(bad)) if bad.any() else C.size
    return first - offset


def lmm_order(method: LinearMultistep) -> int:
    """The order p of a linear multistep method: C_0 = ... = C_p = 0 and C_{p+1} != 0 (each
    constant compared with ORDER_CONDITION_TOL times the size of its terms). 0 means not even
    consistent (which `LinearMultistep` already refuses)."""
    _check_type(method, LinearMultistep, "method")
    C, scale = _constants(method.alpha, method.beta, 2 * method.steps + 1, 1)
    return _order_from_constants(C, scale, 1)


def second_order_lmm_error_constants(method: SecondOrderMultistep, q_max: int | None = None):
    """C_0 ... C_{q_max} of a multistep method for x'' = a (default q_max = 2k + 2)."""
    _check_type(method, SecondOrderMultistep, "method")
    q_max = 2 * method.steps + 2 if q_max is None else _check_int(q_max, "q_max", 0, 40)
    return _constants(method.alpha, method.beta, q_max, 2)[0]


def second_order_lmm_order(method: SecondOrderMultistep) -> int:
    """The order p of a multistep method for x'' = a: C_0 = ... = C_{p+1} = 0 (Stormer's rule
    alpha = (1, -2, 1), beta = (0, 1, 0) has C_4 = 1/12, order 2)."""
    _check_type(method, SecondOrderMultistep, "method")
    C, scale = _constants(method.alpha, method.beta, 2 * method.steps + 2, 2)
    return _order_from_constants(C, scale, 2)


# =============================================================================================
# Exact local-error series (truncated power series in h, high-precision arithmetic)
# =============================================================================================
# The generic test problems. Coefficients are decimal strings with no special structure, and
# the exponential makes every derivative of the vector field non-zero, so an elementary
# differential of any tree (any bracket of the split vector fields) can show up in the error.
_SERIES_DPS = 60
# U(q) = k1 q1^2/2 + k2 q2^2/2 + kap q1 q2 + c1 q1^2 q2 + c2 q2^3/3 + eps exp(al q1 + be q2)
_NEWTON_COEFFS = {
    "k1": "1.1319", "k2": "0.7853", "kap": "0.3183", "c1": "0.2718", "c2": "-0.4142",
    "eps": "0.5772", "al": "0.6931", "be": "-0.3679",
}
_NEWTON_STARTS = (("0.3141", "-0.2236", "0.1732", "0.4472"),
                  ("-0.1618", "0.2646", "-0.3317", "0.1414"))
_FIRST_COEFFS = {
    "a1": "0.6180", "a2": "-0.4142", "a3": "0.5772", "a4": "0.6931", "a5": "-0.3679",
    "b1": "-0.7071", "b2": "0.2718", "b3": "-0.3183",
    "c1": "0.1732", "c2": "0.4472", "c3": "-0.2236", "c4": "0.1",
}
_FIRST_STARTS = (("0.3141", "-0.2236", "0.1732"), ("-0.1618", "0.2646", "-0.3317"))


class _Series:
    """Truncated power series arithmetic on lists of mpmath numbers (degree `N`)."""

    def __init__(self, mp, N: int):
        self.mp = mp
        self.N = N
        self.zero = mp.mpf(0)

    def const(self, c) -> list:
        return [self.mp.mpf(c)] + [self.zero] * self.N

    def add(self, *terms: list) -> list:
        return [sum((t[n] for t in terms), self.zero) for n in range(self.N + 1)]

    def scale(self, c, a: list) -> list:
        return [c * x for x in a]

    def mul(self, a: list, b: list) -> list:
        return [sum((a[k] * b[n - k] for k in range(n + 1)), self.zero) for n in range(self.N + 1)]

    def shift(self, a: list) -> list:
        """Multiply by the series variable (h or t)."""
        return [self.zero, *a[: self.N]]

    def exp(self, a: list) -> list:
        e = [self.mp.exp(a[0])]
        for n in range(1, self.N + 1):
            e.append(sum((k * a[k] * e[n - k] for k in range(1, n + 1)), self.zero) / n)
        return e


def _newton_accel(S: _Series, P: dict, q: list[list]) -> list[list]:
    q1, q2 = q
    E = S.exp(S.add(S.scale(P["al"], q1), S.scale(P["be"], q2)))
    q1q2 = S.mul(q1, q2)
    a1 = S.add(S.scale(P["k1"], q1), S.scale(P["kap"], q2), S.scale(2 * P["c1"], q1q2),
               S.scale(P["eps"] * P["al"], E))
    a2 = S.add(S.scale(P["k2"], q2), S.scale(P["kap"], q1), S.scale(P["c1"], S.mul(q1, q1)),
               S.scale(P["c2"], S.mul(q2, q2)), S.scale(P["eps"] * P["be"], E))
    return [S.scale(-1, a1), S.scale(-1, a2)]


def _first_rhs(S: _Series, P: dict, y: list[list]) -> list[list]:
    y1, y2, y3 = y
    E1 = S.exp(S.add(S.scale(P["a4"], y1), S.scale(P["a5"], y3)))
    E2 = S.exp(S.scale(P["c2"], y2))
    f1 = S.add(S.scale(P["a1"], y2), S.scale(P["a2"], S.mul(y1, y3)), S.scale(P["a3"], E1))
    f2 = S.add(S.scale(P["b1"], y1), S.scale(P["b2"], S.mul(y2, y2)), S.scale(P["b3"], y3))
    f3 = S.add(S.scale(P["c1"], S.mul(E2, y1)), S.scale(P["c3"], y3), S.const(P["c4"]))
    return [f1, f2, f3]


def _exact_flow(S: _Series, F: Callable[[list], list], y0: list) -> list[list]:
    """Taylor coefficients of the exact solution of y' = F(y), y(0) = y0, by Picard iteration
    on series (each sweep fixes one more coefficient)."""
    y = [S.const(c) for c in y0]
    for _ in range(S.N):
        f = F(y)
        y = [[c] + [f[i][n - 1] / n for n in range(1, S.N + 1)] for i, c in enumerate(y0)]
    return y


def _error_profile(S: _Series, numeric: list[list], exact: list[list]):
    err = [max(abs(numeric[i][n] - exact[i][n]) for i in range(len(exact))) for n in range(S.N + 1)]
    size = [max(abs(exact[i][n]) for i in range(len(exact))) for n in range(S.N + 1)]
    return err, size


def splitting_local_error_series(scheme: SplittingScheme, degree: int = 11) -> list[float]:
    """|e_n|, n = 0..degree: the coefficients of h^n in the local error of `scheme` on the
    generic problem (max over components and the two starting points), in units of the size of
    the exact solution's h^n coefficient (at least 1)."""
    _check_type(scheme, SplittingScheme, "scheme")
    degree = _check_int(degree, "degree", 1, 16)
    import mpmath

    out = [0.0] * (degree + 1)
    with mpmath.workdps(_SERIES_DPS):
        mp = mpmath.mp
        S = _Series(mp, degree)
        P = {k: mp.mpf(v) for k, v in _NEWTON_COEFFS.items()}
        steps = [(kind, mp.mpf(float(c))) for kind, c in scheme.sequence]  # exact float values

        def F(y):
            return [y[2], y[3], *_newton_accel(S, P, y[:2])]

        for start in _NEWTON_STARTS:
            y0 = [mp.mpf(v) for v in start]
            q = [S.const(y0[0]), S.const(y0[1])]
            v = [S.const(y0[2]), S.const(y0[3])]
            for kind, c in steps:
                if kind == "D":
                    q = [S.add(q[i], S.scale(c, S.shift(v[i]))) for i in range(2)]
                else:
                    a = _newton_accel(S, P, q)
                    v = [S.add(v[i], S.scale(c, S.shift(a[i]))) for i in range(2)]
            err, size = _error_profile(S, q + v, _exact_flow(S, F, y0))
            for n in range(degree + 1):
                out[n] = max(out[n], float(err[n] / max(mp.mpf(1), size[n])))
    return out


def _order_from_series(errors: list[float], max_order: int) -> int:
    bad = [n for n, e in enumerate(errors) if e > tol.SERIES_ORDER_TOL]
    return min(bad) - 1 if bad else max_order


@lru_cache(maxsize=256)
def _splitting_order_cached(fingerprint: str, max_order: int, scheme_box: tuple) -> int:
    return _order_from_series(splitting_local_error_series(scheme_box[0], max_order + 1), max_order)


def splitting_order(scheme: SplittingScheme, max_order: int = 10) -> int:
    """The order of a drift/kick composition, from its coefficients, by an exact expansion.

    Method (Hairer, Lubich & Wanner, *Geometric Numerical Integration*, III.3 and V.3): the
    order of a splitting scheme is the largest p for which its local error is O(h^(p+1)) for
    every separable problem q'' = a(q). The scheme is applied to a generic 2-degree-of-freedom
    separable Hamiltonian H = |v|^2/2 + U(q) (a polynomial potential plus an exponential term,
    decimal coefficients with no special structure, two starting points) with h kept as a
    formal variable: every drift and kick acts on truncated power series in h, in 60-digit
    arithmetic (mpmath). The exact flow's Taylor series comes from Picard iteration on series.
    Their difference gives the coefficients e_n of h^n in the local error exactly (the float64
    coefficients are converted without rounding), so no step-size sweep, slope fit or rounding
    floor is involved: the order is p = (first n with |e_n| > SERIES_ORDER_TOL) - 1, e_n
    measured relative to the exact solution's coefficient of h^n. A slope fit would be
    spoiled by the float64 rounding of the coefficients themselves (a defect of ~1e-16 h in the
    local error that hides h^9 below h ~ 1e-2). Returns `max_order` when every coefficient up
    to h^(max_order+1) vanishes.
    """
    _check_type(scheme, SplittingScheme, "scheme")
    max_order = _check_int(max_order, "max_order", 1, 14)
    return _splitting_order_cached(scheme.fingerprint(), max_order, (scheme,))


def rk_order_series(tableau: ButcherTableau, max_order: int = 8) -> int:
    """The order of a Runge-Kutta tableau by the same exact series expansion as
    `splitting_order`, on a generic 3-dimensional first-order system: an independent check of
    the rooted-tree count in `rk_order`. The stage equations (implicit or not) are solved on
    series by fixed-point iteration, which fixes one more power of h per sweep."""
    _check_type(tableau, ButcherTableau, "tableau")
    max_order = _check_int(max_order, "max_order", 1, 12)
    import mpmath

    degree = max_order + 1
    worst = [0.0] * (degree + 1)
    with mpmath.workdps(_SERIES_DPS):
        mp = mpmath.mp
        S = _Series(mp, degree)
        P = {k: mp.mpf(v) for k, v in _FIRST_COEFFS.items()}
        A = [[mp.mpf(float(x)) for x in row] for row in tableau.A]
        b = [mp.mpf(float(x)) for x in tableau.b]
        s = tableau.stages

        def F(y):
            return _first_rhs(S, P, y)

        for start in _FIRST_STARTS:
            y0 = [mp.mpf(v) for v in start]
            Y0 = [S.const(c) for c in y0]
            K = [F(Y0) for _ in range(s)]
            for _ in range(degree + 1):
                for i in range(s):  # Gauss-Seidel sweep: explicit tableaux settle in one
                    Yi = [S.add(Y0[m], S.shift(S.add(*[S.scale(A[i][j], K[j][m]) for j in range(s)])))
                          for m in range(3)]
                    K[i] = F(Yi)
            y1 = [S.add(Y0[m], S.shift(S.add(*[S.scale(b[j], K[j][m]) for j in range(s)])))
                  for m in range(3)]
            err, size = _error_profile(S, y1, _exact_flow(S, F, y0))
            for n in range(degree + 1):
                worst[n] = max(worst[n], float(err[n] / max(mp.mpf(1), size[n])))
    return _order_from_series(worst, max_order)


def order_from_coefficients(stepper: Any) -> int | None:
    """The order implied by a stepper's coefficient object (`stepper.coefficients`), or None
    when it has none (external, adaptive, Taylor) or of a kind this module does not know."""
    coeffs = getattr(stepper, "coefficients", None)
    if isinstance(coeffs, ButcherTableau):
        return rk_order(coeffs)
    if isinstance(coeffs, LinearMultistep):
        return lmm_order(coeffs)
    if isinstance(coeffs, SecondOrderMultistep):
        return second_order_lmm_order(coeffs)
    if isinstance(coeffs, SplittingScheme):
        return splitting_order(coeffs)
    return None


# =============================================================================================
# Linear stability from the coefficients
# =============================================================================================
def rk_stability_function(tableau: ButcherTableau, z: Any) -> np.ndarray:
    """R(z) = 1 + z b^T (I - zA)^{-1} e for an array of complex z (poles give inf or nan)."""
    _check_type(tableau, ButcherTableau, "tableau")
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
    method is stable at z when it is <= 1 (with simple roots on the unit circle)."""
    _check_type(method, LinearMultistep, "method")
    z = np.asarray(z, dtype=complex)
    coeffs = method.alpha[None, :] - z.reshape(-1, 1) * method.beta[None, :]
    return _max_root_modulus(coeffs).reshape(z.shape)


def second_order_lmm_amplification(method: SecondOrderMultistep, hw: Any) -> np.ndarray:
    """For x'' = -omega^2 x: the largest root modulus of sum_j (alpha_j + (h omega)^2 beta_j)
    zeta^j, for each h*omega in `hw`."""
    _check_type(method, SecondOrderMultistep, "method")
    hw = np.asarray(hw, dtype=float)
    coeffs = method.alpha[None, :] + (hw.reshape(-1, 1) ** 2) * method.beta[None, :]
    return _max_root_modulus(coeffs.astype(complex)).reshape(hw.shape)


def splitting_propagator(scheme: SplittingScheme, hw: Any) -> np.ndarray:
    """The one-step matrix of `scheme` on (x, v) for x'' = -x with step h*omega (omega = 1):
    a drift a is [[1, a h], [0, 1]], a kick b is [[1, 0], [-b h, 1]], applied in sequence order.
    Shape hw.shape + (2, 2)."""
    _check_type(scheme, SplittingScheme, "scheme")
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
    """Largest eigenvalue modulus of a batch of square matrices (..., k, k); inf if not finite."""
    M = np.asarray(M)
    flat = M.reshape(-1, M.shape[-2], M.shape[-1])
    out = np.full(flat.shape[0], np.inf)
    finite = np.all(np.isfinite(flat.reshape(flat.shape[0], -1)), axis=1)
    if finite.any():
        out[finite] = np.max(np.abs(np.linalg.eigvals(flat[finite])), axis=-1)
    return out.reshape(M.shape[:-2])


def splitting_amplification(scheme: SplittingScheme, hw: Any) -> np.ndarray:
    """Spectral radius of `splitting_propagator(scheme, hw)`."""
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
    """
    from scipy.optimize import brentq

    try:
        limit = float(limit)
    except (TypeError, ValueError):
        raise InputError(f"`limit` must be a positive number, got {limit!r}") from None
    if not (math.isfinite(limit) and limit > 0):
        raise InputError(f"`limit` must be positive and finite, got {limit!r}")
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
    function `R` (complex z array -> R(z) or |R(z)|); see `stability_boundary`."""
    return stability_boundary(lambda x: np.abs(R(-np.asarray(x) + 0j)), **kwargs)


def imag_stability_interval(R: Callable[[np.ndarray], np.ndarray], **kwargs: Any) -> float:
    """The largest y with |R(i s)| <= 1 for s in [0, y]; see `stability_boundary`."""
    return stability_boundary(lambda y: np.abs(R(1j * np.asarray(y))), **kwargs)


def hw_stability_limit(amplification: Callable[[np.ndarray], np.ndarray], **kwargs: Any) -> float:
    """The largest h*omega with spectral radius <= 1 on (0, h*omega]; see `stability_boundary`."""
    return stability_boundary(amplification, **kwargs)


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
    import mpmath

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
    from scipy.optimize import brentq

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
    (exact zeros from the linear order), the end located on R evaluated in stage form."""
    _check_type(tableau, ButcherTableau, "tableau")
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
            value = abs(rk_stability_function(tableau, np.array([direction * x]))[0])
            return value - 1.0 - tol.STABILITY_AMPLIFICATION_TOL if np.isfinite(value) else math.nan

        out.append(_interval_end(F, F_abs, p_lin if imaginary else 0, excess))
    return out[0], out[1]


def splitting_trace_polynomial(scheme: SplittingScheme) -> tuple[np.ndarray, np.ndarray]:
    """The trace of the propagator on x'' = -x as a polynomial in h (ascending), with magnitudes."""
    _check_type(scheme, SplittingScheme, "scheme")
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
    [-sin h, cos h]]: the method's order on linear problems q'' = -K q (K diagonalisable)."""
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
    """Largest h omega with |tr M| <= 2 on (0, h omega] (det M = 1: the eigenvalues stay on the
    unit circle): the sign near 0 from the polynomial 4 - tr(h)^2, the end located on the trace
    of the propagator multiplied out numerically."""
    tr, tr_abs, _, _ = splitting_trace_polynomial(scheme)
    F = _poly_add(np.array([4.0]), -_poly_mul(tr, tr))
    F_abs = _poly_add(np.array([4.0]), _poly_mul(tr_abs, tr_abs))

    def excess(hw: float) -> float:
        M = splitting_propagator(scheme, np.array([hw]))[0]
        return abs(M[0, 0] + M[1, 1]) / 2.0 - 1.0 - tol.STABILITY_AMPLIFICATION_TOL

    return _interval_end(F, F_abs, 1, excess)


def lmm_real_interval(method: LinearMultistep, scanned: float) -> float:
    """The real stability interval of a multistep method without a search ceiling.

    The boundary of the stability region lies on the root locus z(theta) = rho(e^(i theta)) /
    sigma(e^(i theta)) (Hairer & Wanner II, V.1): the interval on the negative real axis can only
    end where the locus crosses it. Crossings are found on a fine theta grid and refined; the
    first crossing beyond which the method is unstable ends the interval. When the scan found
    the method stable up to its limit (`scanned` = inf) and the locus never crosses the negative
    real axis beyond it, while every root of sigma lies inside the unit disc (the roots as
    z -> -inf), the whole axis is stable: inf, proven. Otherwise the scanned figure stands."""
    from scipy.optimize import brentq

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
        return float(lmm_amplification(method, np.array([-x + 0j]))[0])

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
    hw -> spectral radius, 'hw_limit'}."""
    if isinstance(coefficients, ButcherTableau):
        def amp(z):
            return np.abs(rk_stability_function(coefficients, z))
    elif isinstance(coefficients, LinearMultistep):
        def amp(z):
            return lmm_amplification(coefficients, z)
    elif isinstance(coefficients, SplittingScheme):
        def hw_amp(hw):
            return splitting_amplification(coefficients, hw)
    elif isinstance(coefficients, SecondOrderMultistep):
        def hw_amp(hw):
            return second_order_lmm_amplification(coefficients, hw)
    else:
        return None
    if isinstance(coefficients, ButcherTableau):
        real, imag = rk_stability_intervals(coefficients)
        return {"kind": "first-order", "amplification": amp, "real_interval": real,
                "imag_interval": imag}
    if isinstance(coefficients, LinearMultistep):
        return {
            "kind": "first-order",
            "amplification": amp,
            "real_interval": lmm_real_interval(coefficients, real_stability_interval(amp, limit=limit)),
            "imag_interval": imag_stability_interval(amp, limit=limit),
        }
    if isinstance(coefficients, SplittingScheme):
        return {"kind": "newtonian", "amplification": hw_amp, "hw_limit": splitting_hw_limit(coefficients)}
    return {"kind": "newtonian", "amplification": hw_amp,
            "hw_limit": hw_stability_limit(hw_amp, limit=limit)}
