"""File schemas, the keys a saved run's meta.json must hold, and the errors a bad results file raises."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd

from harness.errors import HarnessError

SCHEMA = "harness-results/1"
# A cell file's content checksum hashes its text columns with pandas' own hashing
# (`pandas.util.hash_pandas_object`): pandas' version is part of the schema, so a cache written
# under another pandas is never read (the cells' keys change and they are measured again).
CELL_SCHEMA = f"harness-cell/3+pandas-{pd.__version__}"
# meta.json nested deeper than this is not one the harness wrote (it nests about 6 deep)
MAX_META_DEPTH = 64
TABLES = ("rows", "summary")
META_KEYS = ("schema", "run_id", "created_utc", "provenance", "config", "experiments", "totals")
EXPERIMENT_KEYS = ("wall_s", "n_cells", "computed_cells", "cached_cells", "failed_cells", "tables",
                   "failures", "skips", "cells")

SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,99}$")


class ResultsError(HarnessError):
    """A results directory or run cannot be found or written (the message says which)."""


class CorruptResultsError(ResultsError):
    """A results file is unreadable or is not what the harness wrote; `path` names it."""

    def __init__(self, path: str | Path, problem: str):
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"results file {str(path)!r}: {problem}")
