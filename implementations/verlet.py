"""Two-step (Stormer) Verlet: x_{n+1} + alpha_1 x_n + alpha_0 x_{n-1} = h^2 beta_1 a_n.

One step loop (`TwoStepVerlet`) built from a `harness.coefficients.SecondOrderMultistep` table
(Stormer's rule alpha = (1, -2, 1), beta = (0, 1, 0); Hairer, Norsett & Wanner I, III.10), as
derived from central differences in course-material file 000 (eq. (5)) and file 001:

- start (Taylor): x_1 = x_0 + h v_0 + h^2 a(x_0, v_0, t_0) / 2;
- observed velocity: the central difference v_n = (x_{n+1} - x_{n-1}) / 2h. The carry at step n
  already holds x_{n+1} (computed from a_n, the step's only force evaluation), so observing
  costs nothing; at the start, v_0 itself is returned;
- `stormer-verlet` (velocity-independent forces) is the k = 2 record of the second-order
  multistep family (`implementations.second_order_multistep`), the same start and velocity;
- `verlet-damped` (course file 000, Example 2): the velocity inside the force is replaced by
  (x_{n+1} - x_{n-1}) / 2h, so x_{n+1} is implicit. When a is linear in v (d^2a/dv^2 = 0,
  found symbolically) the linear equation is solved in closed form with B = da/dv from the
  problem's Jacobian; otherwise Newton's method on x_{n+1}, with a stated tolerance, raising
  `StepFailure` when it does not converge.

Reversing time swaps x_{n-1} and x_{n+1} and negates h, so the recurrence runs backwards exactly.
"""

from __future__ import annotations

import heyoka as hy
import numpy as np
from scipy.linalg.blas import daxpy as _axpy

from harness.coefficients import SecondOrderMultistep
from harness.errors import CoefficientError
from harness.problem import Dynamics, Problem
from harness.stepper import Carry, StepFailure, Stepper, StepperInfo
from harness.tolerances import NEWTON_MAX_ITER, NEWTON_TOL
from implementations import ProblemCache

__all__ = ["TwoStepVerlet", "STORMER", "STEPPERS", "solve_members", "stormer_carry"]


class _VelocityStructure:
    """How a problem's acceleration depends on the velocity, found symbolically once.

    kind: 'none' (a ignores v), 'constant' (a linear in v with da/dv free of q, v and t),
    'linear' (linear in v, da/dv varying), 'nonlinear'.
    """

    def __init__(self, problem: Problem):
        form = problem.newtonian
        vel = list(form.velocities)
        B = [[hy.diff(a, v) for v in vel] for a in form.acceleration]
        zero = hy.expression(0.0)
        if not problem.velocity_dependent:
            self.kind = "none"
        elif all(hy.diff(b, v) == zero for row in B for b in row for v in vel):
            varying = any(hy.get_variables(b) for row in B for b in row) or bool(
                hy.cfunc([b for row in B for b in row], list(problem.variables)).is_time_dependent
            )
            self.kind = "linear" if varying else "constant"
        else:
            self.kind = "nonlinear"


