"""Runge-Kutta orders on problem classes where elementary differentials vanish, stage order, and
the defects of the order conditions (the leading local error term, tree by tree).

A Runge-Kutta step's local error is the B-series
    y_1 - y(t_0 + h) = sum_t h^|t| / sigma(t) (Phi(t) - 1/gamma(t)) F(t)(y_0)
(Hairer, Norsett & Wanner, *Solving ODEs I*, II.2, Theorems 2.11 and 2.13), with F(t) the
elementary differential of the tree t: F(leaf) = f, F([t_1 ... t_m]) = f^(m)(F(t_1), ...,
F(t_m)). On a class of problems where F(t) vanishes identically for some trees, only the
conditions of the other trees count (`rk_class_order`):

- right-hand side a polynomial of degree d in the state: f^(m) = 0 for m > d, so every tree with
  a vertex of more than d children vanishes. d = 1 leaves the tall trees, bᵀ A^(k-1) e = 1/k!:
  the linear order (`rk_linear_order`); d = 2 (a quadratic field) first drops [***] at order 4.
- Nystrom class, x'' = g(x) written as (x, v)' = (v, g(x)) (Hairer, Norsett & Wanner I, II.14;
  Hairer, Lubich & Wanner, *Geometric Numerical Integration*, III.2): the position component of
  f is linear in v and reads nothing else, the velocity component reads only x. A tree's
  elementary differential is a sum over two-colourings of its vertices, colours alternating
  along every edge; a position-coloured vertex carries at most one child. So a tree survives
  when the vertices of one depth parity have at most one child each (and, for a polynomial
  acceleration of degree d, those of the other parity at most d). The first tree that vanishes
  is [[**]*] at order 5: an order-4 method that satisfies the other eight order-5 conditions
  is of order 5 on this class. Time-dependent problems join the class through the time
  coordinate (t' = 1, a position whose velocity is constant), as every tableau here has c = A e.

Stiff problems (Hairer & Wanner, *Solving ODEs II*, IV.15): the stage order q is the largest q
with C(q): sum_j a_ij c_j^(k-1) = c_i^k / k for k <= q (`rk_stage_order`); a method is stiffly
accurate when the last row of A equals b (`rk_stiffly_accurate`). On the Prothero-Robinson
equation with h|lambda| -> infinity the global error of such methods is O(h^(q+1)) (O(h^q)
without stiff accuracy), and B-convergence holds with order q (Theorem 15.3 there).
"""

from __future__ import annotations

import math
from fractions import Fraction
from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from harness import tolerances as tol
from harness.theory.checks import check_int, check_type
from harness.theory.orders import MAX_TREE_ORDER, condition_tolerance, elementary_weights, rooted_trees

if TYPE_CHECKING:  # annotations only: the theory reads coefficient objects by their `family`
    from harness.coefficients import ButcherTableau
    from harness.theory.orders import RootedTree

__all__ = ["tree_symmetry", "tree_survives", "rk_class_order", "rk_class_orders", "rk_error_defects",
           "rk_stage_order", "rk_stiffly_accurate"]


@cache
def _children_counts(max_order: int) -> tuple[tuple[int, ...], ...]:
    """For each tree, the number of children of every vertex, listed by depth parity:
    ((max children at even depths, max children at odd depths), ...) per tree."""
    trees = rooted_trees(max_order)
    out: list[tuple[int, int]] = []
    for t in trees:
        even = len(t.children)
        odd = 0
        for k in t.children:  # a child's even depths are this tree's odd ones, and vice versa
            even_k, odd_k = out[k]
            odd = max(odd, even_k)
            even = max(even, odd_k)
        out.append((even, odd))
    return tuple(out)


