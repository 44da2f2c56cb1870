"""One-degree-of-freedom oscillators: `harmonic`, `pendulum`, `pendulum-small`, `forced-duffing`,
`damped-cubic`.

The pendulum's exact solution uses Jacobi elliptic functions (valid for any librating start, so
perturbed ensembles keep an exact answer); the forced Duffing and damped cubic oscillators are the
two worked examples of the Verlet notes the project grew from.
"""

from __future__ import annotations

import math

import heyoka as hy
import numpy as np
from scipy import special

from harness.errors import InputError
from harness.problem import NewtonianForm, Problem
from harness.tolerances import CONVERGENCE_PERIODS

__all__ = [
    "PROBLEMS",
    "HARMONIC",
    "PENDULUM",
    "PENDULUM_SMALL",
    "FORCED_DUFFING",
    "DAMPED_CUBIC",
    "pendulum_exact",
    "pendulum_period",
    "small_angle",
]

_COURSE_ODE = (
    "course material 004_bfdbb1594143ed8b.txt (A. Mignone, lecture notes 'Ordinary Differential "
    "Equations: Initial Value Problems', Univ. Torino 2017-18)"
)
_COURSE_VERLET = (
    "course material 000_30bd195af4439699.txt (notes deriving Verlet integration from central differences)"
)

_x, _v = hy.make_vars("x", "v")
_theta, _omega = hy.make_vars("theta", "omega")


# -- harmonic: x'' = -x -------------------------------------------------------------------------
def _harmonic_exact(t: float, y0: np.ndarray, t0: float, pars: np.ndarray | None) -> np.ndarray:
    y0 = np.asarray(y0, dtype=np.float64)
    c, s = math.cos(t - t0), math.sin(t - t0)
    return np.stack([y0[0] * c + y0[1] * s, -y0[0] * s + y0[1] * c])


HARMONIC = Problem(
    "harmonic",
    variables=[_x, _v],
    newtonian=NewtonianForm(positions=(_x,), velocities=(_v,), acceleration=(-_x,)),
    y0=[1.0, 0.0],
    t_span=(0.0, 20.0 * math.pi),  # 10 periods
    # A little over one period for the convergence sweep: over 10 periods Euler's error
    # (~ h t / 2) first falls below 1e-2 at ~2e5 steps, beyond the sweep's budget; the order does
    # not depend on the horizon, only the error constant does. Not a whole period: there the
    # O(h) term of conjugate-symplectic methods (symplectic Euler) cancels and they measure 2.
    convergence_t_end=CONVERGENCE_PERIODS * 2.0 * math.pi,
    invariants={"energy": (_x * _x + _v * _v) / 2.0},
    period=2.0 * math.pi,
    exact=_harmonic_exact,
    conservative=True,
    description=(
        "Harmonic oscillator x'' = -x (omega = 1), x = 1, v = 0, over 10 periods; exact "
        "x = x0 cos(t - t0) + v0 sin(t - t0). Energy (x^2 + v^2)/2 is conserved."
    ),
    reference=f"{_COURSE_ODE}, Practice Sessions #2 and #4 (harmonic oscillator, 10 periods).",
    tags=("newtonian", "linear", "hamiltonian"),
)


# -- pendulum: theta'' = -sin(theta) --------------------------------------------------------------
def pendulum_period(theta0: float, omega0: float = 0.0) -> float:
    """True period 4 K(m) of a librating pendulum, m = k^2 = E/2, E = omega^2/2 + 1 - cos theta.

    Parameters
    ----------
    theta0 : float, start angle.
    omega0 : float, optional, start angular velocity (default 0).

    Returns
    -------
    float: the period; `InputError` for a rotating start (energy >= 2).
    """
    energy = omega0 * omega0 / 2.0 + 2.0 * math.sin(theta0 / 2.0) ** 2
    m = energy / 2.0
    if not 0.0 <= m < 1.0:
        raise InputError(f"pendulum period needs a librating start (energy < 2), got energy {energy}")
    return 4.0 * float(special.ellipk(m))


def pendulum_exact(t: float, y0: np.ndarray, t0: float, pars: np.ndarray | None = None) -> np.ndarray:
    """Exact pendulum state at t from librating starts (theta0, omega0), shaped (2, N).

    With k^2 = m = E/2 (E = omega^2/2 + 1 - cos theta) the solution is
    sin(theta/2) = k sn(u | m), omega = 2 k cn(u | m), u = t - t0 + F(phi0 | m), where the
    amplitude phi0 = atan2(sin(theta0/2), omega0/2) (NIST DLMF section 22.19(i)). u is reduced
    modulo the period 4K before evaluating sn and cn.

    Parameters
    ----------
    t : float, the time.
    y0 : ndarray, shape (2, N), librating starts (theta, omega).
    t0 : float, their time.
    pars : ndarray, optional, unused.

    Returns
    -------
    ndarray, shape (2, N)
    """
    y0 = np.asarray(y0, dtype=np.float64)
    theta0, omega0 = y0[0], y0[1]
    # bring theta0 into (-pi, pi], remembering the whole turns to add back
    turns = np.round(theta0 / (2.0 * math.pi))
    theta_red = theta0 - turns * 2.0 * math.pi
    half_sin = np.sin(theta_red / 2.0)
    m = (omega0 * omega0 / 4.0) + half_sin * half_sin
    if np.any(m >= 1.0):
        raise InputError(
            "pendulum exact solution needs librating starts (energy < 2), got energy "
            f"{float(np.max(2.0 * m))}"
        )
    k = np.sqrt(m)
    phi0 = np.arctan2(half_sin, omega0 / 2.0)
    tau = special.ellipkinc(phi0, m)
    period = 4.0 * special.ellipk(m)
    u = np.mod(tau + (t - t0), period)
    sn, cn, _dn, _ph = special.ellipj(u, m)
    theta = 2.0 * np.arcsin(k * sn) + turns * 2.0 * math.pi
    omega = 2.0 * k * cn
    at_rest = m == 0.0
    if np.any(at_rest):
        theta = np.where(at_rest, theta0, theta)
        omega = np.where(at_rest, 0.0, omega)
    return np.stack([theta, omega])


