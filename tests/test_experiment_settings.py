"""Bad settings of the experiments that judge long runs, each refused in one line that names
the setting and its rule, before any cell runs (one table per experiment, one test)."""

from __future__ import annotations

import pytest

from harness.errors import InputError
from harness.experiments import get_experiment

# experiment: (a stepper the experiment applies to, [(bad setting, message pattern), ...])
BAD_SETTINGS = {
    "energy": ("velocity-verlet", [
        ({"steps": 0}, r"config `steps` must be a whole number >= 1, got 0"),
        ({"ensemble": 1.5}, r"config `ensemble` must be a whole number >= 1"),
        ({"fit_decades": -1.0}, r"config `fit_decades` must be a positive finite number"),
        ({"h": -0.1}, r"config `h` must be a positive finite number \(or unset\), got -0.1"),
        ({"perturbation": float("nan")}, r"config `perturbation` must be a positive finite number"),
    ]),
    "reversibility": ("leapfrog", [
        ({"steps": []}, r"config `steps` must be a non-empty list of whole numbers >= 1"),
        ({"steps": [100, -1]}, r"config `steps` must be a non-empty list"),
        ({"adaptive_tol": 0.0}, r"config `adaptive_tol` must be a positive finite number"),
        ({"ensemble": 0}, r"config `ensemble` must be a whole number >= 1, got 0"),
    ]),
    "symplecticity": ("leapfrog", [
        ({"states": 0}, r"config `states` must be a whole number >= 1, got 0"),
        ({"adaptive_tol": -1e-6}, r"config `adaptive_tol` must be a positive finite number"),
        ({"h": 0.0}, r"config `h` must be a positive finite number \(or unset\)"),
    ]),
    "work-precision": ("rk4", [
        ({"tolerances": []}, r"config `tolerances` must be a non-empty list of numbers in \(0, 1\)"),
        ({"tolerances": [1e-3, 2.0]}, r"config `tolerances` must be"),
        ({"work_budget": 0}, r"config `work_budget` must be a whole number >= 1, got 0"),
        ({"timing_max_repeats": 0}, r"config `timing_max_repeats` must be a whole number >= 1"),
        ({"timing_budget_s": -1.0}, r"config `timing_budget_s` must be a positive finite number"),
    ]),
}


@pytest.mark.parametrize("experiment, stepper, bad, match", [
    (experiment, stepper, bad, match)
    for experiment, (stepper, table) in BAD_SETTINGS.items()
    for bad, match in table
])
def test_bad_settings_are_refused_with_the_setting_named(experiment, stepper, bad, match):
    exp = get_experiment(experiment)
    with pytest.raises(InputError, match=match):
        exp.cells([stepper], ["harmonic"], exp.config(bad, quick=True))
