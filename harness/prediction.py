"""The predicted leading global error of a Runge-Kutta method on a problem: err ~ C h^p.

For a one-step method of order p the global error at T is h^p e(T) + O(h^(p+1)), where
    e' = f'(y(t)) e + d(y(t)),  e(t0) = 0,   d(y) = sum_{|t| = p+1} delta(t) F(t)(y)
(Hairer, Norsett & Wanner, *Solving ODEs I*, II.8, Theorem 8.1: the principal error function d
is the h^(p+1) term of the local error, carried by the variational equation). With the B-series
of the local error (`harness.theory.classes`), delta(t) = (Phi(t) - 1/gamma(t)) / sigma(t)
comes from the coefficients and F(t) is the elementary differential, so

    e(T) = sum_t delta(t) E_t(T),   E_t' = f'(y) E_t + F(t)(y),  E_t(t0) = 0.

The E_t(T) depend on the problem and the tree only: they are integrated once per (problem,
order) by heyoka's Taylor integrator on the system (y, E_t for every tree t) built from the
symbolic definition (F(t) by symbolic differentiation, `elementary_differentials`) and kept on
disk (`harness.derived`); a method's prediction is then a dot product with its defects. p is the
method's order on the problem (its class order where elementary differentials vanish, the
linear order on linear problems), so the trees that vanish on the class contribute exact zeros.

The prediction follows the problem's own start; the convergence experiment's error is a
max-norm over a small ensemble around it, so C = max_i |e_i(T)| is compared with it as an
asymptotic statement: within a modest factor once the h^p term dominates. The same sum at
order p+2 (the next trees' local terms carried to T; the h^(p+1) global term also has a part
from e itself, which this leaves out) estimates the next term's size, and C_next / C the step
below which the leading term must show.
Symbolic elementary differentials grow like dim^m for m-fold derivatives: the prediction is
made where dim^(order-1) stays within PREDICTION_MAX_WORK, and otherwise says why not.
"""

from __future__ import annotations

import math
from typing import Any

import heyoka as hy
import numpy as np

from harness import tolerances as tol
from harness.derived import remembered
from harness.problem import Problem
from harness.theory import rooted_trees
from harness.theory.classes import rk_error_defects

__all__ = ["elementary_differentials", "propagated_tree_terms", "predicted_error", "explain_slope"]


def _autonomous(problem: Problem) -> tuple[list, list]:
    """(variables, right-hand side) with the time made a variable `tau_time_` (t' = 1) when the
    problem reads it; the Runge-Kutta tableaux here have c = A e, so the time is integrated
    exactly and the autonomous B-series applies."""
    variables, rhs = list(problem.variables), list(problem.rhs)
    if problem.time_dependent:
        tau = hy.make_vars("tau_time_")
        rhs = [hy.subs(e, {hy.time: tau}) for e in rhs] + [hy.expression(1.0)]
        variables.append(tau)
    return variables, rhs


def elementary_differentials(problem: Problem, order: int) -> tuple[list, list[list]]:
    """The trees with `order` vertices and their elementary differentials F(t) as heyoka
    expressions in the problem's (autonomous) variables.

    Parameters
    ----------
    problem : Problem
    order : int
        Number of vertices of the trees (p + 1 for the leading local error of order p).

    Returns
    -------
    (trees, differentials) : the `RootedTree`s and, per tree, one expression per component.
    """
    variables, f = _autonomous(problem)
    n = len(variables)
    trees = rooted_trees(order)
    max_children = max(len(t.children) for t in trees)
    directions = [[hy.make_vars(f"w_dir{k}_{j}_") for j in range(n)] for k in range(max_children)]
    forms = [f]  # forms[m] = f^(m)(w_0, ..., w_{m-1}) as expressions in y and the w's
    for k in range(max_children):
        jac = hy.diff_tensors(forms[-1], diff_args=variables, diff_order=1)
        rows = [[None] * n for _ in range(n)]
        for idx, expr in jac.get_derivatives(1):
            rows[idx[0]][idx[1:].index(1)] = expr
        forms.append([hy.sum([rows[i][j] * directions[k][j] for j in range(n)]) for i in range(n)])
    F: list[list] = []
    for t in trees:
        if not t.children:
            F.append(list(f))
            continue
        mapping = {str(directions[k][j]): F[c][j] for k, c in enumerate(t.children) for j in range(n)}
        F.append(hy.subs(forms[len(t.children)], mapping))
    picked = [t for t in trees if t.order == order]
    return picked, [F[t.index] for t in picked]


