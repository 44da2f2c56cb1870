"""Kernel of explicit second-order multistep tables (Stormer, the symmetric Quinlan-Tremaine
methods), run by `implementations.second_order_multistep_compiled`.

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

from implementations.kernels.common import EXACT, rhs_members

__all__ = ["lmm2_explicit_advance"]


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
                if not abs(X[newest, d, j]) <= 1.7976931348623157e308:
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
