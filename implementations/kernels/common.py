"""What the family kernels share: a problem function over every member, the finiteness test,
and the ensemble Newton steps (LU factor and solve per member, the update, the convergence test
and the failure record) of the implicit families.

Compile options, one name each (Lam, Pitrou & Seibert, *Numba: a LLVM-based Python JIT
compiler*, LLVM-HPC 2015): `error_model="numpy"` everywhere (a division by zero gives inf/NaN as
in NumPy, and no check blocks vectorisation); `cache=True` (numba's disk cache, kept under
`harness.cache.code_dir()` by `implementations.kernels`).
"""

import numpy as np
from numba import njit

from implementations.kernel_calls import call_state
from implementations.newton_rule import newton_stop

__all__ = ["CONTRACT", "EXACT", "INLINE", "is_finite", "rhs_members", "rhs_all", "accel_all", "lu_factor",
           "lu_apply", "newton_factor_members", "newton_solve_members", "newton_update", "newton_converged",
           "load_member", "newton_start", "newton_members_step", "newton_stats"]

#: The explicit one-step and Stormer loops: a*b + c may become one fused multiply-add, as in
#: heyoka's compiled functions and the BLAS axpy updates of the NumPy loops; no other fast-math
#: licence.
CONTRACT = {"cache": True, "error_model": "numpy", "fastmath": {"contract"}}
#: The multistep and implicit Runge-Kutta loops, whose NumPy loops are plain array expressions
#: (one rounding per operation, no BLAS), contract nothing. Also the ensemble Newton steps
#: (factor, solve, update over all members; called once per iteration whatever the ensemble
#: size) and the scalar convergence test and failure record: compiled once and called, not
#: inlined into each kernel.
EXACT = {"cache": True, "error_model": "numpy"}
#: Helpers called once per step or per member, inlined into the kernels (numba's IR inlining):
#: a call between compiled functions passes each array with its reference counts.
INLINE = {"cache": True, "error_model": "numpy", "inline": "always"}


@njit(**INLINE)
def is_finite(x):
    """Whether scalar `x` is finite: np.isfinite's test without the per-element library call.

    Parameters
    ----------
    x : float, the value tested.

    Returns
    -------
    bool: False for inf, -inf and NaN.
    """
    return abs(x) <= 1.7976931348623157e308


@njit(**INLINE)
def rhs_members(f_rhs, t, Y, P, Out, y, out, p):
    """Out[:, j] = f(t, Y[:, j], P[:, j]) member by member, through the caller's work vectors (so a
    kernel calling it once per step allocates nothing).

    Parameters
    ----------
    f_rhs : compiled problem function `f(t, y, p, out)`; t : float, the time.
    Y : (dim, n) states; P : (n_par, n) parameters; Out : (dim, n) written in place.
    y, out : (dim,) work vectors; p : (n_par,) work vector.
    """
    for j in range(Y.shape[1]):
        for d in range(Y.shape[0]):
            y[d] = Y[d, j]
        for k in range(P.shape[0]):
            p[k] = P[k, j]
        call_state(f_rhs, t, y, p, out)
        for d in range(Y.shape[0]):
            Out[d, j] = out[d]


@njit(**INLINE)
def rhs_all(f_rhs, t, Y, P, Out):
    """Out[:, j] = f(t, Y[:, j], P[:, j]) for every member, with work vectors of its own.

    Parameters
    ----------
    f_rhs : compiled problem function; t : float, the time; Y : (dim, n) states;
    P : (n_par, n) parameters; Out : (dim, n) written in place.
    """
    dim = Y.shape[0]
    rhs_members(f_rhs, t, Y, P, Out, np.empty(dim), np.empty(dim), np.empty(P.shape[0]))


@njit(**CONTRACT)
def accel_all(f_accel, t, Q, P, Out):
    """The acceleration of every member: the same member loop as the right-hand side's.

    Parameters
    ----------
    f_accel : compiled acceleration `a(t, q, p, out)`; t : float, the time; Q : (dim, n) positions;
    P : (n_par, n) parameters; Out : (dim, n) written in place.
    """
    rhs_all(f_accel, t, Q, P, Out)


