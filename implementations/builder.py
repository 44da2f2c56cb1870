"""A method record's stepper: the one step loop of its coefficients' family.

Kept apart from the package's `__init__`, which the family modules import for their shared
helpers: the builder imports the family modules, never the other way round. Those imports stay
inside `build_stepper`: a family module builds its own steppers while it is imported
(`Method.stepper()`), so it is half-imported when the builder asks it for its loop.
"""

from harness.coefficients import ButcherTableau, LinearMultistep, SecondOrderMultistep, SplittingScheme
from harness.errors import InputError

__all__ = ["build_stepper"]


def build_stepper(method):
    """The stepper that runs a `harness.methods.Method` record: the one step loop of its
    coefficients' family (explicit or implicit Runge-Kutta, splitting or its staggered leapfrog
    form, linear multistep, second-order multistep (Stormer-Cowell and symmetric methods; the
    course's two-step Verlet loop when `implicit_velocity` is given))."""
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
    elif isinstance(c, SecondOrderMultistep) and "implicit_velocity" in opts:
        from implementations.verlet import TwoStepVerlet  # the course's two-step Verlet form

        stepper = TwoStepVerlet(opts.pop("name", c.name), c, reference=method.reference,
                                description=method.description, **opts)
    elif isinstance(c, SecondOrderMultistep):
        from implementations.second_order_multistep import SecondOrderMultistepStepper

        stepper = SecondOrderMultistepStepper(c, **claims, **opts)
    else:
        raise InputError(f"method {method.name!r}: no step loop for coefficients of type {type(c).__name__}")
    if stability is not None:
        stepper.info.extra["stability"] = stability
    return stepper
