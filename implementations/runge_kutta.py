"""Explicit Runge-Kutta methods: one step loop (`ExplicitRungeKutta`) for every tableau.

A method is a `harness.coefficients.ButcherTableau` plus its claimed order and reference; the
loop reads the stage matrix, weights and nodes from it and nothing else. The methods work on
every problem through its first-order right-hand side y' = f(t, y).

Tableaux (Hairer, Norsett & Wanner, *Solving Ordinary Differential Equations I*, 2nd ed.,
Sect. II.1, Tables 1.1-1.2; the course's ODE lecture notes, course-material file 004):
`euler`, `midpoint`, `heun`, `ralston`, `rk3` (Kutta's third order), `rk4`, `rk38`, and the
Bogacki-Shampine 3(2) pair with its embedded method.
"""

from __future__ import annotations

from fractions import Fraction as F

import numpy as np
from scipy.linalg.blas import daxpy as _axpy

from harness.coefficients import ButcherTableau
from harness.errors import CoefficientError
from harness.methods import Method
from harness.problem import Dynamics
from harness.stepper import Carry, Stepper
from implementations import coefficient_info

__all__ = ["ExplicitRungeKutta", "METHODS", "STEPPERS"]


class ExplicitRungeKutta(Stepper):
    """Any explicit Runge-Kutta method, given by its Butcher tableau.

    One step: k_i = f(t + c_i h, y + h sum_{j<i} a_ij k_j), y <- y + h sum_i b_i k_i
    (Hairer, Norsett & Wanner I, Sect. II.1, eq. (1.8)). Stage buffers are allocated once per
    run; each nonzero coefficient is one in-place BLAS axpy (y <- y + a x), which costs a
    fraction of a NumPy multiply-and-add pair on small ensembles.
    """

    def __init__(
        self,
        tableau: ButcherTableau,
        *,
        claimed_order: int,
        reference: str,
        description: str = "",
    ):
        if not isinstance(tableau, ButcherTableau):
            raise CoefficientError(f"`tableau` must be a ButcherTableau, got {type(tableau).__name__}")
        if not tableau.explicit:
            raise CoefficientError(
                f"`{tableau.name}`: an explicit Runge-Kutta stepper needs a strictly lower "
                "triangular stage matrix A"
            )
        self.coefficients = tableau
        self.info = coefficient_info(
            tableau, family="explicit-rk", claimed_order=claimed_order, explicit=True,
            evals_per_step=float(tableau.stages), reference=reference, description=description,
        )
        A, b = tableau.A, tableau.b
        # For each stage: the indices of its nonzero coefficients (none for the first).
        self._stage_terms = [tuple(np.flatnonzero(A[i, :i])) for i in range(tableau.stages)]
        self._weight_terms = tuple(np.flatnonzero(b))

    # -- private math -----------------------------------------------------------------------------
    def _scale(self, c: Carry) -> None:
        """Refresh what depends on the signed step size (at the start and on reversal): the
        scaled coefficients and, for a carry with stage buffers, the step plan."""
        tab = self.coefficients
        c.hA = tab.A * c.h
        c.hb = tab.b * c.h
        c.hc = tab.c * c.h
        if getattr(c, "k", None) is not None:
            self._plan(c)

    def _plan(self, c: Carry) -> None:
        """For each stage: (time offset, its terms (h a_ij, k_j), output buffer); the final
        update's terms (h b_i, k_i). Zero coefficients are skipped."""
        k_rows = [c.k[j].reshape(-1) for j in range(self.coefficients.stages)]
        c.plan = tuple(
            (float(c.hc[i]), tuple((float(c.hA[i, j]), k_rows[j]) for j in terms), c.k[i])
            for i, terms in enumerate(self._stage_terms)
        )
        c.final = tuple((float(c.hb[j]), k_rows[j]) for j in self._weight_terms)

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        s = self.coefficients.stages
        c = Carry(t0, h, np.ascontiguousarray(y0))
        c.y_flat = c.y.reshape(-1)  # a view: axpy updates act on the state itself
        c.k = np.empty((s, *c.y.shape))
        c.stage = np.empty_like(c.y)
        c.stage_flat = c.stage.reshape(-1)
        self._scale(c)
        return c

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        y, stage, stage_flat = c.y, c.stage, c.stage_flat
        t = c.t0 + c.n * c.h
        f, copyto, axpy = dyn.f, np.copyto, _axpy
        for dt, terms, out in c.plan:
            if not terms:
                f(t + dt, y, out=out)
                continue
            copyto(stage, y)
            for coef, k_j in terms:
                axpy(k_j, stage_flat, a=coef)
            f(t + dt, stage, out=out)
        y_flat = c.y_flat
        for coef, k_j in c.final:
            axpy(k_j, y_flat, a=coef)

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        super()._reverse(dyn, c)
        self._scale(c)


