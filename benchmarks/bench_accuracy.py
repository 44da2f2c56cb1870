"""Accuracy tracked over commits, beside speed: each suite runs one experiment over the whole
registry once per commit (`setup_cache`, in this process, no result cache, quick settings) and
reports one number per stepper.

- `MeasuredOrder`: the convergence order fitted on the harmonic oscillator;
- `EnergyDriftSlope`, `MaxEnergyError`: the energy-drift slope (relative energy error per unit
  time, Theil-Sen over the late decades) and the largest relative energy error on Kepler
  (e = 0.6), where the energy experiment reports them (a bounded error has no slope);
- `Reversibility`: the return error, in ulps of the state, of the longest quick round trip on
  Kepler;
- `GroundTruthError`: the certified error of the ground truth at each problem's convergence end.
A stepper the experiment skips, or that fails, or whose value is not a finite number, is skipped
here (in `setup`) with the reason.
"""

from __future__ import annotations

import math

from ._common import skip, stepper_names


def _run(experiment: str, problem: str) -> dict:
    try:
        from harness.runner import run_experiment

        result = run_experiment(
            experiment, None, [problem], jobs=1, cache=False, quick=True, progress=False
        )
    except Exception as exc:  # an older commit without the experiment or the runner
        return {"_error": f"{experiment}: {type(exc).__name__}: {exc}"}
    return {"summary": result.summary.to_dict("records")}


def _value(results: dict, stepper: str, column: str, **where) -> float:
    if "_error" in results:
        raise skip(results["_error"])
    rows = [r for r in results["summary"] if r.get("stepper") == stepper
            and all(r.get(k) == v for k, v in where.items())]
    if not rows:
        raise skip(f"no {column} for {stepper}")
    value = rows[-1].get(column)
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        raise skip(f"{column} of {stepper} is not a finite number ({rows[-1].get('verdict')})")
    return float(value)


class _PerStepper:
    """One tracked summary column per stepper; a subclass names the column and says where its
    `setup_cache` runs (asv keys the cached results by the function's place in the source, so
    suites that inherit one `setup_cache` share its run)."""

    params = (stepper_names(),)
    param_names = ["stepper"]
    timeout = 1800
    column = ""

    def setup(self, results, stepper):
        self.value = _value(results, stepper, self.column)


class MeasuredOrder(_PerStepper):
    unit = "order"
    column = "measured_order"

    def setup_cache(self):
        return _run("convergence", "harmonic")

    def track_measured_order(self, results, stepper):
        return self.value


class _EnergyOnKepler(_PerStepper):
    """The energy experiment on Kepler (e = 0.6), run once for every column read from it: asv
    shares a `setup_cache` between the suites that inherit it."""

    def setup_cache(self):
        return _run("energy", "kepler-elliptic")


class EnergyDriftSlope(_EnergyOnKepler):
    unit = "relative energy error / time"
    column = "drift_slope"

    def track_energy_drift_slope(self, results, stepper):
        return self.value


class MaxEnergyError(_EnergyOnKepler):
    unit = "relative energy error"
    column = "max_rel_energy_error"

    def track_max_energy_error(self, results, stepper):
        return self.value


class Reversibility(_PerStepper):
    unit = "ulps"
    column = "return_error_ulps"

    def setup_cache(self):
        results = _run("reversibility", "kepler-elliptic")
        if "summary" in results:
            longest = max((r["steps"] for r in results["summary"]), default=None)
            results["summary"] = [r for r in results["summary"] if r["steps"] == longest]
        return results

    def track_return_error(self, results, stepper):
        return self.value


def _problem_names() -> list[str]:
    from harness.registry import problems

    return problems.names()


class GroundTruthError:
    params = (_problem_names(),)
    param_names = ["problem"]
    unit = "certified absolute error"
    timeout = 600

    def setup(self, problem):
        try:
            from harness.ground_truth import reference
            from harness.registry import get_problem
        except ImportError as exc:
            raise skip(str(exc)) from None
        p = get_problem(problem)
        self.ref = reference(p, p.convergence_t_end, p.ensemble(16, seed=0))

    def track_reference_error(self, problem):
        return self.ref.max_error