def tree_symmetry(tree: RootedTree, max_order: int | None = None) -> int:
    """sigma(t): the order of the tree's automorphism group, sigma([t_1^m_1 ... t_k^m_k]) =
    prod m_i! sigma(t_i)^m_i (Hairer, Norsett & Wanner I, II.2, Definition 2.10).

    Parameters
    ----------
    tree : RootedTree, a tree of `rooted_trees`.
    max_order : int, optional
        The `rooted_trees` table the tree's children index into (default: the tree's order).

    Returns
    -------
    int: sigma(tree).
    """
    trees = rooted_trees(max_order or max(tree.order, 1))
    out = 1
    for k in set(tree.children):
        m = tree.children.count(k)
        out *= math.factorial(m) * tree_symmetry(trees[k], max_order) ** m
    return out


def tree_survives(tree: RootedTree, *, nystrom: bool = False, degree: int | None = None) -> bool:
    """True when the elementary differential F(tree) can be non-zero on the class: `nystrom`
    (x'' = g(x) as a first-order system) and/or a right-hand side polynomial of `degree` in the
    state (None: any smooth field). See the module docstring.

    Parameters
    ----------
    tree : RootedTree, a tree of `rooted_trees`.
    nystrom : bool, optional, the problem is x'' = g(x) written as a first-order system.
    degree : int or None, optional, the right-hand side is a polynomial of this degree in the state.

    Returns
    -------
    bool: whether the tree's order condition counts on that class.
    """
    even, odd = _children_counts(tree.order)[tree.index] if tree.order <= MAX_TREE_ORDER else (0, 0)
    d = math.inf if degree is None else degree
    if nystrom:  # positions at one depth parity (at most one child), velocities at the other
        return (even <= 1 and odd <= d) or (odd <= 1 and even <= d)
    return max(even, odd) <= d


def rk_class_order(tableau: ButcherTableau, *, nystrom: bool = False, degree: int | None = None,
                   max_order: int | None = None) -> int:
    """The order of `tableau` on a problem class: the largest p such that every order condition
    of a tree with at most p vertices whose elementary differential survives on the class
    (`tree_survives`) holds to rounding.

    Parameters
    ----------
    tableau : ButcherTableau
    nystrom : bool, the class x'' = g(x) (acceleration free of velocities) written as a first-order system.
    degree : int or None
        The right-hand side is a polynomial of this degree in the state (None: not known to be).
    max_order : int, optional
        Highest order checked (default: the stage count for an explicit method, where the tall
        tree b^T A^(s) e = 0 already fails, else 2s; capped at MAX_TREE_ORDER).

    Returns
    -------
    int
        The class order; at least `rk_order(tableau)`. A result equal to `max_order` means "at
        least that".
    """
    check_type(tableau, "runge-kutta", "tableau")
    if degree is not None:
        degree = check_int(degree, "degree", 1, 1000)
    if max_order is None:
        max_order = min(MAX_TREE_ORDER, tableau.stages if tableau.explicit else 2 * tableau.stages)
    max_order = check_int(max_order, "max_order", 1, MAX_TREE_ORDER)
    return rk_class_orders(tableau, [(nystrom, degree)], max_order)[0]


def rk_class_orders(tableau: ButcherTableau, classes: list[tuple[bool, int | None]],
                    max_order: int | None = None) -> list[int]:
    """`rk_class_order` for several (nystrom, degree) classes at once: the elementary weights
    are computed once and each violated condition is checked against every class.

    Parameters
    ----------
    tableau : ButcherTableau
    classes : list of (bool, int or None), (nystrom, degree) pairs, as in `tree_survives`.
    max_order : int, optional
        The highest order checked (default: s for explicit s-stage methods, 2s otherwise,
        capped at MAX_TREE_ORDER).

    Returns
    -------
    list of int: the order on each class, in the order of `classes`.
    """
    check_type(tableau, "runge-kutta", "tableau")
    if max_order is None:
        max_order = min(MAX_TREE_ORDER, tableau.stages if tableau.explicit else 2 * tableau.stages)
    max_order = check_int(max_order, "max_order", 1, MAX_TREE_ORDER)
    phi, size = elementary_weights(tableau, max_order)
    violated = [t for t in rooted_trees(max_order)
                if abs(phi[t.index] - 1.0 / t.gamma) > condition_tolerance(t, size[t.index],
                                                                           tableau.published_precision)]
    out = []
    for nystrom, degree in classes:
        failed = [t.order for t in violated if tree_survives(t, nystrom=nystrom, degree=degree)]
        out.append(min(failed) - 1 if failed else max_order)
    return out


