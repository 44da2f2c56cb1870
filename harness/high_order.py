"""Methods whose order is known by construction at orders 4-12: the families the gate is judged
on at high order (`harness.populations`), as exact coefficient objects.

- `extrapolation_tableau`: Aitken-Neville extrapolation of explicit Euler (steps 1, 2, ..., p,
  extrapolated in h: order p) or of the explicit midpoint rule (Euler first step, no smoothing;
  steps 2, 4, ..., 2k, extrapolated in h^2: order 2k) written as one explicit Runge-Kutta
  tableau with exact rational coefficients (Hairer, Norsett & Wanner I, II.9, Theorem 9.1 and
  the GBS algorithm; W. B. Gragg, SIAM J. Numer. Anal. 2 (1965) 384-403); any increasing step
  sequence gives a member of the family with the same order.
- `symmetric_composition`: the triple jump (Yoshida, Phys. Lett. A 150 (1990) 262) or Suzuki's
  fractal five-fold composition (Phys. Lett. A 146 (1990) 319) of a symmetric method of order
  2m, recursively, with the weights exact where they are rational and otherwise given to 40
  digits (enough for real128), raising the order by two per level (Hairer, Lubich & Wanner,
  *Geometric Numerical Integration*, II.4, eqs. (4.4)-(4.6)).
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction

__all__ = ["extrapolation_tableau", "extrapolation_weights", "composition_weights"]


def extrapolation_weights(steps: Sequence[int], power: int) -> list[Fraction]:
    """gamma_j with sum gamma_j = 1 and sum gamma_j n_j^(-power m) = 0 for m = 1..k-1 (the
    Aitken-Neville value T_kk as a combination of the T_j1), exactly.

    Parameters
    ----------
    steps : the step numbers n_1 < ... < n_k
    power : 1 for an error expansion in h (Euler), 2 for one in h^2 (the midpoint rule)

    Returns
    -------
    The k weights as Fractions."""
    k = len(steps)
    M = [[Fraction(1, n ** (power * m)) for n in steps] + [Fraction(int(m == 0))] for m in range(k)]
    for col in range(k):  # Gauss-Jordan in exact arithmetic
        piv = next(r for r in range(col, k) if M[r][col] != 0)
        M[col], M[piv] = M[piv], M[col]
        M[col] = [x / M[col][col] for x in M[col]]
        for r in range(k):
            if r != col and M[r][col] != 0:
                M[r] = [a - M[r][col] * b for a, b in zip(M[r], M[col], strict=True)]
    return [M[r][k] for r in range(k)]


def extrapolation_tableau(k: int, base: str = "euler", steps: Sequence[int] | None = None
                          ) -> tuple[list[list[Fraction]], list[Fraction]]:
    """(A, b) of the extrapolated method as one explicit Runge-Kutta tableau (first stage shared).

    Parameters
    ----------
    k : number of extrapolation columns: order k (Euler) or 2k (midpoint)
    base : 'euler' or 'midpoint'
    steps : the step-number sequence (default 1..k for Euler, 2, 4, ..., 2k for the midpoint
        rule; midpoint sequences must be even)

    Returns
    -------
    (A, b) as nested lists of Fractions."""
    if base not in ("euler", "midpoint"):
        raise ValueError(f"`base` must be 'euler' or 'midpoint', got {base!r}")
    if steps is None:
        steps = list(range(1, k + 1)) if base == "euler" else [2 * j for j in range(1, k + 1)]
    steps = [int(n) for n in steps]
    if len(steps) != k or sorted(set(steps)) != steps or (base == "midpoint" and any(n % 2 for n in steps)):
        raise ValueError(f"`steps` must be {k} increasing step numbers (even for the midpoint rule), got {steps}")
    rows: list[dict[int, Fraction]] = [{}]  # stage 0: f(y0), shared
    finals: list[dict[int, Fraction]] = []  # each member's value as sum_j w_j k_j
    for n in steps:
        if base == "euler":
            z: dict[int, Fraction] = {0: Fraction(1, n)}  # y_1 = y0 + (h/n) k_0
            for _ in range(1, n):
                rows.append(dict(z))
                z = {**z, len(rows) - 1: Fraction(1, n)}
        else:
            z_prev: dict[int, Fraction] = {}
            z = {0: Fraction(1, n)}  # Euler first step, then midpoint steps
            for _ in range(1, n):
                rows.append(dict(z))
                s = len(rows) - 1
                z_next = dict(z_prev)
                z_next[s] = z_next.get(s, Fraction(0)) + Fraction(2, n)
                z_prev, z = z, z_next
        finals.append(z)
    s = len(rows)
    A = [[row.get(j, Fraction(0)) for j in range(s)] for row in rows]
    gamma = extrapolation_weights(steps, 1 if base == "euler" else 2)
    b = [sum((g * f.get(j, Fraction(0)) for g, f in zip(gamma, finals, strict=True)), Fraction(0))
         for j in range(s)]
    return A, b