def propagated_tree_terms(problem: Problem, order: int) -> dict[str, Any]:
    """E_t(T) for every tree of `order` vertices (module docstring), at the problem's
    convergence horizon from its own start; kept on disk (`harness.derived`).

    Parameters
    ----------
    problem : Problem, the problem; order : int, the trees' number of vertices.

    Returns
    -------
    dict with `trees` (labels), `terms` (one list of dim numbers per tree, in the problem's
    variables) and `t_end`; or `why` (a sentence) when the prediction is not made.
    """
    return remembered(__name__, "propagated_tree_terms", [problem.fingerprint(), order],
                      lambda: _propagate(problem, order))


def _propagate(problem: Problem, order: int) -> dict[str, Any]:
    if problem.dim ** (order - 1) > tol.PREDICTION_MAX_WORK:
        return {"why": (f"not predicted: {problem.dim} variables and trees of order {order} (the "
                        f"symbolic elementary differentials grow like dim^(order-1) = "
                        f"{problem.dim ** (order - 1)}, above PREDICTION_MAX_WORK = "
                        f"{tol.PREDICTION_MAX_WORK})")}
    variables, f = _autonomous(problem)
    n = len(variables)
    trees, F = elementary_differentials(problem, order)
    jac = hy.diff_tensors(f, diff_args=variables, diff_order=1)
    J = [[hy.expression(0.0)] * n for _ in range(n)]
    for idx, expr in jac.get_derivatives(1):
        J[idx[0]][idx[1:].index(1)] = expr
    sys = list(zip(variables, f, strict=True))
    for k, Fk in enumerate(F):
        E = [hy.make_vars(f"e_tree{k}_{i}_") for i in range(n)]
        sys += [(E[i], hy.sum([J[i][j] * E[j] for j in range(n)]) + Fk[i]) for i in range(n)]
    y0 = list(problem.y0) + ([problem.t0] if problem.time_dependent else [])
    state = np.concatenate([y0, np.zeros(n * len(trees))])
    # opt_level 0: LLVM's optimisation passes were most of the cost (forced Duffing, trees of 5
    # vertices: 0.61 s compiled at level 3, 0.07 s at 0, E_t(T) equal to 6e-16)
    ta = hy.taylor_adaptive(sys, state.tolist(), time=float(problem.t0), tol=tol.PREDICTION_TAYLOR_TOL,
                            pars=problem.parameter_values.tolist(), compact_mode=True, opt_level=0)
    outcome = ta.propagate_until(problem.convergence_t_end)[0]
    if outcome != hy.taylor_outcome.time_limit:
        return {"why": f"not predicted: the variational integration stopped ({outcome})"}
    terms = ta.state[n:].reshape(len(trees), n)[:, :problem.dim]
    return {"trees": [t.label for t in trees], "terms": terms.tolist(),
            "t_end": float(problem.convergence_t_end)}


