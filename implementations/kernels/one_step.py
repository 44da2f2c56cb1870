"""The explicit one-step families' kernels: explicit Runge-Kutta, drift/kick splitting, the
staggered leapfrog, Stormer's two-step rule, a splitting under a step controller, and the column
forms of the first three for ensembles.

One trajectory is the common case of the long runs, so the explicit Runge-Kutta kernel keeps it
in flat rows padded to whole blocks of four values (each block formed in registers, unsigned
offsets, no per-access negative-index handling). A kernel runs each member through all its steps
with the state in registers, calling the problem's function through its address
(`implementations.kernel_calls`).
"""

import numpy as np
from numba import njit

from implementations.kernel_calls import call_columns, call_state, call_state_into
from implementations.kernels.common import CONTRACT, EXACT, INLINE

__all__ = ["rk_advance", "rk_advance_cols", "split_advance", "split_advance_cols", "leapfrog_advance",
           "leapfrog_advance_cols", "stormer_advance", "controlled_advance", "COLUMN_BLOCK"]

# Ensemble forms of the three explicit one-step families: blocks of COLUMN_BLOCK members advance
# together, every update a loop along the members (vectorisable), the right-hand side or force
# evaluated by the problem's column function. Per member the arithmetic is that of the kernels
# of one member, operation for operation.
COLUMN_BLOCK = 256


@njit(**INLINE)
def rk_block(W, e, dst, term, coef, q0, q1):
    """One block of four entries, formed in registers: W[dst + e + i] = W[e + i] + sum_q coef[q]
    W[term[q] + e + i], q from q0 to q1 - 1 added in order.

    Parameters
    ----------
    W : flat work rows; e : unsigned offset of the block; dst : unsigned offset of the target row;
    term, coef : row offsets and coefficients of the nonzero terms; q0, q1 : the terms used.
    """
    U1 = np.uint64(1)
    U2 = np.uint64(2)
    U3 = np.uint64(3)
    a0 = W[e]
    a1 = W[e + U1]
    a2 = W[e + U2]
    a3 = W[e + U3]
    for q in range(q0, q1):
        cq = coef[q]
        o = term[q] + e
        a0 += cq * W[o]
        a1 += cq * W[o + U1]
        a2 += cq * W[o + U2]
        a3 += cq * W[o + U3]
    W[dst + e] = a0
    W[dst + e + U1] = a1
    W[dst + e + U2] = a2
    W[dst + e + U3] = a3


# Explicit Runge-Kutta (Hairer, Norsett & Wanner I, II.1, eq. (1.8)):
# k_i = f(t + c_i h, y + h sum_j a_ij k_j), y <- y + h sum_i b_i k_i; zero coefficients skipped.
@njit(**CONTRACT)
def rk_advance(f_rhs, A, b, c, t0, n0, h, nsteps, Y, P):
    """`nsteps` explicit Runge-Kutta steps of every member, one member at a time.

    W holds rows of w = dim rounded up to whole blocks of four (the padding stays zero): the
    state, the stage argument, then k_0 .. k_(s-1). The nonzero terms of each stage and of the
    update are (coefficient, unsigned row offset); each block of four is formed in registers.

    Parameters
    ----------
    f_rhs : compiled right-hand side; A, b, c : the Butcher tableau; t0 : float, start time;
    n0 : int, steps already taken (step n starts at t0 + (n0 + n) h); h : float, the step;
    nsteps : int; Y : (dim, n) states, advanced in place; P : (n_par, n) parameters.

    Returns
    -------
    int: right-hand-side evaluations per member (s * nsteps).
    """
    s = b.shape[0]
    dim = Y.shape[0]
    npar = P.shape[0]
    w = (dim + 3) // 4 * 4
    nb = w // 4
    hA = A * h
    hb = b * h
    hc = c * h
    start = np.zeros(s + 1, dtype=np.int64)
    term = np.empty(s * s, dtype=np.uint64)
    coef = np.empty(s * s)
    nz = 0
    for i in range(s):
        start[i] = nz
        for m in range(i):
            if hA[i, m] != 0.0:
                term[nz] = (m + 2) * w
                coef[nz] = hA[i, m]
                nz += 1
    start[s] = nz
    wterm = np.empty(s, dtype=np.uint64)
    wcoef = np.empty(s)
    nw = 0
    for m in range(s):
        if hb[m] != 0.0:
            wterm[nw] = (m + 2) * w
            wcoef[nw] = hb[m]
            nw += 1
    W = np.zeros((s + 2) * w)
    p = np.empty(npar)
    uw = np.uint64(w)
    u0 = np.uint64(0)
    for j in range(Y.shape[1]):
        for d in range(dim):
            W[d] = Y[d, j]
        for k in range(npar):
            p[k] = P[k, j]
        for n in range(nsteps):
            t = t0 + (n0 + n) * h
            for i in range(s):
                q0 = start[i]
                q1 = start[i + 1]
                if q0 == q1:  # a stage at y itself (the first): no copy
                    call_state_into(f_rhs, t + hc[i], W, 0, p, W, (i + 2) * w)
                    continue
                for bb in range(nb):
                    rk_block(W, np.uint64(4) * np.uint64(bb), uw, term, coef, q0, q1)
                call_state_into(f_rhs, t + hc[i], W, w, p, W, (i + 2) * w)
            for bb in range(nb):
                rk_block(W, np.uint64(4) * np.uint64(bb), u0, wterm, wcoef, 0, nw)
        for d in range(dim):
            Y[d, j] = W[d]
    return s * nsteps


