"""Rendered figures kept on disk, keyed by what they draw: a report of the same data draws nothing again.

A figure function's result (a `figure_svg.Figure`, or None) depends only on its arguments (data
frames, the palette, flags), the report's drawing code and matplotlib. `cached_call` hashes all
of them (the arguments pickled; the source of every module of the `harness` package, since a
figure may use any of it; matplotlib's version) and keeps the result as data, never as a
pickle (a shared cache directory must not run anyone's code): `<harness cache>/figures/<hash>.json`
holds the SVG, alt text and style rules, `<hash>.parquet` the figure's data table
(`harness.cache.cache_dir`, `HARNESS_CACHE_DIR`). Matplotlib
takes most of a report's build time, and a rerun whose cells all come from the cell cache hands
every figure function the same data, so the figures come from here. Any change of data or
drawing code changes the key; an unreadable entry is drawn again. Entries not read for
`MAX_AGE_DAYS` are removed when new ones are written.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import pickle  # only to hash the arguments; nothing is ever unpickled
import time
from collections.abc import Callable
from importlib.metadata import version
from pathlib import Path
from typing import Any

import pandas as pd

from harness.cache import cache_dir

__all__ = ["cached_call", "figure_cache_dir", "code_version", "keep_figures_of", "MAX_AGE_DAYS"]

# An entry nobody has read for this long belongs to an old run or old drawing code.
MAX_AGE_DAYS = 14
_DISABLE_ENV = "HARNESS_FIGURE_CACHE"  # "off": always draw


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """A hash of everything a figure's drawing depends on besides its arguments.

    Returns
    -------
    str: 20 hex digits of a SHA-256 over matplotlib's version and every module of `harness`.
    """
    h = hashlib.sha256(version("matplotlib").encode())
    package = Path(__file__).resolve().parent.parent  # all of `harness`: a figure may use any
    for f in sorted(package.rglob("*.py")):           # of it (the convergence fit, tolerances)
        h.update(str(f.relative_to(package)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:20]


def figure_cache_dir() -> Path | None:
    """`<harness cache>/figures`, or None when caching is off or the directory is unusable.

    Returns
    -------
    Path or None: the directory, created if needed.
    """
    if os.environ.get(_DISABLE_ENV, "").lower() in ("off", "0", "no"):
        return None
    try:
        d = cache_dir() / "figures"
        d.mkdir(parents=True, exist_ok=True)
        return d
    except Exception:  # noqa: BLE001  (no cache is never an error: the figure is drawn)
        return None


def _key(fn: Callable, args: tuple, kwargs: dict) -> str | None:
    try:
        payload = pickle.dumps((args, sorted(kwargs.items())), protocol=5)
    except Exception:  # noqa: BLE001  (an argument that cannot be pickled: draw, do not cache)
        return None
    h = hashlib.sha256(f"{fn.__module__}.{fn.__qualname__}|{code_version()}|".encode())
    h.update(payload)
    return h.hexdigest()[:40]


_figure_type: type | None = None


def keep_figures_of(cls: type) -> type:
    """Register the figure class whose results the cache keeps (`harness.kit.figure_svg`
    registers its `Figure`; this module imports no drawing code, so the two stay acyclic). Its
    objects have `slug`, `svg`, `alt`, `css` and `data` (a DataFrame or None) and are rebuilt
    from those fields. Until a class is registered nothing is cached.

    Parameters
    ----------
    cls : type, the figure class.

    Returns
    -------
    type: `cls`, so it can decorate the class.
    """
    global _figure_type
    _figure_type = cls
    return cls


def cached_call(fn: Callable, args: tuple, kwargs: dict) -> Any:
    """`fn(*args, **kwargs)`, from the cache when the same call was drawn before.

    Parameters
    ----------
    fn : callable, the drawing function.
    args, kwargs : tuple, dict, its arguments (part of the cache key).

    Returns
    -------
    Any: what `fn` returns, or the result stored for the same call.
    """
    directory = figure_cache_dir()
    key = _key(fn, args, kwargs) if directory is not None else None
    if key is None or directory is None:
        return fn(*args, **kwargs)
    path = directory / f"{key}.json"
    try:
        result = _read(path)
        with contextlib.suppress(OSError):
            os.utime(path)
        return result
    except Exception:  # noqa: BLE001  (missing or unreadable: draw it again)
        pass
    result = fn(*args, **kwargs)
    try:
        _write(directory, key, result)
        _prune(directory)
    except Exception:  # noqa: BLE001  (a full disk, a table Parquet cannot hold: not cached)
        pass
    return result


def _read(path: Path) -> Any:
    """The Figure (or None) kept at `path` (+ its `.parquet` table): JSON and Parquet only."""
    Figure = _figure_type
    if Figure is None:
        raise LookupError("no figure class registered")
    with open(path, encoding="utf-8") as fh:
        entry = json.load(fh)
    if entry is None:
        return None
    data = None
    if entry["data"]:
        data = pd.read_parquet(path.with_suffix(".parquet"))
    return Figure(str(entry["slug"]), str(entry["svg"]), str(entry["alt"]), data=data,
                  css=str(entry["css"]))


def _write(directory: Path, key: str, result: Any) -> None:
    if _figure_type is None or (result is not None and not isinstance(result, _figure_type)):
        return  # only figures are kept
    tmp = [directory / f".{key}.{os.getpid()}.{ext}.tmp" for ext in ("parquet", "json")]
    try:
        entry = None
        if result is not None:
            entry = {"slug": result.slug, "svg": result.svg, "alt": result.alt, "css": result.css,
                     "data": result.data is not None}
            if result.data is not None:
                result.data.to_parquet(tmp[0])
        with open(tmp[1], "w", encoding="utf-8") as fh:
            json.dump(entry, fh)
        if entry is not None and entry["data"]:
            os.replace(tmp[0], directory / f"{key}.parquet")
        os.replace(tmp[1], directory / f"{key}.json")  # last: the entry exists once complete
    finally:
        for t in tmp:
            with contextlib.suppress(OSError):
                t.unlink()


_pruned: set[Path] = set()


def _prune(directory: Path) -> None:
    """Remove entries not read for MAX_AGE_DAYS (once per process and directory)."""
    if directory in _pruned:
        return
    _pruned.add(directory)
    limit = time.time() - MAX_AGE_DAYS * 86400
    for entry in [*directory.glob("*.json"), *directory.glob("*.parquet"), *directory.glob("*.pkl")]:
        with contextlib.suppress(OSError):
            if entry.stat().st_mtime < limit:
                entry.unlink()
