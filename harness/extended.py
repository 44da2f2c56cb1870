"""Convergence order in extended precision, for methods whose asymptotic range float64 cannot reach.

A high-order method (order 8-10) on an orbit meets the float64 rounding floor (about 1e-16 |y|
times the flow's sensitivity) while its local slopes still drift towards the order; the float64
sweep then ends `insufficient-range`. The same coefficients run here in real128 (113-bit
significand, ~34 digits, heyoka's numpy dtype; one step is one real128 `heyoka.cfunc` built from
the problem's symbolic definition and the exact coefficients) from the problem's own start (one
trajectory), against a 192-bit `heyoka.real` ground truth certified by a 256-bit rerun. The
floor drops by ~18 decades, so the slopes settle and the order is fitted by the float64 sweep's
rules (`harness.order_fit.classify_points`).

This gains nothing unless the coefficients are exact beyond float64 (a 1e-16 error in one
breaks the order conditions at 1e-16 h): the coefficient objects keep an exact form (`exact`,
Fractions); a method given only in float64 is not measurable here, with that reason.

References: Hairer, Norsett & Wanner, *Solving ODEs I*, II.3-II.4 (order, error constants);
H. Yoshida, Phys. Lett. A 150 (1990) 262-268 (compositions); Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, V.3 (order conditions of compositions).
"""

from __future__ import annotations

import math
import time
from fractions import Fraction
from typing import Any

import heyoka as hy
import mpmath
import numpy as np

from harness import cache
from harness import tolerances as tol
from harness.coefficient_floors import coefficient_floor, mark_above_order, rounded_coefficient_floor
from harness.coefficients import ButcherTableau, SecondOrderMultistep, SplittingScheme
from harness.order_fit import classify_points, fit_order
from harness.problem.definition import subs_pars
from harness.theory.newtonian import velocity_weights
from harness.theory.series import Series, composition_series

__all__ = ["NotMeasurable", "exact_form", "extended_sweep", "refine_composition_weights", "EXTENDED_EPS",
           "extended_reference"]

#: Unit roundoff of real128 (113-bit significand).
EXTENDED_EPS = 2.0**-113
# Precision (bits) of the ground truth and of its certifier.
_REFERENCE_PREC, _CERTIFIER_PREC = 192, 256
_integrators = cache.IntegratorPool()  # Taylor, by (problem, precision): ~0.15 s to build each


class NotMeasurable(Exception):
    """An extended-precision run cannot measure this pair; the message says why."""


# -- exact coefficients -----------------------------------------------------------------------------
def exact_form(coefficients: Any) -> Any:
    """The coefficient object's exact form (Fractions), or NotMeasurable with the reason.

    Parameters
    ----------
    coefficients : an explicit ButcherTableau, a SplittingScheme or a SecondOrderMultistep.

    Returns
    -------
    Its `exact` attribute."""
    if not isinstance(coefficients, (ButcherTableau, SplittingScheme, SecondOrderMultistep)):
        raise NotMeasurable("extended precision runs explicit Runge-Kutta tableaux, drift/kick "
                            "compositions and second-order multistep tables; this method is none")
    if isinstance(coefficients, ButcherTableau) and not coefficients.explicit:
        raise NotMeasurable("extended precision runs explicit Runge-Kutta tableaux only (this one "
                            "is implicit)")
    exact = getattr(coefficients, "exact", None)
    if exact is None:
        raise NotMeasurable("not measurable in extended precision, because the coefficients are "
                            "given only to float64 (give them as Fractions or decimal strings)")
    return exact


def _composition_residuals(mp, base_exact, free, order: int) -> list:
    """Signed coefficients of h^1..h^order in the local error of the symmetric composition
    base(w_m h)...base(w_0 h)...base(w_m h), w_0 = 1 - 2 sum w_i, on the generic separable
    problem of `harness.theory` (every component, both starting points): all vanish exactly
    when the composition has that order."""
    w0 = 1 - 2 * sum(free)
    weights = [*reversed(free), w0, *free]
    steps = [(k, w * mp.mpf(v.numerator) / v.denominator) for w in weights for k, v in base_exact]
    S = Series(mp, order)
    out = []
    for numeric, exact in composition_series(mp, S, steps):
        out.extend(numeric[i][n] - exact[i][n] for i in range(4) for n in range(1, order + 1))
    return out


