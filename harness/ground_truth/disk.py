"""The on-disk cache of references: one file per (problem, level, times, initial states,
parameters), keyed also on the source of the ground-truth package."""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from typing import Any

import heyoka as hy
import numpy as np

from harness import cache
from harness.ground_truth.levels import REFERENCE_SCHEMA
from harness.problem import Problem
from harness.tolerances import CERTIFIER_TOL_FACTOR, REFERENCE_TOL_FACTOR


# -- disk cache ------------------------------------------------------------------------------------
def references_dir() -> Path:
    """The directory of cached references (`cache_dir()/references`), created if missing.

    Returns
    -------
    Path: the directory.
    """
    d = cache.cache_dir() / "references"
    d.mkdir(parents=True, exist_ok=True)
    return d


def _code_hash() -> str:
    """The source of every module of this package: a change to how references are computed or
    certified invalidates every cached reference, with no schema number to remember to bump."""
    global _CODE_HASH
    if _CODE_HASH is None:
        h = hashlib.sha256()
        for path in sorted(Path(__file__).parent.glob("*.py")):
            h.update(path.name.encode() + b"\n" + path.read_bytes())
        _CODE_HASH = h.hexdigest()
    return _CODE_HASH


_CODE_HASH: str | None = None


def reference_key(problem: Problem, level: str, times, t0, y0, pars) -> str:
    """The hash that names a cached reference: problem fingerprint, level, times, t0, initial
    states, parameters, tolerance factors, heyoka version and this package's source.

    Parameters
    ----------
    problem, level : what is integrated and at which precision level; times, t0, y0, pars : the
    request, as arrays.

    Returns
    -------
    str: A hex digest.
    """
    h = hashlib.sha256()
    for part in (
        f"schema={REFERENCE_SCHEMA}",
        _code_hash(),
        f"heyoka={hy.__version__}",
        f"tol={REFERENCE_TOL_FACTOR!r},{CERTIFIER_TOL_FACTOR!r}",
        problem.fingerprint(),
        level,
        repr(float(t0)),
    ):
        h.update(part.encode())
        h.update(b"\0")
    for arr in (times, y0, pars):
        a = np.ascontiguousarray(arr, dtype=np.float64)
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:40]


def cache_path(problem: Problem, level: str, key: str) -> Path:
    """The file of the cached reference `key` of `problem` at `level`.

    Parameters
    ----------
    problem : Problem, the problem (its name, made file-safe, starts the file name).
    level : str, the precision level.
    key : str, the request's hash.

    Returns
    -------
    Path: ``references_dir()/<name>-<level>-<key>.npz``.
    """
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in problem.name)
    return references_dir() / f"{safe}-{level}-{key}.npz"


def load_reference(path: Path, times: np.ndarray, shape: tuple[int, int, int]):
    """The arrays cached at `path`, or None when the file is missing, unreadable, or does not hold
    `times` and states of `shape` (a corrupt file is ignored and recomputed).

    Parameters
    ----------
    path : Path, the cached file.
    times : ndarray, the output times it must hold.
    shape : (int, int, int), the states' shape (nt, dim, N).

    Returns
    -------
    tuple or None: (y, error, floor, certified_by, compute_s), or None.
    """
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            y, error, floor, t = data["y"], data["error"], data["floor"], data["t"]
            certified_by = str(data["certified_by"])
            compute_s = float(data["compute_s"])
        if (
            y.shape != shape
            or error.shape != (shape[0], shape[2])
            or floor.shape != error.shape
            or not np.array_equal(t, times)
        ):
            return None
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(error)) and np.all(error >= 0)):
            return None
        return y, error, floor, certified_by, compute_s
    except Exception:  # a truncated or corrupt file is recomputed, never trusted
        return None


def store_reference(path: Path, **arrays: Any) -> None:
    """Write `arrays` to `path` as one .npz file, atomically (temporary file, then rename).

    Parameters
    ----------
    path : Path, the file to write.
    **arrays
        Named arrays (and scalars), as for `numpy.savez`.
    """
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem[:40] + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
