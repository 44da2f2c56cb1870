"""Stiff test-set problems judged fairly: an implicit method whose solve fails where no theorem
guarantees it converges is not measurable (not failed), and a gate row says when a problem stiff
over its declared span was measured over a span where it is not.

Swept over the registry's fixed-step steppers: the verdict follows from the method's facts
(explicit or not) and the problem's stiffness, never from a name.
"""

from __future__ import annotations

from dataclasses import replace

import heyoka as hy
import numpy as np
import pandas as pd
import pytest

from harness import tolerances as tol
from harness.experiments.convergence.judge import summarize_cell
from harness.facts import ProblemFacts, method_facts, problem_facts
from harness.gate import stiff_span_flag
from harness.problem import Problem
from harness.registry import get_problem, steppers
from harness.rules import convergence_expectation, judge_convergence

FIXED_STEP = [s for s in steppers.all() if not s.info.adaptive and s.info.form == "first-order"]
STIFFNESS = 1e6
FAILURE = ("stepper 'x': Newton iteration did not converge at t=0.5 after 20 iteration(s) (full): "
           "scaled increment 7.9e-07, contraction 1")


def _stiff_facts() -> ProblemFacts:
    return ProblemFacts(linear=False, polynomial_degree=None, newtonian=False, velocity_free=False,
                        time_dependent=False, stiffness=STIFFNESS, horizon=1.0, rhs_degree=2)


def _failed_rows(finest_h: float) -> pd.DataFrame:
    """A sweep whose every step size failed in its solve (error NaN, the failure as message)."""
    hs = finest_h * 2.0 ** np.arange(4)[::-1]
    return pd.DataFrame({
        "kind": ["global"] * 4, "h": hs, "error": [np.nan] * 4, "excluded": ["blow-up"] * 4,
        "in_fit": [False] * 4, "n_steps": np.round(1.0 / hs).astype(int), "reference_error": [1e-20] * 4,
        "reference_precision": ["float64"] * 4, "rounding_level": [1e-16] * 4, "wall_s": [0.0] * 4,
        "message": [FAILURE] * 4, "t_end": [1.0] * 4,
    })


@pytest.mark.parametrize("stepper", FIXED_STEP, ids=[s.info.name for s in FIXED_STEP])
@pytest.mark.parametrize("h_times_stiffness", [1e3, tol.NEWTON_GUARANTEE_STEPS, 1.0])
def test_a_solve_failing_where_no_theorem_guarantees_it_is_not_measurable(stepper, h_times_stiffness):
    """Implicit: failed at every step size down to h with h x stiffness >= NEWTON_GUARANTEE_STEPS
    is not measurable (HNW I, II.7, Thm 7.2 needs h L |a| < 1); below it the failure stands.
    Explicit: a failed step is always a failure (no solve to excuse it)."""
    h = h_times_stiffness / STIFFNESS
    record = summarize_cell(stepper, "stiff", _failed_rows(h))
    assert record["verdict"] == "failed"
    assert record["finest_h"] == pytest.approx(h) and record["t_end"] == 1.0
    expectation = convergence_expectation(method_facts(stepper), _stiff_facts())
    outcome, reason = judge_convergence(record, expectation)
    excused = (not stepper.info.explicit) and h_times_stiffness >= tol.NEWTON_GUARANTEE_STEPS
    assert outcome == ("not-measurable" if excused else "fail"), reason
    if excused:
        assert "Theorem 7.2" in reason and f"h = {h:.3g}" in reason and FAILURE in reason


def test_the_excuse_needs_a_stiff_problem():
    """A non-stiff problem (stiffness 0) gives an implicit method's failed solve no excuse."""
    bdf = next(s for s in FIXED_STEP if not s.info.explicit)
    facts = ProblemFacts(linear=False, polynomial_degree=None, newtonian=False, velocity_free=False,
                         time_dependent=False, stiffness=0.0, horizon=1.0)
    record = summarize_cell(bdf, "mild", _failed_rows(1e-1))
    outcome, _ = judge_convergence(record, convergence_expectation(method_facts(bdf), facts))
    assert outcome == "fail"


