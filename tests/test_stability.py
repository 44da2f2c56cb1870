"""The stability experiment: published intervals measured through the black-box probe, probe
against formula for every registered stepper, and mislabelled steppers caught.

Oracles: NodePy / Hairer & Wanner II, IV.2 (rk4 2.785293563 and 2 sqrt 2; euler 2 and 0; heun 2;
rk3 2.5127 and sqrt 3; A-stable implicit methods unbounded), V.1 (ab2: 1), and the Verlet
limit h omega < 2 (Hairer, Lubich & Wanner, GNI I.5).
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pandas as pd
import pytest

from harness import tolerances as tol
from harness.coefficients import (
    ButcherTableau,
    LinearMultistep,
    SecondOrderMultistep,
    SplittingScheme,
)
from harness.errors import InputError
from harness.experiments import get_experiment
from harness.experiments.stability import SUMMARY_COLUMNS, FirstOrderProbe
from harness.registry import get_problem, get_stepper, steppers
from harness.stepper import AdaptiveStepper, Carry, Stepper, StepperInfo
from implementations.splitting import SplittingStepper

QUICK = {"grid": 41, "hw_grid": 41}


# -- test doubles ---------------------------------------------------------------------------------
class _TableauRK(Stepper):
    """Explicit Runge-Kutta that declares `declared` as its coefficients but steps with
    `actual` (a mislabelled method when they differ). Hairer, Norsett & Wanner I, II.1."""

    def __init__(self, name: str, declared: ButcherTableau, actual: ButcherTableau):
        self.coefficients = declared
        self._actual = actual
        self.info = StepperInfo(
            name=name, family="explicit-rk", claimed_order=1, explicit=True, symplectic=False,
            symmetric=False, evals_per_step=float(actual.stages), form="first-order",
            velocity_dependent=True, reference="Hairer, Norsett & Wanner I, II.1 (test double)")

    def _start(self, dyn, t0, y0, h):
        return Carry(t0, h, y0)

    def _step(self, dyn, c):
        tab, h, y = self._actual, c.h, c.y
        k = []
        for i in range(tab.stages):
            stage = y + h * sum((tab.A[i, j] * k[j] for j in range(i)), np.zeros_like(y))
            k.append(dyn.f(c.t + tab.c[i] * h, stage))
        c.y = y + h * sum(tab.b[i] * k[i] for i in range(tab.stages))


class _HistoryLMM(Stepper):
    """Explicit linear multistep recurrence with a history hook; declares `declared`, steps with
    `actual`. Euler supplies the first k - 1 values in `integrate`. HNW I, III.1."""

    def __init__(self, name: str, declared: LinearMultistep, actual: LinearMultistep):
        self.coefficients = declared
        self._actual = actual
        self.history_length = declared.steps
        self.info = StepperInfo(
            name=name, family="multistep", claimed_order=2, explicit=True, symplectic=False,
            symmetric=False, evals_per_step=1.0, form="first-order", velocity_dependent=True,
            reference="Hairer, Norsett & Wanner I, III.1 (test double)")

    def _start(self, dyn, t0, y0, h):
        return Carry(t0, h, y0, hist=[y0])

    def _start_from_history(self, dyn, t0, h, history):
        k = len(history)
        return Carry(t0 + (k - 1) * h, h, history[-1], hist=list(history))

    def _step(self, dyn, c):
        m, k, h, t = self._actual, self._actual.steps, c.h, c.t
        if len(c.hist) < k:
            y = c.hist[-1] + h * dyn.f(t, c.hist[-1])
        else:
            y = np.zeros_like(c.y)
            for j in range(k):
                y += -m.alpha[j] * c.hist[j] + h * m.beta[j] * dyn.f(t - (k - 1 - j) * h, c.hist[j])
        c.hist = [*c.hist, y][-k:]
        c.y = y


class _HistoryStormer(Stepper):
    """Two-step position recurrence sum_j alpha_j x_(n+j) = h^2 sum_j beta_j a(x_(n+j)) (beta_2 =
    0) with a history hook; declares `declared`, steps with `actual`. Taylor start, backward-
    difference velocity. Hairer, Norsett & Wanner I, III.10."""

    history_length = 2

    def __init__(self, name: str, declared: SecondOrderMultistep, actual: SecondOrderMultistep):
        self.coefficients = declared
        self._actual = actual
        self.info = StepperInfo(
            name=name, family="stormer", claimed_order=2, explicit=True, symplectic=True,
            symmetric=True, evals_per_step=1.0, form="newtonian", velocity_dependent=False,
            reference="Hairer, Norsett & Wanner I, III.10 (test double)")

    def _start(self, dyn, t0, y0, h):
        nq = dyn.nq
        x0, v0 = y0[:nq], y0[nq:]
        x_prev = x0 - h * v0 + 0.5 * h * h * dyn.accel(t0, x0)  # Taylor backwards
        return Carry(t0, h, y0, prev=x_prev, cur=x0.copy())

    def _start_from_history(self, dyn, t0, h, history):
        nq = dyn.nq
        return Carry(t0 + h, h, history[-1], prev=history[0][:nq].copy(), cur=history[1][:nq].copy())

    def _step(self, dyn, c):
        a, b, h = self._actual.alpha, self._actual.beta, c.h
        rhs = -a[0] * c.prev - a[1] * c.cur + h * h * (
            b[0] * dyn.accel(c.t - h, c.prev) + b[1] * dyn.accel(c.t, c.cur))
        c.prev, c.cur = c.cur, rhs

    def _observe(self, dyn, c):
        return np.concatenate([c.cur, (c.cur - c.prev) / c.h])


class _StormerNoHook(_HistoryStormer):
    """The same recurrence without a history hook: the probe must identify it from the observed
    positions of its runs (the 'position-recurrence' probe)."""

    history_length = 1
    _start_from_history = Stepper._start_from_history


def _with_claim(stepper: Stepper, name: str, claim: dict) -> Stepper:
    clone = type(stepper).__new__(type(stepper))
    clone.__dict__.update(stepper.__dict__)
    extra = {**stepper.info.extra, "stability": claim}
    clone.info = dataclasses.replace(stepper.info, name=name, extra=extra)
    return clone


def _doubles() -> list[Stepper]:
    rk4 = get_stepper("rk4").coefficients
    b = np.array(rk4.b)
    b[0] += 1e-3
    rk4_bad = ButcherTableau("rk4-bad", rk4.A, b / b.sum(), rk4.c)
    ab2 = LinearMultistep("ab2", [0, -1, 1], [-0.5, 1.5, 0])
    ab2_bad = LinearMultistep("ab2-bad", [0, -1, 1], [-0.5 - 1e-3, 1.5 + 1e-3, 0])
    vv = get_stepper("velocity-verlet")
    skewed = SplittingScheme("vv-skewed", [("K", 0.5 + 1e-3), ("D", 1.0), ("K", 0.5 - 1e-3)])
    vv_mislabelled = SplittingStepper(skewed, claimed_order=2, reference="test double")
    vv_mislabelled.coefficients = vv.coefficients  # declares velocity Verlet, steps the skewed scheme
    vv_mislabelled.info = dataclasses.replace(vv_mislabelled.info, name="test-vv-mislabelled")
    stormer = SecondOrderMultistep("stormer", [1, -2, 1], [0, 1, 0])
    stormer_bad = SecondOrderMultistep("stormer-bad", [1, -2, 1], [0.01, 0.99, 0])
    return [
        _TableauRK("test-rk4-mislabelled", rk4, rk4_bad),
        _HistoryLMM("test-ab2-history", ab2, ab2),
        _HistoryLMM("test-ab2-mislabelled", ab2, ab2_bad),
        _with_claim(get_stepper("rk4"), "test-rk4-claims-3", {"real_interval": 3.0}),
        _with_claim(get_stepper("rk4"), "test-rk4-claims-right",
                    {"real_interval": 2.7853, "imag_interval": 2.8284}),
        _with_claim(get_stepper("backward-euler"), "test-be-claims-unbounded",
                    {"real_interval": math.inf, "imag_interval": "inf"}),
        _with_claim(vv, "test-vv-claims-2.5", {"hw_limit": 2.5}),
        vv_mislabelled,
        _HistoryStormer("test-stormer-history", stormer, stormer),
        _HistoryStormer("test-stormer-mislabelled", stormer, stormer_bad),
        _StormerNoHook("test-stormer-no-hook", stormer, stormer),
        _StormerNoHook("test-stormer-no-hook-mislabelled", stormer, stormer_bad),
    ]


@pytest.fixture(scope="module")
def run():
    doubles = _doubles()
    for d in doubles:
        steppers.register(d, origin="test")
    try:
        exp = get_experiment("stability")
        cfg = exp.config(QUICK, quick=True)
        cells, skips = exp.cells(steppers.names(), ["ignored"], cfg)
        rows = pd.concat([exp.run_cell(c, cfg) for c in cells], ignore_index=True)
        summary = exp.summarize(rows, cfg)
        yield {"cells": cells, "skips": skips, "rows": rows,
               "summary": summary.set_index("stepper", drop=False)}
    finally:
        for d in doubles:
            steppers.unregister(d.info.name)


# -- published figures through the black-box probe -------------------------------------------------
ORACLES = [  # stepper, figure, value, absolute tolerance
    ("rk4", "real_interval", 2.785293563, 1e-8),
    ("rk4", "imag_interval", 2.0 * math.sqrt(2.0), 1e-8),
    ("euler", "real_interval", 2.0, 1e-8),
    ("euler", "imag_interval", 0.0, 0.0),
    ("heun", "real_interval", 2.0, 1e-8),
    ("rk3", "real_interval", 2.5127, 1e-4),
    ("rk3", "imag_interval", math.sqrt(3.0), 1e-8),
    ("backward-euler", "real_interval", math.inf, 0.0),
    ("implicit-midpoint", "real_interval", math.inf, 0.0),
    ("trapezoid", "real_interval", math.inf, 0.0),
    ("gauss-legendre-4", "real_interval", math.inf, 0.0),
    ("test-ab2-history", "real_interval", 1.0, 1e-8),
    ("test-ab2-history", "imag_interval", 0.0, 0.0),
    ("velocity-verlet", "hw_limit", 2.0, 1e-8),
    ("stormer-verlet", "hw_limit", 2.0, 1e-8),
    ("test-stormer-history", "hw_limit", 2.0, 1e-8),
    ("test-stormer-no-hook", "hw_limit", 2.0, 1e-8),
]


@pytest.mark.parametrize("name, figure, value, atol", ORACLES)
def test_published_figures_through_the_probe(run, name, figure, value, atol):
    row = run["summary"].loc[name]
    assert row[figure] == pytest.approx(value, abs=atol)
    assert row["verdict"] == "agrees" and row["passed"]


def test_probe_rows_are_the_measured_amplification(run):
    """Grid rows of rk4: |R| from the probe equals |R(z)| of the formula (to rounding)."""
    g = run["rows"]
    g = g[(g.stepper == "rk4") & (g.kind == "grid")]
    assert len(g) == QUICK["grid"] ** 2
    z = g.z_re.to_numpy() + 1j * g.z_im.to_numpy()
    R = 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24
    np.testing.assert_allclose(g.abs_r_probe.to_numpy(), np.abs(R), rtol=1e-13, atol=1e-15)


# -- every registered stepper --------------------------------------------------------------------
def test_every_registered_stepper_has_a_row_or_a_reason(run):
    covered = {c.stepper for c in run["cells"]} | {s.stepper for s in run["skips"]}
    assert covered == set(steppers.names())
    for s in run["skips"]:
        assert s.reason
        stepper = get_stepper(s.stepper)
        cannot_run = "cannot run the test equation" in s.reason  # e.g. needs an N-body structure
        assert cannot_run or isinstance(stepper, AdaptiveStepper) or getattr(
            stepper, "history_length", 1) < getattr(stepper.coefficients, "steps", 1)


def test_registered_steppers_agree_with_their_coefficients(run):
    summary = run["summary"]
    mine = summary[~summary.stepper.str.startswith("test-")]
    for _, row in mine.iterrows():
        if get_stepper(row.stepper).coefficients is None:
            continue
        assert row.analytic_agrees is True, (row.stepper, row.message)
        assert row.max_probe_analytic_diff <= tol.STABILITY_AGREEMENT_TOL
        assert row.verdict == "agrees"


def test_summary_has_the_promised_columns(run):
    summary = run["summary"]
    assert list(summary.columns) == SUMMARY_COLUMNS
    first = summary[summary.form == "first-order"]
    newton = summary[summary.form == "newtonian"]
    assert first.real_interval.notna().all() and first.imag_interval.notna().all()
    assert newton.hw_limit.notna().all() and newton.real_interval.isna().all()
    assert set(summary.loc["backward-euler", "unbounded"].split(",")) == {"real_interval", "imag_interval"}


# -- mislabelled steppers are caught ---------------------------------------------------------------
@pytest.mark.parametrize(
    "name, verdict",
    [
        ("test-rk4-mislabelled", "disagree"),
        ("test-ab2-mislabelled", "disagree"),
        ("test-vv-mislabelled", "disagree"),
        ("test-stormer-mislabelled", "disagree"),
        ("test-stormer-no-hook-mislabelled", "disagree"),
        ("test-rk4-claims-3", "claim-false"),
        ("test-vv-claims-2.5", "claim-false"),
        ("test-rk4-claims-right", "agrees"),
        ("test-be-claims-unbounded", "agrees"),
    ],
)
def test_verdicts(run, name, verdict):
    row = run["summary"].loc[name]
    assert row["verdict"] == verdict, row["message"]
    assert row["passed"] == (verdict == "agrees")
    if verdict == "claim-false":
        assert "claimed" in row["message"] and json.loads(row["claimed"])


def test_probe_modes(run):
    summary = run["summary"]
    assert summary.loc["test-stormer-history", "probe"] == "history"
    assert summary.loc["test-stormer-no-hook", "probe"] == "position-recurrence"
    assert summary.loc["test-ab2-history", "probe"] == "history-2"
    assert summary.loc["velocity-verlet", "probe"] == "one-step"


def test_mislabelled_probe_difference_is_reported(run):
    row = run["summary"].loc["test-rk4-mislabelled"]
    assert row.analytic_agrees is False
    assert row.max_probe_analytic_diff > 1e-6
    assert "differs from the coefficients' formula" in row.message


# -- the probe itself ------------------------------------------------------------------------------
def test_probe_marks_only_failing_points():
    """Backward Euler at its pole z = 1 fails the Newton solve; the rest of the ensemble is kept."""
    probe = FirstOrderProbe(get_stepper("backward-euler"), get_problem("dahlquist"))
    z = np.array([-1.0, 1.0, 0.5j, -3.0 + 2.0j])
    C = probe.blocks(z)
    assert np.isnan(C[1]).all()
    ok = [0, 2, 3]
    np.testing.assert_allclose(C[ok, 0, 0, 0] + 1j * C[ok, 0, 1, 0], 1.0 / (1.0 - z[ok]), rtol=1e-14)


def test_bad_config_is_named():
    exp = get_experiment("stability")
    cell = exp.cells(["rk4"], [], exp.config())[0][0]
    with pytest.raises(InputError, match=r"`grid` must be a whole number in \[3, 1001\]"):
        exp.run_cell(cell, exp.config({"grid": 2}))
    with pytest.raises(InputError, match="`re_min` must be below `re_max`"):
        exp.run_cell(cell, exp.config({"re_min": 1.0, "re_max": -1.0}))
    with pytest.raises(InputError, match="`search_limit` must be a positive finite number"):
        exp.run_cell(cell, exp.config({"search_limit": math.inf}))
