"""How cells run: cached, in parallel (local processes or a Dask cluster), each failure in its cell.

Layout (one job per module; everything public is re-exported here):

    harness/runner/__init__.py    this overview; re-exports
    harness/runner/orchestration.py  run_experiment, RunOptions
    harness/runner/several.py     run_experiments: several experiments, one display and connection
    harness/runner/checks.py      argument checks (jobs, scheduler, names, plugins, config)
    harness/runner/limits.py      a cell's time limit (SIGALRM, or an abandoned helper thread)
    harness/runner/validation.py  checking a cell's rows (validate_rows)
    harness/runner/memory.py      the memory guard (estimate_bytes, check_memory)
    harness/runner/workers.py     one cell wherever it runs (execute), claim files, orphan watch
    harness/runner/executors.py   many cells: serial, loky workers, Dask
    harness/runner/result.py      RunResult and its tables' columns
    harness/keys.py               cache keys from the import graph
    harness/store/                the only reader and writer of cell and result files

`run_experiment(name, steppers, problems, ...)` lists an experiment's cells, reuses every cell
already in the cache, runs the others, and returns a `RunResult` (rows, summary, failures, skips,
per-cell records, counts, wall time). `run_experiments(...)` does the same for several
experiments with one progress display and one Dask connection.

Cache. A cell's key (`cell_key`, harness/keys.py) hashes the cell, the experiment's resolved
configuration and a code version: the fingerprints of its stepper and problem (coefficients and
class source), the measuring source of the experiment found from its import graph (judging code
and judging thresholds left out), and the harness version. A finished cell is written to the
cache (`harness.store.CellCache`, with a checksum and its schema) the moment its result reaches
this process, so a `kill -9` loses only the cells in flight; the next run reuses the rest. A
changed method changes only its own cells' keys. `fresh=True` recomputes every cell and
overwrites its cache entry. Failed cells are not cached: they run again.

Where cells run.
- `jobs=1`: in this process, one after another.
- `jobs=N>1` (default: all cores): N local worker processes (loky, joblib's process executor,
  reused across runs). Results come back in any order; rows are put in the order of the
  experiment's cell list, so the result equals a serial run.
- `scheduler='tcp://HOST:PORT'` (or a `distributed.Client`): the same cells as Dask tasks
  (`client.submit` of `execute`, gathered with `as_completed`). Workers need the same
  environment as this process (`pip install -r requirements.txt` and this project, e.g.
  `pip install -e .`); plugin files are shipped with each task and written to the worker's temp
  directory when the worker cannot see the path. The cache stays with this process.
Each task carries the experiment object, the cell, the configuration, the plugin files and the
expected stepper/problem code version: a worker whose code differs (an older checkout on the
cluster) records the cell as failed instead of mixing results from other code into the run.

Failures stay in their cell. Each cell ends in rows or in a failure record
(`harness.experiments.base.failed_record`) of one of these kinds:
`error` (run_cell raised), `invalid` (not a DataFrame, no rows, non-scalar or complex columns,
declared dtypes or finite columns violated, not storable as Parquet; or a stepper returned a
state of the wrong shape or made NaN from a finite state: `StepperOutputError`), `timeout`, `crash` (the
worker process died: segfault, `os._exit`, out-of-memory kill), `lookup` (the stepper or problem
cannot be found or fingerprinted), `version` (a worker runs other code), `summarize` (the
experiment's summary raised; the rows are kept).

Experiments may declare (all optional):
- `row_dtypes = {"error": "float", "n_steps": "int", "verdict": "str"}`: required columns and
  their kinds (`float`, `int`, `bool`, `str`, or a tuple of them);
- `finite_columns = ("n_steps", "wall_s")`: measured columns in which NaN/inf means the cell went
  wrong (other columns may hold NaN/inf as a measurement, e.g. the error of a blow-up);
- `estimate_bytes(cell, config) -> int`: peak memory of one cell, for the memory guard.
- `exclusive = True`: its cells time themselves (`harness.timing`): they run one at a time on
  one loky worker (in this process with `jobs=1` or a Dask scheduler), never beside another.

Time limit (`cell_timeout` seconds, from the moment the cell starts):
- in a process's main thread (`jobs=1`, and every loky worker): `SIGALRM` via
  `signal.setitimer` raises `CellTimeout` (a BaseException, so `except Exception` in the cell
  cannot swallow it). It takes effect when control returns to Python, so in loky workers a
  watchdog thread also ends the worker process (`os._exit`) `HARD_TIMEOUT_GRACE_S` seconds later
  if the cell is stuck in compiled code; the pool replaces the worker and the run goes on.
- elsewhere (a Dask worker's task thread, or `jobs=1` outside the main thread): the cell runs in
  a helper thread that is abandoned at the limit; the cell is recorded as timed out, but its
  thread keeps running (Python cannot stop a thread) until it returns.

Crashes. When a loky worker dies, every cell in flight fails with it. While a worker runs a
cell it keeps a claim file holding its pid, faulthandler's traceback should a fatal signal
(SIGSEGV, SIGFPE, SIGABRT, SIGBUS, SIGILL) end it, and the watchdog's note on a hard timeout.
After the pool breaks, a claim that says why names its cell (`crash` with the fatal error, or
`timeout`) and the other cells are resubmitted; when no claim says why (`os._exit`, a SIGKILL
from the out-of-memory killer), the cells that were in flight are rerun one at a time, alone,
and the one that kills its worker again is recorded as `crash`. A Dask cluster retries a task
whose worker died and finally reports it (`KilledWorker`), which becomes a `crash` record.

Time limits, crashes and the memory guard protect the run, not the machine: `jobs=1` runs cells
in this process, so a segfault there ends the run (finished cells are in the cache).

Memory guard. Before anything runs, the runner estimates each cell's peak memory (the
experiment's `estimate_bytes` hook, else from `config['ensemble']` and the problem's dimension,
see `estimate_bytes`) and refuses, with `InputError`, a run whose `jobs` largest cells together
exceed `MEMORY_HEADROOM` of the available memory.
"""

