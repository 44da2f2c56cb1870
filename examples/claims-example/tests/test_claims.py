"""The integrator's claims, checked by the harness's pytest plugin (fixture `integrator_claims`)."""

import yoshida4

from harness.api import FunctionStepper

STEPPER = FunctionStepper(
    yoshida4.step,
    name="yoshida4-example",
    form="newtonian",
    evals_per_step=6,  # two force evaluations per substep, three substeps
    reference="H. Yoshida, Phys. Lett. A 150 (1990) 262-268",
)


def test_order_symmetry_and_energy(integrator_claims):
    integrator_claims(
        STEPPER,
        ["harmonic", "kepler-circular"],
        order=4,
        symmetric=True,
        energy="bounded",
    )
