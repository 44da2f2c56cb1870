"""asv benchmark suites of the harness (asv.conf.json at the repository root points here).

Suites (each parameterised over the registry; `setup` raises NotImplementedError for pairs that
do not apply, which asv records as skipped):
- `bench_steppers`: one step of every stepper (single trajectory, ensembles of 10^3 and 10^5),
  peak memory of ensemble runs, and every stepper's time per trajectory-step as a ratio to the
  plain C loops of `c_baseline/` measured in the same process;
- `bench_targets`: the performance targets (ratios to C, the compiled implementation's cached
  load time);
- `bench_accuracy`: accuracy over commits: measured order, energy-drift slope, reversibility
  return error, ground-truth error;
- `bench_time_to_accuracy`: the warm time each stepper needs to reach an error of 1e-8 per
  problem (seconds, and steps of its family's C loop timed in the same cell): time to accuracy,
  not only time per step;
- `bench_workflow`: the ground-truth build (cached and cold) and the gate on one problem;
- `scaling`: time against ensemble size, step count and number of steppers (also a script).

Under asv (environment variable ASV=true) the harness's compiled-code cache is the repository's
`.cache/` (heyoka's and numba's on-disk caches), so benchmark processes load compiled code
instead of compiling it in every process; asv's own files live under `.asv/`.
"""

import os
from pathlib import Path

if os.environ.get("ASV") == "true" and "HARNESS_CACHE_DIR" not in os.environ:
    os.environ["HARNESS_CACHE_DIR"] = str(Path(__file__).resolve().parent.parent / ".cache")
