"""The order of a Runge-Kutta or multistep method from its order conditions.

- Runge-Kutta (`rk_order`): Butcher's order conditions, one per rooted tree t with |t| <= p:
  the elementary weight Phi(t) = b^T g(t) must equal 1/gamma(t). Hairer, Norsett & Wanner,
  *Solving ODEs I*, II.2 (Theorem 2.13); Butcher, *Numerical Methods for ODEs* (2016), 3.1-3.2.
- Linear multistep (`lmm_order`): the error constants C_q vanish for q <= p. Hairer, Norsett &
  Wanner I, III.2; for x'' = a (`second_order_lmm_order`) III.10.
- `order_from_coefficients`: the order of any coefficient object (splitting schemes through
  `harness.theory.series`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np

from harness import tolerances as tol
from harness.theory.checks import check_int, check_type, family_of
from harness.theory.series import splitting_order

if TYPE_CHECKING:  # annotations only: the theory reads coefficient objects by their `family`
    from harness.coefficients import ButcherTableau, LinearMultistep, SecondOrderMultistep

__all__ = ["MAX_TREE_ORDER", "RootedTree", "OrderCondition", "rooted_trees", "rk_order", "elementary_weights",
           "condition_tolerance",
           "rk_order_conditions", "rk_stability_coefficients", "rk_linear_order",
           "lmm_error_constants", "lmm_order", "second_order_lmm_error_constants",
           "second_order_lmm_order", "order_from_coefficients"]


MAX_TREE_ORDER = 12  # 7813 trees up to order 12 (4766 of order 12)



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

    Parameters
    ----------
    max_order : int, optional, the largest number of vertices, 1 to MAX_TREE_ORDER (default 8).

    Returns
    -------
    tuple of RootedTree: the trees, each tree's `index` its position in the tuple.
    """
    max_order = check_int(max_order, "max_order", 1, MAX_TREE_ORDER)
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


def elementary_weights(tableau: ButcherTableau, max_order: int,
                        weights: np.ndarray | None = None) -> tuple[list[float], list[float]]:
    """Phi(t) = b^T g(t) for every tree up to `max_order`, and the same sum taken over the
    magnitudes |b|, |A| (the size the rounding of Phi(t) scales with).

    Parameters
    ----------
    tableau : ButcherTableau
    max_order : int, the largest tree order.
    weights : ndarray, optional, weights used in place of b (an embedded method).

    Returns
    -------
    (list of float, list of float): phi(t) and its magnitude sum, indexed like `rooted_trees(max_order)`.
    """
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


def condition_tolerance(t: RootedTree, size: float, precision: float = 0.0) -> float:
    """How far Phi(t) may sit from 1/gamma(t) through rounding alone: ORDER_CONDITION_ULPS
    roundings per vertex of the sum of magnitudes, and never less than ORDER_CONDITION_TOL
    relative to the condition's value 1/gamma(t) nor ORDER_CONDITION_FLOOR (tableaux published
    with 13-14 digits); for coefficients printed to `precision` (`published_precision`), each of
    a product's t.order factors may be off by that much (twice, for safety).

    Parameters
    ----------
    t : RootedTree, the tree of the condition.
    size : float, phi(t) taken over |b| and |A| (`elementary_weights`).
    precision : float, optional
        The coefficients' printed precision (0 for exact or full float64 coefficients).

    Returns
    -------
    float: the allowed |Phi(t) - 1/gamma(t)|.
    """
    return max(tol.ORDER_CONDITION_ULPS * tol.EPS * t.order * size,
               tol.ORDER_CONDITION_TOL / t.gamma, tol.ORDER_CONDITION_FLOOR,
               2.0 * precision * t.order * max(1.0, size))


def rk_order_conditions(tableau: ButcherTableau, order: int) -> list[OrderCondition]:
    """The order conditions of exactly `order` (one per rooted tree with `order` vertices),
    with residual Phi(t) - 1/gamma(t); satisfied when |residual| is within rounding
    (`condition_tolerance`).

    Parameters
    ----------
    tableau : ButcherTableau
    order : int, the order whose conditions are listed, 1 to MAX_TREE_ORDER.

    Returns
    -------
    list of OrderCondition: one per tree of that order, in the order of `rooted_trees`.
    """
    check_type(tableau, "runge-kutta", "tableau")
    order = check_int(order, "order", 1, MAX_TREE_ORDER)
    trees = rooted_trees(order)
    phi, size = elementary_weights(tableau, order)
    out = []
    for t in trees:
        if t.order != order:
            continue
        expected = 1.0 / t.gamma
        r = phi[t.index] - expected
        out.append(OrderCondition(t.label, t.order, phi[t.index], expected, r,
                                  abs(r) <= condition_tolerance(t, size[t.index],
                                                                tableau.published_precision)))
    return out


