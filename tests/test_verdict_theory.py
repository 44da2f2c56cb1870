"""Verdicts no stronger than their theory: the false alarms the harness once raised, as tables.

- energy: the drift of a method neither symplectic nor symmetric is a prediction (first-order
  theory, HNW I, II.8), never a failure: backward Euler's energy error saturates on
  `lennard-jones`, forward Euler's grows faster than linearly;
- energy: a run too short to tell a drift from a bounded error (free fall leaves its regime within
  16 steps) is `not-measurable` and gets no drift class; so is a bounded-energy claim at a step
  beyond the method's h-omega limit (the theorem holds for small steps);
- course claims are judged on what their words name: RK4's drift is not refuted where RK4 is
  exact, Verlet's angular momentum is judged on the splittings it names, on central fields
  (derived from the definition) only — and both judges can still disagree;
- the gate's exit statuses: 0 passed, 1 contradicted, 3 not verified on the problems given.
"""

from __future__ import annotations

import json
import math

import helpers
import heyoka as hy
import numpy as np
import pandas as pd
import pytest

from harness import tolerances as tol
from harness.api import FunctionStepper, check
from harness.cli import main
from harness.cli.output import EXIT_FAILED, EXIT_NOT_VERIFIED, EXIT_OK
from harness.coefficients import ButcherTableau
from harness.experiments import get_experiment
from harness.facts import central_field
from harness.problem import NBody, NewtonianForm, Problem
from harness.registry import get_problem, steppers
from harness.report.claims import AGREE, CLAIMS, DISAGREE, NOT_MEASURED, check_claims
from implementations.runge_kutta import ExplicitRungeKutta

ENERGY = get_experiment("energy")


# -- energy: a prediction is not a claim --------------------------------------------------------------
@pytest.mark.parametrize("stepper, problem, config, shown", [
    # backward Euler is dissipative: its energy error saturates (the rule failed this cell).
    ("backward-euler", "lennard-jones", {"implicit_steps": 10_000}, "bounded instead"),
    # forward Euler's energy grows like (1 + h^2 w^2)^n: faster than linear, reaching 10 %.
    ("euler", "harmonic", {"steps": 20_000}, "reaching"),
    ("rk4", "harmonic", {"steps": 20_000}, "the run shows it"),
])
def test_a_drift_prediction_never_fails_a_cell(stepper, problem, config, shown):
    summary = helpers.run_direct(ENERGY, [stepper], [problem], ensemble=1, **config)
    r = summary.iloc[0]
    assert r.expected_class == "" and r.verdict == "no-claim" and bool(r.passed), r.to_dict()
    assert "first-order theory predicts" in r.message and shown in r.message, r.message


FREE_FALL_STEPPERS = ["rk4", "velocity-verlet", "stormer-verlet", "backward-euler", "trapezoid"]


def test_a_run_too_short_to_classify_gets_no_drift_class():
    """Free fall leaves its regime within 16 steps (the exact methods' curves at 1e-16): not one
    drift class (one used to read `unstable`), whatever the method and its claim."""
    summary = helpers.run_direct(ENERGY, FREE_FALL_STEPPERS, ["free-fall"], ensemble=1)
    assert sorted(summary.stepper) == sorted(FREE_FALL_STEPPERS)
    for r in summary.itertuples():
        assert r.steps < 100, r
        assert r.verdict == "not-measurable" and r.drift_class == "" and bool(r.passed), r
        assert "too short to tell a drift" in r.message, r.message


@pytest.mark.parametrize("stepper", ["velocity-verlet", "forest-ruth"])
def test_a_bounded_energy_claim_is_not_judged_beyond_the_methods_step_limit(stepper):
    """h omega = 2.5 is past both methods' h-omega limits (2 and 1.57): the orbit blows up, and
    the theorem behind the claim (small steps) says nothing there (it used to fail the claim)."""
    r = helpers.run_direct(ENERGY, [stepper], ["harmonic"], h=2.5, steps=2_000, ensemble=1).iloc[0]
    assert r.expected_class == "bounded" and r.verdict == "not-measurable" and bool(r.passed), r.message
    assert r.drift_class == "" and "exceeds the method's limit" in r.message, r.message


# -- central fields, from the definition ----------------------------------------------------------------
_x, _y, _z, _vx, _vy, _vz = hy.make_vars("x", "y", "z", "vx", "vy", "vz")
_r2 = _x * _x + _y * _y + _z * _z


