"""The records a command prints: JSON, or a plain-text table, into the command's output
(`harness.cli.output`); and why each requested pair of a run over zero applicable cells does not
apply."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from harness.cli.output import output_buffer

__all__ = ["explain_skips", "print_json", "print_table"]


def explain_skips(skips: Sequence[dict], as_json: bool) -> None:
    """Why each requested pair does not apply: JSON records or a table, on stdout.

    Parameters
    ----------
    skips : sequence of dict, skip records (stepper, problem, reason, ...).
    as_json : bool, print JSON records instead of a table.
    """
    if as_json:
        print_json([dict(r, verdict="not-applicable", passed=False) for r in skips])
        return

    print("not applicable:", file=output_buffer())
    print_table(pd.DataFrame(list(skips), columns=["experiment", "stepper", "problem", "reason"]),
                 ["experiment", "stepper", "problem", "reason"])


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def print_json(records: Any) -> None:
    """Print `records` as indented JSON to the command's output.

    Parameters
    ----------
    records : any, JSON-able data (NumPy and pandas values converted).
    """
    print(json.dumps(_jsonable(records), indent=2), file=output_buffer())


def print_table(frame, columns: Sequence[str]) -> None:
    """Print the `columns` of `frame` as a plain-text table to the command's output.

    Parameters
    ----------
    frame : DataFrame
    columns : sequence of str, the columns shown.
    """
    if frame.empty:
        print("(none)", file=output_buffer())
        return
    cols = [c for c in columns if c in frame.columns]
    with pd.option_context("display.max_rows", None, "display.max_columns", None,
                           "display.width", 200, "display.max_colwidth", 70):
        print(frame[cols].to_string(index=False, float_format=lambda x: f"{x:.4g}"), file=output_buffer())


