"""Helpers the experiments share: settings checks, the (stepper, problem) cell table, which
problems an experiment applies to (from facts about the problem, never its name), initial
ensembles, the fixed-step plan with its command-line overrides, and the step sweep.

Which experiment applies to which problem follows from the problem's definition:
- energy: the problem declares an invariant (Hairer, Lubich & Wanner, GNI IV.1: first
  integrals);
- reversibility: q'' = a(q) (autonomous, velocity-free force: the flow is reversible under
  v -> -v, GNI V.1), or the problem is declared conservative;
- symplecticity: q'' = a(q) whose force Jacobian da/dq is symmetric after a diagonal weighting
  W (masses): a = -W^-1 grad V, whose flow preserves dq ^ W dv (GNI VI.2).

Overrides a user gives on the command line (`harness run ... --h --steps --t-end
--perturbation`) arrive as config keys `h`, `steps`, `t_end`, `perturbation` (None: derived from
the problem, `Problem.time_scale` and `Problem.ensemble_perturbation`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from harness.derived import remembered
from harness.errors import IncompatibleError, InputError
from harness.experiments.base import Cell, Skip
from harness.problem.checks import check_positive
from harness.regimes import regime_end
from harness.registry import get_problem, get_stepper
from harness.scales import fastest_times, sample_orbit, states_at
from harness.stepper import check_compatible

__all__ = [
    "check_config",
    "check_overrides",
    "problem_cells",
    "invariant_reason",
    "reversible_reason",
    "hamiltonian_reason",
    "hamiltonian_weights",
    "primary_invariant",
    "initial_ensemble",
    "perturbation_used",
    "fixed_plan",
    "long_run_steps",
    "period_states",
    "OVERRIDE_KEYS",
]

# Command-line overrides and the config key each sets (None in `default_config`: derived).
OVERRIDE_KEYS = ("h", "steps", "t_end", "perturbation")


def _is_count(v: Any, minimum: int) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | np.integer) and v >= minimum


def _is_positive(v: Any) -> bool:
    ok = not isinstance(v, bool) and isinstance(v, int | float | np.number)
    return ok and math.isfinite(float(v)) and float(v) > 0.0


def check_config(
    config: Mapping[str, Any],
    *,
    counts: Sequence[str] = (),
    count_lists: Sequence[str] = (),
    positives: Sequence[str] = (),
    name_lists: Sequence[str] = (),
    optional_positives: Sequence[str] = (),
) -> None:
    """Raise `InputError` naming the first setting that breaks its rule: `counts` are whole
    numbers >= 1, `count_lists` non-empty lists of them, `positives` finite numbers > 0,
    `name_lists` lists of strings, `optional_positives` None or finite numbers > 0.

    Parameters
    ----------
    config : mapping, the settings to check (absent keys are checked as None).
    counts, count_lists, positives, name_lists, optional_positives : sequence of str, the keys
        under each rule.
    """
    for key in counts:
        v = config.get(key)
        if not _is_count(v, 1):
            raise InputError(f"config `{key}` must be a whole number >= 1, got {v!r}")
    for key in count_lists:
        v = config.get(key)
        if (isinstance(v, str | bytes) or not isinstance(v, Sequence) or not v
                or not all(_is_count(x, 1) for x in v)):
            raise InputError(f"config `{key}` must be a non-empty list of whole numbers >= 1, got {v!r}")
    for key in positives:
        v = config.get(key)
        if not _is_positive(v):
            raise InputError(f"config `{key}` must be a positive finite number, got {v!r}")
    for key in optional_positives:
        v = config.get(key)
        if v is not None and not _is_positive(v):
            raise InputError(f"config `{key}` must be a positive finite number (or unset), got {v!r}")
    for key in name_lists:
        v = config.get(key)
        if isinstance(v, str | bytes) or not isinstance(v, Sequence) or not all(
            isinstance(x, str) and x for x in v
        ):
            raise InputError(f"config `{key}` must be a list of names, got {v!r}")


def _number(flag: str, value: Any) -> float:
    return check_positive(value, f"`{flag}`")


def _counts(flag: str, value: Any) -> list[int]:
    items = value.split(",") if isinstance(value, str) else (
        list(value) if isinstance(value, list | tuple) else [value])
    out = []
    for item in items:
        try:
            n = int(item.strip()) if isinstance(item, str) else item
        except ValueError:
            n = None
        if not _is_count(n, 1):
            raise InputError(f"`{flag}` must be whole numbers >= 1 (comma-separated), got {value!r}")
        out.append(int(n))
    return out


def check_overrides(experiment, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The command-line overrides (`h`, `steps`, `t_end`, `perturbation`; None = not given;
    numbers or their text, `steps` possibly comma-separated) as config settings of `experiment`.
    A flag the experiment has no setting for, or a value that breaks its rule, raises
    `InputError` naming the flag.

    Parameters
    ----------
    experiment : Experiment, whose `default_config` says which settings exist.
    overrides : mapping of str, the flag values by setting name.

    Returns
    -------
    dict: setting -> checked value (positive floats; `steps` as int counts, a list when the default
        is one, copied to `implicit_steps` when that setting exists).
    """
    given = {k: v for k, v in overrides.items() if v is not None}
    if "steps" in given and "t_end" in given:
        raise InputError("give `--steps` or `--t-end`, not both (the step count follows from "
                         "`--t-end` and the step size)")
    out: dict[str, Any] = {}
    for key, value in given.items():
        flag = "--" + key.replace("_", "-")
        if key not in OVERRIDE_KEYS:
            raise InputError(f"`{flag}` is not an override; known: "
                             + ", ".join("--" + k.replace("_", "-") for k in OVERRIDE_KEYS))
        if key not in experiment.default_config:
            raise InputError(f"`{flag}` does not apply to experiment {experiment.name!r} (it has no "
                             f"{key.replace('_', ' ')} setting)")
        if key != "steps":
            out[key] = _number(flag, value)
            continue
        counts = _counts(flag, value)
        if isinstance(experiment.default_config[key], list | tuple):
            out[key] = counts
        elif len(counts) != 1:
            raise InputError(f"`{flag}` takes one step count for experiment {experiment.name!r}, "
                             f"got {len(counts)}")
        else:
            out[key] = counts[0]
        # A step count given by the user holds for implicit steppers too.
        if f"implicit_{key}" in experiment.default_config:
            out[f"implicit_{key}"] = out[key]
    return out