@njit(**CONTRACT)
def rk_advance_cols(f_rhs_cols, A, b, c, t0, n0, h, nsteps, Y, K, Stage, P):
    """The column form of `rk_advance`: blocks of COLUMN_BLOCK members advance together.

    Parameters
    ----------
    f_rhs_cols : compiled column right-hand side; A, b, c, t0, n0, h, nsteps, Y, P : as in
    `rk_advance`; K : (s, dim, n) stage derivatives and Stage : (dim, n) stage argument, work.

    Returns
    -------
    int: right-hand-side evaluations per member (s * nsteps).
    """
    s = b.shape[0]
    dim, N = Y.shape
    hA = A * h
    hb = b * h
    hc = c * h
    for j0 in range(0, N, COLUMN_BLOCK):
        j1 = min(N, j0 + COLUMN_BLOCK)
        for n in range(nsteps):
            t = t0 + (n0 + n) * h
            for i in range(s):
                for d in range(dim):
                    for j in range(j0, j1):
                        Stage[d, j] = Y[d, j]
                    for m in range(i):
                        coef = hA[i, m]
                        if coef != 0.0:
                            for j in range(j0, j1):
                                Stage[d, j] += coef * K[m, d, j]
                call_columns(f_rhs_cols, t + hc[i], Stage, P, K[i], j0, j1)
            for d in range(dim):
                for m in range(s):
                    coef = hb[m]
                    if coef != 0.0:
                        for j in range(j0, j1):
                            Y[d, j] += coef * K[m, d, j]
    return s * nsteps


# One member of a Newtonian ensemble in working vectors: (q, v) from the rows of Y, its force
# from Acc and its parameters from P, and back after its steps.
@njit(**INLINE)
def take_member(Y, Acc, P, j, q, v, a, p):
    """Copy member j's position, velocity, acceleration and parameters into the work vectors.

    Parameters
    ----------
    Y : (2 nq, n) states (positions over velocities); Acc : (nq, n) accelerations;
    P : (n_par, n) parameters; j : int, the member; q, v, a, p : work vectors (written).
    """
    nq = q.shape[0]
    for d in range(nq):
        q[d] = Y[d, j]
        v[d] = Y[nq + d, j]
        a[d] = Acc[d, j]
    for k in range(p.shape[0]):
        p[k] = P[k, j]


@njit(**INLINE)
def put_member(Y, Acc, j, q, v, a):
    """Copy the work vectors back into member j's columns (the inverse of `take_member`).

    Parameters
    ----------
    Y, Acc : as in `take_member` (written); j : int, the member; q, v, a : the work vectors.
    """
    nq = q.shape[0]
    for d in range(nq):
        Y[d, j] = q[d]
        Y[nq + d, j] = v[d]
        Acc[d, j] = a[d]