from __future__ import annotations

from harness.keys import MEASURING_MODULES, cell_key, code_version, experiment_fingerprint  # noqa: F401
from harness.runner.checks import (  # noqa: F401  (re-exported)
    MAX_JOBS_PER_CORE,
    check_jobs,
    check_names,
    check_plugins,
    check_scheduler,
    default_jobs,
    progress_display,
    resolve_config,
    resolve_experiment,
)
from harness.runner.executors import (  # noqa: F401  (re-exported)
    DASK_CONNECT_TIMEOUT_S,
    LOKY_IDLE_TIMEOUT_S,
    MAX_CRASH_ROUNDS,
    Task,
    crash_outcome,
    dask_client,
    loky_batch,
    run_dask,
    run_loky,
    run_serial,
)
from harness.runner.limits import (  # noqa: F401  (re-exported)
    HARD_TIMEOUT_GRACE_S,
    MAX_CELL_TIMEOUT_S,
    CellTimeout,
    call_limited,
    check_timeout,
    time_limit,
)
from harness.runner.memory import (  # noqa: F401  (re-exported)
    WORK_ARRAYS,
    available_memory,
    check_memory,
    estimate_bytes,
    guard_memory,
)
from harness.runner.orchestration import (  # noqa: F401  (re-exported)
    FAILURE_KINDS,
    ExperimentError,
    NoApplicableCellsError,
    RunOptions,
    no_cells_error,
    run_experiment,
)
from harness.runner.result import (  # noqa: F401  (re-exported)
    CELL_COLUMNS,
    FAILURE_COLUMNS,
    ID_COLUMNS,
    SKIP_COLUMNS,
    RunResult,
)
from harness.runner.several import run_experiments  # noqa: F401  (re-exported)
from harness.runner.validation import SCALARS, CellOutputError, validate_rows  # noqa: F401
from harness.runner.workers import (  # noqa: F401  (re-exported)
    ORPHAN_CHECK_S,
    STALE_CLAIMS_S,
    clean_stale_claims,
    execute,
    one_line,
    plugin_spec,
    short_traceback,
)

__all__ = [
    "RunResult",
    "RunOptions",
    "run_experiment",
    "run_experiments",
    "cell_key",
    "code_version",
    "experiment_fingerprint",
    "validate_rows",
    "estimate_bytes",
    "check_memory",
    "available_memory",
    "default_jobs",
    "time_limit",
    "CellTimeout",
    "CellOutputError",
    "ExperimentError",
    "NoApplicableCellsError",
    "no_cells_error",
    "FAILURE_KINDS",
    "MEASURING_MODULES",
]
