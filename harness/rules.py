"""How to judge: the verdict a (method, problem) pair should show, from facts alone.

Every rule reads `harness.facts.MethodFacts` and `ProblemFacts` and says why in one sentence.
The gate, every experiment and the report use these rules; none of them looks at a name, so a
user's method with the same coefficients as a built-in gets the same expectation.

Convergence (`convergence_expectation`), first rule that applies. Each verdict rests on the
theorem cited with it; a slope is read against it only over the asymptotic range, where the
global error's expansion e(h) = C_p h^p + O(h^(p+1)) holds (HNW I, II.8, Theorem 8.1):
1. adaptive method: judged by its tolerance sweep (`meets-tolerance`), see below;
2. the solution is a polynomial of degree d in t and the method's linear order is >= d: `exact`
   (the one-step map is the Taylor polynomial of the exact flow up to degree d). Such a problem
   is y' = Ay + b with A nilpotent (A^(d+1) = 0), where a Runge-Kutta step is y_1 = R(hA) y_0
   (augmented by b) and R(hA) = exp(hA) once R(z) agrees with e^z to degree d, so every step is
   exact up to rounding (the stability function, Hairer & Wanner II, IV.3; HNW I, II.2 for the
   Taylor expansion of the numerical solution);
3. linear constant-coefficient problem: `converged` at the linear order (R(z) against e^z),
   which exceeds the order for some methods (several SSP methods, Merson's). On y' = Ay the
   step is y_1 = R(hA) y_0, whose local error R(hA) - exp(hA) = O(h^(q+1)) for R(z) = e^z +
   O(z^(q+1)) (HW II, IV.3); local errors of order q + 1 carried by a stable recursion give a
   global error O(h^q) (Lady Windermere's fan, HNW I, II.3, Theorem 3.4);
4. a problem class where elementary differentials vanish (x'' = g(x) as a first-order system,
   a right-hand side polynomial of degree d in the state; `harness.theory.classes`): `converged`
   at the Runge-Kutta method's order on that class where it exceeds the order. The local error
   is a sum over rooted trees of the order-condition defects times elementary differentials
   (HNW I, II.2, Theorem 2.13); on x'' = g(x) only the Nystrom trees survive (HNW I, II.14), and
   for a polynomial field of degree d every tree with a vertex of more than d children
   vanishes, so only the surviving trees' conditions enter, and the global order follows from
   the local one as in rule 3 (HNW I, II.3, Theorem 3.4);
5. an implicit Runge-Kutta method on a problem that is stiff over its horizon (the fastest
   decay rate times the horizon above STIFF_HORIZON_DECAYS) whose stage order q is below its
   order p: `converged` with any order in [q, p] (`order_low` = q). On the Prothero-Robinson
   equation with h|lambda| -> oo the error is O(h^q), O(h^(q+1)) for stiffly accurate methods,
   and the method is B-convergent of order q (Hairer & Wanner II, IV.15, Theorem 15.3; for
   singularly perturbed problems VI.3); a sweep whose steps cross h|lambda| ~ 1 sees a slope
   between the stiff and the classical order that no theorem fixes, so the range is the verdict;
6. otherwise `converged` at the order (from coefficients, or the claim of a black box): a
   one-step method of order p (local error O(h^(p+1)), HNW I, II.2) with a Lipschitz increment
   converges with global error O(h^p) (HNW I, II.3, Theorem 3.6); a zero-stable linear
   multistep method of order p, with starting values of error O(h^p), likewise (Dahlquist;
   HNW I, III.4, and III.10 for x'' = f(x) methods). A black box's order is its claim's own
   words, tested by the same expansion.
Verdicts that say "not measurable here" rather than "wrong" (`tolerated`):
- `insufficient-range` always: the measurement states the limit that stopped it (work budget,
  float64 floor, reference accuracy) and the order is then judged on the other problems;
- `unstable` too, when the problem is stiff for this method: the stability interval divided
  by the stiffness (largest -Re(lambda) along the reference) asks for more than
  STIFF_STEP_COUNT steps over the horizon, where the error is already near the rounding floor;
- `converged` when the problem is stiff for this method and the fitted steps reach above its
  stable step (real stability interval / stiffness): h lambda lies outside the stability region
  there, and the slope is that of an amplified mode, not of the error expansion (HW II, IV.2);
- `converged` at another order when the problem starts in an initial layer (`layer_width`:
  most of the start's velocity lies along fast decaying modes) that every fitted step steps
  over: the convergence results for stiff problems (Hairer & Wanner II, VI.2 for multistep
  methods: order p uniformly in the stiffness for A(alpha)-stable methods strictly stable at
  infinity; VI.3 for Runge-Kutta methods) are for a smooth solution, with starting values within
  O(h^p) of it, and the unresolved layer leaves an error of its own (bdf2 on Bari's VDPOL,
  measured: 0.21 eps h in y1 for eps = 5e-7..2e-6, order 1);
- `exact` when not predicted: the error was at the rounding floor even at the coarsest step
  sizes the sweep tried, so no order can be read off (an order-8 method on a short smooth span).
- `failed` of an implicit method whose every step size failed in its implicit solve, when even
  the finest of them has h x stiffness >= NEWTON_GUARANTEE_STEPS: the stage equations' iteration
  is guaranteed to converge only for h L |a| < 1 (L a Lipschitz constant, at least the
  stiffness; |a| the implicit coefficient; HNW I, II.7, Theorem 7.2, and Hairer & Wanner II,
  IV.8 for Newton's iteration), so a failure beyond it says nothing about the method's order.
The gate also needs at least one cell per stepper that measures the claim: a stepper judged on
nothing does not pass.

Adaptive steppers (`tolerance_allowance`): local error control keeps each accepted step's error
near tol x |y|, and the flow carries every step's error to the final time, amplified by at most
A = ||d Phi(t_k -> T)||, taken as max(1, ||d Phi(t0 -> T)||) (`harness.flow.flow_amplification`).
Summed over the N accepted steps of a trajectory (Lady Windermere's fan, HNW I, II.3, Theorem
3.4), the global error is at most ~N A tol |y|; TOLERANCE_ESTIMATE_FACTOR allows for the error
estimate itself being only asymptotically correct. On y' = -y (A = 1, N ~ 2-50) that is tighter
than a fixed 1e4, and on the e = 0.99 orbit (A ~ 7e4) it admits what the flow does to a
perfectly controlled local error.

Energy (`energy_expectation`, `drift_prediction`, `describe_drift`). A verdict only where a
theorem backs it; elsewhere the cell is informational (`no-claim`):
- symplectic by its coefficients => the energy error stays bounded, O(h^p), over exponentially
  long times, for small h and an orbit that stays in a compact set (backward error analysis:
  the method exactly conserves a modified Hamiltonian; HLW IX.8, Theorem 8.1, and IX.3), plus
  rounding's random walk (Brouwer's law, HLW VIII.5). The energy experiment states where the
  premises fail (a run that leaves its bounded regime, h rho beyond the method's h-omega limit
  in a close encounter) as `not-measurable`;
- declared symplectic (a black box, or a claim its coefficients contradict): the claim's own
  words, held to the same bound (the gate fails the contradiction itself);
- symmetric, not symplectic: no drift on reversible *integrable* problems (near-conservation of
  the actions, HLW XI.3, Theorem 3.1), possibly a drift on others (HLW XI.4-XI.5); integrability
  is not a derived problem fact, so `no-claim`;
- neither symplectic nor symmetric, a fixed-step one-step method of order p: `no-claim`, with a
  prediction beside the measurement. On a bounded interval the global error expands as
  h^p e_p(t) + O(h^(p+1)) (HNW I, II.8, Theorem 8.1), so the energy error is
  h^p int_0^t grad H . d_(p+1)(y(s)) ds + O(h^(p+1)) (d_(p+1) the principal local error): a
  drift linear in t on a periodic orbit when that integrand's orbit average is non-zero, the
  rk4 drift on Kepler of HLW I.2. No theorem makes it obligatory over a long run at fixed h: the
  average may vanish, and once the drift is no longer small the orbit it is averaged over has
  changed (a dissipative method's energy settles towards an equilibrium and its error
  saturates: backward Euler on y'' = -w^2 y gives E_n = E_0 (1 + h^2 w^2)^-n). The drift is
  predicted from the run's first natural period (running maximum e_1 there, so e_1 x periods
  over the fit window) and the cell says whether the run shows it; where the prediction is
  within DRIFT_MEASURABLE_FACTOR of what rounding explains, it is `not-measurable`, with the
  numbers;
- adaptive steppers, multistep methods and black boxes are measured without a claim.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from harness import tolerances as tol
from harness.facts import MethodFacts, ProblemFacts, class_key

__all__ = ["Expectation", "convergence_expectation", "describe_drift", "drift_prediction",
           "energy_expectation", "judge_convergence", "tolerance_allowance"]


@dataclass(frozen=True)
class Expectation:
    """The verdict a cell should show, the order it should measure (or None), the verdicts that
    only mean "not measurable here", and the reason for the expectation (empty when it is the
    plain claim). With `order_low`, any measured order in [order_low, order] is expected."""

    verdict: str
    order: float | None
    tolerated: tuple[str, ...]
    reason: str
    order_low: float | None = None
    implicit_stiffness: float | None = None  # the problem's stiffness, for an implicit method
    stable_h: float | None = None  # real stability interval / stiffness, where stiff for the method
    layer_width: float | None = None  # the problem's initial layer, which steps above it skip


def _stiff_steps(method: MethodFacts, problem: ProblemFacts) -> float:
    """Steps the method needs over the horizon before its step is inside its stability interval
    (0 when the interval is unbounded or the problem has no decaying mode)."""
    interval = method.real_interval
    if interval is None or not math.isfinite(interval) or problem.stiffness <= 0:
        return 0.0
    if interval <= 0:
        return math.inf
    return problem.horizon * problem.stiffness / interval


def convergence_expectation(method: MethodFacts, problem: ProblemFacts) -> Expectation:
    """The expected convergence verdict of a (method, problem) pair; see the module docstring.

    Parameters
    ----------
    method : MethodFacts, the method's facts; problem : ProblemFacts, the problem's facts.

    Returns
    -------
    Expectation: the verdict, order and reason, with the stable step for stiff pairs and the
    stiffness for an implicit fixed-step method on a stiff problem.
    """
    expectation = _expectation(method, problem)
    if problem.layer_width is not None and not method.adaptive:
        expectation = replace(expectation, layer_width=float(problem.layer_width))
    if _stiff_steps(method, problem) > tol.STIFF_STEP_COUNT:
        expectation = replace(expectation, stable_h=float(method.real_interval / problem.stiffness))
    if not method.explicit and not method.adaptive and problem.stiffness > 0:
        return replace(expectation, implicit_stiffness=float(problem.stiffness))
    return expectation


def _expectation(method: MethodFacts, problem: ProblemFacts) -> Expectation:
    if method.adaptive or method.order is None:
        return Expectation("meets-tolerance", None, (), "adaptive: judged by its tolerance sweep")
    tolerated = ["insufficient-range", "exact"]
    notes = []
    steps = _stiff_steps(method, problem)
    if steps > tol.STIFF_STEP_COUNT:
        tolerated.append("unstable")
        notes.append(
            f"stiff for this method: -Re(lambda) reaches {problem.stiffness:.3g} along the reference "
            f"and the real stability interval is {method.real_interval:.3g}, so a stable step needs "
            f"~{steps:.3g} steps over the horizon {problem.horizon:.3g}"
        )
    linear_order = method.linear_order if method.linear_order is not None else method.order
    degree = problem.polynomial_degree
    if degree is not None and linear_order >= degree:
        reason = (f"the solution is a polynomial of degree {degree} in t, which a method of linear "
                  f"order {linear_order} >= {degree} reproduces to rounding")
        return Expectation("exact", None, ("insufficient-range",), "; ".join([reason, *notes]))
    if problem.linear and linear_order != method.order:
        reason = (f"linear problem: the error follows R(z) - e^z, which this method matches to "
                  f"order {linear_order} (its order is {method.order})")
        return Expectation("converged", float(linear_order), tuple(tolerated), "; ".join([reason, *notes]))
    class_order, class_reason = _class_order(method, problem)
    if class_order is not None and class_order > method.order:
        return Expectation("converged", float(class_order), tuple(tolerated),
                           "; ".join([class_reason, *notes]))
    low, stiff_reason = _stiff_reduced_order(method, problem)
    if low is not None:
        return Expectation("converged", float(method.order), tuple(tolerated),
                           "; ".join([stiff_reason, *notes]), order_low=float(low))
    return Expectation("converged", float(method.order), tuple(tolerated), "; ".join(notes))


def _class_order(method: MethodFacts, problem: ProblemFacts) -> tuple[int | None, str]:
    """(the method's order on the problem's class, why) or (None, '') when no class applies."""
    degree = problem.rhs_degree if problem.rhs_degree is not None and problem.rhs_degree >= 2 else None
    key = class_key(problem.velocity_free, degree)
    if key is None or not method.class_orders or key not in method.class_orders:
        return None, ""
    parts = ([] if not problem.velocity_free else
             ["x'' = g(x) without velocities (only trees whose vertices of one depth parity have "
              "at most one child survive; HNW I, II.14)"])
    if degree is not None:
        parts.append(f"a right-hand side polynomial of degree {degree} in the state (trees with a "
                     f"vertex of more than {degree} children vanish)")
    order = method.class_orders[key]
    return order, (f"problem class: {' and '.join(parts)}; the coefficients satisfy every "
                   f"surviving order condition up to order {order} (their order is {method.order})")


def _stiff_reduced_order(method: MethodFacts, problem: ProblemFacts) -> tuple[int | None, str]:
    """(stage order q, why) for an implicit Runge-Kutta method with q below its order on a
    problem stiff over its horizon (module docstring, rule 5); (None, '') otherwise."""
    q = method.stage_order
    if (method.explicit or q is None or method.order is None or q >= method.order
            or not problem.stiffness * problem.horizon > tol.STIFF_HORIZON_DECAYS):
        return None, ""
    extra = (", O(h^(q+1)) = h^" + str(q + 1) + " for this stiffly accurate method as h|lambda| -> oo"
             if method.stiffly_accurate else "")
    return q, (f"stiff over the horizon (-Re(lambda) up to {problem.stiffness:.3g}, horizon "
               f"{problem.horizon:.3g}): an implicit method of stage order {q} may fall from its "
               f"order {method.order} towards {q} (B-convergence, Prothero-Robinson{extra}; Hairer "
               f"& Wanner II, IV.15); where the steps cross h|lambda| ~ 1 no theorem fixes the "
               f"slope, so any order in [{q}, {method.order}] is expected")


def judge_convergence(record: dict, expectation: Expectation) -> tuple[str, str]:
    """(outcome, reason) of one convergence summary record: outcome is `pass`, `fail` or
    `not-measurable` (a tolerated verdict: neither evidence for nor against the claim).

    Parameters
    ----------
    record : dict, with 'verdict', 'message' and, for a fit, 'measured_order' and 'fit_h_max';
    expectation : Expectation, from `convergence_expectation`.

    Returns
    -------
    tuple (str, str): (outcome, reason).
    """
    verdict = record["verdict"]
    msg = str(record.get("message") or "")
    if expectation.verdict == "meets-tolerance":
        if verdict == "meets-tolerance":
            return "pass", expectation.reason
        if verdict == "insufficient-range":  # no tolerance of the sweep inside the library's range
            return "not-measurable", msg or "adaptive stepper: no tolerance of the sweep could run"
        return "fail", f"adaptive stepper: {verdict}" + (f": {msg}" if msg else "")
    stable_h = expectation.stable_h
    above = stable_h is not None and float(record.get("fit_h_max", math.nan)) > stable_h
    if verdict == "converged" and above:  # a fit over steps outside the stability interval
        return "not-measurable", (
            f"the fitted steps reach h = {float(record['fit_h_max']):.3g}, above the stable step "
            f"{expectation.stable_h:.3g} (real stability interval / stiffness): there h lambda lies "
            f"outside the stability region and the error is an amplified mode, not the expansion "
            f"C h^p the order is read from (HW II, IV.2)"
            + (f"; {expectation.reason}" if expectation.reason else ""))
    if verdict == expectation.verdict:
        if expectation.order is None:
            return "pass", expectation.reason
        measured = float(record["measured_order"])
        if expectation.order_low is not None:
            lo, hi = expectation.order_low, expectation.order
            if math.isfinite(measured) and lo - tol.GATE_ORDER_TOL <= measured <= hi + tol.GATE_ORDER_TOL:
                return "pass", f"measured order {measured:.3f} within [{lo:g}, {hi:g}]: {expectation.reason}"
            if layer := _unresolved_layer(record, expectation):
                return "not-measurable", (f"measured order {measured:.3f} outside [{lo:g}, {hi:g}], "
                                          f"but {layer}")
            return "fail", (f"measured order {measured:.3f} outside [{lo:g}, {hi:g}] (+-"
                            f"{tol.GATE_ORDER_TOL}): {expectation.reason}")
        diff = abs(measured - expectation.order)
        if math.isfinite(measured) and diff <= tol.GATE_ORDER_TOL:
            return "pass", expectation.reason
        if layer := _unresolved_layer(record, expectation):
            return "not-measurable", (f"measured order {measured:.3f} against {expectation.order:g}, "
                                      f"but {layer}")
        return "fail", (f"measured order {measured:.3f} differs from the expected "
                        f"{expectation.order:g} by {diff:.3f} > {tol.GATE_ORDER_TOL}"
                        + (f" ({expectation.reason})" if expectation.reason else ""))
    if verdict in expectation.tolerated:
        why = {
            "insufficient-range": "too few points in the asymptotic range",
            "exact": "the error is at the rounding floor at every step size tried",
            "unstable": "unstable at every step size above the rounding floor",
        }[verdict]
        detail = "; ".join(x for x in (msg, expectation.reason) if x)
        return "not-measurable", f"{why}" + (f": {detail}" if detail else "")
    unguaranteed = _unguaranteed_solve(record, expectation)
    if unguaranteed:
        return "not-measurable", "; ".join(x for x in (unguaranteed, msg) if x)
    expected = expectation.verdict + (f" at order {expectation.order:g}" if expectation.order else "")
    return "fail", (f"expected {expected}, got {verdict}" + (f": {msg}" if msg else "")
                    + (f" ({expectation.reason})" if expectation.reason else ""))


def _unresolved_layer(record: dict, expectation: Expectation) -> str:
    """Why a fitted order says nothing about the method (module docstring), or '' when it
    stands: the problem starts in an initial layer that every fitted step steps over."""
    width = expectation.layer_width
    h_min = float(record.get("fit_h_min", math.nan))
    if width is None or not h_min > width:
        return ""
    return (f"the problem starts in an initial layer of width {width:.3g} (1 / the fastest decay "
            f"rate at the start, along which most of the start's velocity lies) and every fitted "
            f"step (h >= {h_min:.3g}) steps over it: order p on stiff problems is proved for a "
            f"smooth solution, with starting values within O(h^p) of it (Hairer & Wanner II, VI.2 "
            f"for multistep, VI.3 for Runge-Kutta methods); the layer the steps do not resolve "
            f"leaves an error those results do not bound by C h^p")


def _unguaranteed_solve(record: dict, expectation: Expectation) -> str:
    """Why a `failed` implicit cell is not measurable (module docstring), or '' when it stands:
    every step size failed in its implicit solve and even the finest one lies where no theorem
    guarantees that the stage equations' iteration converges."""
    stiffness = expectation.implicit_stiffness
    h = float(record.get("finest_h", math.nan))
    if record["verdict"] != "failed" or not stiffness or not math.isfinite(h):
        return ""
    if h * stiffness < tol.NEWTON_GUARANTEE_STEPS:
        return ""
    return (f"the implicit solve failed at every step size the work budget allowed, down to h = "
            f"{h:.3g}, where h x stiffness = {h * stiffness:.3g} >= {tol.NEWTON_GUARANTEE_STEPS:g}: "
            f"the stage equations' iteration is guaranteed to converge only for h L |a| < 1 (HNW I, "
            f"II.7, Theorem 7.2; Hairer & Wanner II, IV.8), so the failure says nothing about the "
            f"method's order")


