"""The published test sets (DETEST A-E, the Bari IVP test set): definitions kept as published,
references certified for the problem as published, the stiff ones refused as stiff and answered
by the published end values.

The references are checked against what the sources publish: the Bari problem files' end values
(HIRES, PLEI integrated here; the stiff ones served) and DETEST's closed forms.
"""

from __future__ import annotations

from fractions import Fraction

import heyoka as hy
import numpy as np
import pandas as pd
import pytest

from harness.errors import InputError, StiffReferenceError
from harness.ground_truth import reference, stiff
from harness.ground_truth.levels import LEVELS_BY_NAME
from harness.problem import Problem, Published
from harness.registry import problems

TEST_SETS = [p for p in problems.all(variants=True) if "test-set" in p.tags]
DETEST = [p for p in TEST_SETS if "detest" in p.tags]
BARI = [p for p in TEST_SETS if "bari" in p.tags]
STIFF = ["bari-vdpol", "bari-rober", "bari-orego", "bari-e5", "bari-pollu"]
# closed forms given by the paper (A1-A4, D1-D5, E1)
WITH_CLOSED_FORM = [p for p in DETEST if p.exact is not None]


def test_the_families_are_complete_listed_and_on_request():
    assert len(DETEST) == 25 and len(BARI) == 7
    assert {p.name for p in DETEST} == {f"detest-{c}{i}" for c in "abcde" for i in range(1, 6)}
    default = set(problems.names())
    assert all(p.name not in default for p in TEST_SETS)  # run only when named
    assert all(p.published is not None and p.describe()["on_request"] for p in TEST_SETS)


@pytest.mark.parametrize("problem", TEST_SETS, ids=[p.name for p in TEST_SETS])
def test_definition_is_the_rounding_of_the_published_values(problem: Problem):
    pub = problem.published
    assert problem.y0.tolist() == pub.y0_float
    assert problem.t_end == pub.t_end_float
    assert list(problem.parameters.values()) == list(pub.parameters_float.values())
    f = problem.dynamics().f(problem.t0, problem.y0[:, None].copy())
    assert np.all(np.isfinite(f))
    # the compiled Jacobian takes every parameter (it counts those up to the last one it reads)
    jac = problem.dynamics().jac(problem.t0, problem.y0[:, None].copy())
    assert jac.shape == (problem.dim, problem.dim, 1) and np.all(np.isfinite(jac))
    rounding = pub.rounding()
    assert pub.exact_in_float64 == (not any(rounding.values()))
    assert all(0 <= v <= 2.0**-53 for v in rounding.values())


def test_rounding_is_measured_exactly():
    hires = problems.get("bari-hires").published
    assert hires.rounding()["y0"] == pytest.approx(abs(float(Fraction(0.0057) - Fraction("0.0057")))
                                                   / 0.0057, rel=1e-12)
    assert problems.get("detest-a1").published.exact_in_float64
    assert problems.get("bari-plei").published.exact_in_float64


def test_exact_levels_hold_more_than_the_float64_rounding():
    real128 = LEVELS_BY_NAME["real128"]
    exact = real128.exact(["0.0057"])[0]
    assert exact != real128.array(np.array([0.0057]))[0]
    assert abs(float(exact - hy.real128("0.0057"))) == 0.0


@pytest.mark.parametrize("bad, match", [
    (dict(y0=(0.5,)), "must be exact"),
    (dict(y0=("x",)), "decimal number"),
    (dict(y0=("1",), values=("1",)), "stated `accuracy`"),
])
def test_published_record_refuses_inexact_or_incomplete_values(bad, match):
    with pytest.raises(InputError, match=match):
        Published("source", **bad)


def test_a_float64_form_that_is_not_the_rounding_is_refused():
    y = hy.make_vars("y")
    with pytest.raises(InputError, match="float64 rounding of the published"):
        Problem("p", variables=[y], rhs=[-y], y0=[0.1], t_span=(0.0, 1.0),
                published=Published("s", y0=("0.1000001",)), description="d", reference="r")


