"""The compiled implementation (implementations/compiled.py) against the NumPy one it mirrors.

A table over every registered compiled stepper and every compatible problem: the same states to
rounding (COMPILED_AGREEMENT_ULPS of the state's scale) and the same evaluation counts (Newton
iterations and starter steps included). Methods given only as coefficients (a user's tableau,
scheme or multistep table) get a compiled implementation that agrees too. Kernels compile into
the compiled-code directory (`harness.cache.code_dir()/numba`: the project's cache directory
unless HARNESS_CODE_CACHE_DIR names another), so the first run on a machine pays the numba
compiles (seconds per family) and later runs load them. Compile and
load times are recorded in test-artifacts/, never asserted.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from fractions import Fraction as F
from pathlib import Path

import heyoka as hy
import numpy as np
import pytest

from harness.coefficients import ButcherTableau, LinearMultistep, SplittingScheme
from harness.errors import IncompatibleError, InputError
from harness.problem import NewtonianForm, Problem
from harness.registry import get_problem, get_stepper, problems, steppers
from harness.step_loops import fastest
from harness.stepper import StepFailure, check_compatible
from harness.tolerances import COMPILED_AGREEMENT_ULPS, EPS
from implementations import FAMILY_MODULES
from implementations.compiled import (
    COLUMN_MIN,
    COMPILE_LOG,
    NOT_COMPILED,
    SUFFIX,
    UnsupportedExpression,
    compiled_variant,
    problem_functions,
)
from implementations.implicit_rk import ImplicitRungeKutta
from implementations.kernels.one_step import COLUMN_BLOCK
from implementations.multistep import LinearMultistepStepper
from implementations.native_functions import NAMES, native_function
from implementations.runge_kutta import ExplicitRungeKutta
from implementations.splitting import SplittingStepper

ROOT = Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "test-artifacts"

COMPILED = [s for s in steppers.all(variants=True) if s.info.implementation == "compiled"]
PAIRS = [(s, p) for s in COMPILED for p in problems.all() if s.compatible(p)]
# A short run: 100 steps of a thousandth of the problem's convergence interval.
STEPS, FRACTION = 100, 1e-3


def _h(problem) -> float:
    return (problem.convergence_t_end - problem.t0) * FRACTION


def _assert_agree(a: np.ndarray, b: np.ndarray, what: str, evals_per_step: float = 4.0) -> None:
    """Equal to rounding: COMPILED_AGREEMENT_ULPS of the scale for a method of up to four
    evaluations a step, and in proportion beyond (the compiled right-hand side is a translation of
    the same expression whose last bit may differ: kepler-elliptic, 100 steps of a 15-evaluation
    composition differ by 21.9 ulps, 0.015 ulps per evaluation)."""
    assert np.array_equal(np.isfinite(a), np.isfinite(b)), f"{what}: non-finite entries differ"
    scale = max(1.0, float(np.max(np.abs(a[np.isfinite(a)]), initial=0.0)))
    diff = float(np.max(np.abs(np.where(np.isfinite(a), a - b, 0.0)), initial=0.0))
    ulps = COMPILED_AGREEMENT_ULPS * max(1.0, float(evals_per_step) / 4.0)
    assert diff <= ulps * EPS * scale, (
        f"{what}: compiled and NumPy differ by {diff / (EPS * scale):.1f} ulps of the scale"
    )


def _compare(base, variant, problem, *, steps: int = STEPS, size: int = 3) -> None:
    y0 = problem.ensemble(size, seed=1)
    save = [0, 1, steps // 2, steps]
    h = _h(problem)
    try:
        a = base.integrate(problem, h=h, n_steps=steps, y0=y0, save_steps=save)
    except StepFailure as exc:
        with pytest.raises(StepFailure):
            variant.integrate(problem, h=h, n_steps=steps, y0=y0, save_steps=save)
        return exc
    b = variant.integrate(problem, h=h, n_steps=steps, y0=y0, save_steps=save)
    _assert_agree(a.y, b.y, f"{variant.info.name} on {problem.name}", base.info.evals_per_step or 4.0)
    assert a.evals == b.evals
    assert a.finite == b.finite
    return None


@pytest.fixture(scope="module", autouse=True)
def _record_compile_log():
    yield
    if COMPILE_LOG:
        ARTIFACTS.mkdir(exist_ok=True)
        path = ARTIFACTS / "compiled_kernels.json"
        path.write_text(json.dumps(COMPILE_LOG, indent=1))


# -- the registry ------------------------------------------------------------------------------------
def test_every_builtin_with_coefficients_has_a_registered_compiled_variant():
    from importlib import import_module

    builtins = [
        s
        for name in FAMILY_MODULES
        if name != "compiled"
        for s in import_module(f"implementations.{name}").STEPPERS
        if s.coefficients is not None
    ]
    assert len(builtins) >= 25
    # a family without a compiled loop says why (none today: Cowell's implicit tables have one)
    assert {get_stepper(n).info.family for n in NOT_COMPILED} <= {"second-order-multistep"}
    assert all("no compiled loop" in why for why in NOT_COMPILED.values())
    names = {s.info.name for s in COMPILED}
    for s in builtins:
        assert s.info.name + SUFFIX in names or s.info.name in NOT_COMPILED
    families = {s.info.family for s in COMPILED}
    assert {"explicit-rk", "splitting", "stormer", "multistep", "implicit-rk"} <= families


def test_every_registered_method_with_coefficients_has_a_compiled_variant():
    """Over the whole registry, variants included (`<name>@embedded`, the step-controlled
    splittings, anything added since): a NumPy stepper whose method is a record of data (a
    coefficient object or a controlled scheme) has `<name>@compiled`, which the agreement sweep
    below compares with it; only the black boxes (no record) have none."""
    from implementations.step_control import ControlledSplittingStepper

    names = set(steppers.names(variants=True))
    missing, black_boxes = [], []
    for s in steppers.all(variants=True):
        if s.info.implementation == "compiled":
            continue
        if s.coefficients is None and not isinstance(s, ControlledSplittingStepper):
            black_boxes.append(s.info.name)
        elif s.info.name + SUFFIX not in names and s.info.name not in NOT_COMPILED:
            missing.append(s.info.name)
    assert missing == []
    assert {"bogacki-shampine@embedded", "velocity-verlet+dtheta-reversible"} <= {
        s.info.extra["numpy_implementation"] for s in COMPILED
    }
    assert all(get_stepper(n).info.family in ("taylor", "external") for n in black_boxes)


@pytest.mark.parametrize("stepper", COMPILED, ids=lambda s: s.info.name)
def test_same_claims_and_the_same_coefficient_object(stepper):
    base = stepper.base
    assert get_stepper(stepper.info.extra["numpy_implementation"]) is base
    assert stepper.info.name == base.info.name + SUFFIX
    assert stepper.info.implementation == "compiled" and base.info.implementation == "numpy"
    for field in ("family", "claimed_order", "explicit", "symplectic", "symmetric",
                  "evals_per_step", "form", "velocity_dependent", "reference"):
        assert getattr(stepper.info, field) == getattr(base.info, field), field
    # No second copy of any coefficient: the compiled stepper reads the NumPy stepper's object.
    assert stepper.coefficients is base.coefficients
    assert stepper.history_length == base.history_length
    assert stepper.fingerprint() != base.fingerprint()


# -- agreement with the NumPy loops -------------------------------------------------------------------
@pytest.mark.parametrize(
    "stepper,problem", PAIRS, ids=[f"{s.info.name}-{p.name}" for s, p in PAIRS]
)
def test_agrees_with_numpy_to_rounding(stepper, problem):
    _compare(stepper.base, stepper, problem)


def test_the_sweep_covers_every_compiled_stepper_and_problem():
    assert {s.info.name for s, _ in PAIRS} == {s.info.name for s in COMPILED}
    assert {p.name for _, p in PAIRS} == {p.name for p in problems.all()}


def _round_trip_problem(stepper):
    problem = get_problem("kepler-elliptic")
    return problem if stepper.compatible(problem) else get_problem("harmonic")


@pytest.mark.parametrize("stepper", COMPILED, ids=lambda s: s.info.name)
def test_round_trip_and_single_step_agree(stepper):
    problem = _round_trip_problem(stepper)
    h = _h(problem)
    y0 = problem.ensemble(2, seed=3)
    start_a, back_a = stepper.base.round_trip(problem, h=h, n_steps=40, y0=y0)
    start_b, back_b = stepper.round_trip(problem, h=h, n_steps=40, y0=y0)
    _assert_agree(start_a, start_b, f"{stepper.info.name} start")
    _assert_agree(back_a, back_b, f"{stepper.info.name} round trip")
    # short trips too: a reversal inside the starting values of a multistep method
    for n in (1, 2):
        _, a = stepper.base.round_trip(problem, h=h, n_steps=n, y0=y0)
        _, b = stepper.round_trip(problem, h=h, n_steps=n, y0=y0)
        _assert_agree(a, b, f"{stepper.info.name} round trip of {n}")
    k = stepper.history_length
    history = [problem.exact(problem.t0 + j * h, y0, problem.t0, None) for j in range(k)]
    one_a = stepper.base.step_from_history(problem, h=h, history=history)
    one_b = stepper.step_from_history(problem, h=h, history=history)
    _assert_agree(one_a, one_b, f"{stepper.info.name} one step from history")


@pytest.mark.parametrize("name", ["rk4", "velocity-verlet", "forest-ruth", "leapfrog", "position-verlet"])
@pytest.mark.parametrize("problem_name", ["kepler-elliptic", "forced-duffing"])
def test_ensembles_run_by_the_column_kernels_agree(name, problem_name):
    """Ensembles of COLUMN_MIN members and more go through the column kernels (blocks of
    COLUMN_BLOCK members); one that spans two blocks, with a partial last block."""
    problem = get_problem(problem_name)
    stepper = get_stepper(name + SUFFIX)
    assert stepper.compatible(problem)
    for size in (COLUMN_MIN, COLUMN_BLOCK + 5):
        _compare(stepper.base, stepper, problem, steps=30, size=size)
    _, back_a = stepper.base.round_trip(problem, h=_h(problem), n_steps=20, y0=problem.ensemble(20))
    _, back_b = stepper.round_trip(problem, h=_h(problem), n_steps=20, y0=problem.ensemble(20))
    _assert_agree(back_a, back_b, f"{name} ensemble round trip")


def test_member_parameters_are_passed_per_member():
    problem = get_problem("dahlquist")
    pars = np.array([[-1.0, -2.0, -0.5], [0.0, 1.0, 3.0]])
    y0 = np.ones((2, 3))
    wide_pars = np.tile(pars, 4)  # 12 members: the column kernels
    wide_y0 = np.ones((2, 12))
    for name in ("rk4", "euler", "gauss-legendre-4", "bdf2", "ab3"):
        for P, Y in ((pars, y0), (wide_pars, wide_y0)):
            a = get_stepper(name).integrate(problem, h=0.01, n_steps=50, y0=Y, pars=P)
            b = get_stepper(name + SUFFIX).integrate(problem, h=0.01, n_steps=50, y0=Y, pars=P)
            _assert_agree(a.final, b.final, f"{name} with per-member parameters")
            assert a.evals == b.evals
            assert not np.allclose(b.final[:, 0], b.final[:, 1])


# -- methods given only as coefficients --------------------------------------------------------------
def _plugin_steppers():
    ref = "test plugin: a method given only by its coefficients"
    # Kutta's third-order family member c2 = 2/3, c3 = 2/3 (Hairer, Norsett & Wanner I, II.1).
    rk = ExplicitRungeKutta(
        ButcherTableau("plugin-rk3", [[0, 0, 0], [F(2, 3), 0, 0], [0, F(2, 3), 0]],
                       [F(1, 4), F(3, 8), F(3, 8)]),
        claimed_order=3, reference=ref,
    )
    # Two-stage Radau IIA (Hairer & Wanner II, IV.5, Table 5.5).
    radau = ImplicitRungeKutta(
        ButcherTableau("plugin-radau3", [[F(5, 12), F(-1, 12)], [F(3, 4), F(1, 4)]],
                       [F(3, 4), F(1, 4)], [F(1, 3), 1]),
        name="plugin-radau3", claimed_order=3, symplectic=False, symmetric=False,
        reference=ref, description="Radau IIA, two stages",
    )
    split = SplittingStepper(
        SplittingScheme("plugin-split", [("D", 0.25), ("K", 0.5), ("D", 0.5), ("K", 0.5), ("D", 0.25)]),
        claimed_order=2, reference=ref,
    )
    ab2 = LinearMultistepStepper(
        LinearMultistep("plugin-ab2", [0, -1, 1], [F(-1, 2), F(3, 2), 0]),
        name="plugin-ab2", claimed_order=2, reference=ref, description="AB2 again",
    )
    return [rk, radau, split, ab2]


@pytest.mark.parametrize("stepper", _plugin_steppers(), ids=lambda s: s.info.name)
def test_a_method_given_as_coefficients_gets_a_compiled_implementation(stepper):
    variant = compiled_variant(stepper)
    assert variant.info.name == stepper.info.name + SUFFIX
    problem = get_problem("kepler-elliptic")
    _compare(stepper, variant, problem)
    assert fastest(stepper, problem).info.implementation == "compiled"


def test_a_copy_of_a_builtin_runs_exactly_as_the_builtin():
    builtin = get_stepper("ab2@compiled")
    copy = compiled_variant(_plugin_steppers()[3])
    problem = get_problem("harmonic")
    a = builtin.integrate(problem, h=0.01, n_steps=200)
    b = copy.integrate(problem, h=0.01, n_steps=200)
    assert np.array_equal(a.y, b.y) and a.evals == b.evals


@pytest.mark.parametrize("name", ["ab2", "ab3", "ab4", "rk4", "bogacki-shampine"])
@pytest.mark.parametrize("size", [1, 3])
def test_a_blow_up_turns_non_finite_at_the_same_step_in_both(name, size):
    """Far outside the stability region the state overflows: the compiled loop (one member, or
    the ensemble) turns non-finite at the same step as the NumPy loop (states saved at every
    step), and run on in one call past the blow-up it ends in the same state with the same
    evaluation counts (a multistep method evaluates nothing once its newest state is not finite)."""
    problem = get_problem("dahlquist")
    stepper = get_stepper(name + SUFFIX)
    steps = 300
    y0 = problem.y0[:, None].copy() if size == 1 else problem.ensemble(size, seed=1)
    for save in (list(range(steps + 1)), [0, steps]):
        with np.errstate(all="ignore"):
            a = stepper.base.integrate(problem, h=30.0, n_steps=steps, y0=y0, save_steps=save)
            b = stepper.integrate(problem, h=30.0, n_steps=steps, y0=y0, save_steps=save)
        finite_a = np.isfinite(a.y)
        assert not finite_a[-1].any(), "the test needs a blow-up within the run"
        assert np.array_equal(finite_a, np.isfinite(b.y))
        assert a.evals == b.evals and a.finite == b.finite
        before = finite_a.all(axis=(1, 2))
        _assert_agree(a.y[before], b.y[before], f"{name} before the blow-up")


@pytest.mark.parametrize("name", ["implicit-midpoint", "gauss-legendre-4", "trapezoid", "ab4", "bdf2"])
@pytest.mark.parametrize("size", [1, 3])
def test_a_non_finite_start_stays_non_finite_as_in_the_numpy_loop(name, size):
    """A start with a NaN entry: the implicit and multistep loops (one member, or the ensemble)
    turn and keep the state non-finite with the NumPy loop's evaluation counts (none for the
    implicit Runge-Kutta steps)."""
    problem = get_problem("kepler-elliptic")
    runs = []
    for stepper in (get_stepper(name), get_stepper(name + SUFFIX)):
        y0 = problem.y0[:, None].copy() if size == 1 else problem.ensemble(size, seed=2)
        y0[1, 0] = np.nan
        dyn = problem.dynamics(None, size)
        with np.errstate(all="ignore"):
            c = stepper._start(dyn, problem.t0, y0, 1e-3)
            stepper._advance(dyn, c, 6)
        runs.append((stepper._observe(dyn, c), dict(dyn.counts)))
    (a, counts_a), (b, counts_b) = runs
    assert not np.isfinite(a).all()
    assert np.array_equal(np.isfinite(a), np.isfinite(b))
    _assert_agree(a, b, f"{name} from a non-finite start")
    assert counts_a == counts_b


def test_newton_failure_is_a_step_failure_in_both():
    base = get_stepper("gauss-legendre-4").with_newton(tol=0.0, max_iter=2)
    variant = compiled_variant(base)
    problem = get_problem("kepler-elliptic")
    with pytest.raises(StepFailure, match="did not converge"):
        base.integrate(problem, h=0.01, n_steps=3)
    with pytest.raises(StepFailure, match=r"gauss-legendre-4@compiled.*did not converge.*2 iteration"):
        variant.integrate(problem, h=0.01, n_steps=3)
    simplified = get_stepper("bdf2").with_newton(mode="simplified")
    _compare(simplified, compiled_variant(simplified), problem)


# -- choosing the implementation ----------------------------------------------------------------------
def _with_kepe() -> Problem:
    x, v = hy.make_vars("x", "v")
    return Problem(
        "test-kepe",
        variables=[x, v],
        newtonian=NewtonianForm(positions=(x,), velocities=(v,), acceleration=(-hy.kepE(0.1, x),)),
        y0=[0.5, 0.0],
        t_span=(0.0, 1.0),
        reference="test problem: Kepler's equation E(e, M) as a force, an operation heyoka compiles "
        "inline (an iterative solve), which no hand translation covered",
    )


def test_any_operation_heyoka_compiles_runs_compiled():
    """The kernels call heyoka's own machine code, so an operation such as kepE (solved by an
    iteration inside heyoka's code) runs compiled, and agrees with the NumPy loop."""
    problem = _with_kepe()
    for name in ("velocity-verlet", "rk4", "gauss-legendre-4"):
        _compare(get_stepper(name), get_stepper(name + SUFFIX), problem)


