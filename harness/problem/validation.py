"""A problem's definition checked before anything is compiled or measured, and against its own
exact flow before a method run on it is judged.

At construction (`check_definition`, cheap, no compile): the name (`harness.names`), a non-empty
state of distinct heyoka variables, real finite start values (complex values are refused, never
cast), and a Newtonian form with one velocity per position.

Against the flow (`check_invariants_along_flow`, once per definition, on first use by an
experiment that reads invariants): a declared invariant I must satisfy
dI/dt = grad I . f + dI/dt|explicit = 0 along the problem's own float64 Taylor orbit
(`harness.scales.sample_orbit`), to INVARIANT_FLOW_RTOL of |grad I| |f| + |dI/dt|. The
derivative is formed symbolically (`hy.diff`) and evaluated at the orbit's samples; where the
terms cancel inside themselves (forces near an equilibrium) that ratio is not resolved, so an
invariant fails only when it also moves along the orbit by more than INVARIANT_FLOW_DRIFT of its
size. A declared invariant that fails is the problem's error (`ProblemError`), so no method is blamed for not
conserving it. A singularity within the span is detected from the same orbit
(`harness.scales.derive_time_scale`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from harness.errors import InputError, ProblemError
from harness.names import check_name

__all__ = ["check_definition", "check_start", "check_invariants_along_flow", "exact_state"]


def check_definition(name: Any, variables: Sequence[Any], newtonian: Any) -> str:
    """The checks of a definition's name, state variables and Newtonian form.

    Parameters
    ----------
    name : the problem's name; variables : its state variables; newtonian : its NewtonianForm
    or None.

    Returns
    -------
    str
        The name.
    """
    import heyoka as hy

    name = check_name(name, "problem `name`")
    if len(variables) == 0:
        raise InputError(f"problem {name!r}: `variables` must hold at least one state variable, "
                         "got none (an empty state has nothing to integrate)")
    for v in variables:
        if not isinstance(v, hy.expression) or hy.get_variables(v) != [str(v)]:
            raise InputError(f"problem {name!r}: `variables` must be heyoka variables "
                             f"(hy.make_vars), got {v!r}")
    if newtonian is not None:
        nq, nv = len(newtonian.positions), len(newtonian.velocities)
        if nq != nv or nq == 0:
            raise InputError(f"problem {name!r}: a Newtonian form needs one velocity per "
                             f"position, got {nq} position(s) and {nv} velocity(ies)")
    return name


def check_start(name: str, y0: Any, dim: int) -> np.ndarray:
    """`y0` as a read-only float64 array (dim,): real, finite numbers; complex values refused.

    Parameters
    ----------
    name : the problem's name; y0 : the start values given; dim : the number of variables.

    Returns
    -------
    numpy.ndarray
    """
    try:
        raw = np.asarray(y0)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"problem {name!r}: `y0` must be numbers, got {y0!r}"[:300]) from None
    if np.iscomplexobj(raw) or (raw.dtype == object and any(isinstance(x, complex)
                                                            for x in raw.ravel())):
        raise InputError(f"problem {name!r}: `y0` must be real numbers (complex values are not "
                         f"cast to real), got {y0!r}"[:300])
    if raw.dtype.kind in "USVb" or raw.dtype == bool:
        raise InputError(f"problem {name!r}: `y0` must be numbers, got {y0!r}"[:300])
    try:
        arr = np.array(raw, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"problem {name!r}: `y0` must be numbers, got {y0!r}"[:300]) from None
    if arr.shape != (dim,):
        raise InputError(f"problem {name!r}: `y0` needs {dim} values, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"problem {name!r}: `y0` must be finite, got {arr.tolist()}")
    return arr


def check_invariants_along_flow(problem) -> None:
    """Raise `ProblemError` when a declared invariant is not conserved by the problem's own
    exact flow (see the module docstring); remembered per definition (`harness.derived`)."""
    if not problem.invariants:
        return
    from harness.derived import remembered

    defects = remembered("harness.problem.validation", "invariant_defects",
                         [problem.fingerprint()], lambda: _invariant_defects(problem))
    if defects:
        worst = ", ".join(f"{k!r} (relative dI/dt = {r:.2g} at t = {t:.6g})"
                          for k, r, t in defects)
        raise ProblemError(
            f"problem {problem.name!r}: declared invariant(s) {worst} not conserved by the "
            "problem's own exact flow (dI/dt = grad I . f is not zero); the problem definition "
            "is at fault, no method is judged on it")


def _invariant_defects(problem) -> list:
    import heyoka as hy

    from harness import tolerances as tol
    from harness.scales import sample_orbit

    orbit = sample_orbit(problem)
    idx = np.arange(orbit.t.size)
    if idx.size > tol.ORBIT_MAX_SAMPLES:
        idx = np.unique(np.linspace(0, idx.size - 1, tol.ORBIT_MAX_SAMPLES).round().astype(int))
    t, y = orbit.t[idx], np.ascontiguousarray(orbit.y[:, idx])
    pars = problem.pars_for(t.size)
    names = sorted(problem.invariants)
    clock = hy.make_vars("harness_explicit_time_")
    exprs, spans = [], []
    for k in names:
        inv = problem.invariants[k]
        terms = [hy.diff(inv, v) * f for v, f in zip(problem.variables, problem.rhs, strict=True)]
        explicit = hy.subs(hy.diff(hy.subs(inv, {hy.time: clock}), clock), {clock: hy.time})
        spans.append((len(exprs), len(exprs) + len(terms) + 1))
        exprs += [*terms, explicit, inv]
    out = hy.cfunc(exprs, list(problem.variables))(y, pars=pars, time=t)
    defects = []
    for k, (a, b) in zip(names, spans, strict=True):
        rate, scale = np.abs(np.sum(out[a:b], axis=0)), np.sum(np.abs(out[a:b]), axis=0)
        values = out[b]
        with np.errstate(all="ignore"):
            drift = float(np.max(np.abs(values - values[0])) / np.max(np.abs(values)))
        if not drift > tol.INVARIANT_FLOW_DRIFT:  # kept along the orbit: cancellation, not a defect
            continue
        with np.errstate(all="ignore"):
            rel = np.where(scale > 0.0, rate / scale, np.where(rate > 0.0, np.inf, 0.0))
        rel = np.where(np.isfinite(rate), rel, 0.0)
        j = int(np.argmax(rel))
        if rel[j] > tol.INVARIANT_FLOW_RTOL:
            defects.append((k, float(rel[j]), float(t[j])))
    return defects


def exact_state(problem, t: float, y0: np.ndarray) -> np.ndarray:
    """The problem's declared exact solution at `t` from states `y0` (dim, N), checked: an
    exception it raises, or a result that is not a real finite (dim, N) array, is the problem's
    `ProblemError` (one line), never a traceback.

    Parameters
    ----------
    problem : the Problem (its `exact` is not None); t : the time; y0 : start states (dim, N).

    Returns
    -------
    numpy.ndarray
        States shaped (dim, N).
    """
    try:
        out = problem.exact(t, y0, problem.t0, problem.pars_for(y0.shape[1]))
        arr = np.asarray(out)
    except Exception as exc:  # noqa: BLE001  (a user's function: anything may be raised)
        raise ProblemError(f"problem {problem.name!r}: its exact solution raised at t = {t:g}: "
                           f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}") from None
    if np.iscomplexobj(arr) or arr.dtype.kind not in "fiu" or arr.shape != y0.shape:
        raise ProblemError(f"problem {problem.name!r}: its exact solution must return real "
                           f"states shaped {y0.shape}, got {arr.dtype} shaped {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ProblemError(f"problem {problem.name!r}: its exact solution is not finite at "
                           f"t = {t:g}")
    return arr.astype(np.float64)