def test_hires_reference_matches_the_published_values():
    """Integrated as published (exact decimals): within the stated 1e-15 of the Bari values,
    where the float64 form alone is ~1e-13 relative away in the smallest component."""
    p = problems.get("bari-hires")
    ref = reference(p, [p.t_end])
    assert ref.form == "published" and ref.precision != "published"
    published = np.array(p.published.values_float)
    got = ref.y[0][:, 0]
    assert np.all(np.abs(got - published) <= p.published.accuracy * np.abs(published) + ref.max_error)


def test_plei_reference_matches_the_published_values():
    p = problems.get("bari-plei")
    ref = reference(p, [p.t_end])
    published = np.array(p.published.values_float)
    assert np.all(np.abs(ref.y[0][:, 0] - published)
                  <= p.published.accuracy * np.abs(published) + ref.max_error)


@pytest.fixture
def without_implicit_path(monkeypatch):
    """The explicit reference alone (as without scikit-sundae): its refusal is what is seen."""
    from harness.ground_truth import stiff

    monkeypatch.setattr(stiff, "available", lambda: False)


@pytest.mark.parametrize("name", STIFF)
def test_stiff_problems_are_refused_as_stiff_and_served_their_published_values(
        name, without_implicit_path):
    p = problems.get(name)
    with pytest.raises(StiffReferenceError, match="stiff for the explicit Taylor reference"):
        reference(p, [p.t0 + (p.t_end - p.t0) / 2])
    ref = reference(p, [p.t_end])
    assert ref.form == "published values" and ref.precision == "published"
    assert ref.y[0][:, 0].tolist() == p.published.values_float
    assert ref.max_error == pytest.approx(p.published.accuracy * max(map(abs, p.published.values_float)))
    assert "stiff" in ref.certified_by and p.published.source in ref.certified_by
    # another start is not the published problem: no published values for it
    with pytest.raises(StiffReferenceError, match="stiff for the explicit"):
        reference(p, [p.t_end], p.y0 * 1.0)


@pytest.mark.parametrize("problem", WITH_CLOSED_FORM, ids=[p.name for p in WITH_CLOSED_FORM])
def test_detest_references_match_the_closed_forms(problem: Problem):
    """The float64 form's reference against the closed form from the same float64 start, and
    the published form's reference against it within the effect of the start's rounding."""
    t = problem.t_end
    exact = problem.exact(t, problem.y0[:, None], problem.t0, problem.pars_for(1))[:, 0]
    scale = np.max(np.abs(exact)) + 1.0
    as_float64 = reference(problem, [t], problem.y0.reshape(-1, 1))
    assert as_float64.form == "float64"
    assert np.max(np.abs(as_float64.y[0][:, 0] - exact)) <= 1e-14 * scale + as_float64.max_error
    as_published = reference(problem, [t])
    assert as_published.form == "published"
    assert np.max(np.abs(as_published.y[0][:, 0] - exact)) <= 1e-12 * scale


@pytest.mark.parametrize("problem", WITH_CLOSED_FORM, ids=[p.name for p in WITH_CLOSED_FORM])
def test_detest_closed_forms_solve_the_equation(problem: Problem):
    """d/dt exact by a 4th-order central difference equals f(t, exact) for perturbed starts."""
    y0 = problem.ensemble(3)
    pars = problem.pars_for(3)
    dyn = problem.dynamics(pars, 3)
    for t in (0.37, 7.1, 18.0):
        d = 1e-3
        ys = [problem.exact(t + k * d, y0, problem.t0, pars) for k in (-2, -1, 1, 2)]
        deriv = (ys[0] - 8 * ys[1] + 8 * ys[2] - ys[3]) / (12 * d)
        rhs = dyn.f(t, problem.exact(t, y0, problem.t0, pars))
        np.testing.assert_allclose(deriv, rhs, rtol=0, atol=1e-7 * (np.max(np.abs(rhs)) + 1.0))


PROTHERO_ROBINSON_RATE = 1e6


