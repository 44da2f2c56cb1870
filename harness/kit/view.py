"""The run as the sections read it: per-experiment rows and summaries, failures, the stepper infos."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pandas as pd

from harness.gate import gate_table
from harness.kit.figure_style import Palette

__all__ = ["RunView", "split", "part", "rows_of", "problems_in"]


@dataclass
class RunView:
    """What the sections read: per-experiment rows and summaries, failures, the stepper infos."""

    rows: dict[str, pd.DataFrame]
    summaries: dict[str, pd.DataFrame]
    meta: dict
    steppers: list[str]
    problems: list[str]
    infos: dict[str, Any]
    origins: dict[str, str]
    quick: bool
    palette: Palette
    run_id: str = ""

    def gate(self) -> pd.DataFrame:
        """The CI gate's judgement of every convergence cell (computed once per report).

        Returns
        -------
        DataFrame: one row per convergence cell (stepper, problem, passed, reason, verdict,
            expected); empty when convergence did not run.
        """
        cached = self.__dict__.get("_gate")
        if cached is None:
            conv = self.summary("convergence")
            cached = gate_table(conv) if len(conv) and "stepper" in conv else pd.DataFrame(
                columns=["stepper", "problem", "passed", "reason", "verdict", "expected"])
            self.__dict__["_gate"] = cached
        return cached

    def has(self, name: str) -> bool:
        """Whether experiment `name` is part of this run (a summary and a meta entry).

        Parameters
        ----------
        name : str, the experiment's name.

        Returns
        -------
        bool: False also when it ran but recorded nothing.
        """
        return name in self.summaries and name in self.meta.get("experiments", {})

    def summary(self, name: str) -> pd.DataFrame:
        """The summary table of experiment `name` (empty when it did not run).

        Parameters
        ----------
        name : str, the experiment's name.

        Returns
        -------
        DataFrame: one row per cell.
        """
        return self.summaries.get(name, pd.DataFrame())

    def rowtable(self, name: str) -> pd.DataFrame:
        """The tidy rows of experiment `name` (empty when it did not run).

        Parameters
        ----------
        name : str, an experiment (as the CLI names it).

        Returns
        -------
        DataFrame: one row per measured point.
        """
        return self.rows.get(name, pd.DataFrame())

    def failures(self, name: str | None = None) -> list[dict]:
        """The failed-cell records of experiment `name` (None: of every experiment).

        Parameters
        ----------
        name : str or None, optional, the experiment's name.

        Returns
        -------
        list of dict: records as `harness.experiments.base.failed_record` writes them.
        """
        exps = self.meta.get("experiments", {})
        names = [name] if name else list(exps)
        out = []
        for n in names:
            out.extend(exps.get(n, {}).get("failures", []))
        return out

    def skips(self, name: str) -> list[dict]:
        """The pairs experiment `name` does not apply to, with their reasons.

        Parameters
        ----------
        name : str, the experiment's name.

        Returns
        -------
        list of dict: stepper, problem and reason of each skipped pair.
        """
        return self.meta.get("experiments", {}).get(name, {}).get("skips", [])

    def flag(self, attr: str) -> dict[str, bool]:
        """stepper -> a boolean of its info (symmetric, symplectic, adaptive...).

        Parameters
        ----------
        attr : str, an attribute of the stepper info (missing reads False).

        Returns
        -------
        dict of str to bool: one entry per stepper of the run.
        """
        return {n: bool(getattr(i, attr, False)) for n, i in self.infos.items()}


def split(view: RunView, table: pd.DataFrame, column: str) -> dict:
    """`table`'s rows by their value of `column`, split once per table and view (sections ask
    for one stepper's or one problem's rows many times; a boolean mask each time scans all).

    Parameters
    ----------
    view : RunView, the run (holds the cache).
    table : DataFrame, a table of the run.
    column : str, the column to group by.

    Returns
    -------
    dict: value -> its rows; empty when `table` has no such column.
    """
    cache = view.__dict__.setdefault("_splits", {})
    key = (id(table), column)
    if key not in cache:
        cache[key] = (table, dict(tuple(table.groupby(column, sort=False))) if column in table else {})
    return cache[key][1]


def part(view: RunView, table: pd.DataFrame, column: str, value: object) -> pd.DataFrame:
    """The rows of `table` whose `column` equals `value` (empty with the same columns if none).

    Parameters
    ----------
    view : RunView, the run (holds the cache of `split`).
    table : DataFrame, a table of the run.
    column : str, the column compared.
    value : object, the value looked for.

    Returns
    -------
    DataFrame: the matching rows.
    """
    part = split(view, table, column).get(value)
    return part if part is not None else table.iloc[0:0]


def rows_of(view: RunView, name: str, stepper: str) -> pd.DataFrame:
    """One stepper's rows of experiment `name`'s summary.

    Parameters
    ----------
    view : RunView, the run.
    name : str, the experiment.
    stepper : str, the method.

    Returns
    -------
    DataFrame: the rows; the whole (empty or stepper-less) summary when it has no stepper column.
    """
    s = view.summary(name)
    if s.empty or "stepper" not in s:
        return s
    return part(view, s, "stepper", stepper)


def problems_in(view: RunView, table: pd.DataFrame) -> list[str]:
    """The problems `table` has rows for: the run's order first, any others after, sorted.

    Parameters
    ----------
    view : RunView, the run (its problem order).
    table : DataFrame, a table with a `problem` column (none: no problems).

    Returns
    -------
    list of str
    """
    present = set(table["problem"]) if "problem" in table else set()
    return [p for p in view.problems if p in present] + sorted(present - set(view.problems))
