"""Rendered figures kept on disk, keyed by what they draw: a report of the same data draws nothing again.

A figure function's result (a `figure_svg.Figure`, or None) depends only on its arguments (data
frames, the palette, flags), the report's drawing code and matplotlib. `cached_call` hashes all
of them (the arguments pickled; the source of every module of the `harness` package, since a
figure may use any of it; matplotlib's version) and keeps the result in
`<harness cache>/figures/<hash>.pkl` (`harness.cache.cache_dir`, `HARNESS_CACHE_DIR`). Matplotlib
takes most of a report's build time, and a rerun whose cells all come from the cell cache hands
every figure function the same data, so the figures come from here. Any change of data or
drawing code changes the key; an unreadable entry is drawn again. Entries not read for
`MAX_AGE_DAYS` are removed when new ones are written.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import pickle
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["cached_call", "figure_cache_dir", "code_version", "MAX_AGE_DAYS"]

# An entry nobody has read for this long belongs to an old run or old drawing code.
MAX_AGE_DAYS = 14
_DISABLE_ENV = "HARNESS_FIGURE_CACHE"  # "off": always draw


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """A hash of everything a figure's drawing depends on besides its arguments."""
    from importlib.metadata import version  # without importing matplotlib (a second)

    h = hashlib.sha256(version("matplotlib").encode())
    package = Path(__file__).resolve().parent.parent  # all of `harness`: a figure may use any
    for f in sorted(package.rglob("*.py")):           # of it (the convergence fit, tolerances)
        h.update(str(f.relative_to(package)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:20]


def figure_cache_dir() -> Path | None:
    """`<harness cache>/figures`, or None when caching is off or the directory is unusable."""
    if os.environ.get(_DISABLE_ENV, "").lower() in ("off", "0", "no"):
        return None
    try:
        from harness.cache import cache_dir

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


def cached_call(fn: Callable, args: tuple, kwargs: dict) -> Any:
    """`fn(*args, **kwargs)`, from the cache when the same call was drawn before."""
    directory = figure_cache_dir()
    key = _key(fn, args, kwargs) if directory is not None else None
    if key is None or directory is None:
        return fn(*args, **kwargs)
    path = directory / f"{key}.pkl"
    try:
        with open(path, "rb") as fh:
            result = pickle.load(fh)
        with contextlib.suppress(OSError):
            os.utime(path)
        return result
    except Exception:  # noqa: BLE001  (missing or unreadable: draw it again)
        pass
    result = fn(*args, **kwargs)
    tmp = directory / f".{key}.{os.getpid()}.tmp"
    try:
        with open(tmp, "wb") as fh:
            pickle.dump(result, fh, protocol=5)
        os.replace(tmp, path)
        _prune(directory)
    except Exception:  # noqa: BLE001  (a full disk does not stop the report)
        with contextlib.suppress(OSError):
            tmp.unlink()
    return result


_pruned: set[Path] = set()


def _prune(directory: Path) -> None:
    """Remove entries not read for MAX_AGE_DAYS (once per process and directory)."""
    if directory in _pruned:
        return
    _pruned.add(directory)
    limit = time.time() - MAX_AGE_DAYS * 86400
    for entry in directory.glob("*.pkl"):
        with contextlib.suppress(OSError):
            if entry.stat().st_mtime < limit:
                entry.unlink()