def refine_composition_weights(base: SplittingScheme, weights: list, order: int,
                               digits: int = 40) -> list[str]:
    """The free weights (w_1..w_m) of a symmetric composition of `base` to `digits` significant
    digits: Gauss-Newton on the exact local-error series (`harness.theory`) from a start.

    Parameters
    ----------
    base : SplittingScheme with exact coefficients; weights : the start (for instance a paper's
        15-digit values); order : int, the composition's order; digits : int.

    Returns
    -------
    list of str: decimal strings. NotMeasurable when it does not converge (a start not near a
    solution)."""
    if base.exact is None:
        raise NotMeasurable("the base method's coefficients are given only to float64")
    with mpmath.workdps(digits + 25):
        mp = mpmath.mp
        x = mpmath.matrix([mp.mpf(str(w)) for w in weights])
        step = mp.mpf(10) ** (-(digits + 10))
        for _ in range(12):
            r = mpmath.matrix(_composition_residuals(mp, base.exact, list(x), order))
            J = mpmath.matrix(len(r), len(x))
            for j in range(len(x)):
                xp = x.copy()
                xp[j] += step
                rp = _composition_residuals(mp, base.exact, list(xp), order)
                for i in range(len(r)):
                    J[i, j] = (rp[i] - r[i]) / step
            dx = mpmath.lu_solve(J.T * J, -(J.T * r))
            x = x + dx
            if mpmath.norm(dx, mpmath.inf) < mp.mpf(10) ** (-(digits + 2)):
                break
        else:
            raise NotMeasurable("the composition weights did not converge from the given start")
        return [mpmath.nstr(v, digits, strip_zeros=False, min_fixed=-1, max_fixed=1) for v in x]


def composition_defect(base: SplittingScheme, weights: list, order: int) -> float:
    """Largest |coefficient of h^n|, n <= order, of the local error of the symmetric composition,
    in 60-digit arithmetic.

    Parameters
    ----------
    base : SplittingScheme with exact coefficients; weights : the free weights (decimal strings
        or Fractions); order : int, the order checked.

    Returns
    -------
    float: ~0 when the weights are accurate, ~1e-16 for float64 weights."""
    with mpmath.workdps(60):
        mp = mpmath.mp
        free = [mp.mpf(Fraction(w).numerator) / Fraction(w).denominator for w in weights]
        return float(max(abs(v) for v in _composition_residuals(mp, base.exact, free, order)))


# -- the extended-precision step loops -----------------------------------------------------------
# One step of the method is one real128 `heyoka.cfunc`: the problem's symbolic right-hand side
# (or acceleration) substituted into the method's stages with the exact coefficients rounded once
# to real128 and the step size h as the runtime parameter par[0], so a step is one call into
# compiled code (the same operations in the same order as stage-by-stage array arithmetic, bit
# for bit, at 3-8x less time: rk4 on damped-cubic 6 us a step against 48 us).
def _real128(value) -> Any:
    """A float or an exact Fraction as real128 (a Fraction rounded once, by the division)."""
    if isinstance(value, Fraction):
        return hy.real128(value.numerator) / hy.real128(value.denominator)
    return hy.real128(value)


def _to_real128(values) -> np.ndarray:
    return np.array([_real128(v) for v in values])


def _real128_constant(value) -> Any:
    return hy.expression(_real128(Fraction(value)))


def _with_parameter_values(problem, exprs: list) -> list:
    """`exprs` with the problem's parameters replaced by their values (h is the only runtime
    parameter of a step function)."""
    if not problem.parameters:
        return list(exprs)
    mapping = {f"p{i}": hy.expression(float(v)) for i, v in enumerate(problem.parameter_values)}
    return [subs_pars(e, mapping) for e in exprs]


