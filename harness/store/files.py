"""Atomic writes and checked files: every file is written to a temporary file, fsynced and
renamed into place; Parquet files carry harness metadata that every read checks."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import stat
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO, Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from harness.errors import InputError, OutputError, describe_os_error
from harness.provenance import to_jsonable
from harness.store.schema import CorruptResultsError
from harness.tolerances import MAX_STORED_FILE_BYTES

_META_MARK = b"harness"

# -- atomic writes --------------------------------------------------------------------------------
def fsync_dir(path: Path) -> None:
    """Flush the directory entry of `path` to disk (after a rename into it); a no-op where the
    system cannot open directories.

    Parameters
    ----------
    path : Path, the directory.
    """
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
    is removed when Python still runs, and is hidden (`.name.*.tmp`) otherwise.

    Parameters
    ----------
    path : str or PathLike, the file to replace; `OutputError` naming it when its directory cannot be written.

    Yields
    ------
    binary file
        The temporary file, open for writing.
    """
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
    fsync_dir(target.parent)


def _output_error(exc: OSError, target: Path) -> OutputError:
    """`OutputError` naming the file being written and the OS problem (see
    `harness.errors.describe_os_error`)."""
    exc.filename = str(target)  # a temporary file's or a parent's name would only confuse
    message, status = describe_os_error(exc)
    return OutputError(message, status)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` atomically (see `atomic_writer`).

    Parameters
    ----------
    path : str or PathLike, the file.
    data : bytes, its new content.
    """
    with atomic_writer(path) as fh:
        fh.write(data)


def atomic_write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write `obj` as JSON (NumPy values converted, no NaN literals) atomically.

    Parameters
    ----------
    path : str or PathLike, the file.
    obj : any, A JSON-able value (after `to_jsonable`).
    """
    text = json.dumps(to_jsonable(obj), indent=1, allow_nan=False) + "\n"
    atomic_write_bytes(path, text.encode("utf-8"))


def arrow_table(df: pd.DataFrame) -> Any:
    """`df` (index dropped) as a pyarrow Table, the form `table_bytes` writes. Raises
    `InputError` when `df` cannot be stored (say, a column of mixed Python objects), with the
    reason pyarrow gives.

    Parameters
    ----------
    df : DataFrame

    Returns
    -------
    pyarrow.Table
    """
    if not isinstance(df, pd.DataFrame):
        raise InputError(f"a results table must be a pandas DataFrame, got {type(df).__name__}")
    try:
        return pa.Table.from_pandas(df.reset_index(drop=True), preserve_index=False)
    except Exception as exc:  # pyarrow's ArrowInvalid / ArrowTypeError / TypeError
        raise _unstorable(exc) from None


def table_bytes(table: Any, extra: Mapping[str, Any] | None = None) -> bytes:
    """An `arrow_table` as Parquet bytes, `extra` in the file's metadata.

    Parameters
    ----------
    table : pyarrow.Table
    extra : mapping, optional, JSON-able metadata stored under the harness's key.

    Returns
    -------
    bytes
    """
    try:
        if extra is not None:
            meta = dict(table.schema.metadata or {})
            meta[_META_MARK] = json.dumps(to_jsonable(extra), allow_nan=False).encode()
            table = table.replace_schema_metadata(meta)
        buf = io.BytesIO()
        pq.write_table(table, buf)
    except Exception as exc:  # pyarrow's ArrowInvalid / ArrowTypeError / TypeError
        raise _unstorable(exc) from None
    return buf.getvalue()


def _unstorable(exc: Exception) -> InputError:
    msg = " ".join(str(exc).split())[:200]
    return InputError(f"table cannot be stored as Parquet: {type(exc).__name__}: {msg}")


def encode_parquet(df: pd.DataFrame, extra: Mapping[str, Any] | None = None) -> bytes:
    """`df` (index dropped) as Parquet bytes, `extra` in the file's metadata. Raises
    `InputError` when `df` cannot be stored (say, a column of mixed Python objects), with the
    reason pyarrow gives.

    Parameters
    ----------
    df : DataFrame
    extra : mapping, optional, JSON-able metadata.

    Returns
    -------
    bytes
    """
    return table_bytes(arrow_table(df), extra)


def decode_parquet(data: bytes, path: str | os.PathLike = "<bytes>") -> tuple[pd.DataFrame, dict]:
    """(DataFrame, `extra` metadata or {}) from Parquet bytes; `CorruptResultsError` naming
    `path` when they are not Parquet or the harness metadata is damaged.

    Parameters
    ----------
    data : bytes, the file's content.
    path : str or PathLike, optional, where it came from (for messages).

    Returns
    -------
    (DataFrame, dict)
    """
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
    """Write `df` as Parquet atomically (see `encode_parquet`); return the file's sha256.

    Parameters
    ----------
    path : str or PathLike, the file.
    df : DataFrame
    extra : mapping, optional, JSON-able metadata.

    Returns
    -------
    str: the sha256 of the bytes written, in hex.
    """
    data = encode_parquet(df, extra)
    atomic_write_bytes(path, data)
    return hashlib.sha256(data).hexdigest()


def read_bounded(path: str | os.PathLike, limit: int | None = None) -> bytes:
    """The bytes of the regular file `path` (links followed), read with a bound: a device, pipe
    or directory (a link to /dev/zero), or a file over `limit` bytes (default
    MAX_STORED_FILE_BYTES), raises `CorruptResultsError` naming it; a missing file raises
    FileNotFoundError and another OS error OSError, for the caller to name.

    Parameters
    ----------
    path : str or PathLike, the file.
    limit : int, optional, the largest size accepted, in bytes.

    Returns
    -------
    bytes
    """
    limit = MAX_STORED_FILE_BYTES if limit is None else int(limit)
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as fh:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise CorruptResultsError(path, "is not a regular file (a device, pipe, socket or "
                                            "directory); a harness file is never one")
        if info.st_size > limit:
            raise CorruptResultsError(path, f"has {info.st_size} bytes, more than any harness "
                                            f"file ({limit})")
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise CorruptResultsError(path, f"grew past {limit} bytes while read")
    return data


def read_parquet(
    path: str | os.PathLike,
    *,
    columns: list[str] | None = None,
    n_rows: int | None = None,
    sha256: str | None = None,
) -> tuple[pd.DataFrame, dict]:
    """Read a Parquet file the harness wrote: (DataFrame, the `extra` metadata or {}).

    Checks, when given, the exact column list, the row count and the checksum; any mismatch,
    or a file that is not Parquet, raises `CorruptResultsError` naming the file.

    Parameters
    ----------
    path : str or PathLike, the file.
    columns : list of str, optional, the exact columns it must have.
    n_rows : int, optional, the row count it must have.
    sha256 : str, optional, the checksum its bytes must have.

    Returns
    -------
    (DataFrame, dict)
    """
    p = Path(path)
    try:
        data = read_bounded(p)
    except FileNotFoundError:
        raise CorruptResultsError(p, "missing") from None
    except OSError as exc:
        raise CorruptResultsError(p, f"cannot be read: {exc.strerror or exc}") from None
    if sha256 is not None and hashlib.sha256(data).hexdigest() != sha256:
        raise CorruptResultsError(
            p, "content differs from the checksum in meta.json (changed after the run was saved)"
        )
    df, extra = decode_parquet(data, p)
    check_frame(p, df, columns=columns, n_rows=n_rows)
    return df, extra


def check_frame(path: str | os.PathLike, df: pd.DataFrame, *, columns: list[str] | None = None,
                n_rows: int | None = None) -> None:
    """`CorruptResultsError` naming `path` when `df`'s columns or row count differ from the
    recorded ones (None: not checked).

    Parameters
    ----------
    path : str or PathLike, the file `df` came from (for the message).
    df : DataFrame, the table read.
    columns : list of str, optional, the recorded columns.
    n_rows : int, optional, the recorded row count.
    """
    if columns is not None and list(df.columns) != list(columns):
        raise CorruptResultsError(
            path, f"columns {list(map(str, df.columns))} differ from the recorded {list(columns)}"
        )
    if n_rows is not None and len(df) != n_rows:
        raise CorruptResultsError(path, f"has {len(df)} rows, meta.json records {n_rows}")


def read_json(path: Path) -> Any:
    """The parsed JSON file `path`; `CorruptResultsError` naming it when it is missing, not UTF-8,
    not JSON, or nested too deeply to be a harness file.

    Parameters
    ----------
    path : Path, the file.

    Returns
    -------
    any: the parsed value.
    """
    try:
        text = read_bounded(path).decode("utf-8")
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
