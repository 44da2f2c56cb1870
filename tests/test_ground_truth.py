"""The certified ground truth: agreement with exact solutions, honest error bounds, the level
policy, the on-disk cache, and clear errors.

Every test here computes its references afresh in a private cache directory, so a stale cache
from an earlier version can never make a test pass.
"""

from __future__ import annotations

import heyoka as hy
import numpy as np
import pytest

from harness import ground_truth as gt
from harness.errors import InputError, ReferenceError_
from harness.problem import Problem
from harness.registry import get_problem

EPS = np.finfo(np.float64).eps

# Allowance for the exact formulas' own rounding, in units of eps x max(1, |y|): the ground truth
# must agree with the exact solution within its certified error plus this.
EXACT_ROUNDING_ULPS = {
    "harmonic": 4,  # cos/sin of an exactly known argument
    "gaussian": 4,  # one exp
    "free-fall": 4,  # a quadratic polynomial
    "dahlquist": 8,  # complex exp and product
    "kepler-circular": 8,  # Kepler's equation solved in long double, then rounded
    "kepler-elliptic": 8,
    # scipy's ellipj/ellipkinc work in float64 with arguments up to ~35 (5 periods): measured
    # ~16 eps, allowed 200.
    "pendulum": 200,
    "pendulum-small": 200,
}
ENSEMBLE = 16


@pytest.fixture(autouse=True)
def private_reference_cache(tmp_path_factory, monkeypatch):
    directory = tmp_path_factory.getbasetemp() / "references"
    directory.mkdir(exist_ok=True)
    monkeypatch.setattr(gt.disk, "references_dir", lambda: directory)
    return directory


@pytest.mark.parametrize("name", sorted(EXACT_ROUNDING_ULPS))
def test_reference_agrees_with_exact_solution(name):
    problem = get_problem(name)
    y0 = problem.ensemble(ENSEMBLE)
    pars = problem.pars_for(ENSEMBLE)
    times = np.linspace(problem.t0, problem.convergence_t_end, 4)[1:]
    ref = gt.reference(problem, times, y0)
    assert ref.y.shape == (times.size, problem.dim, ENSEMBLE)
    assert ref.error.shape == (times.size, ENSEMBLE)
    assert (ref.precision, ref.certified_by) == (gt.DEFAULT_LEVEL, gt.certifier_of(gt.DEFAULT_LEVEL))
    exact = np.stack([problem.exact(t, y0, problem.t0, pars) for t in times])
    allowance = EXACT_ROUNDING_ULPS[name] * EPS * np.maximum(1.0, np.abs(exact))
    excess = np.abs(ref.y - exact) - ref.error[:, None, :] - allowance
    assert np.all(excess <= 0), f"worst excess {np.max(excess):.3g}"
    # the default level certifies errors at the float64 rounding of the state
    assert np.all(ref.error <= 8 * EPS * np.max(np.abs(exact), axis=1))


def test_dahlquist_with_complex_lambda_per_member():
    problem = get_problem("dahlquist")
    y0 = problem.ensemble(4)
    pars = np.array([[-1.0, -0.5, 0.0, -2.0], [0.0, 3.0, 5.0, -1.0]])
    ref = gt.reference(problem, [0.5, 1.0], y0, pars=pars)
    exact = np.stack([problem.exact(t, y0, 0.0, pars) for t in (0.5, 1.0)])
    assert np.all(np.abs(ref.y - exact) <= ref.error[:, None, :] + 8 * EPS)


def test_kepler_elliptic_at_t100_issue_check():
    problem = get_problem("kepler-elliptic")
    ref = gt.reference(problem, 100.0)
    exact = problem.exact(100.0, problem.y0[:, None], 0.0, None)[:, 0]
    assert np.max(np.abs(ref.y[0, :, 0] - exact)) <= 1e-13
    assert ref.max_error <= 1e-15


def test_float64_level_error_is_measured_not_assumed():
    """A loose requirement picks float64; its certified error really bounds its actual error
    (~2e-12 at t = 100, far above the tolerance heyoka was given)."""
    problem = get_problem("kepler-elliptic")
    ref = gt.reference(problem, [10.0, 100.0], required_error=1e-9)
    assert (ref.precision, ref.certified_by) == ("float64", "longdouble")
    exact = np.stack([problem.exact(t, problem.y0[:, None], 0.0, None) for t in (10.0, 100.0)])
    actual = np.max(np.abs(ref.y - exact), axis=1)
    assert np.all(actual <= ref.error + 8 * EPS * np.max(np.abs(exact), axis=1))
    assert ref.error[-1, 0] > 1e-13  # the float64 reference alone is not good enough here
    # and the error estimate is sharp: within 10 % of the actual error where it dominates
    np.testing.assert_allclose(ref.error[-1], actual[-1], rtol=0.1)


