"""Time to accuracy tracked over commits: the warm time each stepper needs to reach an error of
1e-8 at the final time, per problem, so a regression in an implementation reads "this method now
needs 1.4x the time to reach 1e-8".

One `setup_cache` runs the work-precision experiment (quick settings, in this process, no result
cache) on the problems below; its timed columns follow the protocol of `harness.timing` (warm,
minimum of repeats), and `harness.timing.time_to_target` interpolates log-error against log-time
between the measured points. Two numbers per (stepper, problem):

- `track_time_to_1e8`: seconds;
- `track_time_to_1e8_c_steps`: the same time in steps of the C loop of the stepper's family on
  Kepler timed in the same cell (a change of machine or of its load moves both; a change of the
  stepper moves only the first).
A stepper that does not apply to the problem, or whose sweep does not reach 1e-8, is skipped
with the reason.
"""

from __future__ import annotations

import math

from ._common import skip, stepper_names

PROBLEMS = ["kepler-elliptic", "harmonic"]
TARGET = 1e-8


def _times() -> dict:
    try:
        from harness.runner import run_experiment
        from harness.timing import time_to_target

        result = run_experiment("work-precision", None, PROBLEMS, jobs=1, cache=False, quick=True,
                                progress=False, allow_empty=True)
    except Exception as exc:  # an older commit without the timing protocol or the runner
        return {"_error": f"work-precision timing: {type(exc).__name__}: {exc}"}
    rows = result.rows
    if "t_min_s" not in rows:
        return {"_error": "this commit's work-precision rows are not timed"}
    out = {}
    for (stepper, problem), g in rows.groupby(["stepper", "problem"]):
        seconds, status = time_to_target(g["t_min_s"], g["error"], TARGET)
        step = float(g["baseline_step_s"].median())
        out[f"{stepper}|{problem}"] = {"seconds": seconds, "c_steps": seconds / step, "status": status}
    return out


class TimeToAccuracy:
    params = (stepper_names(), PROBLEMS)
    param_names = ["stepper", "problem"]
    timeout = 3600

    def setup_cache(self):
        return _times()

    def setup(self, results, stepper, problem):
        if "_error" in results:
            raise skip(results["_error"])
        entry = results.get(f"{stepper}|{problem}")
        if entry is None:
            raise skip(f"{stepper} was not run on {problem} (it does not apply or failed)")
        if not math.isfinite(entry["seconds"]):
            raise skip(f"{stepper} does not reach {TARGET:g} on {problem} ({entry['status']})")
        self.entry = entry

    def track_time_to_1e8(self, results, stepper, problem):
        return self.entry["seconds"]

    track_time_to_1e8.unit = "seconds"

    def track_time_to_1e8_c_steps(self, results, stepper, problem):
        return self.entry["c_steps"]

    track_time_to_1e8_c_steps.unit = "C-baseline steps"
