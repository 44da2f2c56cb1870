"""The linear multistep kernels (y' = f): explicit, one member or the ensemble in lockstep, and
implicit by Newton's method with the problem's Jacobian.

The history is a ring of k states and derivatives per member; which derivatives are known is
kept as bits (`fvalid`), so a derivative is evaluated once, when a beta first needs it. The
ensemble kernels sweep all members per step ("lockstep"): a non-finite state stops every member,
as in the NumPy loop, and Newton's convergence is a maximum over members.
"""

import numpy as np
from numba import njit

from implementations.kernel_calls import call_state, call_state_into
from implementations.kernels.common import (
    EXACT,
    INLINE,
    is_finite,
    load_member,
    newton_members_step,
    newton_start,
    newton_stats,
    rhs_members,
)

__all__ = ["lmm_explicit_single", "lmm_explicit_advance", "lmm_implicit_advance"]


@njit(**INLINE)
def lmm_terms(alpha, beta, h, k, alpha_sign, beta_kind):
    """The explicit formula's nonzero terms over j < k, in the NumPy loop's order (j ascending, alpha
    before beta).

    Parameters
    ----------
    alpha, beta : (k + 1,) the method's coefficients; h : float, the step; k : int, the number of
    steps; alpha_sign : float, the sign put on alpha terms (exact); beta_kind : int, the kind given
    to beta terms.

    Returns
    -------
    tuple: (kind, index j, coefficient, count); an alpha term has kind 0 and coefficient
    alpha_sign * alpha_j, a beta term kind `beta_kind` and coefficient h beta_j.
    """
    kind = np.empty(2 * k, dtype=np.int64)
    index = np.empty(2 * k, dtype=np.int64)
    coef = np.empty(2 * k)
    nt = 0
    for jj in range(k):
        if alpha[jj] != 0.0:
            kind[nt] = 0
            index[nt] = jj
            coef[nt] = alpha_sign * alpha[jj]
            nt += 1
        if beta[jj] != 0.0:
            kind[nt] = beta_kind
            index[nt] = jj
            coef[nt] = h * beta[jj]
            nt += 1
    return kind, index, coef, nt


@njit(**INLINE)
def lmm_history_f(f_rhs, beta, t, h, H, F, fvalid, P, slots, y, out, p):
    """f at the history points that a nonzero beta needs and whose f is not known yet (index jj at
    time t - (k - 1 - jj) h, in ring slot slots[jj]).

    Parameters
    ----------
    f_rhs : compiled right-hand side; beta : the beta coefficients; t : float, the newest history
    time; h : float, the step; H, F : (k, dim, n) ring of states and derivatives (F written);
    fvalid : (k,) bool, which slots of F are known (updated); P : parameters; slots : (k,) ring
    slot of each history index; y, out, p : work vectors.

    Returns
    -------
    int: the number of ensemble evaluations made.
    """
    k = H.shape[0]
    evals = 0
    for jj in range(k):
        slot = slots[jj]
        if beta[jj] != 0.0 and not fvalid[slot]:
            rhs_members(f_rhs, t - (k - 1 - jj) * h, H[slot], P, F[slot], y, out, p)
            fvalid[slot] = True
            evals += 1
    return evals


# Linear multistep, shared part: f at the history points a beta needs (each evaluated once, when
# first needed) and psi = -sum_j alpha_j y_{n+j} + h sum_j beta_j f_{n+j} over j < k.
@njit(**INLINE)
def lmm_psi(f_rhs, alpha, beta, t, h, H, F, fvalid, head, P, psi, y, out, p, slots):
    """psi = sum over j < k of (-alpha_j y_j + h beta_j f_j), the known part of the step's equation;
    history index jj (0 = oldest) lives in ring slot (head + jj) % k.

    Parameters
    ----------
    f_rhs, alpha, beta, t, h, H, F, fvalid, P, y, out, p : as in `lmm_history_f`; head : int, the
    ring slot of the oldest state; psi : (dim, n) written; slots : (k,) work, filled with the slots.

    Returns
    -------
    int: the number of ensemble evaluations made.
    """
    k, dim, N = H.shape
    for jj in range(k):
        slot = head + jj
        slots[jj] = slot - k if slot >= k else slot
    evals = lmm_history_f(f_rhs, beta, t, h, H, F, fvalid, P, slots, y, out, p)
    for m in range(N):
        for d in range(dim):
            acc = 0.0
            for jj in range(k):
                slot = slots[jj]
                if alpha[jj] != 0.0:
                    acc -= alpha[jj] * H[slot, d, m]
                if beta[jj] != 0.0:
                    acc += (h * beta[jj]) * F[slot, d, m]
            psi[d, m] = acc
    return evals


