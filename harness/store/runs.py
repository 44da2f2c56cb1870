"""Saved runs: the results root, run ids (sortable by time) and writing a run atomically
(assembled in a hidden staging directory, renamed into place with meta.json last)."""

from __future__ import annotations

import datetime as _dt
import difflib
import os
import re
import shutil
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from harness.errors import InputError, OutputError, UnknownNameError, describe_os_error
from harness.provenance import collect, default_directory, to_jsonable, utc_now
from harness.store.files import atomic_write_json, fsync_dir, write_parquet
from harness.store.schema import SAFE_NAME, SCHEMA, TABLES, ResultsError

RUN_ID = re.compile(r"^(\d{8}T\d{6}Z)-([0-9a-z]+)(?:-(\d+))?$")

# -- locations ------------------------------------------------------------------------------------
def results_root(root: str | os.PathLike | None = None, *, create: bool = False) -> Path:
    """The directory holding saved runs: `root`, else `HARNESS_RESULTS_DIR`, else
    `<project>/results` (the current directory's `results/` when installed elsewhere).

    Parameters
    ----------
    root : str or PathLike, optional, the directory.
    create : bool, optional, create it when missing.

    Returns
    -------
    Path
    """
    root = default_directory(root, "HARNESS_RESULTS_DIR", "results")
    if not isinstance(root, str | os.PathLike) or not str(root):
        raise InputError(f"`root` must be a directory path, got {root!r}")
    path = Path(root)
    if path.exists() and not path.is_dir():
        raise ResultsError(f"results root {str(path)!r} exists and is not a directory")
    if create:
        path.mkdir(parents=True, exist_ok=True)
    return path



# -- run ids --------------------------------------------------------------------------------------
def _run_sort_key(run_id: str) -> tuple:
    m = RUN_ID.match(run_id)
    if m is None:
        return ("", 0, run_id)
    return (m.group(1), int(m.group(3) or 1), m.group(2))


def new_run_id(root: str | os.PathLike | None = None, *, short_sha: str | None = None,
               now: _dt.datetime | None = None) -> str:
    """A fresh, sortable run id `YYYYmmddTHHMMSSZ-<sha>` not yet used under `root`.

    Parameters
    ----------
    root : str or PathLike, optional, the results root (ids already used there are skipped).
    short_sha : str, optional, the code's short commit hash (default "nogit").
    now : datetime, optional, the time stamped (default now, UTC).

    Returns
    -------
    str
    """
    when = (now or utc_now()).astimezone(_dt.UTC)
    stamp = when.strftime("%Y%m%dT%H%M%SZ")
    sha = (short_sha or "nogit").lower()
    if not re.fullmatch(r"[0-9a-z]+", sha):
        raise InputError(f"`short_sha` must be lowercase letters and digits, got {short_sha!r}")
    base = results_root(root)
    taken = 0
    if base.is_dir():
        for entry in os.listdir(base):
            if entry.startswith(".staging-"):  # a run being saved right now
                entry = entry[len(".staging-"):].rsplit("@", 1)[0]
            if entry.startswith(stamp + "-"):
                taken += 1
    return f"{stamp}-{sha}" if taken == 0 else f"{stamp}-{sha}-{taken + 1}"


def list_runs(root: str | os.PathLike | None = None) -> list[str]:
    """Saved run ids under `root`, oldest first (directories named like run ids).

    Parameters
    ----------
    root : str or PathLike, optional, the results root.

    Returns
    -------
    list of str
    """
    base = results_root(root)
    if not base.is_dir():
        return []
    ids = [e.name for e in os.scandir(base) if e.is_dir() and RUN_ID.match(e.name)]
    return sorted(ids, key=_run_sort_key)


def resolve_run(run: str | os.PathLike | None = None, root: str | os.PathLike | None = None) -> Path:
    """The directory of a saved run: None or 'latest' (newest under `root`), a run id under
    `root`, or a path to a run directory.

    Parameters
    ----------
    run : str or PathLike, optional, which run.
    root : str or PathLike, optional, the results root.

    Returns
    -------
    Path: `ResultsError` when there is no such run.
    """
    base = results_root(root)
    if run is None or (isinstance(run, str) and run == "latest"):
        ids = list_runs(base)
        if not ids:
            raise ResultsError(
                f"no saved runs under {str(base)!r} (run `harness run` or `harness report` first)"
            )
        return base / ids[-1]
    if not isinstance(run, str | os.PathLike):
        raise InputError(f"`run` must be a run id, 'latest', or a path, got {type(run).__name__}")
    text = os.fspath(run)
    if not text or "\x00" in text or "\n" in text:
        raise InputError(f"`run` must be a run id, 'latest', or a path, got {text!r}")
    as_path = Path(text)
    if SAFE_NAME.match(text) and (base / text).is_dir():
        return base / text
    if (os.sep in text or as_path.is_absolute() or text.startswith(".")) and as_path.is_dir():
        if not (as_path / "meta.json").is_file():
            raise ResultsError(f"`run` {text[:200]!r} is a directory but not a saved run (no meta.json)")
        return as_path
    ids = list_runs(base)

    close = difflib.get_close_matches(text, ids, n=3)
    hint = f"; closest: {', '.join(close)}" if close else (f"; newest: {ids[-1]}" if ids else "")
    shown = text if len(text) <= 80 else text[:77] + "..."
    raise UnknownNameError(
        f"`run` {shown!r} is neither a saved run under {str(base)!r} nor a run directory{hint}"
    )


