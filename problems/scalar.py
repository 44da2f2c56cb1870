"""Scalar test equations with closed-form solutions: `gaussian`, `dahlquist`, `free-fall`.

Each is small enough that every method can be run far into its asymptotic range, and each has an
exact solution that the ground truth is checked against.
"""

from __future__ import annotations

import heyoka as hy
import numpy as np

from harness.problem import NewtonianForm, Problem

__all__ = ["PROBLEMS", "GAUSSIAN", "DAHLQUIST", "FREE_FALL"]

_COURSE_ODE = (
    "course material 004_bfdbb1594143ed8b.txt (A. Mignone, lecture notes 'Ordinary Differential "
    "Equations: Initial Value Problems', Univ. Torino 2017-18)"
)


# -- gaussian: y' = -t y ------------------------------------------------------------------------
def _gaussian_exact(t: float, y0: np.ndarray, t0: float, pars: np.ndarray | None) -> np.ndarray:
    return np.asarray(y0, dtype=np.float64) * np.exp(-(t * t - t0 * t0) / 2.0)


_y = hy.make_vars("y")
GAUSSIAN = Problem(
    "gaussian",
    variables=[_y],
    rhs=[-hy.time * _y],
    y0=[1.0],
    t_span=(0.0, 3.0),
    exact=_gaussian_exact,
    description=(
        "y' = -t y, y(0) = 1 on [0, 3]; exact y = y0 exp(-(t^2 - t0^2)/2). A non-autonomous "
        "scalar equation: the first test of every one-step method."
    ),
    reference=f"{_COURSE_ODE}, Practice Session #1 (Euler's method on dy/dx = -xy).",
    tags=("scalar", "non-autonomous"),
)


# -- dahlquist: y' = lambda y, lambda complex, state (Re y, Im y) -------------------------------
def _dahlquist_exact(t: float, y0: np.ndarray, t0: float, pars: np.ndarray | None) -> np.ndarray:
    y0 = np.asarray(y0, dtype=np.float64)
    n = y0.shape[1]
    if pars is None:
        pars = DAHLQUIST.pars_for(n)
    pars = np.asarray(pars, dtype=np.float64)
    if pars.ndim == 1:
        pars = np.repeat(pars[:, None], n, axis=1)
    z = np.exp((pars[0] + 1j * pars[1]) * (t - t0)) * (y0[0] + 1j * y0[1])
    return np.stack([z.real, z.imag])


_yr, _yi = hy.make_vars("y_re", "y_im")
_lre, _lim = hy.par[0], hy.par[1]
DAHLQUIST = Problem(
    "dahlquist",
    variables=[_yr, _yi],
    rhs=[_lre * _yr - _lim * _yi, _lim * _yr + _lre * _yi],
    y0=[1.0, 0.0],
    t_span=(0.0, 1.0),
    parameters={"lambda_re": -1.0, "lambda_im": 0.0},
    exact=_dahlquist_exact,
    description=(
        "Dahlquist's test equation y' = lambda y with complex lambda, written as the real system "
        "for (Re y, Im y); parameters lambda_re, lambda_im (default lambda = -1); y(0) = 1 on "
        "[0, 1]; exact y = exp(lambda (t - t0)) y0. Sweeping lambda h over the complex plane maps "
        "a method's linear stability domain."
    ),
    reference=(
        f"{_COURSE_ODE}, the model problem y' = lambda y and the linear stability domain; "
        "G. Dahlquist, BIT 3 (1963) 27-43."
    ),
    tags=("scalar", "linear", "stability"),
)


# -- free-fall: x'' = -10 -----------------------------------------------------------------------
def _free_fall_exact(t: float, y0: np.ndarray, t0: float, pars: np.ndarray | None) -> np.ndarray:
    y0 = np.asarray(y0, dtype=np.float64)
    s = t - t0
    return np.stack([y0[0] + y0[1] * s - 5.0 * s * s, y0[1] - 10.0 * s])


_x, _v = hy.make_vars("x", "v")
FREE_FALL = Problem(
    "free-fall",
    variables=[_x, _v],
    newtonian=NewtonianForm(positions=(_x,), velocities=(_v,), acceleration=(hy.expression(-10.0),)),
    y0=[5.0, 0.0],
    t_span=(0.0, 1.0),
    invariants={"energy": _v * _v / 2.0 + 10.0 * _x},
    exact=_free_fall_exact,
    conservative=True,
    description=(
        "A ball dropped from x = 5 under constant gravity x'' = -10 (v = 0), until it reaches the "
        "ground at t = 1; exact x = x0 + v0 s - 5 s^2, s = t - t0. The solution is a quadratic, "
        "so every method of order >= 2 reproduces it to rounding: an `exact` verdict."
    ),
    reference=(
        "course material 001_99dff2c5051246a9.txt (algorithm-archive chapter 'Verlet "
        "Integration'), the dropped-ball example."
    ),
    tags=("newtonian", "polynomial"),
)

PROBLEMS: list[Problem] = [GAUSSIAN, DAHLQUIST, FREE_FALL]