# -- which problems an experiment applies to ---------------------------------------------------------
def invariant_reason(problem) -> str | None:
    """None when the problem declares an invariant to follow, else why not.

    Parameters
    ----------
    problem : Problem

    Returns
    -------
    str or None: the reason the problem does not apply.
    """
    if not problem.invariants:
        return f"problem {problem.name!r} declares no invariant (no conserved quantity to follow)"
    return None


def primary_invariant(problem) -> str:
    """The invariant the energy experiment follows: `energy` when declared, else the first one.

    Parameters
    ----------
    problem : Problem, one with at least one invariant.

    Returns
    -------
    str: the invariant's name.
    """
    return "energy" if "energy" in problem.invariants else sorted(problem.invariants)[0]


def _plain_newtonian(problem) -> str | None:
    if problem.newtonian is None:
        return f"problem {problem.name!r} is first-order (no acceleration q'' = a(q) declared)"
    if problem.velocity_dependent:
        return f"problem {problem.name!r} has a velocity-dependent force (its flow is not reversible)"
    if problem.time_dependent:
        return f"problem {problem.name!r} has a time-dependent force (q'' = a(q, t) is not autonomous)"
    return None


def reversible_reason(problem) -> str | None:
    """None when the problem's flow is reversible (q'' = a(q), or declared conservative).

    Parameters
    ----------
    problem : Problem, read for its force's form and its `conservative` flag.

    Returns
    -------
    str or None: why the round trip does not apply, or None.
    """
    reason = _plain_newtonian(problem)
    if reason is None or problem.conservative:
        return None
    return (f"{reason}, and it is not declared conservative: its backward flow amplifies rounding "
            "exponentially, so a round trip would measure the problem")


def hamiltonian_weights(problem, states: np.ndarray | None = None) -> np.ndarray | None:
    """Diagonal weights w (one per position, max 1) with w_i A_ij = w_j A_ji for the force
    Jacobian A = da/dq at `states` (dim, S; default: 8 states along the float64 orbit of
    `harness.scales`), or None when no such weighting exists (the force is not a weighted
    gradient). The default states' weights are derived once per problem definition and code
    version (`harness.derived`): every process that lists or measures symplecticity asks.

    Parameters
    ----------
    problem : Problem
    states : ndarray, shape (dim, S), optional, the states the Jacobian is taken at.

    Returns
    -------
    ndarray of float, shape (positions,), or None
    """
    if states is None:
        found = remembered("harness.experiments.common", "hamiltonian_weights", [problem.fingerprint()],
                           lambda: _as_list(_weights(problem, _orbit_states(problem))))
        return None if found is None else np.asarray(found, dtype=float)
    return _weights(problem, states)