# Drift/kick splitting (Hairer, Lubich & Wanner, GNI, II.5): drifts q += a_i h v, kicks
# v += b_i h a(q, t + tau_i h); a scheme that begins and ends with a kick reuses the last force.
@njit(**CONTRACT)
def split_advance(f_accel, kick, hcoef, htau, fsal, valid0, t0, n0, h, nsteps, Y, Acc, P):
    """`nsteps` steps of a drift/kick splitting for every member, one member at a time.

    Parameters
    ----------
    f_accel : compiled acceleration; kick : (nops,) bool, whether operation i is a kick (else a
    drift); hcoef : (nops,) h times each operation's coefficient; htau : (nops,) time offset of
    each kick; fsal : bool, whether the last kick's acceleration serves the next step's first;
    valid0 : bool, whether Acc already holds the acceleration at the start; t0, n0, h, nsteps : as
    in `rk_advance`; Y : (2 nq, n) states and Acc : (nq, n) accelerations, advanced in place;
    P : (n_par, n) parameters.

    Returns
    -------
    int: acceleration evaluations per member.
    """
    nops = kick.shape[0]
    nq = Acc.shape[0]
    q, v, a, p = np.empty(nq), np.empty(nq), np.empty(nq), np.empty(P.shape[0])
    evals = 0
    for j in range(Y.shape[1]):
        take_member(Y, Acc, P, j, q, v, a, p)
        valid = valid0
        e = 0
        for n in range(nsteps):
            t = t0 + (n0 + n) * h
            for i in range(nops):
                if kick[i]:
                    if not (i == 0 and valid):
                        call_state(f_accel, t + htau[i], q, p, a)
                        e += 1
                    for d in range(nq):
                        v[d] += a[d] * hcoef[i]
                else:
                    for d in range(nq):
                        q[d] += v[d] * hcoef[i]
            valid = fsal
        put_member(Y, Acc, j, q, v, a)
        evals = e
    return evals


@njit(**CONTRACT)
def split_advance_cols(f_accel_cols, kick, hcoef, htau, fsal, valid0, t0, n0, h, nsteps, Y, Acc, P):
    """The column form of `split_advance`: blocks of COLUMN_BLOCK members advance together.

    Parameters
    ----------
    f_accel_cols : compiled column acceleration; kick, hcoef, htau, fsal, valid0, t0, n0, h,
    nsteps, Y, Acc, P : as in `split_advance`.

    Returns
    -------
    int: acceleration evaluations per member.
    """
    nops = kick.shape[0]
    nq, N = Acc.shape
    evals = 0
    for j0 in range(0, N, COLUMN_BLOCK):
        j1 = min(N, j0 + COLUMN_BLOCK)
        valid = valid0
        e = 0
        for n in range(nsteps):
            t = t0 + (n0 + n) * h
            for i in range(nops):
                coef = hcoef[i]
                if kick[i]:
                    if not (i == 0 and valid):
                        call_columns(f_accel_cols, t + htau[i], Y, P, Acc, j0, j1)
                        e += 1
                    for d in range(nq):
                        for j in range(j0, j1):
                            Y[nq + d, j] += Acc[d, j] * coef
                else:
                    for d in range(nq):
                        for j in range(j0, j1):
                            Y[d, j] += Y[nq + d, j] * coef
            valid = fsal
        evals = e
    return evals


