"""Time reversibility: every registered stepper's round trip against its symmetry claim, the
rounding bound, and mislabelled steppers that must be caught.

Expectations: a symmetric method (Phi_{-h} = Phi_h^{-1}) returns to its start up to rounding,
a non-symmetric one misses by ~h^p T (Hairer, Lubich & Wanner, GNI II.3 and V.1).
"""

from __future__ import annotations

import helpers
import numpy as np
import pandas as pd
import pytest
from helpers import cells_or_reasons, relabelled

from harness import tolerances as tol
from harness.cli import main
from harness.experiments import get_experiment
from harness.experiments.common import long_run_steps
from harness.experiments.reversibility import (
    SUMMARY_COLUMNS,
    flow_amplification,
    one_sided_reason,
    rounding_bound_ulps,
)
from harness.registry import get_problem, steppers
from harness.stepper import AdaptiveStepper

EXP = get_experiment("reversibility")
STEPPERS = steppers.names()
PROBLEMS = ["harmonic", "kepler-elliptic"]

run_direct, run = helpers.runners(EXP)


@pytest.fixture(scope="module")
def registry_table():
    """The whole registry: round trips of 10^2 and 10^3 steps (one period for adaptive peers)."""
    return run_direct(STEPPERS, PROBLEMS, steps=[100, 1000], implicit_steps=[100], adaptive_steps=[1])


# -- the registry ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", STEPPERS)
def test_every_stepper_gets_cells_or_a_reason_on_every_problem(name):
    cfg = EXP.config()
    cells, _ = cells_or_reasons(EXP, name, cfg)
    stepper = steppers.get(name)
    expected = (cfg["adaptive_steps"] if isinstance(stepper, AdaptiveStepper)
                else cfg["steps"] if stepper.info.explicit else cfg["implicit_steps"])
    for p in {c.problem for c in cells}:
        counts = expected
        if not isinstance(stepper, AdaptiveStepper):  # cut where the orbit leaves its regime
            problem = get_problem(p)
            cap = long_run_steps(problem, problem.time_scale.h, max(expected))[0]
            counts = {min(n, cap) for n in expected}
        assert sorted(c.param("steps") for c in cells if c.problem == p) == sorted(counts)


@pytest.mark.parametrize("name", STEPPERS)
def test_registry_round_trips_match_the_symmetry_claim(name, registry_table):
    rows = registry_table[registry_table.stepper == name]
    stepper = steppers.get(name)
    compatible = [p for p in PROBLEMS if stepper.compatible(get_problem(p))]
    if one_sided_reason(stepper) and stepper.kept_points > stepper.history_length:  # see the skip
        compatible = []
    assert sorted(set(rows.problem)) == sorted(compatible)
    if one_sided_reason(stepper):  # a symmetric recurrence: judged on its positions
        assert all("positions only" in m for m in rows.message)
    for _, r in rows.iterrows():
        assert bool(r.passed), (r.problem, r.steps, r.message)
        if r.claimed_symmetric:
            assert r.verdict == "reversible"
            assert r.return_error_ulps <= r.rounding_bound_ulps
        else:
            assert r.verdict == "irreversible"
            assert r.return_error_ulps > r.rounding_bound_ulps


def test_records_carry_the_promised_fields(registry_table):
    for field in ("stepper", "problem", "steps", "return_error", "return_error_ulps",
                  "claimed_symmetric", "verdict", "passed"):
        assert field in registry_table.columns
    assert list(registry_table.columns) == SUMMARY_COLUMNS


def test_symmetric_return_error_grows_no_faster_than_rounding_allows():
    """Velocity Verlet on the harmonic oscillator (no amplification by the flow): the return
    error stays within a few ulps per step over 10^2..10^4 steps."""
    table = run(["velocity-verlet"], ["harmonic"], steps=[100, 1000, 10_000], ensemble=8)
    assert list(table.steps) == [100, 1000, 10_000]
    assert (table.return_error_ulps <= tol.REVERSIBILITY_ULPS_PER_STEP * 1.5 * table.steps).all()
    assert table.growth_exponent.iloc[0] <= 1.2


def test_rounding_bound_uses_the_flow_amplification():
    harmonic = flow_amplification(get_problem("harmonic"), 100 * get_problem("harmonic").time_scale.h)
    kepler_problem = get_problem("kepler-elliptic")
    kepler = flow_amplification(kepler_problem, 1000 * kepler_problem.time_scale.h)
    # A rotation: ||J||_inf = |cos| + |sin| <= sqrt(2). Kepler shears: perturbations grow.
    assert 1.0 - 1e-6 <= harmonic <= np.sqrt(2.0) + 1e-6
    assert kepler > 100.0
    assert rounding_bound_ulps(1000, kepler) == pytest.approx(
        tol.REVERSIBILITY_ULPS_PER_STEP * 1000 * kepler)
    assert rounding_bound_ulps(1000, 0.5) == tol.REVERSIBILITY_ULPS_PER_STEP * 1000


