"""Generated numba code for the compiled implementation: one step loop per family, fed the
method's coefficients as arrays and the problem's functions as addresses, compiled once.

Two kinds of generated module (Lam, Pitrou & Seibert, *Numba: a LLVM-based Python JIT compiler*,
LLVM-HPC 2015, for the compiler):
- the family module, the same for every problem and method: the kernels of explicit Runge-Kutta,
  splitting, the staggered leapfrog, Stormer's two-step rule, explicit and implicit linear
  multistep, implicit Runge-Kutta (Newton), splittings under a step controller, and column forms
  of the explicit one-step families for ensembles. A kernel reads its method from arrays (A, b,
  c; the drift/kick sequence; alpha, beta) and calls the problem's functions through their
  addresses (`call_state`, `call_state_into`, `call_columns`: an indirect call, as a C loop
  through a function pointer). So a cold run
  compiles each family kernel once, whatever the problems and methods, and later processes load
  them from numba's disk cache.
- per problem, nothing is generated: its functions are heyoka's own compiled code, called through
  the addresses `implementations.native_functions` gives (`rhs`, its strided form `rhs_cols`,
  for Newtonian problems whose acceleration ignores the velocity `accel` and `accel_cols`, and
  the row-major Jacobian `jac` for the Newton-solved families). heyoka has already compiled them
  for the NumPy steppers (or loads them from its disk cache), so the compiled and NumPy
  implementations evaluate every right-hand side with the same machine code, and a cold run
  compiles no per-problem code of its own.

Caching: the family module's text is written once to `harness.cache.code_dir() / "numba"`, named by a
hash of its text, and imported under a name derived from that hash; every function has
`cache=True`. A compile holds a file lock (`_compile_lock`), so processes started together compile
each kernel once and the others load it. `COMPILE_LOG` records, per process, what was compiled or
loaded and how long it took (wall and CPU seconds).

One trajectory is the common case of the long runs, so the explicit Runge-Kutta and explicit
multistep kernels keep it in flat rows padded to whole blocks of four values (each block formed
in registers, unsigned offsets, no per-access negative-index handling), and a one-stage implicit
Runge-Kutta method runs one member by `irk_single`: the same operations as the ensemble loops, in
the same order, without their per-member views and member loops.

Floating-point rules: operations in the NumPy loops' order; in the functions and the explicit
one-step and Stormer kernels a*b + c may become one fused multiply-add (as in heyoka's compiled
functions and the BLAS axpy updates of the NumPy loops); the multistep and implicit kernels,
whose NumPy loops are plain array expressions, contract nothing; no other fast-math licence;
`error_model="numpy"` (a division by zero gives inf/NaN as in NumPy, and no check blocks
vectorisation).
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from types import ModuleType
from typing import Any

from harness import cache
from harness.errors import InputError
from harness.problem import Problem
from implementations.native_functions import (
    NativeFunction,
    UnsupportedExpression,
    function_address,
    native_function,
)

__all__ = [
    "UnsupportedExpression",
    "family_source",
    "problem_functions",
    "family_module",
    "address",
    "call_kernel",
    "KERNELS",
    "TEMPLATES",
    "COMPILE_LOG",
    "COLUMN_BLOCK",
    "PARTS",
]

# -- kernels: one per family, coefficients as arrays ----------------------------------------------
# `f_rhs`, `f_accel` and `f_jac` are the addresses of the problem's functions. Kernels that
# judge the whole ensemble at once (a non-finite state stops every member in the NumPy multistep
# loop; Newton's convergence is a max over members) sweep all members per step ("lockstep");
# the others run each member through all its steps with the state in registers.
_JIT = '@njit(cache=True, error_model="numpy", fastmath={"contract"})'
# The multistep and implicit Runge-Kutta loops of the NumPy implementation are plain array
# expressions (one rounding per operation, no BLAS): their kernels contract nothing either.
_JIT_EXACT = '@njit(cache=True, error_model="numpy")'
# Helpers called once per step or per member are inlined into the kernels (numba's IR inlining):
# a call between compiled functions passes each array with its reference counts.
_JIT_INLINE = '@njit(cache=True, error_model="numpy", inline="always")'
# The ensemble Newton steps (factor, solve, update over all members) are called once per
# iteration whatever the ensemble size, the convergence test and the failure record take scalars
# only: compiled once and called, not inlined into each kernel.
_JIT_CALLED = '@njit(cache=True, error_model="numpy")'

_HELPERS = f'''
{_JIT_INLINE}
def is_finite(x):
    # np.isfinite on a scalar: the same test, without the per-element library call it compiles to
    return abs(x) <= 1.7976931348623157e308


{_JIT_INLINE}
def rhs_all(f_rhs, t, Y, P, Out):
    dim = Y.shape[0]
    y = np.empty(dim)
    out = np.empty(dim)
    p = np.empty(P.shape[0])
    for j in range(Y.shape[1]):
        for d in range(dim):
            y[d] = Y[d, j]
        for k in range(P.shape[0]):
            p[k] = P[k, j]
        call_state(f_rhs, t, y, p, out)
        for d in range(dim):
            Out[d, j] = out[d]
'''

_ACCEL_HELPER = f'''
{_JIT}
def accel_all(f_accel, t, Q, P, Out):
    # the acceleration of every member: the same member loop as the right-hand side's
    rhs_all(f_accel, t, Q, P, Out)
'''

# Explicit Runge-Kutta (Hairer, Norsett & Wanner I, II.1, eq. (1.8)):
# k_i = f(t + c_i h, y + h sum_j a_ij k_j), y <- y + h sum_i b_i k_i; zero coefficients skipped.
RK = f'''
{_JIT}
def rk_advance(f_rhs, A, b, c, t0, n0, h, nsteps, Y, P):
    # One member at a time. W holds rows of w = dim rounded up to whole blocks of four (the
    # padding stays zero): the state, the stage argument, then k_0 .. k_(s-1). The nonzero terms
    # of each stage (start[i] .. start[i + 1]) and of the update are (coefficient, row offset);
    # offsets are unsigned (no negative-index handling per access) and each block of four
    # entries is formed in registers, the terms added in order.
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
    U1 = np.uint64(1)
    U2 = np.uint64(2)
    U3 = np.uint64(3)
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
                    e = np.uint64(4) * np.uint64(bb)
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
                    W[uw + e] = a0
                    W[uw + e + U1] = a1
                    W[uw + e + U2] = a2
                    W[uw + e + U3] = a3
                call_state_into(f_rhs, t + hc[i], W, w, p, W, (i + 2) * w)
            for bb in range(nb):
                e = np.uint64(4) * np.uint64(bb)
                a0 = W[e]
                a1 = W[e + U1]
                a2 = W[e + U2]
                a3 = W[e + U3]
                for q in range(nw):
                    cq = wcoef[q]
                    o = wterm[q] + e
                    a0 += cq * W[o]
                    a1 += cq * W[o + U1]
                    a2 += cq * W[o + U2]
                    a3 += cq * W[o + U3]
                W[e] = a0
                W[e + U1] = a1
                W[e + U2] = a2
                W[e + U3] = a3
        for d in range(dim):
            Y[d, j] = W[d]
    return s * nsteps
'''

# Drift/kick splitting (Hairer, Lubich & Wanner, GNI, II.5): drifts q += a_i h v, kicks
# v += b_i h a(q, t + tau_i h); a scheme that begins and ends with a kick reuses the last force.
SPLITTING = f'''
{_JIT}
def split_advance(f_accel, kick, hcoef, htau, fsal, valid0, t0, n0, h, nsteps, Y, Acc, P):
    nops = kick.shape[0]
    nq = Acc.shape[0]
    npar = P.shape[0]
    q = np.empty(nq)
    v = np.empty(nq)
    a = np.empty(nq)
    p = np.empty(npar)
    evals = 0
    for j in range(Y.shape[1]):
        for d in range(nq):
            q[d] = Y[d, j]
            v[d] = Y[nq + d, j]
            a[d] = Acc[d, j]
        for k in range(npar):
            p[k] = P[k, j]
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
        for d in range(nq):
            Y[d, j] = q[d]
            Y[nq + d, j] = v[d]
            Acc[d, j] = a[d]
        evals = e
    return evals
'''

# A drift/kick splitting under a step controller (`implementations.step_control`): per member a
# physical step hs = h sigma(q, v) (naive) or hs = h / z with z_{n+1/2} = z_{n-1/2} + h G(y_n),
# G = -position_power (q.v) / |q|^2 (reversible; Huang & Leimkuhler 1997; Hairer, Lubich & Wanner,
# GNI, VIII.3.2); sigma = |q|^position_power |L|^momentum_power with |L| frozen at the start for
# the reversible controller. Powers as NumPy evaluates `array ** scalar` (exact fast paths for the
# exponents -1, 0, 1/2, 1, 2). Each member keeps its own clock Time.
CONTROLLED = f'''
{_JIT_INLINE}
def numpy_power(x, e):
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


{_JIT_EXACT}
def controlled_advance(f_accel, kick, coef, fsal, valid0, reversible, pos_power, mom_power, t0, h,
                       nsteps, Y, Acc, Time, Z, P):
    nops = kick.shape[0]
    nq = Acc.shape[0]
    npar = P.shape[0]
    q = np.empty(nq)
    v = np.empty(nq)
    a = np.empty(nq)
    p = np.empty(npar)
    half = 0.5 * pos_power
    evals = 0
    for j in range(Y.shape[1]):
        for d in range(nq):
            q[d] = Y[d, j]
            v[d] = Y[nq + d, j]
            a[d] = Acc[d, j]
        for k in range(npar):
            p[k] = P[k, j]
        time = Time[j]
        z = Z[j]
        valid = valid0
        e = 0
        for n in range(nsteps):
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
        for d in range(nq):
            Y[d, j] = q[d]
            Y[nq + d, j] = v[d]
            Acc[d, j] = a[d]
        Time[j] = time
        Z[j] = z
        evals = e
    return evals
'''


# Staggered leapfrog: x += d h v_{n+1/2}, v_{n+3/2} = v_{n+1/2} + k h a(x_{n+1}, t_{n+1}).
LEAPFROG = f'''
{_JIT}
def leapfrog_advance(f_accel, hdrift, hkick, t0, n0, h, nsteps, Y, Acc, P):
    nq = Acc.shape[0]
    npar = P.shape[0]
    q = np.empty(nq)
    v = np.empty(nq)
    a = np.empty(nq)
    p = np.empty(npar)
    for j in range(Y.shape[1]):
        for d in range(nq):
            q[d] = Y[d, j]
            v[d] = Y[nq + d, j]
            a[d] = Acc[d, j]
        for k in range(npar):
            p[k] = P[k, j]
        for n in range(nsteps):
            t = t0 + (n0 + n + 1) * h
            for d in range(nq):
                q[d] += v[d] * hdrift
            call_state(f_accel, t, q, p, a)
            for d in range(nq):
                v[d] += a[d] * hkick
        for d in range(nq):
            Y[d, j] = q[d]
            Y[nq + d, j] = v[d]
            Acc[d, j] = a[d]
    return nsteps
'''

# Ensemble forms of the three explicit one-step families: blocks of COLUMN_BLOCK members advance
# together, every update a loop along the members (vectorisable), the right-hand side or force
# evaluated by the generated column function. Per member the arithmetic is that of the kernels
# above, operation for operation.
COLUMN_BLOCK = 256

RK_COLUMNS = f'''
{_JIT}
def rk_advance_cols(f_rhs_cols, A, b, c, t0, n0, h, nsteps, Y, K, Stage, P):
    s = b.shape[0]
    dim, N = Y.shape
    hA = A * h
    hb = b * h
    hc = c * h
    for j0 in range(0, N, {COLUMN_BLOCK}):
        j1 = min(N, j0 + {COLUMN_BLOCK})
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
'''

SPLITTING_COLUMNS = f'''
{_JIT}
def split_advance_cols(f_accel_cols, kick, hcoef, htau, fsal, valid0, t0, n0, h, nsteps, Y, Acc, P):
    nops = kick.shape[0]
    nq, N = Acc.shape
    evals = 0
    for j0 in range(0, N, {COLUMN_BLOCK}):
        j1 = min(N, j0 + {COLUMN_BLOCK})
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
'''

LEAPFROG_COLUMNS = f'''
{_JIT}
def leapfrog_advance_cols(f_accel_cols, hdrift, hkick, t0, n0, h, nsteps, Y, Acc, P):
    nq, N = Acc.shape
    for j0 in range(0, N, {COLUMN_BLOCK}):
        j1 = min(N, j0 + {COLUMN_BLOCK})
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
'''

# Stormer's two-step form (Hairer, Norsett & Wanner I, III.10):
# x_{n+1} = -alpha_1 x_n - alpha_0 x_{n-1} + h^2 beta_1 a(x_n, t_n). Prev/Cur/Nxt hold
# (x_{n-1}, x_n, x_{n+1}); a step shifts them and forms the new x_{n+1} at t = t_n + h.
STORMER = f'''
{_JIT}
def stormer_advance(f_accel, alpha0, alpha1, b1hh, t0, n0, h, nsteps, Prev, Cur, Nxt, Acc, P):
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
'''

# Linear multistep, shared part: f at the history points a beta needs (each evaluated once, when
# first needed) and psi = -sum_j alpha_j y_{n+j} + h sum_j beta_j f_{n+j} over j < k.
_LMM_PSI = f'''
{_JIT_INLINE}
def lmm_psi(f_rhs, alpha, beta, t, h, H, F, fvalid, head, P, psi, y, out, p, slots):
    # history index jj (0 = oldest) lives in ring slot (head + jj) % k
    k, dim, N = H.shape
    for jj in range(k):
        slot = head + jj
        slots[jj] = slot - k if slot >= k else slot
    evals = 0
    for jj in range(k):
        slot = slots[jj]
        if beta[jj] != 0.0 and not fvalid[slot]:
            tj = t - (k - 1 - jj) * h
            for m in range(N):
                for d in range(dim):
                    y[d] = H[slot, d, m]
                for q in range(P.shape[0]):
                    p[q] = P[q, m]
                call_state(f_rhs, tj, y, p, out)
                for d in range(dim):
                    F[slot, d, m] = out[d]
            fvalid[slot] = True
            evals += 1
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


{_JIT_INLINE}
def lmm_finite(H, slot):
    k, dim, N = H.shape
    for d in range(dim):
        for m in range(N):
            if not is_finite(H[slot, d, m]):
                return False
    return True


{_JIT_INLINE}
def lmm_blow_up(H, fvalid, slot):
    k, dim, N = H.shape
    for d in range(dim):
        for m in range(N):
            H[slot, d, m] = np.nan
    fvalid[slot] = False


{_JIT_EXACT}
def lmm_unroll(H, F, fvalid, head):
    # the ring back in history order, oldest first
    # (element loops: an array-slice assignment compiles to ~5 s of broadcasting code)
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
'''

# Explicit linear multistep (Hairer, Norsett & Wanner I, III.2): y_{n+k} = psi. A non-finite
# newest state makes every member NaN with no further evaluation, as in the NumPy loop. The
# history is a ring of k slots: a step writes one slot instead of shifting k.
LMM_EXPLICIT = f'''
{_JIT_EXACT}
def lmm_explicit_single(f_rhs, alpha, beta, t0, n0, h, nsteps, H, F, fvalid, P):
    # One member. The history ring lies flat in W in rows of w = dim rounded up to whole blocks
    # of four (the padding stays zero): states in rows 0..k-1, derivatives in rows k..2k-1. The
    # formula's terms are (signed coefficient, row) in the NumPy loop's order, their rows
    # tabulated once for each position of the ring; offsets are unsigned (no negative-index
    # handling per access). Which derivatives are known is a bit mask over the ring (k <= 62).
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
    tkind = np.empty(2 * k, dtype=np.int64)
    tindex = np.empty(2 * k, dtype=np.int64)
    tcoef = np.empty(2 * k)
    nt = 0
    for jj in range(k):
        if alpha[jj] != 0.0:
            tkind[nt] = 0
            tindex[nt] = jj
            tcoef[nt] = -alpha[jj]
            nt += 1
        if beta[jj] != 0.0:
            tkind[nt] = k
            tindex[nt] = jj
            tcoef[nt] = h * beta[jj]
            nt += 1
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


{_JIT_EXACT}
def lmm_explicit_advance(f_rhs, alpha, beta, t0, n0, h, nsteps, H, F, fvalid, P):
    k, dim, N = H.shape
    if N == 1:
        return lmm_explicit_single(f_rhs, alpha, beta, t0, n0, h, nsteps, H, F, fvalid, P)
    npar = P.shape[0]
    y = np.empty(dim)
    out = np.empty(dim)
    p = np.empty(npar)
    slots = np.empty(k, dtype=np.int64)
    # the formula's nonzero terms in the NumPy loop's order (j ascending, alpha before beta):
    # kind 0 is -alpha_j y_j, kind 1 is + h beta_j f_j
    kind = np.empty(2 * k, dtype=np.int64)
    index = np.empty(2 * k, dtype=np.int64)
    coef = np.empty(2 * k)
    nt = 0
    for jj in range(k):
        if alpha[jj] != 0.0:
            kind[nt] = 0
            index[nt] = jj
            coef[nt] = alpha[jj]
            nt += 1
        if beta[jj] != 0.0:
            kind[nt] = 1
            index[nt] = jj
            coef[nt] = h * beta[jj]
            nt += 1
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
        for jj in range(k):
            sl = slots[jj]
            if beta[jj] != 0.0 and not fvalid[sl]:
                tj = t - (k - 1 - jj) * h
                for m in range(N):
                    for d in range(dim):
                        y[d] = H[sl, d, m]
                    for q in range(npar):
                        p[q] = P[q, m]
                    call_state(f_rhs, tj, y, p, out)
                    for d in range(dim):
                        F[sl, d, m] = out[d]
                fvalid[sl] = True
                evals += 1
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
'''

# Newton's method on the ensemble axis, as `implementations.implicit_rk.newton_solve`: the
# increment's max-norm over members and components (scaled by 1 + |y_n|) at most `tol`, or the
# contraction estimate theta / (1 - theta) |dx| at most `tol` (Hairer & Wanner II, IV.8, eq.
# (8.10)); LU with partial pivoting per member. Status 1: no convergence; 2: singular matrix.
_NEWTON = f'''
{_JIT_INLINE}
def lu_factor(M, piv):
    # M = P L U in place (Gaussian elimination with partial pivoting, whole rows swapped, the
    # multipliers stored below the diagonal); False on an exactly zero pivot
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
            l = M[r, col] * inv
            M[r, col] = l
            if l != 0.0:
                for q in range(col + 1, m):
                    M[r, q] -= l * M[col, q]
    return True


{_JIT_INLINE}
def lu_apply(M, piv, b, x):
    # x = M^-1 b from `lu_factor`'s factors: every row swap first, then the two substitutions (each
    # entry sees the same operations in the same order as elimination interleaved with the swaps)
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
            l = M[r, col]
            if l != 0.0:
                x[r] -= l * x[col]
    for i in range(m - 1, -1, -1):
        acc = x[i]
        for q in range(i + 1, m):
            acc -= M[i, q] * x[q]
        x[i] = acc / M[i, i]


{_JIT_CALLED}
def newton_factor_members(Mats, Piv):
    # every member's Newton matrix factored in place (once per matrix, whatever the number of
    # iterations that solve with it); False on a singular matrix
    for j in range(Mats.shape[0]):
        if not lu_factor(Mats[j], Piv[j]):
            return False
    return True


{_JIT_CALLED}
def newton_solve_members(Mats, Piv, G, DX, rhs_w, sol):
    # DX[:, j] = -Mats[j]^-1 G[:, j] for every member, from the factors of `newton_factor_members`
    m = rhs_w.shape[0]
    for j in range(G.shape[1]):
        for r in range(m):
            rhs_w[r] = -G[r, j]
        lu_apply(Mats[j], Piv[j], rhs_w, sol)
        for r in range(m):
            DX[r, j] = sol[r]


{_JIT_CALLED}
def newton_update(X, DX, inv_scale):
    # X += DX; the increment's max-norm scaled by inv_scale (rows i * dim + d use row d), NaN
    # when any scaled entry is not finite
    dim = inv_scale.shape[0]
    norm = 0.0
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
    if nan_seen or not is_finite(norm):
        return np.nan
    return norm


{_JIT_CALLED}
def newton_converged(norm, previous, tol, theta):
    # (converged, contraction): the increment at most tol, or theta / (1 - theta) |dx| at most tol
    if norm <= tol:
        return True, theta
    if is_finite(previous):
        theta = norm / previous
        if theta < 1.0 and theta / (1.0 - theta) * norm <= tol:
            return True, theta
    return False, theta


{_JIT_CALLED}
def newton_stats(stats, n, n_rhs, n_jac, n_iter, iteration, norm, res_norm, theta, status):
    stats[0] = n
    stats[1] = n_rhs
    stats[2] = n_jac
    stats[3] = n_iter
    stats[4] = iteration
    stats[5] = norm
    stats[6] = res_norm
    stats[7] = theta
    stats[8] = status
'''

# Implicit Runge-Kutta (Hairer & Wanner II, IV.8): unknowns Z_i = h sum_j a_ij f(t + c_j h,
# y + Z_j) on the stages with a nonzero row of A; y_{n+1} = y + sum_i d_i Z_i + h w f(t, y),
# d = A_ii^{-T} b_impl; first same as last recovers f at the step's end from Z.
# flags: [f_start valid, z_prev valid]; stats out: [steps done, rhs, jac, iterations,
# failed iteration, increment, residual, contraction, status].
IMPLICIT_RK = f'''
{_JIT_EXACT}
def irk_single(f_rhs, f_jac, A_ii, aie_sum, c_impl, dvec, wsum, last_inv, E, has_pred, has_expl, fsal,
               full, tol, max_iter, t0, n0, h, nsteps, Y, Fstart, Zprev, flags, P, stats):
    # irk_advance for one member and one implicit stage (Z = h a f(t + c h, y + Z) - h a_e f(t, y)),
    # the state in flat arrays: the same operations in the same order
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
        previous = np.inf
        norm = np.inf
        theta = np.nan
        res_norm = np.nan
        converged = False
        status = 1
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
            # X += DX; the increment's max-norm scaled by inv_scale, NaN when any entry is not finite
            norm = 0.0
            nan_seen = False
            for d in range(dim):
                X[d] += sol[d]
                e = abs(sol[d] * inv_scale[d])
                if e != e:
                    nan_seen = True
                elif e > norm:
                    norm = e
            if nan_seen or not is_finite(norm):
                norm = np.nan
                break
            converged, theta = newton_converged(norm, previous, tol, theta)
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


{_JIT_EXACT}
def irk_advance(f_rhs, f_jac, A_ii, aie_sum, c_impl, dvec, wsum, last_inv, E, has_pred, has_expl, fsal,
                full, tol, max_iter, t0, n0, h, nsteps, Y, Fstart, Zprev, flags, P, stats):
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
    Const = np.zeros((impl, dim))
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
        previous = np.inf
        norm = np.inf
        theta = np.nan
        res_norm = np.nan
        converged = False
        status = 1
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
                if not newton_factor_members(Mats, Piv):
                    n_iter += 1
                    status = 2
                    break
            n_iter += 1
            newton_solve_members(Mats, Piv, G, DX, rhs_w, sol)
            norm = newton_update(X, DX, inv_scale)
            if norm != norm:
                break
            converged, theta = newton_converged(norm, previous, tol, theta)
            if converged:
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
'''

# Implicit linear multistep: y_{n+k} - h beta_k f(t_{n+k}, y_{n+k}) = psi by Newton's method from
# the polynomial extrapolation of the history; f at the new point recovered as (y - psi) / h beta_k.
LMM_IMPLICIT = f'''
{_JIT_EXACT}
def lmm_implicit_advance(f_rhs, f_jac, alpha, beta, wpred, full, tol, max_iter, t0, n0, h, nsteps, H, F,
                         fvalid, P, stats):
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
        previous = np.inf
        norm = np.inf
        theta = np.nan
        res_norm = np.nan
        converged = False
        status = 1
        it = 0
        for it in range(1, max_iter + 1):
            res_norm = 0.0
            for j in range(N):
                for d in range(dim):
                    y[d] = X[d, j]
                for q in range(npar):
                    p[q] = P[q, j]
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
                if not newton_factor_members(Mats, Piv):
                    n_iter += 1
                    status = 2
                    break
            n_iter += 1
            newton_solve_members(Mats, Piv, G, DX, rhs_w, sol)
            norm = newton_update(X, DX, inv_scale)
            if norm != norm:
                break
            converged, theta = newton_converged(norm, previous, tol, theta)
            if converged:
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
'''

#: The family kernels (and helpers) of the generated family module.
KERNELS = (
    "rk_advance", "rk_advance_cols", "split_advance", "split_advance_cols", "leapfrog_advance",
    "leapfrog_advance_cols", "stormer_advance", "lmm_explicit_advance", "irk_advance",
    "lmm_implicit_advance", "controlled_advance", "rhs_all", "accel_all",
)
#: Every template, for fingerprints (a change to any kernel changes every compiled stepper's).
TEMPLATES = (
    _HELPERS, _ACCEL_HELPER, _LMM_PSI, _NEWTON, RK, SPLITTING, LEAPFROG, STORMER, LMM_EXPLICIT,
    IMPLICIT_RK, LMM_IMPLICIT, RK_COLUMNS, SPLITTING_COLUMNS, LEAPFROG_COLUMNS, CONTROLLED,
)
#: Per problem: 'functions' (rhs, rhs_cols, and accel, accel_cols for accelerations of the
#: positions only) and 'jacobian' (jac, for the Newton-solved families).
PARTS = ("functions", "jacobian")


_FAMILY_HEADER = '''"""Generated by implementations.compiled_kernels: the family kernels, compiled once
for every problem (problem functions are called through their addresses); do not edit.
numba {numba_version}, Python {python}; call intrinsics {intrinsics}.
"""
import numpy as np
from numba import njit

from implementations.kernel_calls import call_columns, call_state, call_state_into

'''

def _versions() -> dict[str, str]:
    import numba

    return {"numba_version": numba.__version__, "python": ".".join(map(str, sys.version_info[:3]))}


def _intrinsics_digest() -> str:
    """A hash of the call intrinsics' module (`implementations.kernel_calls`): numba's cache checks
    only the generated module's own file, so the module's text names the intrinsics' version."""
    from implementations import kernel_calls

    code = Path(kernel_calls.__file__).read_text()
    return hashlib.sha256(code.encode()).hexdigest()[:16]


