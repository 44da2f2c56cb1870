"""Implicit Runge-Kutta methods: Butcher tableaux plus one Newton-solved step loop.

`backward-euler`, `trapezoid` (Crank-Nicolson, the implicit Adams-Moulton rule, written as the
two-stage Lobatto IIIA tableau), `implicit-midpoint` and `gauss-legendre-4` (two-stage Gauss).

The stage equations Z_i = h sum_j a_ij f(t + c_j h, y + Z_j) are solved by Newton's method with
the Jacobian derived from the problem's symbolic definition (`dyn.jac`); every ensemble member is
solved at once with a batched linear solve over the ensemble axis. The new state is
y + h sum_e w_e F_e + sum_i d_i Z_i (d = A^{-T} b on the implicit stages), so no right-hand side is
evaluated after the iteration has converged (Hairer & Wanner, *Solving Ordinary Differential
Equations II*, IV.8). A step whose iteration does not reach `newton_tol` within `newton_max_iter`
iterations raises `StepFailure`; it is never accepted.

References: course material 004_bfdbb1594143ed8b.txt (backward Euler and its unconditional
stability; the implicit trapezoid/Adams-Moulton rule); E. Hairer, G. Wanner, *Solving Ordinary
Differential Equations II*, IV.5 (collocation: Gauss, Lobatto IIIA) and IV.8 (Newton for the
stage equations); E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, II.1 and
VI.4 (symplectic and symmetric Gauss methods; quadratic invariants).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from harness.coefficients import ButcherTableau
from harness.errors import InputError
from harness.methods import Method
from harness.problem import Dynamics
from harness.stepper import Carry, StepFailure, Stepper
from harness.tolerances import (
    NEWTON_MAX_ITER,
    NEWTON_TOL,
)
from implementations import coefficient_info
from implementations.newton_rule import newton_stop

__all__ = [
    "METHODS",
    "STEPPERS",
    "ImplicitRungeKutta",
    "NewtonSettings",
    "NewtonStepper",
    "StageSplit",
    "stage_split",
    "newton_solve",
    "newton_stop",
    "scaled_norm",
    "extrapolation_matrix",
    "BACKWARD_EULER",
    "TRAPEZOID",
    "IMPLICIT_MIDPOINT",
    "GAUSS_LEGENDRE_4",
]

NEWTON_MODES = ("full", "simplified")
# Newton iterations per step on a smooth problem, starting from the extrapolated previous stages
# (for the declared evals_per_step; large stiff steps take three or more).
TYPICAL_NEWTON_ITERATIONS = 2


# -- Newton's method on the ensemble axis ---------------------------------------------------------
@dataclass(frozen=True)
class NewtonSettings:
    """How implicit equations are solved.

    `mode`: 'full' re-evaluates the Jacobian at every iterate (quadratic convergence);
    'simplified' evaluates it once per step at (t_n, y_n) (linear convergence, cheaper).
    `tol`: bound on the max-norm of the Newton increment (or of its estimated remaining error),
    componentwise scaled by 1 + |y_n|. `max_iter`: iterations allowed before the step fails.
    """

    tol: float = NEWTON_TOL
    max_iter: int = NEWTON_MAX_ITER
    mode: str = "full"

    def __post_init__(self):
        try:
            tol = float(self.tol)
        except (TypeError, ValueError):
            raise InputError(f"`newton_tol` must be a real number, got {self.tol!r}") from None
        if not (math.isfinite(tol) and tol >= 0.0):
            raise InputError(f"`newton_tol` must be finite and >= 0, got {self.tol!r}")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, int | np.integer):
            raise InputError(f"`newton_max_iter` must be a whole number, got {self.max_iter!r}")
        if self.max_iter < 1:
            raise InputError(f"`newton_max_iter` must be at least 1, got {self.max_iter}")
        if self.mode not in NEWTON_MODES:
            raise InputError(f"`newton` must be one of {NEWTON_MODES}, got {self.mode!r}")
        object.__setattr__(self, "tol", tol)
        object.__setattr__(self, "max_iter", int(self.max_iter))

    def describe(self) -> str:
        """These settings in words, for a stepper's description.

        Returns
        -------
        str: mode, tolerance and iteration limit.
        """
        return f"{self.mode} Newton, tolerance {self.tol:.0e}, at most {self.max_iter} iterations"

    def keywords(
        self, mode: str | None = None, tol: float | None = None, max_iter: int | None = None
    ) -> dict:
        """These settings as a stepper's constructor keywords, with `mode`, `tol` and `max_iter`
        replacing them where given (how `with_newton` and its kin rebuild a stepper).

        Parameters
        ----------
        mode : str or None, 'simplified' or 'full'; tol : float or None, the Newton tolerance;
        max_iter : int or None, the iteration limit.

        Returns
        -------
        dict: 'newton', 'newton_tol', 'newton_max_iter'.
        """
        return {
            "newton": self.mode if mode is None else mode,
            "newton_tol": self.tol if tol is None else tol,
            "newton_max_iter": self.max_iter if max_iter is None else max_iter,
        }


def scaled_norm(dx: np.ndarray, inv_scale: np.ndarray) -> float:
    """max_i |dx_i| / scale_i over components and ensemble members (NaN propagates).

    Parameters
    ----------
    dx : array, the increment; inv_scale : array of the same shape, the reciprocal scales.

    Returns
    -------
    float: the scaled max-norm.
    """
    return float(np.abs(dx * inv_scale).max())


def newton_solve(
    residual: Callable[[np.ndarray], np.ndarray],
    matrix: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    inv_scale: np.ndarray,
    *,
    settings: NewtonSettings,
    counts: dict,
    stepper: str,
    t: float,
) -> np.ndarray:
    """Solve residual(x) = 0 for x shaped (m, N), all ensemble members together, from the
    first iterate `x`; `inv_scale` (m, N) holds the reciprocal componentwise scales.

    `matrix(x)` returns the iteration matrix d residual / dx shaped (N, m, m); it is called at the
    first iterate and, in 'full' mode, at every iterate. Converged by `newton_stop`: the scaled
    increment at most `settings.tol`, or the contraction rate theta of two successive increments
    giving an estimated remaining error theta / (1 - theta) * |dx| at most `settings.tol` (Hairer &
    Wanner II, IV.8, eq. 8.10), or the increment stalled at the rounding level. Iterations are
    added to counts['newton_iterations']. Raises `StepFailure` naming `stepper`, the time, the
    increment and the residual when it does not converge.

    Parameters
    ----------
    residual : callable, x (m, N) -> residual (m, N); matrix : callable, x -> (N, m, m) iteration
    matrices; x : (m, N) the first iterate; inv_scale : (m, N) reciprocal scales;
    settings : NewtonSettings, mode, tolerance and iteration limit; counts : dict of counters
    (updated); stepper : str, the stepper's name for errors; t : float, the step's time for errors.

    Returns
    -------
    ndarray (m, N): the converged iterate.
    """
    tol = settings.tol
    previous = math.inf
    mat = None
    norm = math.inf
    theta = math.nan
    g = None
    for k in range(1, settings.max_iter + 1):
        g = residual(x)
        if mat is None or settings.mode == "full":
            mat = matrix(x)
        counts["newton_iterations"] = counts.get("newton_iterations", 0) + 1
        try:
            dx = np.linalg.solve(mat, -g.T[..., None])[..., 0].T
        except np.linalg.LinAlgError:
            raise StepFailure(
                f"stepper {stepper!r}: singular Newton matrix at t={t:.17g} (iteration {k}); "
                f"scaled residual {scaled_norm(g, inv_scale):.3e}"
            ) from None
        x = x + dx
        norm = scaled_norm(dx, inv_scale)
        if not math.isfinite(norm):
            break
        converged, theta = newton_stop(norm, previous, tol, theta, scaled_norm(x, inv_scale))
        if converged:
            return x
        previous = norm
    res_norm = scaled_norm(g, inv_scale) if g is not None else math.nan
    raise StepFailure(
        f"stepper {stepper!r}: Newton iteration did not converge at t={t:.17g} after "
        f"{k} iteration(s) ({settings.mode}): scaled increment {norm:.3e}, "
        f"scaled residual {res_norm:.3e} (before the last increment), contraction "
        f"{theta:.3g}, tolerance {tol:.1e}"
    )


def extrapolation_matrix(nodes: np.ndarray) -> np.ndarray | None:
    """E with Z_new_i ~ sum_j E_ij Z_prev_j: the polynomial u(tau) through (0, 0) and
    (c_j, Z_j) (the previous step's collocation polynomial, in units of h, relative to y_{n-1}),
    evaluated at 1 + c_i and taken relative to u(1). None when the nodes are not distinct and
    nonzero (no such polynomial).

    Parameters
    ----------
    nodes : (s,) the implicit stages' nodes c_i.

    Returns
    -------
    ndarray (s, s) or None: the extrapolation matrix E.
    """
    pts = np.concatenate([[0.0], nodes])
    if np.any(nodes == 0.0) or np.unique(pts).size != pts.size:
        return None

    def lagrange(j: int, tau: float) -> float:
        others = np.delete(pts, j)
        return float(np.prod((tau - others) / (pts[j] - others)))

    s = nodes.size
    E = np.empty((s, s))
    for i in range(s):
        for j in range(s):
            E[i, j] = lagrange(j + 1, 1.0 + nodes[i]) - lagrange(j + 1, 1.0)
    return E


@dataclass(frozen=True, eq=False)
class StageSplit:
    """An implicit tableau split for the Newton step (Hairer & Wanner II, IV.8). Stages whose row
    of A is zero are explicit (one evaluation at (t_n, y_n)); the others are the unknowns Z, and
    y_{n+1} = y_n + h w . F_explicit + d . Z with d = A_ii^{-T} b_implicit, w = b_explicit -
    A_ie^T d. `fsal`: the first stage is the only explicit one, the last row of A is b and
    c_s = 1, so the derivative at the step's end is recovered from Z (h F_last =
    `last_row_inv` . (Z - h A_ie F_e)) instead of evaluated. `predictor`: the extrapolation of
    the previous step's stages (`extrapolation_matrix`), or None."""

    explicit: np.ndarray
    implicit: np.ndarray
    A_ii: np.ndarray
    A_ie: np.ndarray
    c_implicit: np.ndarray
    d: np.ndarray
    w: np.ndarray
    last_row_inv: np.ndarray
    fsal: bool
    predictor: np.ndarray | None


