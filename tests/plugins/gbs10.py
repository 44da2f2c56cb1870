"""A user's order-10 explicit Runge-Kutta method as a plugin record, with exact coefficients.

The Gragg-Bulirsch-Stoer extrapolation of the explicit midpoint rule (Euler first step, no
smoothing) over the step-number sequence 2, 4, 6, 8, 10, extrapolated in h^2 to T_55, is an
explicit Runge-Kutta method of order 10 with 26 stages (one shared first stage and n_j - 1 per
sequence member). Its coefficients are rationals, built here exactly (Fractions) from that
construction, so the record carries an exact form and extended-precision runs can measure its
order beyond the float64 floor.

References: E. Hairer, S. P. Norsett, G. Wanner, Solving Ordinary Differential Equations I,
2nd ed., Springer 1993, II.9 (the GBS algorithm; the extrapolated values are explicit
Runge-Kutta methods, order 2k for T_kk); W. B. Gragg, SIAM J. Numer. Anal. 2 (1965) 384-403
(the h^2 expansion of the midpoint rule with an even number of steps).
"""

from fractions import Fraction

SEQUENCE = (2, 4, 6, 8, 10)


def _extrapolation_weights(ns) -> list[Fraction]:
    """gamma_j with sum gamma_j = 1 and sum gamma_j n_j^(-2m) = 0, m = 1..k-1 (Neville in h^2)."""
    k = len(ns)
    M = [[Fraction(1, n ** (2 * m)) for n in ns] + [Fraction(int(m == 0))] for m in range(k)]
    for col in range(k):  # Gauss-Jordan in exact arithmetic
        piv = next(r for r in range(col, k) if M[r][col] != 0)
        M[col], M[piv] = M[piv], M[col]
        M[col] = [x / M[col][col] for x in M[col]]
        for r in range(k):
            if r != col and M[r][col] != 0:
                M[r] = [a - M[r][col] * b for a, b in zip(M[r], M[col], strict=True)]
    return [M[r][k] for r in range(k)]


def gbs_tableau(ns=SEQUENCE) -> tuple[list[list[Fraction]], list[Fraction]]:
    """(A, b) of the extrapolated GBS method as an explicit Runge-Kutta tableau."""
    rows: list[dict[int, Fraction]] = [{}]  # stage 0: f(y0)
    finals = []
    for n in ns:
        z_prev: dict[int, Fraction] = {}
        z = {0: Fraction(1, n)}
        for _ in range(1, n):
            rows.append(dict(z))
            s = len(rows) - 1
            z_next = dict(z_prev)
            z_next[s] = z_next.get(s, Fraction(0)) + Fraction(2, n)
            z_prev, z = z, z_next
        finals.append(z)
    s = len(rows)
    A = [[row.get(j, Fraction(0)) for j in range(s)] for row in rows]
    gamma = _extrapolation_weights(ns)
    b = [sum((g * f.get(j, Fraction(0)) for g, f in zip(gamma, finals, strict=True)), Fraction(0))
         for j in range(s)]
    return A, b


_A, _b = gbs_tableau()
METHODS = [{
    "name": "gbs10",
    "A": _A,
    "b": _b,
    "claimed_order": 10,
    "reference": "Hairer, Norsett & Wanner, Solving ODEs I, II.9 (GBS extrapolation T_55, sequence "
                 "2, 4, 6, 8, 10); Gragg, SIAM J. Numer. Anal. 2 (1965) 384-403",
    "description": "Gragg-Bulirsch-Stoer extrapolation as a 26-stage explicit Runge-Kutta method, order 10",
}]
