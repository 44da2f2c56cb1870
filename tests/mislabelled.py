"""Deliberately mislabelled steppers the experiments' tests share: each claim is false, and the
experiment that checks it must say so."""

from __future__ import annotations

import copy
import dataclasses

from harness.registry import steppers
from harness.stepper import Carry, Stepper, StepperInfo

__all__ = ["PlainEulerLabelledSymplectic", "relabelled"]


class PlainEulerLabelledSymplectic(Stepper):
    """Explicit Euler on (q, v): q1 = q0 + h v0, v1 = v0 + h a(q0). It has the right order, but
    the label "symplectic" is false: the symplectic Euler method kicks with the new position
    (GNI I.1.2). The deliberate mislabel the experiments must catch."""

    def __init__(self, name: str = "mislabelled-symplectic-euler"):
        self.info = StepperInfo(
            name=name, family="splitting", claimed_order=1, explicit=True, symplectic=True,
            symmetric=False, evals_per_step=1, form="newtonian", velocity_dependent=False,
            reference="Hairer, Lubich & Wanner, Geometric Numerical Integration, I.1.2 (mislabelled)",
        )

    def _start(self, dyn, t0, y0, h):
        return Carry(t0, h, y0)

    def _step(self, dyn, c):
        q, v = c.y[: dyn.nq], c.y[dyn.nq :]
        a = dyn.accel(c.t, q)
        q += c.h * v
        v += c.h * a


def relabelled(name: str, **claims) -> Stepper:
    original = steppers.get(name)
    clone = copy.copy(original)
    clone.info = dataclasses.replace(original.info, name=f"{name}-relabelled", **claims)
    return clone
