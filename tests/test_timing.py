"""The timing protocol's logic on fake timers (never on wall-clock values): repeat counts and stop
reasons, warm-up excluded, ratios against the same run's baseline, the Pareto front of time and
error, time-to-target interpolation, grouping of implementations by coefficient identity, and
the runner executing an `exclusive` experiment's cells one at a time."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from harness import timing
from harness.errors import InputError
from harness.experiments.work_precision import pareto_front


class ScriptedClock:
    """A fake timer: each timed call of `fn` lasts the next scripted duration."""

    def __init__(self, durations):
        self.durations = list(durations)
        self.now = 0.0
        self.calls = 0

    def __call__(self) -> float:
        return self.now

    def run(self) -> None:  # the timed function: advances the clock by its scripted duration
        self.now += self.durations[self.calls]
        self.calls += 1


# -- repeats, spread, budget, warm-up -------------------------------------------------------------
@pytest.mark.parametrize(("durations", "settings", "expected_samples", "stop"), [
    # steady: stops at min_repeats with spread 0
    ([1.0] * 10, {"min_repeats": 3, "max_repeats": 7, "budget_s": 100}, [1.0, 1.0, 1.0], "spread"),
    # noisy then steady: the spread (median - min) / min falls to <= 5 % at the fifth run
    ([1.0, 2.0, 1.5, 1.01, 1.02, 9, 9], {"min_repeats": 3, "max_repeats": 7, "budget_s": 100},
     [1.0, 2.0, 1.5, 1.01, 1.02], "spread"),
    # never steady: max_repeats
    ([1.0, 2.0, 3.0, 4.0, 5.0], {"min_repeats": 2, "max_repeats": 4, "budget_s": 100},
     [1.0, 2.0, 3.0, 4.0], "max-repeats"),
    # a dear point: the budget ends it before min_repeats
    ([0.3, 0.31, 0.9], {"min_repeats": 3, "max_repeats": 7, "budget_s": 0.5}, [0.3, 0.31], "budget"),
    # one run over budget: timed once
    ([2.0, 1.0], {"budget_s": 0.5}, [2.0], "budget"),
])
def test_measure_repeats_until_spread_or_budget(durations, settings, expected_samples, stop):
    clock = ScriptedClock(durations)
    t = timing.measure(clock.run, clock=clock, target_spread=0.05, **settings)
    assert list(t.samples) == pytest.approx(expected_samples)
    assert t.stop == stop
    assert t.repeats == len(expected_samples)
    assert t.min_s == pytest.approx(min(expected_samples))
    assert t.median_s == pytest.approx(float(np.median(expected_samples)))


def test_warmup_runs_are_excluded_and_kept_apart():
    clock = ScriptedClock([5.0, 3.0, 1.0, 1.0, 1.0])  # compile, first call, then warm runs
    t = timing.measure(clock.run, clock=clock, warmup=2, min_repeats=3, max_repeats=5, budget_s=100)
    assert t.warmup_s == (5.0, 3.0)
    assert t.samples == (1.0, 1.0, 1.0)
    assert t.min_s == 1.0 and t.spread == 0.0


@pytest.mark.parametrize(("samples", "spread"), [
    ([1.0], math.nan), ([2.0, 3.0], 0.25), ([1.0, 1.1, 5.0], 0.1), ([4.0, 4.0, 4.0], 0.0)])
def test_relative_spread(samples, spread):
    got = timing.relative_spread(samples)
    assert (math.isnan(got) and math.isnan(spread)) or got == pytest.approx(spread)


@pytest.mark.parametrize("bad", [{"min_repeats": 0}, {"min_repeats": 4, "max_repeats": 3},
                                 {"warmup": -1}, {"max_repeats": 2.5}])
def test_measure_refuses_bad_settings(bad):
    with pytest.raises(InputError, match="repeats|warmup"):
        timing.measure(lambda: None, **bad)


# -- ratio to the baseline timed in the same run --------------------------------------------------
def test_time_points_ratio_uses_the_same_cells_baseline(monkeypatch):
    """Every timed run lasts 2 ms on the fake clock; the baseline step, timed in the same call,
    lasts 4 ns: the ratio columns follow from these two numbers and from nothing else. The
    sweep's first run (1.5 s, it compiled) is reported apart and not a sample; its second (2 ms,
    warm) is the second point's first sample, so that point is run twice more, not three times."""
    from harness.experiments.work_precision import timed_runs
    from harness.registry import get_problem, get_stepper

    class Tick:
        def __init__(self, dt):
            self.dt, self.now, self.reads = dt, 0.0, 0

        def __call__(self):  # each read after a start read moves time on by dt
            self.reads += 1
            if self.reads % 2 == 0:
                self.now += self.dt
            return self.now

    seen = {}

    def fake_baseline(family, *, clock, **protocol):
        seen["clock"] = clock
        return "C fake loop", timing.Timing((4e-9, 5e-9), "spread"), ""

    monkeypatch.setattr(timed_runs, "baseline_step", fake_baseline)  # the name it calls
    stepper, problem = get_stepper("rk4"), get_problem("harmonic")
    frame = pd.DataFrame({"n_steps": [8, 16], "h": [0.5, 0.25], "tol": [np.nan, np.nan],
                          "t_end": [4.0, 4.0], "error": [1e-3, 1e-4], "wall_s": [1.5, 2e-3]})
    clock = Tick(2e-3)
    out = timed_runs.time_points(stepper, problem, frame, {"ensemble": 1, "seed": 0}, clock=clock)
    # two clock reads per timed run: 3 + 2 runs of the compiled loop, and 3 of the NumPy loop at
    # the larger point (its warm-up run is not timed)
    assert clock.reads == 2 * (3 + 2 + 3)
    assert out["twin_implementation"].tolist() == ["", "numpy"]
    assert np.isfinite(out.loc[1, "twin_error"]) and out.loc[1, "twin_min_s"] == pytest.approx(2e-3)
    assert seen["clock"] is clock
    assert out["t_min_s"].tolist() == pytest.approx([2e-3, 2e-3])
    assert (out["t_repeats"] == timing.TIMING_MIN_REPEATS).all() and (out["t_stop"] == "spread").all()
    assert out["baseline_units"].tolist() == pytest.approx([2e-3 / 4e-9] * 2)
    assert out["per_step_ratio"].tolist() == pytest.approx([2e-3 / 8 / 4e-9, 2e-3 / 16 / 4e-9])
    assert out["first_call_s"].tolist() == [1.5, 1.5]  # the sweep's first run, reported apart
    assert (out["baseline"] == "C fake loop").all()


