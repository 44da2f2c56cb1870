"""The per-cell cache: one checked Parquet file per finished cell, named by the cell's key, and
one pack per finished experiment run (every cell's rows in one file, so a cached run reads one
file, not thousands); `encode_cell`/`decode_cell` are the only code that writes or reads their
format."""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness.cache import cache_dir
from harness.errors import InputError, OutputError, describe_os_error
from harness.provenance import to_jsonable
from harness.store.files import (
    arrow_table,
    atomic_write_bytes,
    decode_parquet,
    read_bounded,
    table_bytes,
)
from harness.store.schema import CELL_SCHEMA, CorruptResultsError

_CELL_KEY = re.compile(r"^[0-9a-f]{32}$")

# -- the cell cache -------------------------------------------------------------------------------
def _content_sha256(df: pd.DataFrame) -> str:
    """sha256 over a table's column names, dtypes and values (independent of Parquet's bytes,
    so it can live inside the file it checks). Numeric columns count by their bytes, text
    columns by pandas' 64-bit hash of each value (vectorised: a million-row pack in a fraction
    of a second), any other column by each value's repr."""
    h = hashlib.sha256()
    dtypes = list(df.dtypes)
    h.update(json.dumps([[str(c), str(d)] for c, d in zip(df.columns, dtypes, strict=True)]).encode())
    h.update(str(len(df)).encode())
    for (_, col), dtype in zip(df.items(), dtypes, strict=True):
        numeric = (dtype.kind in "biufc" if isinstance(dtype, np.dtype)
                   else pd.api.types.is_numeric_dtype(dtype))
        if numeric:
            h.update(np.ascontiguousarray(col.to_numpy()).tobytes())
            continue
        try:
            h.update(pd.util.hash_pandas_object(col, index=False).to_numpy().tobytes())
        except TypeError:  # unhashable values (lists, dicts): their text form
            h.update(json.dumps([None if v is None else repr(v) for v in col.tolist()]).encode())
    return h.hexdigest()


def _cell_schema(df: pd.DataFrame) -> dict[str, str]:
    return {str(c): str(d) for c, d in df.dtypes.items()}


def encode_cell(key: str, rows: pd.DataFrame, info: Mapping[str, Any]) -> tuple[pd.DataFrame, bytes]:
    """A finished cell as (its rows as they read back from the file, the file's bytes). The
    metadata holds `info`, the key, the schema, the column dtypes, the row count and the content
    checksum. Raises `InputError` when the rows cannot be stored as Parquet.

    Parameters
    ----------
    key : str, the cell's key.
    rows : DataFrame, its rows.
    info : mapping, its metadata (made JSON-safe).

    Returns
    -------
    (DataFrame, bytes)
    """
    plain = {**to_jsonable(dict(info)), "schema": CELL_SCHEMA, "key": key}
    table = arrow_table(rows)
    back = table.to_pandas()  # what a Parquet file of `table` reads back as (its Arrow schema)
    meta = {**plain, "columns": _cell_schema(back), "n_rows": int(len(back)),
            "content_sha256": _content_sha256(back)}
    return back, table_bytes(table, meta)