def _as_list(w: np.ndarray | None) -> list[float] | None:
    return None if w is None else [float(x) for x in w]


def _orbit_states(problem) -> np.ndarray:
    orbit = sample_orbit(problem)
    return orbit.y[:, np.unique(np.linspace(0, orbit.t.size - 1, 8).round().astype(int))]


def _weights(problem, states: np.ndarray) -> np.ndarray | None:
    nq = len(problem.newtonian.positions)
    S = states.shape[1]
    jac = problem.dynamics(size=S).jac(problem.t0, np.ascontiguousarray(states))
    A = np.transpose(jac[nq:, :nq, :], (2, 0, 1))  # (S, nq, nq)
    scale = max(float(np.max(np.abs(A))), 1e-300)
    tiny = 1e-12 * scale
    log_w = np.full(nq, np.nan)
    for root in range(nq):  # each connected block of A gets its own weights
        if not np.isnan(log_w[root]):
            continue
        log_w[root] = 0.0
        stack = [root]
        while stack:
            i = stack.pop()
            for j in range(nq):
                if not np.isnan(log_w[j]):
                    continue
                a_ij, a_ji = A[:, i, j], A[:, j, i]
                k = int(np.argmax(np.abs(a_ij)))
                if abs(a_ij[k]) <= tiny or abs(a_ji[k]) <= tiny or a_ij[k] * a_ji[k] <= 0.0:
                    continue
                log_w[j] = log_w[i] + math.log(abs(a_ij[k] / a_ji[k]))
                stack.append(j)
    w = np.exp(log_w - np.max(log_w))
    WA = w[None, :, None] * A
    asym = float(np.max(np.abs(WA - np.transpose(WA, (0, 2, 1)))))
    if asym > 1e-9 * max(float(np.max(np.abs(WA))), 1e-300):
        return None
    return w


def hamiltonian_reason(problem) -> str | None:
    """None when the problem is q'' = a(q) with a weighted gradient force (see the module doc).

    Parameters
    ----------
    problem : Problem, read for its force's form and Jacobian.

    Returns
    -------
    str or None: why the symplecticity test does not apply, or None.
    """
    reason = _plain_newtonian(problem)
    if reason is not None:
        return f"{reason}: its flow preserves no symplectic form to test against"
    if hamiltonian_weights(problem) is None:
        return (f"problem {problem.name!r}: the force Jacobian da/dq is not symmetric under any "
                "diagonal (mass) weighting, so the force is not a gradient and the flow preserves "
                "no symplectic form to test against")
    return None


def period_states(problem, n: int, t_end: float | None = None) -> np.ndarray:
    """Up to n states on the orbit (dim, <= n; coinciding times taken once): the start, then
    states evenly over one natural period (or to `t_end`), and half of them (n // 2) where the
    motion is fastest (the largest Jacobian spectral radius along the span: close approaches,
    pericentres), so a map is probed
    where it differs most from the flow (`harness.scales`; float64 Taylor states, which is all
    a probe point needs).

    Parameters
    ----------
    problem : Problem
    n : int, the number of states asked for.
    t_end : float, optional, the end of the span (default one natural period after t0).

    Returns
    -------
    ndarray, shape (dim, m), m <= n
    """
    n_fast = n // 2
    n_even = n - n_fast
    span = (float(t_end) - problem.t0) if t_end is not None else problem.time_scale.period
    times = [problem.t0 + span * k / n_even for k in range(n_even)]
    if n_fast:
        times.extend(float(x) for x in fastest_times(problem, n_fast))
    return states_at(problem, np.unique(np.array(times)))


# -- the cell table -------------------------------------------------------------------------------
def problem_cells(
    experiment: str,
    steppers: Sequence[str],
    problems: Sequence[str],
    applicable: Callable[[Any], str | None],
    pair_reason: Callable[[Any, Any], str | None] | None = None,
) -> tuple[list[Cell], list[Skip]]:
    """Cells for the (stepper, problem) pairs whose problem passes `applicable(problem) -> reason
    or None`, whose pair passes `pair_reason(stepper, problem)` when given, and whose stepper can
    run the problem; every other pair becomes a `Skip` with its reason (the first that applies).

    Parameters
    ----------
    experiment : str, the experiment's name (written into each cell).
    steppers, problems : sequence of str, the registered names.
    applicable : callable, Problem -> reason or None.
    pair_reason : callable, optional, (Stepper, Problem) -> reason or None.

    Returns
    -------
    (list of Cell, list of Skip)
    """
    cells: list[Cell] = []
    skips: list[Skip] = []
    for p in problems:
        problem = get_problem(p)
        reason = applicable(problem)
        for s in steppers:
            stepper = get_stepper(s)
            why = reason if reason is not None or pair_reason is None else pair_reason(stepper, problem)
            if why is not None:
                skips.append(Skip(experiment, s, p, why))
                continue
            try:
                check_compatible(stepper, problem)
            except IncompatibleError as exc:
                skips.append(Skip(experiment, s, p, str(exc) or f"stepper {s!r} cannot run {p!r}"))
                continue
            cells.append(Cell(experiment, s, p))
    return cells, skips


