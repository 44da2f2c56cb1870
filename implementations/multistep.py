"""Linear multistep methods: (alpha, beta) tables plus one step loop for explicit and implicit ones.

`ab2`, `ab3`, `ab4` (Adams-Bashforth), `am3` (the two-step Adams-Moulton method, order 3) and
`bdf2` (second-order backward differentiation formula). A k-step method
sum_j alpha_j y_{n+j} = h sum_j beta_j f_{n+j} needs k - 1 starting values beyond y_0; they come
from a stated source, the `starter`, recorded in `info.extra['starter']` and the description,
because a low-order start spoils the measured order:
- 'reference': the certified ground truth (`harness.ground_truth.reference`) at t0 + h, ...;
- a registered one-step stepper's name (default 'rk4', the classical Runge-Kutta method), or a
  `Stepper` object, run through the stepper contract with the same `Dynamics`, so its evaluations
  are counted with the multistep method's. An implicit table whose explicit starter would step
  outside its real stability interval (h x the fastest decay rate at y_0 beyond it: a stiff
  problem at a coarse step) is started from the certified ground truth instead, counted in
  `counts['reference_start']`.
Implicit tables are solved by Newton's method (`implementations.implicit_rk.newton_solve`); the
derivative at the new point is recovered from the converged equation, not re-evaluated.

References: course material 004_bfdbb1594143ed8b.txt (two-step Adams-Bashforth, fourth-order
Adams-Bashforth Y_{n+1} = Y_n + h/24 (55 R_n - 59 R_{n-1} + 37 R_{n-2} - 9 R_{n-3}), the trapezoidal
Adams-Moulton rule, and the need for a one-step starter); E. Hairer, S. P. Norsett, G. Wanner,
*Solving Ordinary Differential Equations I*, III.1 (Adams methods, BDF) and III.2 (order).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from harness.coefficients import LinearMultistep
from harness.errors import IncompatibleError, InputError, UnknownNameError
from harness.facts import method_facts
from harness.ground_truth import reference
from harness.methods import Method
from harness.problem import Dynamics
from harness.registry import get_stepper
from harness.stepper import Carry, Stepper, check_compatible
from harness.tolerances import NEWTON_MAX_ITER, NEWTON_TOL
from implementations import coefficient_info
from implementations.implicit_rk import NewtonSettings, NewtonStepper, newton_solve

__all__ = ["METHODS", "STEPPERS", "LinearMultistepStepper", "AB2", "AB3", "AB4", "AM3", "BDF2"]

DEFAULT_STARTER = "rk4"


def _starting_values_text(k: int) -> str:
    if k == 1:
        return "No starting value beyond y_0 is needed, so none comes"
    if k == 2:
        return "The starting value y_1 comes"
    return f"The starting values y_1..y_{k - 1} come"


class LinearMultistepStepper(NewtonStepper):
    """One step loop for every linear multistep table, explicit or implicit.

    The carry holds the last k states (oldest first) with their derivatives (evaluated lazily,
    only where a beta needs them) and `pending`: states already known ahead of the current one
    (the starting values after `_start`, the stored history after `_reverse`). A step first
    consumes a pending value; only then does it apply the multistep formula.
    `_reverse` reverses the history order and negates h: the stored past becomes the pending
    future of the backward run, so a round trip retraces exactly the points it visited.
    """

    def __init__(
        self,
        table: LinearMultistep,
        *,
        name: str,
        claimed_order: int,
        reference: str,
        description: str,
        starter: str | Stepper = DEFAULT_STARTER,
        newton: str = "full",
        newton_tol: float = NEWTON_TOL,
        newton_max_iter: int = NEWTON_MAX_ITER,
        stability: dict | None = None,
    ):
        if not isinstance(table, LinearMultistep):
            raise InputError(f"`table` must be a LinearMultistep, got {type(table).__name__}")
        if isinstance(starter, Stepper):
            starter_name = starter.info.name
        elif isinstance(starter, str) and starter.strip():
            starter_name = starter
        else:
            raise InputError(
                f"`starter` must be 'reference', a registered stepper name or a Stepper, got {starter!r}"
            )
        if isinstance(starter, LinearMultistepStepper):
            raise InputError(
                f"`starter` must be a one-step method, got the multistep method {starter_name!r}"
            )
        self.coefficients = table
        self.history_length = table.steps
        # extrapolation weights through k equally spaced states (oldest first) to the next one:
        # w_j = (-1)^(k-1-j) C(k, j)
        self._predictor = [
            float((-1) ** (table.steps - 1 - j) * math.comb(table.steps, j)) for j in range(table.steps)
        ]
        self.starter = starter
        self.starter_name = starter_name
        self.newton = NewtonSettings(newton_tol, newton_max_iter, newton)
        k = table.steps
        explicit = bool(table.explicit)
        if explicit:
            cost = "1 f evaluation per step"
            evals = 1.0
        else:
            cost = (
                f"implicit: {self.newton.describe()} (increments scaled by 1 + |y_n|) from the "
                "extrapolated history as first iterate; 1 f evaluation per iteration and 1 "
                f"Jacobian evaluation per {'iteration' if self.newton.mode == 'full' else 'step'}; "
                "evals_per_step is a typical figure (two iterations), "
                "measured counts (counts['newton_iterations']) are recorded with every run"
            )
            evals = 2.0
        start = (
            "the certified ground truth"
            if starter_name == "reference"
            else f"the one-step method {starter_name!r}"
        )
        self.info = coefficient_info(
            table,
            family="multistep",
            name=name,
            claimed_order=claimed_order,
            explicit=explicit,
            evals_per_step=evals,
            reference=reference,
            description=(
                f"{description} {k}-step; {cost}. {_starting_values_text(k)} from {start} "
                f"(starter={starter_name!r}); the starter's own evaluations are counted."
            ),
            extra={
                "starter": starter_name,
                "steps": k,
                **({"stability": dict(stability)} if stability else {}),
                **({} if explicit else {"newton": self.newton.mode, "newton_tol": self.newton.tol}),
            },
        )

    def with_starter(self, starter: str | Stepper) -> LinearMultistepStepper:
        """The same method with another source of starting values.

        Parameters
        ----------
        starter : a registered stepper's name, a Stepper, or 'reference' (the ground truth).

        Returns
        -------
        LinearMultistepStepper: a new stepper.
        """
        return self._rebuild(starter=starter)

    def incompatibility(self, problem) -> str | None:
        """Why this stepper cannot run `problem`, or None.

        Parameters
        ----------
        problem : the Problem asked about.

        Returns
        -------
        str or None: its starter is unusable or cannot run the problem (never with the reference
        starter).
        """
        if self.starter_name == "reference":
            return None
        try:
            starter = self._starter_stepper()
        except (UnknownNameError, InputError) as exc:
            return f"its starter cannot be used: {exc}"
        if not starter.compatible(problem):
            return f"its starter {self.starter_name!r} cannot run this problem"
        return None

    # -- starting values ---------------------------------------------------------------------------
    def _starter_stepper(self) -> Stepper:
        if isinstance(self.starter, Stepper):
            return self.starter

        starter = get_stepper(self.starter)
        if isinstance(starter, LinearMultistepStepper):
            raise InputError(
                f"`starter` must be a one-step method, got the multistep method {self.starter!r}"
            )
        return starter

    def starting_values(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> list:
        """y_1 .. y_{k-1} from the starter (its evaluations counted in `dyn`); shared with the
        compiled loop of the same method.

        Parameters
        ----------
        dyn : Dynamics, the problem run; t0 : float, the start time; y0 : (dim, N) the start states;
        h : float, the step.

        Returns
        -------
        list of ndarray: k - 1 states, y_1 first. Raises IncompatibleError when the starter cannot run
        the problem.
        """
        count = self.coefficients.steps - 1
        if count == 0:
            return []
        if self.starter_name == "reference":
            return self._reference_start(dyn, t0, y0, h, count)
        else:
            starter = self._starter_stepper()
            try:
                check_compatible(starter, dyn.problem)
            except IncompatibleError as exc:
                raise IncompatibleError(f"starter of {self.info.name!r}: {exc}") from None
            if not self.coefficients.explicit and _start_unstable(starter, dyn, t0, y0, h):
                dyn.counts["reference_start"] = dyn.counts.get("reference_start", 0) + 1
                return self._reference_start(dyn, t0, y0, h, count)
            values = starter.first_steps(dyn, t0, y0, h, count)
        dyn.counts["starter_steps"] = dyn.counts.get("starter_steps", 0) + count
        return values

    def reference_times(self, problem, t0: float, y0: np.ndarray, h: float) -> np.ndarray:
        """t0 + h, ..., t0 + (k - 1) h where the starting values come from the ground truth (the
        'reference' starter, or an implicit table whose explicit starter would be unstable at h,
        as `starting_values` decides); empty otherwise.

        Parameters
        ----------
        problem : Problem; t0 : float; y0 : ndarray (dim, N); h : float, the step.

        Returns
        -------
        ndarray: the times (empty when the starter runs).
        """
        count = self.coefficients.steps - 1
        times = t0 + h * np.arange(1, count + 1)
        if count == 0 or self.starter_name == "reference":
            return times
        if self.coefficients.explicit:
            return np.empty(0)
        try:
            starter = self._starter_stepper()
        except (UnknownNameError, InputError):
            return np.empty(0)
        y = np.asarray(y0, dtype=np.float64).reshape(problem.dim, -1)
        unstable = _start_unstable(starter, problem.dynamics(None, y.shape[1]), t0, y, h)
        return times if unstable else np.empty(0)

    def _reference_start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float, count: int) -> list:
        times = t0 + h * np.arange(1, count + 1)
        ref = reference(dyn.problem, times, y0.copy(), t0=t0, pars=dyn.pars)
        dyn.counts["starter_steps"] = dyn.counts.get("starter_steps", 0) + count
        return [np.array(ref.y[i], dtype=np.float64) for i in range(count)]

    # -- contract ----------------------------------------------------------------------------------
    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        pending = [(y, None) for y in self.starting_values(dyn, t0, y0, h)]
        return Carry(t0, h, y0, hist_y=[y0], hist_f=[None], pending=pending)

    def _start_from_history(self, dyn: Dynamics, t0: float, h: float, history: list) -> Carry:
        """A carry at t0 + (k-1) h holding the given exact states (oldest first) as its history,
        so the next step applies the multistep formula itself (local error measurement)."""
        k = len(history)
        return Carry(t0 + (k - 1) * h, h, history[-1], hist_y=list(history), hist_f=[None] * k, pending=[])

    def _push(self, c: Carry, y: np.ndarray, f: np.ndarray | None) -> None:
        k = self.coefficients.steps
        c.hist_y.append(y)
        c.hist_f.append(f)
        if len(c.hist_y) > k:
            del c.hist_y[0]
            del c.hist_f[0]
        c.y = y

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        if c.pending:
            y, f = c.pending.pop(0)
            self._push(c, y, f)
            return
        table = self.coefficients
        k = table.steps
        alpha, beta = table.alpha, table.beta
        t, h = c.t, c.h
        hist_y, hist_f = c.hist_y, c.hist_f
        if not np.all(np.isfinite(hist_y[-1])):
            self._push(c, np.full_like(hist_y[-1], np.nan), None)
            return
        psi = np.zeros_like(hist_y[-1])
        for j in range(k):
            if alpha[j] != 0.0:
                psi -= alpha[j] * hist_y[j]
            if beta[j] != 0.0:
                if hist_f[j] is None:
                    hist_f[j] = dyn.f(t - (k - 1 - j) * h, hist_y[j])
                psi += (h * beta[j]) * hist_f[j]
        if table.explicit:
            self._push(c, psi, None)
            return
        t_new = t + h
        hb = h * beta[k]
        dim, N = psi.shape
        eye = np.eye(dim)
        y_n = hist_y[-1]

        def residual(x: np.ndarray) -> np.ndarray:
            return x - psi - hb * dyn.f(t_new, x)

        if self.newton.mode == "full":

            def matrix(x: np.ndarray) -> np.ndarray:
                return eye - hb * dyn.jac(t_new, x).transpose(2, 0, 1)

        else:

            def matrix(x: np.ndarray) -> np.ndarray:
                return eye - hb * dyn.jac(t, y_n).transpose(2, 0, 1)

        # first iterate: the polynomial through the stored states, extrapolated one step
        guess = sum(w * yj for w, yj in zip(self._predictor, hist_y, strict=True))
        y_new = newton_solve(
            residual,
            matrix,
            guess,
            1.0 / (1.0 + np.abs(y_n)),
            settings=self.newton,
            counts=dyn.counts,
            stepper=self.info.name,
            t=t,
        )
        self._push(c, y_new, (y_new - psi) / hb)

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        super()._reverse(dyn, c)
        known = list(zip(c.hist_y, c.hist_f, strict=True))  # oldest .. current
        ahead = [(y, f) for y, f in reversed(known[:-1])]  # the past, now ahead
        behind = [(y, f) for y, f in reversed(c.pending)] + [known[-1]]  # the future, now behind
        behind = behind[-self.coefficients.steps :]
        c.hist_y = [y for y, _ in behind]
        c.hist_f = [f for _, f in behind]
        c.pending = ahead
        c.y = c.hist_y[-1]


def _start_unstable(starter: Stepper, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> bool:
    """Whether an explicit starter's first steps lie outside its real stability interval: h times
    the fastest decay rate at the start, max over members of -Re(lambda) of the Jacobian at y0,
    exceeds the interval derived from the starter's coefficients (`harness.facts.method_facts`;
    rk4: 2.785). Its starting values would then be amplified by ~|R(h lambda)| >> 1 (rk4 at
    h lambda = -5e7 on POLLU: y_1 ~ 1e12), which no later step of a zero-stable method undoes
    (Hairer & Wanner II, IV.2: stability of explicit methods on stiff problems).
    False for implicit or claim-only starters and when the Jacobian is not finite."""
    facts = method_facts(starter)
    interval = facts.real_interval
    if not facts.explicit or interval is None or not math.isfinite(interval):
        return False
    # the harness's check, not the method's work: a Dynamics of its own keeps the run's counts
    jac = dyn.problem.dynamics(dyn.pars, y0.shape[1]).jac(t0, y0)
    if not np.all(np.isfinite(jac)):
        return False
    rates = [-np.linalg.eigvals(jac[:, :, j]).real.min() for j in range(jac.shape[2])]
    return bool(abs(h) * max(rates) > interval)


# -- tables (data), oldest coefficient first ------------------------------------------------------
def _fr(*values: int | str) -> list[Fraction]:
    return [Fraction(v) for v in values]


AB2 = LinearMultistep("ab2", alpha=_fr(0, -1, 1), beta=_fr("-1/2", "3/2", 0))
AB3 = LinearMultistep("ab3", alpha=_fr(0, 0, -1, 1), beta=_fr("5/12", "-16/12", "23/12", 0))
AB4 = LinearMultistep("ab4", alpha=_fr(0, 0, 0, -1, 1), beta=_fr("-9/24", "37/24", "-59/24", "55/24", 0))
AM3 = LinearMultistep("am3", alpha=_fr(0, -1, 1), beta=_fr("-1/12", "8/12", "5/12"))
BDF2 = LinearMultistep("bdf2", alpha=_fr("1/3", "-4/3", 1), beta=_fr(0, 0, "2/3"))

_COURSE_ODE = (
    "course material 004_bfdbb1594143ed8b.txt (A. Mignone, lecture notes 'Ordinary Differential "
    "Equations: Initial Value Problems', Univ. Torino 2017-18)"
)
_HNW = "Hairer, Norsett & Wanner, Solving Ordinary Differential Equations I"
# Real stability intervals (-x, 0) claimed below: Hairer & Wanner, Solving ODEs II, V.1
# (Adams methods: ab2 1, ab3 6/11, ab4 3/10, two-step Adams-Moulton 6; bdf2 is A-stable).

METHODS: list[Method] = [
    Method(
        AB2,
        claimed_order=2,
        reference=f"{_COURSE_ODE}, the two-step Adams-Bashforth method; {_HNW}, III.1.",
        description="Adams-Bashforth y_{n+1} = y_n + h (3/2 f_n - 1/2 f_{n-1}).",
        stability={"real_interval": 1.0},
    ),
    Method(
        AB3,
        claimed_order=3,
        reference=f"{_HNW}, III.1, Table 1.1 (explicit Adams methods).",
        description="Adams-Bashforth y_{n+1} = y_n + h/12 (23 f_n - 16 f_{n-1} + 5 f_{n-2}).",
        stability={"real_interval": 6.0 / 11.0},
    ),
    Method(
        AB4,
        claimed_order=4,
        reference=f"{_COURSE_ODE}, the fourth-order Adams-Bashforth method; {_HNW}, III.1.",
        description="Adams-Bashforth y_{n+1} = y_n + h/24 (55 f_n - 59 f_{n-1} + 37 f_{n-2} - 9 f_{n-3}).",
        stability={"real_interval": 0.3},
    ),
    Method(
        AM3,
        claimed_order=3,
        reference=f"{_HNW}, III.1, Table 1.2 (implicit Adams methods, k = 2).",
        description="Implicit Adams-Moulton y_{n+1} = y_n + h/12 (5 f_{n+1} + 8 f_n - f_{n-1}), solved "
        "by Newton's method.",
        stability={"real_interval": 6.0},
    ),
    Method(
        BDF2,
        claimed_order=2,
        reference=f"{_HNW}, III.1, eq. (1.22'); C. F. Curtiss & J. O. Hirschfelder, PNAS 38 (1952) 235 "
        "(backward differentiation formulas).",
        description="Backward differentiation formula y_{n+1} - 4/3 y_n + 1/3 y_{n-1} = 2/3 h f_{n+1}; "
        "A-stable, solved by Newton's method.",
        stability={"real_interval": math.inf},
    ),
]

STEPPERS: list[Stepper] = [s for m in METHODS for s in m.steppers()]
