"""Checking a cell's rows: plain tidy data of the declared kinds (see `validate_rows`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from harness.errors import (
    HarnessError,
)
from harness.experiments.base import Experiment


class CellOutputError(HarnessError):
    """A cell returned something other than valid tidy rows."""



_KINDS = {
    "float": pd.api.types.is_float_dtype,
    "int": lambda s: pd.api.types.is_integer_dtype(s) and not pd.api.types.is_bool_dtype(s),
    "bool": pd.api.types.is_bool_dtype,
    "str": lambda s: pd.api.types.is_string_dtype(s) or pd.api.types.is_object_dtype(s),
}
SCALARS = (str, bool, int, float, np.bool_, np.integer, np.floating)


def validate_rows(experiment: Experiment, rows: Any) -> pd.DataFrame:
    """Check what `run_cell` returned; raise `CellOutputError` saying what is wrong.

    Always: a non-empty DataFrame with distinct, non-empty string column names, columns of
    numbers, booleans or strings (plain scalars; no complex values, lists or objects). Declared by
    the experiment: `row_dtypes` (column -> kind) and `finite_columns` (no NaN/inf there).

    Parameters
    ----------
    experiment : Experiment, the experiment that made the rows.
    rows : any, what its `run_cell` returned.

    Returns
    -------
    DataFrame: `rows`, checked.
    """
    if not isinstance(rows, pd.DataFrame):
        raise CellOutputError(f"run_cell returned {type(rows).__name__}, expected a pandas DataFrame")
    if len(rows) == 0:
        raise CellOutputError("run_cell returned no rows")
    cols = list(rows.columns)
    bad = [c for c in cols if not isinstance(c, str) or not c]
    if bad or isinstance(rows.columns, pd.MultiIndex):
        raise CellOutputError(f"column names must be non-empty strings, got {bad[:5]!r}")
    if len(set(cols)) != len(cols):
        dup = sorted({c for c in cols if cols.count(c) > 1})
        raise CellOutputError(f"column names must be distinct, repeated: {dup}")
    for c in cols:
        s = rows[c]
        if pd.api.types.is_complex_dtype(s):
            raise CellOutputError(f"column {c!r} is complex; store real and imaginary parts apart")
        if pd.api.types.is_object_dtype(s):
            odd = [type(v).__name__ for v in s if v is not None and not isinstance(v, SCALARS)
                   and not (isinstance(v, float) and math.isnan(v))]
            if odd:
                raise CellOutputError(
                    f"column {c!r} holds {odd[0]} values; rows must hold plain numbers or strings"
                )
    declared = getattr(experiment, "row_dtypes", None) or {}
    for c, kinds in dict(declared).items():
        kinds = (kinds,) if isinstance(kinds, str) else tuple(kinds)
        if c not in rows.columns:
            raise CellOutputError(f"column {c!r} is missing (declared in `row_dtypes`)")
        if not any(_KINDS[k](rows[c]) for k in kinds):
            raise CellOutputError(
                f"column {c!r} has dtype {rows[c].dtype}, declared {' or '.join(kinds)}"
            )
    for c in getattr(experiment, "finite_columns", None) or ():
        if c not in rows.columns:
            raise CellOutputError(f"column {c!r} is missing (declared in `finite_columns`)")
        s = rows[c]
        if pd.api.types.is_bool_dtype(s) or not pd.api.types.is_numeric_dtype(s):
            continue
        values = s.to_numpy(dtype=float, na_value=np.nan)
        where = np.flatnonzero(~np.isfinite(values))
        if where.size:
            raise CellOutputError(
                f"column {c!r} has {where.size} non-finite value(s) (NaN/inf) at rows "
                f"{where[:5].tolist()}"
            )
    return rows


