"""Symplecticity: the one-step Jacobian of every registered stepper against its claim, the
finite-difference machinery on maps with a known Jacobian, and mislabelled steppers.

Expectations: splitting methods, Stormer-Verlet, implicit midpoint and Gauss collocation are
symplectic; explicit Runge-Kutta methods, backward Euler and the trapezoidal rule are not
(the trapezoidal rule is, on linear problems: it is the Cayley transform there). Hairer, Lubich &
Wanner, GNI VI.3-VI.4.
"""

from __future__ import annotations

import json

import helpers
import numpy as np
import pandas as pd
import pytest
from helpers import PlainEulerLabelledSymplectic, cells_or_reasons, relabelled

from harness import tolerances as tol
from harness.cli import main
from harness.experiments import get_experiment
from harness.experiments import symplecticity as symp
from harness.registry import get_problem, steppers

EXP = get_experiment("symplecticity")
STEPPERS = steppers.names()
PROBLEMS = ["harmonic", "kepler-elliptic"]

run_direct, run = helpers.runners(EXP)


# -- the machinery on maps with a known Jacobian ---------------------------------------------------
def test_canonical_form_and_deviation_of_known_matrices():
    omega = symp.canonical_form(4)
    assert np.array_equal(omega.T, -omega) and np.array_equal(omega @ omega, -np.eye(4))
    h = 0.1
    rotation = np.array([[np.cos(h), np.sin(h)], [-np.sin(h), np.cos(h)]])
    euler = np.array([[1.0, h], [-h, 1.0]])  # explicit Euler on x'' = -x: det = 1 + h^2
    assert symp.symplectic_deviation(rotation)[0] < 1e-15
    dev, raw = symp.symplectic_deviation(euler)
    assert raw == pytest.approx(h * h, rel=1e-12)
    assert dev == pytest.approx(np.sqrt(2) * h * h / (2 + 2 * h * h), rel=1e-12)


def test_finite_difference_jacobian_of_a_linear_map_is_exact_to_rounding(registered):
    """Plain Euler on x'' = -x is the linear map [[1, h], [-h, 1]]: the differenced Jacobian
    must reproduce it at every base state."""
    name = registered(PlainEulerLabelledSymplectic("euler-probe"))
    stepper = steppers.get(name)
    states = get_problem("harmonic").ensemble(3, seed=1)
    h = 0.05
    J = symp.one_step_jacobians(stepper, get_problem("harmonic"), states, h)
    assert J.shape == (3, 2, 2)
    assert np.max(np.abs(J - np.array([[1.0, h], [-h, 1.0]]))) < 1e-11


# -- the registry ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", STEPPERS)
def test_every_stepper_gets_a_cell_or_a_reason_on_every_problem(name):
    cells, skips = cells_or_reasons(EXP, name)
    stepper = steppers.get(name)
    # Stormer's two-step rule with the Taylor start and central velocity is velocity Verlet
    one_step = stepper.info.family == "stormer" or getattr(stepper, "one_step_verlet", False)
    if stepper.history_length > 1 and not one_step:
        assert not cells
        assert any("starting procedure" in s.reason for s in skips)


@pytest.fixture(scope="module")
def registry_table():
    return run_direct(STEPPERS, PROBLEMS)


@pytest.mark.parametrize("name", STEPPERS)
def test_registry_jacobians_match_the_symplecticity_claim(name, registry_table):
    rows = registry_table[registry_table.stepper == name]
    stepper = steppers.get(name)
    cells, _ = EXP.cells([name], PROBLEMS, EXP.config(quick=True))
    assert sorted(rows.problem) == sorted(c.problem for c in cells)
    for _, r in rows.iterrows():
        assert bool(r.passed), (r.problem, r.deviation, r.message)
        if stepper.info.symplectic:
            assert r.verdict == "symplectic" and r.deviation <= tol.SYMPLECTIC_FD_TOL
        elif r.problem == "kepler-elliptic" and r.verdict != "not-measurable":
            # nonlinear: every non-symplectic map shows it, unless it is too close to the exact
            # flow at this step (a black box run at a tolerance it beats by far), said as such
            assert r.verdict == "non-symplectic"
            assert r.deviation >= tol.SYMPLECTIC_CLEAR_FACTOR * tol.SYMPLECTIC_FD_TOL
        elif r.verdict == "not-measurable":
            assert r.message.startswith("not measurable") and r.deviation < (
                tol.SYMPLECTIC_CLEAR_FACTOR * tol.SYMPLECTIC_FD_TOL)


def test_trapezoid_is_symplectic_on_the_linear_oscillator_only(registry_table):
    if "trapezoid" not in steppers:
        pytest.skip("no `trapezoid` stepper registered")
    t = registry_table[registry_table.stepper == "trapezoid"].set_index("problem")
    assert t.loc["harmonic", "verdict"] == "symplectic-here"
    assert t.loc["kepler-elliptic", "verdict"] == "non-symplectic"


def test_records_carry_the_promised_fields(registry_table):
    assert list(registry_table.columns) == symp.SUMMARY_COLUMNS
    for field in ("stepper", "problem", "deviation", "claimed_symplectic", "verdict", "passed"):
        assert field in symp.SUMMARY_COLUMNS


# -- mislabelled steppers must fail ---------------------------------------------------------------
@pytest.mark.parametrize("problem", PROBLEMS)
def test_plain_euler_labelled_symplectic_fails(problem, registered):
    name = registered(PlainEulerLabelledSymplectic())
    r = run([name], [problem]).iloc[0]
    assert r.verdict == "claim-false" and not bool(r.passed)
    assert r.deviation > 1e3 * tol.SYMPLECTIC_FD_TOL


def test_rk4_labelled_symplectic_fails(registered):
    """The smallest defect in the registry: rk4 at h omega = 0.1 misses by ~(h omega)^6 / 72."""
    name = registered(relabelled("rk4", symplectic=True))
    table = run([name], PROBLEMS)
    assert (table.verdict == "claim-false").all() and not table.passed.any()


def test_velocity_verlet_labelled_not_symplectic_fails(registered):
    name = registered(relabelled("velocity-verlet", symplectic=False))
    table = run([name], PROBLEMS)
    assert (table.verdict == "claim-false").all() and not table.passed.any()
    assert table.message.str.contains("not clearly above").all()


# -- settings and the command line ----------------------------------------------------------------

def test_cli_json_records(capsys):
    code = main(["run", "symplecticity", "--quick", "--stepper", "leapfrog", "--stepper", "rk4",
                 "--stepper", "ab2", "--problem", "pendulum", "--jobs", "1", "--fresh", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    records = pd.DataFrame(json.loads(out))
    assert set(records.stepper) == {"leapfrog", "rk4"}
    assert dict(zip(records.stepper, records.verdict, strict=True)) == {
        "leapfrog": "symplectic", "rk4": "non-symplectic"}