def _step_function(problem, step: list, evals_per_step: int):
    """(y0, span, n) -> (y_n, evaluations) with h = span / n: `step` (y_{k+1} as expressions of
    y_k and h = par[0]) compiled once in real128 and called n times."""
    cache.configure_heyoka_cache()
    fn = hy.cfunc(step, list(problem.variables), fp_type=hy.real128, compact_mode=cache.compact_mode(problem))

    def run(y0: np.ndarray, span: float, n: int) -> tuple[np.ndarray, int]:
        # h = span / n rounded once in real128: a float64 h would end the run ~1e-16 T off the
        # final time whenever n is not a power of two
        pars = np.array([hy.real128(span) / hy.real128(n)])
        y = y0.copy()
        for _ in range(n):
            y = fn(y, pars=pars)
        return y, n * evals_per_step

    return run


def _rk_runner(problem, exact):
    """y_{n+1} = y_n + h sum b_i k_i, k_i = f(t_n + c_i h, y_n + h sum_j a_ij k_j) in real128."""
    if problem.time_dependent:
        raise NotMeasurable("extended precision runs autonomous problems only")
    A, b, _ = exact
    names = [str(v) for v in problem.variables]
    f = _with_parameter_values(problem, problem.rhs)
    h = hy.par[0]
    K: list[list] = []
    for i in range(len(b)):
        Y = list(problem.variables)
        for j in range(i):
            if A[i][j] != 0:
                ha = h * _real128_constant(A[i][j])
                Y = [Yk + ha * Kk for Yk, Kk in zip(Y, K[j], strict=True)]
        K.append(hy.subs(f, dict(zip(names, Y, strict=True))) if i else f)
    incr = None
    for i, w in enumerate(b):
        if w != 0:
            terms = [_real128_constant(w) * Kk for Kk in K[i]]
            incr = terms if incr is None else [a + t for a, t in zip(incr, terms, strict=True)]
    step = [y + h * d for y, d in zip(problem.variables, incr, strict=True)]
    return _step_function(problem, step, len(b))


def _newtonian_indices(problem, what: str):
    """(Newtonian form, position indices, velocity indices) in the state of `problem`;
    `NotMeasurable` naming `what` unless the acceleration is velocity-free and autonomous."""
    form = problem.newtonian
    if form is None or problem.velocity_dependent or problem.time_dependent:
        raise NotMeasurable(f"{what} needs a velocity-free, autonomous acceleration")
    names = [str(v) for v in problem.variables]
    return (form, [names.index(str(v)) for v in form.positions],
            [names.index(str(v)) for v in form.velocities])


def _split_runner(problem, exact):
    """Drifts q += a h v and kicks v += b h a(q) in real128."""
    form, qi, vi = _newtonian_indices(problem, "a drift/kick composition")
    accel = _with_parameter_values(problem, form.acceleration)
    positions = [str(v) for v in form.positions]
    h = hy.par[0]
    q = [problem.variables[i] for i in qi]
    v = [problem.variables[i] for i in vi]
    for kind, c in exact:
        hc = h * _real128_constant(c)
        if kind == "D":
            q = [qk + hc * vk for qk, vk in zip(q, v, strict=True)]
        else:
            a = hy.subs(accel, dict(zip(positions, q, strict=True)))
            v = [vk + hc * ak for vk, ak in zip(v, a, strict=True)]
    step = list(problem.variables)
    for k, i in enumerate(qi):
        step[i] = q[k]
    for k, i in enumerate(vi):
        step[i] = v[k]
    return _step_function(problem, step, sum(1 for k, _ in exact if k == "K"))