def decode_cell(data: bytes, path: str | os.PathLike, key: str | None = None) -> tuple[pd.DataFrame, dict]:
    """(rows, info) of a cell file's bytes, after checking its schema, key, columns, dtypes,
    row count and content checksum; `CorruptResultsError` naming `path` otherwise.

    Parameters
    ----------
    data : bytes, the file's content.
    path : str or PathLike, where it came from (for messages).
    key : str, optional, the key it must hold.

    Returns
    -------
    (DataFrame, dict)
    """
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
    `fresh=True`, which overwrites). A run reads through `get_or_discard`: a cache is only a
    copy, so a damaged entry is removed with a one-line warning and its cell computed again
    (damaged *results* stay an error: `harness.store.loading`). `put` writes atomically."""

    HINT = "; delete it, or recompute with fresh=True (--fresh), which overwrites it"

    def __init__(self, root: str | os.PathLike | None = None):
        if root is None:
            root = cache_dir()
        if not isinstance(root, str | os.PathLike) or not str(root):
            raise InputError(f"`cache_dir` must be a directory path, got {root!r}")
        self.root = Path(root) / "cells"

    def path(self, key: str) -> Path:
        """The file that holds the cell with key `key` (32 lowercase hex digits), existing or not.

        Parameters
        ----------
        key : str, the cell key; `InputError` otherwise.

        Returns
        -------
        Path: ``<root>/<key[:2]>/<key>.parquet``.
        """
        if not isinstance(key, str) or not _CELL_KEY.match(key):
            raise InputError(f"`key` must be 32 lowercase hex digits, got {key!r}")
        return self.root / key[:2] / f"{key}.parquet"

    def get(self, key: str) -> tuple[pd.DataFrame, dict] | None:
        """(rows, info) of a finished cell, or None when it is not cached.

        Parameters
        ----------
        key : str, the cell key.

        Returns
        -------
        (DataFrame, dict) or None: `CorruptResultsError` when the file exists but is damaged.
        """
        return self._read(self.path(key), key)

    def _read(self, p: Path, key: str) -> tuple[pd.DataFrame, dict] | None:
        try:
            if not p.is_file():
                if p.exists() or p.is_symlink():
                    raise CorruptResultsError(p, "is not a regular file" + self.HINT)
                return None
            data = read_bounded(p)
        except OSError as exc:
            message, _ = describe_os_error(exc, p)
            raise CorruptResultsError(p, f"cannot be read: {message}{self.HINT}") from None
        try:
            return decode_cell(data, p, key)
        except CorruptResultsError as exc:
            raise CorruptResultsError(p, exc.problem + self.HINT) from None

    def get_or_discard(self, key: str, kind: str = "cells") -> tuple[pd.DataFrame, dict] | None:
        """Like `get` (`kind='cells'`) or `get_pack` (`'packs'`, `'summaries'`), but a damaged
        entry is removed, named in one warning line on stderr, and read as missing.

        Parameters
        ----------
        key : str, the cell or pack key.
        kind : str, optional, 'cells' (default), 'packs' or 'summaries'.

        Returns
        -------
        (DataFrame, dict) or None
        """
        path = self.path(key) if kind == "cells" else self.pack_path(key, kind)
        try:
            return self._read(path, key)
        except CorruptResultsError as exc:
            self.discard(path, exc.problem.removesuffix(self.HINT))
            return None

    def discard(self, path: Path, reason: str) -> None:
        """Remove the damaged cache entry `path` with one warning line naming it; a directory
        where an entry belongs is left (and named) for the user to move.

        Parameters
        ----------
        path : Path, the damaged entry.
        reason : str, what is wrong with it (for the warning line).
        """
        if path.is_dir() and not path.is_symlink():
            print(f"harness: warning: cache entry {str(path)!r} is a directory; not used, "
                  "move it away", file=sys.stderr)
            return
        try:
            path.unlink()
            done = "discarded, recomputed"
        except OSError as err:
            done = f"could not be removed ({err.strerror or err}); recomputed"
        why = " ".join(reason.split())
        print(f"harness: warning: damaged cache entry {str(path)!r} {done} ({why})"[:600],
              file=sys.stderr)

    def check_writable(self) -> CellCache:
        """This cache, or `OutputError` (exit 77/73/74, one line naming the directory) when it
        cannot be written: found before any cell runs, not as every cell's failure.

        Returns
        -------
        CellCache: self.
        """
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            fd, probe = tempfile.mkstemp(prefix=".writable-", dir=self.root)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            message, status = describe_os_error(exc, self.root)
            raise OutputError(f"cache directory: {message} (set HARNESS_CACHE_DIR, or run "
                              "without the cache)", status) from None
        return self

    # -- packs: every cell of one experiment's run in one file --------------------------------------
    @staticmethod
    def pack_key(experiment: str, keys: Sequence[str]) -> str:
        """The key of the pack holding exactly the cells `keys` of `experiment`, in that order.

        Parameters
        ----------
        experiment : str, the experiment's name.
        keys : sequence of str, the cell keys, in order.

        Returns
        -------
        str: 32 lowercase hex digits.
        """
        text = "\n".join(["harness-pack", str(experiment), *keys])
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    def pack_path(self, key: str, kind: str = "packs") -> Path:
        """The file of the pack with key `key` (beside the cell files, under `packs/`; a run's
        cached summary under `summaries/`).

        Parameters
        ----------
        key : str, the pack key (32 lowercase hex digits).
        kind : str, optional, 'packs' (default) or 'summaries'.

        Returns
        -------
        Path
        """
        if not isinstance(key, str) or not _CELL_KEY.match(key):
            raise InputError(f"`key` must be 32 lowercase hex digits, got {key!r}")
        if kind not in ("packs", "summaries"):
            raise InputError(f"`kind` must be 'packs' or 'summaries', got {kind!r}")
        return self.root.parent / kind / key[:2] / f"{key}.parquet"

    def get_pack(self, key: str, kind: str = "packs") -> tuple[pd.DataFrame, dict] | None:
        """(rows of every cell, info) of a pack, or None; checked like a cell file.

        Parameters
        ----------
        key : str, the pack key.
        kind : str, optional, 'packs' (default) or 'summaries'.

        Returns
        -------
        (DataFrame, dict) or None
        """
        return self._read(self.pack_path(key, kind), key)

    def put_pack(self, key: str, rows: pd.DataFrame, info: Mapping[str, Any],
                 kind: str = "packs") -> pd.DataFrame:
        """Write a pack atomically; return its rows as they read back from the file.

        Parameters
        ----------
        key : str, the pack key.
        rows : DataFrame, every cell's rows.
        info : mapping, the pack's metadata.
        kind : str, optional, 'packs' (default) or 'summaries'.

        Returns
        -------
        DataFrame
        """
        back, data = encode_cell(key, rows, info)
        atomic_write_bytes(self.pack_path(key, kind), data)
        return back

    def put(self, key: str, rows: pd.DataFrame, info: Mapping[str, Any]) -> Path:
        """Write a finished cell (encoded by `encode_cell`) atomically; return its path.

        Parameters
        ----------
        key : str, the cell key.
        rows : DataFrame, its rows.
        info : mapping, its metadata.

        Returns
        -------
        Path
        """
        _, data = encode_cell(key, rows, info)
        return self.put_encoded(key, data)

    def put_encoded(self, key: str, data: bytes) -> Path:
        """Write the bytes `encode_cell` made for `key` atomically; return the path.

        Parameters
        ----------
        key : str, the cell key.
        data : bytes, what `encode_cell` returned for it.

        Returns
        -------
        Path
        """
        p = self.path(key)
        atomic_write_bytes(p, data)
        return p

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and bool(_CELL_KEY.match(key)) and self.path(key).exists()

    def __len__(self) -> int:
        if not self.root.is_dir():
            return 0
        return sum(1 for _ in self.root.glob("??/*.parquet"))
