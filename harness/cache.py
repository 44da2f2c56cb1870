"""Where the harness keeps compiled code: one directory it controls.

`HARNESS_CACHE_DIR` overrides the default `.cache/` at the project root (or the current
directory when the package is installed elsewhere). heyoka's on-disk JIT cache lives in its
`heyoka/` subfolder, so compiled right-hand sides and Taylor integrators survive across processes.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_dir", "configure_heyoka_cache"]

_configured: Path | None = None


def cache_dir() -> Path:
    """The harness's cache root, created when missing (`OutputError` naming the path when it
    cannot be)."""
    env = os.environ.get("HARNESS_CACHE_DIR")
    if env:
        root = Path(env)
    else:
        project = Path(__file__).resolve().parent.parent
        root = project / ".cache" if (project / "pyproject.toml").exists() else Path.cwd() / ".cache"
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file where the directory belongs, no permission, ...
        from harness.errors import OutputError, describe_os_error

        raise OutputError(*describe_os_error(exc, root)) from None
    return root


def configure_heyoka_cache() -> Path:
    """Point heyoka's on-disk JIT cache at the harness's cache directory (once per process)."""
    global _configured
    target = cache_dir() / "heyoka"
    if _configured != target:
        import heyoka as hy

        target.mkdir(parents=True, exist_ok=True)
        hy.llvm_state.set_diskcache_path(str(target))
        _configured = target
    return target