# -- Pareto front and time to target --------------------------------------------------------------
@pytest.mark.parametrize("seed", range(5))
def test_pareto_front_of_time_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = 40
    rows = pd.DataFrame({"problem": "p", "stepper": rng.choice(["a", "b", "c"], n),
                         "t_min_s": 10 ** rng.uniform(-5, -1, n), "error": 10 ** rng.uniform(-12, 0, n)})
    rows.loc[3, "t_min_s"] = np.nan  # an untimed point is on no front
    front = pareto_front(rows, "t_min_s")
    c, e = rows["t_min_s"].to_numpy(), rows["error"].to_numpy()
    timed = [j for j in range(n) if np.isfinite(c[j])]
    brute = {i for i in timed if not any(
        c[j] <= c[i] and e[j] <= e[i] and (c[j] < c[i] or e[j] < e[i]) for j in timed)}
    assert sorted(front["t_min_s"]) == sorted(c[list(brute)])


@pytest.mark.parametrize("order", [2.0, 4.0, 8.0])
def test_time_to_target_interpolates_a_power_law_exactly(order):
    """On error = C t^-p (a straight line in log-log) the interpolated time is exact, wherever
    the target falls between points; the points may come in any order."""
    t = np.array([1e-4, 3e-4, 1e-3, 3e-3, 1e-2])
    err = 1e-3 * (t / 1e-4) ** -order
    target = 1e-3 * (2e-3 / 1e-4) ** -order
    shuffled = np.random.default_rng(0).permutation(len(t))
    got, status = timing.time_to_target(t[shuffled], err[shuffled], target)
    assert status == "interpolated" and got == pytest.approx(2e-3, rel=1e-12)


def test_time_to_target_first_point_and_not_reached():
    assert timing.time_to_target([1.0, 2.0], [1e-9, 1e-10], 1e-8) == (1.0, "first point")
    got, status = timing.time_to_target([1.0, 2.0, np.nan], [1e-3, 1e-5, 1e-12], 1e-8)
    assert math.isnan(got) and status == "not reached"
    # the cheapest point that reaches the target decides, not a later, dearer one
    got, status = timing.time_to_target([1.0, 2.0, 4.0, 8.0], [1e-2, 1e-9, 1e-3, 1e-10], 1e-8)
    assert status == "interpolated" and 1.0 < got < 2.0
    with pytest.raises(InputError, match="target"):
        timing.time_to_target([1.0], [1.0], 0.0)


