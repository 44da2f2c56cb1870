"""Whole-run packs: every cell of one experiment's run in one cache file, and its summary.

A run whose cells are all cached reads one pack instead of one file per cell (`read_pack`); a
finished run without failures writes its pack (`write_pack`) and continues with the rows as the
pack reads back, so a fresh run and a cached one are the same. The summary of a packed run is
cached under the pack and the judging code's version (`harness.keys.judging_version`): it is
recomputed whenever a rule, a threshold or the judging code changes, never served after.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping, Sequence

import pandas as pd

from harness.errors import InputError
from harness.experiments.base import Experiment
from harness.keys import judging_version
from harness.store import CellCache

__all__ = ["read_pack", "write_pack", "summarize_packed"]

def read_pack(store: CellCache, key: str, keys: Sequence[str]) -> tuple[pd.DataFrame, list[dict]] | None:
    """(rows, per-cell records) of the pack `key` holding the cells `keys`, in order, or None
    when there is no such pack; a damaged pack, or one that lists other cells, is discarded
    with a one-line warning (`CellCache.get_or_discard`) and read as missing.

    Parameters
    ----------
    store : CellCache, the cache.
    key : str, the pack key.
    keys : sequence of str, the cell keys it must list, in order.

    Returns
    -------
    (DataFrame, list of dict) or None
    """
    hit = store.get_or_discard(key, "packs")
    if hit is None:
        return None
    rows, info = hit
    listed = info.get("cells")
    if (not isinstance(listed, list) or not all(isinstance(c, dict) for c in listed)
            or [c.get("key") for c in listed] != list(keys)):
        store.discard(store.pack_path(key), "its cell list is not the run's")
        return None
    return rows, listed


def write_pack(store: CellCache, key: str, experiment: str, rows: pd.DataFrame,
               records: Sequence[Mapping]) -> pd.DataFrame:
    """Write the pack of a finished run (its rows and each cell's key, row count, time and
    worker) and return the rows as they read back.

    Parameters
    ----------
    store : CellCache, the cache.
    key : str, the pack key.
    experiment : str, the experiment's name.
    rows : DataFrame, every cell's rows.
    records : sequence of mapping, one per cell, with key, n_rows, wall_s and worker.

    Returns
    -------
    DataFrame
    """
    cells = [{k: r[k] for k in ("key", "n_rows", "wall_s", "worker")} for r in records]
    return store.put_pack(key, rows, {"experiment": experiment, "cells": cells})


def summarize_packed(store: CellCache, pack_key: str, experiment: Experiment, rows: pd.DataFrame,
                     summarize: Callable[[], pd.DataFrame], fresh: bool = False) -> pd.DataFrame:
    """The summary of a packed run: cached under the pack and the judging code's version, else
    `summarize()` (then cached, and returned as it reads back). A summary that cannot be stored
    is returned as computed.

    Parameters
    ----------
    store : CellCache, the cache.
    pack_key : str, the pack's key.
    experiment : Experiment, the experiment (its judging code's version keys the summary).
    rows : DataFrame, the run's rows.
    summarize : callable, makes the summary.
    fresh : bool, optional, recompute even when cached.

    Returns
    -------
    DataFrame
    """
    text = f"summary\n{pack_key}\n{judging_version(experiment)}"
    key = hashlib.sha256(text.encode()).hexdigest()[:32]
    hit = None if fresh else store.get_or_discard(key, "summaries")
    if hit is not None:
        return hit[0]
    summary = summarize()
    if not isinstance(summary, pd.DataFrame):
        return summary  # the caller reports it
    try:
        return store.put_pack(key, summary, {"experiment": experiment.name, "summary_of": pack_key},
                              kind="summaries")
    except InputError:  # not storable as Parquet: used as it is, computed again next time
        return summary
