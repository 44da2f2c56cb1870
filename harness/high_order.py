"""Methods whose order is known by construction at orders 4-12: the families the gate is judged
on at high order (`harness.populations`), as exact coefficient objects.

- `extrapolation_tableau`: Aitken-Neville extrapolation of explicit Euler (steps 1, 2, ..., p,
  extrapolated in h: order p) or of the explicit midpoint rule (Euler first step, no smoothing;
  steps 2, 4, ..., 2k, extrapolated in h^2: order 2k) written as one explicit Runge-Kutta
  tableau with exact rational coefficients (Hairer, Norsett & Wanner I, II.9, Theorem 9.1 and
  the GBS algorithm; W. B. Gragg, SIAM J. Numer. Anal. 2 (1965) 384-403); any increasing step
  sequence gives a member of the family with the same order.
- `composition`: the triple jump (Yoshida, Phys. Lett. A 150 (1990) 262) or Suzuki's
  fractal five-fold composition (Phys. Lett. A 146 (1990) 319) of a symmetric method of order
  2m, recursively, with the weights exact where they are rational and otherwise given to 40
  digits (enough for real128), raising the order by two per level (Hairer, Lubich & Wanner,
  *Geometric Numerical Integration*, II.4, eqs. (4.4)-(4.6)).
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction

import mpmath
import numpy as np

from harness.coefficients import ButcherTableau, SplittingScheme
from harness.theory import rooted_trees

__all__ = ["extrapolation_tableau", "extrapolation_weights", "composition", "null_space_weights",
           "HIGH_ORDER_PROBLEMS", "draw_high_order", "perturb_high_order", "subtle_high_order"]

# Problems each high-order family is measured on: a nonlinear one first (every order condition
# shows; mutants run there), then the harmonic oscillator (the linear order).
HIGH_ORDER_PROBLEMS = {
    "extrap-euler": ("pendulum", "harmonic"),
    "extrap-midpoint": ("pendulum", "harmonic"),
    "compose": ("pendulum",),
}
_DIGITS = 45  # composition weights: far beyond real128's 34 digits


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


def extrapolation_tableau(k: int, base: str = "forward-euler", steps: Sequence[int] | None = None
                          ) -> tuple[list[list[Fraction]], list[Fraction]]:
    """(A, b) of the extrapolated method as one explicit Runge-Kutta tableau (first stage shared).

    Parameters
    ----------
    k : number of extrapolation columns: order k (Euler) or 2k (midpoint)
    base : 'forward-euler' (steps of explicit Euler) or 'gragg-midpoint' (an Euler step, then, midpoint steps)
    steps : the step-number sequence (default 1..k for Euler, 2, 4, ..., 2k for the midpoint
        rule; midpoint sequences must be even)

    Returns
    -------
    (A, b) as nested lists of Fractions."""
    if base not in ("forward-euler", "gragg-midpoint"):
        raise ValueError(f"`base` must be 'forward-euler' or 'gragg-midpoint', got {base!r}")
    if steps is None:
        steps = list(range(1, k + 1)) if base == "forward-euler" else [2 * j for j in range(1, k + 1)]
    steps = [int(n) for n in steps]
    odd = base == "gragg-midpoint" and any(n % 2 for n in steps)
    if len(steps) != k or sorted(set(steps)) != steps or odd:
        raise ValueError(f"`steps` must be {k} increasing step numbers (even for the midpoint rule), "
                         f"got {steps}")
    rows: list[dict[int, Fraction]] = [{}]  # stage 0: f(y0), shared
    finals: list[dict[int, Fraction]] = []  # each member's value as sum_j w_j k_j
    for n in steps:
        if base == "forward-euler":
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
    gamma = extrapolation_weights(steps, 1 if base == "forward-euler" else 2)
    b = [sum((g * f.get(j, Fraction(0)) for g, f in zip(gamma, finals, strict=True)), Fraction(0))
         for j in range(s)]
    return A, b


# -- symmetric compositions of velocity Verlet -------------------------------------------------------
def _level_weights(kind: str, order: int) -> list[str]:
    """Weights raising a symmetric method of even `order` by two: the triple jump
    (g, 1 - 2g, g), g = 1 / (2 - 2^(1/(order+1))), or Suzuki's five-fold
    (p, p, 1 - 4p, p, p), p = 1 / (4 - 4^(1/(order+1))), to _DIGITS digits."""
    with mpmath.workdps(_DIGITS + 10):
        k = mpmath.mpf(1) / (order + 1)
        if kind == "triple":
            g = 1 / (2 - mpmath.mpf(2) ** k)
            w = [g, 1 - 2 * g, g]
        else:
            g = 1 / (4 - mpmath.mpf(4) ** k)
            w = [g, g, 1 - 4 * g, g, g]
        return [mpmath.nstr(x, _DIGITS, strip_zeros=False, min_fixed=-1, max_fixed=1) for x in w]


def composition(levels: Sequence[str], name: str, top_factor: Fraction = Fraction(0)):
    """The symmetric composition of velocity Verlet raised one level per entry of `levels`
    ('triple' or 'suzuki'): order 2 + 2 len(levels). `top_factor` d moves the outer weights of
    the last level to w (1 + d) and the middle one so they still sum to one: symmetric and
    consistent, of the order below (a subtle mutant).

    Parameters
    ----------
    levels : sequence of 'triple' or 'suzuki', one per level; name : str, the scheme's name;
    top_factor : Fraction, d (0: the correct composition).

    Returns
    -------
    SplittingScheme: the composed scheme, coefficients exact.
    """
    half = Fraction(1, 2)  # velocity Verlet, kick-drift-kick: the symmetric base of order 2
    scheme, order = SplittingScheme(f"{name}-base", [("K", half), ("D", 1), ("K", half)]), 2
    for i, kind in enumerate(levels):
        weights = [Fraction(w) for w in _level_weights(kind, order)]
        if i == len(levels) - 1 and top_factor:
            mid = len(weights) // 2
            weights = [w * (1 + top_factor) if j != mid else w for j, w in enumerate(weights)]
            weights[mid] = 1 - sum(w for j, w in enumerate(weights) if j != mid)
        scheme = SplittingScheme.compose(name, scheme, weights)
        order += 2
    return scheme


# -- Runge-Kutta weights in the null space of the lower-order conditions -------------------------
def null_space_weights(A, b, order: int, size: float = 0.05) -> list[float] | None:
    """b + d, d of max-norm `size` orthogonal to g(t) for every tree of order < `order` (the
    conditions are linear in b; d is the last right singular vector of their matrix, in float64),
    so every condition below `order` still holds to rounding and the order-`order` ones break;
    None where the conditions leave no such direction.

    Parameters
    ----------
    A, b : the tableau's matrix and weights; order : int, the first order whose conditions break;
    size : float, the max-norm of the move.

    Returns
    -------
    list of float or None: the moved weights.
    """
    A_arr, b_arr = np.array(A, dtype=float), np.array(b, dtype=float)
    g: list[np.ndarray] = []
    for t in rooted_trees(order - 1):
        v = np.ones(b_arr.size)
        for k in t.children:
            v = v * (A_arr @ g[k])
        g.append(v)
    _, sv, vt = np.linalg.svd(np.array(g))
    rank = int(np.sum(sv > 1e-10 * sv[0]))
    if rank >= b_arr.size:
        return None
    d = vt[-1]
    return (b_arr + size * d / np.max(np.abs(d))).tolist()


# -- the families: draws and mutants ---------------------------------------------------------------
def draw_high_order(family: str, rng, max_order: int = 12):
    """One correct member: (coefficients description, claimed order), or None for a draw above
    `max_order`. Extrapolation: a random increasing step sequence; compositions: a random
    choice of triple jump or Suzuki's five-fold at each level (at most 125 Verlet steps).

    Parameters
    ----------
    family : str, a key of HIGH_ORDER_PROBLEMS (ValueError otherwise); rng : numpy Generator;
    max_order : int, the highest order drawn.

    Returns
    -------
    tuple or None: (spec, order); spec is ('rk', A, b) or ('compose', levels).
    """
    if family == "extrap-euler":
        p = int(rng.integers(5, min(12, max_order) + 1))
        steps = sorted(int(x) for x in rng.choice(np.arange(1, p + 3), size=p, replace=False))
        return ("rk", *extrapolation_tableau(p, "forward-euler", steps)), p
    if family == "extrap-midpoint":
        k = int(rng.integers(3, min(12, max_order) // 2 + 1))
        steps = sorted(int(x) for x in rng.choice(np.arange(2, 2 * k + 6, 2), size=k, replace=False))
        return ("rk", *extrapolation_tableau(k, "gragg-midpoint", steps)), 2 * k
    if family == "compose":
        levels: list[str] = []
        for _ in range(int(rng.integers(1, min(10, max_order) // 2))):
            suzuki_fits = 5 * np.prod([5 if x == "suzuki" else 3 for x in levels]) <= 125
            levels.append("suzuki" if suzuki_fits and rng.uniform() < 0.5 else "triple")
        return ("compose", levels), 2 + 2 * len(levels)
    raise ValueError(f"`family` must be one of {tuple(HIGH_ORDER_PROBLEMS)}, got {family!r}")


def build_high_order(spec, name: str):
    """The coefficient object of a drawn member.

    Parameters
    ----------
    spec : a spec of `draw_high_order`, `perturb_high_order` or `subtle_high_order`; name : str,
    the method's name.

    Returns
    -------
    ButcherTableau or SplittingScheme.
    """
    if spec[0] == "rk":
        return ButcherTableau(name, spec[1], spec[2])
    scheme = composition(spec[1], name, spec[2] if len(spec) > 2 else Fraction(0))
    if spec[0] == "compose-asymmetric":
        seq = [list(x) for x in scheme.exact]
        drifts = [k for k, (kind, _) in enumerate(seq) if kind == "D"]
        seq[drifts[0]][1] += Fraction(1, 20)  # drifts still sum to one; the symmetry breaks
        seq[drifts[-1]][1] -= Fraction(1, 20)
        scheme = SplittingScheme(name, [tuple(x) for x in seq])
    return scheme


def perturb_high_order(spec, rng):
    """One coefficient moved by 1/20: an entry of A (the node follows the row sum), or the
    first drift of the top-level composition against the last (no longer symmetric).

    Parameters
    ----------
    spec : a correct member's spec; rng : numpy Generator, which entry and which sign.

    Returns
    -------
    tuple: the mutant's spec.
    """
    if spec[0] == "rk":
        A = [list(row) for row in spec[1]]
        i = int(rng.integers(1, len(A)))
        j = int(rng.integers(0, i))
        A[i][j] += Fraction(1, 20) * (1 if rng.uniform() < 0.5 else -1)
        return ("rk", A, spec[2])
    return ("compose-asymmetric", spec[1])


def subtle_high_order(spec, claimed: int):
    """A mutant keeping every condition below the claimed order: Runge-Kutta weights moved in
    the null space of the lower-order conditions, or the top composition level's outer weights
    moved symmetrically (order two below); None where there is no such freedom.

    Parameters
    ----------
    spec : a correct member's spec; claimed : int, its order.

    Returns
    -------
    tuple or None: the mutant's spec.
    """
    if spec[0] == "rk":
        b = null_space_weights(spec[1], spec[2], claimed)
        return None if b is None else ("rk", spec[1], b)
    return ("compose", spec[1], Fraction(1, 20))