def test_time_to_target_table_ratio_to_fastest():
    rows = pd.DataFrame({
        "problem": "p", "stepper": ["fast"] * 2 + ["slow"] * 2 + ["short"] * 2,
        "t_min_s": [1.0, 10.0, 3.0, 30.0, 1.0, 2.0], "error": [1e-2, 1e-6, 1e-2, 1e-6, 1e-2, 1e-3]})
    table = timing.time_to_target_table(rows, targets=[1e-4])
    got = table.set_index("stepper")
    assert got.loc["fast", "ratio_to_fastest"] == pytest.approx(1.0)
    assert got.loc["slow", "ratio_to_fastest"] == pytest.approx(3.0)
    assert got.loc["short", "status"] == "not reached" and math.isnan(got.loc["short", "ratio_to_fastest"])
    assert (table["fastest"] == "fast").all()


# -- one method, several implementations ----------------------------------------------------------
def test_method_identity_follows_the_coefficients_not_the_name():
    """Over the registry: a compiled variant has its NumPy method's identity; two different
    coefficient objects never share one; a black box without declared coefficients has none."""
    from harness.registry import get_stepper, steppers

    ids = {}
    for name in steppers.names(variants=True):
        s = get_stepper(name)
        mid = timing.method_identity(s)
        twin = s.info.extra.get("numpy_implementation")
        if twin:
            assert mid == timing.method_identity(get_stepper(twin)), name
        elif mid is not None:
            ids.setdefault(mid, []).append(name)
        if getattr(s, "coefficients", None) is None and "declared_splitting" not in s.info.extra:
            assert mid is None, name
    fingerprints = {}
    for mid, names in ids.items():
        for n in names:
            s = get_stepper(n)
            if s.coefficients is not None:
                fingerprints.setdefault(s.coefficients.fingerprint(), set()).add(mid)
    assert all(len(v) == 1 for v in fingerprints.values())
    assert len({m for v in fingerprints.values() for m in v}) == len(fingerprints)


def test_declared_splitting_joins_the_method_it_declares():
    """A black box's declared coefficients give it the identity of the in-house method with the
    same coefficients (REBOUND's leapfrog: drift-kick-drift, as position Verlet)."""
    from harness.registry import get_stepper, steppers

    declared = [n for n in steppers.names() if "declared_splitting" in get_stepper(n).info.extra]
    if not declared:
        pytest.skip("no stepper declaring its splitting is installed (REBOUND is an optional extra)")
    inhouse = {timing.method_identity(get_stepper(n)): n for n in steppers.names()
               if getattr(get_stepper(n), "coefficients", None) is not None}
    for name in declared:
        assert timing.method_identity(get_stepper(name)) in inhouse, name


def _group_rows(errors, ids, implementations, steppers=None, times=(1.0, 3.0)):
    n = len(errors)
    return pd.DataFrame({"stepper": steppers or ["m"] * n, "implementation": implementations,
                         "method_id": ids, "problem": "p", "h": 0.1, "n_steps": 100,
                         "error": errors, "t_min_s": list(times)[:n], "rounding_level": 1e-15})


@pytest.mark.parametrize(("errors", "agree"), [
    ([1e-6, 1e-6], True),
    ([1e-6, 1e-6 * (1 + 1e-9)], True),          # a last-bits difference of a large error
    ([1e-12, 1e-12 + 2e-15], True),             # near rounding: within 64 ulps * sqrt(n)
    ([1e-6, 1.1e-6], False),                    # a different method
    ([math.inf, math.inf], True),               # both overflowed at this step: no difference
    ([math.inf, 1e-6], False),                  # one overflowed
    ([math.nan, math.nan], False),              # nothing to compare
])
def test_same_method_groups_check_errors_agree_to_rounding(errors, agree):
    groups = timing.same_method_groups(_group_rows(errors, ["id", "id"], ["compiled", "numpy"]))
    assert len(groups) == 1
    assert bool(groups.loc[0, "agree"]) is agree
    assert groups.loc[0, "time_ratios"] == "1.00 / 3.00"


