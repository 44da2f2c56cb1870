"""pytest-benchmark micro-benchmarks: the right-hand-side evaluation the steppers pay for.

Kepler's first-order right-hand side and acceleration through `Dynamics` (heyoka's compiled
functions, counted), over 1, 10^3 and 10^5 members, and the compiled implementation's generated
function for one state. Each checks its values against -r / |r|^3 computed here with NumPy.
Disabled in the normal test run; timed by `make bench`.
"""

from __future__ import annotations

import numpy as np
import pytest

from harness.registry import get_problem
from harness.tolerances import EPS

SIZES = [1, 1_000, 100_000]


def _kepler_accel(q: np.ndarray) -> np.ndarray:
    r2 = q[0] * q[0] + q[1] * q[1]
    return -q / (r2 * np.sqrt(r2))


@pytest.fixture(scope="module")
def problem():
    return get_problem("kepler-elliptic")


@pytest.mark.parametrize("size", SIZES)
def test_rhs(benchmark, problem, size):
    y = problem.ensemble(size, seed=0)
    dyn = problem.dynamics(None, size)
    out = np.empty_like(y)
    benchmark(dyn.f, 0.0, y, out)
    assert np.array_equal(out[:2], y[2:])
    assert np.allclose(out[2:], _kepler_accel(y[:2]), rtol=8 * EPS, atol=0.0)
    assert dyn.counts["rhs"] >= 1


@pytest.mark.parametrize("size", SIZES)
def test_accel(benchmark, problem, size):
    q = np.ascontiguousarray(problem.ensemble(size, seed=0)[:2])
    dyn = problem.dynamics(None, size)
    out = np.empty_like(q)
    benchmark(dyn.accel, 0.0, q, None, out)
    assert np.allclose(out, _kepler_accel(q), rtol=8 * EPS, atol=0.0)


def test_compiled_rhs(benchmark, problem):
    compiled = pytest.importorskip("implementations.compiled")
    rhs = compiled.problem_functions(problem)["rhs"]  # heyoka's code, loaded by address
    y = problem.y0.copy()
    out = np.empty(4)
    pars = np.empty(0)
    rhs(0.0, y, pars, out)  # loaded outside the timing
    benchmark(rhs, 0.0, y, pars, out)
    assert np.array_equal(out[:2], y[2:])
    assert np.allclose(out[2:], _kepler_accel(y[:2, None])[:, 0], rtol=8 * EPS, atol=0.0)