@pytest.mark.parametrize("stiffness, span, measured, flagged", [
    (1e6, 1.0, 1e-4, True),      # stiff over the span (1e6), the layer only where measured (100)
    (1e6, 1.0, 1e-2, False),     # stiff where measured (1e4)
    (1e2, 1.0, 1.0, False),      # not stiff over its span (100): nothing to flag
    (1e6, 1.0, np.nan, False),   # no measured span: no flag
    (1e6, 1.0, None, False),
])
def test_a_stiff_problem_measured_where_it_is_not_stiff_is_flagged(stiffness, span, measured, flagged):
    flag = stiff_span_flag(stiffness, 0.0, span, measured)
    assert bool(flag) == flagged
    if flagged:
        assert flag.startswith("stiff problem not stiff over the measured span")
        assert f"{stiffness * measured:.3g}" in flag and f"{stiffness * span:.3g}" in flag


@pytest.mark.parametrize("problem, config_t_end", [
    ("detest-a1", None), ("bari-hires", None), ("harmonic", None), ("bari-hires", 7.5)])
def test_work_precision_runs_a_test_set_to_its_published_end(monkeypatch, problem, config_t_end):
    """A test-set problem's work-precision sweep ends at the published end point (the test set's
    own reports measure the error there); others at their convergence horizon; a t_end the user
    set wins."""
    import harness.experiments.work_precision as wp
    from harness.experiments.base import Cell
    from harness.registry import get_problem

    seen = {}

    def fake_sweep(stepper, prob, cfg):
        seen["t_end"] = cfg.get("t_end")
        return pd.DataFrame({"kind": ["global"], "h": [0.1], "tol": [np.nan], "n_steps": [10],
                             "t_end": [1.0], "error": [1e-3], "rhs_evals": [40.0],
                             "force_evals": [0.0], "wall_s": [0.0], "message": [""]})

    monkeypatch.setattr(wp, "step_sweep", fake_sweep)
    monkeypatch.setattr(wp, "time_points", lambda stepper, prob, frame, cfg: frame)
    config = {**wp.WorkPrecisionExperiment.default_config, "t_end": config_t_end}
    wp.WorkPrecisionExperiment().run_cell(Cell("work-precision", "rk4", problem), config)
    p = get_problem(problem)
    expected = config_t_end if config_t_end is not None else (p.t_end if p.published is not None else None)
    assert seen["t_end"] == expected


def test_the_orbit_sampler_keeps_its_step_cap_and_its_samples(monkeypatch):
    """The orbit is heyoka's steps plus ORBIT_DENSE_POINTS points inside each; the step cap
    ends it as incomplete, not singular (a stiff span), and the samples lie on the flow."""
    from harness import scales
    from harness.registry import get_problem

    problem = get_problem("harmonic")
    full = scales.sample_orbit(problem)
    assert full.complete and full.singular == "" and full.t[0] == problem.t0 and full.t[-1] == problem.t_end
    steps = (full.t.size - 1) // (tol.ORBIT_DENSE_POINTS + 1)
    assert full.t.size == 1 + steps * (tol.ORBIT_DENSE_POINTS + 1) and np.all(np.diff(full.t) > 0)
    monkeypatch.setattr(tol, "ORBIT_MAX_STEPS", 5)
    capped = scales.sample_orbit(problem)
    assert not capped.complete and capped.singular == ""
    assert capped.t.size == 1 + 5 * (tol.ORBIT_DENSE_POINTS + 1)
    np.testing.assert_allclose(capped.t, full.t[:capped.t.size], rtol=0, atol=1e-12)
    np.testing.assert_allclose(capped.y, full.y[:, :capped.t.size], rtol=0, atol=1e-12)


def test_an_orbit_that_blows_up_is_singular():
    """y' = y^2 from 1 is singular at t = 1: the orbit ends before it, incomplete, with a reason."""
    import heyoka as hy

    from harness.problem import Problem
    from harness.scales import sample_orbit

    y = hy.make_vars("y")
    p = Problem("blow-up", variables=[y], rhs=[y * y], y0=[1.0], t_span=(0.0, 2.0),
                description="d", reference="r")
    orbit = sample_orbit(p)
    assert not orbit.complete and orbit.singular and orbit.t[-1] < 1.0
    assert np.all(np.isfinite(orbit.y))


