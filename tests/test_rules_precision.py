"""Extended-precision convergence, the energy drift rule and the not-converged listing.

Orders measured in real128 against a 192-bit reference (certified by 256 bits); the coefficients
must be exact beyond float64 for that to mean anything, and a record given only as float64
numbers is reported as not measurable, with that reason.
"""

from __future__ import annotations

import math
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import plugin_problem

from harness import tolerances as tol
from harness.coefficients import ButcherTableau, SplittingScheme, exact_value
from harness.extended import NotMeasurable, composition_defect, exact_form, extended_sweep
from harness.facts import method_facts
from harness.methods import from_record
from harness.registry import get_problem, get_stepper
from harness.rules import describe_drift, drift_prediction, energy_expectation

sys.path.insert(0, str(Path(__file__).parent / "plugins"))
import gbs10  # noqa: E402

from implementations.splitting import _YOSHIDA8_A, VELOCITY_VERLET  # noqa: E402

# Yoshida's published 15-digit weights (Phys. Lett. A 150 (1990) 262, Table 2, solution A).
_PUBLISHED_YOSHIDA8 = ["-1.61582374150097", "-2.44699182370524", "-0.716989419708120e-2",
                       "2.44002732616735", "0.157739928123617", "1.82020630970714",
                       "1.04242620869991"]


# -- exact forms --------------------------------------------------------------------------------------
def test_exact_values_accept_exact_inputs_and_refuse_rounded_floats():
    assert exact_value("0.1") == Fraction(1, 10)
    assert exact_value(Fraction(1, 3)) == Fraction(1, 3)
    assert exact_value(0.5) == Fraction(1, 2)
    assert exact_value(1.0 / 3.0) is None
    assert exact_value(0.1) is None


def test_a_float64_tableau_is_not_measurable_in_extended_precision_and_says_why():
    third = 1.0 / 3.0
    heun3 = ButcherTableau("x", [[0, 0, 0], [third, 0, 0], [0, 2 * third, 0]], [0.25, 0, 0.75])
    assert heun3.exact is None
    with pytest.raises(NotMeasurable, match="given only to float64"):
        exact_form(heun3)
    exact = ButcherTableau("y", [[0, 0, 0], [Fraction(1, 3), 0, 0], [0, Fraction(2, 3), 0]],
                           [Fraction(1, 4), 0, Fraction(3, 4)])
    assert exact.exact[2] == (0, Fraction(1, 3), Fraction(2, 3))
    for a, b in zip((exact.A, exact.b, exact.c), (heun3.A, heun3.b, heun3.c), strict=True):
        assert np.array_equal(a, b)  # same floats run in float64; only one has an exact form
    assert exact.fingerprint() != heun3.fingerprint()  # so they never share a cached cell


def test_compositions_keep_the_exact_form_of_exact_weights():
    scheme = SplittingScheme.compose("c", VELOCITY_VERLET, ["1.351207191959657634047687808971460826922",
                                                            "-1.702414383919315268095375617942921653844",
                                                            "1.351207191959657634047687808971460826922"])
    assert scheme.exact is not None and sum(v for k, v in scheme.exact if k == "D") == 1
    floats = SplittingScheme.compose("f", VELOCITY_VERLET, [1.3512071919596578, -1.7024143839193153,
                                                            1.3512071919596578])
    assert floats.exact is None


def test_yoshida8_record_weights_satisfy_the_order_conditions_beyond_float64():
    # The record's 40-digit weights (refined on the exact series) against the published ones.
    assert composition_defect(VELOCITY_VERLET, _YOSHIDA8_A, 8) < 1e-35
    assert composition_defect(VELOCITY_VERLET, _PUBLISHED_YOSHIDA8, 8) > 1e-14
    assert get_stepper("yoshida8").coefficients.exact is not None


def test_the_gbs_plugin_tableau_has_order_ten_from_its_coefficients():
    stepper = from_record(gbs10.METHODS[0])
    c = stepper.coefficients
    assert c.stages == 26 and c.explicit and c.exact is not None
    assert c.order() == 10
    assert sum(c.exact[1]) == 1


# -- extended-precision sweeps -------------------------------------------------------------------------
def test_yoshida8_measures_order_8_in_real128_on_the_circular_orbit():
    problem = get_problem("kepler-circular")
    out = extended_sweep(get_stepper("yoshida8").coefficients, problem, amplification=190.0)
    fit = out["fit"]
    assert fit is not None, out["stopped_by"]
    assert abs(fit["order"] - 8.0) <= 0.05, (fit, out["local_slopes"])
    assert fit["error_min"] < 1e-18  # far below the float64 floor (~1e-11 with the flow's 190)
    assert out["reference_error"] < 1e-40


