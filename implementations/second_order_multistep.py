"""Second-order linear multistep methods for x'' = a(x, t): (alpha, beta) tables plus one loop.

A k-step method sum_j alpha_j x_{n+j} = h^2 sum_j beta_j a_{n+j} (`SecondOrderMultistep`; Hairer,
Norsett & Wanner I, III.10) generalises the course's two-step Stormer rule (course-material file
000, eq. (5)). Records:

- Stormer k = 2..8 (explicit, order k; k = 2 is `stormer-verlet`, the course's two-step form
  with its Taylor start and central-difference velocity) and Cowell k = 2, 4..8 (implicit, order k + 1; Cowell
  k = 2 is Numerov's method, order 4, and Cowell k = 3 has the same coefficients because
  sigma*_3 = 0): x_{n+1} - 2 x_n + x_{n-1} = h^2 sum_j sigma_j nabla^j a_n (Stormer) or
  h^2 sum_j sigma*_j nabla^j a_{n+1} (Cowell), with the generating functions
  sum sigma_j t^j = (t / log(1 - t))^2 / (1 - t) and sum sigma*_j t^j = (t / log(1 - t))^2
  (HNW I, III.10, eqs. (10.6)-(10.8)), expanded here in exact rational arithmetic;
- Quinlan & Tremaine's symmetric methods SL8, SL10, SL12 (AJ 100 (1990) 1694, Table 1) and
  Quinlan's 8A and 8B (astro-ph/9901136, 1999), symmetric explicit k-step methods of order k
  whose spurious roots lie on the unit circle; transcribed as integers over a denominator from
  the Principia project's table of methods (integrators/methods.hpp), and checked here by their
  order from the coefficients.

The loop (`SecondOrderMultistepStepper`):
- starting values x_1 .. x_(H-1) (H = the history kept, below) come from heyoka's adaptive Taylor
  integrator at tolerance eps (`taylor`, variable order, a one-step method of order above every
  record's): their error is ~eps |y| each, far below any error a sweep measures, and their
  evaluations are counted as the run's (`starter_steps`, `internal_steps`);
- explicit tables step x_{n+k} directly (one force evaluation per step); implicit (Cowell)
  tables solve x = psi + h^2 beta_k a(x) by simplified Newton iterations (one Jacobian per step)
  from the polynomial extrapolation of the history, to NEWTON_TOL (a `StepFailure` after
  NEWTON_MAX_ITER);
- velocities are reconstructed by v_n = (x_n - x_(n-1)) / h + h sum_(j<m) c_j a_(n-j), the exact
  identity v_n = (x_n - x_(n-1)) / h + (1/h) int (s - t_(n-1)) a(s) ds with a replaced by its
  interpolant at the last m points, c_j = int_0^1 u l_j(u) du: order m + 1. The loop keeps
  m = H = max(k, p - 1) points, so the velocity's order is at least the method's p.
Reversing time turns the stored history into the pending future, like the first-order loop.
"""

from __future__ import annotations

from fractions import Fraction
from math import comb

import numpy as np

from harness.coefficients import SecondOrderMultistep
from harness.errors import CoefficientError, IncompatibleError
from harness.methods import Method
from harness.problem import Dynamics
from harness.registry import get_stepper
from harness.stepper import Carry, StepFailure, Stepper, check_compatible
from harness.theory.newtonian import velocity_weights
from harness.tolerances import NEWTON_MAX_ITER, NEWTON_TOL
from implementations import coefficient_info
from implementations.verlet import solve_members

__all__ = ["METHODS", "STEPPERS", "SecondOrderMultistepStepper", "stormer_table", "cowell_table",
           "velocity_weights", "START_KINDS"]

#: How the loop gets x_1 .. x_(H-1): from a one-step `starter` stepper, or (two-step tables of
#: order <= 2) the course's Taylor polynomial x_1 = x_0 + h v_0 + h^2 a_0 / 2.
START_KINDS = ("starter", "taylor-polynomial")


