"""The implicit Runge-Kutta kernels: stages solved by a simplified Newton iteration with the
problem's Jacobian, for one member (`irk_single`, the same operations in the same order as the
ensemble loop, without its per-member views and member loops) and for the ensemble
(`irk_advance`, Newton's convergence a maximum over members as in the NumPy loop).
"""

import numpy as np
from numba import njit

from implementations.kernel_calls import call_state
from implementations.kernels.common import (
    EXACT,
    is_finite,
    lu_apply,
    lu_factor,
    newton_converged,
    newton_members_step,
    newton_start,
    newton_stats,
    rhs_all,
)

__all__ = ["irk_single", "irk_advance"]


# Implicit Runge-Kutta (Hairer & Wanner II, IV.8): unknowns Z_i = h sum_j a_ij f(t + c_j h,
# y + Z_j) on the stages with a nonzero row of A; y_{n+1} = y + sum_i d_i Z_i + h w f(t, y),
# d = A_ii^{-T} b_impl; first same as last recovers f at the step's end from Z.
# flags: [f_start valid, z_prev valid]; stats out: [steps done, rhs, jac, iterations,
# failed iteration, increment, residual, contraction, status].
@njit(**EXACT)
def irk_single(f_rhs, f_jac, A_ii, aie_sum, c_impl, dvec, wsum, last_inv, E, has_pred, has_expl, fsal,
               full, tol, max_iter, t0, n0, h, nsteps, Y, Fstart, Zprev, flags, P, stats):
    """`irk_advance` for one member and one implicit stage (Z = h a f(t + c h, y + Z) - h a_e f(t, y)),
    the state in flat arrays: the same operations in the same order.

    Parameters
    ----------
    f_rhs, f_jac, A_ii, aie_sum, c_impl, dvec, wsum, last_inv, E, has_pred, has_expl, fsal, full,
    tol, max_iter, t0, n0, h, nsteps, Y, Fstart, Zprev, flags, P, stats : as in `irk_advance`, with
    one member and one implicit stage.
    """
    dim = Y.shape[0]
    npar = P.shape[0]
    a00 = h * A_ii[0, 0]
    c00 = -a00
    hexp = h * aie_sum[0]
    hw = h * wsum
    e00 = E[0, 0]
    d0 = dvec[0]
    l0 = last_inv[0]
    tc = c_impl[0] * h
    y = np.empty(dim)
    fstart = np.empty(dim)
    zprev = np.empty(dim)
    for d in range(dim):
        y[d] = Y[d, 0]
        fstart[d] = Fstart[d, 0]
        zprev[d] = Zprev[0, d, 0]
    p = np.empty(npar)
    for q in range(npar):
        p[q] = P[q, 0]
    X = np.empty(dim)
    F = np.empty(dim)
    Fexp = np.empty(dim)
    inv_scale = np.empty(dim)
    ys = np.empty(dim)
    J = np.empty(dim * dim)
    M = np.empty((dim, dim))
    piv = np.empty(dim, dtype=np.int64)
    rhs_w = np.empty(dim)
    sol = np.empty(dim)
    f0 = flags[0]
    f1 = flags[1]
    n_rhs = 0
    n_jac = 0
    n_iter = 0
    failed = False
    for n in range(nsteps):
        t = t0 + (n0 + n) * h
        finite = True
        for d in range(dim):
            finite &= is_finite(y[d])
        if not finite:
            for d in range(dim):
                y[d] = np.nan
            f0 = 0
            f1 = 0
            continue
        if has_expl:
            if f0 != 0:
                for d in range(dim):
                    Fexp[d] = fstart[d]
            else:
                call_state(f_rhs, t, y, p, Fexp)
                n_rhs += 1
        for d in range(dim):
            inv_scale[d] = 1.0 / (1.0 + abs(y[d]))
        if f1 != 0 and has_pred:
            for d in range(dim):
                acc = 0.0
                acc += e00 * zprev[d]
                X[d] = acc
        else:
            for d in range(dim):
                X[d] = 0.0
        previous, norm, theta, res_norm, converged, status = newton_start()
        k = 0
        for k in range(1, max_iter + 1):
            # residual g = Z - h a F(Z) - h a_e F_e, kept negated for the solve
            for d in range(dim):
                ys[d] = y[d] + X[d]
            call_state(f_rhs, t + tc, ys, p, F)
            n_rhs += 1
            res_norm = 0.0
            for d in range(dim):
                g = X[d] - a00 * F[d]
                if has_expl:
                    g -= hexp * Fexp[d]
                rhs_w[d] = -g
                r = abs(g * inv_scale[d])
                if not (r <= res_norm):
                    res_norm = r
            if k == 1 or full:
                if full:
                    call_state(f_jac, t + tc, ys, p, J)
                else:
                    call_state(f_jac, t, y, p, J)
                for a in range(dim):
                    for bb in range(dim):
                        M[a, bb] = c00 * J[a * dim + bb]
                for a in range(dim):
                    M[a, a] += 1.0
                n_jac += 1
                if not lu_factor(M, piv):
                    n_iter += 1
                    status = 2
                    break
            n_iter += 1
            lu_apply(M, piv, rhs_w, sol)
            # X += DX; the increment's and the iterate's max-norms scaled by inv_scale (the increment's
            # NaN when any entry is not finite)
            norm = 0.0
            size = 0.0
            nan_seen = False
            for d in range(dim):
                X[d] += sol[d]
                e = abs(sol[d] * inv_scale[d])
                if e != e:
                    nan_seen = True
                elif e > norm:
                    norm = e
                x = abs(X[d] * inv_scale[d])
                if x > size:
                    size = x
            if nan_seen or not is_finite(norm):
                norm = np.nan
                break
            converged, theta = newton_converged(norm, previous, tol, theta, size)
            if converged:
                break
            previous = norm
        if not converged:
            newton_stats(stats, n, n_rhs, n_jac, n_iter, k, norm, res_norm, theta, status)
            failed = True
            break
        for d in range(dim):
            acc = 0.0
            acc += d0 * X[d]
            ynew = y[d] + acc
            if has_expl:
                ynew += hw * Fexp[d]
            if fsal:
                z = X[d]
                if has_expl:
                    z -= hexp * Fexp[d]
                hf = 0.0
                hf += l0 * z
                fstart[d] = hf / h
            y[d] = ynew
        if fsal:
            f0 = 1
        for d in range(dim):
            zprev[d] = X[d]
        f1 = 1
    for d in range(dim):
        Y[d, 0] = y[d]
        Fstart[d, 0] = fstart[d]
        Zprev[0, d, 0] = zprev[d]
    flags[0] = f0
    flags[1] = f1
    if not failed:
        stats[0] = nsteps
        stats[1] = n_rhs
        stats[2] = n_jac
        stats[3] = n_iter
        stats[8] = 0


