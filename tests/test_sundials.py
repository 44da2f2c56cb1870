"""The SUNDIALS CVODE adapter (implementations/sundials_adapter.py, scikit-sundae): CVODE's BDF and
Adams methods as adaptive steppers. The adapter without scikit-sundae is tested with the other
optional adapters in tests/test_steppers.py."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from harness.ground_truth import reference
from harness.registry import get_problem, steppers

HAVE_SUNDAE = importlib.util.find_spec("sksundae") is not None
needs_sundae = pytest.mark.skipif(
    not HAVE_SUNDAE, reason="scikit-sundae is not installed (optional extra: pip install .[sundials])")


@pytest.fixture(scope="module")
def cvode():
    """The adapter's steppers, registered by default when scikit-sundae is installed."""
    from implementations import sundials_adapter

    return [s.info.name for s in sundials_adapter.STEPPERS if s.info.name in steppers.names()]


@needs_sundae
def test_loaded_as_a_plugin_both_methods_are_adaptive_outside_steppers(cvode):
    assert cvode == ["cvode-bdf", "cvode-adams"]
    for name in cvode:
        info = steppers.get(name).info
        assert info.adaptive and info.implementation == "sundials"


@needs_sundae
@pytest.mark.parametrize("name", ["cvode-bdf", "cvode-adams"])
@pytest.mark.parametrize("problem", ["kepler-elliptic", "van-der-pol-stiff"])
def test_tighter_tolerance_gives_smaller_error_and_more_work(cvode, name, problem):
    P = get_problem(problem)
    T = P.convergence_t_end
    exact = reference(P, np.array([T]), P.y0[:, None]).y[-1]
    runs = [steppers.get(name).with_tolerance(tol).integrate(P, h=T - P.t0, n_steps=1)
            for tol in (1e-5, 1e-9)]
    errors = [np.max(np.abs(r.final - exact)) for r in runs]
    assert errors[1] < 1e-2 * errors[0] and errors[1] < 1e-5
    assert runs[1].evals["rhs"] > runs[0].evals["rhs"] > 0 and runs[1].evals["internal_steps"] > 0


@needs_sundae
def test_members_are_solved_separately_and_a_failure_is_a_step_failure(cvode):
    from harness.stepper import StepFailure

    P = get_problem("kepler-elliptic")
    y0 = P.ensemble(3)
    s = steppers.get("cvode-adams").with_tolerance(1e-8)
    together = s.integrate(P, h=1.0, n_steps=2, y0=y0).final
    alone = s.integrate(P, h=1.0, n_steps=2, y0=y0[:, 1]).final[:, 0]
    assert np.array_equal(together[:, 1], alone)
    bad = y0.copy()
    bad[:2, 0] = 0.0  # the body at the attracting centre: the right-hand side is singular
    with pytest.raises(StepFailure, match="cvode-adams"):
        s.integrate(P, h=1.0, n_steps=1, y0=bad)
