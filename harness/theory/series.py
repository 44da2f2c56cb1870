"""Order from an exact local-error series: a method applied to a generic problem with h kept as a
formal variable (truncated power series in h, 60-digit mpmath arithmetic).

`splitting_order` gives the order of drift/kick compositions (Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, III.3 and V.3); `rk_order_series` is an independent check
of the rooted-tree count for Runge-Kutta tableaux.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from typing import TYPE_CHECKING

import mpmath

from harness import tolerances as tol
from harness.theory.checks import check_int, check_type

if TYPE_CHECKING:  # annotations only: the theory reads coefficient objects by their `family`
    from harness.coefficients import ButcherTableau, SplittingScheme

__all__ = ["splitting_local_error_series", "splitting_order", "rk_order_series"]


# =============================================================================================
# Exact local-error series (truncated power series in h, high-precision arithmetic)
# =============================================================================================
# The generic test problems. Coefficients are decimal strings with no special structure, and
# the exponential makes every derivative of the vector field non-zero, so an elementary
# differential of any tree (any bracket of the split vector fields) can show up in the error.
_SERIES_DPS = 60
# U(q) = k1 q1^2/2 + k2 q2^2/2 + kap q1 q2 + c1 q1^2 q2 + c2 q2^3/3 + eps exp(al q1 + be q2)
NEWTON_COEFFS = {
    "k1": "1.1319", "k2": "0.7853", "kap": "0.3183", "c1": "0.2718", "c2": "-0.4142",
    "eps": "0.5772", "al": "0.6931", "be": "-0.3679",
}
NEWTON_STARTS = (("0.3141", "-0.2236", "0.1732", "0.4472"),
                  ("-0.1618", "0.2646", "-0.3317", "0.1414"))
_FIRST_COEFFS = {
    "a1": "0.6180", "a2": "-0.4142", "a3": "0.5772", "a4": "0.6931", "a5": "-0.3679",
    "b1": "-0.7071", "b2": "0.2718", "b3": "-0.3183",
    "c1": "0.1732", "c2": "0.4472", "c3": "-0.2236", "c4": "0.1",
}
_FIRST_STARTS = (("0.3141", "-0.2236", "0.1732"), ("-0.1618", "0.2646", "-0.3317"))


class Series:
    """Truncated power series arithmetic on lists of mpmath numbers (degree `N`)."""

    def __init__(self, mp, N: int):
        self.mp = mp
        self.N = N
        self.zero = mp.mpf(0)

    def const(self, c) -> list:
        """A constant as a series.

        Parameters
        ----------
        c : number or str, the constant (converted with ``mp.mpf``).

        Returns
        -------
        list: [c, 0, ..., 0], N + 1 coefficients.
        """
        return [self.mp.mpf(c)] + [self.zero] * self.N

    def add(self, *terms: list) -> list:
        """The sum of series.

        Parameters
        ----------
        *terms : list, series of degree N.

        Returns
        -------
        list: their coefficient-wise sum.
        """
        return [sum((t[n] for t in terms), self.zero) for n in range(self.N + 1)]

    def scale(self, c, a: list) -> list:
        """A series times a constant.

        Parameters
        ----------
        c : mpmath number, the factor.
        a : list

        Returns
        -------
        list: c a.
        """
        return [c * x for x in a]

    def mul(self, a: list, b: list) -> list:
        """The product of two series, truncated at degree N (Cauchy product).

        Parameters
        ----------
        a, b : list, series of degree N.

        Returns
        -------
        list: a b mod h^(N+1).
        """
        return [sum((a[k] * b[n - k] for k in range(n + 1)), self.zero) for n in range(self.N + 1)]

    def shift(self, a: list) -> list:
        """Multiply by the series variable (h or t).

        Parameters
        ----------
        a : list, a series (its coefficient of degree N drops out).

        Returns
        -------
        list: h a, truncated at degree N.
        """
        return [self.zero, *a[: self.N]]

    def exp(self, a: list) -> list:
        """exp of a series (the recurrence from e' = a' e).

        Parameters
        ----------
        a : list

        Returns
        -------
        list: exp(a), truncated at degree N.
        """
        e = [self.mp.exp(a[0])]
        for n in range(1, self.N + 1):
            e.append(sum((k * a[k] * e[n - k] for k in range(1, n + 1)), self.zero) / n)
        return e


def newton_accel(S: Series, P: dict, q: list[list]) -> list[list]:
    """The acceleration a(q) = -grad U of the generic separable test problem, on series.

    U(q) = k1 q1^2/2 + k2 q2^2/2 + kap q1 q2 + c1 q1^2 q2 + c2 q2^3/3 + eps exp(al q1 + be q2).

    Parameters
    ----------
    S : Series, the series arithmetic.
    P : dict, the coefficients of U by name (`NEWTON_COEFFS`, as mpmath numbers).
    q : list of two series, the positions q1, q2.

    Returns
    -------
    list of two series: a_1(q), a_2(q).
    """
    q1, q2 = q
    E = S.exp(S.add(S.scale(P["al"], q1), S.scale(P["be"], q2)))
    q1q2 = S.mul(q1, q2)
    a1 = S.add(S.scale(P["k1"], q1), S.scale(P["kap"], q2), S.scale(2 * P["c1"], q1q2),
               S.scale(P["eps"] * P["al"], E))
    a2 = S.add(S.scale(P["k2"], q2), S.scale(P["kap"], q1), S.scale(P["c1"], S.mul(q1, q1)),
               S.scale(P["c2"], S.mul(q2, q2)), S.scale(P["eps"] * P["be"], E))
    return [S.scale(-1, a1), S.scale(-1, a2)]


def _first_rhs(S: Series, P: dict, y: list[list]) -> list[list]:
    y1, y2, y3 = y
    E1 = S.exp(S.add(S.scale(P["a4"], y1), S.scale(P["a5"], y3)))
    E2 = S.exp(S.scale(P["c2"], y2))
    f1 = S.add(S.scale(P["a1"], y2), S.scale(P["a2"], S.mul(y1, y3)), S.scale(P["a3"], E1))
    f2 = S.add(S.scale(P["b1"], y1), S.scale(P["b2"], S.mul(y2, y2)), S.scale(P["b3"], y3))
    f3 = S.add(S.scale(P["c1"], S.mul(E2, y1)), S.scale(P["c3"], y3), S.const(P["c4"]))
    return [f1, f2, f3]


def exact_flow(S: Series, F: Callable[[list], list], y0: list) -> list[list]:
    """Taylor coefficients of the exact solution of y' = F(y), y(0) = y0, by Picard iteration
    on series (each sweep fixes one more coefficient).

    Parameters
    ----------
    S : Series, the series arithmetic (degree N).
    F : callable, the vector field on lists of series.
    y0 : list, the initial state (numbers).

    Returns
    -------
    list of series: y_i(h) to degree N, one per component.
    """
    y = [S.const(c) for c in y0]
    for _ in range(S.N):
        f = F(y)
        y = [[c] + [f[i][n - 1] / n for n in range(1, S.N + 1)] for i, c in enumerate(y0)]
    return y


def _error_profile(S: Series, numeric: list[list], exact: list[list]):
    err = [max(abs(numeric[i][n] - exact[i][n]) for i in range(len(exact))) for n in range(S.N + 1)]
    size = [max(abs(exact[i][n]) for i in range(len(exact))) for n in range(S.N + 1)]
    return err, size


def splitting_local_error_series(scheme: SplittingScheme, degree: int = 11) -> list[float]:
    """|e_n|, n = 0..degree: the coefficients of h^n in the local error of `scheme` on the
    generic problem (max over components and the two starting points), in units of the size of
    the exact solution's h^n coefficient (at least 1).

    Parameters
    ----------
    scheme : SplittingScheme
    degree : int, optional, the last power of h, 1 to 16 (default 11).

    Returns
    -------
    list of float: |e_0|, ..., |e_degree|.
    """
    check_type(scheme, "splitting", "scheme")
    degree = check_int(degree, "degree", 1, 16)

    out = [0.0] * (degree + 1)
    with mpmath.workdps(_SERIES_DPS):
        mp = mpmath.mp
        S = Series(mp, degree)
        steps = [(kind, mp.mpf(float(c))) for kind, c in scheme.sequence]  # exact float values
        for numeric, exact in composition_series(mp, S, steps):
            err, size = _error_profile(S, numeric, exact)
            for n in range(degree + 1):
                out[n] = max(out[n], float(err[n] / max(mp.mpf(1), size[n])))
    return out


def composition_series(mp, S: Series, steps: list) -> list[tuple[list, list]]:
    """For each starting point of the generic separable problem (`NEWTON_STARTS`): the Taylor
    series in h of the drift/kick composition `steps` ([(kind, coefficient)], mp numbers) and of
    the exact flow, each as the four components [q1, q2, v1, v2].

    Parameters
    ----------
    mp : the mpmath context (its precision is the caller's).
    S : the truncated power-series arithmetic.
    steps : the composition's (kind, coefficient) sequence, "D" drifts and "K" kicks.

    Returns
    -------
    One (numeric, exact) pair of series lists per starting point.
    """
    P = {k: mp.mpf(v) for k, v in NEWTON_COEFFS.items()}

    def F(y):
        return [y[2], y[3], *newton_accel(S, P, y[:2])]

    out = []
    for start in NEWTON_STARTS:
        y0 = [mp.mpf(v) for v in start]
        q = [S.const(y0[0]), S.const(y0[1])]
        v = [S.const(y0[2]), S.const(y0[3])]
        for kind, c in steps:
            if kind == "D":
                q = [S.add(q[i], S.scale(c, S.shift(v[i]))) for i in range(2)]
            else:
                a = newton_accel(S, P, q)
                v = [S.add(v[i], S.scale(c, S.shift(a[i]))) for i in range(2)]
        out.append((q + v, exact_flow(S, F, y0)))
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

    Parameters
    ----------
    scheme : SplittingScheme
    max_order : int, optional, the highest order checked, 1 to 14 (default 10).

    Returns
    -------
    int: the order p.
    """
    check_type(scheme, "splitting", "scheme")
    max_order = check_int(max_order, "max_order", 1, 14)
    return _splitting_order_cached(scheme.fingerprint(), max_order, (scheme,))


def rk_order_series(tableau: ButcherTableau, max_order: int = 8) -> int:
    """The order of a Runge-Kutta tableau by the same exact series expansion as
    `splitting_order`, on a generic 3-dimensional first-order system: an independent check of
    the rooted-tree count in `rk_order`. The stage equations (implicit or not) are solved on
    series by fixed-point iteration, which fixes one more power of h per sweep.

    Parameters
    ----------
    tableau : ButcherTableau
    max_order : int, optional, as for `splitting_order` but 1 to 12 (default 8).

    Returns
    -------
    int: the order p (`max_order` when every coefficient up to h^(max_order+1) vanishes).
    """
    check_type(tableau, "runge-kutta", "tableau")
    max_order = check_int(max_order, "max_order", 1, 12)

    degree = max_order + 1
    worst = [0.0] * (degree + 1)
    with mpmath.workdps(_SERIES_DPS):
        mp = mpmath.mp
        S = Series(mp, degree)
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
            err, size = _error_profile(S, y1, exact_flow(S, F, y0))
            for n in range(degree + 1):
                worst[n] = max(worst[n], float(err[n] / max(mp.mpf(1), size[n])))
    return _order_from_series(worst, max_order)
