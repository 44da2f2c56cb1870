"""Step contracts for library solvers (`StateStepper`, implicit `FunctionStepper`), the JAX path
(`harness.jax_problem`), and what a library's test suite meets: `jobs=N` with a function stepper,
float32 states, claim messages, plugin folders, refused records.

The stateful and multistep cases are small NumPy solvers written here (reversible Heun, the
leapfrog two-step rule), so the contract is tested without any library; the diffrax example
project (`test_diffrax_example.py`) is the real exam.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from harness.api import ClaimReport, FunctionStepper, StateStepper, check
from harness.errors import InputError, UnknownNameError
from harness.registry import get_problem, get_stepper, load_plugin, problems, steppers

jax = pytest.importorskip("jax", reason="the JAX path is the optional extra `jax` (pinned in "
                          "requirements.txt)")
jax.config.update("jax_enable_x64", True)


# -- the JAX path ---------------------------------------------------------------------------------
# Problems up to this dimension: the unrolled Jacobian's compile time grows as dim^2 (a 36-variable
# problem takes about a minute), and the translation is the same code for every size.
JAX_SWEEP_MAX_DIM = 4


def test_jax_functions_agree_with_heyoka_on_every_small_problem():
    from harness.jax_problem import jax_functions

    checked = []
    for name in problems.names():
        problem = get_problem(name)
        if problem.dim > JAX_SWEEP_MAX_DIM or problems.origin(name) != "builtin":
            continue  # (another test's plugin problem may be registered in this process)
        fns = jax_functions(problem)
        y = problem.ensemble(3, seed=7)
        dyn = problem.dynamics(None, 3)
        for label, want, got in [("f", dyn.f(0.37, y), fns.f(0.37, y)),
                                 ("jac", dyn.jac(0.37, y), fns.jac(0.37, y))]:
            np.testing.assert_allclose(np.asarray(got), want, rtol=1e-13, atol=1e-13,
                                       err_msg=f"{name}: {label}")
        if fns.accel is not None:
            nq = dyn.nq
            np.testing.assert_allclose(np.asarray(fns.accel(0.37, y[:nq], y[nq:])),
                                       dyn.accel(0.37, y[:nq], y[nq:]), rtol=1e-13, atol=1e-13)
        assert np.asarray(fns.y0).dtype == np.float64 and np.asarray(fns.y0)[:, 0].tolist() == \
            problem.y0.tolist()
        checked.append(name)
    assert len(checked) >= 8, checked


def test_the_jax_path_refuses_32_bit_mode_and_untranslatable_functions():
    import heyoka as hy

    from harness.jax_problem import expression_to_jax, jax_functions

    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(InputError, match="32-bit mode.*jax_enable_x64"):
            jax_functions("harmonic")
    finally:
        jax.config.update("jax_enable_x64", True)
    x, y = hy.make_vars("x", "y")
    with pytest.raises(InputError, match="cannot translate"):
        expression_to_jax(hy.select(hy.gt(x, y), x, y), ["x", "y"])


# -- small solvers with state, written against the contract -----------------------------------
def _heun_init(f, t0, y0, h):
    """Reversible Heun (Kidger et al. 2021, eq. 5): two states y and z, and f(t, z)."""
    return {"t": t0, "h": h, "y": y0, "z": y0.copy(), "fz": f(t0, y0)}


def _heun_step(f, s):
    t, h, y, z, fz = s["t"], s["h"], s["y"], s["z"], s["fz"]
    z1 = 2.0 * y - z + h * fz
    fz1 = f(t + h, z1)
    return {"t": t + h, "h": h, "y": y + 0.5 * h * (fz + fz1), "z": z1, "fz": fz1}


def _heun_reverse(s):
    return {**s, "h": -s["h"]}


def _leapfrog_init(f, t0, ys, h):
    return {"t": t0 + h, "h": h, "y": ys[1], "prev": ys[0]}


def _leapfrog_step(f, s):
    t, h = s["t"], s["h"]
    return {"t": t + h, "h": h, "y": s["prev"] + 2.0 * h * f(t, s["y"]), "prev": s["y"]}


def _leapfrog_reverse(s):  # the same two points, walked the other way
    return {**s, "h": -s["h"]}


REVERSIBLE_HEUN = StateStepper(_heun_init, _heun_step, reverse=_heun_reverse, name="test-rev-heun",
                               evals_per_step=1, reference="Kidger et al., NeurIPS 2021, eq. 5")


def test_a_stateful_reversible_solver_keeps_its_claims():
    report = check(REVERSIBLE_HEUN, ["harmonic"], order=2, symmetric=True)
    assert report.passed


def test_without_its_reverse_the_same_solver_is_measured_irreversible():
    restarted = StateStepper(_heun_init, _heun_step, name="test-rev-heun-restarted",
                             reference="Kidger et al., NeurIPS 2021, eq. 5")
    report = check(restarted, ["harmonic"], symmetric=True, raise_on_failure=False)
    assert not report.passed
    assert report.table.loc[0, "measured"] == "irreversible"


def test_a_two_step_method_runs_from_exact_starting_values():
    leapfrog = StateStepper(_leapfrog_init, _leapfrog_step, reverse=_leapfrog_reverse, history=2,
                            name="test-leapfrog", reference="HNW I, III.1 (explicit midpoint rule)")
    report = check(leapfrog, ["harmonic", "kepler-circular"], order=2)
    assert report.passed
    problem = get_problem("harmonic")
    traj = leapfrog.integrate(problem, h=0.1, n_steps=3)  # y_1 is the reference's, not a starter's
    assert traj.evals.get("starter_steps") == 1


def test_an_implicit_step_is_offered_the_jacobian_and_the_linear_solve():
    def implicit_euler(f, t, y, h, *, jac, solve):
        """Implicit Euler by Newton's method on y1 - y - h f(t + h, y1) = 0."""
        y1 = y + h * f(t, y)
        eye = np.eye(y.shape[0])[:, :, None]
        for _ in range(20):
            residual = y1 - y - h * f(t + h, y1)
            delta = solve(eye - h * jac(t + h, y1), -residual)
            y1 = y1 + delta
            if np.max(np.abs(delta)) <= 1e-15 * (1.0 + np.max(np.abs(y1))):
                break
        return y1

    stepper = FunctionStepper(implicit_euler, name="test-implicit-euler", order=1, implicit=True)
    assert not stepper.info.explicit
    assert check(stepper, ["harmonic", "gaussian"], order=1).passed


