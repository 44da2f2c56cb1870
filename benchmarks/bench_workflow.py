"""Whole-workflow timings: the ground-truth build, cached and cold (kept apart), and the gate on
one problem.

Cold means nothing on disk and nothing in the process: `setup` points HARNESS_CACHE_DIR at a
fresh temporary directory (heyoka's JIT cache and the reference cache live there), drops the
Taylor integrators this process built and clears heyoka's in-memory JIT cache, so the timed call
compiles (long double and real128) and integrates. Cached means the reference file exists: the
timed call only loads it.
"""

from __future__ import annotations

import os
import shutil
import tempfile

from ._common import skip

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

        self._saved = os.environ.get("HARNESS_CACHE_DIR")
        self._tmp = tempfile.mkdtemp(prefix="harness-cold-")
        os.environ["HARNESS_CACHE_DIR"] = self._tmp
        ground_truth._integrators.clear()
        import heyoka as hy

        hy.llvm_state.clear_memcache()

    def teardown(self, problem):
        if self._saved is None:
            os.environ.pop("HARNESS_CACHE_DIR", None)
        else:
            os.environ["HARNESS_CACHE_DIR"] = self._saved
        shutil.rmtree(self._tmp, ignore_errors=True)

    def time_reference_cold(self, problem):
        ref = self.reference(self.problem, self.t, self.y0)
        assert not ref.cached


class Gate:
    """The CI gate (convergence of every stepper, judged) on the harmonic oscillator, computed
    from scratch in this process with the quick settings."""

    timeout = 1800
    number = 1
    repeat = 1
    warmup_time = 0.0

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