def _lmm2_runner(problem, coefficients, exact):
    """sum_j alpha_j x_(n+j) = h^2 sum_j beta_j a(x_(n+j)) in real128, started from the 192-bit
    ground truth at t_0 + j h (j < H, H = max(k, p - 1) as the float64 loop keeps), implicit tables
    by fixed-point iteration to real128 rounding; the velocity at the end by the loop's formula of
    order H + 1 (`harness.theory.newtonian.velocity_weights`)."""
    form, qi, vi = _newtonian_indices(problem, "a second-order multistep table")
    cache.configure_heyoka_cache()
    accel = hy.cfunc(_with_parameter_values(problem, form.acceleration), list(form.positions),
                     fp_type=hy.real128, compact_mode=cache.compact_mode(problem))
    alpha, beta = _to_real128(exact[0]), _to_real128(exact[1])
    k = coefficients.steps
    keep = max(k, int(coefficients.order()) - 1)
    weights = _to_real128(velocity_weights(keep))

    def run(y0: np.ndarray, span: float, n: int) -> tuple[np.ndarray, int]:
        h = hy.real128(span) / hy.real128(n)
        h2 = h * h
        step = hy.real(float(span), _REFERENCE_PREC) / n
        t0 = hy.real(float(problem.t0), _REFERENCE_PREC)
        starts = _taylor(problem, None, _REFERENCE_PREC, [t0 + j * step for j in range(1, keep)])
        X = [y0[qi].copy()] + [_to_real128([s[i] for i in qi]) for s in starts]
        A = [accel(x) for x in X]
        evals = len(X)
        XA, AA, hb = np.array(X[-k:]), np.array(A[-k:]), (h2 * beta[:k])[:, None]  # the last k as rows
        for _ in range(n - (keep - 1)):
            aX, hA, psi = alpha[:k, None] * XA, hb * AA, np.zeros_like(X[-1])
            for j in range(k):
                psi = psi - aX[j] + hA[j]
            x = psi
            if beta[k] != 0:  # implicit: x = psi + h^2 beta_k a(x), a contraction at small h
                for _ in range(tol.NEWTON_MAX_ITER * 10):
                    new = psi + h2 * beta[k] * accel(x)
                    evals += 1
                    done = bool(np.all(np.abs(new - x) <= hy.real128(EXTENDED_EPS) * np.abs(new)))
                    x = new
                    if done:
                        break
            X = X[1:] + [x]
            A = A[1:] + [accel(x)]
            XA[:-1], AA[:-1], XA[-1], AA[-1] = XA[1:], AA[1:], x, A[-1]
            evals += 1
        v = (X[-1] - X[-2]) / h
        for j in range(keep):
            v = v + h * weights[j] * A[-1 - j]
        y = y0.copy()
        y[qi] = X[-1]
        y[vi] = v
        return y, evals

    run.min_steps = keep  # at least one step of the recurrence after the starting values
    # rho's double root 1 integrates each rounding error twice: n^(3/2) eps (HLW VIII.5;
    # `harness.experiments.roundoff`)
    run.rounding_exponent = 1.5
    return run


def _runner(coefficients, problem):
    exact = exact_form(coefficients)
    if isinstance(coefficients, ButcherTableau):
        return _rk_runner(problem, exact)
    if isinstance(coefficients, SecondOrderMultistep):
        return _lmm2_runner(problem, coefficients, exact)
    return _split_runner(problem, exact)


# -- ground truth in 192 bits, certified by 256 ----------------------------------------------------
def _taylor(problem, T, prec: int, times: list | None = None) -> list:
    """The `prec`-bit Taylor state at T; with `times` (increasing, `prec`-bit reals), the states
    there instead, on the same orbit. The integrator is built once per process for a problem and
    precision (~0.15 s; a second-order multistep sweep asks for its starting values at every step
    count) and set to the start before each use: its steps follow from its state and time alone,
    so the states are those of a fresh integrator, digit for digit."""

    def build():
        start = [hy.real(float(v), prec) for v in problem.y0]
        pars = [hy.real(float(v), prec) for v in problem.parameter_values] if problem.parameters else []
        return hy.taylor_adaptive(list(zip(problem.variables, problem.rhs, strict=True)), start, pars=pars,
                                  tol=hy.real(2.0 ** (1 - prec), prec), high_accuracy=True, compact_mode=True,
                                  fp_type=hy.real, prec=prec)

    lock, ta = _integrators.get((problem.fingerprint(), prec), build)
    with lock:
        ta.state[:] = [hy.real(float(v), prec) for v in problem.y0]
        ta.time = hy.real(float(problem.t0), prec)
        out = []
        for t in ([hy.real(float(T), prec)] if times is None else times):
            outcome = ta.propagate_until(t)[0]
            if outcome != hy.taylor_outcome.time_limit:
                raise NotMeasurable(f"the {prec}-bit ground truth stopped with {outcome}")
            out.append(list(ta.state))
    return out[0] if times is None else out


