"""Exact polynomial arithmetic over the rationals (re-exported by `harness.theory.roots`).

A polynomial is a tuple of `Fraction` coefficients in ascending powers, trailing zeros removed
(the zero polynomial is ``()``); every operation is exact. The arguments a and b of the
functions below are such polynomials (type `Poly`).
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction

__all__ = ["Poly", "poly", "padd", "psub", "pmul", "pscale", "peval", "pderiv", "pdivmod", "pgcd",
           "det_exact"]

Poly = tuple[Fraction, ...]


def poly(coefficients: Sequence) -> Poly:
    """An exact polynomial from ascending coefficients (ints, Fractions or floats, taken exactly),
    trailing zeros removed.

    Parameters
    ----------
    coefficients : sequence of int, Fraction or float, a_0, a_1, ... in ascending powers.

    Returns
    -------
    Poly: the coefficients as Fractions.
    """
    out = [Fraction(c) for c in coefficients]
    while out and out[-1] == 0:
        out.pop()
    return tuple(out)


def padd(a: Poly, b: Poly) -> Poly:
    """a + b, exactly.

    Parameters
    ----------
    a, b : Poly, the two terms.

    Returns
    -------
    Poly: their sum, trailing zeros removed.
    """
    n = max(len(a), len(b))
    return poly([(a[i] if i < len(a) else 0) + (b[i] if i < len(b) else 0) for i in range(n)])


def pscale(a: Poly, c) -> Poly:
    """c a, exactly.

    Parameters
    ----------
    a : Poly
    c : int, Fraction or float, the factor (a float is taken exactly).

    Returns
    -------
    Poly: the scaled polynomial.
    """
    return poly([c * x for x in a])


def psub(a: Poly, b: Poly) -> Poly:
    """a - b, exactly.

    Parameters
    ----------
    a, b : Poly, minuend and subtrahend (b is scaled by -1 and added).

    Returns
    -------
    Poly: their difference.
    """
    return padd(a, pscale(b, -1))


def pmul(a: Poly, b: Poly) -> Poly:
    """a b, exactly.

    Parameters
    ----------
    a, b : Poly, the factors (schoolbook product, every coefficient pair).

    Returns
    -------
    Poly: their product (the zero polynomial ``()`` if either is zero).
    """
    if not a or not b:
        return ()
    out = [Fraction(0)] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        if x:
            for j, y in enumerate(b):
                out[i + j] += x * y
    return poly(out)


def peval(a: Poly, x: Fraction) -> Fraction:
    """a(x), exactly (Horner).

    Parameters
    ----------
    a : Poly, the polynomial; x : Fraction, the point.

    Returns
    -------
    Fraction: a(x).
    """
    acc = Fraction(0)
    for c in reversed(a):
        acc = acc * x + c
    return acc


def pderiv(a: Poly) -> Poly:
    """a', exactly.

    Parameters
    ----------
    a : Poly (differentiated term by term: i a_i x^(i-1)).

    Returns
    -------
    Poly: its derivative.
    """
    return poly([i * a[i] for i in range(1, len(a))])


def pdivmod(a: Poly, b: Poly) -> tuple[Poly, Poly]:
    """Quotient and remainder of a / b (b not zero).

    Parameters
    ----------
    a, b : Poly, dividend and divisor; a zero `b` raises ZeroDivisionError.

    Returns
    -------
    (Poly, Poly): q and r with a = q b + r and deg r < deg b.
    """
    if not b:
        raise ZeroDivisionError("polynomial division by zero")
    r = list(a)
    q = [Fraction(0)] * max(len(a) - len(b) + 1, 0)
    lead = b[-1]
    for shift in range(len(a) - len(b), -1, -1):
        c = r[shift + len(b) - 1] / lead
        q[shift] = c
        if c:
            for j, y in enumerate(b):
                r[shift + j] -= c * y
    return poly(q), poly(r[: len(b) - 1])


def _monic(a: Poly) -> Poly:
    return pscale(a, 1 / a[-1]) if a else a


def pgcd(a: Poly, b: Poly) -> Poly:
    """The monic greatest common divisor (Euclid's algorithm).

    Parameters
    ----------
    a, b : Poly

    Returns
    -------
    Poly: gcd(a, b) with leading coefficient 1.
    """
    while b:
        a, b = b, pdivmod(a, b)[1]
    return _monic(a)


def det_exact(rows: list[list[Fraction]]) -> Fraction:
    """The determinant of a square matrix of Fractions (Gaussian elimination, exact).

    Parameters
    ----------
    rows : list of list of Fraction, the matrix, row by row.

    Returns
    -------
    Fraction: its determinant.
    """
    m = [list(r) for r in rows]
    n = len(m)
    det = Fraction(1)
    for col in range(n):
        pivot = next((i for i in range(col, n) if m[i][col] != 0), None)
        if pivot is None:
            return Fraction(0)
        if pivot != col:
            m[col], m[pivot] = m[pivot], m[col]
            det = -det
        det *= m[col][col]
        for i in range(col + 1, n):
            f = m[i][col] / m[col][col]
            if f:
                for j in range(col, n):
                    m[i][j] -= f * m[col][j]
    return det
