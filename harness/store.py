"""Where results live: saved runs with provenance, and the per-cell cache.

Saved runs (`save_run`, `load_run`)::

    <results root>/<run id>/meta.json                    provenance, configuration, cell records
    <results root>/<run id>/<experiment>.rows.parquet    tidy rows, one per measured point
    <results root>/<run id>/<experiment>.summary.parquet one record per cell

The results root is `<project>/results`, or `HARNESS_RESULTS_DIR`, or the `root` argument. Run
ids are `YYYYmmddTHHMMSSZ-<short git sha>` (UTC), with `-2`, `-3`, ... when several runs start
in the same second, so they sort by time.

Cell cache (`CellCache`): one Parquet file per finished cell, `<cache root>/cells/<k[:2]>/<k>.parquet`
where `k` is the cell's key (`harness.runner.cell_key`); the cache root is `harness.cache.cache_dir()`
(`.cache/`, or `HARNESS_CACHE_DIR`) unless given. A cell file's metadata records its schema
(`CELL_SCHEMA`), its key, its columns with their dtypes, its row count and a sha256 of its
content (`content_sha256`, over column names, dtypes and values); every read checks all of them,
so a flipped bit, a dropped column or a column rewritten as strings is `CorruptResultsError`
naming the file, never a silently different measurement. A damaged cell file is an error, not a
cache miss: the run stops before using it and says to delete it or rerun with `--fresh` (a
damaged cache usually means a damaged disk, which a user should hear about). Cell files are
read and written only here (`encode_cell`, `decode_cell`, `CellCache`).

Guarantees:
- Every file is written atomically: a temporary file in the same directory, flushed and fsynced,
  then `os.replace`d over the target. A run is assembled in a hidden staging directory and
  renamed into place only when complete, `meta.json` last. A reader never sees half a file or
  half a run; a crash leaves the previous file intact.
- A corrupt or foreign file (unreadable Parquet, columns or row count other than `meta.json`
  records, a checksum mismatch, `meta.json` of another schema or missing keys) raises
  `CorruptResultsError` naming the file and what is wrong. It is never overwritten or used.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import io
import json
import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import pandas as pd

from harness.errors import HarnessError, InputError, OutputError, UnknownNameError, describe_os_error
from harness.provenance import PROJECT_ROOT, collect, to_jsonable, utc_now

__all__ = [
    "SCHEMA",
    "CELL_SCHEMA",
    "ResultsError",
    "CorruptResultsError",
    "results_root",
    "atomic_writer",
    "atomic_write_bytes",
    "atomic_write_json",
    "encode_parquet",
    "decode_parquet",
    "write_parquet",
    "read_parquet",
    "new_run_id",
    "list_runs",
    "resolve_run",
    "save_run",
    "load_run",
    "StoredRun",
    "CellCache",
    "encode_cell",
    "decode_cell",
    "TABLES",
]

SCHEMA = "harness-results/1"
CELL_SCHEMA = "harness-cell/2"
# meta.json nested deeper than this is not one the harness wrote (it nests about 6 deep)
MAX_META_DEPTH = 64
TABLES = ("rows", "summary")
META_KEYS = ("schema", "run_id", "created_utc", "provenance", "config", "experiments", "totals")
EXPERIMENT_KEYS = ("wall_s", "n_cells", "computed_cells", "cached_cells", "failed_cells", "tables",
                   "failures", "skips", "cells")
_RUN_ID = re.compile(r"^(\d{8}T\d{6}Z)-([0-9a-z]+)(?:-(\d+))?$")
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,99}$")
_CELL_KEY = re.compile(r"^[0-9a-f]{32}$")
_META_MARK = b"harness"


class ResultsError(HarnessError):
    """A results directory or run cannot be found or written (the message says which)."""


class CorruptResultsError(ResultsError):
    """A results file is unreadable or is not what the harness wrote; `path` names it."""

    def __init__(self, path: str | Path, problem: str):
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"results file {str(path)!r}: {problem}")


# -- locations ------------------------------------------------------------------------------------
def results_root(root: str | os.PathLike | None = None, *, create: bool = False) -> Path:
    """The directory holding saved runs: `root`, else `HARNESS_RESULTS_DIR`, else
    `<project>/results` (the current directory's `results/` when installed elsewhere)."""
    if root is None:
        env = os.environ.get("HARNESS_RESULTS_DIR")
        if env:
            root = env
        elif (PROJECT_ROOT / "pyproject.toml").exists():
            root = PROJECT_ROOT / "results"
        else:
            root = Path.cwd() / "results"
    if not isinstance(root, str | os.PathLike) or not str(root):
        raise InputError(f"`root` must be a directory path, got {root!r}")
    path = Path(root)
    if path.exists() and not path.is_dir():
        raise ResultsError(f"results root {str(path)!r} exists and is not a directory")
    if create:
        path.mkdir(parents=True, exist_ok=True)
    return path


# -- atomic writes --------------------------------------------------------------------------------
def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_writer(path: str | os.PathLike) -> Iterator[IO[bytes]]:
    """Open a temporary file beside `path` for writing; on success flush, fsync and rename it
    over `path`. On any error (or a crash) `path` keeps its previous content; the temporary file
    is removed when Python still runs, and is hidden (`.name.*.tmp`) otherwise."""
    target = Path(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    except OSError as exc:
        raise _output_error(exc, target) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise _output_error(exc, target) from None
        raise
    _fsync_dir(target.parent)


def _output_error(exc: OSError, target: Path) -> OutputError:
    """`OutputError` naming the file being written and the OS problem (see
    `harness.errors.describe_os_error`)."""
    exc.filename = str(target)  # a temporary file's or a parent's name would only confuse
    message, status = describe_os_error(exc)
    return OutputError(message, status)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` atomically (see `atomic_writer`)."""
    with atomic_writer(path) as fh:
        fh.write(data)


def atomic_write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write `obj` as JSON (NumPy values converted, no NaN literals) atomically."""
    text = json.dumps(to_jsonable(obj), indent=1, allow_nan=False) + "\n"
    atomic_write_bytes(path, text.encode("utf-8"))


def encode_parquet(df: pd.DataFrame, extra: Mapping[str, Any] | None = None) -> bytes:
    """`df` (index dropped) as Parquet bytes, `extra` in the file's metadata. Raises
    `InputError` when `df` cannot be stored (say, a column of mixed Python objects), with the
    reason pyarrow gives."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    if not isinstance(df, pd.DataFrame):
        raise InputError(f"a results table must be a pandas DataFrame, got {type(df).__name__}")
    try:
        table = pa.Table.from_pandas(df.reset_index(drop=True), preserve_index=False)
        if extra is not None:
            meta = dict(table.schema.metadata or {})
            meta[_META_MARK] = json.dumps(to_jsonable(extra), allow_nan=False).encode()
            table = table.replace_schema_metadata(meta)
        buf = io.BytesIO()
        pq.write_table(table, buf)
    except Exception as exc:  # pyarrow's ArrowInvalid / ArrowTypeError / TypeError
        msg = " ".join(str(exc).split())[:200]
        raise InputError(f"table cannot be stored as Parquet: {type(exc).__name__}: {msg}") from None
    return buf.getvalue()


def decode_parquet(data: bytes, path: str | os.PathLike = "<bytes>") -> tuple[pd.DataFrame, dict]:
    """(DataFrame, `extra` metadata or {}) from Parquet bytes; `CorruptResultsError` naming
    `path` when they are not Parquet or the harness metadata is damaged."""
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(io.BytesIO(data))
        df = table.to_pandas()
    except Exception as exc:  # ArrowInvalid and friends: not (valid) Parquet
        msg = " ".join(str(exc).split())[:200]
        problem = f"not a readable Parquet file ({type(exc).__name__}: {msg})"
        raise CorruptResultsError(path, problem) from None
    extra: dict = {}
    raw = (table.schema.metadata or {}).get(_META_MARK)
    if raw is not None:
        try:
            extra = json.loads(raw)
        except ValueError:
            raise CorruptResultsError(path, "harness metadata is not valid JSON") from None
        if not isinstance(extra, dict):
            raise CorruptResultsError(path, "harness metadata is not a JSON object")
    return df, extra


def write_parquet(path: str | os.PathLike, df: pd.DataFrame,
                  extra: Mapping[str, Any] | None = None) -> str:
    """Write `df` as Parquet atomically (see `encode_parquet`); return the file's sha256."""
    data = encode_parquet(df, extra)
    atomic_write_bytes(path, data)
    return hashlib.sha256(data).hexdigest()


def read_parquet(
    path: str | os.PathLike,
    *,
    columns: list[str] | None = None,
    n_rows: int | None = None,
    sha256: str | None = None,
) -> tuple[pd.DataFrame, dict]:
    """Read a Parquet file the harness wrote: (DataFrame, the `extra` metadata or {}).

    Checks, when given, the exact column list, the row count and the checksum; any mismatch,
    or a file that is not Parquet, raises `CorruptResultsError` naming the file."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise CorruptResultsError(p, "missing") from None
    except OSError as exc:
        raise CorruptResultsError(p, f"cannot be read: {exc.strerror or exc}") from None
    if sha256 is not None and hashlib.sha256(data).hexdigest() != sha256:
        raise CorruptResultsError(
            p, "content differs from the checksum in meta.json (changed after the run was saved)"
        )
    df, extra = decode_parquet(data, p)
    if columns is not None and list(df.columns) != list(columns):
        raise CorruptResultsError(
            p, f"columns {list(map(str, df.columns))} differ from the recorded {list(columns)}"
        )
    if n_rows is not None and len(df) != n_rows:
        raise CorruptResultsError(p, f"has {len(df)} rows, meta.json records {n_rows}")
    return df, extra


def _read_json(path: Path) -> Any:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CorruptResultsError(path, "missing") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CorruptResultsError(path, f"cannot be read: {exc}") from None
    try:
        return json.loads(text)
    except ValueError as exc:
        raise CorruptResultsError(path, f"not valid JSON ({exc})") from None
    except RecursionError:
        raise CorruptResultsError(path, "JSON nested too deeply to be a harness file") from None


# -- run ids --------------------------------------------------------------------------------------
def _run_sort_key(run_id: str) -> tuple:
    m = _RUN_ID.match(run_id)
    if m is None:
        return ("", 0, run_id)
    return (m.group(1), int(m.group(3) or 1), m.group(2))


def new_run_id(root: str | os.PathLike | None = None, *, short_sha: str | None = None,
               now: _dt.datetime | None = None) -> str:
    """A fresh, sortable run id `YYYYmmddTHHMMSSZ-<sha>` not yet used under `root`."""
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
    """Saved run ids under `root`, oldest first (directories named like run ids)."""
    base = results_root(root)
    if not base.is_dir():
        return []
    ids = [e.name for e in os.scandir(base) if e.is_dir() and _RUN_ID.match(e.name)]
    return sorted(ids, key=_run_sort_key)


def resolve_run(run: str | os.PathLike | None = None, root: str | os.PathLike | None = None) -> Path:
    """The directory of a saved run: None or 'latest' (newest under `root`), a run id under
    `root`, or a path to a run directory."""
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
    if _SAFE_NAME.match(text) and (base / text).is_dir():
        return base / text
    if (os.sep in text or as_path.is_absolute() or text.startswith(".")) and as_path.is_dir():
        if not (as_path / "meta.json").is_file():
            raise ResultsError(f"`run` {text[:200]!r} is a directory but not a saved run (no meta.json)")
        return as_path
    ids = list_runs(base)
    import difflib

    close = difflib.get_close_matches(text, ids, n=3)
    hint = f"; closest: {', '.join(close)}" if close else (f"; newest: {ids[-1]}" if ids else "")
    shown = text if len(text) <= 80 else text[:77] + "..."
    raise UnknownNameError(
        f"`run` {shown!r} is neither a saved run under {str(base)!r} nor a run directory{hint}"
    )


# -- saving and loading runs ----------------------------------------------------------------------
def _check_experiment_name(name: Any) -> str:
    if not isinstance(name, str) or not _SAFE_NAME.match(name):
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
    elif not isinstance(run_id, str) or not _SAFE_NAME.match(run_id):
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
    _fsync_dir(base)
    return final


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
        return list(self.meta["experiments"])

    @property
    def provenance(self) -> dict:
        return self.meta["provenance"]

    @property
    def config(self) -> dict:
        return self.meta["config"]

    @property
    def wall_s(self) -> dict[str, float]:
        """Wall time per experiment, seconds."""
        return {n: e["wall_s"] for n, e in self.meta["experiments"].items()}

    @property
    def n_failed(self) -> int:
        return int(self.meta["totals"]["failed"])

    def table(self, name: str, experiment: str | None = None) -> pd.DataFrame:
        """One table ('rows', 'summary', 'failures', 'skips', 'cells') of one experiment, or of
        all experiments stacked with an `experiment` column first."""
        if name not in (*TABLES, "failures", "skips", "cells"):
            raise InputError(
                f"`table` must be one of rows, summary, failures, skips, cells; got {name!r}"
            )
        if experiment is not None and experiment not in self.meta["experiments"]:
            import difflib

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
        return self.table("failures")

    @property
    def skips(self) -> pd.DataFrame:
        return self.table("skips")

    @property
    def cells(self) -> pd.DataFrame:
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
        if not isinstance(name, str) or not _SAFE_NAME.match(name):
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


def load_run(run: str | os.PathLike | None = None, *, root: str | os.PathLike | None = None) -> StoredRun:
    """Load and check a saved run: `run` is None or 'latest' (the newest), a run id under `root`
    (default: the results root), or a path to a run directory. Every table is read and checked
    against `meta.json` (columns, row count, checksum); any mismatch raises
    `CorruptResultsError` naming the file."""
    path = resolve_run(run, root)
    meta_path = path / "meta.json"
    meta = _check_meta(meta_path, _read_json(meta_path))
    out = StoredRun(run_id=str(meta["run_id"]), path=path, meta=meta)
    for name, exp in meta["experiments"].items():
        for table in TABLES:
            spec = exp["tables"][table]
            df, _ = read_parquet(
                path / spec["file"],
                columns=spec["columns"],
                n_rows=spec["n_rows"],
                sha256=spec.get("sha256"),
            )
            (out.rows if table == "rows" else out.summaries)[name] = df
    return out


# -- the cell cache -------------------------------------------------------------------------------
def _content_sha256(df: pd.DataFrame) -> str:
    """sha256 over a table's column names, dtypes and values (independent of Parquet's bytes,
    so it can live inside the file it checks)."""
    import numpy as np

    h = hashlib.sha256()
    h.update(json.dumps([[str(c), str(df[c].dtype)] for c in df.columns]).encode())
    h.update(str(len(df)).encode())
    for c in df.columns:
        col = df[c]
        if pd.api.types.is_numeric_dtype(col) and not pd.api.types.is_object_dtype(col):
            h.update(np.ascontiguousarray(col.to_numpy()).tobytes())
        else:
            h.update(json.dumps([None if v is None else repr(v) for v in col.tolist()]).encode())
    return h.hexdigest()


def _cell_schema(df: pd.DataFrame) -> dict[str, str]:
    return {str(c): str(df[c].dtype) for c in df.columns}


def encode_cell(key: str, rows: pd.DataFrame, info: Mapping[str, Any]) -> tuple[pd.DataFrame, bytes]:
    """A finished cell as (its rows as they read back from the file, the file's bytes). The
    metadata holds `info`, the key, the schema, the column dtypes, the row count and the content
    checksum. Raises `InputError` when the rows cannot be stored as Parquet."""
    plain = {**to_jsonable(dict(info)), "schema": CELL_SCHEMA, "key": key}
    back, _ = decode_parquet(encode_parquet(rows, plain))
    meta = {**plain, "columns": _cell_schema(back), "n_rows": int(len(back)),
            "content_sha256": _content_sha256(back)}
    return back, encode_parquet(rows, meta)


def decode_cell(data: bytes, path: str | os.PathLike, key: str | None = None) -> tuple[pd.DataFrame, dict]:
    """(rows, info) of a cell file's bytes, after checking its schema, key, columns, dtypes,
    row count and content checksum; `CorruptResultsError` naming `path` otherwise."""
    df, info = decode_parquet(data, path)
    if info.get("schema") != CELL_SCHEMA:
        raise CorruptResultsError(path, f"not a harness cell file of schema {CELL_SCHEMA!r} "
                                        f"(schema {str(info.get('schema'))[:60]!r})")
    if key is not None and info.get("key") != key:
        raise CorruptResultsError(path, f"holds cell {str(info.get('key'))[:40]!r}, not {key!r}")
    columns, n_rows, digest = info.get("columns"), info.get("n_rows"), info.get("content_sha256")
    if not isinstance(columns, dict) or not isinstance(n_rows, int) or not isinstance(digest, str):
        raise CorruptResultsError(path, "cell metadata lacks its columns, row count or checksum")
    found = _cell_schema(df)
    if found != columns:
        lost = [c for c in columns if c not in found]
        changed = [f"{c} ({columns[c]} -> {found[c]})" for c in columns
                   if c in found and found[c] != columns[c]]
        extra = [c for c in found if c not in columns]
        raise CorruptResultsError(path, "columns differ from the recorded schema: "
                                        f"missing {lost}, retyped {changed}, unexpected {extra}")
    if len(df) != n_rows:
        raise CorruptResultsError(path, f"has {len(df)} rows, its metadata records {n_rows}")
    if _content_sha256(df) != digest:
        raise CorruptResultsError(path, "content differs from its checksum (the file was changed "
                                        "or damaged after it was written)")
    return df, info


class CellCache:
    """Finished cells, one Parquet file each, keyed by `harness.runner.cell_key`.

    `get` returns a cell's rows or None; a file that exists but is damaged, of another schema
    or of another key raises `CorruptResultsError` naming it (delete it, or run with
    `fresh=True`, which overwrites). `put` writes atomically."""

    HINT = "; delete it, or recompute with fresh=True (--fresh), which overwrites it"

    def __init__(self, root: str | os.PathLike | None = None):
        if root is None:
            from harness.cache import cache_dir

            root = cache_dir()
        if not isinstance(root, str | os.PathLike) or not str(root):
            raise InputError(f"`cache_dir` must be a directory path, got {root!r}")
        self.root = Path(root) / "cells"

    def path(self, key: str) -> Path:
        if not isinstance(key, str) or not _CELL_KEY.match(key):
            raise InputError(f"`key` must be 32 lowercase hex digits, got {key!r}")
        return self.root / key[:2] / f"{key}.parquet"

    def get(self, key: str) -> tuple[pd.DataFrame, dict] | None:
        """(rows, info) of a finished cell, or None when it is not cached."""
        p = self.path(key)
        try:
            if not p.is_file():
                if p.exists() or p.is_symlink():
                    raise CorruptResultsError(p, "is not a regular file" + self.HINT)
                return None
            data = p.read_bytes()
        except OSError as exc:
            message, _ = describe_os_error(exc, p)
            raise CorruptResultsError(p, f"cannot be read: {message}{self.HINT}") from None
        try:
            return decode_cell(data, p, key)
        except CorruptResultsError as exc:
            raise CorruptResultsError(p, exc.problem + self.HINT) from None

    def put(self, key: str, rows: pd.DataFrame, info: Mapping[str, Any]) -> Path:
        """Write a finished cell (encoded by `encode_cell`) atomically; return its path."""
        _, data = encode_cell(key, rows, info)
        return self.put_encoded(key, data)

    def put_encoded(self, key: str, data: bytes) -> Path:
        """Write the bytes `encode_cell` made for `key` atomically; return the path."""
        p = self.path(key)
        atomic_write_bytes(p, data)
        return p

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and bool(_CELL_KEY.match(key)) and self.path(key).exists()

    def __len__(self) -> int:
        if not self.root.is_dir():
            return 0
        return sum(1 for _ in self.root.glob("??/*.parquet"))