def solve_members(M: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve M[:, :, j] x[:, j] = rhs[:, j] for every ensemble member j (M of shape (1, 1, N):
    a division).

    Parameters
    ----------
    M : (m, m, N) matrices; rhs : (m, N) right-hand sides.

    Returns
    -------
    ndarray (m, N): the solutions.
    """
    if M.shape[0] == 1:
        return rhs / M[0]
    x = np.linalg.solve(np.moveaxis(M, -1, 0), np.moveaxis(rhs, -1, 0)[..., None])
    return np.ascontiguousarray(np.moveaxis(x[..., 0], 0, -1))


def stormer_carry(dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
    """The carry of Stormer's two-step rule at its start: the starting velocity `v0`, the
    current positions `cur` and room for the previous ones `prev` (NumPy and compiled loops).

    Parameters
    ----------
    dyn : Dynamics, the problem run (its `nq`); t0 : float, the start time; y0 : (2 nq, N) the
    start states; h : float, the step.

    Returns
    -------
    Carry: the carry with `v0`, `cur` and `prev`.
    """
    c = Carry(t0, h, y0)
    c.v0 = y0[dyn.nq:].copy()
    c.cur = y0[:dyn.nq].copy()
    c.prev = np.empty_like(c.cur)
    return c


class TwoStepVerlet(Stepper):
    """Stormer's two-step rule with the Taylor start and the central-difference velocity.

    With `implicit_velocity`, a velocity-dependent force is evaluated at the central-difference
    velocity (x_{n+1} - x_{n-1}) / 2h, which makes x_{n+1} implicit (course file 000, Example 2).
    """

    def __init__(
        self,
        name: str,
        table: SecondOrderMultistep,
        *,
        implicit_velocity: bool,
        reference: str,
        description: str = "",
    ):
        if not isinstance(table, SecondOrderMultistep):
            raise CoefficientError(
                f"`table` must be a SecondOrderMultistep, got {type(table).__name__}"
            )
        if table.steps != 2 or not table.explicit or table.beta[0] != 0.0:
            raise CoefficientError(
                f"`{table.name}`: the two-step Verlet loop needs a two-step table with "
                f"beta_0 = beta_2 = 0, got alpha={table.alpha.tolist()}, beta={table.beta.tolist()}"
            )
        self.coefficients = table
        self._alpha0, self._alpha1 = float(table.alpha[0]), float(table.alpha[1])
        self._beta1 = float(table.beta[1])
        self._implicit_velocity = implicit_velocity
        self._structures = ProblemCache()  # key: problem fingerprint
        self.info = StepperInfo(
            name=name,
            family="stormer",
            claimed_order=2,
            explicit=not implicit_velocity,
            symplectic=True,
            symmetric=True,
            evals_per_step=1.0,
            form="newtonian",
            velocity_dependent=implicit_velocity,
            reference=reference,
            description=description,
            extra={
                "start": "Taylor: x_1 = x_0 + h v_0 + h^2 a_0 / 2",
                "velocity": "central difference (x_{n+1} - x_{n-1}) / 2h",
            },
        )

    def _structure(self, problem: Problem) -> _VelocityStructure:
        return self._structures.get(problem.fingerprint(), lambda: _VelocityStructure(problem))

    # -- private math -----------------------------------------------------------------------------
    #: The recurrence uses two past positions (x_{n-1}, x_n); see `_start_from_history`.
    history_length = 2

    def _new_carry(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = stormer_carry(dyn, t0, y0, h)
        c.a = np.empty_like(c.cur)
        c.zero_v = np.zeros_like(c.cur)
        c.kind = self._structure(dyn.problem).kind if self._implicit_velocity else "none"
        if c.kind == "constant":
            c.B = self._dadv(dyn, t0, c.cur, c.zero_v)
            c.P, c.M = self._linear_system(c.B, h)
        return c

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = self._new_carry(dyn, t0, y0, h)
        c.at_start = True  # x_{-1} unknown: observe v_0 itself
        x0, v0 = c.cur, c.v0
        c.a_start = dyn.accel(t0, x0, v0)
        c.nxt = x0 + h * v0 + (0.5 * h * h) * c.a_start
        return c

    def _start_from_history(self, dyn: Dynamics, t0: float, h: float, history: list) -> Carry:
        """The recurrence itself from exact positions x(t0), x(t0 + h) (velocities unused), so
        its local error (course file 000: of order h^4 in the positions) can be measured."""
        c = self._new_carry(dyn, t0 + h, history[-1], h)
        c.at_start = False
        c.prev = history[0][: dyn.nq].copy()
        c.nxt = np.empty_like(c.cur)
        self._solve_next(dyn, c, c.t)
        return c

    def _linear_system(self, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """For a = a(x_n, 0, t) + B v, the step solves M x_{n+1} = -alpha_1 x_n + P x_{n-1}
        + h^2 beta_1 a(x_n, 0, t) with M = I - g B, P = -alpha_0 I - g B, g = beta_1 h / 2.
        P is formed as one coefficient (course file 000: (1 - h/2) x_{n-1}), which keeps the
        rounding of the two-step recurrence at the level of the explicit Stormer form."""
        g = 0.5 * self._beta1 * h
        eye = np.eye(B.shape[0])[:, :, None]
        gB = g * B
        return -self._alpha0 * eye - gB, eye - gB

    def _dadv(self, dyn: Dynamics, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """B = da/dv, shaped (nq, nq, N), from the problem's Jacobian."""
        nq = dyn.nq
        J = dyn.jac(t, np.concatenate([q, v]))
        return J[nq:, nq:]

    def _explicit_part(self, c: Carry, a: np.ndarray, out: np.ndarray) -> np.ndarray:
        """out = -alpha_1 x_n - alpha_0 x_{n-1} + h^2 beta_1 a; `out` may be x_{n-1}'s buffer."""
        np.multiply(c.prev, -self._alpha0, out=out)
        flat = out.reshape(-1)
        _axpy(c.cur.reshape(-1), flat, a=-self._alpha1)
        _axpy(a.reshape(-1), flat, a=self._beta1 * c.h * c.h)
        return out

    def _solve_next(self, dyn: Dynamics, c: Carry, t: float) -> None:
        """x_{n+1} from x_n = c.cur and x_{n-1} = c.prev at time t = t_n, into c.nxt."""
        kind = c.kind
        if kind == "none":
            dyn.accel(t, c.cur, out=c.a)
            c.nxt = self._explicit_part(c, c.a, c.nxt)
            return
        if kind in ("constant", "linear"):
            # a(x_n, v, t) = a(x_n, 0, t) + B v with v = (x_{n+1} - x_{n-1}) / 2h:
            # (I - beta_1 h/2 B) x_{n+1} = explicit part - beta_1 h/2 B x_{n-1}.
            dyn.accel(t, c.cur, c.zero_v, out=c.a)
            if kind == "constant":
                P, M = c.P, c.M
            else:
                P, M = self._linear_system(self._dadv(dyn, t, c.cur, c.zero_v), c.h)
            rhs = -self._alpha1 * c.cur
            rhs += np.einsum("ijn,jn->in", P, c.prev)
            rhs += (self._beta1 * c.h * c.h) * c.a
            c.nxt = solve_members(M, rhs)
            return
        c.nxt = self._newton(dyn, c, t)

    def _newton(self, dyn: Dynamics, c: Carry, t: float) -> np.ndarray:
        """Newton's method on G(z) = z + alpha_1 x_n + alpha_0 x_{n-1} - h^2 beta_1 a(x_n, v(z)),
        v(z) = (z - x_{n-1}) / 2h. Converged when every member's correction is at most
        NEWTON_TOL * (1 + |z|); the error left after a correction is of its square's size."""
        h = c.h
        g = 0.5 * self._beta1 * h
        eye = np.eye(dyn.nq)[:, :, None]
        buf = np.empty_like(c.cur)
        # Predictor: the force at the backward-difference velocity.
        z = self._explicit_part(c, dyn.accel(t, c.cur, (c.cur - c.prev) / h), np.empty_like(c.cur))
        correction = np.inf
        for _ in range(NEWTON_MAX_ITER):
            v = (z - c.prev) / (2.0 * h)
            residual = z - self._explicit_part(c, dyn.accel(t, c.cur, v), buf)
            M = eye - g * self._dadv(dyn, t, c.cur, v)
            dz = solve_members(M, residual)
            z = z - dz
            scale = 1.0 + np.max(np.abs(z), axis=0)
            correction = float(np.max(np.max(np.abs(dz), axis=0) / scale))
            if correction <= NEWTON_TOL:
                return z
            if not np.isfinite(correction):
                break
        raise StepFailure(
            f"stepper {self.info.name!r}: Newton's method for x_(n+1) at t={t!r} did not converge "
            f"in {NEWTON_MAX_ITER} iterations (last relative correction {correction:.3g}, "
            f"tolerance {NEWTON_TOL:g})"
        )

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        # (x_{n-1}, x_n, x_{n+1}) -> (x_n, x_{n+1}, x_{n+2}); x_{n-1}'s buffer takes x_{n+2}.
        c.prev, c.cur, c.nxt = c.cur, c.nxt, c.prev
        c.at_start = False
        self._solve_next(dyn, c, c.t + c.h)

    @staticmethod
    def observed_state(c: Carry, nq: int) -> np.ndarray:
        """(x_n, v_n) of a carry (prev, cur, nxt) = (x_{n-1}, x_n, x_{n+1}): the start velocity
        before the first step, else the central difference (x_{n+1} - x_{n-1}) / 2h. Shared with
        the compiled loop of the same carry.

        Parameters
        ----------
        c : Carry, the two-step carry; nq : int, the number of positions.

        Returns
        -------
        ndarray (2 nq, N): positions over velocities.
        """
        out = np.empty_like(c.y)
        out[:nq] = c.cur
        if c.at_start:
            out[nq:] = c.v0
        else:
            np.subtract(c.nxt, c.prev, out=out[nq:])
            out[nq:] /= 2.0 * c.h
        return out

    @staticmethod
    def reverse_neighbours(c: Carry) -> None:
        """The carry's neighbours for the reversed direction (after h changed sign): swapped, or
        the Taylor start in the new direction when x_{-1} was never formed.

        Parameters
        ----------
        c : Carry, changed in place.
        """
        if c.at_start:
            h = c.h
            c.prev = c.nxt
            c.nxt = c.cur + h * c.v0 + (0.5 * h * h) * c.a_start
            c.at_start = False
        else:
            c.prev, c.nxt = c.nxt, c.prev

    def _observe(self, dyn: Dynamics, c: Carry) -> np.ndarray:
        return self.observed_state(c, dyn.nq)

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        super()._reverse(dyn, c)
        if c.kind == "constant":
            c.P, c.M = self._linear_system(c.B, c.h)
        self.reverse_neighbours(c)


STORMER = SecondOrderMultistep("stormer", [1, -2, 1], [0, 1, 0])

STEPPERS: list[Stepper] = [
    TwoStepVerlet(
        "verlet-damped",
        STORMER,
        implicit_velocity=True,
        reference="course-material file 000, Example 2 (velocity-dependent Verlet)",
        description=(
            "two-step Verlet with the velocity in the force replaced by (x_(n+1) - x_(n-1))/2h; "
            "closed form when a is linear in v, Newton otherwise. One force evaluation per "
            "step when da/dv is constant (plus one Jacobian per step when it varies, and a "
            "force and a Jacobian per Newton iteration when a is nonlinear in v)"
        ),
    ),
]