@njit(**INLINE)
def lmm_finite(H, slot):
    """Whether every entry of the ring slot is finite.

    Parameters
    ----------
    H : (k, dim, n) the state ring; slot : int, the slot tested.

    Returns
    -------
    bool: False when any entry is inf or NaN.
    """
    k, dim, N = H.shape
    for d in range(dim):
        for m in range(N):
            if not is_finite(H[slot, d, m]):
                return False
    return True


@njit(**INLINE)
def lmm_blow_up(H, fvalid, slot):
    """Mark a slot as blown up: its states NaN for every member, its derivative unknown.

    Parameters
    ----------
    H : (k, dim, n) the state ring; fvalid : (k,) known-derivative flags; slot : int, the slot.
    """
    k, dim, N = H.shape
    for d in range(dim):
        for m in range(N):
            H[slot, d, m] = np.nan
    fvalid[slot] = False


@njit(**EXACT)
def lmm_unroll(H, F, fvalid, head):
    """Put the ring back in history order, oldest first, in place (element loops: an array-slice
    assignment compiles to ~5 s of broadcasting code).

    Parameters
    ----------
    H, F : (k, dim, n) the state and derivative rings; fvalid : (k,) known-derivative flags;
    head : int, the ring slot of the oldest entry.
    """
    k, dim, N = H.shape
    if head == 0:
        return
    Hc = H.copy()
    Fc = F.copy()
    vc = fvalid.copy()
    for jj in range(k):
        slot = (head + jj) % k
        for d in range(dim):
            for m in range(N):
                H[jj, d, m] = Hc[slot, d, m]
                F[jj, d, m] = Fc[slot, d, m]
        fvalid[jj] = vc[slot]


# Explicit linear multistep (Hairer, Norsett & Wanner I, III.2): y_{n+k} = psi. A non-finite
# newest state makes every member NaN with no further evaluation, as in the NumPy loop. The
# history is a ring of k slots: a step writes one slot instead of shifting k.
@njit(**EXACT)
def lmm_explicit_single(f_rhs, alpha, beta, t0, n0, h, nsteps, H, F, fvalid, P):
    """`nsteps` explicit multistep steps of one member.

    The history ring lies flat in W in rows of w = dim rounded up to whole blocks of four (the
    padding stays zero): states in rows 0..k-1, derivatives in rows k..2k-1. The formula's terms
    are (signed coefficient, row) in the NumPy loop's order, their rows tabulated once for each
    position of the ring; offsets are unsigned. Which derivatives are known is a bit mask over the
    ring (k <= 62).

    Parameters
    ----------
    f_rhs : compiled right-hand side; alpha, beta : the method's coefficients; t0 : float, start
    time; n0 : int, steps already taken; h : float, the step; nsteps : int; H, F : (k, dim, 1)
    history of states and derivatives, oldest first, advanced in place; fvalid : (k,) bool, which
    derivatives are known (updated); P : (n_par, 1) parameters.

    Returns
    -------
    int: right-hand-side evaluations.
    """
    k, dim, N = H.shape
    w = (dim + 3) // 4 * 4
    nb = w // 4
    W = np.zeros(2 * k * w)
    for sl in range(k):
        for d in range(dim):
            W[sl * w + d] = H[sl, d, 0]
            W[(k + sl) * w + d] = F[sl, d, 0]
    p = np.empty(P.shape[0])
    for q in range(P.shape[0]):
        p[q] = P[q, 0]
    tkind, tindex, tcoef, nt = lmm_terms(alpha, beta, h, k, -1.0, k)
    off = np.empty(k * nt, dtype=np.uint64)
    for ph in range(k):
        for q in range(nt):
            off[ph * nt + q] = (tkind[q] + (ph + tindex[q]) % k) * w
    # per position of the ring: the slots whose derivative the formula needs
    need = np.zeros(k, dtype=np.int64)
    for ph in range(k):
        for jj in range(k):
            if beta[jj] != 0.0:
                need[ph] |= 1 << ((ph + jj) % k)
    have = 0
    for sl in range(k):
        if fvalid[sl]:
            have |= 1 << sl
    U1 = np.uint64(1)
    U2 = np.uint64(2)
    U3 = np.uint64(3)
    evals = 0
    head = 0
    # whether the newest state is finite: tested here, then on each new state as it is formed
    # (0 * x is 0 for finite x, NaN for inf or NaN)
    finite = True
    for d in range(dim):
        finite &= is_finite(W[(k - 1) * w + d])
    for n in range(nsteps):
        oldest = head
        newest = oldest + k - 1 if oldest > 0 else k - 1
        head = head + 1 if head + 1 < k else 0
        if not finite:
            for d in range(dim):
                W[oldest * w + d] = np.nan
            have &= ~(1 << oldest)
            continue
        t = t0 + (n0 + n) * h
        missing = need[oldest] & ~have
        if missing == 1 << newest:  # the usual step: only the newest state's derivative
            call_state_into(f_rhs, t, W, newest * w, p, W, (k + newest) * w)
            evals += 1
            have |= missing
        elif missing != 0:
            for jj in range(k):
                sl = oldest + jj
                if sl >= k:
                    sl -= k
                if missing & (1 << sl):
                    call_state_into(f_rhs, t - (k - 1 - jj) * h, W, sl * w, p, W, (k + sl) * w)
                    evals += 1
            have |= missing
        dst = np.uint64(oldest * w)
        row = np.uint64(oldest * nt)
        zero = 0.0
        for bb in range(nb):
            e = np.uint64(4) * np.uint64(bb)
            a0 = 0.0
            a1 = 0.0
            a2 = 0.0
            a3 = 0.0
            for q in range(nt):
                cq = tcoef[q]
                o = off[row + np.uint64(q)] + e
                a0 += cq * W[o]
                a1 += cq * W[o + U1]
                a2 += cq * W[o + U2]
                a3 += cq * W[o + U3]
            zero += (a0 * 0.0 + a1 * 0.0) + (a2 * 0.0 + a3 * 0.0)
            W[dst + e] = a0
            W[dst + e + U1] = a1
            W[dst + e + U2] = a2
            W[dst + e + U3] = a3
        have &= ~(1 << oldest)
        finite = zero == 0.0
    for jj in range(k):
        sl = (head + jj) % k
        for d in range(dim):
            H[jj, d, 0] = W[sl * w + d]
            F[jj, d, 0] = W[(k + sl) * w + d]
        fvalid[jj] = (have >> sl) & 1 != 0
    return evals