def rk_order(tableau: ButcherTableau, max_order: int | None = None,
             weights: np.ndarray | None = None) -> int:
    """The order of a Butcher tableau: the largest p <= `max_order` such that every order
    condition of order <= p holds to rounding (`condition_tolerance`, scaled by the size of the
    coefficients). By default `max_order` is the highest order the tableau could have (s for
    an explicit s-stage method, 2s otherwise), capped at MAX_TREE_ORDER; a result equal to
    MAX_TREE_ORDER means "at least that". `weights` replaces b (an embedded method).

    Parameters
    ----------
    tableau : ButcherTableau
    max_order : int, optional, the highest order checked, 1 to MAX_TREE_ORDER.
    weights : ndarray, optional, weights used in place of b.

    Returns
    -------
    int: the order p (0 when even the first-order condition fails).
    """
    check_type(tableau, "runge-kutta", "tableau")
    if max_order is None:
        max_order = min(MAX_TREE_ORDER, tableau.stages if tableau.explicit else 2 * tableau.stages)
    max_order = check_int(max_order, "max_order", 1, MAX_TREE_ORDER)
    phi, size = elementary_weights(tableau, max_order, weights)
    failed = [t.order for t in rooted_trees(max_order)
              if abs(phi[t.index] - 1.0 / t.gamma) > condition_tolerance(t, size[t.index],
                                                                         tableau.published_precision)]
    return min(failed) - 1 if failed else max_order


def rk_stability_coefficients(tableau: ButcherTableau, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Taylor coefficients r_k = b^T A^(k-1) e of R(z) for k = 0..degree (r_0 = 1), and the same
    products over |b|, |A| (their rounding scale).

    Parameters
    ----------
    tableau : ButcherTableau
    degree : int, the last k.

    Returns
    -------
    (ndarray, ndarray): r_0 ... r_degree, and the same products over |b|, |A|.
    """
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
    order) and capped there.

    Parameters
    ----------
    tableau : ButcherTableau

    Returns
    -------
    int: the linear order p, at most min(2s + 2, 40).
    """
    check_type(tableau, "runge-kutta", "tableau")
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
    highest order any k-step method reaches).

    Parameters
    ----------
    method : LinearMultistep
    q_max : int, optional, the last constant, 0 to 40.

    Returns
    -------
    ndarray: C_0 ... C_{q_max}.
    """
    return _lmm_constants(method, "multistep", 1, q_max)[0]


def _lmm_constants(method: Any, kind: str, derivative: int, q_max: int | None):
    # (C, scale) of a multistep method for y' = f (derivative 1) or x'' = a (2), up to q_max
    # (default 2k + derivative), after checking that `method` is of `kind`
    check_type(method, kind, "method")
    q_max = 2 * method.steps + derivative if q_max is None else check_int(q_max, "q_max", 0, 40)
    return _constants(method.alpha, method.beta, q_max, derivative)


def _order_from_constants(C: np.ndarray, scale: np.ndarray, offset: int) -> int:
    bad = np.abs(C) > tol.ORDER_CONDITION_TOL * np.maximum(1.0, scale)
    first = int(np.argmax(bad)) if bad.any() else C.size
    return first - offset


def lmm_order(method: LinearMultistep) -> int:
    """The order p of a linear multistep method: C_0 = ... = C_p = 0 and C_{p+1} != 0 (each
    constant compared with ORDER_CONDITION_TOL times the size of its terms). 0 means not even
    consistent (which `LinearMultistep` already refuses).

    Parameters
    ----------
    method : LinearMultistep

    Returns
    -------
    int: the order p.
    """
    return _order_from_constants(*_lmm_constants(method, "multistep", 1, None), 1)


def second_order_lmm_error_constants(method: SecondOrderMultistep, q_max: int | None = None):
    """C_0 ... C_{q_max} of a multistep method for x'' = a (default q_max = 2k + 2).

    Parameters
    ----------
    method : SecondOrderMultistep; q_max : as for `lmm_error_constants`.

    Returns
    -------
    ndarray: C_0 ... C_{q_max}.
    """
    return _lmm_constants(method, "second-order multistep", 2, q_max)[0]


def second_order_lmm_order(method: SecondOrderMultistep) -> int:
    """The order p of a multistep method for x'' = a: C_0 = ... = C_{p+1} = 0 (Stormer's rule
    alpha = (1, -2, 1), beta = (0, 1, 0) has C_4 = 1/12, order 2).

    Parameters
    ----------
    method : SecondOrderMultistep, a table for x'' = a.

    Returns
    -------
    int: the order p.
    """
    return _order_from_constants(*_lmm_constants(method, "second-order multistep", 2, None), 2)

def order_from_coefficients(stepper: Any) -> int | None:
    """The order implied by a stepper's coefficient object (`stepper.coefficients`), or None
    when it has none (external, adaptive, Taylor) or of a kind this module does not know.

    Parameters
    ----------
    stepper : Stepper, any stepper; only its `coefficients` attribute is read.

    Returns
    -------
    int or None: the order its coefficients imply.
    """
    coeffs = getattr(stepper, "coefficients", None)
    order_of = {"runge-kutta": rk_order, "multistep": lmm_order,
                "second-order multistep": second_order_lmm_order, "splitting": splitting_order}
    family = family_of(coeffs)
    return None if family is None else order_of[family](coeffs)