def test_fastest_picks_the_compiled_loop_where_it_applies():
    kepler = get_problem("kepler-elliptic")
    for name in ("rk4", "velocity-verlet", "gauss-legendre-4", "bdf2", "stormer-verlet"):
        chosen = fastest(get_stepper(name), kepler)
        assert chosen.info.implementation == "compiled"
        assert chosen.info.name == name + SUFFIX
    assert fastest(get_stepper("velocity-verlet"), _with_kepe()).info.name == "velocity-verlet" + SUFFIX
    assert fastest(get_stepper("taylor"), kepler).info.name == "taylor"  # no coefficient object
    damped = get_problem("damped-cubic")
    assert fastest(get_stepper("verlet-damped"), damped).info.name == "verlet-damped"
    assert "velocity" in get_stepper("verlet-damped@compiled").incompatibility(damped)


@pytest.mark.parametrize("bad", ["taylor", "scipy-rk45", "velocity-verlet@compiled"])
def test_compiled_variant_refuses_steppers_without_coefficients(bad):
    with pytest.raises(InputError, match="`stepper`"):
        compiled_variant(get_stepper(bad))


# -- the problems' functions: heyoka's machine code, loaded by address --------------------------------
@pytest.mark.parametrize("problem", problems.all(), ids=lambda p: p.name)
def test_every_problem_function_loads_and_is_heyokas_own(problem):
    """Every part of every registered problem loads; each function gives heyoka's own values bit
    for bit at states that are not the start (the loader checks the start): the state form on
    one point, the columns form on 11 members (whole SIMD batches and a remainder)."""
    rng = np.random.default_rng(3)
    for part in ("functions", "jacobian"):
        loaded = problem_functions(problem, part)
        assert problem_functions(problem, part) == loaded  # loaded once per process
        for name, fn in loaded.items():
            kind, form = NAMES[name]
            assert fn.address and fn is native_function(problem, name)
            size = 1 if form == "state" else 11
            y = problem.y0[:, None] * (1 + 0.01 * rng.standard_normal((problem.dim, size)))
            if kind == "accel_q":
                y = y[: len(problem.newtonian.positions)]
            y = np.ascontiguousarray(y if size > 1 else y[:, 0])
            pars = problem.pars_for(size)
            pars = np.ascontiguousarray(pars if size > 1 else pars[:, 0])
            out = np.empty((fn.nouts, size) if size > 1 else fn.nouts)
            fn(0.7, y, pars, out)
            heyoka = problem.compiled(kind, None)
            time = np.full(size, 0.7) if size > 1 else 0.7
            expected = heyoka(y, pars=pars, time=time) if heyoka.nparams else heyoka(y, time=time)
            assert np.array_equal(out, expected, equal_nan=True), (problem.name, name)