def test_the_order_10_gbs_method_measures_order_10_in_real128():
    problem = get_problem("kepler-circular")
    out = extended_sweep(from_record(gbs10.METHODS[0]).coefficients, problem, amplification=190.0)
    assert out["fit"] is not None, out["stopped_by"]
    assert abs(out["fit"]["order"] - 10.0) <= 0.1, (out["fit"], out["local_slopes"])


def test_fifteen_digit_weights_do_not_reach_order_8_in_real128():
    # The published weights break the order conditions at ~2e-12: extended precision exposes
    # it (the error stalls at the defect's level instead of falling as h^8).
    scheme = SplittingScheme.compose("y8-15", VELOCITY_VERLET, [
        *reversed(_PUBLISHED_YOSHIDA8),
        str(1 - 2 * sum(Fraction(w) for w in _PUBLISHED_YOSHIDA8)), *_PUBLISHED_YOSHIDA8])
    assert scheme.exact is not None
    out = extended_sweep(scheme, get_problem("kepler-circular"), amplification=190.0,
                         work_budget=300_000)
    assert out["fit"] is None or abs(out["fit"]["order"] - 8.0) > tol.GATE_ORDER_TOL, out["fit"]


@pytest.mark.parametrize("name", ["pendulum", "dahlquist"])  # dahlquist: with parameters
def test_a_reused_reference_integrator_gives_the_states_a_fresh_one_gives(name):
    """The 192-bit Taylor integrators are built once per process and set to the start before
    each use: after propagating elsewhere, the same end state and starting values, digit for
    digit, as from an integrator built for the call."""
    import heyoka as hy

    from harness import extended

    problem, prec = get_problem(name), 192
    times = [hy.real(x, prec) for x in (0.25, 0.5, 0.75)]
    extended._integrators.clear()
    end, starts = extended._taylor(problem, 3.0, prec), extended._taylor(problem, None, prec, times)
    assert len(extended._integrators) == 1
    again = extended._taylor(problem, 3.0, prec)  # reused, last left at t = 0.75
    extended._integrators.clear()
    fresh_starts = extended._taylor(problem, None, prec, times)
    assert [str(v) for v in again] == [str(v) for v in end]
    assert [[str(v) for v in s] for s in fresh_starts] == [[str(v) for v in s] for s in starts]
    assert str(end[0]) != str(starts[-1][0])  # the two calls asked for different times


def test_floor_bound_sweeps_are_rerun_only_with_exact_coefficients():
    from harness.experiments.convergence.extended import floor_bound as _floor_bound

    g = pd.DataFrame({"h": [1.0, 0.5, 0.25, 0.125], "in_fit": [False, True, True, False],
                      "excluded": ["pre-asymptotic", "", "", "roundoff"]})
    assert _floor_bound(g)
    assert not _floor_bound(g.assign(excluded=["roundoff"] * 4))  # that is `exact`
    assert not _floor_bound(g.assign(excluded=["pre-asymptotic", "", "", "pre-asymptotic"]))


def test_a_float64_record_at_the_floor_says_why_it_was_not_rerun(registered):
    from harness.experiments.base import Cell
    from harness.experiments.convergence import ConvergenceExperiment

    weights = [float(w) for w in _PUBLISHED_YOSHIDA8]
    w0 = 1.0 - 2.0 * sum(weights)
    scheme = SplittingScheme.compose("y8-float", VELOCITY_VERLET, [*reversed(weights), w0, *weights])
    assert scheme.exact is None
    registered(from_record({"name": "y8-float", "sequence": list(scheme.sequence), "claimed_order": 8,
                            "reference": "Yoshida, Phys. Lett. A 150 (1990) 262, Table 2 (floats)"}))
    exp = ConvergenceExperiment()
    config = {**exp.default_config, "ensemble": 1, "local": False}
    rows = exp.run_cell(Cell("convergence", "y8-float", "kepler-circular"), config)
    summary = exp.summarize(rows, config).iloc[0]
    # The same float64 sweep that stops yoshida8 at the floor stops this copy of it there too.
    assert summary.verdict == "insufficient-range", summary.to_dict()
    assert "given only to float64" in summary.message, summary.message


