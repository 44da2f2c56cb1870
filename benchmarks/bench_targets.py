"""The performance targets, each a ratio measured within one process (never asserted).

- a compiled implementation runs 10^6 Kepler velocity-Verlet steps in at most 2x the C loop's
  time (`track_compiled_single`), after a cached compile of at most 0.5 s
  (`track_compiled_cached_load`, a fresh process loading numba's on-disk cache);
- NumPy ensemble steppers at N = 10^5 (velocity Verlet, RK4 on Kepler) take at most 1.0x the C
  loop's time per trajectory-step (`track_numpy_ensemble`);
and, for comparison, the compiled RK4 against the C RK4 loop, single trajectory.
C: `c_baseline/kepler.c` compiled with `-O3` (no machine-specific flags).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from ._common import c_seconds_per_step, lookup, skip, stepper_seconds_per_step

_C_METHOD = {"velocity-verlet": "vv", "rk4": "rk4"}


class Targets:
    unit = "x C loop"
    timeout = 300

    params = (["velocity-verlet", "rk4"],)
    param_names = ["method"]

    def _ratio(self, stepper_name: str, method: str, ensemble: int) -> float:
        stepper, problem = lookup(stepper_name, "kepler-elliptic")
        c_step = c_seconds_per_step(_C_METHOD[method], ensemble)
        return stepper_seconds_per_step(stepper, problem, ensemble) / c_step

    def track_compiled_single(self, method):
        return self._ratio(method + "@compiled", method, 1)

    def track_numpy_single(self, method):
        return self._ratio(method, method, 1)

    def track_numpy_ensemble(self, method):
        return self._ratio(method, method, 100_000)

    def track_compiled_ensemble(self, method):
        return self._ratio(method + "@compiled", method, 100_000)


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
