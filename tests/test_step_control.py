"""Step controllers keep their claims: symmetry (round trip), order in the control parameter
(the gate's fit), and bounded versus drifting energy (the energy experiment's classifier)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from harness import tolerances as tol
from harness.errors import CoefficientError, IncompatibleError
from harness.experiments.convergence import classify_points, fit_order
from harness.experiments.energy import classify_drift
from harness.registry import get_problem, get_stepper
from implementations.splitting import VELOCITY_VERLET
from implementations.step_control import (
    DELTA_THETA,
    STEPPERS,
    ControlledScheme,
    ControlledSplittingStepper,
)
from problems.kepler import kepler_exact

NAIVE = "velocity-verlet+dtheta-naive"
REVERSIBLE = "velocity-verlet+dtheta-reversible"
# A round trip of a symmetric map returns to rounding: the error grows like sqrt(n) ulps
# of the state per step pair; 1e-11 absolute over 2000 steps of a state of size ~2.
ROUND_TRIP_ROUNDING = 1e-11
# ... and a non-symmetric one misses by its local error, far above rounding.
ROUND_TRIP_MISS = 1e-6


def _run(name: str, problem: str, h: float, n: int):
    return get_stepper(name).integrate(get_problem(problem), h=h, n_steps=n)


@pytest.mark.parametrize("name", [NAIVE, REVERSIBLE])
def test_records_declare_their_claims(name):
    info = get_stepper(name).info
    assert info.extra["keeps_constant"].startswith("Delta theta")
    assert info.extra["uniform_time"] is False
    assert info.symmetric is (name == REVERSIBLE)
    assert info.claimed_order == 2
    assert not info.symplectic


def test_reversible_order_is_capped_at_two_for_a_higher_order_scheme():
    from harness.coefficients import SplittingScheme

    g = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
    fr = SplittingScheme("fr", [("K", g / 2), ("D", g), ("K", (1 - g) / 2), ("D", 1 - 2 * g),
                                ("K", (1 - g) / 2), ("D", g), ("K", g / 2)])
    rev = ControlledSplittingStepper(ControlledScheme(fr, DELTA_THETA, "reversible"), reference="test")
    naive = ControlledSplittingStepper(ControlledScheme(fr, DELTA_THETA, "naive"), reference="test")
    assert (rev.info.claimed_order, naive.info.claimed_order) == (2, 4)


def test_bad_records_are_refused():
    from harness.coefficients import SplittingScheme

    with pytest.raises(CoefficientError, match="`controller` must be one of"):
        ControlledScheme(VELOCITY_VERLET, DELTA_THETA, "clever")
    with pytest.raises(CoefficientError, match="needs a symmetric scheme"):
        ControlledScheme(SplittingScheme("a", [("K", 1.0), ("D", 1.0)]), DELTA_THETA, "reversible")


def test_a_problem_without_a_central_force_is_incompatible():
    with pytest.raises(IncompatibleError, match="central force"):
        _run(NAIVE, "harmonic", 0.1, 10)


def test_reversible_round_trip_returns_to_rounding_and_naive_does_not():
    problem = get_problem("kepler-e0.9")
    h = 2 * math.pi / 256
    start, back = get_stepper(REVERSIBLE).round_trip(problem, h=h, n_steps=2000)
    assert np.max(np.abs(back - start)) <= ROUND_TRIP_ROUNDING
    start, back = get_stepper(NAIVE).round_trip(problem, h=h, n_steps=2000)
    assert np.max(np.abs(back - start)) >= ROUND_TRIP_MISS


def test_each_member_keeps_its_own_clock_and_ensembles_equal_single_runs():
    problem = get_problem("kepler-elliptic")
    y0 = problem.ensemble(3, seed=1)
    for stepper in STEPPERS:
        tr = stepper.integrate(problem, h=0.05, n_steps=300, y0=y0)
        assert tr.member_t is not None and tr.member_t.shape == (2, 3)
        assert len(set(np.round(tr.member_t[-1], 12))) == 3
        one = stepper.integrate(problem, h=0.05, n_steps=300, y0=y0[:, 1])
        np.testing.assert_allclose(one.final[:, 0], tr.final[:, 1], rtol=0, atol=1e-14)
        assert one.t[-1] == pytest.approx(tr.member_t[-1, 1], abs=1e-13)


@pytest.mark.parametrize("name", [NAIVE, REVERSIBLE])
def test_order_in_the_control_parameter_on_kepler_elliptic(name):
    problem = get_problem("kepler-elliptic")
    span = 2 * math.pi
    hs, errors = [], []
    for n in (64, 128, 256, 512, 1024, 2048):
        tr = _run(name, "kepler-elliptic", span / n, n)
        exact = kepler_exact(tr.t[-1], problem.y0[:, None], problem.t0)
        hs.append(span / n)
        errors.append(float(np.max(np.abs(tr.final - exact))))
    h, e = np.array(hs), np.array(errors)
    reasons = classify_points(h, e, np.full(h.size, 1e-16), math.sqrt(2048) * tol.EPS * 2 * np.ones(h.size),
                              tol.SWEEP_START_ERROR * 2.0)
    kept = reasons == ""
    assert kept.sum() >= tol.MIN_FIT_POINTS, reasons
    fit = fit_order(h[kept], e[kept])
    assert abs(fit["order"] - get_stepper(name).info.claimed_order) <= tol.GATE_ORDER_TOL, fit


def _energy_class(name: str, problem: str, n: int) -> dict:
    from harness.experiments.energy import save_grid

    p = get_problem(problem)
    save = save_grid(n, 20, 400)
    tr = get_stepper(name).integrate(p, h=2 * math.pi / 128, n_steps=n, save_steps=save)
    y = np.ascontiguousarray(tr.y[:, :, 0].T)
    E = p.invariant_values(y)["energy"]
    rel = np.abs(E - E[0]) / abs(E[0])
    return classify_drift(tr.steps, tr.t, rel, fit_start=n // 30)


def test_energy_bounded_for_reversible_and_drifting_for_naive():
    n = 30_000
    naive = _energy_class(NAIVE, "kepler-e0.9", n)
    reversible = _energy_class(REVERSIBLE, "kepler-e0.9", n)
    assert reversible["drift_class"] == "bounded", reversible
    assert naive["drift_class"] in ("sqrt", "linear", "unstable"), naive
    assert naive["max_error"] > 10 * reversible["max_error"]


def test_the_experiment_summary_has_its_columns_on_a_tiny_run():
    from harness.experiments.base import Cell
    from harness.experiments.step_control import SUMMARY_COLUMNS, StepControlExperiment

    exp = StepControlExperiment()
    cfg = exp.config({"energy_steps": 3000, "sweep_points": 5, "fixed_budget": 4096,
                      "uniform_samples": 200, "target_error": 1e-2}, quick=True)
    cells, skips = exp.cells([REVERSIBLE, "velocity-verlet"], ["kepler-elliptic"], cfg)
    # Asked for velocity Verlet, the experiment adds its other controlled version (listed on
    # request only), and skips the fixed-step method itself with the reason.
    assert sorted(c.stepper for c in cells) == sorted([REVERSIBLE, "velocity-verlet+dtheta-naive"])
    assert any("not step-controlled" in s.reason for s in skips)
    rows = exp.run_cell(Cell(exp.name, REVERSIBLE, "kepler-elliptic"), cfg)
    summ = exp.summarize(rows, cfg)
    assert list(summ.columns) == SUMMARY_COLUMNS and len(summ) == 1
    rec = summ.iloc[0]
    assert rec.fixed_peer == "velocity-verlet"
    assert rec.work_ratio > 1.0
    assert set(rows.role) == {"controlled", "fixed"}

    from harness.experiments.step_control.section import build_section

    fragment = build_section({"rows": rows, "summary": summ})
    assert fragment.startswith('<section id="step-control">') and "<svg" in fragment
    assert "Work saved at each eccentricity" in fragment
    assert isinstance(pd.DataFrame(rows), pd.DataFrame)


@pytest.mark.parametrize("e", [0.9, 0.99])
def test_eccentric_kepler_problems_have_their_elements(e):
    from problems.kepler import orbital_elements

    p = get_problem(f"kepler-e{e:g}")
    el = orbital_elements(p.y0[:, None])
    assert el["a"][0] == pytest.approx(1.0, rel=1e-14)
    assert el["e"][0] == pytest.approx(e, rel=1e-13)
    # one period later the exact solution is back at pericentre (a rounding of the time is
    # amplified by the pericentre acceleration 1/(1 - e)^2)
    back = kepler_exact(float(el["period"][0]), p.y0[:, None], 0.0)[:, 0]
    np.testing.assert_allclose(back, p.y0, rtol=0, atol=1e-12 * np.max(np.abs(p.y0)) / (1 - e) ** 2)
    # every ensemble member stays bound with a pericentre near the nominal one
    members = orbital_elements(p.ensemble(16, seed=0))
    assert np.all(members["energy"] < 0)
    assert np.all(members["a"] * (1 - members["e"]) > 0.5 * (1 - e))


def test_the_convergence_experiment_compares_at_each_members_own_clock():
    from harness.gate import gate_table
    from harness.runner import run_experiment

    result = run_experiment("convergence", [REVERSIBLE], ["kepler-elliptic"],
                            config={"ensemble": 2, "work_budget": 2**14}, jobs=1, cache=False,
                            progress=False)
    row = result.summary.iloc[0]
    assert row.verdict == "converged", row.to_dict()
    assert abs(row.measured_order - 2.0) <= tol.GATE_ORDER_TOL
    assert bool(gate_table(result.summary)["passed"].iloc[0])
