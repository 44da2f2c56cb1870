"""A problem's declared invariants checked against its own exact flow before a method run on it is
judged (the energy experiment reads this first).

A declared invariant I must satisfy dI/dt = grad I . f + dI/dt|explicit = 0 along the problem's
own float64 Taylor orbit (`harness.scales.sample_orbit`), to INVARIANT_FLOW_RTOL of
|grad I| |f| + |dI/dt|. The derivative is formed symbolically (`hy.diff`) and evaluated at the
orbit's samples; where the terms cancel inside themselves (forces near an equilibrium) that ratio
is not resolved, so an invariant fails only when it also moves along the orbit by more than
INVARIANT_FLOW_DRIFT of its size. A declared invariant that fails is the problem's error
(`ProblemError`), so no method is blamed for not conserving it.
"""

from __future__ import annotations

import heyoka as hy
import numpy as np

from harness import tolerances as tol
from harness.derived import remembered
from harness.errors import ProblemError
from harness.scales import sample_orbit

__all__ = ["check_invariants_along_flow"]


def check_invariants_along_flow(problem) -> None:
    """Raise `ProblemError` when a declared invariant is not conserved by the problem's own
    exact flow (see the module docstring); remembered per definition (`harness.derived`).

    Parameters
    ----------
    problem : Problem, with its declared invariants.
    """
    if not problem.invariants:
        return

    defects = remembered("harness.invariant_checks", "invariant_defects",
                         [problem.fingerprint()], lambda: _invariant_defects(problem))
    if defects:
        worst = ", ".join(f"{k!r} (relative dI/dt = {r:.2g} at t = {t:.6g})"
                          for k, r, t in defects)
        raise ProblemError(
            f"problem {problem.name!r}: declared invariant(s) {worst} not conserved by the "
            "problem's own exact flow (dI/dt = grad I . f is not zero); the problem definition "
            "is at fault, no method is judged on it")


def _invariant_defects(problem) -> list:
    orbit = sample_orbit(problem)
    t, y = orbit.thinned()
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