def _three_d(name: str, acceleration) -> Problem:
    return Problem(name, variables=[_x, _y, _z, _vx, _vy, _vz],
                   newtonian=NewtonianForm(positions=(_x, _y, _z), velocities=(_vx, _vy, _vz),
                                           acceleration=acceleration),
                   y0=[1.0, 0.2, -0.3, 0.0, 0.8, 0.1], t_span=(0.0, 1.0), reference="test field")


_body = NBody(masses=(1.0, 1e-3), G=1.0, central=0, frame="inertial", dimension=2)
_body_vars, _body_nf, _ = _body.derive()


@pytest.mark.parametrize("problem, central", [
    ("kepler-circular", True), ("kepler-elliptic", True),
    ("outer-solar-system", False),  # the planets pull each other
    ("planets-pair", False), ("henon-heiles", False), ("lennard-jones", False),
    ("harmonic", False),  # one dimension: no body with an angular momentum
    # a 3-D isotropic anharmonic field is central; a slightly anisotropic one is not
    (_three_d("test-isotropic", tuple(-(1.0 + _r2) * c for c in (_x, _y, _z))), True),
    (_three_d("test-anisotropic", (-_x, -_y, -1.001 * _z)), False),
    # two bodies in an inertial frame: each is pulled towards the other, not to the origin
    (Problem("test-two-body", variables=_body_vars, newtonian=_body_nf,
             y0=[0.0, 0.0, 1.0, 0.0, 0.0, -1e-3, 0.0, 1.0], t_span=(0.0, 1.0),
             structure=_body, reference="test two-body"), False),
])
def test_central_field_is_derived_from_the_definition(problem, central):
    problem = get_problem(problem) if isinstance(problem, str) else problem
    assert central_field(problem) is central


def _generated_field(seed: int, anisotropy: float) -> Problem:
    """A random radial field -(c0 + c1 r^2 + c2 r^4) q in 2-D or 3-D, plus `anisotropy` times a
    random traceless linear field (central exactly when `anisotropy` is 0)."""
    rng = np.random.default_rng(seed)
    d = 2 + seed % 2
    q, v = list(hy.make_vars("x", "y", "z")[:d]), list(hy.make_vars("vx", "vy", "vz")[:d])
    r2 = sum((c * c for c in q[1:]), q[0] * q[0])
    c0, c1, c2 = rng.uniform(0.1, 2.0, 3)
    M = rng.standard_normal((d, d))
    M -= np.trace(M) / d * np.eye(d)
    acc = tuple(-(c0 + c1 * r2 + c2 * r2 * r2) * q[i]
                + anisotropy * sum((float(M[i, j]) * q[j] for j in range(d)), hy.expression(0.0))
                for i in range(d))
    return Problem(f"test-field-{seed}", variables=q + v,
                   newtonian=NewtonianForm(positions=tuple(q), velocities=tuple(v), acceleration=acc),
                   y0=list(rng.uniform(-1, 1, d)) + [0.0] * d, t_span=(0.0, 1.0),
                   reference="generated test field")


def test_central_field_has_no_false_alarm_or_miss_on_generated_fields():
    """Judge the judge: 6 random central fields and 6 with a small anisotropy (1e-3 to 1e-8 of
    the field), each known by construction."""
    central = [central_field(_generated_field(seed, 0.0)) for seed in range(6)]
    anisotropic = [central_field(_generated_field(seed, 10.0 ** -(3 + seed))) for seed in range(6)]
    assert all(central), central
    assert not any(anisotropic), anisotropic


# -- course claims: what their words name -------------------------------------------------------------
def _energy(*rows) -> dict[str, pd.DataFrame]:
    cols = ["stepper", "problem", "steps", "drift_class", "verdict", "drift_exponent",
            "max_rel_energy_error", "max_rel_angular_momentum_error", "angular_momentum_rounding",
            "angular_momentum_conserved"]
    return {"energy": pd.DataFrame([dict(zip(cols, r, strict=True)) for r in rows], columns=cols)}


def _rk4(problem, cls, verdict="no-claim"):
    return ("rk4", problem, 100_000, cls, verdict, 1.0, 1e-4, math.nan, math.nan, None)


def _l_row(stepper, problem, error, steps=100_000):
    bound = tol.ANGULAR_MOMENTUM_ROUNDING_ULPS * steps * tol.EPS
    return (stepper, problem, steps, "bounded", "as-claimed", 0.0, 1e-4, error, bound, error <= bound)


