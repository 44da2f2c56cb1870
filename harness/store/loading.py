"""Reading a saved run back: meta.json checked key by key (`load_run`) and its tables (`StoredRun`)."""

from __future__ import annotations

import difflib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from harness.errors import InputError, UnknownNameError
from harness.store.files import check_frame, read_json, read_parquet
from harness.store.runs import resolve_run
from harness.store.schema import (
    EXPERIMENT_KEYS,
    MAX_META_DEPTH,
    META_KEYS,
    SAFE_NAME,
    SCHEMA,
    TABLES,
    CorruptResultsError,
)


@dataclass
class StoredRun:
    """A saved run, checked on loading: its tables per experiment and its `meta.json`."""

    run_id: str
    path: Path
    meta: dict
    rows: dict[str, pd.DataFrame] = field(default_factory=dict)
    summaries: dict[str, pd.DataFrame] = field(default_factory=dict)

    @property
    def experiments(self) -> list[str]:
        """The names of the experiments saved in this run, in run order."""
        return list(self.meta["experiments"])

    @property
    def provenance(self) -> dict:
        """Where the run came from: code version, libraries, machine, date (`harness.provenance`)."""
        return self.meta["provenance"]

    @property
    def config(self) -> dict:
        """The configuration the run was made with."""
        return self.meta["config"]

    @property
    def wall_s(self) -> dict[str, float]:
        """Wall time per experiment, seconds."""
        return {n: e["wall_s"] for n, e in self.meta["experiments"].items()}

    @property
    def n_failed(self) -> int:
        """How many cells of the run failed."""
        return int(self.meta["totals"]["failed"])

    def table(self, name: str, experiment: str | None = None) -> pd.DataFrame:
        """One table ('rows', 'summary', 'failures', 'skips', 'cells') of one experiment, or of
        all experiments stacked with an `experiment` column first.

        Parameters
        ----------
        name : str, 'rows', 'summary', 'failures', 'skips' or 'cells'.
        experiment : str, optional, one experiment of the run (default all).

        Returns
        -------
        DataFrame
        """
        if name not in (*TABLES, "failures", "skips", "cells"):
            raise InputError(
                f"`table` must be one of rows, summary, failures, skips, cells; got {name!r}"
            )
        if experiment is not None and experiment not in self.meta["experiments"]:
            close = difflib.get_close_matches(str(experiment), self.experiments, n=3)
            raise UnknownNameError(
                f"`experiment` {str(experiment)[:80]!r} is not in run {self.run_id!r}; it has: "
                f"{', '.join(close or self.experiments) or 'no experiments'}"
            )
        names = [experiment] if experiment is not None else self.experiments
        frames = []
        for n in names:
            if name == "rows":
                df = self.rows[n]
            elif name == "summary":
                df = self.summaries[n]
            else:
                df = pd.DataFrame.from_records(self.meta["experiments"][n][name])
            if "experiment" not in df.columns:
                df = df.copy()
                df.insert(0, "experiment", n)
            frames.append(df)
        if experiment is not None:
            return frames[0]
        frames = [f for f in frames if len(f.columns)]
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    @property
    def failures(self) -> pd.DataFrame:
        """One record per failed cell, over every experiment."""
        return self.table("failures")

    @property
    def skips(self) -> pd.DataFrame:
        """One record per (stepper, problem) pair that does not apply, with the reason."""
        return self.table("skips")

    @property
    def cells(self) -> pd.DataFrame:
        """One record per cell: its key, status and whether it came from the cache."""
        return self.table("cells")


_KIND_NAMES = {str: "a string", dict: "an object", list: "a list"}


def _describe(value: Any) -> str:
    return type(value).__name__ if not isinstance(value, list) else "a list holding " + ", ".join(
        sorted({type(v).__name__ for v in value}))


