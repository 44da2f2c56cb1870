"""The built-in families' step loops, registered with the registry (`harness.step_loops`) through
the entry-point group `harness.step_loops` (pyproject.toml): for each family, the NumPy loop that
runs a method record, and the compiled implementation of the same method.

Kept apart from the package's `__init__`, which the family modules import for their shared
helpers: the builder imports the family modules, never the other way round. Those imports stay
inside the build functions: a family module builds its own steppers while it is imported
(`Method.stepper()`), so it is half-imported when the registry asks it for its loop; and the
compiled family (numba kernels) is imported only when a compiled variant is asked for.
"""

from harness.coefficients import ButcherTableau, LinearMultistep, SecondOrderMultistep, SplittingScheme
from harness.step_loops import StepLoop

__all__ = ["builtin_step_loops"]


def _claims(method) -> dict:
    return {"claimed_order": method.claimed_order, "reference": method.reference,
            "description": method.description}


def _stability(method) -> dict | None:
    return dict(method.stability) if method.stability is not None else None


def _declared_stability(stepper, method):
    """`stepper` with the method's declared stability figures in its info (families whose
    loop does not take them as an argument)."""
    if method.stability is not None:
        stepper.info.extra["stability"] = _stability(method)
    return stepper


def _explicit_rk(method):
    c = method.coefficients
    if not isinstance(c, ButcherTableau) or not c.explicit:
        return None
    from implementations.runge_kutta import ExplicitRungeKutta

    return _declared_stability(ExplicitRungeKutta(c, **_claims(method), **method.options), method)


def _implicit_rk(method):
    c = method.coefficients
    if not isinstance(c, ButcherTableau) or c.explicit:
        return None
    from implementations.implicit_rk import ImplicitRungeKutta

    return ImplicitRungeKutta(c, name=c.name, **_claims(method), stability=_stability(method),
                              **method.options)


def _splitting(method):
    """A splitting scheme, or its staggered leapfrog form (`loop='staggered'`)."""
    c = method.coefficients
    if not isinstance(c, SplittingScheme):
        return None
    from implementations.splitting import SplittingStepper, StaggeredLeapfrog

    opts = dict(method.options)
    if opts.pop("loop", None) == "staggered":
        stepper = StaggeredLeapfrog(c.name, c, reference=method.reference,
                                    description=method.description)
    else:
        stepper = SplittingStepper(c, **_claims(method), **opts)
    return _declared_stability(stepper, method)


def _linear_multistep(method):
    c = method.coefficients
    if not isinstance(c, LinearMultistep):
        return None
    from implementations.multistep import LinearMultistepStepper

    return LinearMultistepStepper(c, name=c.name, **_claims(method), stability=_stability(method),
                                  **method.options)


def _two_step_verlet(method):
    """The course's two-step Verlet form of a second-order two-step table (`implicit_velocity`
    given)."""
    c = method.coefficients
    if not isinstance(c, SecondOrderMultistep) or "implicit_velocity" not in method.options:
        return None
    from implementations.verlet import TwoStepVerlet

    opts = dict(method.options)
    stepper = TwoStepVerlet(opts.pop("name", c.name), c, reference=method.reference,
                            description=method.description, **opts)
    return _declared_stability(stepper, method)


def _second_order_multistep(method):
    """Stormer-Cowell and symmetric k-step methods for x'' = f."""
    c = method.coefficients
    if not isinstance(c, SecondOrderMultistep):
        return None
    from implementations.second_order_multistep import SecondOrderMultistepStepper

    stepper = SecondOrderMultistepStepper(c, **_claims(method), **method.options)
    return _declared_stability(stepper, method)


def _compiled(stepper):
    from implementations.compiled import faster

    return faster(stepper)


def builtin_step_loops() -> list[StepLoop]:
    """The built-in families' loops, in the order the registry asks them (the two-step Verlet
    form before the general second-order multistep loop, which runs the same coefficients).

    Returns
    -------
    list of `harness.step_loops.StepLoop`.
    """
    return [
        StepLoop("explicit Runge-Kutta", build=_explicit_rk),
        StepLoop("implicit Runge-Kutta", build=_implicit_rk),
        StepLoop("splitting", build=_splitting),
        StepLoop("linear multistep", build=_linear_multistep),
        StepLoop("two-step Verlet", build=_two_step_verlet),
        StepLoop("second-order multistep", build=_second_order_multistep),
        StepLoop("compiled", faster=_compiled),
    ]