# -- coefficients from the generating functions -------------------------------------------------
def _series_inverse(a: list[Fraction], n: int) -> list[Fraction]:
    out = [1 / a[0]]
    for m in range(1, n):
        out.append(-sum(a[i] * out[m - i] for i in range(1, min(m, len(a) - 1) + 1)) / a[0])
    return out


def _sigma(n: int, stormer: bool) -> list[Fraction]:
    """The first n coefficients of (t / log(1 - t))^2 (Cowell) or that over (1 - t) (Stormer)."""
    # t / log(1 - t) = -1 / sum_(i>=0) t^i / (i + 1)
    inv = _series_inverse([Fraction(1, i + 1) for i in range(n + 1)], n)
    g = [-c for c in inv]
    sq = [sum(g[i] * g[m - i] for i in range(m + 1)) for m in range(n)]
    if stormer:
        sq = [sum(sq[: m + 1]) for m in range(n)]
    return sq


def _backward_to_table(sigma: list[Fraction], newest: int, k: int) -> list[Fraction]:
    """beta_0..beta_k from sum_j sigma_j nabla^j a_(n+newest) (oldest coefficient first)."""
    beta = [Fraction(0)] * (k + 1)
    for j, s in enumerate(sigma):
        for i in range(j + 1):  # nabla^j a_m = sum_i (-1)^i C(j, i) a_(m-i)
            beta[k - (1 - newest) - i] += s * (-1) ** i * comb(j, i)
    return beta


def stormer_table(k: int) -> SecondOrderMultistep:
    """Stormer's explicit k-step method, order k (k >= 2).

    Parameters
    ----------
    k : int, the number of steps.

    Returns
    -------
    SecondOrderMultistep: named 'stormer<k>', coefficients exact.
    """
    beta = _backward_to_table(_sigma(k, True), 0, k)
    alpha = [Fraction(0)] * (k - 2) + [Fraction(1), Fraction(-2), Fraction(1)]
    return SecondOrderMultistep(f"stormer{k}", alpha, beta)


def cowell_table(k: int) -> SecondOrderMultistep:
    """Cowell's implicit method with differences up to nabla^k of a_(n+1) (k >= 2), over the
    k + 1 points n+1 .. n+1-k; trailing zero coefficients (sigma*_3 = 0) shorten it.

    Parameters
    ----------
    k : int, the highest backward difference (the table may have fewer steps).

    Returns
    -------
    SecondOrderMultistep: the exact table 'cowell<k>'.
    """
    sigma = _sigma(k + 1, False)
    steps = k
    while steps > 2 and sigma[steps] == 0:
        steps -= 1
    beta = _backward_to_table(sigma[: steps + 1], 1, steps)
    alpha = [Fraction(0)] * (steps - 2) + [Fraction(1), Fraction(-2), Fraction(1)]
    return SecondOrderMultistep(f"cowell{k}", alpha, beta)


def _symmetric(name: str, half_alpha: list, half_beta: list, denominator: int) -> SecondOrderMultistep:
    """A symmetric table from its first half (alpha_0.., beta_0..) as published."""
    a = [Fraction(x) for x in half_alpha]
    b = [Fraction(x, denominator) for x in half_beta]
    return SecondOrderMultistep(name, a + a[-2::-1], b + b[-2::-1])


def _extrapolation_weights(m: int) -> np.ndarray:
    """Weights of the polynomial through m equally spaced values (oldest first), at the next."""
    w = []
    for j in range(m):
        num = Fraction(1)
        for i in range(m):
            if i != j:
                num *= Fraction(m - i, j - i)
        w.append(float(num))
    return np.array(w)


