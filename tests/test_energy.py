"""Long-term energy drift: the envelope classifier on synthetic envelopes, the verdicts over the
registry, and deliberately mislabelled steppers that must be caught.

Expectations: symplectic methods keep the energy error bounded (Hairer, Lubich & Wanner, GNI
IX.3); RK4 drifts linearly on Kepler (GNI I.2.3); splitting methods and Stormer's rule keep the
angular momentum of a central force to rounding (GNI IV.2).
"""

from __future__ import annotations

from functools import partial

import helpers
import numpy as np
import pandas as pd
import pytest
from helpers import PlainEulerLabelledSymplectic, cells_or_reasons, relabelled

from harness import tolerances as tol
from harness.errors import UnknownNameError
from harness.experiments import get_experiment
from harness.experiments.energy import (
    SUMMARY_COLUMNS,
    classify_drift,
    conserves_quadratic_invariants,
)
from harness.registry import get_problem, problems, steppers
from harness.stepper import AdaptiveStepper

EXP = get_experiment("energy")
STEPPERS = steppers.names()
# Small runs: 2000 steps still leave more than a decade after the first two periods (64 steps
# each on the harmonic oscillator), enough to tell bounded from linear.
SMALL = {"steps": 2_000, "implicit_steps": 1_000, "adaptive_outputs": 40, "adaptive_periods": 4,
         "ensemble": 1}

run_direct = partial(helpers.run_direct, EXP)


def run(stepper_names, problem_names, **overrides):
    summary = helpers.run_through_runner(EXP, stepper_names, problem_names, **overrides)
    return summary.set_index(["stepper", "problem"])


# -- the classifier on envelopes of known shape ---------------------------------------------------
def _grid(n=100_000):
    steps = np.unique(np.round(np.logspace(0, np.log10(n), 400))).astype(float)
    return steps, 0.1 * steps


@pytest.mark.parametrize("shape, expected", [
    (lambda n: 1e-4 * np.abs(np.sin(0.37 * n)), "bounded"),
    (lambda n: 1e-15 * np.sqrt(n) * (1.0 + 0.3 * np.sin(n)), "sqrt"),
    (lambda n: 1e-9 * n + 1e-8 * np.abs(np.sin(n)), "linear"),
    (lambda n: 1e-12 * np.exp(n / 4000.0), "unstable"),
    (lambda n: np.where(n > 5e4, np.inf, 1e-6), "unstable"),
    (lambda n: 1e-3 * n, "unstable"),  # reaches a relative error of order one
])
def test_classify_drift_recognises_known_envelopes(shape, expected):
    steps, t = _grid()
    out = classify_drift(steps, t, shape(steps), fit_start=1000)
    assert out["drift_class"] == expected, out


def _verlet_on_oscillator(hw: float, n: int = 100_000, period_steps: float | None = None):
    """The exact relative energy error of velocity Verlet on x'' = -x at step h = hw, from its
    one-step propagator M (det M = 1): bounded for |tr M| < 2, i.e. h w < 2 (a modified energy
    p^2 + (1 - h^2/4) q^2 is conserved), growing exponentially beyond."""
    h = hw
    M = np.array([[1 - h * h / 2, h], [-h * (1 - h * h / 4), 1 - h * h / 2]])
    steps, t = _grid(n)
    powers = np.empty((int(steps[-1]) + 1, 2))
    y = np.array([1.0, 0.0])
    for k in range(int(steps[-1]) + 1):
        powers[k] = y
        y = M @ y
        if not np.all(np.isfinite(y)):
            powers[k + 1:] = np.inf
            break
    q, p = powers[steps.astype(int)].T
    with np.errstate(over="ignore", invalid="ignore"):
        err = np.abs(0.5 * (p * p + q * q) - 0.5) / 0.5
    return steps, h * steps, err, (2 * np.pi / h if period_steps is None else period_steps)