def _prothero_robinson() -> Problem:
    """y' = -L (y - cos t) - sin t, y(0) = 1: the solution is cos t whatever L, and L = 1e6 makes
    the explicit reference stiff (Prothero & Robinson, Math. Comp. 28 (1974) 145-162)."""
    y = hy.make_vars("y")
    return Problem("prothero-robinson", variables=[y],
                   rhs=[-PROTHERO_ROBINSON_RATE * (y - hy.cos(hy.time)) - hy.sin(hy.time)],
                   y0=[1.0], t_span=(0.0, 10.0), description="d", reference="r")


@pytest.mark.skipif(not stiff.available(), reason="scikit-sundae (the optional sundials extra) "
                    "is not installed: the cross-check needs CVODE")
def test_the_implicit_cross_check_answers_a_stiff_problem_within_its_stated_error():
    p = _prothero_robinson()
    times = np.array([2.5, 10.0])
    ref = reference(p, times)
    assert ref.precision == stiff.IMPLICIT_LEVEL and ref.certified_by == stiff.IMPLICIT_CERTIFIER
    truth = np.cos(times)
    actual = np.abs(ref.y[:, 0, 0] - truth)
    assert np.all(actual <= ref.error[:, 0] + 4 * np.finfo(float).eps)
    assert np.all(ref.error < 1e-10)


def test_without_the_implicit_solvers_a_stiff_problem_is_refused_as_stiff(without_implicit_path):
    with pytest.raises(StiffReferenceError, match="eigenvalue with real part -1e\\+06"):
        reference(_prothero_robinson(), [10.0])


