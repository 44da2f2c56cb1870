"""What to measure: the contract every experiment follows.

Contract for an experiment (a subclass of `Experiment`, registered in `EXPERIMENTS`):
1. `name` is its CLI name (`harness run NAME`); an experiment that is a folder (its class defined in
   a package's `__init__`) is named after the folder (`step_control` -> `step-control`) unless
   the class sets one.
2. `cells(steppers, problems, config)` lists the independent units of work (one per stepper x
   problem x parameters); a pair that does not apply is not a cell but a `Skip` with its reason.
3. `run_cell(cell, config)` computes one cell and returns tidy rows (a DataFrame, one row per
   measured point) — plain data only, so it can run in another process or on a Dask worker. It
   looks steppers and problems up by name in the registry; it must not depend on other cells.
4. `summarize(rows, config)` turns all rows into one record per cell (a DataFrame) with at least
   the columns the CLI's JSON promises, including `verdict` and `passed` where the experiment
   judges a claim.
5. Failures stay in their cell: the runner turns an exception in `run_cell` into a failed-cell
   record (`harness.experiments.base.failed_record`), and the run goes on.
6. `section` names its report section, a `harness.kit.SectionSpec` (title, intro, the function
   that draws it from the saved run, its scoreboard columns): the one way a section is
   registered. An experiment folder's is the `SECTION` its `__init__` exports (from its
   `section.py`) unless the class sets one; None: the report shows the summary as one generic
   table.

A built-in experiment is one folder, `harness/experiments/<name>/`: `__init__.py` measures (the
`Experiment` subclass, registered), `section.py` presents (its `SECTION`, over the presentation
kit `harness.kit`), `figures.py` draws, and `judge.py` holds verdict code that is not a rule of
`harness.rules`; the modules that only judge or present are never part of a cell's cache key
(`harness.code_versions.PRESENTING_PARTS`).

Experiments come in through the entry-point group `harness.experiments`, as steppers and
problems do (`load_experiments`): this project's own entry is the built-in list
(`harness.experiments.builtin_experiments`), another distribution's entry names an `Experiment`
instance, a subclass, or a callable returning one or a list of them.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import sys
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import pandas as pd

from harness.errors import UnknownNameError
from harness.registry import expand, group_entry_points, missing_builtins

if TYPE_CHECKING:
    from harness.kit.section import SectionSpec

__all__ = [
    "Cell",
    "Skip",
    "Experiment",
    "EXPERIMENTS",
    "register_experiment",
    "get_experiment",
    "load_experiments",
    "failed_record",
    "ENTRY_POINT_EXPERIMENTS",
    "EXPERIMENT_ERRORS",
]


@dataclass(frozen=True)
class Cell:
    """One independent unit of work of an experiment."""

    experiment: str
    stepper: str
    problem: str
    params: tuple[tuple[str, Any], ...] = ()

    @property
    def label(self) -> str:
        extra = ",".join(f"{k}={v}" for k, v in self.params)
        return f"{self.experiment}:{self.stepper}:{self.problem}" + (f"[{extra}]" if extra else "")

    def param(self, key: str, default: Any = None) -> Any:
        """The value of one of the cell's parameters.

        Parameters
        ----------
        key : str, the parameter's name.
        default : Any, optional, returned when the cell has no such parameter (default None).

        Returns
        -------
        Any: the value, or `default`.
        """
        return dict(self.params).get(key, default)

    def key(self, code_version: str, config: Mapping[str, Any]) -> str:
        """Cache key: the cell, the experiment's configuration, and the code of its stepper and
        problem (`code_version`, from their fingerprints).

        Parameters
        ----------
        code_version : str, the hash of the stepper's and problem's code.
        config : mapping, the experiment's settings (values without a JSON form enter by `repr`).

        Returns
        -------
        str: 32 hex digits of a SHA-256.
        """
        blob = json.dumps(
            {"cell": [self.experiment, self.stepper, self.problem, list(self.params)],
             "config": config, "code": code_version},
            sort_keys=True,
            default=repr,
        )
        return hashlib.sha256(blob.encode()).hexdigest()[:32]


@dataclass(frozen=True)
class Skip:
    """A stepper x problem pair an experiment does not apply to, and why."""

    experiment: str
    stepper: str
    problem: str
    reason: str


class Experiment(ABC):
    """Base class; see the module docstring for the contract."""

    name: str = ""
    description: str = ""
    default_config: Mapping[str, Any] = MappingProxyType({})
    quick_config: Mapping[str, Any] = MappingProxyType({})
    section: SectionSpec | None = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A subclass defined in an experiment folder's `__init__` takes its name from the folder
        and its section from the folder's exported `SECTION` (rules 1 and 6), unless it sets them.

        Parameters
        ----------
        **kwargs : passed on to `object.__init_subclass__`.
        """
        super().__init_subclass__(**kwargs)
        module = sys.modules.get(cls.__module__)
        if module is None or not hasattr(module, "__path__"):  # not a folder
            return
        if not cls.__dict__.get("name"):
            cls.name = cls.__module__.rsplit(".", 1)[-1].replace("_", "-")
        if cls.__dict__.get("section") is None and getattr(module, "SECTION", None) is not None:
            cls.section = module.SECTION

    def config(self, overrides: Mapping[str, Any] | None = None, *, quick: bool = False) -> dict:
        """The settings of a run: the defaults, the quick ones over them, then `overrides`.

        Parameters
        ----------
        overrides : mapping, optional, settings that win over both (already checked).
        quick : bool, optional, apply `quick_config` (default False).

        Returns
        -------
        dict: a new dictionary; the class attributes are not changed.
        """
        base = dict(self.default_config)
        if quick:
            base.update(self.quick_config)
        base.update(overrides or {})
        return base

    @abstractmethod
    def cells(
        self, steppers: Sequence[str], problems: Sequence[str], config: Mapping[str, Any]
    ) -> tuple[list[Cell], list[Skip]]:
        """The units of work (contract rule 2).

        Parameters
        ----------
        steppers, problems : sequence of str, the registered names asked for.
        config : mapping, the settings from `config`.

        Returns
        -------
        (list of Cell, list of Skip): the cells to run and the pairs left out, with reasons.
        """

    @abstractmethod
    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """Measure one cell (contract rule 3).

        Parameters
        ----------
        cell : Cell, one of `cells`' results.
        config : mapping, the settings the cells were listed with.

        Returns
        -------
        DataFrame: tidy rows, one per measured point, plain data only.
        """

    @abstractmethod
    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """One record per cell from all cells' rows (contract rule 4).

        Parameters
        ----------
        rows : DataFrame, the concatenated rows of `run_cell`.
        config : mapping, the settings of the run.

        Returns
        -------
        DataFrame: the summary, with `verdict` and `passed` where a claim is judged.
        """