# -- the energy drift rule ----------------------------------------------------------------------------
def test_energy_expectation_follows_symplecticity_then_symmetry():
    assert energy_expectation(method_facts(get_stepper("velocity-verlet")))[0] == "bounded"
    assert drift_prediction(method_facts(get_stepper("velocity-verlet"))) == ""
    assert energy_expectation(method_facts(get_stepper("trapezoid")))[0] == ""  # symmetric: no claim
    assert drift_prediction(method_facts(get_stepper("trapezoid"))) == ""
    for name in ("rk4", "euler", "heun", "backward-euler"):
        # no theorem makes a drift obligatory: no claim, only a prediction beside the measurement
        assert energy_expectation(method_facts(get_stepper(name))) == ("", ""), name
        assert "first-order theory predicts" in drift_prediction(method_facts(get_stepper(name))), name
    for name in ("ab2", "scipy-rk45"):  # multistep, adaptive: neither a claim nor a prediction
        assert energy_expectation(method_facts(get_stepper(name)))[0] == ""
        assert drift_prediction(method_facts(get_stepper(name))) == ""


def test_the_drift_rule_for_rk4_applies_to_its_coefficients_under_any_name():
    rk4 = get_stepper("rk4").coefficients
    mine = from_record({"name": "my-classic", "A": rk4.A.tolist(), "b": rk4.b.tolist(),
                        "claimed_order": 4, "reference": "Kutta (1901)"})
    assert drift_prediction(method_facts(mine)) == drift_prediction(method_facts(get_stepper("rk4")))


@pytest.mark.parametrize("case, expected", [
    # drift_class, max_error, first-period error, periods in fit, total, rounding fit, rounding period
    (("linear", 3e-4, 2e-6, 338, 3380, 7e-12, 1e-14), ("no-claim", "the run shows it")),
    (("sqrt", 1e-13, 1e-15, 338, 3380, 7e-12, 1e-14), ("not-measurable", "within 10x of rounding")),
    (("bounded", 1e-10, 1e-12, 338, 3380, 7e-12, 1e-14), ("no-claim", "bounded instead")),
    # backward Euler on lennard-jones: dissipative, its energy error saturates (was a failure)
    (("bounded", 4.63e-4, 1.78e-4, 189, 1890, 2.2e-12, 1e-14), ("no-claim", "saturates")),
    (("unstable", 1.2, 0.45, 338, 3380, 7e-12, 1e-14), ("no-claim", "reaching")),
    (("unstable", 1.2, 1e-8, 338, 3380, 7e-12, 1e-14), ("no-claim", "unstable instead")),
    (("unstable", math.inf, math.nan, 338, 3380, 7e-12, 1e-14), ("not-measurable", "no finite")),
])
def test_describe_drift_never_fails_a_cell(case, expected):
    verdict, reason = describe_drift("neither symplectic nor symmetric", *case)
    assert verdict == expected[0] and expected[1] in reason, reason


# -- the not-converged listing ------------------------------------------------------------------------
def test_not_converged_lists_every_cell_that_did_not_converge_with_its_reason():
    from harness.not_converged import format_not_converged, not_converged

    gate = pd.DataFrame([
        {"stepper": "a", "problem": "p", "verdict": "converged", "expected": "converged",
         "expected_order": 4.0, "outcome": "pass", "reason": ""},
        {"stepper": "a", "problem": "q", "verdict": "exact", "expected": "exact",
         "expected_order": None, "outcome": "pass", "reason": "polynomial of degree 2"},
        {"stepper": "b", "problem": "p", "verdict": "insufficient-range", "expected": "converged",
         "expected_order": 8.0, "outcome": "not-measurable", "reason": "the float64 floor"},
        {"stepper": "c", "problem": "p", "verdict": "converged", "expected": "converged",
         "expected_order": 4.0, "outcome": "fail", "reason": "measured 3.1"},
        {"stepper": "b", "problem": "(any)", "verdict": "", "expected": "a measured claim",
         "expected_order": None, "outcome": "not-verified", "reason": "not verified: no cell"},
    ])
    rows = not_converged(gate)
    assert list(rows.group) == ["fail", "not-verified", "not-measurable", "predicted"]
    text = format_not_converged(rows, len(gate))
    assert "b x p: insufficient-range (expected converged at order 8): the float64 floor" in text
    assert text.endswith("5 cells: 1 converged as expected, 1 predicted, 1 not-measurable, "
                         "1 not-verified, 1 fail")


def test_not_converged_command_refuses_a_directory_without_a_summary(tmp_path, capsys):
    from harness.not_converged import main

    assert main([str(tmp_path)]) == 2
    assert "RESULTS_DIR" in capsys.readouterr().err


