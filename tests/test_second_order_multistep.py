"""Second-order multistep methods for x'' = f(x): coefficients, facts and the step loop.

Oracles: the Stormer and Cowell coefficients sigma_j, sigma*_j of Hairer, Norsett & Wanner I,
III.10, Table 10.1 (1, 0, 1/12, 1/12, 19/240, 3/40, 863/12096, 275/4032 and 1, -1, 1/12, 0,
-1/240, -1/240, -221/60480, -19/6048); Numerov's method (x_{n+1} - 2x_n + x_{n-1} =
h^2/12 (a_{n+1} + 10 a_n + a_{n-1})) with periodicity limit sqrt 6; Stormer-Verlet's limit 2.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from harness.coefficients import SecondOrderMultistep
from harness.methods import Method, method_from_record
from harness.registry import get_problem
from harness.theory.newtonian import lmm2_hw_bands
from implementations.second_order_multistep import (
    METHODS,
    SecondOrderMultistepStepper,
    _sigma,
    cowell_table,
    stormer_table,
    velocity_weights,
)

F = Fraction


def test_generating_functions_give_the_published_coefficients():
    assert _sigma(8, True) == [F(1), F(0), F(1, 12), F(1, 12), F(19, 240), F(3, 40), F(863, 12096),
                               F(275, 4032)]
    assert _sigma(8, False) == [F(1), F(-1), F(1, 12), F(0), F(-1, 240), F(-1, 240), F(-221, 60480),
                                F(-19, 6048)]
    numerov = cowell_table(2)
    assert list(numerov.beta) == pytest.approx([1 / 12, 10 / 12, 1 / 12], abs=1e-16)
    assert list(stormer_table(2).beta) == [0.0, 1.0, 0.0]


@pytest.mark.parametrize("method", METHODS, ids=[m.name for m in METHODS])
def test_order_from_coefficients_is_the_published_order(method):
    assert method.coefficients.order() == method.claimed_order


@pytest.mark.parametrize("method", METHODS, ids=[m.name for m in METHODS])
def test_periodicity_limit_is_the_exact_root(method):
    """The limit is a root of the exact criterion: just below it the method is stable (roots on
    the circle for symmetric methods, inside otherwise), just above it is not."""
    c = method.coefficients
    bands = lmm2_hw_bands(c, hw_max=12.0)
    lim = bands.limit
    if lim == 0.0:
        assert not c.symmetric  # symmetric methods are periodic for small h omega
        return

    def radius(hw: float) -> float:
        roots = np.roots((c.alpha + hw * hw * c.beta)[::-1])
        return float(np.max(np.abs(roots)))

    assert radius(lim * (1 - 1e-6)) <= 1 + 1e-9
    assert radius(lim * (1 + 1e-4)) > 1 + 1e-7 or not c.symmetric


@pytest.mark.parametrize("table, limit", [(stormer_table(2), 2.0), (cowell_table(2), math.sqrt(6.0))])
def test_published_periodicity_limits(table, limit):
    assert lmm2_hw_bands(table).limit == pytest.approx(limit, abs=1e-12)


@pytest.mark.parametrize("m", [2, 3, 5, 8])
def test_velocity_formula_has_order_m_plus_1(m):
    """On x(t) = t^j the formula is exact for j <= m + 1 and not for j = m + 2."""
    w = velocity_weights(m)
    for j in range(m + 3):
        h = F(1, 3)
        x = [F(-i) ** j * h**j for i in range(m)]  # x at t_n - i h with t_n = 0
        a = [j * (j - 1) * (F(-i) * h) ** (j - 2) if j >= 2 else F(0) for i in range(m)]
        v = (x[0] - x[1]) / h + h * sum(wi * ai for wi, ai in zip(w, a, strict=True))
        exact = F(1) if j == 1 else F(0)
        assert (v == exact) == (j <= m + 1), (m, j)


def test_a_record_with_second_order_coefficients_builds_the_family_loop():
    record = {"name": "numerov-record", "claimed_order": 4, "reference": "Numerov (1924)",
              "alpha": [1, -2, 1], "beta": [F(1, 12), F(10, 12), F(1, 12)]}
    method = method_from_record(record)
    assert isinstance(method.coefficients, SecondOrderMultistep)
    stepper = method.stepper()
    assert isinstance(stepper, SecondOrderMultistepStepper) and stepper.info.form == "newtonian"
    # the two-step table itself, as a Method, builds too (it used to need `implicit_velocity`)
    assert isinstance(Method(stormer_table(2), 2, "HNW I, III.10").stepper(), SecondOrderMultistepStepper)


@pytest.mark.parametrize("name", ["stormer3", "cowell2", "quinlan-tremaine8"])
def test_the_loop_converges_at_the_order_on_the_harmonic_oscillator(name):
    method = next(m for m in METHODS if m.name == name)
    stepper = method.stepper()
    problem = get_problem("harmonic")
    y0 = np.array([[1.0], [0.0]])
    T = 10.0
    errors = []
    for n in (40, 80):  # h omega 0.25 and 0.125: inside every limit, above the rounding floor
        y = stepper.integrate(problem, h=T / n, n_steps=n, y0=y0).y[-1][:, 0]
        errors.append(np.max(np.abs(y - [math.cos(T), -math.sin(T)])))
    assert math.log2(errors[0] / errors[1]) == pytest.approx(method.claimed_order, abs=0.35)


def test_round_trip_retraces_the_history():
    stepper = next(m for m in METHODS if m.name == "quinlan-tremaine8").stepper()
    problem = get_problem("harmonic")
    y0 = np.array([[1.0], [0.0]])
    start, back = stepper.round_trip(problem, h=0.05, n_steps=50, y0=y0)
    assert np.max(np.abs(back - start)) < 1e-12


# -- Stormer-Verlet as the family's two-step record ---------------------------------------------
def test_stormer_verlet_is_the_two_step_record_with_the_course_start_and_velocity():
    """The record runs the course's form (course-material file 000: Taylor start; file 001: the
    central-difference velocity) and agrees with the dedicated two-step loop to rounding."""
    from harness.registry import get_stepper
    from implementations.verlet import TwoStepVerlet

    stepper = get_stepper("stormer-verlet")
    assert isinstance(stepper, SecondOrderMultistepStepper)
    assert stepper.info.family == "second-order-multistep" and stepper.starter is None
    assert stepper.one_step_verlet and stepper.info.symplectic and stepper.info.symmetric
    course = TwoStepVerlet("course", stepper.coefficients, implicit_velocity=False, reference="file 000")
    problem = get_problem("kepler-elliptic")
    y0 = np.array([[0.4, 0.41], [0.0, 0.01], [0.0, 0.0], [2.0, 1.98]])
    saves = range(0, 401, 40)
    a = course.integrate(problem, h=0.01, n_steps=400, y0=y0, save_steps=saves)
    b = stepper.integrate(problem, h=0.01, n_steps=400, y0=y0, save_steps=saves)
    assert np.max(np.abs(np.asarray(a.y) - np.asarray(b.y))) < 1e-12
    assert a.evals["accel"] == b.evals["accel"]


@pytest.mark.parametrize("options, verlet", [
    ({}, False),
    ({"start": "taylor-polynomial"}, False),  # the order-3 velocity: not velocity Verlet
    ({"start": "taylor-polynomial", "velocity_points": 1}, True),
])
def test_the_symplectic_claim_follows_from_table_start_and_velocity(options, verlet):
    stepper = Method(stormer_table(2), 2, "HNW I, III.10", options=options).stepper()
    assert stepper.one_step_verlet is verlet and stepper.info.symplectic is verlet


@pytest.mark.parametrize("table, options, match", [
    (next(m for m in METHODS if m.name == "quinlan-tremaine8").coefficients, {"start": "taylor-polynomial"},
     "'taylor-polynomial' gives x_1 only"),
    (stormer_table(4), {"velocity_points": 1}, "`velocity_points` of 'stormer4' must be"),
    (stormer_table(2), {"velocity_points": 0}, "`velocity_points`"),
    (stormer_table(2), {"start": "euler"}, "`start` must be one of"),
])
def test_loop_options_that_break_the_order_are_refused(table, options, match):
    from harness.errors import CoefficientError

    with pytest.raises(CoefficientError, match=match):
        SecondOrderMultistepStepper(table, claimed_order=int(table.order()), reference="r", **options)


# -- the order in extended precision ----------------------------------------------------------
@pytest.mark.slow
def test_the_highest_order_record_shows_its_order_in_real128():
    """Quinlan-Tremaine SL12 reaches the float64 floor before its slope settles; in real128,
    started from the 192-bit ground truth, the fitted order is the coefficients' 12."""
    from harness.extended import extended_sweep
    from harness.tolerances import MIN_FIT_POINTS

    method = next(m for m in METHODS if m.name == "quinlan-tremaine12")
    r = extended_sweep(method.coefficients, get_problem("harmonic"), order_bound=12)
    assert r["fit"] is not None and r["fit"]["points"] >= MIN_FIT_POINTS, r["note"]
    assert r["fit"]["order"] == pytest.approx(method.coefficients.order(), abs=0.15)