def test_a_jax_state_stepper_runs_compiled_loops():
    def init(f, t0, y0, h):
        return {"t": t0, "h": h, "y": y0}

    def step(f, s):  # classical RK4
        t, h, y = s["t"], s["h"], s["y"]
        k1 = f(t, y)
        k2 = f(t + h / 2, y + h / 2 * k1)
        k3 = f(t + h / 2, y + h / 2 * k2)
        k4 = f(t + h, y + h * k3)
        return {"t": t + h, "h": h, "y": y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)}

    rk4 = StateStepper(init, step, name="test-jax-rk4", order=4, evals_per_step=4, backend="jax",
                       reference="Kutta (1901)")
    native = get_stepper("rk4").integrate(get_problem("kepler-circular"), h=0.05, n_steps=40)
    traj = rk4.integrate(get_problem("kepler-circular"), h=0.05, n_steps=40)
    np.testing.assert_allclose(traj.final, native.final, rtol=1e-13, atol=1e-13)
    assert traj.evals["rhs"] == 160  # booked from evals_per_step: compiled calls are not counted
    assert check(rk4, ["harmonic"], order=4).passed


# -- what a stateless wrapper and the checks refuse ---------------------------------------------
def test_a_solver_with_state_given_to_a_stateless_wrapper_is_refused():
    class Solver:
        def init(self, f, t0, y0, h):
            return y0

        def step(self, f, state):
            return state

    for wrap in (lambda s: FunctionStepper(s), lambda s: check(s, ["harmonic"], order=1)):
        with pytest.raises(InputError, match="own init/step.*StateStepper"):
            wrap(Solver())


def test_a_float32_state_is_refused_with_the_reason():
    def euler32(f, t, y, h):
        return (y + h * f(t, y)).astype(np.float32)

    report = check(FunctionStepper(euler32, name="test-euler32"), ["harmonic"], order=1,
                   raise_on_failure=False)
    assert not report.passed
    assert report.failures["message"].str.contains("float32 state").all()


def test_jobs_2_runs_a_function_stepper_on_workers():
    def euler(f, t, y, h):
        return y + h * f(t, y)

    report = check(FunctionStepper(euler, name="test-euler-jobs"), ["harmonic", "pendulum"], order=1,
                   jobs=2)
    assert report.passed and report.failures.empty


def test_a_long_detail_is_wrapped_at_spaces_never_cut():
    detail = " ".join(f"word{i:03d}" for i in range(60))
    table = pd.DataFrame([{"claim": "order", "problem": "harmonic", "claimed": "2",
                           "measured": "1.0", "passed": False, "detail": detail}])
    text = str(ClaimReport("s", table, {}, pd.DataFrame()))
    words = text.split()
    assert all(f"word{i:03d}" in words for i in range(60))
    assert max(len(line) for line in text.splitlines()) <= 100