def tolerance_allowance(steps_per_trajectory: float, amplification: float) -> tuple[float, str]:
    """(factor, reason): the global error an adaptive run may reach, in units of tol x |y| (see
    the module docstring). Without a step count or an amplification, the fixed
    TOLERANCE_FACTOR (ten thousand steps' worth), and the reason says so.

    Parameters
    ----------
    steps_per_trajectory : float, the run's steps; amplification : float, the flow's error
    amplification.

    Returns
    -------
    tuple (float, str): (factor, reason).
    """
    if not (math.isfinite(steps_per_trajectory) and steps_per_trajectory > 0
            and math.isfinite(amplification) and amplification > 0):
        return tol.TOLERANCE_FACTOR, (f"the fixed {tol.TOLERANCE_FACTOR:g} (no step count or flow "
                                      "amplification)")
    A = max(1.0, amplification)
    factor = tol.TOLERANCE_ESTIMATE_FACTOR * steps_per_trajectory * A
    return factor, (f"{tol.TOLERANCE_ESTIMATE_FACTOR:g} x {steps_per_trajectory:.4g} steps x flow "
                    f"amplification {A:.3g} = {factor:.3g}")


def energy_expectation(method: MethodFacts, declared_symplectic: bool = False) -> tuple[str, str]:
    """(expected drift class or '', reason): the only energy claim a theorem backs is that a
    symplectic method keeps the energy error bounded (HLW IX.8, Theorem 8.1; rounding adds a
    sqrt(t) random walk, Brouwer's law, HLW VIII.5). A declared claim is held to that too, even
    where the coefficients contradict it (the gate fails the contradiction itself). Every
    other method gets ('', ''): no claim (see `drift_prediction`).

    Parameters
    ----------
    method : MethodFacts, its `symplectic` fact; declared_symplectic : bool, the stepper's claim.

    Returns
    -------
    tuple (str, str): ('bounded' or '', the reason).
    """
    if method.symplectic:
        return "bounded", ("symplectic" + (" by its coefficients" if method.source == "coefficients"
                                          else " (declared)") + ": the energy error stays bounded")
    if declared_symplectic:
        return "bounded", ("claimed symplectic (its coefficients say it is not): the energy error "
                           "should stay bounded")
    return "", ""


