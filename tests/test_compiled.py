"""The compiled implementation (implementations/compiled.py) against the NumPy one it mirrors.

A table over every registered compiled stepper and every compatible problem: the same states to
rounding (COMPILED_AGREEMENT_ULPS of the state's scale) and the same evaluation counts. Kernels
compile into the project's cache directory (`harness.cache.cache_dir()/numba`), so the first run
on a machine pays the numba compiles (~1-2 s per kernel and problem) and later runs load them.
The compile and load times are recorded in test-artifacts/compiled_timings.json, never asserted.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import heyoka as hy
import numpy as np
import pytest

from harness.errors import IncompatibleError, InputError
from harness.problem import NewtonianForm, Problem
from harness.registry import get_problem, get_stepper, problems, steppers
from harness.stepper import check_compatible
from harness.tolerances import COMPILED_AGREEMENT_ULPS, EPS
from implementations import compiled
from implementations.compiled import (
    COMPILE_LOG,
    SUFFIX,
    UnsupportedExpression,
    compiled_variant,
    problem_module,
    translate_decomposition,
)

ROOT = Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "test-artifacts"

COMPILED = [s for s in steppers.all() if s.info.implementation == "compiled"]
PAIRS = [(s, p) for s in COMPILED for p in problems.all() if s.compatible(p)]
# A short run: 100 steps of a thousandth of the problem's convergence interval.
STEPS, FRACTION = 100, 1e-3


def _base(stepper):
    return get_stepper(stepper.info.extra["numpy_implementation"])


def _h(problem) -> float:
    return (problem.convergence_t_end - problem.t0) * FRACTION


def _assert_agree(a: np.ndarray, b: np.ndarray, what: str) -> None:
    assert np.array_equal(np.isfinite(a), np.isfinite(b)), f"{what}: non-finite entries differ"
    scale = max(1.0, float(np.max(np.abs(a[np.isfinite(a)]), initial=0.0)))
    diff = float(np.max(np.abs(np.where(np.isfinite(a), a - b, 0.0)), initial=0.0))
    assert diff <= COMPILED_AGREEMENT_ULPS * EPS * scale, (
        f"{what}: compiled and NumPy differ by {diff / (EPS * scale):.1f} ulps of the scale"
    )


@pytest.fixture(scope="module", autouse=True)
def _record_compile_log():
    yield
    if COMPILE_LOG:
        ARTIFACTS.mkdir(exist_ok=True)
        path = ARTIFACTS / "compiled_kernels.json"
        path.write_text(json.dumps(COMPILE_LOG, indent=1))


def test_the_registry_has_the_compiled_variants():
    names = {s.info.name for s in COMPILED}
    for base in ("velocity-verlet", "rk4", "leapfrog", "forest-ruth", "euler", "heun"):
        assert base + SUFFIX in names


@pytest.mark.parametrize("stepper", COMPILED, ids=lambda s: s.info.name)
def test_same_claims_and_the_same_coefficient_object(stepper):
    base = _base(stepper)
    assert stepper.info.name == base.info.name + SUFFIX
    assert stepper.info.implementation == "compiled" and base.info.implementation == "numpy"
    for field in ("family", "claimed_order", "explicit", "symplectic", "symmetric",
                  "evals_per_step", "form", "velocity_dependent", "reference"):
        assert getattr(stepper.info, field) == getattr(base.info, field), field
    # No second copy of any coefficient: the compiled stepper reads the NumPy stepper's object.
    assert stepper.coefficients is base.coefficients
    assert stepper.fingerprint() != base.fingerprint()


@pytest.mark.parametrize(
    "stepper,problem", PAIRS, ids=[f"{s.info.name}-{p.name}" for s, p in PAIRS]
)
def test_agrees_with_numpy_to_rounding(stepper, problem):
    base = _base(stepper)
    y0 = problem.ensemble(3, seed=1)
    save = [0, 1, STEPS // 2, STEPS]
    a = base.integrate(problem, h=_h(problem), n_steps=STEPS, y0=y0, save_steps=save)
    b = stepper.integrate(problem, h=_h(problem), n_steps=STEPS, y0=y0, save_steps=save)
    _assert_agree(a.y, b.y, f"{stepper.info.name} on {problem.name}")
    assert a.evals == b.evals
    assert a.finite == b.finite


@pytest.mark.parametrize("stepper", COMPILED, ids=lambda s: s.info.name)
def test_round_trip_and_single_step_agree(stepper):
    problem = get_problem("kepler-elliptic")
    h = _h(problem)
    start_a, back_a = _base(stepper).round_trip(problem, h=h, n_steps=40)
    start_b, back_b = stepper.round_trip(problem, h=h, n_steps=40)
    _assert_agree(back_a, back_b, f"{stepper.info.name} round trip")
    exact = problem.exact(problem.t0, problem.y0[:, None], problem.t0, None)
    one_a = _base(stepper).step_from_history(problem, h=h, history=[exact])
    one_b = stepper.step_from_history(problem, h=h, history=[exact])
    _assert_agree(one_a, one_b, f"{stepper.info.name} one step")


def test_member_parameters_are_passed_per_member():
    problem = get_problem("dahlquist")
    pars = np.array([[-1.0, -2.0, -0.5], [0.0, 1.0, 3.0]])
    y0 = np.ones((2, 3))
    for name in ("rk4", "euler"):
        a = get_stepper(name).integrate(problem, h=0.01, n_steps=50, y0=y0, pars=pars)
        b = get_stepper(name + SUFFIX).integrate(problem, h=0.01, n_steps=50, y0=y0, pars=pars)
        _assert_agree(a.final, b.final, f"{name} with per-member parameters")
        assert not np.allclose(b.final[:, 0], b.final[:, 1])


def test_generated_module_is_cached_in_the_project_cache_dir():
    problem = get_problem("harmonic")
    module = problem_module(problem)
    assert problem_module(problem) is module
    path = Path(module.__file__)
    from harness.cache import cache_dir

    assert path.parent == cache_dir() / "numba"
    assert "def rhs(t, y, p, out):" in path.read_text()


def _with_kepe() -> Problem:
    x, v = hy.make_vars("x", "v")
    return Problem(
        "test-kepe",
        variables=[x, v],
        newtonian=NewtonianForm(positions=(x,), velocities=(v,), acceleration=(-hy.kepE(0.1, x),)),
        y0=[0.5, 0.0],
        t_span=(0.0, 1.0),
        reference="test problem: Kepler's equation E(e, M) as a force, to exercise an operation "
        "without a compiled translation",
    )


def test_an_untranslatable_operation_makes_the_problem_incompatible():
    problem = _with_kepe()
    for stepper in COMPILED:
        assert not stepper.compatible(problem)
        with pytest.raises(IncompatibleError, match="kepE.*no compiled translation"):
            check_compatible(stepper, problem)
    assert get_stepper("velocity-verlet").compatible(problem)


@pytest.mark.parametrize(
    "entries,message",
    [
        (["x", "(u_0 +", "u_1"], "cannot parse"),
        (["x", "frobnicate(u_0)", "u_1"], "`frobnicate` has no compiled translation"),
        (["x", "(u_0 if u_0 else u_0)", "u_1"], "no compiled translation"),
        (["x", "q", "u_1"], "unknown name 'q'"),
        (["y", "u_0", "u_1"], "does not start with the variables"),
    ],
)
def test_translation_errors_name_the_entry(entries, message):
    with pytest.raises(UnsupportedExpression, match=message):
        translate_decomposition("rhs", entries, ["x"], 1, "y")


@pytest.mark.parametrize("exponent", [0.5, -0.5, 1.5, -1.5, 2.0, 3.0, 2.5, -2.5, 8.0, 1.25, 17.0])
def test_powers_match_the_library_power_to_rounding(exponent):
    source = translate_decomposition("f", ["x", f"u_0**{exponent!r}", "u_1"], ["x"], 1, "y")
    namespace: dict = {}
    exec("import math\n" + source, namespace)
    out = np.empty(1)
    for x in (0.3, 1.7, 12.5):
        namespace["f"](0.0, np.array([x]), np.empty(0), out)
        assert abs(out[0] - x**exponent) <= 4 * EPS * abs(x**exponent)
    small = (2 * exponent).is_integer() and abs(2 * exponent) <= compiled._MAX_SMALL_POWER
    assert ("**" not in source) == small


@pytest.mark.parametrize(
    "bad", ["implicit-midpoint", "stormer-verlet", "velocity-verlet@compiled"]
)
def test_compiled_variant_refuses_other_families(bad):
    with pytest.raises(InputError, match="`stepper`"):
        compiled_variant(get_stepper(bad))


_TIMING_SCRIPT = textwrap.dedent(
    """
    import json, time
    start = time.perf_counter()
    from harness.registry import get_problem, get_stepper
    problem = get_problem("kepler-elliptic")
    stepper = get_stepper("velocity-verlet@compiled")
    problem.dynamics(None, 1)
    imported = time.perf_counter()
    first = stepper.integrate(problem, h=1e-3, n_steps=10)
    loaded = time.perf_counter()
    run = stepper.integrate(problem, h=1e-3, n_steps=10**6)
    from implementations.compiled import COMPILE_LOG
    print(json.dumps({
        "imports_s": imported - start,
        "first_call_s": loaded - imported,
        "kernel": COMPILE_LOG,
        "steps_1e6_s": run.wall_s,
        "final": run.final[:, 0].tolist(),
    }))
    """
)


def test_cold_compile_and_cached_load_are_recorded(tmp_path):
    """A fresh cache directory (cold: heyoka and numba compile) and the same directory again
    (cached: both load from disk), each in a new process. Times are recorded, not asserted;
    the two processes must compute the same 10^6 velocity-Verlet steps bit for bit."""
    env = dict(os.environ, HARNESS_CACHE_DIR=str(tmp_path / "cache"))
    runs = {}
    for label in ("cold", "cached"):
        done = subprocess.run(
            [sys.executable, "-c", _TIMING_SCRIPT], cwd=ROOT, env=env, capture_output=True,
            text=True, timeout=300,
        )
        assert done.returncode == 0, done.stderr
        runs[label] = json.loads(done.stdout.strip().splitlines()[-1])
    assert runs["cold"]["kernel"][0]["source"] == "compiled"
    assert runs["cached"]["kernel"][0]["source"] == "cached"
    assert runs["cold"]["final"] == runs["cached"]["final"]
    runs["load_average"] = os.getloadavg()
    runs["bytecode_cached"] = not sys.dont_write_bytecode
    ARTIFACTS.mkdir(exist_ok=True)
    (ARTIFACTS / "compiled_timings.json").write_text(json.dumps(runs, indent=1))
    print(
        f"\nvelocity-verlet@compiled on kepler-elliptic: cold first call "
        f"{runs['cold']['first_call_s']:.2f} s, cached {runs['cached']['first_call_s']:.2f} s; "
        f"10^6 steps {runs['cached']['steps_1e6_s']:.3f} s (load average {runs['load_average'][0]:.1f})"
    )