def small_angle(t: float, y0: np.ndarray, t0: float, pars: np.ndarray | None = None) -> np.ndarray:
    """The small-angle (sin theta ~ theta) approximation: a harmonic oscillator.

    Parameters
    ----------
    t : float, the time.
    y0 : ndarray, shape (2, N), starts (theta, omega).
    t0 : float, their time.
    pars : ndarray, optional, unused.

    Returns
    -------
    ndarray, shape (2, N): theta0 cos(t - t0) + omega0 sin(t - t0) and its derivative.
    """
    return _harmonic_exact(t, y0, t0, pars)


_PENDULUM_REF = (
    f"{_COURSE_ODE}, Practice Session #5 (simple gravity pendulum, g/L = 1, theta0 = pi/4, "
    "omega0 = 0, 50 periods; theta0 = pi/40 against the small-angle solution)"
)
_pendulum_nf = NewtonianForm(positions=(_theta,), velocities=(_omega,), acceleration=(-hy.sin(_theta),))
_pendulum_energy = {"energy": _omega * _omega / 2.0 + (1.0 - hy.cos(_theta))}
_PERIOD_LARGE = pendulum_period(math.pi / 4.0)
_PERIOD_SMALL = pendulum_period(math.pi / 40.0)

def _pendulum(name: str, theta0: float, period: float, description: str, reference: str, **extra) -> Problem:
    """The pendulum released from rest at `theta0` over 50 true periods; the convergence sweep
    runs 5 periods: 50 periods at the finest step sizes of first-order methods would exceed the
    sweep's step budget without changing the measured order."""
    return Problem(
        name,
        variables=[_theta, _omega],
        newtonian=_pendulum_nf,
        y0=[theta0, 0.0],
        t_span=(0.0, 50.0 * period),
        period=period,
        invariants=_pendulum_energy,
        exact=pendulum_exact,
        conservative=True,
        convergence_t_end=(4.0 + CONVERGENCE_PERIODS - 1.0) * period,
        description=description,
        reference=reference,
        tags=("newtonian", "nonlinear", "hamiltonian"),
        **extra,
    )


PENDULUM = _pendulum(
    "pendulum",
    math.pi / 4.0,
    _PERIOD_LARGE,
    "Simple pendulum theta'' = -sin(theta) (g/L = 1), theta = pi/4, omega = 0, over 50 true "
    f"(amplitude-dependent) periods, T = 4K(sin^2(theta0/2)) = {_PERIOD_LARGE:.6f}. Exact "
    "solution through Jacobi elliptic functions for any librating start.",
    _PENDULUM_REF + "; NIST DLMF section 22.19(i) (the pendulum via elliptic functions).",
)

PENDULUM_SMALL = _pendulum(
    "pendulum-small",
    math.pi / 40.0,
    _PERIOD_SMALL,
    "Simple pendulum at small amplitude, theta = pi/40, omega = 0, over 50 true periods "
    f"(T = {_PERIOD_SMALL:.6f}); exact elliptic-function solution, and the small-angle "
    "solution theta0 cos t + omega0 sin t as an approximation to compare against.",
    _PENDULUM_REF + ".",
    approximations={"small-angle": small_angle},
)


# -- forced Duffing: x'' = -x + x^3 + 0.1 cos t --------------------------------------------------
FORCED_DUFFING = Problem(
    "forced-duffing",
    variables=[_x, _v],
    newtonian=NewtonianForm(
        positions=(_x,), velocities=(_v,), acceleration=(-_x + _x * _x * _x + 0.1 * hy.cos(hy.time),)
    ),
    y0=[0.0, 0.0],
    t_span=(0.0, 10.0),
    description=(
        "Forced softening Duffing oscillator x'' = -x + x^3 + 0.1 cos t from rest at x = 0 on "
        "[0, 10]; the forcing is resonant, so the amplitude grows. Explicitly time-dependent and "
        "non-conservative; no closed-form solution (heyoka ground truth only)."
    ),
    reference=f"{_COURSE_VERLET}, Example 1 (the demonstration there runs h = 0.001 to t = 100).",
    tags=("newtonian", "nonlinear", "non-autonomous"),
)


# -- damped cubic: x'' = -v - x^3 -----------------------------------------------------------------
DAMPED_CUBIC = Problem(
    "damped-cubic",
    variables=[_x, _v],
    newtonian=NewtonianForm(positions=(_x,), velocities=(_v,), acceleration=(-_v - _x * _x * _x,)),
    y0=[10.0, 0.0],
    t_span=(0.0, 3.0),
    description=(
        "Damped oscillator with a cubic spring, x'' = -v - x^3, x = 10, v = 0 on [0, 3]. The "
        "acceleration depends on the velocity, which the two-step Verlet form can only handle "
        "through a central-difference velocity (the velocity-dependent Verlet variant)."
    ),
    reference=f"{_COURSE_VERLET}, Example 2 (velocity-dependent force).",
    tags=("newtonian", "nonlinear", "dissipative", "velocity-dependent"),
)

PROBLEMS: list[Problem] = [HARMONIC, PENDULUM, PENDULUM_SMALL, FORCED_DUFFING, DAMPED_CUBIC]