def family_source() -> str:
    """The text of the generated family-kernel module (the same for every problem)."""
    parts = [_HELPERS, _ACCEL_HELPER, RK, RK_COLUMNS, SPLITTING, SPLITTING_COLUMNS, LEAPFROG,
             LEAPFROG_COLUMNS, STORMER, _LMM_PSI, LMM_EXPLICIT, _NEWTON, IMPLICIT_RK, LMM_IMPLICIT,
             CONTROLLED]
    header = _FAMILY_HEADER.format(**_versions(), intrinsics=_intrinsics_digest())
    return header + "\n\n".join(p.strip("\n") + "\n" for p in parts)


# -- generated modules: written once, imported, numba-cached on disk ------------------------------
#: One record per first use in this process: what ("family kernels" or a kernel), seconds, and
#: whether numba compiled it or loaded it from its disk cache.
COMPILE_LOG: list[dict[str, Any]] = []

_family: list[ModuleType] = []
_lock = threading.RLock()


def _write_once(path: Path, text: str) -> None:
    """Create `path` with `text` unless it exists; never rewrite it (numba's cache index is keyed
    by the source file's time stamp, so a rewrite would force a recompile in every process)."""
    if path.exists():
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        try:
            os.link(tmp, path)
        except FileExistsError:
            pass
        except OSError:  # no hard links on this file system
            if not path.exists():
                os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


