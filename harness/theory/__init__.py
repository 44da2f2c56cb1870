"""Order and linear stability from the coefficients alone: what a method *should* do.

The package re-exports the public names of its modules: `orders` (rooted trees, Runge-Kutta
order conditions, multistep error constants), `classes` (orders on problem classes where
elementary differentials vanish, stage order, order-condition defects), `series` (order from
an exact local-error series), `amplification` (stability functions, scanned intervals),
`intervals` (intervals decided on polynomials and root loci), `roots` (exact polynomial
arithmetic and root isolation), `newtonian` (every unstable h omega band of Newtonian
methods), `checks` (argument checks).

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
The amplification of each family on the linear test equation (`amplification`: R(z) for
Runge-Kutta, the root condition for multistep methods, the one-step propagator on
x'' = -omega^2 x for Newtonian methods; Hairer & Wanner, *Solving ODEs II*, V.1), and where its
stable intervals end (`amplification` by a refined scan, `intervals` on polynomials).
"""

from __future__ import annotations

from harness.theory.amplification import (
    hw_stability_limit,
    imag_stability_interval,
    lmm_amplification,
    real_stability_interval,
    rk_stability_function,
    second_order_lmm_amplification,
    spectral_radius,
    splitting_amplification,
    splitting_propagator,
    stability_boundary,
)
from harness.theory.classes import (
    rk_class_order,
    rk_class_orders,
    rk_error_defects,
    rk_stage_order,
    rk_stiffly_accurate,
    tree_survives,
    tree_symmetry,
)
from harness.theory.intervals import (
    analytic_stability,
    exact_hw_bands,
    lmm_real_interval,
    rk_stability_intervals,
    splitting_hw_limit,
    splitting_linear_order,
    splitting_trace_polynomial,
)
from harness.theory.orders import (
    MAX_TREE_ORDER,
    OrderCondition,
    RootedTree,
    lmm_error_constants,
    lmm_order,
    order_from_coefficients,
    rk_linear_order,
    rk_order,
    rk_order_conditions,
    rk_stability_coefficients,
    rooted_trees,
    second_order_lmm_error_constants,
    second_order_lmm_order,
)
from harness.theory.series import (
    rk_order_series,
    splitting_local_error_series,
    splitting_order,
)

__all__ = [
    "rk_class_order",
    "rk_class_orders",
    "rk_error_defects",
    "rk_stage_order",
    "rk_stiffly_accurate",
    "tree_survives",
    "tree_symmetry",
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
    "splitting_trace_polynomial",
    "exact_hw_bands",
]
