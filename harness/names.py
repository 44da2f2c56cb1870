"""Names of steppers, problems and method records: one check of their type, length and
characters, so a name can become a file name, a table cell and a terminal line safely."""

from __future__ import annotations

import unicodedata
from typing import Any

from harness.errors import InputError
from harness.tolerances import MAX_NAME_LENGTH

__all__ = ["check_name"]


def check_name(name: Any, what: str) -> str:
    """`name` when it is a usable name, else `InputError` naming `what` and the rule.

    Parameters
    ----------
    name : the name given; what : how the message names it (e.g. "problem `name`").

    Returns
    -------
    str: the name, unchanged.
    """
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"{what} must be a non-empty string, got {name!r}"[:300])
    if len(name) > MAX_NAME_LENGTH:
        raise InputError(f"{what} must have at most {MAX_NAME_LENGTH} characters, got "
                         f"{len(name)} ({name[:40]!r}...)")
    bad = sorted({c for c in name if unicodedata.category(c) in ("Cc", "Cf", "Cs", "Zl", "Zp")})
    if bad:
        raise InputError(f"{what} must not contain control characters, got {name!r} "
                         f"(characters {', '.join(repr(c) for c in bad)})")
    return name