def test_a_numpy_twin_whose_step_fails_leaves_the_cell_standing():
    """Where the compiled loop ran a point and the NumPy twin's Newton fails there (bdf2 on
    bari-hires at coarse steps), the twin is untimed at that point with the failure in the row's
    message; the work-precision cell is not turned into an error."""
    from harness.experiments.work_precision import timed_runs
    from harness.registry import get_problem, get_stepper
    from harness.stepper import StepFailure

    stepper, problem = get_stepper("bdf2"), get_problem("harmonic")
    out = pd.DataFrame({"error": [1e-3, 1e-5], "t_min_s": [1e-3, 2e-3], "n_steps": [8, 16],
                        "t_end": [1.0, 1.0], "message": ["", ""]})

    def call(s, i):
        def run():
            raise StepFailure(f"stepper 'bdf2': Newton iteration did not converge at point {i}")
        return run

    settings = {"min_repeats": 1, "max_repeats": 1, "budget_s": 1.0}
    timed_runs._time_twin(stepper, object(), problem, out, problem.y0.reshape(-1, 1), call, settings,
                          clock=iter(np.arange(0.0, 100.0, 0.5)).__next__)
    assert out["twin_min_s"].isna().all()
    assert "NumPy twin not timed" in out.at[1, "message"] and "point 1" in out.at[1, "message"]


def test_a_solve_the_harness_would_not_pay_for_is_not_run_not_failed(monkeypatch):
    """The harness's evaluation cap (`WorkLimitFailure`: CVODE Adams on POLLU, projected 8.9e8
    evaluations) leaves that tolerance not run, with the reason; a sweep where no tolerance ran
    is not measurable. A solver's own failure (`StepFailure`) is still a failed cell."""
    from harness.experiments import convergence
    from harness.experiments.base import get_experiment
    from harness.registry import get_problem, get_stepper
    from harness.rules import Expectation
    from harness.stepper import StepFailure, WorkLimitFailure

    stepper, problem = get_stepper("scipy-radau"), get_problem("harmonic")
    config = {**get_experiment("convergence").default_config, "tolerances": [1e-3, 1e-5]}
    adaptive = Expectation("meets-tolerance", None, (), "adaptive")
    for failure, outcome in ((WorkLimitFailure, "not-measurable"), (StepFailure, "fail")):
        class Refused:
            def integrate(self, *args, failure=failure, **kwargs):
                raise failure("stepper 'scipy-radau': would need about 8.86e+08 evaluations")

        monkeypatch.setattr(type(stepper), "with_tolerance", lambda self, t: Refused())
        rows = convergence._tolerance_sweep(stepper, problem, config)
        record = summarize_cell(stepper, "harmonic", rows)
        got, reason = judge_convergence(record, adaptive)
        assert got == outcome and "8.86e+08" in reason, reason


@pytest.mark.parametrize("errors, verdict", [
    ([8e11, 6e13, 1e21, 8e13, 3e-13], "insufficient-range"),  # ab4 x detest-b2: stable only at the floor
    ([8e11, 6e13, 1e21, 8e13, np.inf], "unstable"),           # the finest step blew up too
    ([8e11, 6e13, 1e-4, 6e-6, 4e-7], "insufficient-range"),   # a stable range above the floor
])
def test_stable_only_at_the_floor_is_no_evidence_but_a_finest_blow_up_is(errors, verdict):
    """A decaying problem at its end point (DETEST B2, C2): every coarse step blew up and the first
    stable one is already at the rounding floor; nothing to read an order from (not measurable),
    unlike a sweep whose finest step blew up (`unstable`)."""
    hs = 2.5 * 0.5 ** np.arange(5)
    err = np.array(errors)
    excluded = np.where(~np.isfinite(err) | (err > 1e6), "blow-up",
                        np.where(err < 1e-12, "roundoff", "pre-asymptotic"))
    g = pd.DataFrame({"kind": ["global"] * 5, "h": hs, "error": err, "excluded": excluded,
                      "in_fit": [False] * 5, "n_steps": (20 / hs).astype(int), "reference_error": [4e-16] * 5,
                      "reference_precision": ["longdouble"] * 5, "rounding_level": [7e-15] * 5,
                      "wall_s": [0.0] * 5, "message": [""] * 5, "t_end": [20.0] * 5})
    record = summarize_cell(steppers.get("ab4"), "detest-b2", g)
    assert record["verdict"] == verdict, record["message"]
    if excluded[-1] == "roundoff":
        assert "already at the floor" in record["message"]


