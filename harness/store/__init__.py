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

Modules: `schema` (schemas, errors), `files` (atomic writes, checked Parquet and JSON), `runs`
(run ids, saving a run), `loading` (reading a run back), `cells` (the per-cell cache).
"""

from __future__ import annotations

import os  # noqa: F401  (tests replace `store.os.replace` to simulate a failing disk)

from harness.store.cells import (
    CellCache,
    decode_cell,
    encode_cell,
)
from harness.store.files import (
    atomic_write_bytes,
    atomic_write_json,
    atomic_writer,
    decode_parquet,
    encode_parquet,
    read_parquet,
    write_parquet,
)
from harness.store.loading import (
    StoredRun,
    load_run,
)
from harness.store.runs import (
    RUN_ID,
    list_runs,
    new_run_id,
    resolve_run,
    results_root,
    save_run,
)
from harness.store.schema import (
    CELL_SCHEMA,
    SCHEMA,
    TABLES,
    CorruptResultsError,
    ResultsError,
)

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
    "RUN_ID",
]
