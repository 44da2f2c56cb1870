"""The source text of a class or function, read once per version of its file.

`inspect.getsource` re-reads and re-parses the whole defining module on every call (tens of
milliseconds for a class); fingerprints ask for the same classes for every cell of a run. The
answer is cached on the object and its file's (path, mtime, size), so an edited file is read
again and a cached answer never outlives the source it came from.
"""

from __future__ import annotations

import functools
import inspect
import os

__all__ = ["source_of"]


def source_of(obj: object) -> str:
    """`inspect.getsource(obj)`, cached per version of the file that defines `obj`.

    Raises what `inspect.getsource` raises (`OSError` when there is no source, `TypeError` for
    a built-in object).

    Parameters
    ----------
    obj : a module, class, function or method.

    Returns
    -------
    str: the source text.
    """
    path = inspect.getsourcefile(obj)  # type: ignore[arg-type]
    if path is None or not os.path.isfile(path):
        return inspect.getsource(obj)  # type: ignore[arg-type]
    st = os.stat(path)
    return _cached(obj, path, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=1024)
def _cached(obj: object, path: str, mtime_ns: int, size: int) -> str:
    return inspect.getsource(obj)  # type: ignore[arg-type]