@pytest.mark.parametrize("fit_h_max, outcome", [(6.5e-3, "not-measurable"), (1e-3, "fail")])
def test_a_fit_over_steps_outside_the_stability_interval_is_not_measurable(fit_h_max, outcome):
    """ab3 on bari-hires (stiffness 192, real interval 0.545: stable for h < 2.8e-3) fitted a
    constant error 7.85e-3 at h = 3.3e-3 ... 6.5e-3 (slope 0): points of an amplified mode, not
    of the error expansion. Within the stable steps a wrong slope still fails."""
    facts = ProblemFacts(linear=False, polynomial_degree=None, newtonian=False, velocity_free=False,
                         time_dependent=False, stiffness=192.0, horizon=321.8)
    ab3 = next(s for s in FIXED_STEP if s.info.name == "ab3")
    expectation = convergence_expectation(method_facts(ab3), facts)
    assert expectation.stable_h == pytest.approx(method_facts(ab3).real_interval / 192.0)
    record = {"verdict": "converged", "measured_order": 0.0, "fit_h_max": fit_h_max, "message": ""}
    got, reason = judge_convergence(record, expectation)
    assert got == outcome, reason


def _singular_perturbation(name: str, z0: float) -> Problem:
    """y' = z, eps z' = (1 - y^2) z - y (van der Pol, eps = 1e-6) from y = 2: its slow manifold
    has z = y / (1 - y^2) + O(eps) = -2/3 there."""
    y, z = hy.make_vars("y", "z")
    return Problem(name, variables=[y, z], rhs=[z, ((1.0 - y * y) * z - y) / 1e-6],
                   y0=[2.0, z0], t_span=(0.0, 2.0), convergence_t_end=1e-3)


def _prothero_robinson(name: str, y0: float) -> Problem:
    """y' = -1e4 (y - cos t) - sin t: smooth solution cos t, a layer for any other start."""
    y = hy.make_vars("y")
    return Problem(name, variables=[y], rhs=[-1e4 * (y - hy.cos(hy.time)) - hy.sin(hy.time)],
                   y0=[y0], t_span=(0.0, 1.0))


@pytest.mark.parametrize("problem, width", [
    (_singular_perturbation("sp-off-manifold", 0.0), 1e-6 / 3),  # offset 2/3 decaying at 3e6
    (_singular_perturbation("sp-on-manifold", -2.0 / 3.0 - 10.0 / 81.0 * 1e-6), None),
    (_prothero_robinson("pr-layer", 2.0), 1e-4),
    (_prothero_robinson("pr-smooth", 1.0), None),
    ("bari-vdpol", 1e-6 / 3), ("van-der-pol-stiff", None),
    ("kepler-e0.9", None),  # a pericentre's +-lambda saddle: fast, but growing as well as decaying
])
def test_an_initial_layer_is_found_from_the_definition(problem, width):
    problem = get_problem(problem) if isinstance(problem, str) else problem
    found = problem_facts(problem).layer_width
    if width is None:
        assert found is None
    else:
        assert found == pytest.approx(width, rel=1e-3)


@pytest.mark.parametrize("fit_h_min, outcome", [(1e-5, "not-measurable"), (1e-7, "fail")])
@pytest.mark.parametrize("stepper", FIXED_STEP[:3] + [s for s in FIXED_STEP if not s.info.explicit][:3],
                         ids=lambda s: s.info.name)
def test_a_slope_over_steps_that_skip_an_initial_layer_is_not_measurable(stepper, fit_h_min, outcome):
    """Order p on stiff problems needs a smooth solution (HW II VI.2-VI.3): a slope off the
    claim over steps all above the layer's width says nothing; with a step inside it, it fails."""
    facts = replace(_stiff_facts(), layer_width=1e-6 / 3)
    expectation = convergence_expectation(method_facts(stepper), facts)
    claimed = expectation.order
    lowest = expectation.order_low if expectation.order_low is not None else claimed
    record = {"verdict": "converged", "measured_order": lowest - 1.0, "fit_h_min": fit_h_min,
              "fit_h_max": 8 * fit_h_min, "message": ""}
    got, reason = judge_convergence(record, expectation)
    if expectation.stable_h is not None and 8 * fit_h_min > expectation.stable_h:
        assert got == "not-measurable" and "stable step" in reason  # the stability rule first
        return
    assert got == outcome, reason
    if outcome == "not-measurable":
        assert "initial layer of width 3.33e-07" in reason and "VI.2" in reason
    record["measured_order"] = claimed
    assert judge_convergence(record, expectation)[0] == "pass"
