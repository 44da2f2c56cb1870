"""Steppers: coefficient tables (data) plus one step loop per family.

Every built-in stepper is registered here, in one place: each family module exports a list
`STEPPERS`, and `builtin_steppers()` concatenates them in the order below.
"""

from importlib import import_module

__all__ = ["builtin_steppers", "unavailable_steppers", "FAMILY_MODULES", "OPTIONAL_MODULES"]

FAMILY_MODULES = (
    "runge_kutta",
    "splitting",
    "verlet",
    "taylor",
    "implicit_rk",
    "multistep",
    "external",
    "compiled",
)
# Adapters of outside libraries, registered with `--plugin implementations/<module>.py` (or by
# adding them to FAMILY_MODULES once the gate's rules cover what they measure; see each module).
OPTIONAL_MODULES = ("rebound_adapter",)


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


def unavailable_steppers() -> dict[str, str]:
    """Optional adapters whose library is not installed: library -> how to install it. A module
    says so in `UNAVAILABLE` and registers no steppers, instead of failing to import."""
    out: dict[str, str] = {}
    for name in FAMILY_MODULES + OPTIONAL_MODULES:
        try:
            module = import_module(f"implementations.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"implementations.{name}":
                raise
            continue
        out.update(getattr(module, "UNAVAILABLE", {}))
    return out