# -- the loop -----------------------------------------------------------------------------------
class SecondOrderMultistepStepper(Stepper):
    """One step loop for every `SecondOrderMultistep` table (see the module docstring)."""

    def __init__(self, table: SecondOrderMultistep, *, claimed_order: int, reference: str,
                 description: str = "", starter: str = "taylor", start: str = "starter",
                 velocity_points: int | None = None, on_request: bool = False):
        if not isinstance(table, SecondOrderMultistep):
            raise CoefficientError(f"`table` must be a SecondOrderMultistep, got {type(table).__name__}")
        if start not in START_KINDS:
            raise CoefficientError(f"`start` must be one of {START_KINDS}, got {start!r}")
        self.coefficients = table
        k = table.steps
        p = int(table.order())
        m = max(k, p - 1) if velocity_points is None else velocity_points
        if not isinstance(m, int) or m < max(1, p - 1):
            raise CoefficientError(
                f"`velocity_points` of {table.name!r} must be an integer >= max(1, p - 1) = "
                f"{max(1, p - 1)} (the velocity formula has order m + 1), got {velocity_points!r}")
        self.history_length = k
        self._keep = max(k, m)
        #: positions the loop keeps (and starts): the k of the recurrence, or the velocity formula's m
        self.kept_points = self._keep
        self._vel_points = m
        if start == "taylor-polynomial" and (self._keep != 2 or p > 2):
            raise CoefficientError(
                f"`start` 'taylor-polynomial' gives x_1 only, to O(h^3): {table.name!r} needs "
                f"{self._keep - 1} starting values and has order {p} (allowed: 2 steps, order <= 2)")
        # with the Taylor start the loop is one-step: no starter stepper
        self.starter = starter if start == "starter" else None
        self._vel = np.array([float(c) for c in velocity_weights(m)])
        self._predict = _extrapolation_weights(k)
        if start == "starter":
            start_text = (f"x_1..x_{self._keep - 1} from the one-step method {starter!r} (heyoka's "
                          "adaptive Taylor integrator at tolerance eps: error ~eps |y| per value)")
        else:
            start_text = "Taylor: x_1 = x_0 + h v_0 + h^2 a_0 / 2 (course-material file 000)"
        extra = {
            "start": start_text,
            "velocity": (f"v_n = (x_n - x_(n-1))/h + h sum_(j<{m}) c_j a_(n-j) (interpolated "
                         f"acceleration, order {m + 1})"),
        }
        if self.starter is not None:
            extra["starter"] = starter
        if on_request:
            extra["on_request"] = True
        claims = {}
        if self.one_step_verlet:
            claims = {"symplectic": True}
            extra["velocity"] += ("; for this table (x_n - x_(n-1))/h + h a_n/2 = (x_(n+1) - "
                                  "x_(n-1))/2h, the central difference")
        self.info = coefficient_info(
            table, family="second-order-multistep", form="newtonian", claimed_order=claimed_order,
            explicit=bool(table.explicit), evals_per_step=1.0 if table.explicit else 2.0,
            reference=reference, description=description, extra=extra, **claims)

    @property
    def one_step_verlet(self) -> bool:
        """Whether the observed map (x_n, v_n) -> (x_(n+1), v_(n+1)) is velocity Verlet in exact
        arithmetic (Hairer, Lubich & Wanner, GNI, I.1.4), hence symplectic: Stormer's table
        (alpha, beta) = ((1, -2, 1), (0, 1, 0)), the Taylor start and the one-point velocity
        v_n = (x_n - x_(n-1))/h + h a_n/2."""
        c = self.coefficients
        return (self.starter is None and c.steps == 2 and self._vel_points == 1
                and list(c.beta) == [0.0, 1.0, 0.0])

    # -- history --------------------------------------------------------------------------------
    def _starter_stepper(self) -> Stepper:
        return get_stepper(self.starter)

    def incompatibility(self, problem) -> str | None:
        """The family's own reason not to run `problem`, else its starter's, else None.

        Parameters
        ----------
        problem : a Problem.

        Returns
        -------
        str or None: one sentence.
        """
        own = super().incompatibility(problem)
        if own:
            return own
        if self.starter is not None and not self._starter_stepper().compatible(problem):
            return f"its starter {self.starter!r} cannot run this problem"
        return None

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        if self.starter is None:  # x_1 = x_0 + h v_0 + h^2 a_0 / 2
            nq = dyn.nq
            x0 = y0[:nq].copy()
            a0 = dyn.accel(t0, x0)
            c = Carry(t0, h, y0)
            c.hist = [[x0, a0, y0.copy()]]
            c.pending = [[x0 + h * y0[nq:] + (0.5 * h * h) * a0, None, None]]
            return c
        starter = self._starter_stepper()
        try:
            check_compatible(starter, dyn.problem)
        except IncompatibleError as exc:
            raise IncompatibleError(f"starter of {self.info.name!r}: {exc}") from None
        count = self._keep - 1
        values = starter.first_steps(dyn, t0, y0, h, count) if count else []
        dyn.counts["starter_steps"] = dyn.counts.get("starter_steps", 0) + count
        nq = dyn.nq
        c = Carry(t0, h, y0)
        c.hist = [[y0[:nq].copy(), None, y0.copy()]]  # [x, a, observed state or None], oldest first
        c.pending = [[y[:nq].copy(), None, y] for y in values]
        return c

    def _start_from_history(self, dyn: Dynamics, t0: float, h: float, history: list) -> Carry:
        """A carry holding exact states as its history (local error of the recurrence)."""
        k = len(history)
        nq = dyn.nq
        c = Carry(t0 + (k - 1) * h, h, history[-1])
        c.hist = [[y[:nq].copy(), None, y] for y in history]
        c.pending = []
        return c

    def _push(self, c: Carry, entry: list) -> None:
        c.hist.append(entry)
        if len(c.hist) > self._keep:
            del c.hist[0]

    def _accel(self, dyn: Dynamics, c: Carry, i: int) -> np.ndarray:
        """a at the stored point i (negative: -1 is the newest, at time c.t), evaluated once."""
        entry = c.hist[i]
        if entry[1] is None:
            entry[1] = dyn.accel(c.t + (i + 1) * c.h, entry[0])
        return entry[1]

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        if c.pending:
            self._push(c, c.pending.pop(0))
            return
        table = self.coefficients
        k = table.steps
        alpha, beta = table.alpha, table.beta
        h2 = c.h * c.h
        if not np.all(np.isfinite(c.hist[-1][0])):
            self._push(c, [np.full_like(c.hist[-1][0], np.nan), None, None])
            return
        psi = np.zeros_like(c.hist[-1][0])
        for j in range(k):  # stored points -k .. -1 are x_n .. x_(n+k-1)
            i = j - k
            if alpha[j] != 0.0:
                psi -= alpha[j] * c.hist[i][0]
            if beta[j] != 0.0:
                psi += (h2 * beta[j]) * self._accel(dyn, c, i)
        if table.explicit:
            self._push(c, [psi, None, None])
            return
        t_new = c.t + c.h
        hb = h2 * beta[k]
        x = sum(w * c.hist[j - k][0] for j, w in enumerate(self._predict))
        # simplified Newton on G(x) = x - psi - hb a(x): the Jacobian I - hb da/dx once, at the
        # polynomial extrapolation of the history (a fixed-point iteration would need ~20
        # iterations where hb |da/dx| nears 0.2)
        nq = x.shape[0]
        state = np.concatenate([x, np.zeros_like(x)])
        M = np.eye(nq)[:, :, None] - hb * dyn.jac(t_new, state)[nq:, :nq]
        correction = np.inf
        for _ in range(NEWTON_MAX_ITER):
            residual = x - psi - hb * dyn.accel(t_new, x)
            dx = solve_members(M, residual)
            x = x - dx
            correction = float(np.max(np.abs(dx) / (1.0 + np.abs(x))))
            if correction <= NEWTON_TOL:
                self._push(c, [x, None, None])
                return
            if not np.isfinite(correction):
                break
        raise StepFailure(f"stepper {self.info.name!r}: the implicit position at t={t_new!r} did not "
                          f"converge in {NEWTON_MAX_ITER} simplified Newton iterations (last relative "
                          f"correction {correction:.3g}, tolerance {NEWTON_TOL:g})")

    def _observe(self, dyn: Dynamics, c: Carry) -> np.ndarray:
        entry = c.hist[-1]
        if entry[2] is not None:
            return entry[2].copy()
        m = len(c.hist)
        x = entry[0]
        v = (x - c.hist[-2][0]) / c.h
        m = min(m, self._vel_points)
        w = self._vel if m == self._vel_points else np.array([float(u) for u in velocity_weights(m)])
        for j in range(m):
            v += (c.h * w[j]) * self._accel(dyn, c, -1 - j)
        return np.concatenate([x, v])

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        super()._reverse(dyn, c)
        ahead = list(reversed(c.hist[:-1]))  # the past, now ahead
        behind = list(reversed(c.pending)) + [c.hist[-1]]  # the future, now behind
        c.hist = behind[-self._keep:]
        c.pending = ahead