def drift_prediction(method: MethodFacts) -> str:
    """The informational drift prediction for a fixed-step one-step method that is neither
    symplectic nor symmetric (the module docstring), or '' for every other method.

    Parameters
    ----------
    method : MethodFacts

    Returns
    -------
    str
        The prediction's sentence, or ''.
    """
    if (method.one_step and not method.adaptive and not method.symplectic
            and method.symmetric is False and method.order):
        return (f"neither symplectic nor symmetric, order {method.order}: first-order theory "
                f"predicts an energy drift ~h^{method.order} t while it stays small (no theorem "
                "requires it)")
    return ""


def describe_drift(prediction: str, drift_class: str, max_error: float, first_period_error: float,
                   periods_in_fit: float, periods_total: float, rounding_fit: float,
                   rounding_period: float) -> tuple[str, str]:
    """(verdict, reason) of an energy cell that carries a drift prediction (`drift_prediction`):
    `not-measurable` when the predicted drift is hidden by rounding or cannot be predicted,
    else `no-claim`, saying whether the run shows the predicted drift. Never a failure: no
    theorem makes the drift obligatory (the module docstring).

    Parameters
    ----------
    prediction : str
        The prediction's sentence (`drift_prediction`).
    drift_class : str
        The measured class of the energy error's envelope.
    max_error, first_period_error : float
        The largest relative energy error of the run, and within its first natural period.
    periods_in_fit, periods_total : float
        Natural periods in the envelope's fit window, and in the whole run.
    rounding_fit, rounding_period : float
        What rounding explains over the fit window and over one period.

    Returns
    -------
    (str, str)
        The verdict and its reason.
    """
    if not math.isfinite(first_period_error):
        return "not-measurable", (f"{prediction}, but the run has no finite energy sample within "
                                  "its first period, so the drift cannot be predicted")
    predicted = first_period_error * periods_in_fit
    hidden = (first_period_error <= tol.DRIFT_MEASURABLE_FACTOR * rounding_period
              or predicted <= tol.DRIFT_MEASURABLE_FACTOR * rounding_fit)
    numbers = (f"energy error {first_period_error:.3g} after the first period, so a drift of "
               f"~{predicted:.3g} over the fit window ({periods_in_fit:.3g} periods); rounding "
               f"explains {rounding_fit:.3g}")
    if hidden:
        return "not-measurable", (f"{prediction}, but the predicted drift is within "
                                  f"{tol.DRIFT_MEASURABLE_FACTOR:g}x of rounding: {numbers}")
    if drift_class == "linear":
        return "no-claim", f"{prediction}; the run shows it: {numbers}"
    reaches = first_period_error * periods_total >= tol.ENERGY_BLOWUP_ERROR
    if drift_class == "unstable" and reaches and max_error >= tol.ENERGY_BLOWUP_ERROR:
        return "no-claim", (f"{prediction}; the run shows it reaching {tol.ENERGY_BLOWUP_ERROR:g}: "
                            f"{numbers}")
    return "no-claim", (f"{prediction}; the run is {drift_class} instead (the secular term may "
                        f"vanish, and a dissipative method's error saturates as the orbit settles; "
                        f"max error {max_error:.3g}): {numbers}")