def test_the_kernels_are_cached_in_the_code_cache_dir_named_by_their_code():
    """numba's cache of the kernels lies under code_dir()/numba, in a directory named by a digest
    of every kernel module and the call intrinsics (numba's own index sees only the stamp of a
    function's file); a kernel run there leaves its index, and no problem is named in a kernel."""
    from harness.cache import code_dir
    from implementations import kernels

    assert kernels.CACHE_DIRECTORY.parent == code_dir() / "numba"
    assert kernels.CACHE_DIRECTORY == kernels.cache_directory()
    get_stepper("rk4@compiled").integrate(get_problem("harmonic"), h=0.01, n_steps=3)
    assert list(kernels.CACHE_DIRECTORY.rglob("one_step.rk_advance-*.nbi"))
    for module in kernels.MODULES:
        assert "kepler" not in Path(kernels.__file__).with_name(f"{module}.py").read_text()


def test_loader_failures_are_reasons_not_crashes():
    """Whatever keeps heyoka's code from being loaded safely is an UnsupportedExpression naming
    the function and the rule: a symbol no loaded library provides (checked before loading, since
    LLVM's linker would abort the process), a signature other than heyoka's, an object that is not
    ELF64."""
    from implementations import native_functions as nf

    with pytest.raises(UnsupportedExpression, match="calls `no_such_symbol_x`, which no library"):
        nf._resolve("no_such_symbol_x", "'p' rhs")
    nf._resolve("cos", "'p' rhs")  # libm, found
    with pytest.raises(UnsupportedExpression, match="unexpected signature"):
        nf._check_signature("define void @cfunc(ptr noalias %in_ptr, ptr %out_ptr) {", 4, "'p' rhs")
    with pytest.raises(UnsupportedExpression, match="defines no `cfunc`"):
        nf._check_signature("define void @other() {", 4, "'p' rhs")
    with pytest.raises(UnsupportedExpression, match="not ELF64"):
        nf._undefined_symbols(b"MZ" + bytes(100), "'p' rhs")
    with pytest.raises(InputError, match="`name` must be one of"):
        native_function(get_problem("harmonic"), "hessian")
    with pytest.raises(UnsupportedExpression, match="no acceleration of the positions alone"):
        native_function(get_problem("damped-cubic"), "accel")
    pendulum = get_problem("pendulum").compiled("rhs", None)
    assert nf._undefined_symbols(pendulum.llvm_states[0].object_code, "x") == ["sin"]


