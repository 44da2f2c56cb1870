"""Steppers: coefficient tables (data) plus one step loop per family.

Every built-in stepper is registered here, in one place: each family module exports a list
`STEPPERS`, and `builtin_steppers()` concatenates them in the order below.
"""

from importlib import import_module

__all__ = ["builtin_steppers", "FAMILY_MODULES"]

FAMILY_MODULES = (
    "runge_kutta",
    "splitting",
    "verlet",
    "taylor",
    "implicit_rk",
    "multistep",
    "external",
    "compiled",
    "step_control",
)


def builtin_steppers() -> list:
    out = []
    for name in FAMILY_MODULES:
        try:
            module = import_module(f"implementations.{name}")
        except ModuleNotFoundError as exc:  # a family not written yet; never hides other errors
            if exc.name != f"implementations.{name}":
                raise
            continue
        out.extend(module.STEPPERS)
    return out
