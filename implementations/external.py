"""External peers: scipy's `solve_ivp` methods, wrapped (not reimplemented), as adaptive steppers.

`scipy-rk45`, `scipy-dop853`, `scipy-radau`, `scipy-bdf`, `scipy-lsoda`. Each `_step` integrates
every ensemble member separately from t to t + h with `scipy.integrate.solve_ivp`, at
rtol = tol (raised to scipy's own floor of 100 machine epsilons when tol is below it) and a
per-component absolute tolerance atol_i = tol x s_i, s_i the component's size along the problem's
orbit (`component_atol`: max |y_i| sampled along it, at most the start's largest component,
as the Bari test set's reports scale atol for ROBER and E5, whose small components an atol of
tol would leave uncontrolled); the
implicit methods get the problem's symbolic Jacobian, one member at a time. A solve that
scipy reports as failed (status < 0) raises `StepFailure` with scipy's message.

Evaluation counts (the harness's unit is one evaluation of the whole ensemble): the right-hand
side and Jacobian are evaluated through the run's `Dynamics` on one member at a time, so the
member calls are converted to ensemble units (member calls / N, the mean per trajectory) in
`counts['rhs']` and `counts['jac']`; the raw totals over all members are kept in
`counts['member_rhs']`, `counts['member_jac']`, beside scipy's own `counts['scipy_nfev']`,
`counts['scipy_njev']`, `counts['scipy_nlu']` (LU decompositions) and
`counts['internal_steps']` (accepted internal steps, summed over members, as for `taylor`).

References: P. Virtanen et al., SciPy 1.0, Nature Methods 17 (2020) 261-272; J. R. Dormand &
P. J. Prince, J. Comput. Appl. Math. 6 (1980) 19-26 (RK45); E. Hairer, S. P. Norsett, G. Wanner,
*Solving Ordinary Differential Equations I*, II.5 (DOP853); E. Hairer & G. Wanner, *Solving
Ordinary Differential Equations II*, IV.8 (Radau IIA, order 5); L. F. Shampine & M. W. Reichelt,
SIAM J. Sci. Comput. 18 (1997) 1-22 (variable-order NDF/BDF); L. Petzold, SIAM J. Sci. Stat.
Comput. 4 (1983) 136-148 (LSODA, automatic Adams/BDF switching).
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.integrate import solve_ivp

from harness.errors import InputError
from harness.problem import Dynamics
from harness.stepper import AdaptiveStepper, Carry, StepFailure, Stepper, StepperInfo, WorkLimitFailure
from harness.tolerances import ADAPTIVE_MAX_EVALS, SCIPY_MIN_RTOL, SCIPY_STALL_CALLS
from harness.work_projection import projected_work

__all__ = ["STEPPERS", "ScipyStepper", "SCIPY_METHODS", "MemberDynamics", "MemberByMemberStepper",
           "component_atol"]

_SCIPY = "P. Virtanen et al., SciPy 1.0, Nature Methods 17 (2020) 261-272"
_HNW1 = "Hairer, Norsett & Wanner, Solving Ordinary Differential Equations I"
_HW2 = "Hairer & Wanner, Solving Ordinary Differential Equations II"

# method -> (registry name, claimed order, explicit, uses Jacobian, typical f evals per internal
# step, reference, description)
SCIPY_METHODS: dict[str, tuple] = {
    "RK45": (
        "scipy-rk45",
        5,
        True,
        False,
        6.0,
        f"J. R. Dormand & P. J. Prince, J. Comput. Appl. Math. 6 (1980) 19-26; {_SCIPY}",
        "Dormand-Prince 5(4) embedded pair (order 5 propagated, 4 for the error estimate); "
        "7 stages, first same as last: 6 f evaluations per accepted internal step.",
    ),
    "DOP853": (
        "scipy-dop853",
        8,
        True,
        False,
        12.0,
        f"{_HNW1}, II.5 (DOP853); {_SCIPY}",
        "Dormand-Prince 8(5,3) pair; 12 f evaluations per accepted internal step.",
    ),
    "Radau": (
        "scipy-radau",
        5,
        False,
        True,
        7.0,
        f"{_HW2}, IV.8 (RADAU5); {_SCIPY}",
        "Three-stage Radau IIA collocation (order 5), simplified Newton with the problem's "
        "Jacobian; f evaluations per internal step vary with the Newton iterations (typical "
        "figure given).",
    ),
    "BDF": (
        "scipy-bdf",
        None,
        False,
        True,
        2.0,
        f"L. F. Shampine & M. W. Reichelt, SIAM J. Sci. Comput. 18 (1997) 1-22; {_SCIPY}",
        "Variable-order (1-5) numerical differentiation / backward differentiation formulas "
        "with the problem's Jacobian; order varies, so no single order is claimed; f "
        "evaluations per internal step vary with the Newton iterations (typical figure given).",
    ),
    "LSODA": (
        "scipy-lsoda",
        None,
        False,
        True,
        2.0,
        f"L. Petzold, SIAM J. Sci. Stat. Comput. 4 (1983) 136-148 (LSODA, ODEPACK); {_SCIPY}",
        "ODEPACK LSODA: switches automatically between non-stiff Adams (orders 1-12) and stiff "
        "BDF (orders 1-5), the Jacobian from the problem; order varies, so no single order is "
        "claimed; f evaluations per internal step are a typical figure.",
    ),
}


class _Stalled(Exception):
    """The solver keeps evaluating at one time value: its step size has collapsed to zero."""


class _WorkLimit(Exception):
    """One output step needed more evaluations than ADAPTIVE_MAX_EVALS allows (args: the time
    reached, and the projected evaluations when the projection stopped it early, else None)."""

    def __str__(self) -> str:
        reached, projected = self.args
        need = (f"needed more than {ADAPTIVE_MAX_EVALS} evaluations" if projected is None else
                f"would need about {projected:.3g} evaluations (projected from the recent ones), "
                f"more than {ADAPTIVE_MAX_EVALS}")
        return f"{need} (stopped at t={reached!r})"


def is_work_limit(exc: BaseException) -> bool:
    """True for the adapter's own evaluation cap (`MemberDynamics`), not a solver's failure.

    Parameters
    ----------
    exc : the exception raised by a solve.

    Returns
    -------
    bool: whether it is the evaluation cap.
    """
    return isinstance(exc, _WorkLimit)


# A hopeless span is recognised before the whole budget is spent: every PROJECTION_EVERY calls
# the evaluations the span needs are projected from the rate of the recent ones
# (`harness.work_projection`); once PROJECTION_START of ADAPTIVE_MAX_EVALS is spent, a projection over
# PROJECTION_MARGIN times the limit stops the solve (a span of 1e300 is projected ~1e290 times
# over; a span the limit allows would need a recent rate 10x slower than its average).
PROJECTION_EVERY = 1_000
PROJECTION_START = 0.1
PROJECTION_MARGIN = 10.0


class MemberDynamics:
    """One ensemble member's view of a run's `Dynamics`: same compiled functions and the same
    counters (so every call is booked), that member's parameters.

    It also watches for a stalled solver: scipy's LSODA, once its step size underflows to zero
    (e.g. at a finite-time blow-up), evaluates f at the same time forever instead of failing.
    """

    def __init__(self, dyn: Dynamics, member: int, atol: np.ndarray | float | None = None):
        self._view = dyn.member(member)  # shares `counts` and the compiled functions
        self.atol = atol  # the solve's absolute tolerance (per component), set by the stepper
        self.reset()

    def reset(self, start: float | None = None, target: float | None = None) -> None:
        """Start counting one solve from `start` to `target` (without them: no projection).

        Parameters
        ----------
        start, target : float or None, the solve's start and end times.
        """
        self._last_t = None
        self._same_t = 0
        self._calls = 0
        self._span = None if start is None or target is None or target == start else (start, target)
        self._checkpoints = [(0, 0.0)]  # (calls, fraction of the span reached), every PROJECTION_EVERY calls

    def f(self, t: float, y: np.ndarray) -> np.ndarray:
        """The right-hand side for one member, counted: past ADAPTIVE_MAX_EVALS calls (or a projected
        excess) it raises the work limit, and SCIPY_STALL_CALLS calls at one time value raise a stall.

        Parameters
        ----------
        t : float, the time; y : (dim,) the member's state.

        Returns
        -------
        ndarray (dim,): f(t, y).
        """
        self._calls += 1
        if self._calls > ADAPTIVE_MAX_EVALS:
            raise _WorkLimit(t, None)
        if self._span is not None and self._calls % PROJECTION_EVERY == 0:
            self._project(t)
        if t == self._last_t:
            self._same_t += 1
            if self._same_t >= SCIPY_STALL_CALLS:
                raise _Stalled(t)
        else:
            self._last_t = t
            self._same_t = 0
        return self._view.f(t, np.ascontiguousarray(y).reshape(-1, 1))[:, 0]

    def jac(self, t: float, y: np.ndarray) -> np.ndarray:
        """The Jacobian for one member (not counted).

        Parameters
        ----------
        t : float, the time; y : (dim,) the member's state.

        Returns
        -------
        ndarray (dim, dim): df/dy at (t, y).
        """
        return self._view.jac(t, np.ascontiguousarray(y).reshape(-1, 1))[:, :, 0]

    def _project(self, t: float) -> None:
        # the fraction of the span at this call (a stage time may lie behind an earlier one)
        start, target = self._span
        progress = max(self._checkpoints[-1][1], (t - start) / (target - start))
        projected = projected_work(self._checkpoints, self._calls, progress, 1.0)
        self._checkpoints.append((self._calls, progress))
        if (self._calls >= PROJECTION_START * ADAPTIVE_MAX_EVALS
                and projected > PROJECTION_MARGIN * ADAPTIVE_MAX_EVALS):
            raise _WorkLimit(t, projected)


def component_atol(dyn: Dynamics, tol: float) -> np.ndarray:
    """Per-component absolute tolerances tol x s_i: s_i = max |y_i| along the problem's sampled
    orbit (a component that stays zero takes its block's scale; `harness.scales`), but never
    above the start's largest component (or 1 when it is zero), so an orbit that runs away (a
    blow-up) cannot loosen the tolerance past atol = tol x |y0|.

    Parameters
    ----------
    dyn : Dynamics, the problem run; tol : float, the stepper's tolerance.

    Returns
    -------
    ndarray: one absolute tolerance per component.
    """
    problem = dyn.problem
    scale = np.asarray(problem.ensemble_perturbation.component_scale, dtype=np.float64)
    start = float(np.max(np.abs(problem.y0))) or 1.0
    return tol * np.minimum(scale, start)


class MemberByMemberStepper(AdaptiveStepper):
    """An outside library's adaptive solver run on one ensemble member at a time, from t to the
    next output time, as its users call it. Every evaluation goes through the run's `Dynamics`
    (through `MemberDynamics`) and is booked in ensemble units: counts['rhs'] and counts['jac']
    grow by the member calls / N, counts['member_rhs'] and counts['member_jac'] by the raw calls.

    A subclass writes `_solve_member` and lists in `COUNTERS` the counts it adds to.
    """

    COUNTERS: tuple[str, ...] = ("internal_steps",)

    def _library_info(self, **fields) -> StepperInfo:
        """The record of a wrapped solver: adaptive, first-order form for any right-hand side,
        family 'external', with no symplectic or symmetric claim and `extra_info()` for this
        tolerance; `fields` gives the rest (name, claimed order, cost, reference, ...)."""
        return StepperInfo(family="external", symplectic=False, symmetric=False, form="first-order",
                           velocity_dependent=True, adaptive=True, extra=self.extra_info(), **fields)

    def _solve_member(self, member: MemberDynamics, m: int, t: float, target: float,
                      y: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
        """Member `m`'s state at `target` from `y` at `t`, and what to add to its `COUNTERS`;
        raises `StepFailure` (naming the member and the span) where the solver fails."""
        raise NotImplementedError

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        atol = component_atol(dyn, self.tol)
        members = [MemberDynamics(dyn, m, atol) for m in range(y0.shape[1])]
        for key in ("member_rhs", "member_jac", *self.COUNTERS):
            dyn.counts.setdefault(key, 0)
        return Carry(t0, h, y0, members=members)

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        y = c.y
        N = y.shape[1]
        t, target = c.t, c.t0 + (c.n + 1) * c.h
        rhs0, jac0 = dyn.counts["rhs"], dyn.counts["jac"]
        try:
            for m in range(N):
                if not np.all(np.isfinite(y[:, m])):
                    continue
                member = c.members[m]
                member.reset(t, target)
                y[:, m], added = self._solve_member(member, m, t, target, y[:, m].copy())
                for key, value in added.items():
                    dyn.counts[key] += value
        finally:
            member_rhs = dyn.counts["rhs"] - rhs0
            member_jac = dyn.counts["jac"] - jac0
            dyn.counts["rhs"] = rhs0 + member_rhs / N
            dyn.counts["jac"] = jac0 + member_jac / N
            dyn.counts["member_rhs"] += member_rhs
            dyn.counts["member_jac"] += member_jac


class ScipyStepper(MemberByMemberStepper):
    """`scipy.integrate.solve_ivp(method=...)` advancing each member to the next output time."""

    COUNTERS = ("internal_steps", "scipy_nfev", "scipy_njev", "scipy_nlu")

    def __init__(self, method: str, tol: float = AdaptiveStepper.tol):
        if method not in SCIPY_METHODS:
            raise InputError(f"`method` must be one of {sorted(SCIPY_METHODS)}, got {method!r}")
        name, order, explicit, uses_jac, evals, reference, description = SCIPY_METHODS[method]
        self.method = method
        self.uses_jacobian = uses_jac
        self.tol = float(tol)
        self.info = self._library_info(
            name=name, claimed_order=order, explicit=explicit, evals_per_step=evals, reference=reference,
            implementation="scipy",
            description=(
                f"scipy.integrate.solve_ivp(method={method!r}), wrapped: {description} "
                "Each output step restarts the solver for every member from t to t + h at "
                "rtol = tol (at least scipy's floor 100 eps) and atol_i = tol x max |y_i| along "
                "the problem's orbit. evals_per_step is per "
                "accepted internal step; counts['rhs'] and counts['jac'] are in ensemble units "
                "(member calls / N), counts['internal_steps'] is summed over members."
            ),
        )

    def extra_info(self) -> dict:
        """The record's `extra` entries for this tolerance: scipy's rtol/atol, method and
        Jacobian use, and the unit the evaluation counts are in.

        Returns
        -------
        dict: the entries, JSON-safe.
        """
        return {
            "tol": self.tol,
            "rtol": max(self.tol, SCIPY_MIN_RTOL),
            "atol": self.tol,
            "atol_per_component": "tol x max|y_i| along the orbit",
            # scipy documents rtol >= 100 eps (below it rtol is raised, with a warning)
            "tol_range": [SCIPY_MIN_RTOL, None],
            "scipy_method": self.method,
            "jacobian": "symbolic (dyn.jac)" if self.uses_jacobian else "not used",
            "evals_unit": "ensemble evaluations (member calls / N)",
        }

    def _solve_member(self, member: MemberDynamics, m: int, t: float, target: float,
                      y: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
        options = {"jac": member.jac} if self.uses_jacobian else {}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # overflow: sol.status says it
                sol = solve_ivp(member.f, (t, target), y, method=self.method,
                                rtol=max(self.tol, SCIPY_MIN_RTOL), atol=member.atol, **options)
        except _Stalled as stall:
            raise StepFailure(
                f"stepper {self.info.name!r}: scipy {self.method} stalled for ensemble "
                f"member {m} between t={t!r} and t={target!r}: {SCIPY_STALL_CALLS} "
                f"consecutive evaluations at t={stall.args[0]!r} (step size collapsed "
                "to zero)"
            ) from None
        except _WorkLimit as limit:
            raise WorkLimitFailure(
                f"stepper {self.info.name!r}: scipy {self.method}, ensemble member {m} between "
                f"t={t!r} and t={target!r}: {limit}; the span is too long for tol={self.tol:g}"
            ) from None
        if sol.status < 0:
            raise StepFailure(
                f"stepper {self.info.name!r}: scipy {self.method} failed for ensemble "
                f"member {m} between t={t!r} and t={target!r} (reached "
                f"t={float(sol.t[-1])!r}): {sol.message}"
            )
        return sol.y[:, -1], {"internal_steps": sol.t.size - 1, "scipy_nfev": int(sol.nfev),
                              "scipy_njev": int(sol.njev), "scipy_nlu": int(sol.nlu)}


STEPPERS: list[Stepper] = [ScipyStepper(method) for method in SCIPY_METHODS]
