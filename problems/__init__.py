"""The problem catalogue: one module per problem family, symbolic definitions only.

Every built-in problem is registered here, in one place: each module exports `PROBLEMS`.
"""

from importlib import import_module

__all__ = ["builtin_problems", "PROBLEM_MODULES"]

PROBLEM_MODULES = (
    "scalar",
    "oscillators",
    "kepler",
    "many_body",
    "stiff",
    "planetary",
    "detest",
    "bari",
)


def builtin_problems() -> list:
    """Every problem of the modules in PROBLEM_MODULES, in that order. A module that cannot be
    imported (deleted, renamed) is an error, never a silently smaller catalogue.

    Returns
    -------
    list of Problem
    """
    return [p for name in PROBLEM_MODULES for p in import_module(f"problems.{name}").PROBLEMS]