def test_an_exact_record_that_breaks_an_order_condition_shows_the_lower_order_in_real128():
    """A mutant of Stormer's 4-step table (beta_1 and beta_2 moved by 1/24 each way: consistent,
    order 2 by its error constants) measures order 2, not the 4 it would claim."""
    from harness.extended import extended_sweep

    base = stormer_table(4)
    beta = list(base.exact[1])
    beta[1] += F(1, 24)
    beta[2] -= F(1, 24)
    mutant = SecondOrderMultistep("stormer4-mutant", list(base.exact[0]), beta)
    assert mutant.order() < 4
    r = extended_sweep(mutant, get_problem("harmonic"), order_bound=4, work_budget=4000)
    assert r["fit"] is not None
    assert r["fit"]["order"] == pytest.approx(mutant.order(), abs=0.15)


def test_a_float64_table_is_not_measurable_in_extended_precision_and_says_why():
    from harness.extended import NotMeasurable, exact_form

    exact = cowell_table(4)
    floats = SecondOrderMultistep("cowell4-floats", exact.alpha.tolist(), exact.beta.tolist())
    assert exact.exact is not None and floats.exact is None
    with pytest.raises(NotMeasurable, match="given only to float64"):
        exact_form(floats)
    assert exact.fingerprint() != floats.fingerprint()  # never one cached cell for both