@pytest.mark.parametrize("name", ["forced-duffing", "kepler-elliptic", "planets-pair"])
def test_batched_flow_amplification_is_the_orbit_by_orbit_central_difference(name):
    """The perturbed orbits run through heyoka's batch integrator (a last batch with fewer
    orbits than lanes is filled with repeats): the same central difference as one scalar orbit
    after another, to the difference's own noise."""
    from harness import flow, scales

    problem = get_problem(name)
    span = 20 * problem.time_scale.h
    base = np.asarray(problem.y0, dtype=float)
    delta = tol.REVERSIBILITY_FLOW_DELTA * np.where(base != 0.0, np.abs(base), 1.0)
    J = np.empty((problem.dim, problem.dim))
    for j in range(problem.dim):
        plus, minus = base.copy(), base.copy()
        plus[j] += delta[j]
        minus[j] -= delta[j]
        end = [problem.t0 + span]
        J[:, j] = (scales.states_at(problem, end, plus) - scales.states_at(problem, end, minus))[:, 0] / (
            2.0 * delta[j])
    expected = float(np.max(np.sum(np.abs(J), axis=1)))
    assert flow.flow_amplification(problem, span) == pytest.approx(expected, rel=1e-6)


def test_an_orbit_the_batch_integrator_cannot_follow_gives_no_amplification():
    import heyoka as hy

    from harness import flow
    from harness.problem import Problem

    y = hy.make_vars("y")
    blow_up = Problem("riccati-flow", variables=[y], rhs=[y * y], y0=[1.0], t_span=(0.0, 0.5),
                      reference="test")
    assert np.isnan(flow.flow_amplification(blow_up, 2.0))
    assert flow.flow_amplification(blow_up, 0.5) == pytest.approx(4.0, rel=1e-6)  # 1 / (1 - t)^2


# -- mislabelled steppers must fail ---------------------------------------------------------------
@pytest.mark.parametrize("problem", PROBLEMS)
def test_explicit_euler_labelled_symmetric_fails(problem, registered):
    name = registered(relabelled("euler", symmetric=True))
    table = run([name], [problem])
    assert len(table) == len(EXP.config(quick=True)["steps"])
    assert (table.verdict == "claim-false").all() and not table.passed.any()
    assert table.message.str.contains("claimed symmetric").all()


def test_velocity_verlet_labelled_not_symmetric_fails(registered):
    name = registered(relabelled("velocity-verlet", symmetric=False))
    table = run([name], ["harmonic"])
    assert (table.verdict == "claim-false").all() and not table.passed.any()


# -- settings and the command line ----------------------------------------------------------------

def test_cli_json_records(capsys):
    code = main(["run", "reversibility", "--quick", "--stepper", "leapfrog", "--stepper", "rk4",
                 "--problem", "harmonic", "--jobs", "1", "--fresh", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    import json

    records = pd.DataFrame(json.loads(out))
    assert set(records.stepper) == {"leapfrog", "rk4"}
    assert set(records.verdict) == {"reversible", "irreversible"}
    assert records.passed.all()


def test_cli_overrides_set_the_step_size_and_the_span(capsys):
    """`--h` and `--t-end` replace the problem's derived step and the list of step counts: one
    round trip of exactly the span asked for, recorded with the h used."""
    code = main(["run", "reversibility", "--quick", "--stepper", "leapfrog", "--problem", "harmonic",
                 "--h", "0.05", "--t-end", "10", "--jobs", "1", "--fresh", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    import json

    records = pd.DataFrame(json.loads(out))
    assert list(records.steps) == [200] and records.h.iloc[0] == pytest.approx(0.05)
    assert records.verdict.iloc[0] == "reversible"


@pytest.mark.parametrize("argv, match", [
    (["--h", "-1"], r"`--h` must be a positive finite number, got '-1'"),
    (["--steps", "10,x"], r"`--steps` must be whole numbers >= 1"),
    (["--steps", "100", "--t-end", "5"], r"give `--steps` or `--t-end`, not both"),
    (["--perturbation", "nan"], r"`--perturbation` must be a positive finite number"),
])
def test_cli_overrides_are_validated_in_one_line(capsys, argv, match):
    import re

    code = main(["run", "reversibility", "--quick", "--stepper", "leapfrog", "--problem", "harmonic",
                 "--jobs", "1", *argv])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and re.search(match, err), err


def test_within_rounding_on_a_slow_stretch_passes_when_shown_elsewhere():
    """A problem whose h resolves a close encounter leaves a non-symmetric method's truncation
    below rounding over short slow stretches: that cell is `reversible-here` when the method is
    irreversible in another cell of the run, and `claim-false` when it never is."""
    def row(steps, ulps):
        return {"stepper": "rk4", "problem": "harmonic", "steps": steps, "h": 0.1, "tol": np.nan,
                "t_span": 0.1 * steps, "return_error": ulps * tol.EPS, "return_error_ulps": ulps,
                "flow_amplification": 1.0, "rounding_bound_ulps": 2.0 * steps, "perturbation": 0.01,
                "ensemble_size": 4, "wall_s": 0.0, "message": ""}

    both = EXP.summarize(pd.DataFrame([row(100, 10.0), row(1000, 1e9)]), EXP.config(quick=True))
    assert list(both.verdict) == ["reversible-here", "irreversible"] and both.passed.all()
    assert "irreversible in another cell" in both.message.iloc[0]
    never = EXP.summarize(pd.DataFrame([row(100, 10.0)]), EXP.config(quick=True))
    assert list(never.verdict) == ["claim-false"] and not never.passed.any()
