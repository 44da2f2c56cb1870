"""Whole-workflow timings: the ground-truth build, cached and cold (kept apart), the gate on one
problem, and the user-facing commands end to end (`WorkflowCold`: the report and the
whole-registry gate from nothing on disk; `ReportCached`: the report with everything cached).

Cold means nothing on disk and nothing in the process: `setup` points HARNESS_CACHE_DIR at a
fresh temporary directory (heyoka's JIT cache and the reference cache live there; a
HARNESS_CODE_CACHE_DIR of the caller's is dropped, so compiled code is cold too), drops the
Taylor integrators this process built and clears heyoka's in-memory JIT cache, so the timed call
compiles (long double and real128) and integrates. Cached means the reference file exists: the
timed call only loads it.
"""

from __future__ import annotations

import os
import shutil
import tempfile

from ._common import skip

_CACHE_VARIABLES = ("HARNESS_CACHE_DIR", "HARNESS_CODE_CACHE_DIR")
GROUND_TRUTH_PROBLEMS = ["kepler-elliptic", "harmonic", "outer-solar-system"]
ENSEMBLE = 16


def _reference_inputs(problem_name: str):
    try:
        from harness.ground_truth import reference
        from harness.registry import get_problem
    except ImportError as exc:
        raise skip(str(exc)) from None
    problem = get_problem(problem_name)
    return reference, problem, problem.convergence_t_end, problem.ensemble(ENSEMBLE, seed=0)


class GroundTruthCached:
    params = (GROUND_TRUTH_PROBLEMS,)
    param_names = ["problem"]
    timeout = 600

    def setup(self, problem):
        self.reference, self.problem, self.t, self.y0 = _reference_inputs(problem)
        self.reference(self.problem, self.t, self.y0)  # computed once, then on disk

    def time_reference_cached(self, problem):
        ref = self.reference(self.problem, self.t, self.y0)
        assert ref.cached


class GroundTruthCold:
    params = (GROUND_TRUTH_PROBLEMS,)
    param_names = ["problem"]
    timeout = 900
    number = 1
    repeat = (1, 3, 120.0)
    warmup_time = 0.0

    def setup(self, problem):
        self.reference, self.problem, self.t, self.y0 = _reference_inputs(problem)
        from harness import ground_truth

        self._saved = {k: os.environ.get(k) for k in _CACHE_VARIABLES}
        self._tmp = tempfile.mkdtemp(prefix="harness-cold-")
        os.environ["HARNESS_CACHE_DIR"] = self._tmp
        os.environ.pop("HARNESS_CODE_CACHE_DIR", None)  # compiled code cold as well
        ground_truth._integrators.clear()
        import heyoka as hy

        hy.llvm_state.clear_memcache()

    def teardown(self, problem):
        for key, value in self._saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
        shutil.rmtree(self._tmp, ignore_errors=True)

    def time_reference_cold(self, problem):
        ref = self.reference(self.problem, self.t, self.y0)
        assert not ref.cached


class _Once:
    """A run of seconds to minutes: timed once, no warm-up."""

    timeout = 3600
    number = 1
    repeat = 1
    warmup_time = 0.0


class Gate(_Once):
    """The CI gate (convergence of every stepper, judged) on the harmonic oscillator, computed
    from scratch in this process with the quick settings."""

    timeout = 1800

    def setup(self):
        try:
            from harness.gate import gate_table
            from harness.runner import run_experiment
        except ImportError as exc:
            raise skip(str(exc)) from None
        self.run_experiment, self.gate_table = run_experiment, gate_table

    def time_gate_one_problem(self):
        result = self.run_experiment(
            "convergence", None, ["harmonic"], jobs=1, cache=False, quick=True, progress=False
        )
        self.gate_table(result.summary)


def _harness(args: list[str], env: dict[str, str]) -> None:
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "harness", *args], env=env, capture_output=True, text=True, timeout=3600
    )
    # A failed verdict exits non-zero with its table; only a crash (no output) is an error here.
    if done.returncode != 0 and not done.stdout.strip():
        raise RuntimeError(f"harness {' '.join(args)} failed: {done.stderr.strip()[-800:]}")


class _Workflow(_Once):
    def setup(self):
        try:
            import harness.cli  # noqa: F401
        except ImportError as exc:
            raise skip(str(exc)) from None
        self._tmp = tempfile.mkdtemp(prefix="harness-workflow-")

    def teardown(self):
        shutil.rmtree(self._tmp, ignore_errors=True)

    def _env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if k != "HARNESS_CODE_CACHE_DIR"}
        env.update(HARNESS_CACHE_DIR=os.path.join(self._tmp, "cache"),
                   HARNESS_RESULTS_DIR=os.path.join(self._tmp, "results"))
        return env  # compiled code in the same temporary cache: cold means that too

    def _report(self) -> None:
        _harness(["report", "--jobs", "1", "--output", os.path.join(self._tmp, "reports")], self._env())


class WorkflowCold(_Workflow):
    """`harness report` and the whole-registry `harness gate` from nothing on disk (fresh results
    and compiled-code caches: heyoka, numba, references), each in a new process with `--jobs 1`.
    Minutes each: run them on their own (`asv run --bench WorkflowCold`)."""

    def time_report_cold(self):
        self._report()

    def time_gate_cold(self):
        _harness(["gate", "--jobs", "1"], self._env())


class ReportCached(_Workflow):
    """`harness report` with every cell, reference and kernel cached: `setup` runs it once."""

    def setup(self):
        super().setup()
        self._report()

    def time_report_cached(self):
        self._report()