@pytest.mark.parametrize("key, tables, status", [
    # RK4 is exact on free fall: its bounded error there says nothing about drift.
    ("rk4-drifts", _energy(_rk4("free-fall", "bounded"), _rk4("harmonic", "linear")), AGREE),
    ("rk4-drifts", _energy(_rk4("free-fall", "bounded"), _rk4("harmonic", "bounded")), DISAGREE),
    ("rk4-drifts", _energy(_rk4("harmonic", "", "not-measurable"), _rk4("pendulum", "linear")), AGREE),
    ("rk4-drifts", _energy(_rk4("free-fall", "bounded")), NOT_MEASURED),
    # Stormer's two-step form and damped Verlet are not named by the claim; the outer solar
    # system is not a central field.
    ("verlet-angular-momentum", _energy(_l_row("velocity-verlet", "kepler-elliptic", 5e-14),
                                        _l_row("leapfrog", "kepler-circular", 4e-14),
                                        _l_row("stormer-verlet", "outer-solar-system", 1e-9),
                                        _l_row("verlet-damped", "lennard-jones", 5e-12, 10_000),
                                        _l_row("velocity-verlet", "outer-solar-system", 1e-9)), AGREE),
    ("verlet-angular-momentum", _energy(_l_row("position-verlet", "kepler-elliptic", 1e-9)), DISAGREE),
    ("verlet-angular-momentum", _energy(_l_row("stormer-verlet", "kepler-elliptic", 1e-9)), NOT_MEASURED),
    # a run without the experiment a claim reads leaves it not measured, for every claim
    *[(spec.key, {}, NOT_MEASURED) for spec in CLAIMS],
])
def test_course_claims_are_judged_on_what_they_name(key, tables, status):
    (result,) = [r for r in check_claims(tables) if r.key == key]
    assert result.status == status, result.measurement
    if not tables:
        (spec,) = [s for s in CLAIMS if s.key == key]
        assert result.measurement == f"no {spec.experiment} results"


# -- the gate's exit statuses ---------------------------------------------------------------------------
def _kdk(a, t, q, v, h):
    v = v + 0.5 * h * a(t, q)
    q = q + h * v
    return q, v + 0.5 * h * a(t + h, q)


_q, _v = hy.make_vars("x", "v")
# x'' = -x^3 over 1e-6: every step count leaves the error at the rounding floor, so no cell can
# measure an order (a correct method, not verified there).
TINY = Problem("test-tiny-span", variables=[_q, _v],
               newtonian=NewtonianForm(positions=(_q,), velocities=(_v,), acceleration=(-_q * _q * _q,)),
               y0=[1.0, 0.0], t_span=(0.0, 1e-6), reference="x'' = -x^3 over a span too short for an error")


def _box():
    return FunctionStepper(_kdk, name="test-kdk-box", order=2, form="newtonian", symmetric=True,
                           symplectic=True)


def _heun_claiming_three():
    heun = steppers.get("heun").coefficients
    return ExplicitRungeKutta(ButcherTableau("test-heun-as-3", heun.A.tolist(), heun.b.tolist()),
                              claimed_order=3, reference="Heun's method relabelled as third order")


@pytest.mark.parametrize("stepper, problems_given, status, outcomes", [
    ("rk4", ["free-fall"], EXIT_OK, {"pass"}),
    (_box, [TINY], EXIT_NOT_VERIFIED, {"not-measurable", "not-verified"}),
    # contradicted by its coefficients: failed, and not also "not verified"
    (_heun_claiming_three, ["free-fall"], EXIT_FAILED, {"fail"}),
])
def test_gate_exit_status_tells_contradicted_from_not_verified(stepper, problems_given, status,
                                                               outcomes, registered, capsys):
    name = stepper if isinstance(stepper, str) else registered(stepper())
    names = [p if isinstance(p, str) else registered(p) for p in problems_given]
    argv = ["gate", "--stepper", name, "--jobs", "1", "--json"]
    for p in names:
        argv += ["--problem", p]
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == status, err
    records = json.loads(out)
    assert {r["outcome"] for r in records} == outcomes
    unverified = [r for r in records if r["outcome"] == "not-verified"]
    assert all(r["problem"] == "(any)" and "not verified" in r["reason"] for r in unverified)


def test_check_fails_a_claim_it_could_not_verify_and_says_so():
    report = check(_box(), [TINY], order=2, raise_on_failure=False)
    assert not report.passed
    text = str(report)
    assert "1 claim(s) not verified: no problem given measured them" in text, text
    assert "claims false" not in text, text