# -- saving and loading runs ----------------------------------------------------------------------
def _check_experiment_name(name: Any) -> str:
    if not isinstance(name, str) or not SAFE_NAME.match(name):
        raise InputError(
            f"`experiment` name {name!r} cannot name a results file: use letters, digits and _.+- "
            "(at most 100 characters, starting with a letter or digit)"
        )
    return name


def _records(df: Any) -> list[dict]:
    if df is None:
        return []
    if isinstance(df, pd.DataFrame):
        return [to_jsonable(r) for r in df.to_dict(orient="records")]
    return [to_jsonable(dict(r)) for r in df]


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _clean_stale_staging(base: Path) -> None:
    """Remove staging directories of saves whose process no longer exists (killed mid-save)."""
    for entry in os.scandir(base):
        if entry.is_dir() and entry.name.startswith(".staging-") and "@" in entry.name:
            try:
                pid = int(entry.name.rsplit("@", 1)[1])
            except ValueError:
                continue
            if pid != os.getpid() and not _pid_alive(pid):
                shutil.rmtree(entry.path, ignore_errors=True)


def save_run(
    results: Iterable[Any] | Mapping[str, Any],
    *,
    root: str | os.PathLike | None = None,
    run_id: str | None = None,
    config: Mapping[str, Any] | None = None,
) -> Path:
    """Save the results of one run (one `harness.runner.RunResult` per experiment) with its
    provenance; return the run directory `<root>/<run id>`.

    `config` is the run's own configuration (command, jobs, steppers, problems, plugins, ...);
    each experiment's resolved configuration is taken from its result. The directory appears
    complete or not at all (assembled in `.staging-...` and renamed). An existing run is never
    overwritten: an explicit `run_id` that exists raises `ResultsError`; an OS error (read-only
    or full disk, a file where the directory belongs) raises `OutputError` naming the path.

    Parameters
    ----------
    results : iterable or mapping of RunResult, one result per experiment.
    root : str or PathLike, optional, the results root.
    run_id : str, optional, the run id (default a fresh one, `new_run_id`).
    config : mapping, optional, the run's own configuration.

    Returns
    -------
    Path
    """
    try:
        return _save_run(results, root=root, run_id=run_id, config=config)
    except OutputError:
        raise
    except OSError as exc:  # a results root that is a file, read-only, full, ...
        raise OutputError(*describe_os_error(exc)) from None


def _save_run(results, *, root, run_id, config) -> Path:
    items = list(results.values()) if isinstance(results, Mapping) else list(results)
    names = [_check_experiment_name(getattr(r, "experiment", None)) for r in items]
    if len(set(names)) != len(names):
        raise InputError(f"`results` names an experiment twice: {names}")
    base = results_root(root, create=True)
    _clean_stale_staging(base)
    prov = collect(config)
    if run_id is None:
        run_id = new_run_id(base, short_sha=prov["git"]["short_sha"])
    elif not isinstance(run_id, str) or not SAFE_NAME.match(run_id):
        raise InputError(f"`run_id` must use letters, digits and _.+- only, got {run_id!r}")
    final = base / run_id
    if final.exists():
        raise ResultsError(f"run {str(final)!r} already exists; a saved run is never overwritten")
    staging = base / f".staging-{run_id}@{os.getpid()}"
    staging.mkdir()
    try:
        experiments: dict[str, Any] = {}
        totals = {"cells": 0, "computed": 0, "cached": 0, "failed": 0, "skipped": 0, "wall_s": 0.0}
        for name, res in zip(names, items, strict=True):
            tables = {}
            for table in TABLES:
                df = res.rows if table == "rows" else res.summary
                if df is None:
                    df = pd.DataFrame()
                fname = f"{name}.{table}.parquet"
                try:
                    digest = write_parquet(staging / fname, df, {"schema": SCHEMA, "experiment": name,
                                                                 "table": table, "run_id": run_id})
                except InputError as exc:
                    raise InputError(f"experiment {name!r}, {table}: {exc}") from None
                tables[table] = {
                    "file": fname,
                    "columns": [str(c) for c in df.columns],
                    "n_rows": int(len(df)),
                    "sha256": digest,
                }
            failures = _records(getattr(res, "failures", None))
            skips = _records(getattr(res, "skips", None))
            cells = _records(getattr(res, "cells", None))
            experiments[name] = {
                "description": getattr(res, "description", ""),
                "config": to_jsonable(getattr(res, "config", {})),
                "wall_s": float(res.wall_s),
                "n_cells": int(getattr(res, "n_cells", len(cells))),
                "computed_cells": int(res.computed_cells),
                "cached_cells": int(res.cached_cells),
                "failed_cells": len(failures),
                "tables": tables,
                "failures": failures,
                "skips": skips,
                "cells": cells,
            }
            totals["cells"] += experiments[name]["n_cells"]
            totals["computed"] += experiments[name]["computed_cells"]
            totals["cached"] += experiments[name]["cached_cells"]
            totals["failed"] += len(failures)
            totals["skipped"] += len(skips)
            totals["wall_s"] += float(res.wall_s)
        meta = {
            "schema": SCHEMA,
            "run_id": run_id,
            "created_utc": prov["date_utc"],
            "provenance": {k: prov[k] for k in ("git", "versions", "machine", "date_utc")},
            "config": {
                "run": prov["config"],
                "experiments": {n: experiments[n]["config"] for n in names},
            },
            "experiments": experiments,
            "totals": totals,
        }
        atomic_write_json(staging / "meta.json", meta)
        os.rename(staging, final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    fsync_dir(base)
    return final