def test_an_unresolvable_symbol_makes_the_problem_incompatible(monkeypatch):
    from implementations import native_functions as nf

    x, v = hy.make_vars("x", "v")
    problem = Problem(
        "test-unresolved",
        variables=[x, v],
        rhs=[v, -hy.sin(x)],
        y0=[0.5, 0.0],
        t_span=(0.0, 1.0),
        reference="test problem",
    )
    real = nf._undefined_symbols
    monkeypatch.setattr(nf, "_undefined_symbols", lambda obj, what: [*real(obj, what), "no_such_symbol_y"])
    with pytest.raises(IncompatibleError, match="no_such_symbol_y"):
        check_compatible(get_stepper("rk4@compiled"), problem)
    assert get_stepper("rk4").compatible(problem)


# -- compile and load times, recorded -----------------------------------------------------------------
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
    env = dict(os.environ, HARNESS_CACHE_DIR=str(tmp_path / "cache"),
               HARNESS_CODE_CACHE_DIR=str(tmp_path / "cache"))
    runs = {}
    for label in ("cold", "cached"):
        done = subprocess.run(
            [sys.executable, "-c", _TIMING_SCRIPT], cwd=ROOT, env=env, capture_output=True,
            text=True, timeout=300,
        )
        assert done.returncode == 0, done.stderr
        runs[label] = json.loads(done.stdout.strip().splitlines()[-1])
    # the splitting kernel: compiled cold, loaded when cached (the problem's functions are
    # heyoka's, compiled by heyoka, not by numba)
    assert {r["what"] for r in runs["cold"]["kernel"]} >= {"split_advance"}
    assert {r["source"] for r in runs["cold"]["kernel"]} == {"compiled"}
    assert {r["source"] for r in runs["cached"]["kernel"]} == {"cached"}
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