def extended_reference(problem, T: float) -> tuple[list, float]:
    """The state at T in 192-bit arithmetic and its certified error.

    Parameters
    ----------
    problem : Problem, from its own start; T : float, the end time.

    Returns
    -------
    tuple: (state as heyoka reals, max over components of the difference with a 256-bit rerun)."""
    ref = _taylor(problem, T, _REFERENCE_PREC)
    cert = _taylor(problem, T, _CERTIFIER_PREC)
    return ref, max(float(abs(a - b)) for a, b in zip(ref, cert, strict=True))


def _error(y: np.ndarray, ref: list) -> float:
    return max(float(abs(hy.real(v, _REFERENCE_PREC) - r)) for v, r in zip(y, ref, strict=True))


def _settled(rows: list[dict]) -> bool:
    """The last two local slopes agree to EXTENDED_SETTLED_SLOPE: cheap points are taken until
    the slopes stop drifting (a float64 sweep cannot afford to wait)."""
    if len(rows) < 3:
        return False
    h = np.log([r["h"] for r in rows[-3:]])
    e = np.log([r["error"] for r in rows[-3:]])
    slopes = np.diff(e) / np.diff(h)
    return bool(abs(slopes[1] - slopes[0]) <= tol.EXTENDED_SETTLED_SLOPE)