def rk_error_defects(tableau: ButcherTableau, order: int) -> tuple[list[RootedTree], np.ndarray]:
    """The trees with `order` vertices and their local error coefficients
    (Phi(t) - 1/gamma(t)) / sigma(t): the h^order term of the local error is the sum of these
    times F(t)(y) (module docstring). Exact (Fraction) coefficients are used when the tableau
    was given exactly, so a defect far below float64 rounding is still its true value.

    Parameters
    ----------
    tableau : ButcherTableau
    order : int, the number of vertices, 1 to MAX_TREE_ORDER.

    Returns
    -------
    (trees, defects) : the trees of that order and a float array of their coefficients.
    """
    check_type(tableau, "runge-kutta", "tableau")
    order = check_int(order, "order", 1, MAX_TREE_ORDER)
    trees = [t for t in rooted_trees(order) if t.order == order]
    if tableau.exact is not None:
        phi = _exact_weights(tableau.exact, order)

        defects = [(phi[t.index] - Fraction(1, t.gamma)) / tree_symmetry(t) for t in trees]
        return trees, np.array([float(x) for x in defects])
    phi, _ = elementary_weights(tableau, order)
    return trees, np.array([(phi[t.index] - 1.0 / t.gamma) / tree_symmetry(t) for t in trees])


def _exact_weights(exact: tuple, max_order: int) -> list:
    A, b, _ = exact
    s = len(b)
    g: list[list] = []
    for t in rooted_trees(max_order):
        v = [Fraction(1)] * s
        for k in t.children:
            Ag = [sum((A[i][j] * g[k][j] for j in range(s)), Fraction(0)) for i in range(s)]
            v = [v[i] * Ag[i] for i in range(s)]
        g.append(v)
    return [sum((b[i] * gk[i] for i in range(s)), Fraction(0)) for gk in g]


def rk_stage_order(tableau: ButcherTableau) -> int:
    """The stage order: the largest q such that B(q) and C(q) hold (Hairer & Wanner II, IV.15):
    sum_i b_i c_i^(k-1) = 1/k and sum_j a_ij c_j^(k-1) = c_i^k / k for every stage i and
    k <= q. Each residual is compared with rounding of the sum of its magnitudes.

    Parameters
    ----------
    tableau : ButcherTableau

    Returns
    -------
    int: the stage order q (at most 2s).
    """
    check_type(tableau, "runge-kutta", "tableau")
    A, b, c = tableau.A, tableau.b, tableau.c
    for k in range(1, 2 * tableau.stages + 1):
        lhs = np.append(A @ c ** (k - 1), b @ c ** (k - 1))
        rhs = np.append(c**k / k, 1.0 / k)
        scale = np.append(np.abs(A) @ np.abs(c) ** (k - 1), np.abs(b) @ np.abs(c) ** (k - 1)) + np.abs(rhs)
        allowed = np.maximum(tol.ORDER_CONDITION_ULPS * tol.EPS * k * scale, tol.ORDER_CONDITION_FLOOR)
        if np.any(np.abs(lhs - rhs) > allowed):
            return k - 1
    return 2 * tableau.stages


def rk_stiffly_accurate(tableau: ButcherTableau) -> bool:
    """The last row of A equals b (so y_1 is the last stage; R(infinity) = 0 when A is
    invertible): Hairer & Wanner II, IV.6 and IV.15.

    Parameters
    ----------
    tableau : ButcherTableau

    Returns
    -------
    bool: whether a_sj = b_j for every j, to rounding.
    """
    check_type(tableau, "runge-kutta", "tableau")
    scale = np.abs(tableau.b) + np.abs(tableau.A[-1])
    allowed = np.maximum(tol.ORDER_CONDITION_ULPS * tol.EPS * scale, tol.ORDER_CONDITION_FLOOR)
    return bool(np.all(np.abs(tableau.A[-1] - tableau.b) <= allowed))
