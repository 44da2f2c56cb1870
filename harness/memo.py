"""JSON values kept on disk under a key, computed once across processes.

`kept(directory, key, compute)` returns the JSON value stored under `key` in
`<cache root>/<directory>/<key[:2]>/<key>.json`, else `compute()`, then stores it atomically.
The cache root is `harness.cache.cache_dir()` unless the caller names another (`root`): values
that follow from the code's own text alone belong under `code_dir()`, shared like compiled code.
A value not on disk is computed under an exclusive file lock of its key (`<key>.lock` beside
it; POSIX `flock`, released when its process ends however it ends), so processes that ask for
the same value at once compute it once: the others wait and read it. A file that cannot be read
or parsed is recomputed and replaced; a cache that cannot be written costs only time.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable
from typing import Any

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

from pathlib import Path

from harness.cache import cache_dir
from harness.errors import OutputError
from harness.store import atomic_write_bytes

__all__ = ["kept"]


def kept(directory: str, key: str, compute: Callable[[], Any], label: str = "",
         root: Callable[[], Path] = cache_dir) -> Any:
    """The JSON value stored under `key` in `<cache root>/<directory>`, else `compute()`, then
    stored (atomically). A file that cannot be read or parsed is recomputed and replaced; a
    cache that cannot be written costs only time.

    Parameters
    ----------
    directory : str, the folder under the cache root; key : str, the hex key (its first two
    characters name the subfolder); compute : callable with no argument returning JSON-serialisable
    data; label : str, the function's name stored with the value; root : callable with no
    argument returning the cache root (default `harness.cache.cache_dir`; `code_dir` for values
    of the code's text alone).

    Returns
    -------
    The stored or computed value.
    """
    try:
        path = root() / directory / key[:2] / f"{key}.json"
    except OutputError:  # no cache directory: the value is computed every time
        return compute()
    found = _read(path, key)
    if found:
        return found[0]
    with _key_lock(path):
        found = _read(path, key)  # computed by another process while this one waited
        if found:
            return found[0]
        value = compute()
        with contextlib.suppress(OutputError):
            atomic_write_bytes(path, json.dumps({"key": key, "function": label, "value": value}).encode())
    return value


def _read(path, key: str) -> tuple[Any] | None:
    """(value,) stored at `path` under `key`, or None when missing or unreadable."""
    with contextlib.suppress(OSError, ValueError, KeyError, TypeError):
        stored = json.loads(path.read_text())
        if stored["key"] == key:
            return (stored["value"],)
    return None


@contextlib.contextmanager
def _key_lock(path):
    """An exclusive lock on `path`'s `.lock` file while the value is computed; no lock (each
    process computes for itself) without `fcntl` or where the lock file cannot be made."""
    if fcntl is None:  # pragma: no cover - not POSIX
        yield
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle = open(path.with_suffix(".lock"), "a")  # noqa: SIM115 - held across the yield
    except OSError:
        yield
        return
    with handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
