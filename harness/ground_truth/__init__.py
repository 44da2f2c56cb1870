"""Certified ground truth: heyoka's Taylor integrator at a chosen precision, checked by a rerun
one precision level higher.

A reference is computed at one *level* (float64, long double, real128) with tolerance equal to
that level's unit roundoff and `high_accuracy=True`, and *certified* by the next level up
(long double, real128, then 192-bit multiprecision `hy.real`). heyoka's tolerance bounds each
step's Taylor remainder, not the global error, so the error is measured, never assumed:

    error[t, n] = max over components of ( |y_level - y_next| + |fl64(y_level) - y_level| ),

the difference with the next level (computed exactly in the higher precision) plus the rounding
of the stored float64 value. The certifying run uses the tolerance max(its own unit roundoff,
the certified level's x `CERTIFIER_TOL_FACTOR` = 2^-16): its error is then ~1e-5 of the
certified level's, so the difference measures the level's error (on Kepler e = 0.6 at t = 100
the float64 level's certified 2.04e-12 matches its true error, from the exact solution, to 0.01 %).

Level policy (`required_error`):
- None (default): long double certified by real128 (the best available pair without real128).
  Measured on this machine type: all 15 catalogue problems, a 16-member ensemble each, at their
  convergence final times cost ~2 s of CPU in total (~90 % in the real128 certifier; the most
  expensive are `lennard-jones` and `outer-solar-system`, ~0.45 s each), with certified errors
  at the float64 rounding of the state (<= 1.2e-16 relative). A fresh heyoka JIT cache adds a
  one-time ~7 s of compilation; a cached reference loads in ~1-10 ms.
- a number: the cheapest level whose certified error (max over times and members) meets it;
  `ReferenceError_` names the required and the best achieved error when none does. When the
  float64 rounding of the state alone already exceeds the requirement, the dearer levels are
  skipped (their error includes that same rounding).

Integrators are compiled once per (problem, level, tolerance) and process and reset per ensemble
member (parameters are runtime values); heyoka's on-disk JIT cache lives in the harness cache
directory. References are cached on disk under `cache_dir()/references`, keyed by a hash of the
problem's fingerprint, times, t0, initial states, parameters, level, tolerance factors and heyoka
version; files are written atomically, and a corrupt file is ignored and recomputed.

A problem with a published form (`Problem.published`: a test set's exact decimals), asked from
its own start with its own constants, is integrated as published: every level starts from the
exact start values and constants, rounded once to the level, and reaches the exact published end
time (`Reference.form` = 'published'); any other request integrates the float64 form.

Stiff problems: when the Taylor step is held by the Jacobian's eigenvalues and the span would
need more than `REFERENCE_STIFF_STEPS` steps (`propagation.stiff_check`), the explicit reference
refuses with `StiffReferenceError`. Then, in order: the published end values, for the problem as
published at its published end time (precision 'published', error = their stated accuracy);
else the implicit cross-check (`harness.ground_truth.stiff`: scipy Radau against CVODE BDF,
error = their disagreement, examined first against the published end values); else the refusal.

This module computes and certifies a reference (`reference`); `levels` (precision levels, exact
comparison), `propagation` (bounded Taylor propagation) and `disk` (the reference cache) serve it.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from harness.errors import InputError, ReferenceError_, StiffReferenceError
from harness.ground_truth import stiff
from harness.ground_truth.disk import (
    cache_path,
    load_reference,
    reference_key,
    references_dir,
    store_reference,
)
from harness.ground_truth.levels import (
    DEFAULT_LEVEL,
    LEVELS,
    LEVELS_BY_NAME,
    Level,
    Reference,
    available_levels,
    certifier_of,
    certify,
    level_chain,
)
from harness.ground_truth.propagation import certifier_tol, integrators, propagate, reference_tol
from harness.problem import Problem, check_state, check_time
from harness.problem.checks import check_positive
from harness.registry import get_problem

# the integrators built in this process, by (problem, level, tolerance); benchmarks clear it
_integrators = integrators


__all__ = [
    "Reference",
    "reference",
    "LEVELS",
    "DEFAULT_LEVEL",
    "available_levels",
    "certifier_of",
    "references_dir",
]


def published_values(problem: Problem, times: np.ndarray, as_published: bool, start: float,
                     refusal: StiffReferenceError) -> Reference | None:
    """The test set's own end values as the reference, where the explicit reference refused a
    stiff problem: only for the problem as published (its own start and constants) and only at
    the published end time. Their error is the stated accuracy (relative, per component) times
    the largest component, so a comparison against them is never held to more than the source
    states. None where they do not apply.

    Parameters
    ----------
    problem : the problem; times : the requested times; as_published : whether the request is
    for the problem as published; start : perf_counter at the request; refusal : the stiff
    refusal being answered.

    Returns
    -------
    Reference or None
    """
    pub = problem.published
    if not as_published or pub is None or pub.values is None or times.size != 1 or (
            float(times[0]) != pub.t_end_float):
        return None
    values = np.array(pub.values_float, dtype=np.float64)
    error = np.full((1, 1), pub.accuracy * float(np.max(np.abs(values))))
    return Reference(problem.name, times.copy(), values.reshape(1, -1, 1), error, "published",
                     f"published values ({pub.source}; {pub.accuracy_note}); the explicit "
                     f"reference refused: {refusal}", time.perf_counter() - start,
                     form="published values")


def _stiff_reference(problem: Problem, times: np.ndarray, y: np.ndarray, t0: float, P: np.ndarray,
                     start: float, refusal: StiffReferenceError) -> Reference:
    """The cross-checked implicit reference (`harness.ground_truth.stiff`), cached on disk like
    the Taylor ones; the refusal stands when its solvers are not installed."""
    if not stiff.available():
        raise refusal
    exam = _implicit_exam(problem, start)
    if exam:
        raise StiffReferenceError(f"{refusal}; the implicit cross-check does not apply: {exam}")
    return _implicit_cached(problem, times, y, t0, P, start)


def _implicit_cached(problem: Problem, times: np.ndarray, y: np.ndarray, t0: float, P: np.ndarray,
                     start: float) -> Reference:
    key = reference_key(problem, stiff.IMPLICIT_LEVEL, times, t0, y, P)
    path = cache_path(problem, stiff.IMPLICIT_LEVEL, key)
    loaded = load_reference(path, times, (times.size, problem.dim, y.shape[1]))
    if loaded is not None:
        y_ref, error, _, certified_by, compute_s = loaded
        cached = True
    else:
        y_ref, error, compute_s = stiff.implicit_reference(problem, times, y, t0, P)
        certified_by, cached = stiff.IMPLICIT_CERTIFIER, False
        try:
            store_reference(path, y=y_ref, error=error, floor=np.zeros_like(error), t=times,
                            certified_by=np.array(certified_by), compute_s=np.array(compute_s))
        except OSError as exc:
            warnings.warn(f"reference cache not written ({path}): {exc}", stacklevel=2)
    return Reference(problem.name, times, y_ref, error, stiff.IMPLICIT_LEVEL, certified_by,
                     time.perf_counter() - start, cached=cached, compute_s=compute_s)


def _implicit_exam(problem: Problem, start: float) -> str:
    """The implicit cross-check judged where the truth is known: from the published start (its
    float64 form) to the published end time, against the published values. '' when it passes
    (its difference from them within its own stated error plus their stated accuracy, and the
    effect of the float64 rounding of the inputs), else why not. A problem without published
    values is not examined."""
    pub = problem.published
    if pub is None or pub.values is None or pub.t_end_float is None:
        return ""
    times = np.array([pub.t_end_float])
    ref = _implicit_cached(problem, times, problem.y0.reshape(-1, 1), problem.t0,
                           problem.pars_for(1), start)
    values = np.array(pub.values_float)
    diff = float(np.max(np.abs(ref.y[0][:, 0] - values)))
    rounding = max(pub.rounding().values()) * float(np.max(np.abs(values)))
    allowed = ref.max_error + pub.accuracy * float(np.max(np.abs(values))) + 100.0 * rounding
    if diff <= allowed:
        return ""
    return (f"at the published end time it is {diff:.3g} from the published values, more than "
            f"its stated error {ref.max_error:.3g} plus their accuracy allow ({allowed:.3g})")


# -- public entry point ----------------------------------------------------------------------------
def _check_times(times: Any, t0: float) -> np.ndarray:
    try:
        arr = np.array(times, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"`times` must be a number or a 1-D array of numbers, got {times!r}") from None
    if arr.ndim == 0:
        arr = arr[None]
    if arr.ndim != 1 or arr.size == 0:
        raise InputError(f"`times` must be a number or a non-empty 1-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError("`times` must be finite (no NaN or inf)")
    if np.any(np.diff(arr) <= 0):
        raise InputError("`times` must be strictly increasing")
    if arr[0] < t0:
        raise InputError(f"`times` must be >= t0 = {t0!r}, got {arr[0]!r}")
    return arr


def reference(
    problem: Problem | str,
    times: Any,
    y0: Any = None,
    *,
    t0: float | None = None,
    pars: np.ndarray | Mapping[str, float] | None = None,
    required_error: float | None = None,
) -> Reference:
    """Certified ground truth of `problem` at `times` (scalar or increasing 1-D array >= t0) from
    initial states `y0` ((dim,) or (dim, N); default the problem's) with parameters `pars` (as in
    `Problem.pars_for`). See the module docstring for the level policy.

    Parameters
    ----------
    problem : Problem or str, the problem, or its registered name.
    times : float or array_like, output times, increasing, >= t0.
    y0 : array_like, optional, initial states, shape (dim,) or (dim, N) (default the problem's start).
    t0 : float, optional, initial time (default the problem's).
    pars : ndarray or mapping, optional, parameter values, as in `Problem.pars_for`.
    required_error : float, optional
        The certified error the reference must meet (None: the default level pair).

    Returns
    -------
    Reference
        y shaped (nt, dim, N) and its certified error (nt, N), with precision, certifier and
        cost; `ReferenceError_` when no level meets `required_error`.
    """
    start = time.perf_counter()
    if isinstance(problem, str):
        problem = get_problem(problem)
    if not isinstance(problem, Problem):
        raise InputError(f"`problem` must be a Problem or a registered name, got {type(problem).__name__}")
    t0 = problem.t0 if t0 is None else check_time(t0, "t0")
    times = _check_times(times, t0)
    y = check_state(problem.y0 if y0 is None else y0, problem.dim, "y0")
    n_members = y.shape[1]
    P = problem.pars_for(n_members, pars)
    required = None if required_error is None else check_positive(required_error, "`required_error`")
    if not available_levels():
        raise ReferenceError_(
            f"ground truth for problem {problem.name!r} cannot be certified: no precision above "
            "float64 is available (long double is double here and heyoka lacks real128)"
        )
    chain = level_chain()
    names = [lv.name for lv in chain]
    candidates = [DEFAULT_LEVEL] if required is None else available_levels()
    shape = (times.size, problem.dim, n_members)

    runs: dict[tuple[str, float], tuple[np.ndarray, float]] = {}

    # A problem with a published form, asked from its own start with its own constants, is
    # integrated as published (exact decimal constants, start values and end time).
    as_published = problem.published is not None and y0 is None and pars is None
    form = "published" if as_published else "float64"

    def run(lv: Level, tol: float) -> tuple[np.ndarray, float]:
        if (lv.name, tol) not in runs:
            runs[lv.name, tol] = propagate(problem, lv, tol, times, y, t0, P, as_published)
        return runs[lv.name, tol]

    best: tuple[float, str] | None = None
    for name in candidates:
        level = LEVELS_BY_NAME[name]
        cert = chain[names.index(name) + 1]
        key = reference_key(problem, name if not as_published else f"{name}-published", times, t0, y, P)
        path = cache_path(problem, name, key)
        loaded = load_reference(path, times, shape)
        if loaded is not None:
            y_ref, error, floor, certified_by, compute_s = loaded
            cached, cost = True, {}
        else:
            try:
                values, cost_level = run(level, reference_tol(level))
                higher, cost_cert = run(cert, certifier_tol(cert, level))
            except StiffReferenceError as exc:
                served = published_values(problem, times, as_published, start, exc)
                if served is None:
                    served = _stiff_reference(problem, times, y, t0, P, start, exc)
                if required is not None and served.max_error > required:
                    raise ReferenceError_(
                        f"ground truth for problem {problem.name!r} cannot meet `required_error` "
                        f"= {required:.3g}: the stiff problem's reference ({served.certified_by}) "
                        f"has error {served.max_error:.3g}") from exc
                return served
            y_ref, error, floor = certify(values, level, higher, cert)
            compute_s = cost_level + cost_cert
            try:
                store_reference(
                    path,
                    y=y_ref,
                    error=error,
                    floor=floor,
                    t=times,
                    certified_by=np.array(cert.name),
                    compute_s=np.array(compute_s),
                )
            except OSError as exc:  # the cache is an optimisation: a read-only disk is no error
                warnings.warn(f"reference cache not written ({path}): {exc}", stacklevel=2)
            certified_by, cached, cost = cert.name, False, {name: cost_level, cert.name: cost_cert}
        ref = Reference(problem.name, times, y_ref, error, name, certified_by,
                        time.perf_counter() - start, cached=cached, compute_s=compute_s, cost=cost,
                        form=form)
        if required is None or ref.max_error <= required:
            ref.wall_s = time.perf_counter() - start
            return ref
        if best is None or ref.max_error < best[0]:
            best = (ref.max_error, name)
        # The stored float64 value's own rounding is part of every level's error: when it alone
        # exceeds the requirement (less the spread between this level and its certifier), no
        # dearer level can succeed.
        if float(np.max(floor)) > required:
            break
    assert best is not None
    raise ReferenceError_(
        f"ground truth for problem {problem.name!r} cannot meet `required_error` = {required:.3g}: "
        f"the best certified error achieved is {best[0]:.3g} ({best[1]}, certified by "
        f"{certifier_of(best[1])}); levels available: {', '.join(available_levels())}"
    )
