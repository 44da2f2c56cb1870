"""Newton's stopping test, rounding-aware (Hairer & Wanner, Solving ODEs II, IV.8): a
well-conditioned solve stops at NEWTON_TOL as before, a solve whose increments are rounding noise
above NEWTON_TOL (an ill-conditioned one) stops once they no longer decrease, and a divergent or
noisy-above-rounding iteration still fails; the NumPy rule and the compiled loops' rule agree.

The solves are scalar-per-component model iterations with known truth: a residual whose
evaluation carries a fixed-seed perturbation of a stated size plays the rounding noise of an
ill-conditioned residual (its increments then stall at that size, with contraction ~1).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from harness.stepper import StepFailure
from harness.tolerances import EPS, NEWTON_ROUNDING_ULPS, NEWTON_STALL_CONTRACTION, NEWTON_TOL
from implementations.implicit_rk import NewtonSettings, newton_solve, newton_stop

ROUNDING_LEVEL = NEWTON_ROUNDING_ULPS * EPS  # scaled, for an iterate of size << 1


def _solve(noise: float, gain: float = 1.0, dim: int = 5, seed: int = 0, start: float = 1.0,
           mode: str = "simplified"):
    """Newton on g(x) = gain (x - x*) + noise_k with the matrix I, from x* + start (0 - x*):
    exact in one step when noise is 0 and gain 1; gain != 1 contracts (|1 - gain| < 1) or
    diverges; noise_k fresh each call. From start = 0 (a predictor at the solution) every increment
    is noise, so the 8.10 estimate never sees a large first increment to contract from."""
    rng = np.random.default_rng(seed)
    truth = rng.uniform(-1e-3, 1e-3, (dim, 1))

    def residual(x):
        return gain * (x - truth) + noise * rng.uniform(-1.0, 1.0, x.shape)

    def matrix(x):
        return np.eye(dim)[None].repeat(x.shape[1], axis=0)

    counts: dict = {}
    x = newton_solve(residual, matrix, truth * (1.0 - start), np.ones((dim, 1)),
                     settings=NewtonSettings(mode=mode), counts=counts, stepper="model", t=0.0)
    return x, truth, counts["newton_iterations"]


def test_a_well_conditioned_solve_stops_at_the_tolerance_as_before():
    x, truth, iterations = _solve(noise=0.0, gain=0.9)  # contraction 0.1: geometric decrease
    assert np.max(np.abs(x - truth)) <= 2 * NEWTON_TOL
    # a clean geometric iteration runs on to NEWTON_TOL (or the 8.10 estimate), through the
    # rounding level where a stalled one would stop: 0.1^k from 1e-3 to ~1e-13 takes >= 9
    assert iterations >= 9


@pytest.mark.parametrize("noise", [3e-14, 1e-13, 3e-13])
def test_a_solve_stalled_at_the_rounding_level_converges(noise):
    """Increments of rounding size above NEWTON_TOL never fall below it: before the rounding-aware
    stop this was a StepFailure after NEWTON_MAX_ITER iterations; now it stops at the noise."""
    assert NEWTON_TOL < noise < ROUNDING_LEVEL / 2
    x, truth, iterations = _solve(noise=noise, start=0.0)
    assert np.max(np.abs(x - truth)) <= 2 * noise
    assert iterations <= 6


@pytest.mark.parametrize("noise, gain, start", [(1e-9, 1.0, 0.0), (0.0, 3.0, 1.0), (1e-13, 2.5, 1.0)])
def test_a_divergent_or_noisy_solve_still_fails(noise, gain, start):
    """Noise far above the rounding level (1e-9) and a diverging iteration (error x -2 or -1.5 per
    step) are not rounding: the step fails with the last increment in the message."""
    with pytest.raises(StepFailure, match="did not converge"):
        _solve(noise=noise, gain=gain, start=start)


CASES = list(itertools.product(
    [0.0, 5e-15, 2e-14, 1e-13, 1e-12, 3e-12, 1e-9, 1.0, math.inf],  # norm
    [math.inf, 1e-14, 1e-13, 2e-13, 1e-12, 1e-3],  # previous
    [NEWTON_TOL, 1e-10],  # tol
    [0.0, 0.3, 5.0],  # size of the iterate
))


def test_numpy_and_compiled_rules_agree_on_every_case():
    from implementations import kernels

    compiled = kernels.kernel("newton_converged")
    for norm, previous, tol, size in CASES:
        expected = newton_stop(norm, previous, tol, math.nan, size)
        got = compiled(norm, previous, tol, math.nan, size)
        assert bool(got[0]) == expected[0], (norm, previous, tol, size)
        assert (math.isnan(got[1]) and math.isnan(expected[1])) or got[1] == expected[1]


def test_the_stall_needs_both_no_contraction_and_rounding_size():
    level = ROUNDING_LEVEL * (1 + 0.5)
    # stalled at rounding size: converged
    assert newton_stop(level * 0.9, level * 0.9, NEWTON_TOL, math.nan, 0.5)[0]
    # still contracting fast at rounding size: iterate on (the next increment meets NEWTON_TOL)
    fast = NEWTON_STALL_CONTRACTION / 4
    assert not newton_stop(level * 0.9, level * 0.9 / fast, 1e-20, math.nan, 0.5)[0]
    # no contraction but above the rounding level: not converged
    assert not newton_stop(level * 1.1, level * 1.1, NEWTON_TOL, math.nan, 0.5)[0]
