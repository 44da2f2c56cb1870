"""What a tableau's coefficients say about the errors a convergence sweep can show.

- `coefficient_floor`: the record's own defects in the order conditions leave an error no
  arithmetic removes (`harness.theory.defects`); a sweep excludes points near it (`coefficients`);
- `coefficient_rounding_floor`: coefficients rounded to float64 miss the conditions by their
  rounding times their size, part of the float64 rounding floor (large extrapolation weights);
  `rounded_coefficient_floor` is the same at another unit roundoff (the real128 sweep's);
- `order_bound` and `mark_above_order`: no problem shows a slope above max(order, linear order)
  asymptotically (the linear order counts the tall trees, which every class keeps), so a fitted
  slope above it by more than ABOVE_ORDER_TOL is higher-order terms still dominating; a black
  box is bounded by its declared claims the same way.
Used by the float64 sweep (`harness.experiments.convergence`) and the real128 one
(`harness.extended`) alike.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from harness import tolerances as tol
from harness.coefficients import ButcherTableau
from harness.scales import derive_time_scale
from harness.stepper import Stepper
from harness.theory.defects import condition_defects, defect_floor

__all__ = ["coefficient_floor", "coefficient_rounding_floor", "rounded_coefficient_floor", "order_bound",
           "mark_above_order", "problem_rate"]


def problem_rate(problem) -> float:
    """The problem's fastest rate along its orbit (`harness.scales`), the size of an elementary
    differential per order; 1 per unit time where it cannot be derived.

    Parameters
    ----------
    problem : Problem, whose time scale is derived.

    Returns
    -------
    float: a positive rate, 1.0 when it cannot be derived.
    """
    try:
        rate = float(derive_time_scale(problem).fastest_rate)
    except Exception:  # a problem whose orbit sampling fails keeps its cell: unit rate
        return 1.0
    return rate if np.isfinite(rate) and rate > 0 else 1.0


def coefficient_rounding_floor(coefficients, problem, *, span: float,
                               scale: float) -> Callable[[np.ndarray], np.ndarray | None]:
    """h -> the error a float64 loop owes to its tableau's coefficients rounded to float64 (their
    defects in the order conditions as run, `harness.theory.defects`): part of the float64
    rounding floor, which it raises only for coefficients of large magnitude (an order-11
    extrapolation tableau's weights sum |b| to ~1e5 and lose ~1e-11); None where every defect
    is within DEFECT_NOISE_ULPS roundings, as for coefficients of ordinary size.

    Parameters
    ----------
    coefficients : the method's coefficient object (only explicit ButcherTableau count);
    problem : Problem, whose rate sizes the elementary differentials; span : float, the
    integration time; scale : float, the solution's size.

    Returns
    -------
    callable: h array -> floor array, or -> None when there is no such floor.
    """
    none = lambda h: None  # noqa: E731
    if not isinstance(coefficients, ButcherTableau) or not coefficients.explicit:
        return none
    defects = condition_defects(coefficients, coefficients.order(), as_run_in_float64=True)
    if not any(d > tol.DEFECT_NOISE_ULPS * tol.EPS for d, _ in defects):
        return none
    rate = problem_rate(problem)
    return lambda h: defect_floor(defects, 0.0, h, span=span, rate=rate, scale=scale)


def rounded_coefficient_floor(coefficients, problem, *, span: float, scale: float,
                              eps: float) -> Callable[[np.ndarray], np.ndarray] | None:
    """h -> what rounding a tableau's coefficients to the unit roundoff `eps` leaves, for the
    real128 sweep: each order condition off by about eps times the size of its products
    (`harness.theory.defects`), as large as 1e-29 in real128 for extrapolation weights summing
    |b| to 1e5.

    Parameters
    ----------
    coefficients, problem, span, scale : as in `coefficient_floor`; eps : float, the unit roundoff
    the coefficients are rounded to.

    Returns
    -------
    callable or None: h array -> floor array; None for other families than ButcherTableau.
    """
    if not isinstance(coefficients, ButcherTableau):
        return None
    sizes = [(eps * size, size) for _, size in condition_defects(coefficients, coefficients.order())]
    rate = problem_rate(problem)
    return lambda h: defect_floor(sizes, 0.0, h, span=span, rate=rate, scale=scale)


def coefficient_floor(coefficients, problem, *, span: float, scale: float,
                      noise: float) -> Callable[[np.ndarray], np.ndarray | None]:
    """h -> the error floor an explicit Runge-Kutta tableau's defects in the order conditions
    leave (`harness.theory.defects.defect_floor`), or None where those defects are within
    `noise` (the arithmetic's unit roundoff) of rounding or `coefficients` is no such tableau.

    Parameters
    ----------
    coefficients : the method's coefficient object; problem : Problem, whose rate sizes the
    elementary differentials; span : float, the integration time; scale : float, the solution's
    size; noise : float, the unit roundoff of the arithmetic run.

    Returns
    -------
    callable: h array -> floor array; its value is None where the defects are within noise.
    """
    none = lambda h: None  # noqa: E731
    if not isinstance(coefficients, ButcherTableau) or not coefficients.explicit:
        return none
    defects = condition_defects(coefficients, coefficients.order())
    threshold = tol.DEFECT_NOISE_ULPS * noise
    if not any(d > threshold * q * max(1.0, size) for q, (d, size) in enumerate(defects, start=1)):
        return none
    rate = problem_rate(problem)

    def floor(h: np.ndarray) -> np.ndarray:
        return defect_floor(defects, threshold, h, span=span, rate=rate, scale=scale)

    return floor


def order_bound(stepper: Stepper) -> int | None:
    """max(order, linear order) of the stepper's coefficients; for a black box, of its declared
    claims (`claimed_order`, and `extra["linear_order"]` where declared): a slope above the
    claimed order does not contradict the claim (the error is O(h^p) still) and cannot be read as
    the order either, so those points are pre-asymptotic as for a tableau. None when neither is
    known (no coefficients and no claimed order).

    Parameters
    ----------
    stepper : Stepper, its coefficients or its declared claims (an adaptive one has no bound).

    Returns
    -------
    int or None: the bound.
    """
    coefficients = getattr(stepper, "coefficients", None)
    try:
        return max(int(coefficients.order()), int(coefficients.linear_order()))
    except Exception:  # a black box, or a family without both facts: its declared claims
        info = getattr(stepper, "info", None)
        claimed = getattr(info, "claimed_order", None)
        if not isinstance(claimed, int) or isinstance(claimed, bool) or getattr(info, "adaptive", False):
            return None
        linear = (getattr(info, "extra", None) or {}).get("linear_order")
        return max(claimed, linear) if isinstance(linear, int) and not isinstance(linear, bool) else claimed


def mark_above_order(h: np.ndarray, error: np.ndarray, reasons: np.ndarray,
                     bound: int | None) -> str:
    """Where the points kept (reason '') fit a slope above `bound` + ABOVE_ORDER_TOL, mark them
    `pre-asymptotic` in place and return the reason; else ''.

    Parameters
    ----------
    h, error : step sizes and errors of the points; reasons : str array, each point's exclusion
    reason ('' when kept), changed in place; bound : int or None, from `order_bound` (None: no
    check).

    Returns
    -------
    str: the reason given to the marked points, or ''.
    """
    kept = np.flatnonzero(reasons == "")
    if bound is None or kept.size < 2:
        return ""
    slope = float(np.polyfit(np.log(h[kept]), np.log(error[kept]), 1)[0])  # the fit's least-squares slope
    if slope <= bound + tol.ABOVE_ORDER_TOL:
        return ""
    reasons[kept] = "pre-asymptotic"
    return (f"slope {slope:.3f} over the settled points is above the order bound {bound} (max of "
            f"order and linear order, from the coefficients or the declared claims): higher-order "
            f"error terms still dominate there")
