"""Load saved results for your own analysis, as pandas DataFrames.

Every `harness run` / `harness report` saves its tables under `results/<run id>/` (see
`harness.store`). This module reads them back, checked against the run's `meta.json`::

    from harness import results

    results.runs()                                   # saved run ids, oldest first
    rows = results.load(experiment="convergence")    # the newest run's tidy rows
    summary = results.load("latest", "convergence", table="summary")
    slow = summary[summary.verdict != "converged"][["stepper", "problem", "verdict"]]
    everything = results.load()                      # all experiments' rows, stacked
    failed = results.load(table="failures")          # failed cells: kind, message, traceback
    meta = results.meta()                            # provenance: git SHA, versions, CPU, config

`run` is None or 'latest' (the newest run), a run id such as '20250101T120000Z-abc1234', or a
path to a run directory; `root` (or `HARNESS_RESULTS_DIR`) points at another results directory.
A damaged or foreign file raises `harness.store.CorruptResultsError` naming it.
"""

from __future__ import annotations

import os

import pandas as pd

from harness.store import StoredRun, list_runs, load_run

__all__ = ["load", "meta", "runs", "load_run"]


def load(
    run: str | os.PathLike | None = None,
    experiment: str | None = None,
    *,
    table: str = "rows",
    root: str | os.PathLike | None = None,
) -> pd.DataFrame:
    """One table of a saved run as a DataFrame.

    `table` is 'rows' (one row per measured point; default), 'summary' (one record per cell),
    'failures', 'skips' or 'cells' (every cell: status, cached, wall time, worker). With
    `experiment` None, the tables of all experiments in the run are stacked, with an
    `experiment` column first (columns one experiment lacks are NaN for its rows).

    Parameters
    ----------
    run : run id or path, or None for the latest run; experiment : str or None, one experiment's
        name; table : str, which table; root : the results directory (default: the project's).

    Returns
    -------
    DataFrame: the table.

    >>> from harness import results
    >>> df = results.load(experiment="convergence", table="summary")   # doctest: +SKIP
    >>> df[["stepper", "problem", "claimed_order", "measured_order", "verdict"]]  # doctest: +SKIP
    """
    stored: StoredRun = load_run(run, root=root)
    return stored.table(table, experiment)


def meta(run: str | os.PathLike | None = None, *, root: str | os.PathLike | None = None) -> dict:
    """The run's `meta.json`: provenance (git SHA and dirty flag, versions, CPU, date), the full
    configuration, per-experiment wall times and cell counts, failed and skipped cells.

    Parameters
    ----------
    run : run id or path, or None for the latest run; root : the results directory (default: the
    project's).

    Returns
    -------
    dict: the parsed `meta.json`.
    """
    return load_run(run, root=root).meta


def runs(root: str | os.PathLike | None = None) -> list[str]:
    """Saved run ids under the results directory, oldest first.

    Parameters
    ----------
    root : the results directory (default: the project's).

    Returns
    -------
    list of str: run ids.
    """
    return list_runs(root)