def stage_split(tableau: ButcherTableau, label: str) -> StageSplit:
    """`tableau` split into explicit and implicit stages; `InputError` starting with `label`
    (how the caller names the tableau) when the implicit block of A is singular.

    Parameters
    ----------
    tableau : ButcherTableau, the method's tableau; label : str, the tableau's name in errors.

    Returns
    -------
    StageSplit: the stage indices, the blocks of A, d, w, the last row of A_ii^{-1}, whether the
    first stage repeats the last, and the predictor `extrapolation_matrix`.
    """
    A, b, c = tableau.A, tableau.b, tableau.c
    zero_rows = np.all(A == 0.0, axis=1)
    expl, impl = np.flatnonzero(zero_rows), np.flatnonzero(~zero_rows)
    A_ii, A_ie = A[np.ix_(impl, impl)], A[np.ix_(impl, expl)]
    try:
        A_ii_inv = np.linalg.inv(A_ii)
    except np.linalg.LinAlgError:
        raise InputError(f"{label}: the implicit block of A must be invertible") from None
    d = A_ii_inv.T @ b[impl]
    fsal = bool(expl.size == 1 and expl[0] == 0 and impl.size == tableau.stages - 1
                and np.array_equal(A[-1], b) and c[-1] == 1.0)
    return StageSplit(explicit=expl, implicit=impl, A_ii=A_ii, A_ie=A_ie, c_implicit=c[impl], d=d,
                      w=b[expl] - A_ie.T @ d, last_row_inv=A_ii_inv[-1], fsal=fsal,
                      predictor=extrapolation_matrix(c[impl]))


