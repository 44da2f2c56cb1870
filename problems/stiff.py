"""A stiff problem for implicit methods: `van-der-pol-stiff`.

Van der Pol's equation in the scaled form of Hairer & Wanner (Solving Ordinary Differential
Equations II, 2nd ed., Springer 1996, the VDPOL test problem):

    y1' = y2,    y2' = ((1 - y1^2) y2 - y1) / eps,

started on the smooth (slow-manifold) solution, y1 = 2 and y2 = -2/3 + 10/81 eps - 292/2187 eps^2
- 1814/19683 eps^3 (the same book's asymptotic expansion), so there is no initial transient.

Why eps = 1e-3 on [0, 0.5]: along the slow branch y1 falls from 2 to about 1.6 and the stiff
eigenvalue of the Jacobian, (1 - y1^2)/eps, stays between -3000 and -1500, while the solution
itself varies on a time scale of order one. Explicit methods must keep h |lambda| inside their
stability interval (h < 2/3000 for Euler, ~9e-4 for RK4) although h ~ 1e-2 resolves the
solution: they blow up at step sizes where A-stable implicit methods converge. The span stops
before the fast jump at y1 = 1 (t ~ 0.8), where the problem stops being stiff. heyoka's Taylor
integrator, whose step is limited by |lambda| too, still needs only ~100-200 steps per level
(about 7 ms in real128 per trajectory); eps = 1e-4 would cost 10x more for the same lesson.
eps is a parameter (`epsilon`), so stiffer variants need no new definition.
"""

from __future__ import annotations

import heyoka as hy

from harness.problem import Problem

__all__ = ["PROBLEMS", "VAN_DER_POL_STIFF", "EPSILON", "smooth_start"]

EPSILON = 1e-3


def smooth_start(eps: float) -> list[float]:
    """(y1, y2) at y1 = 2 on the smooth solution, to O(eps^4).

    Parameters
    ----------
    eps : float, van der Pol's eps (the stiff eigenvalue is about (1 - y1^2) / eps).

    Returns
    -------
    list of float
    """
    return [2.0, -2.0 / 3.0 + 10.0 / 81.0 * eps - 292.0 / 2187.0 * eps**2 - 1814.0 / 19683.0 * eps**3]


_y1, _y2 = hy.make_vars("y1", "y2")
_eps = hy.par[0]

VAN_DER_POL_STIFF = Problem(
    "van-der-pol-stiff",
    variables=[_y1, _y2],
    rhs=[_y2, ((1.0 - _y1 * _y1) * _y2 - _y1) / _eps],
    y0=smooth_start(EPSILON),
    t_span=(0.0, 0.5),
    parameters={"epsilon": EPSILON},
    # Perturbing y2 by more than ~eps moves the start off the slow manifold and adds a boundary
    # layer of width ~eps/3; 1e-4 keeps members close to the smooth solution.
    perturbation=1e-4,
    description=(
        "Stiff van der Pol oscillator in Hairer's scaled form y1' = y2, "
        "y2' = ((1 - y1^2) y2 - y1)/eps, eps = 1e-3, started on the smooth solution at y1 = 2, "
        "over [0, 0.5] (the slow branch; stiff eigenvalue -3000 to -1500). Explicit methods are "
        "unstable for h above ~1e-3 where implicit ones converge."
    ),
    reference=(
        "E. Hairer, G. Wanner, Solving Ordinary Differential Equations II, 2nd ed., Springer "
        "1996 (van der Pol's equation in scaled form, test problem VDPOL, and the expansion of "
        "its smooth solution)."
    ),
    tags=("first-order", "stiff", "nonlinear"),
)

PROBLEMS: list[Problem] = [VAN_DER_POL_STIFF]
