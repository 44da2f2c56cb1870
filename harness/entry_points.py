"""Entry-point groups read the one way every registry reads them: this project's own entries
(the built-ins) first, then other distributions' in a fixed order.

Used by the stepper and problem registries (`harness.registry`), the experiment list
(`harness.experiments.base`) and the step loops (`harness.step_loops`); kept in the foundation
layer so that each of them can read its group without importing the others.
"""

from __future__ import annotations

import re
from importlib import metadata

from harness import DISTRIBUTION

__all__ = ["group_entry_points", "missing_builtins"]


def _dist_name(ep: metadata.EntryPoint) -> str:
    """The normalized name of the distribution declaring `ep` ('' when unknown)."""
    dist = getattr(ep, "dist", None)
    return re.sub(r"[-_.]+", "-", dist.name).lower() if dist is not None and dist.name else ""


def _is_own(ep: metadata.EntryPoint) -> bool:
    """Declared by this project's own distribution: a built-in."""
    return _dist_name(ep) == DISTRIBUTION


def group_entry_points(group: str) -> tuple[list, list]:
    """The installed entry points of `group`.

    Parameters
    ----------
    group : str, the entry-point group, e.g. 'harness.steppers'.

    Returns
    -------
    (this project's own, sorted by name; every other distribution's, sorted by distribution: and name)
    """
    eps = list(metadata.entry_points(group=group))
    own = sorted((ep for ep in eps if _is_own(ep)), key=lambda ep: ep.name)
    others = sorted((ep for ep in eps if not _is_own(ep)), key=lambda ep: (_dist_name(ep), ep.name))
    return own, others


def missing_builtins(kind: str, group: str) -> str:
    """The error of a registry whose built-in entry points are not installed.

    Parameters
    ----------
    kind : str, what the group registers ('stepper', 'problem', 'experiment', 'step loop').
    group : str, the entry-point group.

    Returns
    -------
    str, one line naming the group and how to install it.
    """
    return (f"no built-in {kind}s: the {group!r} entry points of {DISTRIBUTION} are not "
            "installed; install the project (`make setup`, or `pip install -e .`)")