def test_required_error_escalates_levels_on_a_chaotic_orbit():
    """On the chaotic Hénon-Heiles orbit long double is ~1e-12 off at t = 200; asking for 1e-15
    must escalate to real128 (certified by 192-bit arithmetic)."""
    problem = get_problem("henon-heiles-chaotic")
    loose = gt.reference(problem, 200.0, required_error=1e-9)
    assert loose.max_error > 1e-15
    if "real128" not in gt.available_levels():
        pytest.skip("this heyoka build has no real128 and no multiprecision support")
    tight = gt.reference(problem, 200.0, required_error=1e-15)
    assert (tight.precision, tight.certified_by) == ("real128", "real192")
    assert tight.max_error <= 1e-15
    assert np.max(np.abs(tight.y - loose.y)) <= loose.max_error + tight.max_error


def test_unreachable_required_error_raises():
    with pytest.raises(ReferenceError_, match=r"cannot meet `required_error` = 1e-30.*best certified error"):
        gt.reference("kepler-elliptic", 1.0, required_error=1e-30)


def test_cache_round_trip_and_corrupt_file_recovery(tmp_path, monkeypatch):
    monkeypatch.setattr(gt.disk, "references_dir", lambda: tmp_path)
    problem = get_problem("harmonic")
    y0 = problem.ensemble(3, seed=11)
    first = gt.reference(problem, [1.0, 2.0], y0)
    assert not first.cached
    files = list(tmp_path.glob("harmonic-*.npz"))
    assert len(files) == 1
    second = gt.reference(problem, [1.0, 2.0], y0)
    assert second.cached
    np.testing.assert_array_equal(second.y, first.y)
    np.testing.assert_array_equal(second.error, first.error)
    assert second.certified_by == first.certified_by
    # other inputs are other keys
    other = gt.reference(problem, [1.0, 2.0], y0 * 1.5)
    assert not other.cached
    # a corrupt file is ignored and recomputed
    files[0].write_bytes(b"not an npz file")
    third = gt.reference(problem, [1.0, 2.0], y0)
    assert not third.cached
    np.testing.assert_array_equal(third.y, first.y)
    assert gt.reference(problem, [1.0, 2.0], y0).cached
    assert not list(tmp_path.glob("*.tmp"))


def test_integrator_is_built_once_per_problem_and_level():
    problem = get_problem("gaussian")
    gt.reference(problem, 1.0)
    built = len(gt.integrators)
    gt.reference(problem, [0.5, 2.0, 3.0], problem.ensemble(5, seed=3))
    assert len(gt.integrators) == built


def test_times_equal_to_t0_return_the_initial_state_exactly():
    problem = get_problem("kepler-circular")
    y0 = problem.ensemble(2)
    ref = gt.reference(problem, [0.0, 1.0], y0)
    np.testing.assert_array_equal(ref.y[0], y0)
    assert np.all(ref.error[0] == 0.0)


def test_blow_up_is_a_clear_error():
    y = hy.make_vars("y")
    problem = Problem(
        "riccati-blow-up", variables=[y], rhs=[y * y], y0=[1.0], t_span=(0.0, 2.0), reference="test"
    )
    with pytest.raises(ReferenceError_, match=r"problem 'riccati-blow-up' failed .* at t = (1|0\.9999)"):
        gt.reference(problem, [0.5, 2.0])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"times": [2.0, 1.0]}, r"`times` must be strictly increasing"),
        ({"times": [-1.0, 1.0]}, r"`times` must be >= t0"),
        ({"times": [np.nan]}, r"`times` must be finite"),
        ({"times": [[1.0, 2.0]]}, r"`times` must be a number or a non-empty 1-D array"),
        ({"times": 1.0, "y0": [1.0, np.nan]}, r"`y0` must be finite"),
        ({"times": 1.0, "y0": [1.0, 0.0, 0.0]}, r"`y0` must have shape \(2,\)"),
        ({"times": 1.0, "required_error": -1e-3}, r"`required_error` must be a positive finite number"),
        ({"times": 1.0, "t0": float("inf")}, r"`t0` must be finite"),
    ],
    ids=[
        "decreasing",
        "before-t0",
        "nan-time",
        "2-d-times",
        "nan-y0",
        "y0-shape",
        "negative-required",
        "inf-t0",
    ],
)
def test_bad_input_raises(kwargs, match):
    kwargs = dict(kwargs)
    times = kwargs.pop("times")
    with pytest.raises(InputError, match=match):
        gt.reference("harmonic", times, **kwargs)