_HNW = "Hairer, Norsett & Wanner, Solving ODEs I, 2nd ed., Sect. II.1"
_COURSE = "course-material file 004 (ODE initial value problems)"

METHODS: list[Method] = [
    Method(
        ButcherTableau("euler", [[0]], [1], [0]),
        claimed_order=1,
        reference=f"L. Euler, Institutionum calculi integralis (1768); {_HNW}; {_COURSE}",
        description="explicit (forward) Euler: one evaluation at the start of the step",
    ),
    Method(
        ButcherTableau("midpoint", [[0, 0], [F(1, 2), 0]], [0, 1], [0, F(1, 2)]),
        claimed_order=2,
        reference=f"C. Runge, Math. Ann. 46 (1895) 167-178; {_HNW}; {_COURSE} (RK midpoint)",
        description="explicit midpoint rule: an Euler half step predicts the midpoint slope",
    ),
    Method(
        ButcherTableau("heun", [[0, 0], [1, 0]], [F(1, 2), F(1, 2)], [0, 1]),
        claimed_order=2,
        reference=f"K. Heun, Z. Math. Phys. 45 (1900) 23-38; {_HNW}; {_COURSE} (modified Euler)",
        description="Heun's method: Euler predictor, trapezoidal corrector",
    ),
    Method(
        ButcherTableau("ralston", [[0, 0], [F(2, 3), 0]], [F(1, 4), F(3, 4)], [0, F(2, 3)]),
        claimed_order=2,
        reference="A. Ralston, Runge-Kutta methods with minimum error bounds, Math. Comp. 16 (1962) 431-437",
        description="Ralston's second-order method (c2 = 2/3, minimal truncation-error bound)",
    ),
    Method(
        ButcherTableau(
            "rk3",
            [[0, 0, 0], [F(1, 2), 0, 0], [-1, 2, 0]],
            [F(1, 6), F(2, 3), F(1, 6)],
            [0, F(1, 2), 1],
        ),
        claimed_order=3,
        reference=f"W. Kutta, Z. Math. Phys. 46 (1901) 435-453; {_HNW}, Table 1.1",
        description="Kutta's third-order method (Simpson weights)",
    ),
    Method(
        ButcherTableau(
            "rk4",
            [[0, 0, 0, 0], [F(1, 2), 0, 0, 0], [0, F(1, 2), 0, 0], [0, 0, 1, 0]],
            [F(1, 6), F(1, 3), F(1, 3), F(1, 6)],
            [0, F(1, 2), F(1, 2), 1],
        ),
        claimed_order=4,
        reference=f"W. Kutta, Z. Math. Phys. 46 (1901) 435-453; {_HNW}, Table 1.2; {_COURSE}",
        description="the classical fourth-order Runge-Kutta method",
    ),
    Method(
        ButcherTableau(
            "rk38",
            [[0, 0, 0, 0], [F(1, 3), 0, 0, 0], [F(-1, 3), 1, 0, 0], [1, -1, 1, 0]],
            [F(1, 8), F(3, 8), F(3, 8), F(1, 8)],
            [0, F(1, 3), F(2, 3), 1],
        ),
        claimed_order=4,
        reference=f"W. Kutta, Z. Math. Phys. 46 (1901) 435-453; {_HNW}, Table 1.2",
        description="Kutta's 3/8 rule, fourth order",
    ),
    Method(
        ButcherTableau(
            "bogacki-shampine",
            [[0, 0, 0, 0], [F(1, 2), 0, 0, 0], [0, F(3, 4), 0, 0], [F(2, 9), F(1, 3), F(4, 9), 0]],
            [F(2, 9), F(1, 3), F(4, 9), 0],
            [0, F(1, 2), F(3, 4), 1],
            b_hat=[F(7, 24), F(1, 4), F(1, 3), F(1, 8)],
        ),
        claimed_order=3,
        claimed_embedded_order=2,
        reference="P. Bogacki & L.F. Shampine, A 3(2) pair of Runge-Kutta formulas, Appl. Math. "
        "Lett. 2 (1989) 321-325 (scipy's RK23)",
        description="Bogacki-Shampine 3(2) pair run at fixed steps; its embedded second-order "
        "method is registered as bogacki-shampine@embedded",
    ),
]

STEPPERS: list[Stepper] = [s for m in METHODS for s in m.steppers()]