# Newton's method on the ensemble axis, as `implementations.implicit_rk.newton_solve`: the
# increment's max-norm over members and components (scaled by 1 + |y_n|) at most `tol`, or the
# contraction estimate theta / (1 - theta) |dx| at most `tol` (Hairer & Wanner II, IV.8, eq.
# (8.10)), or stalled at the rounding level (`newton_converged`); LU with partial pivoting per
# member. Status 1: no convergence; 2: singular matrix.
@njit(**INLINE)
def lu_factor(M, piv):
    """M = P L U in place: Gaussian elimination with partial pivoting, whole rows swapped, the
    multipliers stored below the diagonal.

    Parameters
    ----------
    M : (m, m) float array, overwritten by its factors; piv : (m,) int array, the pivot row of each
    column (written).

    Returns
    -------
    bool: False on an exactly zero pivot (M then partly factored), else True.
    """
    m = M.shape[0]
    for col in range(m):
        p = col
        best = abs(M[col, col])
        for r in range(col + 1, m):
            if abs(M[r, col]) > best:
                best = abs(M[r, col])
                p = r
        piv[col] = p
        if M[p, col] == 0.0:
            return False
        if p != col:
            for q in range(m):
                tmp = M[col, q]
                M[col, q] = M[p, q]
                M[p, q] = tmp
        inv = 1.0 / M[col, col]
        for r in range(col + 1, m):
            multiplier = M[r, col] * inv
            M[r, col] = multiplier
            if multiplier != 0.0:
                for q in range(col + 1, m):
                    M[r, q] -= multiplier * M[col, q]
    return True


@njit(**INLINE)
def lu_apply(M, piv, b, x):
    """x = M^-1 b from `lu_factor`'s factors: every row swap first, then the two substitutions (each
    entry sees the same operations in the same order as elimination interleaved with the swaps).

    Parameters
    ----------
    M, piv : the factors and pivots written by `lu_factor`; b : (m,) right-hand side (read);
    x : (m,) the solution (written).
    """
    m = b.shape[0]
    for i in range(m):
        x[i] = b[i]
    for col in range(m):
        p = piv[col]
        if p != col:
            tmp = x[col]
            x[col] = x[p]
            x[p] = tmp
    for col in range(m):
        for r in range(col + 1, m):
            multiplier = M[r, col]
            if multiplier != 0.0:
                x[r] -= multiplier * x[col]
    for i in range(m - 1, -1, -1):
        acc = x[i]
        for q in range(i + 1, m):
            acc -= M[i, q] * x[q]
        x[i] = acc / M[i, i]


@njit(**EXACT)
def newton_factor_members(Mats, Piv):
    """Every member's Newton matrix factored in place, once per matrix whatever the number of
    iterations that solve with it.

    Parameters
    ----------
    Mats : (n, m, m) matrices, overwritten by their factors; Piv : (n, m) pivots (written).

    Returns
    -------
    bool: False as soon as one matrix is singular.
    """
    for j in range(Mats.shape[0]):
        if not lu_factor(Mats[j], Piv[j]):
            return False
    return True


@njit(**EXACT)
def newton_solve_members(Mats, Piv, G, DX, rhs_w, sol):
    """DX[:, j] = -Mats[j]^-1 G[:, j] for every member, from the factors of `newton_factor_members`.

    Parameters
    ----------
    Mats, Piv : the factored matrices and pivots; G : (m, n) residuals; DX : (m, n) increments
    (written); rhs_w, sol : (m,) work vectors.
    """
    m = rhs_w.shape[0]
    for j in range(G.shape[1]):
        for r in range(m):
            rhs_w[r] = -G[r, j]
        lu_apply(Mats[j], Piv[j], rhs_w, sol)
        for r in range(m):
            DX[r, j] = sol[r]