def predicted_error(tableau: Any, problem: Problem, order: int, *, next_term: bool = True,
                    max_work: int | None = None) -> dict[str, Any]:
    """The predicted leading global error of `tableau` (a `ButcherTableau`) of order `order` on
    `problem` (its order there: class or linear order where it exceeds the order).

    Parameters
    ----------
    tableau : ButcherTableau
    problem : Problem
    order : int
        The order p on this problem; the leading term comes from the trees of p + 1 vertices.
    next_term : bool
        Also estimate the order-(p+1) term (the trees of p + 2 vertices: the costlier half,
        needed only to place the crossover when a slope is to be explained).
    max_work : int, optional
        A smaller budget than PREDICTION_MAX_WORK for dim^(order-1) (the prediction shown
        beside every cell keeps to PREDICTION_ROUTINE_MAX_WORK).

    Returns
    -------
    dict with `order` (p), `coefficient` (C: max_i |e_i(T)|, so err ~ C h^p), `next_coefficient`
    (the order-(p+1) estimate, NaN when not made), `crossover_h` (C / C_next: below it the h^p
    term leads) and `why` (empty, or the reason nothing was predicted).
    """
    out = {"order": order, "coefficient": math.nan, "next_coefficient": math.nan,
           "crossover_h": math.nan, "why": ""}
    sizes = []
    for k in (order + 1, order + 2) if next_term else (order + 1,):
        if max_work is not None and problem.dim ** (k - 1) > max_work:
            terms = {"why": (f"not predicted: {problem.dim} variables and trees of order {k} "
                             f"(dim^(order-1) = {problem.dim ** (k - 1)} is above the budget "
                             f"{max_work} of the prediction beside every cell)")}
        else:
            terms = propagated_tree_terms(problem, k)
        if "why" in terms:
            if k == order + 1:
                out["why"] = terms["why"]
                return out
            break
        _, defects = rk_error_defects(tableau, k)
        e = defects @ np.asarray(terms["terms"], dtype=float)
        sizes.append(float(np.max(np.abs(e))))
    out["coefficient"] = sizes[0]
    if len(sizes) > 1:
        out["next_coefficient"] = sizes[1]
        out["crossover_h"] = sizes[0] / sizes[1] if sizes[1] > 0 else math.inf
    return out


def explain_slope(measured: float, expected: float, prediction: dict[str, Any],
                  h_range: tuple[float, float], error_range: tuple[float, float]) -> tuple[bool, str]:
    """(explained, reason) for a measured slope above the expected order: explained when the
    predicted leading term C h^p is below SLOPE_EXPLAINED_RATIO of the measured error somewhere
    in the fitted steps (a tiny or cancelling leading term: later terms set at least part of the
    fitted slope, which then lies between p and their orders). Not explained: the leading term
    accounts for the measured error over the whole fit, so the slope should have been p. The
    predicted crossover C / C_next (where the h^p term starts to lead) is reported, not judged:
    its next term leaves out part of the h^(p+1) global term (module docstring).

    Parameters
    ----------
    measured, expected : the fitted slope and the expected order p.
    prediction : the `predicted_error` dict of the cell.
    h_range, error_range : (smallest, largest) fitted step and measured error.

    Returns
    -------
    tuple (bool, str): (explained, the reason with the numbers).
    """
    C = float(prediction.get("coefficient", math.nan))
    if not math.isfinite(C):
        why = prediction.get("why") or "no prediction"
        return False, f"slope {measured:.3f} above the order {expected:g}: {why}"
    h_lo, h_hi = h_range
    e_lo, e_hi = error_range
    p = float(expected)
    ratio = min(C * h_lo**p / e_lo, C * h_hi**p / e_hi) if min(e_lo, e_hi) > 0 else math.nan
    cross = float(prediction.get("crossover_h", math.nan))
    numbers = (f"predicted C = {C:.3g} (err ~ C h^{p:g}); C h^p / measured error down to {ratio:.3g} over "
               f"h = {h_lo:.3g}..{h_hi:.3g}" + (f"; leading term dominates below h ~ {cross:.3g}"
                                                 if math.isfinite(cross) else ""))
    if math.isfinite(ratio) and ratio < tol.SLOPE_EXPLAINED_RATIO:
        return True, f"slope {measured:.3f} > {p:g} explained: the leading term is small here: {numbers}"
    return False, f"slope {measured:.3f} > {p:g} not explained by the predicted leading term: {numbers}"