# -- records ------------------------------------------------------------------------------------
_HNW = "Hairer, Norsett & Wanner, Solving Ordinary Differential Equations I, III.10"
_QT = ("G.D. Quinlan & S. Tremaine, Symmetric multistep methods for the numerical integration of "
       "planetary orbits, AJ 100 (1990) 1694, Table 1; coefficients as in the Principia project's "
       "integrators/methods.hpp")
_Q99 = ("G.D. Quinlan, Resonances and instabilities in symmetric multistep methods, "
        "astro-ph/9901136 (1999); coefficients as in the Principia project's integrators/methods.hpp")
DEFAULT = {"stormer-verlet", "stormer4", "cowell2", "quinlan-tremaine8"}
#: Stormer's two-step rule as the course runs it: its own record, the k = 2 member of the family
STORMER_VERLET = SecondOrderMultistep("stormer-verlet", [1, -2, 1], [0, 1, 0])

_TABLES = (
    [(STORMER_VERLET, 2,
      "L. Verlet, Phys. Rev. 159 (1967) 98; course-material file 000 (eq. (5), Taylor start) and file "
      f"001 (Stormer-Verlet velocity); {_HNW}",
      "two-step position form x_(n+1) = 2x_n - x_(n-1) + h^2 a_n, Taylor start, central-difference "
      "velocity; equals velocity Verlet in exact arithmetic")]
    + [(stormer_table(k), k, f"{_HNW} (Stormer's explicit methods, eq. (10.6)); course-material file 000",
        f"explicit Stormer method, {k} steps") for k in range(3, 9)]
    + [(cowell_table(k), 4 if k == 2 else k + 1, f"{_HNW} (Cowell's implicit methods, eq. (10.8))"
        + ("; B. Numerov, MNRAS 84 (1924) 592" if k == 2 else ""),
        f"implicit Cowell method, differences to order {k}" + (" (Numerov)" if k == 2 else ""))
       for k in (2, 4, 5, 6, 7, 8)]
    + [(_symmetric("quinlan-tremaine8", [1, -2, 2, -1, 0], [0, 17671, -23622, 61449, -50516], 12096),
        8, _QT, "symmetric explicit 8-step method SL8"),
       (_symmetric("quinlan-tremaine10", [1, -1, 1, -1, 1, -2],
                   [0, 399187, -485156, 2391436, -2816732, 4651330], 241920),
        10, _QT, "symmetric explicit 10-step method SL10"),
       (_symmetric("quinlan-tremaine12", [1, -2, 2, -1, 0, 0, 0],
                   [0, 90987349, -229596838, 812627169, -1628539944, 2714971338, -3041896548],
                   53222400), 12, _QT, "symmetric explicit 12-step method SL12"),
       (_symmetric("quinlan8a", [1, -2, 2, -2, 2], [0, 22081, -29418, 75183, -75212], 15120),
        8, _Q99, "symmetric explicit 8-step method 8A"),
       (_symmetric("quinlan8b", [1, 0, 0, Fraction(-1, 2), -1], [0, 192481, 6582, 816783, -156812], 120960),
        8, _Q99, "symmetric explicit 8-step method 8B")]
)

#: The course's start and velocity for Stormer-Verlet (the recurrence is the family's)
_OPTIONS = {"stormer-verlet": {"start": "taylor-polynomial", "velocity_points": 1}}

METHODS: list[Method] = [
    Method(table, order, reference, description,
           options={"on_request": table.name not in DEFAULT, **_OPTIONS.get(table.name, {})})
    for table, order, reference, description in _TABLES
]

STEPPERS: list[Stepper] = [m.stepper() for m in METHODS]