class NewtonStepper(Stepper):
    """What the implicit families share: `newton`, the settings of the Newton iteration on their
    implicit equations, and rebuilding the same method with other settings (`with_newton` and
    its kin) from the keywords it was built with, recorded here once for every family."""

    newton: NewtonSettings

    def __new__(cls, *coefficients, **keywords):
        self = super().__new__(cls)
        # Unpickling and copying pass no keywords; the object's saved state then restores these.
        self._construct = keywords
        return self

    def _rebuild(self, **changes) -> Stepper:
        """The same method built again, with `changes` to its constructor keywords."""
        return type(self)(self.coefficients, **{**self._construct, **self.newton.keywords(), **changes})

    def with_newton(self, mode: str | None = None, tol: float | None = None,
                    max_iter: int | None = None) -> Stepper:
        """The same method with other Newton settings (unchanged where None).

        Parameters
        ----------
        mode, tol, max_iter : as in `NewtonSettings.keywords`.

        Returns
        -------
        Stepper: a new stepper of the same method.
        """
        return self._rebuild(**self.newton.keywords(mode, tol, max_iter))


# -- the step loop ------------------------------------------------------------------------------
class ImplicitRungeKutta(NewtonStepper):
    """One step loop for every implicit Runge-Kutta tableau.

    Stages whose row of A is zero (the first stage of Lobatto IIIA) are explicit: they cost one
    evaluation at (t_n, y_n) per step, or none when the tableau is first-same-as-last (first row
    zero, last row equal to b, c = (0, ..., 1)), in which case the derivative at the end of the
    step is recovered from the converged stage equations instead of re-evaluated. The remaining
    stages are the Newton unknowns: each iteration evaluates f once per implicit stage (and, in
    'full' mode, the Jacobian once per implicit stage).
    """

    def __init__(
        self,
        tableau: ButcherTableau,
        *,
        name: str,
        claimed_order: int,
        reference: str,
        description: str,
        symplectic: bool | None = None,
        symmetric: bool | None = None,
        newton: str = "full",
        newton_tol: float = NEWTON_TOL,
        newton_max_iter: int = NEWTON_MAX_ITER,
        stability: dict | None = None,
    ):
        if not isinstance(tableau, ButcherTableau):
            raise InputError(f"`tableau` must be a ButcherTableau, got {type(tableau).__name__}")
        if tableau.explicit:
            raise InputError(f"`tableau` {tableau.name!r} is explicit; use the explicit Runge-Kutta family")
        self.coefficients = tableau
        # Symmetry and symplecticity are asked of the coefficients unless stated.
        symplectic = bool(tableau.symplectic) if symplectic is None else symplectic
        symmetric = bool(tableau.symmetric) if symmetric is None else symmetric
        self.newton = NewtonSettings(newton_tol, newton_max_iter, newton)
        self._split = split = stage_split(tableau, f"`tableau` {tableau.name!r}")
        n_impl = split.implicit.size
        explicit_evals = 0 if split.fsal or split.explicit.size == 0 else 1
        per_iter = n_impl
        self._jac_note = (
            f"{n_impl} Jacobian evaluation(s) per iteration"
            if newton == "full"
            else "1 Jacobian evaluation per step"
        )
        self.info = coefficient_info(
            tableau,
            family="implicit-rk",
            name=name,
            claimed_order=claimed_order,
            explicit=False,
            symplectic=symplectic,
            symmetric=symmetric,
            # typical figure: two Newton iterations (the second confirms the first); the measured
            # count is in the run's `evals`.
            evals_per_step=float(TYPICAL_NEWTON_ITERATIONS * per_iter + explicit_evals),
            reference=reference,
            description=" ".join(
                part
                for part in [
                    f"{description} Stage equations: {self.newton.describe()} (increments scaled "
                    "by 1 + |y_n|), all ensemble members in one batched solve;",
                    f"per iteration {per_iter} f evaluation(s); {self._jac_note};",
                    "1 f evaluation per step for the explicit stage;" if explicit_evals else "",
                    "the derivative at the step end is reused (first same as last);" if split.fsal else "",
                    "first iterate: the previous step's collocation polynomial, extrapolated;",
                    "evals_per_step is a typical figure (two Newton iterations on a smooth "
                    "solution; large stiff steps take three or more); measured counts, with "
                    "counts['newton_iterations'], are recorded with every run.",
                ]
                if part
            ),
            extra={
                "newton": self.newton.mode,
                "newton_tol": self.newton.tol,
                "newton_max_iter": self.newton.max_iter,
                "stages": tableau.stages,
                "implicit_stages": n_impl,
                **({"stability": dict(stability)} if stability else {}),
            },
        )

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        return Carry(t0, h, y0, f_start=None, z_prev=None)

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        t, h, y = c.t, c.h, c.y
        if not np.all(np.isfinite(y)):
            c.y = np.full_like(y, np.nan)  # a blown-up state stays blown up; public methods report it
            c.f_start = c.z_prev = None
            return
        dim, N = y.shape
        split = self._split
        impl = split.implicit.size
        m = impl * dim
        c_impl = split.c_implicit
        A_ii = split.A_ii
        f_expl = None
        if split.explicit.size:
            f_expl = c.f_start if c.f_start is not None else dyn.f(t, y)
        # constant part of the residual: h * A_ie F_e, shaped (impl, dim, N)
        const = None
        if f_expl is not None:
            const = (h * split.A_ie.sum(axis=1))[:, None, None] * f_expl[None]
        inv_scale = np.broadcast_to(1.0 / (1.0 + np.abs(y)), (impl, dim, N)).reshape(m, N)
        eye = np.eye(m)
        hA = h * A_ii
        F = np.empty((impl, dim, N))

        def residual(x: np.ndarray) -> np.ndarray:
            Z = x.reshape(impl, dim, N)
            for i in range(impl):
                dyn.f(t + c_impl[i] * h, y + Z[i], out=F[i])
            g = Z - (hA[0, 0] * F if impl == 1 else np.einsum("ij,jdn->idn", hA, F))
            if const is not None:
                g -= const
            return g.reshape(m, N)

        if self.newton.mode == "full":

            def matrix(x: np.ndarray) -> np.ndarray:
                Z = x.reshape(impl, dim, N)
                if impl == 1:
                    return eye - hA[0, 0] * dyn.jac(t + c_impl[0] * h, y + Z[0]).transpose(2, 0, 1)
                J = np.stack([dyn.jac(t + c_impl[i] * h, y + Z[i]) for i in range(impl)])
                return eye - np.einsum("ij,jabn->niajb", hA, J).reshape(N, m, m)

        else:

            def matrix(x: np.ndarray) -> np.ndarray:
                J = dyn.jac(t, y)
                return eye - np.einsum("ij,abn->niajb", hA, J).reshape(N, m, m)

        # first iterate: the previous step's collocation polynomial, extrapolated (Hairer &
        # Wanner II, IV.8); zero on the first step and after a reversal.
        if c.z_prev is not None and split.predictor is not None:
            x0 = np.einsum("ij,jdn->idn", split.predictor, c.z_prev).reshape(m, N)
        else:
            x0 = np.zeros((m, N))
        x = newton_solve(
            residual,
            matrix,
            x0,
            inv_scale,
            settings=self.newton,
            counts=dyn.counts,
            stepper=self.info.name,
            t=t,
        )
        Z = x.reshape(impl, dim, N)
        y_new = y + np.einsum("i,idn->dn", split.d, Z)
        if f_expl is not None:
            y_new += h * float(split.w.sum()) * f_expl
        if split.fsal:
            hF_last = np.einsum("i,idn->dn", split.last_row_inv, Z if const is None else Z - const)
            c.f_start = hF_last / h
        c.z_prev = Z
        c.y = y_new

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        super()._reverse(dyn, c)  # f(t, y) at the current point stays valid in either direction
        c.z_prev = None  # the predictor extrapolates forward only