def test_the_fixture_returns_the_table_and_can_be_told_not_to_fail(integrator_claims):
    def euler(f, t, y, h):
        return y + h * f(t, y)

    report = integrator_claims(FunctionStepper(euler, name="test-euler-nofail"), ["harmonic"], order=2,
                               fail=False)
    assert not report.passed
    assert report.table.loc[0, "claimed"] == "2" and not report.table.loc[0, "passed"]


# -- plugins -----------------------------------------------------------------------------------------
def test_a_plugin_imports_a_module_from_its_own_folder(tmp_path):
    (tmp_path / "contract_helper_mod.py").write_text("ORDER = 1\n")
    (tmp_path / "plugin.py").write_text(
        "import numpy as np\nimport contract_helper_mod\nfrom harness.api import FunctionStepper\n"
        "def euler(f, t, y, h):\n    return y + h * f(t, y)\n"
        "STEPPERS = [FunctionStepper(euler, name='test-folder-euler', order=contract_helper_mod.ORDER)]\n")
    try:
        assert load_plugin(tmp_path / "plugin.py", probe=False) == ["test-folder-euler"]
        assert get_stepper("test-folder-euler").info.claimed_order == 1
    finally:
        steppers.unregister("test-folder-euler")


def test_naming_a_refused_record_says_why(tmp_path):
    (tmp_path / "records.py").write_text(
        "METHODS = [{'name': 'test-refused-rk', 'claimed_order': 2, 'reference': 'none',\n"
        "            'A': [[0, 0], [0.5, 0]], 'b': [0.5, 0.5], 'c': [0, 0.7]},\n"
        "           {'name': 'test-good-rk', 'claimed_order': 1, 'reference': 'none',\n"
        "            'A': [[0]], 'b': [1]}]\n")
    try:
        load_plugin(tmp_path / "records.py", probe=False)
        with pytest.raises(UnknownNameError, match="test-refused-rk.*refused its record.*row 1 of A"):
            get_stepper("test-refused-rk")
    finally:
        steppers.unregister("test-good-rk")


def test_jobs_2_with_an_unpicklable_stepper_is_one_clear_input_error():
    import threading

    lock = threading.Lock()

    def euler(f, t, y, h):
        with lock:
            return y + h * f(t, y)

    with pytest.raises(InputError, match="`jobs` > 1 ships.*cannot pickle"):
        check(FunctionStepper(euler, name="test-euler-lock"), ["harmonic", "pendulum"], order=1, jobs=2)


def test_the_readme_examples_of_each_contract_keep_their_claims():
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    blocks = [b for b in re.findall(r"```python\n(.*?)```", text, flags=re.S)
              if "stepper = StateStepper(" in b or "implicit=True)" in b]
    assert len(blocks) == 3, "the README shows the stateful, implicit and JAX contracts"
    for block in blocks:
        namespace = {"np": np, "StateStepper": StateStepper, "FunctionStepper": FunctionStepper}
        exec(block, namespace)
        stepper = namespace["stepper"]
        claims = {"order": stepper.info.claimed_order}
        if stepper.info.symmetric:
            claims["symmetric"] = True
        assert check(stepper, ["gaussian" if "implicit" in block else "harmonic"], **claims).passed


def test_an_adaptive_solver_gets_its_tolerance_and_books_its_internal_steps():
    from harness.api import AdaptiveStateStepper

    def init(f, t0, y0, h, *, tol):
        return {"t": t0, "h": h, "y": y0, "tol": tol, "steps": 0}

    def step(f, s):  # Euler with as many substeps as the tolerance asks (error ~ h^2 / n)
        n = int(np.ceil(abs(s["h"]) / s["tol"] ** 0.5))
        y, t, dt = s["y"], s["t"], s["h"] / n
        for _ in range(n):
            y, t = y + dt * f(t, y), t + dt
        return {**s, "t": s["t"] + s["h"], "y": y, "steps": s["steps"] + n * y.shape[1]}

    stepper = AdaptiveStateStepper(init, step, internal_steps=lambda s: s["steps"], tol=1e-4,
                                   name="test-adaptive-euler", reference="substepped Euler")
    assert stepper.info.adaptive and stepper.info.extra == {"tol": 1e-4}
    finer = stepper.with_tolerance(1e-6)
    assert finer.tol == 1e-6 and finer.info.extra == {"tol": 1e-6}
    traj = finer.integrate(get_problem("harmonic"), h=0.5, n_steps=2)
    assert traj.evals["internal_steps"] == 2 * 500  # ceil(0.5 / 1e-3) substeps per step