EXPERIMENTS: dict[str, Experiment] = {}


def register_experiment(exp: Experiment) -> Experiment:
    """Add `exp` to `EXPERIMENTS` under its name (a later one of the same name replaces it).

    Parameters
    ----------
    exp : Experiment, the instance (its `name` is the key).

    Returns
    -------
    Experiment: `exp`, so the call can wrap a module-level instance.
    """
    EXPERIMENTS[exp.name] = exp
    return exp


# Experiments registered by other distributions' entry points, in load order, and the entry
# points that failed to load (with their reason).
ENTRY_POINT_EXPERIMENTS: list[str] = []
EXPERIMENT_ERRORS: list[str] = []
_loaded: list[bool] = []


def load_experiments() -> None:
    """Register the experiments of the entry-point group `harness.experiments`, once per process:
    this project's own entry (the built-ins) first, and an error there raises; then other
    distributions' entries, each failure (or a name already taken) recorded in
    `EXPERIMENT_ERRORS` while the rest load."""
    if _loaded:
        return
    _loaded.append(True)

    own, others = group_entry_points("harness.experiments")
    if not own:
        EXPERIMENT_ERRORS.append(missing_builtins("experiment", "harness.experiments"))
    for ep in own:
        for exp in expand(ep.load(), Experiment):
            register_experiment(exp)
    for ep in others:
        try:
            found = expand(ep.load(), Experiment)
            taken = [e.name for e in found if e.name in EXPERIMENTS and EXPERIMENTS[e.name] is not e]
            if taken:
                raise ValueError(f"experiment name {taken[0]!r} is already registered")
        except Exception as exc:
            EXPERIMENT_ERRORS.append(f"entry point {ep.name!r} ({ep.value}): {type(exc).__name__}: {exc}")
            continue
        for exp in found:
            register_experiment(exp)
            ENTRY_POINT_EXPERIMENTS.append(exp.name)


def get_experiment(name: str) -> Experiment:
    """The registered experiment `name` (entry points loaded first); `UnknownNameError` with the
    closest names otherwise.

    Parameters
    ----------
    name : str, as `harness run NAME` takes it (a near miss gets suggestions).

    Returns
    -------
    Experiment: the registered instance.
    """
    load_experiments()
    try:
        return EXPERIMENTS[name]
    except KeyError:
        close = difflib.get_close_matches(str(name), EXPERIMENTS, n=3)
        hint = f"; closest: {', '.join(close)}" if close else f"; known: {', '.join(sorted(EXPERIMENTS))}"
        raise UnknownNameError(f"unknown experiment {name!r}{hint}") from None


def failed_record(
    cell: Cell, message: str, *, kind: str = "error", traceback: str = "", key: str = ""
) -> dict[str, Any]:
    """The record of a failed cell, as the runner stores it and the report lists it: the cell,
    what kind of failure (`harness.runner.FAILURE_KINDS`), the message, a short traceback.

    Parameters
    ----------
    cell : Cell, the cell that failed.
    message : str, the failure in one line.
    kind : str, optional, one of `harness.runner.FAILURE_KINDS` (default 'error').
    traceback : str, optional, the shortened traceback.
    key : str, optional, the cell's cache key.

    Returns
    -------
    dict: flat, JSON-safe fields (the parameters as a JSON string).
    """
    return {
        "experiment": cell.experiment,
        "cell": cell.label,
        "stepper": cell.stepper,
        "problem": cell.problem,
        "params": json.dumps({str(k): v for k, v in cell.params}, sort_keys=True, default=repr),
        "key": key,
        "kind": kind,
        "message": message,
        "traceback": traceback,
    }
