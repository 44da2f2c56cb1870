"""Steppers: coefficient tables (data) plus one step loop per family.

Every built-in stepper is registered here, in one place: each family module exports a list
`STEPPERS`, and `builtin_steppers()` concatenates them in the order below.
"""

from importlib import import_module

__all__ = ["builtin_steppers", "build_stepper", "unavailable_steppers", "FAMILY_MODULES", "OPTIONAL_MODULES"]

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
    "rebound_adapter",
)
# Adapters of outside libraries whose package is an optional extra: they register no steppers
# when it is missing and say so in `UNAVAILABLE` (listed by `unavailable_steppers()`). Those not
# in FAMILY_MODULES are registered with `--plugin implementations/<module>.py` (see each module).
OPTIONAL_MODULES = ("rebound_adapter", "sundials_adapter")


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


def build_stepper(method):
    """The stepper that runs a `harness.methods.Method` record: the one step loop of its
    coefficients' family (explicit or implicit Runge-Kutta, splitting or its staggered leapfrog
    form, linear multistep, Stormer's two-step form)."""
    from harness.coefficients import ButcherTableau, LinearMultistep, SecondOrderMultistep, SplittingScheme
    from harness.errors import InputError

    c = method.coefficients
    opts = dict(method.options)
    claims = {"claimed_order": method.claimed_order, "reference": method.reference,
              "description": method.description}
    stability = dict(method.stability) if method.stability is not None else None
    if isinstance(c, ButcherTableau):
        if c.explicit:
            from implementations.runge_kutta import ExplicitRungeKutta

            stepper = ExplicitRungeKutta(c, **claims, **opts)
        else:
            from implementations.implicit_rk import ImplicitRungeKutta

            return ImplicitRungeKutta(c, name=c.name, **claims, stability=stability, **opts)
    elif isinstance(c, SplittingScheme):
        from implementations.splitting import SplittingStepper, StaggeredLeapfrog

        if opts.pop("loop", None) == "staggered":
            stepper = StaggeredLeapfrog(c.name, c, reference=method.reference,
                                        description=method.description)
        else:
            stepper = SplittingStepper(c, **claims, **opts)
    elif isinstance(c, LinearMultistep):
        from implementations.multistep import LinearMultistepStepper

        return LinearMultistepStepper(c, name=c.name, **claims, stability=stability, **opts)
    elif isinstance(c, SecondOrderMultistep):
        from implementations.verlet import TwoStepVerlet

        stepper = TwoStepVerlet(opts.pop("name", c.name), c, reference=method.reference,
                                description=method.description, **opts)
    else:
        raise InputError(f"method {method.name!r}: no step loop for coefficients of type {type(c).__name__}")
    if stability is not None:
        stepper.info.extra["stability"] = stability
    return stepper


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