@contextlib.contextmanager
def _compile_lock(stem: str):
    """Hold an exclusive lock on `stem`.lock in the numba cache directory while compiling (or
    loading) what `stem` names: workers started together (the gate's, the report's) compile each
    kernel and problem module once between them; the others wait and load it from numba's disk
    cache. Without `fcntl` (not POSIX) every process compiles for itself."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    path = cache.code_dir() / "numba" / f"{stem}.lock"
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _import_text(text: str, stem: str, what: str) -> ModuleType:
    digest = hashlib.sha256(text.encode()).hexdigest()[:20]
    path = cache.code_dir() / "numba" / f"{stem}_{digest}.py"
    _write_once(path, text)
    mod_name = f"_harness_numba_{digest}"
    module = sys.modules.get(mod_name)
    if module is None:
        # Registered before it runs: numba's cache records the module by name and imports it by
        # that name when it loads a cached function.
        spec = importlib.util.spec_from_file_location(mod_name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[mod_name] = module
        start, cpu = time.perf_counter(), time.process_time()
        try:
            with _compile_lock(f"{stem}_{digest}"):
                spec.loader.exec_module(module)
        except BaseException:
            sys.modules.pop(mod_name, None)
            raise
        cfuncs = [v for v in vars(module).values() if hasattr(v, "address") and hasattr(v, "cache_hits")]
        if cfuncs:
            COMPILE_LOG.append({
                "what": what,
                "seconds": time.perf_counter() - start,
                "cpu_seconds": time.process_time() - cpu,
                "source": "cached" if all(f.cache_hits for f in cfuncs) else "compiled",
            })
    return module


def problem_functions(problem: Problem, part: str = "functions") -> dict[str, NativeFunction]:
    """`problem`'s loaded functions of `part`: 'functions' (rhs, rhs_cols, and accel, accel_cols
    for an acceleration of the positions alone) or 'jacobian' (jac); raises UnsupportedExpression."""
    if part not in PARTS:
        raise InputError(f"`part` must be one of {PARTS}, got {part!r}")
    if part == "jacobian":
        names = ["jac"]
    else:
        names = ["rhs", "rhs_cols"]
        if problem.newtonian is not None and not problem.velocity_dependent:
            names += ["accel", "accel_cols"]
    return {name: native_function(problem, name) for name in names}


def family_module() -> ModuleType:
    """The generated, imported family-kernel module (one per process)."""
    with _lock:
        if not _family:
            _family.append(_import_text(family_source(), "families", "family kernels"))
        return _family[0]


def address(problem: Problem, name: str) -> int:
    """The address of `problem`'s function `name` ('rhs', 'rhs_cols', 'accel', 'accel_cols' or
    'jac'); raises UnsupportedExpression."""
    return function_address(problem, name)


def call_kernel(name: str, *args: Any) -> Any:
    """Call the family kernel `name` with `args`; its first call in this process records its
    compile (or cache load) time in COMPILE_LOG."""
    if name not in KERNELS:
        raise InputError(f"`name` must be one of {list(KERNELS)}, got {name!r}")
    module = family_module()
    kernel = getattr(module, name)
    if kernel.signatures:
        return kernel(*args)
    start, cpu = time.perf_counter(), time.process_time()
    with _compile_lock(f"{module.__name__}_{name}"):  # compiled (or loaded) only, not run
        kernel.compile(tuple(kernel.typeof_pyval(a) for a in args))
    result = kernel(*args)
    stats = kernel.stats
    COMPILE_LOG.append({
        "what": name,
        "seconds": time.perf_counter() - start,
        "cpu_seconds": time.process_time() - cpu,
        "source": "cached" if stats.cache_hits and not stats.cache_misses else "compiled",
    })
    return result