def _depth(value: Any) -> int:
    """Nesting depth of parsed JSON, without recursion (a hostile file may nest very deep)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, dict | list):
            deepest = max(deepest, d)
            if d > MAX_META_DEPTH:
                return d
            stack.extend((c, d + 1) for c in (v.values() if isinstance(v, dict) else v))
    return deepest


def _check_meta(path: Path, meta: Any) -> dict:
    if not isinstance(meta, dict):
        raise CorruptResultsError(path, f"expected a JSON object, got {type(meta).__name__}")
    if "schema" not in meta:
        raise CorruptResultsError(path, "not a harness meta.json (no `schema` key)")
    if meta["schema"] != SCHEMA:
        raise CorruptResultsError(
            path, f"schema {meta['schema']!r} is not the one this harness reads ({SCHEMA!r})"
        )
    missing = [k for k in META_KEYS if k not in meta]
    if missing:
        raise CorruptResultsError(path, f"missing keys {missing}")
    depth = _depth(meta)
    if depth > MAX_META_DEPTH:
        raise CorruptResultsError(path, f"nested {depth} levels deep; a harness meta.json nests "
                                        f"at most {MAX_META_DEPTH}")
    for key, kind in (("run_id", str), ("created_utc", str), ("provenance", dict),
                      ("config", dict), ("experiments", dict), ("totals", dict)):
        if not isinstance(meta[key], kind):
            raise CorruptResultsError(path, f"`{key}` must be {_KIND_NAMES[kind]}, got "
                                            f"{type(meta[key]).__name__}")
    if not SAFE_NAME.match(meta["run_id"]) or meta["run_id"].strip(".") == "":
        raise CorruptResultsError(path, f"`run_id` {meta['run_id'][:80]!r} is not a run id "
                                        "(letters, digits and _.+- only); it is never used as a path")
    for key, value in meta["totals"].items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CorruptResultsError(path, f"`totals.{key}` must be a number, got {type(value).__name__}")
    for name, exp in meta["experiments"].items():
        if not isinstance(exp, dict):
            raise CorruptResultsError(path, f"experiment {name!r} is not an object")
        miss = [k for k in EXPERIMENT_KEYS if k not in exp]
        if miss:
            raise CorruptResultsError(path, f"experiment {name!r} is missing keys {miss}")
        for key in ("wall_s", "n_cells", "computed_cells", "cached_cells", "failed_cells"):
            v = exp[key]
            if isinstance(v, bool) or not isinstance(v, int | float) or (key != "wall_s" and v != int(v)):
                raise CorruptResultsError(path, f"experiment {name!r}: `{key}` must be a number, "
                                                f"got {type(v).__name__}")
        for key in ("failures", "skips", "cells"):
            records = exp[key]
            if not isinstance(records, list) or not all(isinstance(r, dict) for r in records):
                raise CorruptResultsError(path, f"experiment {name!r}: `{key}` must be a list of "
                                                f"records (objects), got {_describe(records)}")
        if not isinstance(exp["tables"], dict):
            raise CorruptResultsError(path, f"experiment {name!r}: `tables` must be an object")
        if not isinstance(name, str) or not SAFE_NAME.match(name):
            raise CorruptResultsError(path, f"experiment name {name!r} is not a valid file name")
        for table in TABLES:
            spec = exp["tables"].get(table) if isinstance(exp["tables"], dict) else None
            if not isinstance(spec, dict) or any(k not in spec for k in ("file", "columns", "n_rows")):
                raise CorruptResultsError(path, f"experiment {name!r} lacks a valid {table!r} table entry")
            if (not isinstance(spec["columns"], list) or not all(isinstance(c, str) for c in spec["columns"])
                    or isinstance(spec["n_rows"], bool) or not isinstance(spec["n_rows"], int)
                    or spec["n_rows"] < 0 or not isinstance(spec["file"], str)
                    or not isinstance(spec.get("sha256", ""), str)):
                raise CorruptResultsError(path, f"experiment {name!r}: the {table!r} table entry has "
                                                "wrong types (columns: list of names, n_rows: count, "
                                                "file and sha256: strings)")
            if spec["file"] != f"{name}.{table}.parquet":
                raise CorruptResultsError(path, f"experiment {name!r}: unexpected file name {spec['file']!r}")
    return meta


def load_run(run: str | os.PathLike | None = None, *, root: str | os.PathLike | None = None,
             tables: Sequence[str] = TABLES,
             stored_rows: Mapping[str, pd.DataFrame] | None = None) -> StoredRun:
    """Load and check a saved run: `run` is None or 'latest' (the newest), a run id under `root`
    (default: the results root), or a path to a run directory. Every table is read and checked
    against `meta.json` (columns, row count, checksum); any mismatch raises
    `CorruptResultsError` naming the file.

    `tables` names the tables to read (default both; ('summary',) skips the rows).
    `stored_rows` maps experiments to rows frames already in their stored form (decoded from
    Parquet, as a run's packs are: the file just saved from them decodes to an equal frame);
    they are taken instead of decoding their files again, after the same column and row-count
    checks.

    Parameters
    ----------
    run : str or PathLike, optional, which run (see above).
    root : str or PathLike, optional, the results root.
    tables : sequence of str, optional, the tables to read.
    stored_rows : mapping, optional, rows frames already decoded, by experiment.

    Returns
    -------
    StoredRun
    """
    unknown = [t for t in tables if t not in TABLES]
    if isinstance(tables, str) or unknown:
        raise InputError(f"`tables` must list tables among {list(TABLES)}, got {tables!r}")
    path = resolve_run(run, root)
    meta_path = path / "meta.json"
    meta = _check_meta(meta_path, read_json(meta_path))
    out = StoredRun(run_id=str(meta["run_id"]), path=path, meta=meta)
    known = dict(stored_rows or {})
    for name, exp in meta["experiments"].items():
        for table in tables:
            spec = exp["tables"][table]
            df = known.get(name) if table == "rows" else None
            if df is not None:
                check_frame(path / spec["file"], df, columns=spec["columns"], n_rows=spec["n_rows"])
            else:
                df, _ = read_parquet(
                    path / spec["file"],
                    columns=spec["columns"],
                    n_rows=spec["n_rows"],
                    sha256=spec.get("sha256"),
                )
            (out.rows if table == "rows" else out.summaries)[name] = df
    return out