@pytest.mark.parametrize("controller", ["naive", "reversible"])
def test_fastest_runs_a_step_controller_compiled_with_the_numpy_bookkeeping(controller):
    """The step-control experiment's long runs take `fastest`: the compiled controller, a subclass
    of the NumPy loop (same carry, reversal and clocks), whose run and round trip are the NumPy
    loop's to rounding, clocks included."""
    from implementations.compiled import CompiledControlledSplitting
    from implementations.step_control import ControlledSplittingStepper

    stepper = get_stepper(f"velocity-verlet+dtheta-{controller}")
    problem = get_problem("kepler-elliptic")
    runner = fastest(stepper, problem)
    assert isinstance(runner, CompiledControlledSplitting)
    assert isinstance(runner, ControlledSplittingStepper) and runner.info.implementation == "compiled"
    y0 = problem.ensemble(2, seed=5)
    a = stepper.integrate(problem, h=0.02, n_steps=3000, y0=y0, save_steps=[0, 1500, 3000])
    b = runner.integrate(problem, h=0.02, n_steps=3000, y0=y0, save_steps=[0, 1500, 3000])
    _assert_agree(a.y, b.y, runner.info.name)
    _assert_agree(a.t, b.t, runner.info.name + " clocks")
    assert a.evals == b.evals


