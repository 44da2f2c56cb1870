"""Where a result came from: code version, library versions, machine, date, configuration.

Every saved run carries this record in its `meta.json` (see `harness.store`), so a number in a
report can be traced to the exact code and settings that produced it. Nothing here fails: a
missing `git`, a tree that is not a repository, or a library that is not installed is recorded
as `None`, never raised.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import platform
import subprocess
from collections.abc import Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from harness import __version__

__all__ = [
    "PROJECT_ROOT",
    "git_info",
    "versions",
    "cpu_model",
    "machine_info",
    "utc_now",
    "collect",
    "to_jsonable",
]

PROJECT_ROOT = Path(__file__).resolve().parent.parent

# Distributions whose versions decide the numbers a run produces (import name -> dist name).
_DISTRIBUTIONS = {
    "numpy": "numpy",
    "scipy": "scipy",
    "heyoka": "heyoka",
    "pandas": "pandas",
    "matplotlib": "matplotlib",
    "pyarrow": "pyarrow",
    "joblib": "joblib",
    "dask": "dask",
    "distributed": "distributed",
    "numba": "numba",
}


def default_directory(given: Any, env_var: str, name: str) -> Any:
    """`given` when it is not None, else the environment variable `env_var` when set, else
    `<project>/<name>` (the current directory's `<name>` when the package is installed outside
    a checkout). The caller checks what it gets.

    Parameters
    ----------
    given : the directory the caller was given, or None; env_var : str, the environment variable
    read next; name : str, the folder's name under the project.

    Returns
    -------
    `given` itself, the variable's string, or a Path.
    """
    if given is not None:
        return given
    env = os.environ.get(env_var)
    if env:
        return env
    base = PROJECT_ROOT if (PROJECT_ROOT / "pyproject.toml").exists() else Path.cwd()
    return base / name


def _git(args: list[str], cwd: Path) -> str | None:
    try:
        proc = subprocess.run(
            ["git", *args],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    if proc.returncode != 0:
        return None
    return proc.stdout.strip()


def git_info(root: str | Path | None = None) -> dict[str, Any]:
    """`{"sha", "short_sha", "dirty", "available"}` of the checkout at `root` (default: the
    project). `dirty` is True when tracked files differ from the commit; all values are None when
    `git` is missing or `root` is not inside a repository.

    Parameters
    ----------
    root : str, Path or None, a folder inside the checkout.

    Returns
    -------
    dict: the four fields above.
    """
    where = Path(root) if root is not None else PROJECT_ROOT
    sha = _git(["rev-parse", "HEAD"], where) if where.is_dir() else None
    if not sha:
        return {"sha": None, "short_sha": None, "dirty": None, "available": False}
    status = _git(["status", "--porcelain", "--untracked-files=no"], where)
    return {
        "sha": sha,
        "short_sha": sha[:7],
        "dirty": None if status is None else bool(status),
        "available": True,
    }


def versions() -> dict[str, str | None]:
    """Versions of Python, the harness and the numerical libraries (None when not installed).

    Read from the installed distributions' metadata, so nothing heavy is imported.

    Returns
    -------
    dict: name -> version string or None; 'python' and 'harness' always set.
    """
    out: dict[str, str | None] = {"python": platform.python_version(), "harness": __version__}
    for name, dist in _DISTRIBUTIONS.items():
        try:
            out[name] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def cpu_model() -> str:
    """The CPU's model name (Linux: /proc/cpuinfo), else what `platform` knows.

    Returns
    -------
    str: the model name; 'unknown' when nothing says.
    """
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine_info() -> dict[str, Any]:
    """CPU model, logical cores, total memory, operating system.

    Returns
    -------
    dict: 'cpu', 'logical_cores', 'memory_bytes' (None without psutil), 'os', 'machine'.
    """
    try:
        import psutil

        memory = int(psutil.virtual_memory().total)
    except Exception:  # psutil missing or unsupported platform
        memory = None
    return {
        "cpu": cpu_model(),
        "logical_cores": os.cpu_count(),
        "memory_bytes": memory,
        "os": platform.platform(),
        "machine": platform.machine(),
    }


def utc_now() -> _dt.datetime:
    """The current time, timezone-aware in UTC.

    Returns
    -------
    datetime.datetime: now.
    """
    return _dt.datetime.now(_dt.UTC)


def to_jsonable(value: Any) -> Any:
    """`value` as plain JSON data: NumPy scalars and arrays become numbers and lists, tuples
    become lists, non-finite floats become the strings 'nan', 'inf', '-inf', anything else its
    `repr`. Used for configurations, which may hold any Python value.

    Parameters
    ----------
    value : any Python value (mappings and sequences converted recursively, sets sorted by repr).

    Returns
    -------
    None, bool, int, float, str, list or dict.
    """
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        return int(value)
    if isinstance(value, float | np.floating):
        x = float(value)
        return x if math.isfinite(x) else repr(x)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        items = sorted(value, key=repr) if isinstance(value, set | frozenset) else value
        return [to_jsonable(v) for v in items]
    if isinstance(value, Path):
        return str(value)
    return repr(value)


def collect(config: Mapping[str, Any] | None = None, *, root: str | Path | None = None) -> dict:
    """The full provenance record of a run started now with `config`.

    Parameters
    ----------
    config : the run's settings (made JSON-safe by `to_jsonable`), or None; root : the checkout
    for `git_info` (default: the project).

    Returns
    -------
    dict: 'date_utc', 'git', 'versions', 'machine', 'config'; JSON-serialisable.
    """
    record = {
        "date_utc": utc_now().isoformat(timespec="seconds"),
        "git": git_info(root),
        "versions": versions(),
        "machine": machine_info(),
        "config": to_jsonable(dict(config or {})),
    }
    json.dumps(record)  # always serialisable by construction
    return record