# Known truth: the exact Verlet map on the oscillator (bounded inside h w < 2, HLW IX.8 and its
# linear propagator; exponential beyond), and envelopes of known shape past 10 %.
@pytest.mark.parametrize("case, expected", [
    (lambda: _verlet_on_oscillator(0.5), "bounded"),
    (lambda: _verlet_on_oscillator(1.5), "bounded"),  # swings to 56 %, never grows
    (lambda: _verlet_on_oscillator(1.99), "bounded"),  # swings past 100 %
    (lambda: _verlet_on_oscillator(2.01), "unstable"),  # |tr M| > 2: exponential growth
    (lambda: _verlet_on_oscillator(1.5, period_steps=0.0), "unstable"),  # period unknown: size rule
    (lambda: (*_grid(), np.minimum(1e-4 * _grid()[0], 0.5), 50.0), "unstable"),  # drift, then a wreck
    (lambda: (*_grid(), 0.2 + 1e-5 * _grid()[0], 50.0), "unstable"),  # large and drifting (6x)
    (lambda: (*_grid(), 0.3 * np.abs(np.sin(0.37 * _grid()[0])), 50.0), "bounded"),
    # an orbit wrecked within its first period: large from the start, but it never swings back
    (lambda: (*_grid(), np.where(_grid()[0] < 20, 1e-3, 0.85 + 1e-3 * np.sin(_grid()[0])), 300.0),
     "unstable"),
])
def test_large_bounded_energy_errors_are_classified_by_growth(case, expected):
    steps, t, err, period = case()
    out = classify_drift(steps, t, err, fit_start=1000, period_steps=period)
    assert out["drift_class"] == expected, out


def test_velocity_verlet_inside_its_stability_interval_keeps_its_claim_at_large_steps():
    """h w = 1.5 on the oscillator (limit 2): a large but bounded energy error is as claimed."""
    r = run_direct(["velocity-verlet"], ["harmonic"], h=1.5, steps=4000, ensemble=1).iloc[0]
    assert r.max_rel_energy_error > tol.ENERGY_BLOWUP_ERROR
    assert r.drift_class == "bounded" and r.verdict == "as-claimed" and bool(r.passed), r.message


def test_linear_drift_slope_is_the_drift_per_unit_time():
    steps, t = _grid()
    out = classify_drift(steps, t, 3e-8 * t, fit_start=1000)
    assert out["drift_class"] == "linear"
    assert out["drift_slope"] == pytest.approx(3e-8, rel=1e-6)
    assert out["drift_exponent"] == pytest.approx(1.0, abs=1e-6)



def test_unknown_names_are_refused():
    with pytest.raises(UnknownNameError, match=r"unknown problem 'kepler'"):
        EXP.cells(["rk4"], ["kepler"], EXP.config(quick=True))


def test_summarize_of_no_rows_has_the_promised_columns():
    out = EXP.summarize(pd.DataFrame(), EXP.config(quick=True))
    assert list(out.columns) == SUMMARY_COLUMNS
    for field in ("stepper", "problem", "h", "steps", "max_rel_energy_error", "drift_class",
                  "drift_slope", "verdict", "passed"):
        assert field in SUMMARY_COLUMNS


# -- the registry ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", STEPPERS)
def test_every_stepper_gets_a_cell_or_a_reason_on_every_problem(name):
    cells, skips = cells_or_reasons(EXP, name)
    stepper = steppers.get(name)
    for c in cells:
        assert get_problem(c.problem).invariants
        assert stepper.compatible(get_problem(c.problem))
    for s in skips:  # a problem with an invariant is skipped only for an incompatible stepper
        if get_problem(s.problem).invariants:
            assert not stepper.compatible(get_problem(s.problem)), s


def test_every_problem_with_an_invariant_gets_the_energy_experiment():
    """Applicability is a fact about the problem (it declares an invariant), never its name."""
    cells, skips = EXP.cells(["velocity-verlet"], problems.names(), EXP.config())
    with_invariants = {p.name for p in problems.all() if p.invariants and p.form == "newtonian"}
    assert {c.problem for c in cells} == with_invariants
    for s in skips:
        assert "declares no invariant" in s.reason or "velocity" in s.reason, s


def test_expected_drift_follows_coefficients_not_names():
    from harness.facts import method_facts
    from harness.rules import energy_expectation

    for name in STEPPERS:
        stepper = steppers.get(name)
        expected, reason = energy_expectation(method_facts(stepper))
        coeffs = getattr(stepper, "coefficients", None)
        derived = getattr(coeffs, "symplectic", None)
        if derived is not None:
            assert (expected == "bounded") == bool(derived), name
        assert (expected == "") == (reason == ""), name