def test_compiled_code_follows_the_code_cache_variable_and_the_cache_otherwise(tmp_path, monkeypatch):
    """Without HARNESS_CODE_CACHE_DIR compiled code lives in the cache directory; with it, there
    and not in the cache directory (cells and references stay where HARNESS_CACHE_DIR says)."""
    from harness.cache import cache_dir, code_dir
    from harness.errors import OutputError

    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path / "results-cache"))
    monkeypatch.delenv("HARNESS_CODE_CACHE_DIR", raising=False)
    assert code_dir() == cache_dir() == tmp_path / "results-cache"
    monkeypatch.setenv("HARNESS_CODE_CACHE_DIR", str(tmp_path / "code"))
    assert code_dir() == tmp_path / "code" and cache_dir() == tmp_path / "results-cache"
    (tmp_path / "blocked").write_text("a file")
    monkeypatch.setenv("HARNESS_CODE_CACHE_DIR", str(tmp_path / "blocked"))
    with pytest.raises(OutputError, match="blocked"):
        code_dir()


def test_a_compile_holds_a_lock_other_processes_wait_on(tmp_path, monkeypatch):
    """While one process compiles a kernel or module, another's attempt to take the same lock
    blocks (here: a non-blocking attempt fails), so workers started together compile once."""
    fcntl = pytest.importorskip("fcntl", reason="file locks are POSIX only; elsewhere each process compiles")
    from implementations.compiled_kernels import _compile_lock

    monkeypatch.setenv("HARNESS_CODE_CACHE_DIR", str(tmp_path))
    with _compile_lock("family_x"):
        path = tmp_path / "numba" / "family_x.lock"
        with open(path, "a") as other, pytest.raises(BlockingIOError):
            fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
    with open(path, "a") as other:  # released
        fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)


def test_fastest_never_replaces_a_changed_loop():
    """A subclass that changes the step (here: the last stage silently reuses the third) is run
    as written: its coefficients alone do not say what it computes."""
    from implementations.runge_kutta import ExplicitRungeKutta

    class Changed(ExplicitRungeKutta):
        def _step(self, dyn, c):
            super()._step(dyn, c)

    base = get_stepper("rk4")
    changed = Changed(base.coefficients, claimed_order=4, reference="a changed loop")
    problem = get_problem("harmonic")
    assert fastest(changed, problem) is changed
    assert fastest(base, problem).info.implementation == "compiled"