# Staggered leapfrog: x += d h v_{n+1/2}, v_{n+3/2} = v_{n+1/2} + k h a(x_{n+1}, t_{n+1}).
@njit(**CONTRACT)
def leapfrog_advance(f_accel, hdrift, hkick, t0, n0, h, nsteps, Y, Acc, P):
    """`nsteps` staggered leapfrog steps per member: drift q += v hdrift, then kick v += a(q) hkick.

    Parameters
    ----------
    f_accel : compiled acceleration; hdrift, hkick : float, the drift and kick lengths; t0, n0, h,
    nsteps : as in `rk_advance`; Y : (2 nq, n) states and Acc : (nq, n) accelerations, advanced in
    place; P : (n_par, n) parameters.

    Returns
    -------
    int: acceleration evaluations per member (nsteps).
    """
    nq = Acc.shape[0]
    q, v, a, p = np.empty(nq), np.empty(nq), np.empty(nq), np.empty(P.shape[0])
    for j in range(Y.shape[1]):
        take_member(Y, Acc, P, j, q, v, a, p)
        for n in range(nsteps):
            t = t0 + (n0 + n + 1) * h
            for d in range(nq):
                q[d] += v[d] * hdrift
            call_state(f_accel, t, q, p, a)
            for d in range(nq):
                v[d] += a[d] * hkick
        put_member(Y, Acc, j, q, v, a)
    return nsteps


@njit(**CONTRACT)
def leapfrog_advance_cols(f_accel_cols, hdrift, hkick, t0, n0, h, nsteps, Y, Acc, P):
    """The column form of `leapfrog_advance`: blocks of COLUMN_BLOCK members advance together.

    Parameters
    ----------
    f_accel_cols : compiled column acceleration; hdrift, hkick, t0, n0, h, nsteps, Y, Acc, P : as
    in `leapfrog_advance`.

    Returns
    -------
    int: acceleration evaluations per member (nsteps).
    """
    nq, N = Acc.shape
    for j0 in range(0, N, COLUMN_BLOCK):
        j1 = min(N, j0 + COLUMN_BLOCK)
        for n in range(nsteps):
            t = t0 + (n0 + n + 1) * h
            for d in range(nq):
                for j in range(j0, j1):
                    Y[d, j] += Y[nq + d, j] * hdrift
            call_columns(f_accel_cols, t, Y, P, Acc, j0, j1)
            for d in range(nq):
                for j in range(j0, j1):
                    Y[nq + d, j] += Acc[d, j] * hkick
    return nsteps


# Stormer's two-step form (Hairer, Norsett & Wanner I, III.10):
# x_{n+1} = -alpha_1 x_n - alpha_0 x_{n-1} + h^2 beta_1 a(x_n, t_n). Prev/Cur/Nxt hold
# (x_{n-1}, x_n, x_{n+1}); a step shifts them and forms the new x_{n+1} at t = t_n + h.
@njit(**CONTRACT)
def stormer_advance(f_accel, alpha0, alpha1, b1hh, t0, n0, h, nsteps, Prev, Cur, Nxt, Acc, P):
    """`nsteps` steps of Stormer's two-step rule x_{n+1} = -alpha0 x_{n-1} - alpha1 x_n + b1hh a(x_n).

    Parameters
    ----------
    f_accel : compiled acceleration; alpha0, alpha1 : float, the rule's coefficients; b1hh : float,
    its force coefficient times h^2; t0, n0, h, nsteps : as in `rk_advance`; Prev, Cur, Nxt :
    (nq, n) positions x_{n-1}, x_n, x_{n+1}, shifted in place; Acc : (nq, n) the last acceleration
    (written); P : (n_par, n) parameters.

    Returns
    -------
    int: acceleration evaluations per member (nsteps).
    """
    nq = Cur.shape[0]
    npar = P.shape[0]
    xp = np.empty(nq)
    xc = np.empty(nq)
    xn = np.empty(nq)
    a = np.empty(nq)
    p = np.empty(npar)
    for j in range(Cur.shape[1]):
        for d in range(nq):
            xp[d] = Prev[d, j]
            xc[d] = Cur[d, j]
            xn[d] = Nxt[d, j]
            a[d] = Acc[d, j]
        for k in range(npar):
            p[k] = P[k, j]
        for n in range(nsteps):
            for d in range(nq):
                xp[d] = xc[d]
                xc[d] = xn[d]
            t = (t0 + (n0 + n) * h) + h
            call_state(f_accel, t, xc, p, a)
            for d in range(nq):
                x = xp[d] * (-alpha0)
                x += xc[d] * (-alpha1)
                x += a[d] * b1hh
                xn[d] = x
        for d in range(nq):
            Prev[d, j] = xp[d]
            Cur[d, j] = xc[d]
            Nxt[d, j] = xn[d]
            Acc[d, j] = a[d]
    return nsteps


