"""Performance history: asv's result files as one tidy table, for the report's history section.

asv (airspeed velocity, https://asv.readthedocs.io, result format version 2) writes one JSON file
per (machine, commit, environment) under `results_dir/<machine>/`, next to that machine's
`machine.json`, and a `benchmarks.json` with each benchmark's type, unit and parameter names at
the top of `results_dir`. In a result file, `results[name]` is a row whose columns are named by
`result_columns`: `result` (a number, or one number per parameter combination, in the order of
the Cartesian product of `params`), `params` (the parameter values as Python literals), ...;
`date` is the commit's time in milliseconds since the epoch.

`load_history()` returns one row per (benchmark, parameter combination, commit, machine) with a
finite value; skipped and failed benchmarks (null results) are left out. The report draws it;
asv's own dashboard loads its scripts from the internet.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import pandas as pd

from harness.errors import InputError

__all__ = ["load_history", "HISTORY_COLUMNS"]

HISTORY_COLUMNS = ["benchmark", "params", "commit", "date", "value", "unit", "machine"]
_UNIT_OF_TYPE = {"time": "seconds", "peakmem": "bytes", "mem": "bytes"}


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _benchmark_meta(results_dir: Path) -> dict:
    data = _read_json(results_dir / "benchmarks.json")
    return data if isinstance(data, dict) else {}


def _unit(meta: dict) -> str:
    unit = meta.get("unit")
    if unit and unit != "unit":
        return str(unit)
    return _UNIT_OF_TYPE.get(meta.get("type", ""), "unit")


def _label(names: list[str], values: tuple[str, ...]) -> str:
    if not values:
        return ""
    if len(names) != len(values):
        names = [f"param{i + 1}" for i in range(len(values))]
    return ", ".join(f"{n}={v}" for n, v in zip(names, values, strict=True))


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _rows_of_file(data: dict, machine: str, meta: dict) -> list[dict]:
    columns = data.get("result_columns") or ["result", "params"]
    try:
        result_at, params_at = columns.index("result"), columns.index("params")
    except ValueError:
        return []
    commit = str(data.get("commit_hash", ""))
    date = pd.to_datetime(data.get("date"), unit="ms", utc=True) if data.get("date") else pd.NaT
    machine = str((data.get("params") or {}).get("machine", machine))
    rows = []
    for name, row in (data.get("results") or {}).items():
        if not isinstance(row, list) or len(row) <= result_at:
            continue
        result = row[result_at]
        params = row[params_at] if len(row) > params_at and row[params_at] else []
        info = meta.get(name, {}) if isinstance(meta.get(name), dict) else {}
        names = list(info.get("param_names") or [])
        if params:
            combos = list(itertools.product(*params))
            values = result if isinstance(result, list) else [result]
        else:
            combos, values = [()], [result[0] if isinstance(result, list) and result else result]
        for combo, value in zip(combos, values, strict=False):
            if not _finite(value):
                continue
            rows.append({
                "benchmark": name,
                "params": _label(names, tuple(map(str, combo))),
                "commit": commit,
                "date": date,
                "value": float(value),
                "unit": _unit(info),
                "machine": machine,
            })
    return rows


def load_history(results_dir: str | Path = ".asv/results") -> pd.DataFrame:
    """Every finite asv result under `results_dir` as a DataFrame with columns
    benchmark, params, commit, date, value, unit, machine (sorted by date); an empty DataFrame
    with these columns when there are none. Unreadable files are skipped.

    Parameters
    ----------
    results_dir : str or Path, asv's results folder (InputError for another type).

    Returns
    -------
    DataFrame: the results, one row per benchmark, parameter set and commit.
    """
    if not isinstance(results_dir, str | Path):
        raise InputError(f"`results_dir` must be a path, got {type(results_dir).__name__}")
    root = Path(results_dir)
    rows: list[dict] = []
    if root.is_dir():
        meta = _benchmark_meta(root)
        for machine_dir in sorted(p for p in root.iterdir() if p.is_dir()):
            for path in sorted(machine_dir.glob("*.json")):
                if path.name == "machine.json":
                    continue
                data = _read_json(path)
                if isinstance(data, dict) and "results" in data:
                    rows.extend(_rows_of_file(data, machine_dir.name, meta))
    frame = pd.DataFrame(rows, columns=HISTORY_COLUMNS)
    if frame.empty:
        frame["date"] = pd.to_datetime(frame["date"], utc=True)
        frame["value"] = frame["value"].astype(float)
        return frame
    return frame.sort_values(["date", "benchmark", "params"], kind="stable").reset_index(drop=True)
