"""Kernels of second-order multistep tables, run by `implementations.second_order_multistep_compiled`:
explicit tables (Stormer, the symmetric Quinlan-Tremaine methods: `lmm2_explicit_advance`) and
implicit ones (Cowell: `lmm2_implicit_advance`, its simplified Newton iteration as the NumPy
loop runs it).

The same operations in the same order as `SecondOrderMultistepStepper._step` (no fused
multiply-add, `error_model="numpy"`): psi = -sum_j alpha_j x_(n+j) + sum_j (h^2 beta_j) a_(n+j),
accelerations evaluated once per stored point when a nonzero beta first needs them, the members
in lockstep so that a non-finite newest position stops every member (as the NumPy loop's
ensemble-wide test does). The problem's acceleration is heyoka's compiled function at an address
(`implementations.kernel_calls.call_state`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from implementations.kernel_calls import call_state
from implementations.kernels.common import (
    EXACT,
    is_finite,
    load_member,
    lu_apply,
    lu_factor,
    newton_converged,
    rhs_members,
)

__all__ = ["lmm2_explicit_advance", "lmm2_implicit_advance"]


@njit(**EXACT)
def lmm2_explicit_advance(f_accel, alpha, beta, h2, t0, n0, h, nsteps, X, A, known, head, P):
    """Advance the ring of the last `keep` positions `nsteps` steps.

    Parameters
    ----------
    f_accel : address of the problem's acceleration a(t, q) (state form).
    alpha, beta : the table (k + 1 values each, oldest first; beta_k = 0).
    h2 : h * h as the NumPy loop forms it; t0, n0, h : the carry's t0, step count and step.
    nsteps : int, the number of steps.
    X, A : rings (keep, nq, N) of positions and accelerations; `known[s]` says whether A[s]
        holds a(x) for slot s; `head` is the slot of the oldest point. Updated in place.
    P : the problem's parameters (npar, N).

    Returns
    -------
    (evaluations, head): acceleration evaluations of the whole ensemble (one per stored point,
    as the NumPy loop counts its batched calls) and the new oldest slot.
    """
    keep, nq, N = X.shape
    k = alpha.shape[0] - 1
    npar = P.shape[0]
    x = np.empty(nq)
    a = np.empty(nq)
    p = np.empty(npar)
    psi = np.empty(nq)
    evals = 0
    for s in range(nsteps):
        tc = t0 + (n0 + s) * h  # the newest stored point's time, as Carry.t
        newest = (head + keep - 1) % keep
        finite = True
        for j in range(N):
            for d in range(nq):
                if not is_finite(X[newest, d, j]):
                    finite = False
        if finite:
            for jj in range(k):  # stored points -k .. -1 are x_n .. x_(n+k-1)
                slot = (head + keep - k + jj) % keep
                if beta[jj] != 0.0 and known[slot] == 0:
                    rhs_members(f_accel, tc + (jj - k + 1) * h, X[slot], P, A[slot], x, a, p)
                    known[slot] = 1
                    evals += 1
        out = head  # the oldest slot takes the new point
        for j in range(N):
            if finite:
                for d in range(nq):
                    psi[d] = 0.0
                for jj in range(k):
                    slot = (head + keep - k + jj) % keep
                    if alpha[jj] != 0.0:
                        for d in range(nq):
                            psi[d] = psi[d] - alpha[jj] * X[slot, d, j]
                    if beta[jj] != 0.0:
                        c = h2 * beta[jj]
                        for d in range(nq):
                            psi[d] = psi[d] + c * A[slot, d, j]
                for d in range(nq):
                    X[out, d, j] = psi[d]
            else:
                for d in range(nq):
                    X[out, d, j] = np.nan
        known[out] = 0
        head = (head + 1) % keep
    return evals, head


@njit(**EXACT)
def lmm2_implicit_advance(f_accel, f_jac, alpha, beta, wpred, h2, t0, n0, h, nsteps, X, A, known, head,
                          P, tol, max_iter, stats):
    """Advance the ring `nsteps` implicit steps: `SecondOrderMultistepStepper._step` for an implicit
    table, its operations in its order: psi as the explicit kernel forms it; the predictor
    sum_q wpred_q x_(n+q); per member the matrix I - h^2 beta_k da/dq at the predictor (velocity
    0), factored once (LU with partial pivoting); then simplified Newton iterations on
    x - psi - h^2 beta_k a(x), all members together, until the largest |dx| / (1 + |x|) over
    members and components is at most `tol` or stalls at the rounding level (`newton_converged`).

    Parameters
    ----------
    f_accel, f_jac : addresses of the problem's acceleration a(t, q) and Jacobian (state form, the
        full first-order system's: its block (velocities, positions) is da/dq).
    alpha, beta : the table (k + 1 values each, oldest first); wpred : (k,) predictor weights.
    h2, t0, n0, h, nsteps, X, A, known, head, P : as in `lmm2_explicit_advance`.
    tol : float, the Newton tolerance; max_iter : int, the most iterations.
    stats : (4,) float array, written: accelerations, Jacobians (whole-ensemble calls), the step
        (0-based) whose iteration failed or -1, the last correction there.

    Returns
    -------
    int: the new oldest slot.
    """
    keep, nq, N = X.shape
    dim = 2 * nq
    k = alpha.shape[0] - 1
    npar = P.shape[0]
    x = np.empty(nq)
    a = np.empty(nq)
    p = np.empty(npar)
    psi = np.empty((nq, N))
    Xn = np.empty((nq, N))
    An = np.empty((nq, N))
    Mats = np.empty((N, nq, nq))
    Piv = np.empty((N, nq), dtype=np.int64)
    yfull = np.zeros(dim)
    Jb = np.empty(dim * dim)
    res = np.empty(nq)
    dx = np.empty(nq)
    hb = h2 * beta[k]
    evals = 0
    jacs = 0
    stats[2] = -1.0
    for s in range(nsteps):
        tc = t0 + (n0 + s) * h
        newest = (head + keep - 1) % keep
        out = head
        finite = True
        for j in range(N):
            for d in range(nq):
                if not is_finite(X[newest, d, j]):
                    finite = False
        if not finite:
            for j in range(N):
                for d in range(nq):
                    X[out, d, j] = np.nan
            known[out] = 0
            head = (head + 1) % keep
            continue
        for jj in range(k):
            slot = (head + keep - k + jj) % keep
            if beta[jj] != 0.0 and known[slot] == 0:
                rhs_members(f_accel, tc + (jj - k + 1) * h, X[slot], P, A[slot], x, a, p)
                known[slot] = 1
                evals += 1
        for j in range(N):
            for d in range(nq):
                psi[d, j] = 0.0
            for jj in range(k):
                slot = (head + keep - k + jj) % keep
                if alpha[jj] != 0.0:
                    for d in range(nq):
                        psi[d, j] = psi[d, j] - alpha[jj] * X[slot, d, j]
                if beta[jj] != 0.0:
                    c = h2 * beta[jj]
                    for d in range(nq):
                        psi[d, j] = psi[d, j] + c * A[slot, d, j]
            for d in range(nq):
                acc = 0.0
                for q in range(k):
                    acc = acc + wpred[q] * X[(head + keep - k + q) % keep, d, j]
                Xn[d, j] = acc
        t_new = tc + h
        for j in range(N):
            load_member(Xn, P, j, nq, yfull, p)
            call_state(f_jac, t_new, yfull, p, Jb)
            for r in range(nq):
                for q in range(nq):
                    v = -(hb * Jb[(nq + r) * dim + q])
                    if r == q:
                        v = 1.0 - hb * Jb[(nq + r) * dim + q]
                    Mats[j, r, q] = v
            lu_factor(Mats[j], Piv[j])
        jacs += 1
        correction = np.inf
        previous = np.inf
        theta = np.nan
        done = False
        for _ in range(max_iter):
            rhs_members(f_accel, t_new, Xn, P, An, x, a, p)
            evals += 1
            correction = 0.0
            size = 0.0
            for j in range(N):
                for d in range(nq):
                    res[d] = Xn[d, j] - psi[d, j] - hb * An[d, j]
                lu_apply(Mats[j], Piv[j], res, dx)
                for d in range(nq):
                    xn = Xn[d, j] - dx[d]
                    Xn[d, j] = xn
                    r = abs(dx[d]) / (1.0 + abs(xn))
                    if not (r <= correction):
                        correction = r
                    z = abs(xn) / (1.0 + abs(xn))
                    if z > size:
                        size = z
            if not is_finite(correction):
                break
            # NEWTON_TOL, or stalled at the rounding level: the NumPy loop's `newton_stop`
            done, theta = newton_converged(correction, previous, tol, theta, size)
            if done:
                break
            previous = correction
        if not done:
            stats[0] = evals
            stats[1] = jacs
            stats[2] = s
            stats[3] = correction
            return head
        for j in range(N):
            for d in range(nq):
                X[out, d, j] = Xn[d, j]
        known[out] = 0
        head = (head + 1) % keep
    stats[0] = evals
    stats[1] = jacs
    return head
