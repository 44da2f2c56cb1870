"""Stiff ground truth: two independent implicit solvers at tight tolerances, cross-checked.

Where the explicit Taylor reference refuses a problem as stiff (`StiffReferenceError`), the
reference is computed twice, by scipy's Radau IIA (order 5, E. Hairer & G. Wanner's RADAU5
algorithm reimplemented in Python) and by SUNDIALS CVODE's BDF (orders 1-5, through
scikit-sundae), both with the problem's symbolic Jacobian, at rtol = `STIFF_REFERENCE_RTOL` and
atol_i = rtol x s_i x `STIFF_REFERENCE_ATOL_SHARE` (s_i the component's size along the orbit:
nearly relative control, so components that fall far below their size stay resolved). The
stored value is Radau's; its stated error is the two solvers' disagreement, max over components
|y_radau - y_cvode|, per time and member: an estimate, not a bound, which is why the two methods
share nothing but the right-hand side (one-step collocation against variable-order multistep,
two code bases), and why a problem with published end values examines the cross-check there
first (`harness.ground_truth._implicit_exam`). The level is recorded as `implicit`, certified by
`radau+cvode-bdf`.

Measured against the Bari test set's published end values (from the float64 start; load ~7):
ROBER stated 2.3e-14, actual 5.6e-15; POLLU 2.4e-14 / 2.3e-14; VDPOL 1.3e-11 / 4.6e-14; OREGO
1.7e-8 / 2.7e-11; E5 1.3e-21 / 1.3e-21 (on components of 9e-23: no correct digit, and said so).

Radau stops at every requested time (one run per member over all of them, each segment started
with the step size the last one reached), so every value is a step's end point, never the
collocation polynomial between steps (stage order 3 against the end point's order 5). Values
are kept in the process per member and time: a later request at times already computed (a
convergence sweep asks for each step size's starting values, after asking for all of them at
once) reuses them, and only missing times are integrated.

Without scikit-sundae installed the path does not apply and the stiff refusal stands. The float64
form of the problem is integrated (both solvers run in float64); a request from the published
start at the published end time gets the published values first (more accurate), see
`harness.ground_truth.published_values`.
"""

from __future__ import annotations

import threading
import time
import warnings
from collections import OrderedDict

import numpy as np
from scipy.integrate import Radau

from harness.c_streams import library_output_captured
from harness.errors import ReferenceError_, WorkLimitError
from harness.problem import Problem
from harness.tolerances import (
    STIFF_REFERENCE_ATOL_SHARE,
    STIFF_REFERENCE_MAX_EVALS,
    STIFF_REFERENCE_RTOL,
)

__all__ = ["implicit_reference", "IMPLICIT_LEVEL", "IMPLICIT_CERTIFIER", "available"]

IMPLICIT_LEVEL = "implicit"
IMPLICIT_CERTIFIER = "radau+cvode-bdf"

# Computed values per member (problem, t0, start, parameters) -> {time: (state, disagreement)},
# least recently used dropped beyond _KEPT_MEMBERS members (a cell's ensemble and its few sweeps).
_KEPT_MEMBERS = 256
_computed: OrderedDict[tuple, dict[float, tuple[np.ndarray, float]]] = OrderedDict()
_computed_lock = threading.Lock()


def available() -> bool:
    """True when both solvers can be imported (scikit-sundae is an optional extra).

    Returns
    -------
    bool: whether ``sksundae.cvode`` imports.
    """
    try:
        import sksundae.cvode  # noqa: F401
    except ImportError:
        return False
    return True


class _Counted:
    """One member's right-hand side and Jacobian, with an evaluation bound."""

    def __init__(self, problem: Problem, pars: np.ndarray, solver: str):
        self.dyn = problem.dynamics(pars.reshape(-1, 1), size=1)
        self.calls = 0
        self.problem = problem
        self.solver = solver

    def f(self, t, y):
        self.calls += 1
        if self.calls > STIFF_REFERENCE_MAX_EVALS:
            raise WorkLimitError(
                f"stiff reference for problem {self.problem.name!r}: {self.solver} needed more "
                f"than {STIFF_REFERENCE_MAX_EVALS} evaluations (stopped at t = {t!r})")
        return self.dyn.f(t, np.ascontiguousarray(y, dtype=np.float64).reshape(-1, 1))[:, 0]

    def jac(self, t, y):
        return self.dyn.jac(t, np.ascontiguousarray(y, dtype=np.float64).reshape(-1, 1))[:, :, 0]