def test_real128_rounding_level_is_below_float64():
    from harness.extended import EXTENDED_EPS

    assert EXTENDED_EPS < 1e-33 < tol.EPS
    assert np.finfo(np.float64).eps / EXTENDED_EPS > 1e17


# -- the adaptive tolerance rule ----------------------------------------------------------------------
def _tolerance_rows(errors, steps, amplification, members=4):
    tols = np.array([1e-3, 1e-5, 1e-7])
    return pd.DataFrame({
        "kind": "tolerance", "tol": tols, "h": np.nan, "n_steps": np.array(steps) * members,
        "error": np.array(errors) * tols, "reference_error": 1e-18, "rounding_level": tol.EPS,
        "excluded": "", "in_fit": True, "wall_s": 0.0, "message": "", "ensemble_size": members,
        "flow_amplification": amplification, "reference_precision": "longdouble",
        "implementation": "scipy", "perturbation": 0.0,
    })


def test_tolerance_allowance_is_steps_times_flow_amplification():
    from harness.rules import tolerance_allowance

    factor, reason = tolerance_allowance(100, 0.5)  # a contracting flow counts as 1
    assert factor == tol.TOLERANCE_ESTIMATE_FACTOR * 100 and "100 steps" in reason
    assert tolerance_allowance(100, 7e4)[0] == pytest.approx(tol.TOLERANCE_ESTIMATE_FACTOR * 7e6)
    assert tolerance_allowance(0, 7e4)[0] == tol.TOLERANCE_FACTOR  # no step count: the fixed rule


@pytest.mark.parametrize("errors, steps, amplification, verdict", [
    ([1.0, 1.0, 1.0], [10, 20, 40], 1.0, "meets-tolerance"),
    # 5e3 x tol passed the fixed 1e4 rule; on a non-amplifying flow with 10-40 steps it is
    # far more than local error control can accumulate
    ([5e3, 5e3, 5e3], [10, 20, 40], 1.0, "misses-tolerance"),
    # the same ratio on an orbit whose flow amplifies errors 7e4-fold is what the flow does
    ([5e3, 5e3, 5e3], [10, 20, 40], 7e4, "meets-tolerance"),
    ([1e8, 1e8, 1e8], [10, 20, 40], 7e4, "misses-tolerance"),
])
def test_adaptive_verdict_uses_the_derived_allowance(errors, steps, amplification, verdict):
    from harness.experiments.convergence.judge import summarize_cell

    rec = summarize_cell(get_stepper("scipy-rk45"), "p", _tolerance_rows(errors, steps, amplification))
    assert rec["verdict"] == verdict, rec["message"]
    if verdict == "misses-tolerance":
        assert "flow amplification" in rec["message"]


# -- close encounters in the energy experiment ---------------------------------------------------------
@pytest.fixture
def pleiades(registered):
    """The Pleiades plugin problem, registered for one test only."""
    return registered(plugin_problem("pleiades.py", "pleiades"))


def _energy(stepper, problem, **overrides):
    from harness.experiments import get_experiment

    exp = get_experiment("energy")
    config = exp.config(overrides, quick=False)
    cells, _ = exp.cells([stepper], [problem], config)
    rows = pd.concat([exp.run_cell(c, config) for c in cells], ignore_index=True)
    return exp.summarize(rows, config).iloc[0]


def test_the_verlet_claim_is_read_after_the_pleiades_closest_approach(pleiades):
    r = _energy("velocity-verlet", pleiades, ensemble=1)
    # The error jumps to ~4e-3 at the closest approach (t ~ 1.7) and stays below it afterwards.
    assert r.verdict == "as-claimed" and bool(r.passed), r.message
    assert "first reached at t = 1.6" in r.message and "h rho = 0.12" in r.message
    assert r.max_rel_energy_error > 1e-3  # the jump is there; the envelope after it is flat


def test_a_step_beyond_the_methods_limit_during_encounters_is_not_measurable(pleiades):
    from harness.facts import method_facts

    limit = method_facts(get_stepper("yoshida8")).hw_limit  # 0.927
    h = 1.5 / 649.7  # h rho = 1.5 at the Pleiades' closest approach
    r = _energy("yoshida8", pleiades, ensemble=1, h=h, steps=3000)
    assert r.verdict == "not-measurable" and bool(r.passed), r.message
    assert f"exceeds the method's limit {limit:.4g}" in r.message