@njit(**EXACT)
def irk_advance(f_rhs, f_jac, A_ii, aie_sum, c_impl, dvec, wsum, last_inv, E, has_pred, has_expl, fsal,
                full, tol, max_iter, t0, n0, h, nsteps, Y, Fstart, Zprev, flags, P, stats):
    """`nsteps` implicit Runge-Kutta steps of every member (see the comment above for the scheme).

    Parameters
    ----------
    f_rhs, f_jac : compiled right-hand side and Jacobian; A_ii : the implicit block of A;
    aie_sum : row sums of its explicit columns; c_impl : the implicit stages' nodes;
    dvec : d = A_ii^{-T} b_impl; wsum : the sum of the explicit weights w; last_inv : the last row
    of A_ii^{-1} (f at the step's end, first same as last); E : the stage extrapolation matrix;
    has_pred, has_expl, fsal : bool, whether E, an explicit stage and first-same-as-last apply;
    full : bool, a new Jacobian at every iteration; tol : float, the Newton tolerance;
    max_iter : int; t0 : float, start time; n0 : int, steps already taken; h : float, the step;
    nsteps : int; Y : (dim, n) states, Fstart : (dim, n) f at the step's start and
    Zprev : (impl, dim, n) the last stages, all updated in place; flags : [f_start valid, z_prev
    valid] (updated); P : (n_par, n) parameters; stats : (9,) float array, written as the
    comment above says.
    """
    dim, N = Y.shape
    if N == 1 and c_impl.shape[0] == 1:
        irk_single(f_rhs, f_jac, A_ii, aie_sum, c_impl, dvec, wsum, last_inv, E, has_pred, has_expl, fsal,
                   full, tol, max_iter, t0, n0, h, nsteps, Y, Fstart, Zprev, flags, P, stats)
        return
    impl = c_impl.shape[0]
    m = impl * dim
    npar = P.shape[0]
    hA = h * A_ii
    X = np.empty((m, N))
    G = np.empty((m, N))
    DX = np.empty((m, N))
    Mats = np.empty((N, m, m))
    Piv = np.empty((N, m), dtype=np.int64)
    Fimp = np.empty((impl, dim, N))
    Fexp = np.empty((dim, N))
    inv_scale = np.empty((dim, N))
    ys = np.empty(dim)
    out = np.empty(dim)
    Jb = np.empty(dim * dim)
    Jall = np.empty((impl, dim * dim))
    rhs_w = np.empty(m)
    sol = np.empty(m)
    p = np.empty(npar)
    n_rhs = 0
    n_jac = 0
    n_iter = 0
    for n in range(nsteps):
        t = t0 + (n0 + n) * h
        finite = True
        for d in range(dim):
            for j in range(N):
                if not is_finite(Y[d, j]):
                    finite = False
        if not finite:
            Y[:, :] = np.nan
            flags[0] = 0
            flags[1] = 0
            continue
        if has_expl:
            if flags[0] != 0:
                for d in range(dim):
                    for j in range(N):
                        Fexp[d, j] = Fstart[d, j]
            else:
                rhs_all(f_rhs, t, Y, P, Fexp)
                n_rhs += 1
        for d in range(dim):
            for j in range(N):
                inv_scale[d, j] = 1.0 / (1.0 + abs(Y[d, j]))
        if flags[1] != 0 and has_pred:
            for i in range(impl):
                for d in range(dim):
                    for j in range(N):
                        acc = 0.0
                        for q in range(impl):
                            acc += E[i, q] * Zprev[q, d, j]
                        X[i * dim + d, j] = acc
        else:
            for r in range(m):
                for j in range(N):
                    X[r, j] = 0.0
        previous, norm, theta, res_norm, converged, status = newton_start()
        k = 0
        for k in range(1, max_iter + 1):
            # residual g = Z - h A_ii F(Z) - h A_ie F_e
            for i in range(impl):
                ti = t + c_impl[i] * h
                for j in range(N):
                    for d in range(dim):
                        ys[d] = Y[d, j] + X[i * dim + d, j]
                    for q in range(npar):
                        p[q] = P[q, j]
                    call_state(f_rhs, ti, ys, p, out)
                    for d in range(dim):
                        Fimp[i, d, j] = out[d]
                n_rhs += 1
            res_norm = 0.0
            for i in range(impl):
                for d in range(dim):
                    for j in range(N):
                        if impl == 1:
                            g = X[d, j] - hA[0, 0] * Fimp[0, d, j]
                        else:
                            acc = 0.0
                            for q in range(impl):
                                acc += hA[i, q] * Fimp[q, d, j]
                            g = X[i * dim + d, j] - acc
                        if has_expl:
                            g -= (h * aie_sum[i]) * Fexp[d, j]
                        G[i * dim + d, j] = g
                        r = abs(g * inv_scale[d, j])
                        if not (r <= res_norm):
                            res_norm = r
            if k == 1 or full:
                for j in range(N):
                    for q in range(npar):
                        p[q] = P[q, j]
                    if full:
                        for i in range(impl):
                            for d in range(dim):
                                ys[d] = Y[d, j] + X[i * dim + d, j]
                            call_state(f_jac, t + c_impl[i] * h, ys, p, Jb)
                            for q in range(dim * dim):
                                Jall[i, q] = Jb[q]
                    else:
                        for d in range(dim):
                            ys[d] = Y[d, j]
                        call_state(f_jac, t, ys, p, Jb)
                        for i in range(impl):
                            for q in range(dim * dim):
                                Jall[i, q] = Jb[q]
                    for i in range(impl):
                        for a in range(dim):
                            for q in range(impl):
                                for bb in range(dim):
                                    v = -hA[i, q] * Jall[q, a * dim + bb]
                                    if i == q and a == bb:
                                        v += 1.0
                                    Mats[j, i * dim + a, q * dim + bb] = v
                n_jac += impl if full else 1
            n_iter += 1
            norm, converged, theta, status = newton_members_step(
                k == 1 or full, Mats, Piv, G, DX, rhs_w, sol, X, inv_scale, norm, previous, tol, theta)
            if converged or status == 2 or norm != norm:
                break
            previous = norm
        if not converged:
            newton_stats(stats, n, n_rhs, n_jac, n_iter, k, norm, res_norm, theta, status)
            return
        for d in range(dim):
            for j in range(N):
                acc = 0.0
                for i in range(impl):
                    acc += dvec[i] * X[i * dim + d, j]
                ynew = Y[d, j] + acc
                if has_expl:
                    ynew += (h * wsum) * Fexp[d, j]
                if fsal:
                    hf = 0.0
                    for i in range(impl):
                        z = X[i * dim + d, j]
                        if has_expl:
                            z -= (h * aie_sum[i]) * Fexp[d, j]
                        hf += last_inv[i] * z
                    Fstart[d, j] = hf / h
                Y[d, j] = ynew
        if fsal:
            flags[0] = 1
        for i in range(impl):
            for d in range(dim):
                for j in range(N):
                    Zprev[i, d, j] = X[i * dim + d, j]
        flags[1] = 1
    stats[0] = nsteps
    stats[1] = n_rhs
    stats[2] = n_jac
    stats[3] = n_iter
    stats[8] = 0