# -- tableaux (data) ------------------------------------------------------------------------------
_SQ3 = math.sqrt(3.0)
_COURSE_ODE = (
    "course material 004_bfdbb1594143ed8b.txt (A. Mignone, lecture notes 'Ordinary Differential "
    "Equations: Initial Value Problems', Univ. Torino 2017-18)"
)

# A-stable: |R(z)| <= 1 on the whole left half-plane, so the real stability interval is unbounded
# (Hairer & Wanner II, IV.3); checked by the stability experiment.
_A_STABLE = {"real_interval": math.inf}

BACKWARD_EULER = ButcherTableau("backward-euler", A=[[1.0]], b=[1.0], c=[1.0])
TRAPEZOID = ButcherTableau("trapezoid", A=[[0.0, 0.0], [0.5, 0.5]], b=[0.5, 0.5], c=[0.0, 1.0])
IMPLICIT_MIDPOINT = ButcherTableau("implicit-midpoint", A=[[0.5]], b=[1.0], c=[0.5])
GAUSS_LEGENDRE_4 = ButcherTableau(
    "gauss-legendre-4",
    A=[[0.25, 0.25 - _SQ3 / 6.0], [0.25 + _SQ3 / 6.0, 0.25]],
    b=[0.5, 0.5],
    c=[0.5 - _SQ3 / 6.0, 0.5 + _SQ3 / 6.0],
)