@njit(**EXACT)
def lmm_explicit_advance(f_rhs, alpha, beta, t0, n0, h, nsteps, H, F, fvalid, P):
    """`nsteps` explicit multistep steps of every member in lockstep (`lmm_explicit_single` for one).

    Parameters
    ----------
    f_rhs, alpha, beta, t0, n0, h, nsteps, H, F, fvalid, P : as in `lmm_explicit_single`, with n
    members.

    Returns
    -------
    int: ensemble right-hand-side evaluations.
    """
    k, dim, N = H.shape
    if N == 1:
        return lmm_explicit_single(f_rhs, alpha, beta, t0, n0, h, nsteps, H, F, fvalid, P)
    npar = P.shape[0]
    y = np.empty(dim)
    out = np.empty(dim)
    p = np.empty(npar)
    slots = np.empty(k, dtype=np.int64)
    # kind 0 is -alpha_j y_j (subtracted with coefficient alpha_j), kind 1 is + h beta_j f_j
    kind, index, coef, nt = lmm_terms(alpha, beta, h, k, 1.0, 1)
    evals = 0
    head = 0
    for n in range(nsteps):
        t = t0 + (n0 + n) * h
        for jj in range(k):
            sl = head + jj
            slots[jj] = sl - k if sl >= k else sl
        newest = slots[k - 1]
        finite = True
        for d in range(dim):
            for m in range(N):
                if not is_finite(H[newest, d, m]):
                    finite = False
        head = head + 1 if head + 1 < k else 0
        slot = slots[0]  # the oldest slot takes the new state
        if not finite:
            for d in range(dim):
                for m in range(N):
                    H[slot, d, m] = np.nan
            fvalid[slot] = False
            continue
        evals += lmm_history_f(f_rhs, beta, t, h, H, F, fvalid, P, slots, y, out, p)
        for m in range(N):
            for d in range(dim):
                acc = 0.0
                for q in range(nt):
                    sl = slots[index[q]]
                    if kind[q] == 0:
                        acc -= coef[q] * H[sl, d, m]
                    else:
                        acc += coef[q] * F[sl, d, m]
                H[slot, d, m] = acc
        fvalid[slot] = False
    lmm_unroll(H, F, fvalid, head)
    return evals