@njit(**EXACT)
def newton_update(X, DX, inv_scale):
    """X += DX, and the increment's and the new iterate's max-norms scaled by `inv_scale`.

    Parameters
    ----------
    X : (s * dim, n) stage values, updated in place; DX : (s * dim, n) increments;
    inv_scale : (dim, n) inverse error scales (row i * dim + d of X uses row d).

    Returns
    -------
    tuple (float, float): the scaled max-norm of DX (NaN when any scaled entry is not finite) and
    the scaled max-norm of the updated X (the iterate's size for the rounding-aware stop).
    """
    dim = inv_scale.shape[0]
    norm = 0.0
    size = 0.0
    nan_seen = False
    for i in range(X.shape[0] // dim):
        for d in range(dim):
            r = i * dim + d
            for j in range(X.shape[1]):
                X[r, j] += DX[r, j]
                e = abs(DX[r, j] * inv_scale[d, j])
                if e != e:
                    nan_seen = True
                elif e > norm:
                    norm = e
                x = abs(X[r, j] * inv_scale[d, j])
                if x > size:
                    size = x
    if nan_seen or not is_finite(norm):
        return np.nan, size
    return norm, size


@njit(**INLINE)
def load_member(X, P, j, n, y, p):
    """Member j's first `n` state components and its parameters into the work vectors a call of
    the problem's function reads.

    Parameters
    ----------
    X : 2-d array (components, members); P : 2-d array (parameters, members); j : int, the member;
    n : int, how many components; y, p : 1-d arrays, written.
    """
    for d in range(n):
        y[d] = X[d, j]
    for q in range(p.shape[0]):
        p[q] = P[q, j]


#: The simplified-Newton stopping test, rounding-aware (Hairer & Wanner, Solving ODEs II, IV.8):
#: `implementations.newton_rule.newton_stop` compiled, the function the NumPy loops call.
newton_converged = njit(**EXACT)(newton_stop)


@njit(**INLINE)
def newton_start():
    """The Newton iteration's state before its first iteration.

    Returns
    -------
    tuple: (previous, norm, theta, res_norm, converged, status) = (inf, inf, NaN, NaN, False, 1).
    """
    return np.inf, np.inf, np.nan, np.nan, False, 1


@njit(**EXACT)
def newton_members_step(factor, Mats, Piv, G, DX, rhs_w, sol, X, inv_scale, norm, previous, tol, theta):
    """One ensemble Newton iteration: factor the new matrices when `factor`, solve, update X, test.

    Parameters
    ----------
    factor : bool, whether Mats hold new (unfactored) matrices; Mats, Piv, G, DX, rhs_w, sol : as
    in `newton_solve_members`; X, inv_scale : as in `newton_update`; norm, previous, tol, theta :
    as in `newton_converged`.

    Returns
    -------
    tuple: (norm, converged, theta, status); status 2 on a singular matrix (X and norm as they
    were), else 1; norm NaN (and not converged) when the increment is not finite.
    """
    if factor and not newton_factor_members(Mats, Piv):
        return norm, False, theta, 2
    newton_solve_members(Mats, Piv, G, DX, rhs_w, sol)
    norm, size = newton_update(X, DX, inv_scale)
    if norm != norm:
        return norm, False, theta, 1
    converged, theta = newton_converged(norm, previous, tol, theta, size)
    return norm, converged, theta, 1


@njit(**EXACT)
def newton_stats(stats, n, n_rhs, n_jac, n_iter, iteration, norm, res_norm, theta, status):
    """The failure record of a Newton solve, written into `stats` in this order.

    Parameters
    ----------
    stats : (9,) float array (written); n : the step index; n_rhs, n_jac, n_iter : counts of
    problem calls, Jacobians and iterations; iteration : the iteration reached; norm, res_norm,
    theta : the last increment norm, residual norm and contraction; status : the solve's status.
    """
    stats[0] = n
    stats[1] = n_rhs
    stats[2] = n_jac
    stats[3] = n_iter
    stats[4] = iteration
    stats[5] = norm
    stats[6] = res_norm
    stats[7] = theta
    stats[8] = status
