"""What the asv suites share: registry parameters, skip rules, prepared carries, timing, C loops.

Benchmarks run against every commit asv checks out, so a name the registry of that commit does
not know, or a harness function it does not have yet, turns into NotImplementedError (a skip),
never into a failure.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from functools import lru_cache

import numpy as np

#: The problems the per-step suites run on: Kepler (the C baseline's problem) and the harmonic
#: oscillator.
PROBLEMS = ["kepler-elliptic", "harmonic"]
ENSEMBLES = [1, 1_000, 100_000]
#: Largest ensemble each family is timed at. `external` (scipy) integrates member by member,
#: 0.3-5 ms per member-step (a step of 10^3 members takes 0.3-5 s); `taylor` (heyoka) takes
#: ~16 us per member-step, so 10^5 members cost ~1.6 s per step. Both stop below 10^5.
MAX_ENSEMBLE = {"external": 1, "taylor": 1_000}
#: Step size of the per-step suites, per problem (a few hundred steps per natural period).
STEP = {"kepler-elliptic": 1e-3, "harmonic": 1e-2}


def skip(reason: str) -> NotImplementedError:
    """A skip with its reason printed (asv shows the benchmark's stderr with -v)."""
    print(f"skipped: {reason}", file=sys.stderr)
    return NotImplementedError(reason)


@lru_cache(maxsize=1)
def stepper_names() -> list[str]:
    from harness.registry import steppers

    try:  # compiled variants are listed on request only (older commits list every entry)
        return steppers.names(variants=True)
    except TypeError:
        return steppers.names()


def lookup(stepper: str, problem: str):
    """(stepper, problem) objects, or a skip when this commit lacks either or they do not fit."""
    try:
        from harness.registry import get_problem, get_stepper

        s, p = get_stepper(stepper), get_problem(problem)
    except Exception as exc:  # an older commit: the name or the registry does not exist
        raise skip(f"{stepper} / {problem}: {exc}") from None
    if not s.compatible(p):
        raise skip(f"{stepper} does not apply to {problem}")
    return s, p


def check_ensemble(stepper, ensemble: int) -> None:
    limit = MAX_ENSEMBLE.get(stepper.info.family)
    if limit is not None and ensemble > limit:
        raise skip(f"{stepper.info.name}: family {stepper.info.family} timed up to {limit} members")


@lru_cache(maxsize=16)
def _initial(problem_name: str, ensemble: int) -> np.ndarray:
    from harness.registry import get_problem

    problem = get_problem(problem_name)
    if ensemble == 1:
        return problem.y0[:, None].copy()
    return problem.ensemble(ensemble, seed=0)


def initial_states(problem, ensemble: int) -> np.ndarray:
    """The problem's start (ensemble 1) or a perturbed ensemble, a fresh copy each call."""
    return _initial(problem.name, ensemble).copy()


def prepared(stepper, problem, ensemble: int, h: float | None = None):
    """(dyn, carry) after warm-up steps, so the next step is a steady-state step (a
    first-same-as-last force is cached, a multistep method's starting values are used up and
    its formula has run once, a compiled kernel is loaded)."""
    h = STEP.get(problem.name, 1e-3) if h is None else h
    y = initial_states(problem, ensemble)
    dyn = problem.dynamics(None, ensemble)
    with np.errstate(all="ignore"):
        carry = stepper._start(dyn, problem.t0, y, h)
        stepper._advance(dyn, carry, max(1, stepper.history_length))
    return dyn, carry


#: The clock of `seconds_per_call`: wall time by default; `HARNESS_BENCH_CLOCK=cpu` takes this
#: thread's CPU time instead, which leaves out the time other processes hold the cores (for
#: ratios measured on a loaded machine).
def _clock() -> Callable[[], float]:
    return time.thread_time if os.environ.get("HARNESS_BENCH_CLOCK") == "cpu" else time.perf_counter


def seconds_per_call(
    fn: Callable[[int], object], budget: float = 0.05, repeats: int = 3
) -> tuple[float, int]:
    """Best time of fn(n) over `repeats` runs, with n doubled until one run takes `budget`
    seconds; returns (seconds per unit of n, n)."""
    clock = _clock()
    n = 1
    while True:
        start = clock()
        fn(n)
        elapsed = clock() - start
        if elapsed >= budget or n >= 1 << 22:
            break
        n *= 2 if elapsed > budget / 10 else 8
    best = elapsed
    for _ in range(repeats - 1):
        start = clock()
        fn(n)
        best = min(best, clock() - start)
    return best / n, n


def stepper_seconds_per_step(stepper, problem, ensemble: int) -> float:
    """Wall seconds per trajectory-step of `stepper` (steady state, steps run by `_advance`)."""
    dyn, carry = prepared(stepper, problem, ensemble)

    def run(n: int) -> None:
        with np.errstate(all="ignore"):
            stepper._advance(dyn, carry, n)

    per_step, _ = seconds_per_call(run)
    return per_step / ensemble


def c_baseline():
    """The compiled C loops, or a skip with the reason (no compiler)."""
    try:
        from .c_baseline.build import CompilerUnavailable, load
    except ImportError as exc:
        raise skip(f"C baseline unavailable: {exc}") from None
    try:
        return load()
    except CompilerUnavailable as exc:
        raise skip(str(exc)) from None


def c_seconds_per_step(method: str, ensemble: int) -> float:
    """Wall seconds per trajectory-step of the C loop `method` ('vv' or 'rk4') on Kepler."""
    from harness.registry import get_problem

    base = c_baseline()
    problem = get_problem("kepler-elliptic")
    y = problem.y0.copy() if ensemble == 1 else initial_states(problem, ensemble)
    h = STEP["kepler-elliptic"]
    per_call, _ = seconds_per_call(lambda n: base.run(method, y, h, n))
    return per_call / ensemble


#: Per family: the representative method (a registered stepper; its `@compiled` variant is timed)
#: and the C loop of the same method in `c_baseline/kepler.c`.
FAMILY_C_LOOPS = {
    "explicit-rk": ("rk4", "rk4"),
    "splitting": ("velocity-verlet", "vv"),
    "staggered-leapfrog": ("leapfrog", "leapfrog"),
    "stormer": ("stormer-verlet", "stormer"),
    "multistep": ("ab4", "ab4"),
    "implicit-rk": ("implicit-midpoint", "midpoint"),
}


def c_family_state(method: str) -> np.ndarray:
    """The C loop's input for one Kepler trajectory from the problem's start: the state, the
    staggered state (x_0, v_1/2), two positions (x_0, x_1), or four exact states."""
    from harness.registry import get_problem

    problem = get_problem("kepler-elliptic")
    h = STEP["kepler-elliptic"]
    y0 = problem.y0.copy()
    if method in ("vv", "rk4", "midpoint"):
        return y0
    if method == "leapfrog":
        r3 = float(np.hypot(y0[0], y0[1])) ** 3
        return np.concatenate([y0[:2], y0[2:] - 0.5 * h * y0[:2] / r3])
    if method == "stormer":
        x1 = problem.exact(problem.t0 + h, y0[:, None], problem.t0, None)[:2, 0]
        return np.concatenate([y0[:2], x1])
    if method == "ab4":
        states = [problem.exact(problem.t0 + j * h, y0[:, None], problem.t0, None)[:, 0] for j in range(4)]
        return np.concatenate(states)
    raise ValueError(f"`method` {method!r} has no C loop")


def c_family_seconds_per_step(method: str) -> float:
    """Wall seconds per step of the single-trajectory C loop `method` on Kepler (h = 1e-3)."""
    base = c_baseline()
    s = c_family_state(method)
    h = STEP["kepler-elliptic"]
    per_call, _ = seconds_per_call(lambda n: base.run(method, s, h, n))
    return per_call
