"""Steppers: coefficient tables (data) plus one step loop per family.

Every built-in stepper is registered here, in one place: each family module exports a list
`STEPPERS`, and `builtin_steppers()` concatenates them in the order below.
"""

import threading
from importlib import import_module

from harness.stepper import StepperInfo

__all__ = [
    "ProblemCache", "builtin_steppers", "coefficient_info", "unavailable_steppers",
    "FAMILY_MODULES", "OPTIONAL_MODULES", "optional_library",
]

FAMILY_MODULES = (
    "runge_kutta",
    "splitting",
    "verlet",
    "second_order_multistep",
    "taylor",
    "implicit_rk",
    "multistep",
    "external",
    "compiled",
    "step_control",
    "rebound_adapter",
    "sundials_adapter",
)
# Adapters of outside libraries whose package is an optional extra: they register no steppers
# when it is missing and say so in `UNAVAILABLE` (listed by `unavailable_steppers()`).
OPTIONAL_MODULES = ("rebound_adapter", "sundials_adapter")


def optional_library(module: str, *, package: str, version: str, extra: str, label: str):
    """Import an optional adapter's library, which may be missing.

    Parameters
    ----------
    module : what to import (e.g. 'sksundae.cvode'); package : its name on PyPI; version : the
    pinned version; extra : the project's optional extra that installs it; label : how the
    message names the library.

    Returns
    -------
    (module or None, install command, the adapter's `UNAVAILABLE`: {} when the import worked,
    else {package: what is missing and how to install it})
    """
    install = f"pip install {package}=={version}  (or: pip install .[{extra}])"
    try:
        library = import_module(module)
    except ImportError:
        return None, install, {package: f"{label} is not installed; install it with: {install}"}
    return library, install, {}


class ProblemCache:
    """What a stepper builds once per problem (and settings) and its runs share, behind a lock.
    Pickled empty: a worker process rebuilds what it needs instead of receiving compiled objects
    (heyoka integrators are not picklable)."""

    def __init__(self):
        self._items: dict = {}
        self._lock = threading.Lock()

    def get(self, key, build):
        """The object stored under `key`, built by `build()` on first use (once, under the lock).

        Parameters
        ----------
        key : hashable, what identifies the object; build : callable with no argument.

        Returns
        -------
        The stored object.
        """
        with self._lock:
            if key not in self._items:
                self._items[key] = build()
            return self._items[key]

    def __len__(self) -> int:
        return len(self._items)

    def __reduce__(self):
        return (ProblemCache, ())


def _modules(names: tuple[str, ...]) -> list:
    """The family modules `names`, imported. A module that cannot be imported (deleted, renamed)
    is an error, never a silently smaller registry; an optional adapter whose library is missing
    still imports and says so in its `UNAVAILABLE`."""
    return [import_module(f"implementations.{name}") for name in names]


def builtin_steppers() -> list:
    """Every stepper of the modules in FAMILY_MODULES, in that order.

    Returns
    -------
    list of Stepper: the built-in steppers.
    """
    return [s for module in _modules(FAMILY_MODULES) for s in module.STEPPERS]


def coefficient_info(coefficients, *, family: str, form: str = "first-order", **fields):
    """The `StepperInfo` of a stepper that runs `coefficients`: its name, symplecticity and
    symmetry are asked of the coefficients (False where the family has no such notion, as for
    linear multistep methods' symplecticity), never typed by hand; a Newtonian form is for
    velocity-independent forces. `fields` gives the rest (claimed order, cost, reference) and
    may override a derived value.

    Parameters
    ----------
    coefficients : the coefficient object; family : str, the stepper family; form : str,
    'first-order' or 'newtonian'; fields : further StepperInfo fields.

    Returns
    -------
    StepperInfo: the derived values, `fields` applied over them.
    """
    derived = {
        "name": coefficients.name,
        "symplectic": bool(getattr(coefficients, "symplectic", False)),
        "symmetric": bool(getattr(coefficients, "symmetric", False)),
        "velocity_dependent": form != "newtonian",
    }
    return StepperInfo(family=family, form=form, **{**derived, **fields})


def unavailable_steppers() -> dict[str, str]:
    """Optional adapters whose library is not installed: library -> how to install it. A module
    says so in `UNAVAILABLE` and registers no steppers, instead of failing to import.

    Returns
    -------
    dict: library name -> installation hint.
    """
    out: dict[str, str] = {}
    for module in _modules(FAMILY_MODULES + OPTIONAL_MODULES):
        out.update(getattr(module, "UNAVAILABLE", {}))
    return out