# -- the sweep ------------------------------------------------------------------------------------
def extended_sweep(coefficients, problem, *, T: float | None = None, work_budget: float | None = None,
                   amplification: float = 1.0, order_bound: int | None = None) -> dict:
    """Global error against step size in real128, one trajectory from the problem's start: n = 1,
    2, 4, ... steps until TARGET_FIT_POINTS points have settled slopes, a floor is reached (real128's,
    or the coefficients' own order-condition defects, `harness.theory.defects`) or `work_budget`
    evaluations are spent; then steps between the last ones (ratio sqrt 2) fill in a window a floor
    cut short. A slope above `order_bound` never settles. Raises NotMeasurable with the reason.

    Parameters
    ----------
    coefficients : the method's coefficient object; problem : Problem; T : the end time (default
        its convergence horizon); work_budget : evaluations allowed (default EXTENDED_WORK_BUDGET);
        amplification : the flow's rounding amplification; order_bound : max(order, linear order) or None.

    Returns
    -------
    dict: 'rows' (h, n_steps, error, reference_error, rounding_level, excluded), 'fit' (order,
    points, h range) or None, 'reference_error', 'stopped_by', 'note', 'evals' and more."""
    runner = _runner(coefficients, problem)
    growth = getattr(runner, "rounding_exponent", 0.5)  # rounding as a random walk: n^(1/2) eps
    T = float(problem.convergence_t_end if T is None else T)
    budget = float(tol.EXTENDED_WORK_BUDGET if work_budget is None else work_budget)
    started = time.perf_counter()
    ref, ref_err = extended_reference(problem, T)
    y0 = _to_real128([float(v) for v in problem.y0])
    scale = max(tol.SCALE_FLOOR, float(np.max(np.abs(problem.y0))), max(abs(float(r)) for r in ref))
    start_error = tol.SWEEP_START_ERROR * scale
    span = T - float(problem.t0)
    floor_of = coefficient_floor(coefficients, problem, span=span, scale=scale, noise=EXTENDED_EPS)
    floor_of = floor_of if floor_of(np.array([1.0])) is not None else None
    rounded_of = rounded_coefficient_floor(coefficients, problem, span=span, scale=scale, eps=EXTENDED_EPS)
    rows: list[dict] = []
    spent = 0
    note = ""

    def run(n: int) -> int:
        with np.errstate(all="ignore"):  # a coarse step may overflow: that point is a blow-up
            y, evals = runner(y0, span, n)
        rows.append({"h": span / n, "n_steps": n, "error": _error(y, ref), "reference_error": ref_err,
                     "rounding_level": n ** growth * EXTENDED_EPS * scale * max(1.0, amplification)
                     + (float(rounded_of(np.array([span / n]))[0]) if rounded_of else 0.0)})
        rows.sort(key=lambda r: -r["h"])
        return evals

    def classified() -> tuple[np.ndarray, str]:
        h_arr = np.array([r["h"] for r in rows])
        e_arr = np.array([r["error"] for r in rows])
        reasons = classify_points(h_arr, e_arr, np.array([r["reference_error"] for r in rows]),
                                  np.array([r["rounding_level"] for r in rows]), start_error,
                                  floor_of(h_arr) if floor_of else None)
        return reasons, mark_above_order(h_arr, e_arr, reasons, order_bound)

    stops = {"roundoff": "the real128 rounding floor", "reference": "the 192-bit reference's accuracy",
             "coefficients": "the coefficients' own accuracy (their defects in the order conditions)"}
    n = 1
    while n < getattr(runner, "min_steps", 1):  # a multistep table takes its history first
        n *= 2
    stop = "the work budget"
    while True:
        evals = run(n)
        spent += evals
        reasons, note = classified()
        err = rows[-1]["error"]
        if math.isfinite(err) and err < start_error:
            if reasons[-1] in stops:
                stop = stops[reasons[-1]]
                break
            if int((reasons == "").sum()) >= tol.TARGET_FIT_POINTS and _settled(rows):
                stop = ""
                break
        if spent + 2 * evals > budget:
            break
        n *= 2
    # Fill in: where a floor came before TARGET_FIT_POINTS settled points, step sizes between the
    # last ones above it (ratio sqrt 2), within the budget.
    if stop and int((reasons == "").sum()) < tol.TARGET_FIT_POINTS:
        usable = [r["n_steps"] for r, why in zip(rows, reasons, strict=True)
                  if why in ("", "pre-asymptotic") and r["error"] < start_error]
        for a, b in list(zip(usable, usable[1:], strict=False))[-3:]:
            m = int(round(math.sqrt(a * b)))
            if m not in (a, b) and spent + m * (evals // max(n, 1)) <= budget:
                spent += run(m)
        reasons, note = classified()
    for r, why in zip(rows, reasons, strict=True):
        r["excluded"] = why
    kept = [r for r in rows if not r["excluded"]]
    fit = None
    if len(kept) >= tol.MIN_FIT_POINTS:
        f = fit_order([r["h"] for r in kept], [r["error"] for r in kept])
        fit = {"order": f["order"], "ci_low": f["ci_low"], "ci_high": f["ci_high"],
               "residual": f["residual"], "points": len(kept), "h_min": min(r["h"] for r in kept),
               "h_max": max(r["h"] for r in kept), "error_min": min(r["error"] for r in kept),
               "error_max": max(r["error"] for r in kept)}
    slopes = np.diff(np.log([r["error"] for r in rows])) / np.diff(np.log([r["h"] for r in rows]))
    if fit is None and not note and stop:
        note = "the local slopes had not settled on an integer order (the error is still curving)"
    return {"rows": rows, "fit": fit, "reference_error": ref_err, "stopped_by": stop, "note": note,
            "evals": spent, "wall_s": time.perf_counter() - started, "t_end": T,
            "local_slopes": [float(s) for s in slopes], "precision": "real128",
            "reference_precision": f"real{_REFERENCE_PREC} certified by real{_CERTIFIER_PREC}"}

