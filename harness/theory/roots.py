"""Real-root isolation over the rationals (Sturm sequences), resultants and the Schur-Cohn test.

A polynomial is a tuple of `Fraction` coefficients in ascending powers (the arithmetic, in
`harness.theory.polynomials`, is re-exported here). Every float coefficient
of a method is a dyadic rational, so polynomials built from a method's coefficients (the trace of
a splitting's propagator, a multistep method's characteristic polynomial) are exact, and so is
every sign decided on them: a root is isolated in an interval with rational ends, never found by
sampling a function that may dip below a threshold between two samples.

- `isolate_real_roots`: the distinct real roots of p in (lo, hi], each in an isolating interval
  refined to a relative width (Sturm's theorem; Basu, Pollack & Roy, *Algorithms in Real
  Algebraic Geometry*, 2.2).
- `count_roots_between`: the number of distinct real roots in (a, b].
- `resultant_in_x`: the resultant in zeta of two polynomials whose coefficients are polynomials
  in x, as a polynomial in x (evaluation at rational points and exact interpolation).
- `schur_all_inside`: whether every root of a real polynomial lies strictly inside the unit disc
  (the Schur-Cohn test, exact on rationals; Henrici, *Applied and Computational Complex
  Analysis* I, 6.8).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction

import numpy as np

from harness.theory.polynomials import (
    Poly,
    det_exact,
    padd,
    pderiv,
    pdivmod,
    peval,
    pgcd,
    pmul,
    poly,
    pscale,
    psub,
)

__all__ = ["Poly", "poly", "padd", "psub", "pmul", "pscale", "peval", "pderiv", "pdivmod", "pgcd",
           "squarefree", "sturm_sequence", "count_roots_between", "isolate_real_roots",
           "root_bound", "resultant_in_x", "schur_all_inside", "det_exact"]

def squarefree(a: Poly) -> Poly:
    """a divided by gcd(a, a'): the same roots, each simple.

    Parameters
    ----------
    a : Poly, a non-zero polynomial.

    Returns
    -------
    Poly: a / gcd(a, a') (`a` itself when the gcd is constant).
    """
    g = _chain(_integer(a))[-1]
    if len(g) == 1:
        return a
    return pdivmod(a, poly(g))[0]


def _primitive(a) -> tuple[int, ...]:
    a = list(a)
    while a and a[-1] == 0:
        a.pop()
    g = 0
    for c in a:
        g = math.gcd(g, c)
    return tuple(c // g for c in a) if g > 1 else tuple(a)


def _pseudo_remainder(a: tuple[int, ...], b: tuple[int, ...]) -> tuple[int, ...]:
    """The remainder of |lc(b)|^(deg a - deg b + 1) a divided by b (a positive multiple of the
    remainder of a / b), in integers."""
    r = list(a)
    lead, db = b[-1], len(b) - 1
    steps = max(len(a) - len(b) + 1, 0)
    for _ in range(steps):
        if len(r) - 1 < db:
            r = [lead * x for x in r]
            continue
        c = r[-1]
        shift = len(r) - 1 - db
        r = [lead * x for x in r]
        for j, y in enumerate(b):
            r[shift + j] -= c * y
        r.pop()
    while r and r[-1] == 0:
        r.pop()
    if lead < 0 and steps % 2 == 1:
        r = [-x for x in r]
    return tuple(r)


def _chain(a: tuple[int, ...]) -> list[tuple[int, ...]]:
    """The Sturm chain p0 = a, p1 = a', p_(i+1) = -rem(p_(i-1), p_i) of an integer polynomial,
    each element a positive multiple of the textbook one with coprime integer coefficients
    (pseudo-division by a positive power |lc|^(d+1) keeps every sign; dividing out the content
    keeps the integers small: Collins' primitive remainder sequence). The last element is
    gcd(a, a')."""
    seq = [a, _primitive(i * a[i] for i in range(1, len(a)))]
    while len(seq[-1]) > 1:
        r = _pseudo_remainder(seq[-2], seq[-1])
        if not r:
            break
        seq.append(_primitive(-c for c in r))
    return [p for p in seq if p]


def sturm_sequence(a: Poly) -> list[tuple[int, ...]]:
    """The Sturm chain of `a` (see `_chain`), as integer polynomials.

    Parameters
    ----------
    a : Poly, a non-zero polynomial (square-free for Sturm's count of distinct roots).

    Returns
    -------
    list of tuple of int
        p_0 = a, p_1 = a', p_{k+1} = -rem(p_{k-1}, p_k), each scaled to integer coefficients.
    """
    return _chain(_integer(a))


def _integer(a: Poly) -> tuple[int, ...]:
    """A positive multiple of `a` with coprime integer coefficients (the same signs everywhere)."""
    lcm = 1
    for c in a:
        lcm = lcm * c.denominator // math.gcd(lcm, c.denominator)
    ints = [int(c * lcm) for c in a]
    g = 0
    for c in ints:
        g = math.gcd(g, c)
    return tuple(c // g for c in ints) if g > 1 else tuple(ints)


def _sign(a: tuple[int, ...], x: Fraction) -> int:
    """The sign of the integer polynomial `a` at the rational x (exact, in integers: the value
    times den^n by a homogeneous Horner scheme)."""
    num, den = x.numerator, x.denominator
    acc, scale = 0, 1
    for c in reversed(a):
        acc = acc * num + c * scale
        scale *= den
    return (acc > 0) - (acc < 0)


def _sign_changes(seq: list, x: Fraction | None) -> int:
    """Sign changes of the (integer) sequence at x (None: at +infinity)."""
    signs = []
    for p in seq:
        v = ((p[-1] > 0) - (p[-1] < 0)) if x is None else _sign(p, x)
        if v:
            signs.append(v > 0)
    return sum(1 for s, t in zip(signs, signs[1:], strict=False) if s != t)


def count_roots_between(a: Poly, lo: Fraction, hi: Fraction | None,
                        seq: list[Poly] | None = None) -> int:
    """The number of distinct real roots of `a` in (lo, hi] (hi None: (lo, infinity)).

    Parameters
    ----------
    a : Poly, a non-zero polynomial.
    lo : Fraction, left end (excluded).
    hi : Fraction or None, right end (included); None for infinity.
    seq : list of Poly, optional, the Sturm sequence of a's square-free part, when already computed.

    Returns
    -------
    int: the count, by Sturm's theorem (sign changes at lo minus sign changes at hi).
    """
    seq = seq if seq is not None else sturm_sequence(squarefree(a))
    return _sign_changes(seq, lo) - _sign_changes(seq, hi)


def root_bound(a: Poly) -> Fraction:
    """Cauchy's bound: every root has modulus below 1 + max |a_i / a_n|.

    Parameters
    ----------
    a : Poly, a polynomial of degree >= 1.

    Returns
    -------
    Fraction: 1 + max_i |a_i / a_n|.
    """
    return 1 + max((abs(c / a[-1]) for c in a[:-1]), default=Fraction(0))


def _root_estimates(q: Poly, lo: Fraction, hi: Fraction) -> list[float]:
    """Sorted floating-point estimates of the real roots of q in (lo, hi] (eigenvalues of the
    companion matrix; only used to choose where to cut)."""
    coeffs = np.array([float(c) for c in q])
    if not np.all(np.isfinite(coeffs)) or coeffs[-1] == 0:
        return []
    with np.errstate(all="ignore"):
        roots = np.polynomial.polynomial.polyroots(coeffs)
    real = roots.real[np.abs(roots.imag) <= 1e-6 * np.maximum(1.0, np.abs(roots))]
    return sorted(float(r) for r in real if float(lo) < r <= float(hi))


def isolate_real_roots(a: Poly, lo: Fraction, hi: Fraction | None = None, *,
                       rel_width: Fraction = Fraction(1, 2**60)) -> list[tuple[Fraction, Fraction]]:
    """The distinct real roots of the non-zero polynomial `a` in (lo, hi] (hi None: up to
    Cauchy's bound), in increasing order, each as an interval (left, right] holding exactly one
    root, refined by bisection on the sign of the square-free part until right - left <=
    rel_width * |right| (an exact root found on the way is returned as (root, root)).

    Parameters
    ----------
    a : Poly
    lo : Fraction, left end of the search (excluded).
    hi : Fraction or None, optional, right end (included); None for Cauchy's bound (`root_bound`).
    rel_width : Fraction, optional, the relative width each interval is refined to (default 2^-60).

    Returns
    -------
    list of (Fraction, Fraction)
        One isolating interval (left, right] per root, in increasing order; empty for a
        constant `a`.
    """
    if len(a) <= 1:
        return []
    q = squarefree(a)
    seq = sturm_sequence(q)
    lo = Fraction(lo)
    hi = root_bound(q) if hi is None else Fraction(hi)
    # Cut (lo, hi] between floating-point estimates of the roots: only where to cut comes from
    # the estimates; the count in every piece is Sturm's, and a piece holding more than one
    # root is bisected.
    hints = _root_estimates(q, lo, hi)
    cuts = [lo] + [Fraction((u + v) / 2) for u, v in zip(hints, hints[1:], strict=False)] + [hi]
    cuts = sorted(set(c for c in cuts if lo <= c <= hi))
    pending = list(zip(cuts, cuts[1:], strict=False))
    isolated = []
    while pending:
        left, right = pending.pop()
        n = count_roots_between(q, left, right, seq)
        if n == 0:
            continue
        if n == 1:
            isolated.append((left, right))
            continue
        m = (left + right) / 2
        pending += [(left, m), (m, right)]
    out = []
    qi = _integer(q)
    for left, right in sorted(isolated):
        if _sign(qi, right) == 0:
            out.append((right, right))
            continue
        for h in hints:  # a bracket of relative width 1e-12 around the estimate, if it holds
            a_, b_ = Fraction(h * (1 - 1e-12)), Fraction(h * (1 + 1e-12))
            if left < a_ < b_ < right and _sign(qi, a_) * _sign(qi, b_) < 0:
                left, right = a_, b_
                break
        sl = _sign(qi, left)
        while sl == 0:  # a root of q at the open end left: move left inside by counting
            m = (left + right) / 2
            if count_roots_between(q, m, right, seq) == 1:
                left, sl = m, _sign(qi, m)
            else:
                right = m
        while sl and right - left > rel_width * max(abs(right), abs(left)):
            m = (left + right) / 2
            sm = _sign(qi, m)
            if sm == 0:
                left = right = m
            elif sm == sl:
                left, sl = m, sm
            else:
                right = m
        out.append((left, right))
    return out


def _sylvester(p: tuple, q: tuple) -> Fraction:
    """The Sylvester determinant of p and q (ascending coefficient tuples of nominal degrees
    len - 1 >= 1, leading coefficients possibly zero): their resultant."""
    m, n = len(p) - 1, len(q) - 1
    size = m + n
    rows = []
    for i in range(n):
        rows.append([Fraction(0)] * i + list(reversed(p)) + [Fraction(0)] * (size - m - 1 - i))
    for i in range(m):
        rows.append([Fraction(0)] * i + list(reversed(q)) + [Fraction(0)] * (size - n - 1 - i))
    return det_exact(rows)


def _interpolate(xs: list[Fraction], ys: list[Fraction]) -> Poly:
    """The polynomial of degree < len(xs) through (xs, ys) (Lagrange, exact)."""
    out: Poly = ()
    for i, (xi, yi) in enumerate(zip(xs, ys, strict=False)):
        if not yi:
            continue
        basis: Poly = (Fraction(1),)
        denom = Fraction(1)
        for j, xj in enumerate(xs):
            if j != i:
                basis = pmul(basis, (-xj, Fraction(1)))
                denom *= xi - xj
        out = padd(out, pscale(basis, yi / denom))
    return out


def resultant_in_x(p_of: Callable[[Fraction], Poly], q_of: Callable[[Fraction], Poly],
                   degree_bound: int, zeta_degrees: tuple[int, int]) -> Poly:
    """Res_zeta(p(., x), q(., x)) as a polynomial in x, where `p_of(x)` and `q_of(x)` give the
    polynomials in zeta at a rational x, of nominal degrees `zeta_degrees` (the Sylvester matrix
    keeps these sizes, leading coefficients may vanish at some x) and the resultant has degree
    at most `degree_bound` in x. Found at degree_bound + 1 integer points and interpolated.

    Parameters
    ----------
    p_of, q_of : callable, ``p_of(x)`` -> Poly in zeta at a rational x (and likewise `q_of`).
    degree_bound : int, an upper bound on the resultant's degree in x.
    zeta_degrees : (int, int), the nominal degrees (m, n) of p and q in zeta.

    Returns
    -------
    Poly: the resultant as a polynomial in x.
    """
    m, n = zeta_degrees
    xs = [Fraction(i) for i in range(degree_bound + 1)]
    ys = []
    for x in xs:
        p = list(p_of(x)) + [Fraction(0)] * (m + 1)
        q = list(q_of(x)) + [Fraction(0)] * (n + 1)
        ys.append(_sylvester(tuple(p[: m + 1]), tuple(q[: n + 1])))
    return _interpolate(xs, ys)


def schur_all_inside(a: Poly) -> bool:
    """True when every root of the real polynomial `a` (degree >= 1) lies strictly inside the
    unit disc: the Schur-Cohn recursion a -> (a_n a(z) - a_0 a*(z)) / z with a* the reversed
    polynomial, which needs |a_0| < |a_n| at every stage.

    Parameters
    ----------
    a : Poly or sequence, the polynomial, ascending powers.

    Returns
    -------
    bool: whether every root satisfies |z| < 1.
    """
    a = poly(a)
    while len(a) > 1:
        lead, const = a[-1], a[0]
        if abs(const) >= abs(lead):
            return False
        rev = tuple(reversed(a))
        nxt = psub(pscale(a, lead), pscale(rev, const))
        a = poly(nxt[1:])
    return True