# A drift/kick splitting under a step controller (`implementations.step_control`): per member a
# physical step hs = h sigma(q, v) (naive) or hs = h / z with z_{n+1/2} = z_{n-1/2} + h G(y_n),
# G = -position_power (q.v) / |q|^2 (reversible; Huang & Leimkuhler 1997; Hairer, Lubich & Wanner,
# GNI, VIII.3.2); sigma = |q|^position_power |L|^momentum_power with |L| frozen at the start for
# the reversible controller. Powers as NumPy evaluates `array ** scalar` (exact fast paths for the
# exponents -1, 0, 1/2, 1, 2). Each member keeps its own clock Time.
@njit(**INLINE)
def numpy_power(x, e):
    """x ** e as NumPy evaluates `array ** scalar`: exact fast paths for e in -1, 0, 1/2, 1, 2.

    Parameters
    ----------
    x : float, the base; e : float, the exponent.

    Returns
    -------
    float: x to the power e.
    """
    if e == 1.0:
        return x
    if e == -1.0:
        return 1.0 / x
    if e == 2.0:
        return x * x
    if e == 0.5:
        return np.sqrt(x)
    if e == 0.0:
        return 1.0
    return x ** e


@njit(**EXACT)
def controlled_advance(f_accel, kick, coef, fsal, valid0, reversible, pos_power, mom_power, t0, h,
                       nsteps, Y, Acc, Time, Z, P):
    """`nsteps` controlled steps of a drift/kick splitting per member (see the comment above).

    Parameters
    ----------
    f_accel : compiled acceleration; kick : (nops,) bool, kick or drift; coef : (nops,) the
    operations' coefficients; fsal, valid0 : as in `split_advance`; reversible : bool, the
    reversible controller (else the naive one); pos_power, mom_power : float, the powers of |q| and
    |L| in sigma; t0 : float, the time passed to the acceleration; h : float, the fictive step;
    nsteps : int; Y, Acc : as in `split_advance`; Time : (n,) each member's clock and Z : (n,) the
    controller's z, advanced in place; P : (n_par, n) parameters.

    Returns
    -------
    int: acceleration evaluations of the last member.
    """
    nops = kick.shape[0]
    nq = Acc.shape[0]
    q, v, a, p = np.empty(nq), np.empty(nq), np.empty(nq), np.empty(P.shape[0])
    half = 0.5 * pos_power
    evals = 0
    for j in range(Y.shape[1]):
        take_member(Y, Acc, P, j, q, v, a, p)
        time = Time[j]
        z = Z[j]
        valid = valid0
        e = 0
        for _n in range(nsteps):
            if reversible:
                hs = h / z if z > 0.0 else np.inf
            else:
                r2 = 0.0
                qv = 0.0
                v2 = 0.0
                for d in range(nq):
                    r2 += q[d] * q[d]
                    qv += q[d] * v[d]
                    v2 += v[d] * v[d]
                L = np.sqrt(max(r2 * v2 - qv * qv, 0.0))
                hs = h * (numpy_power(r2, half) * numpy_power(L, mom_power))
            for i in range(nops):
                ch = coef[i] * hs
                if kick[i]:
                    if not (i == 0 and valid):
                        call_state(f_accel, t0, q, p, a)
                        e += 1
                    for d in range(nq):
                        v[d] += ch * a[d]
                else:
                    for d in range(nq):
                        q[d] += ch * v[d]
            valid = fsal
            time += hs
            if reversible:
                r2 = 0.0
                qv = 0.0
                for d in range(nq):
                    r2 += q[d] * q[d]
                    qv += q[d] * v[d]
                z += h * ((-pos_power) * qv / r2)
        put_member(Y, Acc, j, q, v, a)
        Time[j] = time
        Z[j] = z
        evals = e
    return evals
