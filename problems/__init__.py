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
)


def builtin_problems() -> list:
    out = []
    for name in PROBLEM_MODULES:
        try:
            module = import_module(f"problems.{name}")
        except ModuleNotFoundError as exc:  # a module not written yet; never hides other errors
            if exc.name != f"problems.{name}":
                raise
            continue
        out.extend(module.PROBLEMS)
    return out