METHODS: list[Method] = [
    Method(
        BACKWARD_EULER,
        claimed_order=1,
        reference=f"{_COURSE_ODE}, the implicit (backward) Euler method and its unconditional "
        "stability; Hairer & Wanner, Solving ODEs II, IV.3.",
        description="Backward (implicit) Euler y_{n+1} = y_n + h f(t_{n+1}, y_{n+1}); L-stable.",
        stability=_A_STABLE,
    ),
    Method(
        TRAPEZOID,
        claimed_order=2,
        reference=f"{_COURSE_ODE}, the implicit Adams-Moulton (trapezoidal) rule; J. Crank & P. "
        "Nicolson, Proc. Camb. Phil. Soc. 43 (1947) 50-67; Hairer & Wanner, Solving ODEs II, "
        "IV.5 (Lobatto IIIA, s = 2).",
        description="Trapezoidal rule (Crank-Nicolson, one-step Adams-Moulton) "
        "y_{n+1} = y_n + h/2 (f_n + f_{n+1}), as the two-stage Lobatto IIIA tableau; A-stable.",
        stability=_A_STABLE,
    ),
    Method(
        IMPLICIT_MIDPOINT,
        claimed_order=2,
        reference="Hairer, Lubich & Wanner, Geometric Numerical Integration, I.1 and VI.3 (implicit "
        "midpoint rule; symplectic, symmetric, preserves quadratic invariants).",
        description="Implicit midpoint rule y_{n+1} = y_n + h f(t_n + h/2, (y_n + y_{n+1})/2), the "
        "one-stage Gauss method; A-stable.",
        stability=_A_STABLE,
    ),
    Method(
        GAUSS_LEGENDRE_4,
        claimed_order=4,
        reference="J. C. Butcher, Math. Comp. 18 (1964) 50-64 (implicit Runge-Kutta processes); Hairer "
        "& Wanner, Solving ODEs II, IV.5, Table 5.1; Hairer, Lubich & Wanner, Geometric "
        "Numerical Integration, II.1.3 and VI.4.",
        description="Two-stage Gauss-Legendre collocation method, nodes 1/2 -+ sqrt(3)/6; order 4, "
        "A-stable, symplectic, symmetric, preserves quadratic invariants.",
        stability=_A_STABLE,
    ),
]

STEPPERS: list[Stepper] = [s for m in METHODS for s in m.steppers()]