def test_what_a_library_prints_while_it_runs_is_captured_not_written():
    """What a library prints to stdout inside `library_output_captured` (SUNDIALS' warnings
    through printf's buffer or straight to fd 1, scikit-sundae's Python `print` of SUNDIALS'
    errors) reaches neither stdout nor stderr but the caller; output before and after is kept."""
    import subprocess
    import sys

    code = (
        "import ctypes, os\n"
        "from harness.c_streams import library_output_captured\n"
        "libc = ctypes.CDLL(None)\n"
        "print('before', flush=True)\n"
        "with library_output_captured() as printed:\n"
        "    libc.printf(b'buffered C text\\n')\n"
        "    os.write(1, b'raw fd text\\n')\n"
        "    print('[cvHandleFailure, Error: -3] python text')\n"
        "print('after', flush=True)\n"
        "print('captured:', repr(printed.text), repr(printed.last_line()), flush=True)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[:2] == ["before", "after"] and proc.stderr == ""
    for text in ("buffered C text", "raw fd text", "python text"):
        assert text in lines[2]


def _two_scales() -> Problem:
    y1, y2 = hy.make_vars("y1", "y2")
    return Problem("two-scales", variables=[y1, y2], rhs=[-y1, -2.0 * y2], y0=[1.0, 1e-6],
                   t_span=(0.0, 2.0), description="d", reference="r")


@pytest.mark.parametrize("name", ["scipy-radau", "scipy-bdf", "scipy-lsoda", "cvode-bdf"])
def test_peers_scale_atol_to_each_components_size(name):
    """atol_i = tol x max|y_i| along the orbit: a component of size 1e-6 keeps its relative
    accuracy at tol = 1e-3, where atol = tol would leave it uncontrolled (ROBER's y2)."""
    from harness.registry import steppers

    if name not in steppers.names(variants=True):
        pytest.skip(f"{name} is not installed (optional extra)")
    from harness.registry import get_stepper
    from implementations.external import component_atol

    p = _two_scales()
    atol = component_atol(p.dynamics(), 1e-3)
    assert atol[1] == pytest.approx(1e-9, rel=1e-6) and atol[0] == pytest.approx(1e-3, rel=1e-6)
    stepper = get_stepper(name).with_tolerance(1e-3)
    tr = stepper.integrate(p, h=2.0, n_steps=1, y0=p.y0[:, None])
    small = tr.final[1, 0]
    # rtol = 1e-3 over the span leaves a few percent; atol = tol would leave ~100 %
    assert abs(small - 1e-6 * np.exp(-4.0)) <= 0.1 * 1e-6 * np.exp(-4.0)


class _View:
    def __init__(self, rows):
        self._rows = rows

    def has(self, name):
        return name == "work-precision"

    def rowtable(self, name):
        return self._rows


def test_the_report_section_shows_error_digits_and_work_at_the_end_point():
    from harness.report.test_sets import test_sets_section

    p = problems.get("detest-a1")
    y_end = float(np.exp(-20.0))
    rows = pd.DataFrame([
        {"stepper": "rk4", "problem": "detest-a1", "kind": "step-size", "h": 0.1, "tol": np.nan,
         "t_end": 20.0, "error": 1e-3 * y_end, "rhs_evals": 800, "wall_s": 0.01, "message": ""},
        {"stepper": "rk4", "problem": "harmonic", "kind": "step-size", "h": 0.1, "tol": np.nan,
         "t_end": 8.0, "error": 1e-6, "rhs_evals": 320, "wall_s": 0.01, "message": ""},
    ])
    sec = test_sets_section(_View(rows))
    tables = [b.table for b in sec.blocks if b.kind == "table"]
    assert len(tables) == 3
    work, cells, refs = tables
    assert len(work.rows) == 1  # harmonic has no published form
    assert [c.text for c in cells.rows[0].cells][:4] == ["detest-a1", "rk4", "1", "points"]
    text = [c.text for c in work.rows[0].cells]
    assert "detest-a1" in text and "3" in text  # 1e-3 of |y(20)|: three significant digits
    assert p.published.source in [c.text for c in refs.rows[0].cells]


def test_without_test_set_problems_the_section_says_how_to_ask_for_them():
    from harness.report.test_sets import test_sets_section

    sec = test_sets_section(_View(pd.DataFrame()))
    assert any("on request" in b.text for b in sec.blocks if b.kind != "table")


def test_a_clause_repeated_with_other_numbers_is_said_once():
    from harness.experiments.convergence.judge import summarise_clauses

    clauses = [f"horizon cut to t = {t:g} at h = {h:.3g}" for t, h in ((8, 0.1), (2, 0.05), (0.5, 1e-3))]
    out = summarise_clauses(["too few points", *clauses, "too few points", ""])
    assert out == "too few points; horizon cut to t = 8 at h = 0.1 (and 2 more like it)"
    # Notes that are themselves joined clauses (a step's failure, then the sweep's notes, as a
    # Newton failure at three step sizes gives) say each clause once, not once per note.
    notes = [f"Newton failed at h = {h:g}; floor at 1e-10; explicit tableaux only" for h in (1, 0.5)]
    out = summarise_clauses(["too few points", *notes, "floor at 1e-10; explicit tableaux only"])
    assert out == ("too few points; Newton failed at h = 1 (and 1 more like it); floor at 1e-10; "
                   "explicit tableaux only")


def test_a_stiff_problems_horizon_reaches_past_its_initial_layer():
    """A damped fast rotation (eigenvalues -1e6 +- 1e6 i) driven slowly: ten periods of the
    fastest oscillation (6e-5) end inside the initial layer; the horizon is STIFF_HORIZON_STEPS
    layer widths instead, within the span."""
    from harness.tolerances import HORIZON_PERIODS, STIFF_HORIZON_STEPS

    u, v = hy.make_vars("u", "v")
    k = 1e6
    p = Problem("damped-rotation", variables=[u, v],
                rhs=[-k * (u - hy.cos(hy.time)) - k * v, k * (u - hy.cos(hy.time)) - k * v],
                y0=[1.0, 0.0], t_span=(0.0, 10.0), description="d", reference="r")
    rate = p.time_scale.fastest_rate
    assert rate == pytest.approx(k * 2**0.5, rel=1e-3)
    assert HORIZON_PERIODS * p.time_scale.period * rate < STIFF_HORIZON_STEPS
    assert p.convergence_t_end == pytest.approx(STIFF_HORIZON_STEPS / rate)


def test_a_sweep_whose_every_tolerance_is_outside_the_library_range_is_not_measurable():
    """No tolerance ran (each below the library's documented minimum): the cell is
    `insufficient-range` with the reason and the rule calls it not measurable, never a pass on
    zero points nor a failure."""
    import pandas as pd

    from harness.experiments.convergence.judge import summarize_cell
    from harness.registry import steppers
    from harness.rules import Expectation, judge_convergence

    stepper = steppers.get("scipy-radau")
    why = "tol 1e-15 is outside scipy's documented range (rtol >= 2.2e-14)"
    g = pd.DataFrame({
        "kind": ["tolerance-not-run"] * 2, "tol": [1e-14, 1e-15], "excluded": ["tol-range"] * 2,
        "in_fit": [False, False], "error": [np.nan, np.nan], "h": [np.nan, np.nan],
        "n_steps": [0, 0], "reference_error": [1e-20, 1e-20], "reference_precision": ["float64"] * 2,
        "rounding_level": [1e-16, 1e-16], "wall_s": [0.0, 0.0], "message": [why, why],
        "t_end": [1.0, 1.0],
    })
    record = summarize_cell(stepper, "harmonic", g)
    assert record["verdict"] == "insufficient-range"
    assert "no tolerance of the sweep ran" in record["message"] and "outside" in record["message"]
    outcome, reason = judge_convergence(record, Expectation("meets-tolerance", None, (), "adaptive"))
    assert outcome == "not-measurable" and "outside" in reason


@pytest.mark.parametrize("error, verdict", [(np.inf, "unstable"), (np.nan, "failed")])
def test_a_shortened_horizon_note_is_no_failure_but_a_step_that_could_not_be_completed_is(error, verdict):
    """Every point of a stiff sweep blew up (rk4 on E5) and each row carries the sweep's note that
    the horizon was shortened: `unstable` (tolerated where the problem is stiff for the method),
    not `failed`; a point whose step could not be completed (error NaN, StepFailure's message) is
    still `failed` with that message."""
    import pandas as pd

    from harness.experiments.convergence.judge import summarize_cell
    from harness.registry import steppers

    note = "work budget spent with 0 asymptotic point(s) up to t = 60; horizon shortened to t = 15"
    failure = "stepper 'x': Newton iteration did not converge at t=0.9"
    last = f"{note}; {failure}" if np.isnan(error) else note
    g = pd.DataFrame({
        "kind": ["global"] * 3, "h": [1.0, 0.5, 0.25], "error": [np.inf, np.inf, error],
        "excluded": ["blow-up", "blow-up", "blow-up" if np.isinf(error) else ""],
        "in_fit": [False] * 3, "n_steps": [4, 8, 16], "reference_error": [1e-20] * 3,
        "reference_precision": ["float64"] * 3, "rounding_level": [1e-16] * 3, "wall_s": [0.0] * 3,
        "message": [note, note, last], "t_end": [15.0] * 3,
    })
    record = summarize_cell(steppers.get("rk4"), "bari-e5", g)
    assert record["verdict"] == verdict
    if verdict == "failed":
        assert failure in record["message"]


def test_a_problem_turning_stiff_late_is_measured_into_its_stiff_phase():
    """A fast oscillation (period 0.063: ten periods end at 0.63) beside a decay whose rate
    1 + (t/2)^8 grows along the span: the horizon is where T x the largest rate up to T reaches
    STIFF_HORIZON_STEPS (T ~ 5.1), not the ten periods, which see no stiffness."""
    from scipy.optimize import brentq

    from harness.tolerances import HORIZON_PERIODS, STIFF_HORIZON_STEPS

    x, v, w = hy.make_vars("x", "v", "w")
    s2 = (hy.time / 2.0) * (hy.time / 2.0)
    p = Problem("late-stiff", variables=[x, v, w],
                rhs=[v, -1e4 * x, -(1.0 + (s2 * s2) * (s2 * s2)) * (w - hy.cos(hy.time)) - hy.sin(hy.time)],
                y0=[1.0, 0.0, 1.0], t_span=(0.0, 10.0), description="d", reference="r")
    onset = brentq(lambda T: T * max(100.0, 1.0 + (T / 2.0) ** 8) - STIFF_HORIZON_STEPS, 1.0, 10.0)
    assert p.t0 + HORIZON_PERIODS * p.time_scale.period < 1.0 < onset
    assert p.convergence_t_end == pytest.approx(onset, rel=1e-2)