def summary_per_cell(rows: pd.DataFrame, columns: Sequence[str],
                     summarize_cell: Callable[..., dict], *args: Any) -> pd.DataFrame:
    """The summary table of `rows`: one row per (stepper, problem), in the order they first
    appear, from `summarize_cell(stepper, problem_name, rows_of_that_cell, *args)`; the table
    has `columns` (and no rows when `rows` is empty).

    Parameters
    ----------
    rows : DataFrame, tidy rows with `stepper` and `problem` columns.
    columns : sequence of str, the summary's columns.
    summarize_cell : callable, (StepperInfo, problem name, rows, *args) -> dict.
    *args : passed on to `summarize_cell`.

    Returns
    -------
    DataFrame
    """
    if rows.empty:
        return pd.DataFrame(columns=columns)
    out = [summarize_cell(get_stepper(s), p, g, *args)
           for (s, p), g in rows.groupby(["stepper", "problem"], sort=False)]
    return pd.DataFrame(out, columns=columns)


# -- initial states and the fixed-step plan ------------------------------------------------------------
def perturbation_used(problem, config: Mapping[str, Any]) -> float:
    """The relative ensemble perturbation a run uses: the config's `perturbation`, else the
    problem's (declared or derived).

    Parameters
    ----------
    problem : Problem
    config : mapping, the run's settings.

    Returns
    -------
    float
    """
    given = config.get("perturbation")
    return float(given) if given is not None else float(problem.ensemble_perturbation.size)


def initial_ensemble(problem, config: Mapping[str, Any], size: int) -> np.ndarray:
    """`size` initial states of `problem` (seed and perturbation from the config).

    Parameters
    ----------
    problem : Problem
    config : mapping, the run's settings (`seed`, default 0; `perturbation`).
    size : int, the number of members.

    Returns
    -------
    ndarray, shape (dim, size)
    """
    return problem.ensemble(size, seed=int(config.get("seed", 0)), scale=config.get("perturbation"))


def fixed_plan(problem, config: Mapping[str, Any], steps: int) -> tuple[float, int]:
    """(h, n_steps) for a fixed-step run: h from the config's `h` or the problem's time scale;
    `steps` steps, or, when the config sets `t_end`, as many as reach it (h then shrinks by less
    than one step's worth so that n h is exactly the span).

    Parameters
    ----------
    problem : Problem
    config : mapping, the run's settings (`h`, `t_end`).
    steps : int, the step count when no `t_end` is set.

    Returns
    -------
    (float, int): the step size and the step count; `InputError` when `t_end` is not after t0.
    """
    h = config.get("h")
    h = float(h) if h is not None else problem.time_scale.h
    t_end = config.get("t_end")
    if t_end is None:
        return h, int(steps)
    span = float(t_end) - problem.t0
    if span <= 0.0:
        raise InputError(f"`t_end` must be after the start time {problem.t0:g} of {problem.name!r}, "
                         f"got {t_end!r}")
    n = max(1, int(math.ceil(span / h - 1e-9)))
    return span / n, n


def long_run_steps(problem, h: float, n: int) -> tuple[int, str]:
    """(n, reason): n steps of h, or fewer where the orbit would leave the dynamical regime of
    the problem's span before n h (`harness.regimes.regime_end`); reason says why ("" if not).

    Parameters
    ----------
    problem : Problem
    h : float, the step size.
    n : int, the steps asked for.

    Returns
    -------
    (int, str)
    """
    stop, why = regime_end(problem, problem.t0 + n * h)
    if not why or problem.t0 + n * h <= stop:
        return n, ""
    capped = max(1, int((stop - problem.t0) / h))
    return capped, f"run stopped after {capped} of {n} steps (t = {problem.t0 + capped * h:.6g}): {why}"
