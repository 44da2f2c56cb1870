"""The performance targets, each a ratio measured within one process (never asserted).

- a compiled implementation runs Kepler velocity-Verlet steps (one trajectory, a calibrated run
  of ~10^6 steps) in at most 2x the C loop's time (`CompiledTargets.track_single`), after a
  cached compile of at most 0.5 s (`CompiledLoad.track_compiled_cached_load`, a fresh process
  loading numba's on-disk cache);
- NumPy ensemble steppers at N = 10^5 (velocity Verlet, RK4 on Kepler) take at most 1.0x the C
  loop's time per trajectory-step (`NumpyTargets.track_ensemble`);
- every family's compiled single-trajectory step (its representative method on Kepler) in at
  most 2x the C loop of the same method (`FamilyTargets.track_single_ratio`);
and, for comparison, the other method/implementation/size combinations, each against the C
loop of the same method (velocity Verlet or RK4) at the same ensemble size.
C: `c_baseline/kepler.c` compiled with `-O3` (no machine-specific flags).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from ._common import (
    FAMILY_C_LOOPS,
    STEP,
    c_baseline,
    c_family_seconds_per_step,
    c_family_state,
    c_seconds_per_step,
    lookup,
    prepared,
    skip,
    stepper_seconds_per_step,
)

_C_METHOD = {"velocity-verlet": "vv", "rk4": "rk4"}


class NumpyTargets:
    """The NumPy implementation: one trajectory, and an ensemble of 10^5 (target <= 1.0)."""

    unit = "x C loop"
    timeout = 300
    params = (["velocity-verlet", "rk4"],)
    param_names = ["method"]
    implementation = ""

    def setup(self, method):
        self.stepper, self.problem = lookup(method + self.implementation, "kepler-elliptic")
        c_baseline()

    def _ratio(self, method: str, ensemble: int) -> float:
        c_step = c_seconds_per_step(_C_METHOD[method], ensemble)
        return stepper_seconds_per_step(self.stepper, self.problem, ensemble) / c_step

    def track_single(self, method):
        return self._ratio(method, 1)

    def track_ensemble(self, method):
        return self._ratio(method, 100_000)


class CompiledTargets(NumpyTargets):
    """The compiled implementation: one trajectory (target <= 2.0), and an ensemble of 10^5."""

    implementation = "@compiled"


_LOAD_SCRIPT = """
import json, time
from harness.registry import get_problem, get_stepper
problem = get_problem("kepler-elliptic")
stepper = get_stepper(STEPPER)
stepper.integrate(problem, h=1e-3, n_steps=1)  # module generated, kernel compiled or loaded
problem.dynamics(None, 1)
print(json.dumps({"warm": True}))
"""

_TIMED_SCRIPT = """
import json, time
from harness.registry import get_problem, get_stepper
problem = get_problem("kepler-elliptic")
stepper = get_stepper(STEPPER)
problem.dynamics(None, 1)
start = time.perf_counter()
stepper.integrate(problem, h=1e-3, n_steps=1)
print(json.dumps({"first_call_s": time.perf_counter() - start}))
"""


class CompiledLoad:
    """Seconds from a new process's first call of a compiled stepper to its first step, with the
    kernel in numba's on-disk cache (module generation, import, cache load, numba's start-up)."""

    unit = "seconds"
    timeout = 300
    params = (["velocity-verlet@compiled", "rk4@compiled"],)
    param_names = ["stepper"]

    def setup(self, stepper):
        lookup(stepper, "kepler-elliptic")
        self._run(_LOAD_SCRIPT, stepper)  # warm the cache (compiles on the first run ever)

    def _run(self, script: str, stepper: str) -> dict:
        done = subprocess.run(
            [sys.executable, "-c", script.replace("STEPPER", repr(stepper))],
            capture_output=True, text=True, timeout=600, env=dict(os.environ),
        )
        if done.returncode != 0:
            raise skip(f"{stepper} did not run in a new process: {done.stderr.strip()[-500:]}")
        return json.loads(done.stdout.strip().splitlines()[-1])

    def track_compiled_cached_load(self, stepper):
        return self._run(_TIMED_SCRIPT, stepper)["first_call_s"]


class CLoops:
    """The C reference loops themselves (Kepler, `c_baseline/kepler.c`): 1000 steps of one
    trajectory, or 10 steps of 10^5 members. Their history separates a change of the machine
    from a change of the harness. The compile command (compiler, `-O3`, no machine-specific
    flags) is printed to the benchmark's stderr (`asv run --show-stderr`)."""

    params = (["vv", "rk4"], [1, 100_000])
    param_names = ["method", "ensemble"]
    timeout = 300

    def setup(self, method, ensemble):
        import sys

        from harness.registry import get_problem

        self.baseline = c_baseline()
        print(f"C baseline: {self.baseline.command} ({self.baseline.version})", file=sys.stderr)
        problem = get_problem("kepler-elliptic")
        self.y = problem.y0.copy() if ensemble == 1 else problem.ensemble(ensemble, seed=0)
        self.steps = 1000 if ensemble == 1 else 10

    def time_c_loop(self, method, ensemble):
        self.baseline.run(method, self.y, 1e-3, self.steps)


class FamilyTargets:
    """Per family: its representative method's compiled single-trajectory step on Kepler divided
    by the C loop of the same method (`_common.FAMILY_C_LOOPS`; target <= 2.0), and both loops'
    times for 1000 steps."""

    unit = "x C loop"
    timeout = 300
    params = (list(FAMILY_C_LOOPS),)
    param_names = ["family"]

    def setup(self, family):
        method, self.c_method = FAMILY_C_LOOPS[family]
        self.stepper, self.problem = lookup(method + "@compiled", "kepler-elliptic")
        self.base = c_baseline()
        self.c_state = c_family_state(self.c_method)
        self.dyn, self.carry = prepared(self.stepper, self.problem, 1)

    def track_single_ratio(self, family):
        compiled = stepper_seconds_per_step(self.stepper, self.problem, 1)
        return compiled / c_family_seconds_per_step(self.c_method)

    def time_compiled_1000_steps(self, family):
        self.stepper._advance(self.dyn, self.carry, 1000)

    def time_c_1000_steps(self, family):
        self.base.run(self.c_method, self.c_state, STEP["kepler-elliptic"], 1000)
