"""The external peers (scipy `solve_ivp` methods) against exact solutions at their requested
tolerance, with honest evaluation counts and reported failures.

Tolerance mapping under test: rtol = atol = tol. Local error control does not bound the global
error, so the check is error <= C * tol with C per problem (below, with its reason), plus
tolerance proportionality: asking for 1000x less must give at least 30x less error.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import BLOWUP

from harness.errors import InputError
from harness.registry import get_problem, get_stepper
from harness.stepper import StepFailure
from harness.tolerances import SCIPY_MIN_RTOL
from implementations import external
from implementations.external import ScipyStepper

PEERS = list(external.STEPPERS)
IMPLICIT_PEERS = [s for s in PEERS if s.uses_jacobian]


def ids(items):
    return [s.info.name for s in items]


CLAIMED = {
    "scipy-rk45": (5, True),
    "scipy-dop853": (8, True),
    "scipy-radau": (5, False),
    "scipy-bdf": (None, False),
    "scipy-lsoda": (None, False),
}

# Global error bound C * tol over one period / orbit:
# - harmonic (one period 2 pi): errors stay within a few tens of tol (measured up to ~60 for BDF,
#   whose error estimate is the loosest); C = 300.
# - kepler-elliptic (e = 0.6, one orbit): the pericentre passage at r = 0.4 amplifies local errors
#   into a phase error; measured up to ~2e3 tol (BDF, LSODA); C = 2e4.
ACCURACY = {"harmonic": 300.0, "kepler-elliptic": 2e4}
TOLS = (1e-6, 1e-9)
PROPORTIONALITY = 30.0  # error(1e-9) <= error(1e-6) / 30 (ideal: 1000)


def test_every_peer_is_registered():
    for stepper in PEERS:
        assert get_stepper(stepper.info.name) is stepper
    assert set(ids(PEERS)) == set(CLAIMED)


@pytest.mark.parametrize("stepper", PEERS, ids=ids(PEERS))
def test_declared_properties(stepper):
    info = stepper.info
    order, explicit = CLAIMED[info.name]
    assert info.family == "external" and info.adaptive and info.implementation == "scipy"
    assert info.claimed_order == order and info.explicit == explicit
    assert info.reference and "solve_ivp" in info.description and info.evals_per_step > 0
    assert info.extra["scipy_method"] == stepper.method
    assert info.extra["rtol"] == max(stepper.tol, SCIPY_MIN_RTOL) and info.extra["atol"] == stepper.tol
    assert info.extra["tol_range"] == [SCIPY_MIN_RTOL, None] and "atol_per_component" in info.extra


@pytest.mark.parametrize("problem_name", sorted(ACCURACY))
@pytest.mark.parametrize("stepper", PEERS, ids=ids(PEERS))
def test_error_at_the_requested_tolerance(stepper, problem_name):
    P = get_problem(problem_name)
    y0 = P.ensemble(2)
    t_end = 2.0 * math.pi  # one period of harmonic, one orbit of kepler-elliptic (a = 1)
    exact = P.exact(t_end, y0, P.t0, None)
    errors = []
    for tol in TOLS:
        tr = stepper.with_tolerance(tol).integrate(P, h=t_end / 2, n_steps=2, y0=y0)
        errors.append(float(np.max(np.abs(tr.final - exact))))
        assert errors[-1] <= ACCURACY[problem_name] * tol, (tol, errors[-1] / tol)
    assert errors[1] <= errors[0] / PROPORTIONALITY


@pytest.mark.parametrize("stepper", PEERS, ids=ids(PEERS))
def test_counts_are_recorded_and_honest(stepper):
    P = get_problem("kepler-elliptic")
    N = 3
    tr = stepper.with_tolerance(1e-7).integrate(P, h=1.0, n_steps=2, y0=P.ensemble(N))
    ev = tr.evals
    assert ev["internal_steps"] > 0 and ev["member_rhs"] > 0
    # every evaluation scipy reports went through the run's Dynamics, and no other
    assert ev["member_rhs"] == ev["scipy_nfev"]
    assert ev["member_jac"] == ev["scipy_njev"]
    # ensemble units: the mean per trajectory
    assert ev["rhs"] == pytest.approx(ev["member_rhs"] / N)
    assert ev["jac"] == pytest.approx(ev["member_jac"] / N)
    assert ev["member_rhs"] >= ev["internal_steps"]
    if stepper.info.explicit:
        assert ev["member_jac"] == 0


@pytest.mark.parametrize("stepper", IMPLICIT_PEERS, ids=ids(IMPLICIT_PEERS))
def test_implicit_peers_use_the_symbolic_jacobian_on_a_stiff_problem(stepper):
    P = get_problem("van-der-pol-stiff")
    from harness.ground_truth import reference

    y0 = P.ensemble(2)
    truth = reference(P, [0.5], y0).y[-1]
    tr = stepper.with_tolerance(1e-8).integrate(P, h=0.5, n_steps=1, y0=y0)
    assert tr.evals["member_jac"] > 0
    assert np.max(np.abs(tr.final - truth)) <= 1e3 * 1e-8


def test_members_with_their_own_parameters():
    """Each member is integrated with its own parameters (dahlquist with per-member lambda)."""
    P = get_problem("dahlquist")
    pars = np.array([[-1.0, -0.5, -2.0], [0.0, 3.0, 1.0]])  # lambda_re, lambda_im per member
    y0 = np.array([[1.0, 1.0, 0.5], [0.0, 0.0, 0.5]])
    exact = P.exact(1.0, y0, 0.0, pars)
    for stepper in PEERS:
        tr = stepper.with_tolerance(1e-10).integrate(P, h=0.5, n_steps=2, y0=y0, pars=pars)
        assert np.max(np.abs(tr.final - exact)) <= 1e3 * 1e-10, stepper.info.name


@pytest.mark.parametrize("stepper", PEERS, ids=ids(PEERS))
def test_failed_solve_raises(stepper):
    pattern = rf"stepper '{stepper.info.name}': scipy {stepper.method} (failed|stalled) .*member 0"
    with pytest.raises(StepFailure, match=pattern):
        stepper.with_tolerance(1e-6).integrate(BLOWUP, h=2.0, n_steps=1)


def test_with_tolerance_records_the_new_tolerance():
    base = get_stepper("scipy-rk45")
    tight = base.with_tolerance(1e-16)
    assert tight.tol == 1e-16 and tight.info.extra["tol"] == 1e-16
    assert tight.info.extra["rtol"] == SCIPY_MIN_RTOL and tight.info.extra["atol"] == 1e-16
    assert base.tol != 1e-16  # a copy, not a change


@pytest.mark.parametrize("bad", [0.0, -1e-8, math.inf, "tight"])
def test_bad_tolerance(bad):
    with pytest.raises(InputError, match=r"`tol` must be"):
        get_stepper("scipy-dop853").with_tolerance(bad)


def test_unknown_method():
    with pytest.raises(InputError, match=r"`method` must be one of .*'RK45'.*, got 'RK23'"):
        ScipyStepper("RK23")


@pytest.mark.parametrize("stepper", PEERS, ids=ids(PEERS))
def test_a_hopeless_span_is_stopped_by_the_projection_long_before_the_budget(stepper):
    """A span of 1e300 is projected far over the evaluation budget once PROJECTION_START of it
    is spent: the solve stops at a projection (its message says so), not at the budget."""
    with pytest.raises(StepFailure, match=r"would need about .* evaluations .*too long for tol="):
        stepper.with_tolerance(1e-6).integrate(get_problem("harmonic"), h=1e300, n_steps=1)


@pytest.mark.parametrize("burst", [0.05, 0.3])
def test_a_slow_start_then_a_fast_run_within_the_budget_is_not_stopped(burst):
    """Synthetic calls: the first `burst` of a solve's calls crawl over 5 % of the span (a stiff
    transient), the rest cover it quickly, and the whole needs 0.9x the budget: the projection
    never stops it (with `burst` 0.3 the early projections reach about half the margin). A crawl
    that would need 1e7 calls for the span is stopped at a projection, before the budget."""
    problem = get_problem("harmonic")
    member = external.MemberDynamics(external.Dynamics(problem, problem.pars_for(1, None)), 0)
    total = int(0.9 * external.ADAPTIVE_MAX_EVALS)
    slow = int(burst * total)
    y = np.zeros(2)
    member.reset(0.0, 1.0)
    for k in range(total):
        member.f(0.05 * k / slow if k < slow else 0.05 + 0.95 * (k - slow) / (total - slow), y)
    member.reset(0.0, 1.0)
    calls = 0
    with pytest.raises(Exception, match=r"projected from the recent ones"):
        for k in range(total):
            calls += 1
            member.f(1e-7 * (k + 1), y)
    assert calls < external.ADAPTIVE_MAX_EVALS
