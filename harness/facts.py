"""Facts about a method and a problem, derived from their definitions; the rules read only these.

A verdict never looks at a name. It follows from

- `MethodFacts`: what the coefficients say (order, linear order, stability intervals, symmetric,
  symplectic), asked of the coefficient object like a NodePy method; a method without
  coefficients (a black box) is described by its declared claims instead, and says so
  (`source = "claims"`);
- `ProblemFacts`: what the symbolic (heyoka) definition says: linear (a constant Jacobian and no
  explicit time), the degree of a polynomial solution (a nilpotent affine system), whether the
  acceleration is velocity-free (the Nystrom class), the right-hand side's degree when it is a
  polynomial in the state, and how stiff it is (the Jacobian's spectrum sampled along the
  reference solution over the convergence horizon), and whether it starts in an initial layer
  (`layer_width`: the start's velocity lies mostly along fast decaying modes, so the solution is
  a transient there, not the smooth solution); `central_field`: whether every body's
  acceleration is parallel to its own position (decided on the definition at sampled positions).
A Runge-Kutta method's facts include its orders on those classes (`class_orders`, keyed by
`class_key`), its stage order and whether it is stiffly accurate (`harness.theory.classes`).

Two steppers with the same coefficients have the same facts, whatever they are called.
References: Hairer, Norsett & Wanner, *Solving ODEs I*, II.2 and III.2 (order), Hairer & Wanner,
*Solving ODEs II*, IV.2 (stability functions, stiffness); Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, V-VI (symmetry, symplecticity).
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from functools import lru_cache
from typing import Any

import heyoka as hy
import numpy as np

from harness import tolerances as tol
from harness.coefficients import ButcherTableau, SplittingScheme
from harness.derived import remembered
from harness.ground_truth import reference
from harness.problem import Problem
from harness.stepper import AdaptiveStepper, Stepper
from harness.theory import analytic_stability
from harness.theory.classes import rk_class_orders, rk_stage_order, rk_stiffly_accurate

__all__ = ["MethodFacts", "ProblemFacts", "central_field", "class_key", "method_facts",
           "problem_facts"]

# class orders are derived for right-hand sides of degree 2..CLASS_MAX_DEGREE (degree 1 is the
# linear order); beyond it the first vanishing tree has more vertices than the orders judged here
CLASS_MAX_DEGREE = 6


def class_key(nystrom: bool, degree: int | None) -> str | None:
    """The key of `MethodFacts.class_orders` for a problem class (None: no class, or one with
    no derived order: degree 1 is the linear order, degrees above CLASS_MAX_DEGREE not kept).

    Parameters
    ----------
    nystrom : bool, the problem is x'' = g(x) written as a first-order system.
    degree : int or None, the polynomial degree of the right-hand side in the state.

    Returns
    -------
    str or None: "nystrom", "degree-d" or "nystrom+degree-d"; None as above.
    """
    if degree is not None and not 2 <= degree <= CLASS_MAX_DEGREE:
        degree = None
    if not nystrom and degree is None:
        return None
    return "+".join(([] if not nystrom else ["nystrom"]) + ([] if degree is None else [f"degree-{degree}"]))


@dataclass(frozen=True)
class MethodFacts:
    """What is known about a method, and where it comes from (`coefficients` or `claims`)."""

    source: str
    adaptive: bool
    explicit: bool
    order: int | None
    linear_order: int | None
    embedded_order: int | None
    symmetric: bool | None
    symplectic: bool | None
    real_interval: float | None
    imag_interval: float | None
    hw_limit: float | None
    one_step: bool | None = None  # a one-step map (Runge-Kutta, splitting); None for a black box
    class_orders: dict[str, int] | None = None  # order per problem class (`class_key`), RK only
    stage_order: int | None = None  # B(q) and C(q), RK only
    stiffly_accurate: bool | None = None  # last row of A = b, RK only

    def as_dict(self) -> dict[str, Any]:
        """The facts as a plain dict (for the report and JSON).

        Returns
        -------
        dict: every field.
        """
        return asdict(self)


@dataclass(frozen=True)
class ProblemFacts:
    """What the symbolic definition of a problem implies."""

    linear: bool
    polynomial_degree: int | None
    newtonian: bool
    velocity_free: bool
    time_dependent: bool
    stiffness: float
    horizon: float
    rhs_degree: int | None = None  # polynomial degree of the right-hand side in the state
    layer_width: float | None = None  # the start's initial layer: 1 / its fastest decay rate

    def as_dict(self) -> dict[str, Any]:
        """The facts as a plain dict (for the report and JSON).

        Returns
        -------
        dict: every field.
        """
        return asdict(self)


def method_facts(stepper: Stepper) -> MethodFacts:
    """Facts of `stepper`: from its coefficient object when it has one, else its claims.

    Parameters
    ----------
    stepper : Stepper, any stepper.

    Returns
    -------
    MethodFacts: with `source` "coefficients" or "claims".
    """
    coeffs = getattr(stepper, "coefficients", None)
    key = coeffs.fingerprint() if coeffs is not None and hasattr(coeffs, "fingerprint") else None
    info = stepper.info
    adaptive = isinstance(stepper, AdaptiveStepper) or bool(info.adaptive)
    if key is not None and hasattr(coeffs, "order"):
        derived = dict(_coefficient_facts(key, (coeffs,)))
        for prop in ("symmetric", "symplectic"):  # undecided by the coefficients: the claim
            if derived[prop] is None:
                derived[prop] = bool(getattr(info, prop))
        return MethodFacts(source="coefficients", adaptive=adaptive, explicit=bool(info.explicit),
                           **derived)
    claims = info.extra.get("stability") if isinstance(info.extra.get("stability"), dict) else {}
    order = info.claimed_order
    linear = info.extra.get("linear_order", order)
    return MethodFacts(
        source="claims", adaptive=adaptive, explicit=bool(info.explicit), order=order,
        linear_order=linear, embedded_order=info.extra.get("embedded_order"),
        symmetric=bool(info.symmetric), symplectic=bool(info.symplectic),
        real_interval=claims.get("real_interval"), imag_interval=claims.get("imag_interval"),
        hw_limit=claims.get("hw_limit"), one_step=info.extra.get("one_step"),
    )


@lru_cache(maxsize=512)
def _coefficient_facts(fingerprint: str, box: tuple) -> dict[str, Any]:
    # order conditions and scanned stability intervals take seconds over a registry: kept on
    # disk under the coefficients' fingerprint and this module's code (harness.derived)
    return remembered(__name__, "coefficient_facts", [fingerprint],
                      lambda: _derive_coefficient_facts(box[0]))


def _derive_coefficient_facts(coeffs: Any) -> dict[str, Any]:
    stab = analytic_stability(coeffs) or {}
    embedded = getattr(coeffs, "embedded_order", None)
    return {
        "order": int(coeffs.order()),
        "linear_order": int(coeffs.linear_order()),
        "embedded_order": embedded() if callable(embedded) else None,
        "symmetric": None if getattr(coeffs, "symmetric", None) is None else bool(coeffs.symmetric),
        "symplectic": None if getattr(coeffs, "symplectic", None) is None else bool(coeffs.symplectic),
        "real_interval": stab.get("real_interval"),
        "imag_interval": stab.get("imag_interval"),
        "hw_limit": stab.get("hw_limit"),
        "one_step": isinstance(coeffs, (ButcherTableau, SplittingScheme)),
        **(_rk_class_facts(coeffs) if isinstance(coeffs, ButcherTableau) else {}),
    }


def _rk_class_facts(tableau: Any) -> dict[str, Any]:
    classes = [(nystrom, degree) for nystrom in (False, True)
               for degree in (None, *range(2, CLASS_MAX_DEGREE + 1)) if class_key(nystrom, degree)]
    orders = {class_key(*c): k for c, k in zip(classes, rk_class_orders(tableau, classes), strict=True)}
    return {"class_orders": orders, "stage_order": rk_stage_order(tableau),
            "stiffly_accurate": rk_stiffly_accurate(tableau)}


# -- problems ---------------------------------------------------------------------------------
_STIFFNESS_SAMPLES = 9


def problem_facts(problem: Problem) -> ProblemFacts:
    """Facts of `problem`, derived from its symbolic definition (cached by its fingerprint).

    Parameters
    ----------
    problem : Problem

    Returns
    -------
    ProblemFacts: linearity, polynomial degrees, Newtonian structure, stiffness and horizon.
    """
    return _problem_facts(problem.fingerprint(), (problem,))


@lru_cache(maxsize=256)
def _problem_facts(fingerprint: str, box: tuple) -> ProblemFacts:
    # the stiffness samples the Jacobian along the orbit (compiled functions, a Taylor orbit):
    # kept on disk under the definition and this module's code (harness.derived)
    return ProblemFacts(**remembered(__name__, "problem_facts", [fingerprint],
                                     lambda: asdict(_derive_problem_facts(box[0]))))


def central_field(problem: Problem) -> bool:
    """True when every body moves in a central field about the origin: q'' = a(q), no velocity
    or time in the force, and each body's acceleration parallel to its own position (a
    spherically symmetric potential, where each body's angular momentum q x q' is conserved;
    Hairer, Lubich & Wanner I.2.3). The bodies are those of the problem's `NBody` structure
    (groups of its dimension), or the whole position when it has 2 or 3 components (otherwise
    False: no body to speak of). Decided on the definition itself: the cross products q_i x a_i
    at CENTRAL_FIELD_SAMPLES positions about the start (each body's radius times 0.5-2, seeded
    directions) must vanish to CENTRAL_FIELD_TOL |q_i| |a_i|.

    Parameters
    ----------
    problem : Problem

    Returns
    -------
    bool
    """
    return _central_field(problem.fingerprint(), (problem,))


@lru_cache(maxsize=256)
def _central_field(fingerprint: str, box: tuple) -> bool:
    problem = box[0]
    if problem.newtonian is None or problem.velocity_dependent or problem.time_dependent:
        return False
    nq = len(problem.newtonian.positions)
    structure = getattr(problem, "structure", None)
    d = structure.dimension if structure is not None else nq
    if d not in (2, 3) or nq % d:
        return False
    rng = np.random.default_rng(0)
    q0 = problem.y0[:nq].reshape(-1, d)
    radius = np.linalg.norm(q0, axis=1)
    radius = np.where(radius > 0, radius, 1.0)
    n = tol.CENTRAL_FIELD_SAMPLES
    directions = rng.standard_normal((n, len(q0), d))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    q = directions * (radius[None, :, None] * rng.uniform(0.5, 2.0, (n, len(q0), 1)))
    q = np.concatenate([q0[None], q])  # (samples, bodies, d), the start first
    with np.errstate(all="ignore"):
        a = problem.dynamics(size=len(q)).accel(problem.t0, np.ascontiguousarray(
            q.reshape(len(q), nq).T)).T.reshape(q.shape)
        cross = np.cross(q, a) if d == 3 else (q[..., 0] * a[..., 1] - q[..., 1] * a[..., 0])[..., None]
        size = np.linalg.norm(q, axis=2) * np.linalg.norm(a, axis=2)
        residual = np.linalg.norm(cross, axis=2)
    return bool(np.all(np.isfinite(residual)) and np.all(residual <= tol.CENTRAL_FIELD_TOL * size))


def _derive_problem_facts(problem: Problem) -> ProblemFacts:
    J = _constant_jacobian(problem)
    linear = J is not None and not problem.time_dependent
    degree = _polynomial_degree(problem, J) if linear else None
    return ProblemFacts(
        linear=linear,
        polynomial_degree=degree,
        newtonian=problem.newtonian is not None,
        velocity_free=problem.newtonian is not None and not problem.velocity_dependent,
        time_dependent=bool(problem.time_dependent),
        stiffness=_stiffness(problem),
        horizon=float(problem.convergence_t_end - problem.t0),
        rhs_degree=_rhs_degree(problem),
        layer_width=_initial_layer_width(problem),
    )


_POLYNOMIAL_SCREEN = re.compile(r"\*\*(?!\d+\.0+\b)|/ (?!p\d|\d)")


def _rhs_degree(problem: Problem) -> int | None:
    """The right-hand side's total degree in the state (and the time, which joins the state as
    t' = 1: every Runge-Kutta tableau here has c = A e) when it is a polynomial of degree at most
    CLASS_MAX_DEGREE, else None. Decided exactly: the (d+1)-th derivative along a fixed
    direction folds to the constant 0 in heyoka's algebra for a polynomial of degree d, never
    for a transcendental or rational term. A text screen (only variables, parameters, sums,
    products, non-negative integer powers and division by a parameter or number) skips the
    derivatives where they could not vanish."""
    variables, rhs = list(problem.variables), list(problem.rhs)
    if problem.time_dependent:
        clock = hy.make_vars("clock_time_")
        variables.append(clock)
        rhs = [hy.subs(e, {hy.time: clock}) for e in rhs]
    names = [str(v) for v in variables]
    allowed = set(names)
    for e in rhs:
        text = str(e)
        words = {w for w in re.findall(r"[A-Za-z_][A-Za-z_0-9]*", text) if not re.fullmatch(r"p\d+", w)}
        if words - allowed or _POLYNOMIAL_SCREEN.search(text):
            return None
    direction = np.linspace(0.75, 1.25, len(names))  # fixed, so the fact is reproducible
    zero = hy.expression(0.0)
    exprs = rhs
    for k in range(CLASS_MAX_DEGREE + 2):
        if all(e == zero for e in exprs):
            return max(k - 1, 1)
        grads = [hy.diff_tensors([e], diff_args=variables, diff_order=1).get_derivatives(1)
                 for e in exprs]
        exprs = [hy.sum([float(w) * d for w, (_, d) in zip(direction, g, strict=True)]) for g in grads]
    return None


def _constant_jacobian(problem: Problem) -> np.ndarray | None:
    """The Jacobian as numbers when no entry depends on a state variable, else None."""
    names = {str(v) for v in problem.variables}
    for expr in problem.jacobian_expressions:
        if set(hy.get_variables(expr)) & names:
            return None
    dyn = problem.dynamics()
    return dyn.jac(problem.t0, np.zeros((problem.dim, 1)))[:, :, 0]


def _polynomial_degree(problem: Problem, J: np.ndarray) -> int | None:
    """For y' = J y + c (constant J, c): the solution is a polynomial in t exactly when the
    augmented matrix [[J, c], [0, 0]] is nilpotent; its degree is the nilpotency index - 1."""
    c = problem.dynamics().f(problem.t0, np.zeros((problem.dim, 1)))[:, 0]
    n = problem.dim + 1
    M = np.zeros((n, n))
    M[:-1, :-1] = J
    M[:-1, -1] = c
    P = np.eye(n)
    for k in range(1, n + 1):
        P = P @ M
        if not np.any(P):
            return k - 1
    return None


def _stiffness(problem: Problem) -> float:
    """The largest -Re(lambda) of the Jacobian's eigenvalues along the reference solution from
    the problem's own start over its convergence horizon (0 when every eigenvalue has a
    non-negative real part): the rate a stable explicit step must resolve."""
    t0, T = problem.t0, problem.convergence_t_end
    times = np.linspace(t0, T, _STIFFNESS_SAMPLES)[1:]
    try:
        ref = reference(problem, times, problem.y0.reshape(-1, 1))
        states = np.concatenate([problem.y0.reshape(-1, 1), *[ref.y[i] for i in range(len(times))]], axis=1)
    except Exception:  # a reference that cannot be had: judge the start alone
        states = problem.y0.reshape(-1, 1)
    dyn = problem.dynamics(size=states.shape[1])
    jac = dyn.jac(t0, np.ascontiguousarray(states))
    worst = 0.0
    for k in range(states.shape[1]):
        with np.errstate(all="ignore"):
            lam = np.linalg.eigvals(jac[:, :, k])
        if np.all(np.isfinite(lam)):
            worst = max(worst, float(np.max(-lam.real)))
    return worst if math.isfinite(worst) else math.inf


def _initial_layer_width(problem: Problem) -> float | None:
    """The width 1 / (largest -Re(lambda) at the start) of the initial layer the problem starts
    in, or None when it starts on a smooth solution. At y0 the velocity f(y0) is split along the
    Jacobian's eigenvectors: modes that decay STIFF_HORIZON_DECAYS times over the horizon are
    fast. On a smooth (slow-manifold) solution of a stiff problem the fast part of the velocity is
    of the size of the slow part times slow rate / fast rate; at a start off that manifold it is
    the offset times the fast rate (Hairer & Wanner II, VI.1: the reduced problem and the initial
    layer of a singular perturbation problem). The start is in a layer when the fast part exceeds
    LAYER_VELOCITY_RATIO times the slow part and no mode grows at a fast rate (a saddle, such as
    a pericentre passage's +-lambda pair, is not a layer)."""
    horizon = float(problem.convergence_t_end - problem.t0)
    dyn = problem.dynamics(size=1)
    y0 = np.ascontiguousarray(problem.y0.reshape(-1, 1), dtype=np.float64)
    try:
        jac = dyn.jac(problem.t0, y0)[:, :, 0]
        velocity = np.asarray(dyn.f(problem.t0, y0), dtype=np.float64).ravel()
        with np.errstate(all="ignore"):
            lam, vectors = np.linalg.eig(jac)
            amplitude = np.linalg.lstsq(vectors, velocity.astype(complex), rcond=None)[0]
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None
    if not (np.all(np.isfinite(lam)) and np.all(np.isfinite(amplitude))) or horizon <= 0:
        return None
    fast = -lam.real * horizon > tol.STIFF_HORIZON_DECAYS
    if not fast.any() or np.any(lam.real * horizon > tol.STIFF_HORIZON_DECAYS):
        return None
    fast_part = float(np.linalg.norm(vectors[:, fast] @ amplitude[fast]))
    slow_part = float(np.linalg.norm(vectors[:, ~fast] @ amplitude[~fast]))
    if not fast_part > tol.LAYER_VELOCITY_RATIO * slow_part:
        return None
    return float(1.0 / np.max(-lam.real[fast]))