# Implicit linear multistep: y_{n+k} - h beta_k f(t_{n+k}, y_{n+k}) = psi by Newton's method from
# the polynomial extrapolation of the history; f at the new point recovered as (y - psi) / h beta_k.
@njit(**EXACT)
def lmm_implicit_advance(f_rhs, f_jac, alpha, beta, wpred, full, tol, max_iter, t0, n0, h, nsteps, H, F,
                         fvalid, P, stats):
    """`nsteps` implicit multistep steps of every member in lockstep, each solved by Newton's method
    from an extrapolated predictor.

    Parameters
    ----------
    f_rhs : compiled right-hand side; f_jac : compiled Jacobian; alpha, beta : the method's
    coefficients; wpred : (k,) predictor weights over the history; full : bool, a new Jacobian at
    every iteration (else once per step); tol : float, the Newton tolerance; max_iter : int;
    t0, n0, h, nsteps, H, F, fvalid, P : as in `lmm_explicit_advance`; stats : (9,) float array,
    the counts on success (status 0) or the failure record of `newton_stats`.
    """
    k, dim, N = H.shape
    npar = P.shape[0]
    psi = np.empty((dim, N))
    X = np.empty((dim, N))
    G = np.empty((dim, N))
    DX = np.empty((dim, N))
    Mats = np.empty((N, dim, dim))
    Piv = np.empty((N, dim), dtype=np.int64)
    inv_scale = np.empty((dim, N))
    y = np.empty(dim)
    out = np.empty(dim)
    Jb = np.empty(dim * dim)
    rhs_w = np.empty(dim)
    sol = np.empty(dim)
    p = np.empty(npar)
    hb = h * beta[k]
    slots = np.empty(k, dtype=np.int64)
    n_rhs = 0
    n_jac = 0
    n_iter = 0
    head = 0
    for n in range(nsteps):
        t = t0 + (n0 + n) * h
        newest = (head + k - 1) % k
        if not lmm_finite(H, newest):
            head = (head + 1) % k
            lmm_blow_up(H, fvalid, (head + k - 1) % k)
            continue
        n_rhs += lmm_psi(f_rhs, alpha, beta, t, h, H, F, fvalid, head, P, psi, y, out, p, slots)
        t_new = t + h
        for d in range(dim):
            for j in range(N):
                inv_scale[d, j] = 1.0 / (1.0 + abs(H[newest, d, j]))
                acc = 0.0
                for q in range(k):
                    acc += wpred[q] * H[slots[q], d, j]
                X[d, j] = acc
        previous, norm, theta, res_norm, converged, status = newton_start()
        it = 0
        for it in range(1, max_iter + 1):
            res_norm = 0.0
            for j in range(N):
                load_member(X, P, j, dim, y, p)
                call_state(f_rhs, t_new, y, p, out)
                for d in range(dim):
                    g = X[d, j] - psi[d, j] - hb * out[d]
                    G[d, j] = g
                    r = abs(g * inv_scale[d, j])
                    if not (r <= res_norm):
                        res_norm = r
            n_rhs += 1
            if it == 1 or full:
                for j in range(N):
                    for q in range(npar):
                        p[q] = P[q, j]
                    if full:
                        for d in range(dim):
                            y[d] = X[d, j]
                        call_state(f_jac, t_new, y, p, Jb)
                    else:
                        for d in range(dim):
                            y[d] = H[newest, d, j]
                        call_state(f_jac, t, y, p, Jb)
                    for a in range(dim):
                        for bb in range(dim):
                            v = -hb * Jb[a * dim + bb]
                            if a == bb:
                                v += 1.0
                            Mats[j, a, bb] = v
                n_jac += 1
            n_iter += 1
            norm, converged, theta, status = newton_members_step(
                it == 1 or full, Mats, Piv, G, DX, rhs_w, sol, X, inv_scale, norm, previous, tol, theta)
            if converged or status == 2 or norm != norm:
                break
            previous = norm
        if not converged:
            newton_stats(stats, n, n_rhs, n_jac, n_iter, it, norm, res_norm, theta, status)
            lmm_unroll(H, F, fvalid, head)
            return
        head = (head + 1) % k
        slot = (head + k - 1) % k
        for d in range(dim):
            for j in range(N):
                H[slot, d, j] = X[d, j]
                F[slot, d, j] = (X[d, j] - psi[d, j]) / hb
        fvalid[slot] = True
    lmm_unroll(H, F, fvalid, head)
    stats[0] = nsteps
    stats[1] = n_rhs
    stats[2] = n_jac
    stats[3] = n_iter
    stats[8] = 0