def _radau(problem, times, y0, t0, pars, atol):
    """Radau IIA from t0 to each of `times` in turn, every time a step's end point: one solver
    per segment, started with the last unclipped step of the previous one."""
    fn = _Counted(problem, pars, "scipy Radau")
    out = np.empty((times.size, y0.size))
    t, y, first = float(t0), np.asarray(y0, dtype=np.float64), None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for i, t_next in enumerate(np.asarray(times, dtype=np.float64)):
            if t_next > t:
                solver = Radau(fn.f, t, y, float(t_next), rtol=STIFF_REFERENCE_RTOL, atol=atol,
                               jac=fn.jac, first_step=None if first is None else min(first, t_next - t))
                taken: list[float] = []
                while solver.status == "running":
                    message = solver.step()
                    taken.append(solver.step_size)
                if solver.status != "finished":
                    raise ReferenceError_(f"stiff reference for problem {problem.name!r}: scipy Radau "
                                          f"failed at t = {float(solver.t)!r}: {message}")
                t, y = float(t_next), solver.y.copy()
                first = taken[-2] if len(taken) > 1 else taken[-1]
            out[i] = y
    return out


def _cvode(problem, times, y0, t0, pars, atol):
    from sksundae.cvode import CVODE

    fn = _Counted(problem, pars, "CVODE BDF")

    def rhs(t, y, yp):
        yp[:] = fn.f(t, y)

    def jac(t, y, yp, J):
        J[:, :] = fn.jac(t, y)

    grid = np.concatenate([[t0], times]) if times[0] > t0 else times
    solver = CVODE(rhs, method="BDF", rtol=STIFF_REFERENCE_RTOL, atol=atol, jacfn=jac,
                   max_num_steps=STIFF_REFERENCE_MAX_EVALS)
    with library_output_captured() as printed:
        sol = solver.solve(grid, y0)
    # two output times: scikit-sundae returns every internal step (the last is the end point)
    rows = sol.y[-1:] if grid.size == 2 else sol.y
    if not sol.success or rows.shape[0] != (1 if grid.size == 2 else grid.size):
        said = printed.last_line()
        raise ReferenceError_(f"stiff reference for problem {problem.name!r}: CVODE BDF failed: "
                              f"{sol.message}" + (f" (SUNDIALS: {said})" if said else ""))
    return rows[-times.size:]


def implicit_reference(problem: Problem, times: np.ndarray, y0: np.ndarray, t0: float,
                       pars: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """States at `times` for every member from `y0` (dim, N) with `pars` (P, N), by the two
    solvers (see the module docstring).

    Parameters
    ----------
    problem : the problem (float64 form); times : increasing times >= t0; y0, pars : the members'
    start states and parameters; t0 : the start time.

    Returns
    -------
    y : ndarray (nt, dim, N), Radau's states; error : ndarray (nt, N), the disagreement of the two
    solvers (max over components); seconds : float, the time spent.
    """
    started = time.perf_counter()
    scale = np.asarray(problem.ensemble_perturbation.component_scale, dtype=np.float64)
    atol = STIFF_REFERENCE_RTOL * STIFF_REFERENCE_ATOL_SHARE * scale
    fingerprint = problem.fingerprint()
    ys, errors = [], []
    for n in range(y0.shape[1]):
        known = _member_values((fingerprint, float(t0), y0[:, n].tobytes(), pars[:, n].tobytes()))
        missing = np.array(sorted({float(t) for t in times} - set(known)), dtype=np.float64)
        if missing.size:
            a = _radau(problem, missing, y0[:, n], t0, pars[:, n], atol)
            b = _cvode(problem, missing, y0[:, n], t0, pars[:, n], atol)
            if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
                raise ReferenceError_(f"stiff reference for problem {problem.name!r} is not finite "
                                      f"(member {n})")
            with _computed_lock:
                known.update({float(t): (a[i], float(np.max(np.abs(a[i] - b[i]))))
                              for i, t in enumerate(missing)})
        ys.append(np.stack([known[float(t)][0] for t in times]))
        errors.append(np.array([known[float(t)][1] for t in times]))
    return np.stack(ys, axis=-1), np.stack(errors, axis=-1), time.perf_counter() - started


def _member_values(key: tuple) -> dict[float, tuple[np.ndarray, float]]:
    """The values computed so far for one member (created empty), most recently used last."""
    with _computed_lock:
        known = _computed.pop(key, None)
        _computed[key] = {} if known is None else known
        while len(_computed) > _KEPT_MEMBERS:
            _computed.popitem(last=False)
        return _computed[key]