def test_same_method_groups_group_by_identity_never_by_name():
    # two names, one coefficient identity: a group
    rows = _group_rows([1e-6, 1e-6], ["id", "id"], ["scipy", "compiled"], steppers=["lib-x", "own-y"])
    assert len(timing.same_method_groups(rows)) == 1
    # one name, two identities, or no identity: no group
    assert timing.same_method_groups(_group_rows([1e-6, 1e-6], ["a", "b"], ["compiled", "numpy"])).empty
    assert timing.same_method_groups(_group_rows([1e-6, 1e-6], [None, None], ["compiled", "numpy"])).empty


# -- the runner: an exclusive experiment's cells run one at a time ----------------------------------
def test_exclusive_experiment_runs_on_one_worker(monkeypatch, tmp_path):
    from toys import ToyExperiment, toy_registry

    from harness.runner import orchestration

    used = []

    def fake_loky(tasks, jobs, accept):
        used.append(jobs)
        orchestration.run_serial(tasks, accept)

    monkeypatch.setattr(orchestration, "run_loky", fake_loky)

    class Exclusive(ToyExperiment):
        name = "toy"
        exclusive = True

    with toy_registry(tmp_path) as path:
        orchestration.run_experiment(ToyExperiment(), ["toy-ok"], ["toy-decay"], jobs=2, cache=False,
                                     plugins=[path], progress=False)
        result = orchestration.run_experiment(Exclusive(), ["toy-ok"], ["toy-decay"], jobs=2,
                                              cache=False, plugins=[path], progress=False)
    assert used == [2, 1]
    assert result.failures.empty and len(result.rows) == 9


def test_work_precision_is_exclusive():
    from harness.experiments import get_experiment

    assert get_experiment("work-precision").exclusive is True


# -- the report's tables ---------------------------------------------------------------------------
def test_fastest_table_names_the_fastest_and_the_runners_up():
    from harness.experiments.work_precision.timing_section import fastest_table

    rows = pd.DataFrame({
        "problem": "p", "stepper": ["a"] * 2 + ["b"] * 2 + ["c"] * 2,
        "t_min_s": [1.0, 10.0, 2.0, 20.0, 1.0, 2.0], "error": [1e-2, 1e-6, 1e-2, 1e-6, 1e-2, 1e-3]})
    table = timing.time_to_target_table(rows, targets=[1e-4, 1e-9]).assign(time_c=1.0)
    got = fastest_table(table).set_index("target")
    assert got.loc[1e-4, "fastest"] == "a" and got.loc[1e-4, "next"] == "b 2x"
    assert got.loc[1e-4, "reached"] == "2 of 3"
    assert got.loc[1e-9, "fastest"] == "none reached it" and got.loc[1e-9, "reached"] == "0 of 3"


def test_twin_rows_and_group_summary():
    from harness.experiments.work_precision.timing_section import group_summary, twin_rows

    rows = pd.DataFrame({
        "stepper": ["m", "m", "lib"], "implementation": ["compiled", "compiled", "scipy"],
        "method_id": ["id", "id", "id"], "problem": "p", "h": [0.1, 0.05, 0.1], "n_steps": [10, 20, 10],
        "error": [1e-4, 1e-5, 1e-4], "t_min_s": [1.0, 2.0, 4.0], "rounding_level": 1e-15,
        "twin_implementation": ["numpy", "", ""], "twin_error": [1e-4, np.nan, np.nan],
        "twin_min_s": [8.0, np.nan, np.nan]})
    long = twin_rows(rows)
    assert len(long) == 4 and sorted(long["implementation"]) == ["compiled", "compiled", "numpy", "scipy"]
    groups = timing.same_method_groups(long)
    assert len(groups) == 1 and groups.loc[0, "slowest_ratio"] == pytest.approx(8.0)
    summary = group_summary(groups)
    assert summary.loc[0, "implementations"] == "m (compiled) / lib (scipy) / m (numpy)"
    assert bool(summary.loc[0, "agree"]) and summary.loc[0, "points"] == 1


@pytest.mark.parametrize(("prior", "durations", "samples", "stop"), [
    ((5.0,), [], [5.0], "budget"),                           # a dear point: not run again
    ((0.01,), [0.01, 0.01], [0.01, 0.01, 0.01], "spread"),   # a cheap one: repeated after it
])
def test_prior_warm_samples_count_first(prior, durations, samples, stop):
    clock = ScriptedClock(durations)
    t = timing.measure(clock.run, clock=clock, prior=prior, min_repeats=3, max_repeats=7, budget_s=1.0)
    assert list(t.samples) == pytest.approx(samples) and t.stop == stop
    assert clock.calls == len(durations)