def test_registry_on_the_oscillator_symplectic_claims_hold():
    """Every registered stepper on the harmonic oscillator: a symplectic claim must come out
    bounded (or rounding-level), and every record carries a class and a verdict."""
    table = run_direct(STEPPERS, ["harmonic"], **SMALL).set_index(["stepper", "problem"])
    compatible = [s for s in STEPPERS if steppers.get(s).compatible(get_problem("harmonic"))]
    assert set(table.index.get_level_values(0)) == set(compatible)
    for name in compatible:
        r = table.loc[(name, "harmonic")]
        assert r.drift_class in ("bounded", "sqrt", "linear", "unstable")
        if steppers.get(name).info.symplectic:
            assert r.verdict == "as-claimed" and bool(r.passed), (name, r.drift_class, r.message)
        if not isinstance(steppers.get(name), AdaptiveStepper):
            expected_steps = SMALL["steps"] if steppers.get(name).info.explicit else SMALL["implicit_steps"]
            assert r.steps == expected_steps
            assert r.h == pytest.approx(get_problem("harmonic").time_scale.h)


def test_rk4_drifts_linearly_on_kepler():
    table = run(["rk4"], ["kepler-elliptic"], ensemble=1)
    r = table.loc[("rk4", "kepler-elliptic")]
    assert r.drift_class == "linear", r.to_dict()
    # Its coefficients make it neither symplectic nor symmetric: first-order theory predicts the
    # drift, which no theorem requires, so the cell says it shows it and makes no claim.
    assert r.expected_class == "" and r.verdict == "no-claim" and bool(r.passed)
    assert "the run shows it" in r.message, r.message
    assert r.drift_slope > 0 and 0.75 <= r.drift_exponent <= 1.5


KEPLER_CONSERVING = [s for s in STEPPERS
                     if conserves_quadratic_invariants(steppers.get(s))
                     and steppers.get(s).compatible(get_problem("kepler-elliptic"))]


def test_the_verlet_family_is_among_the_quadratic_invariant_conservers():
    for name in ("velocity-verlet", "position-verlet", "leapfrog", "stormer-verlet"):
        if name in steppers:
            assert name in KEPLER_CONSERVING
    for name in ("rk4", "euler", "trapezoid"):
        if name in steppers:
            assert name not in KEPLER_CONSERVING


def test_angular_momentum_on_kepler_is_kept_to_rounding_by_the_verlet_family():
    assert KEPLER_CONSERVING
    table = run(KEPLER_CONSERVING, ["kepler-elliptic"], steps=5_000, implicit_steps=500)
    for name in KEPLER_CONSERVING:
        r = table.loc[(name, "kepler-elliptic")]
        assert r.angular_momentum_expected and r.angular_momentum_conserved, r.to_dict()
        bound = tol.ANGULAR_MOMENTUM_ROUNDING_ULPS * r.steps * tol.EPS
        assert r.max_rel_angular_momentum_error <= bound
        assert bool(r.passed), (name, r.message)


# -- mislabelled steppers must fail ---------------------------------------------------------------
@pytest.mark.parametrize("problem", ["harmonic", "kepler-elliptic"])
def test_plain_euler_labelled_symplectic_fails(problem, registered):
    name = registered(PlainEulerLabelledSymplectic())
    r = run([name], [problem], **SMALL).loc[(name, problem)]
    assert r.drift_class in ("linear", "unstable"), r.to_dict()
    assert r.verdict == "claim-false" and not bool(r.passed)


def test_rk4_labelled_symplectic_fails_on_kepler(registered):
    name = registered(relabelled("rk4", symplectic=True))
    r = run([name], ["kepler-elliptic"]).loc[(name, "kepler-elliptic")]
    assert r.drift_class == "linear"
    assert r.verdict == "claim-false" and not bool(r.passed)
    assert "claimed symplectic" in r.message


def test_step_size_and_final_time_overrides_set_the_run():
    """`h` and `t_end` (the CLI's --h and --t-end) replace the problem's derived step and the
    step count: 200 steps of 0.1 reach t = 20, for explicit and implicit steppers alike."""
    table = run_direct(["velocity-verlet", "implicit-midpoint"], ["harmonic"], h=0.1, t_end=20.0,
                       ensemble=2, perturbation=1e-3).set_index("stepper")
    for name in ("velocity-verlet", "implicit-midpoint"):
        r = table.loc[name]
        assert r.steps == 200 and r.h == pytest.approx(0.1) and r.t_end == pytest.approx(20.0)
        assert r.perturbation == 1e-3
