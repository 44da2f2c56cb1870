"""SUNDIALS CVODE through scikit-sundae, wrapped as adaptive steppers: `cvode-bdf`, `cvode-adams`.

An optional extra: `pip install .[sundials]` (pins scikit-sundae==1.2.0; requirements.txt pins it
too, so CI installs it). Without it the module registers nothing and
`implementations.unavailable_steppers()` lists it with the install command; loaded as a plugin
file it fails with that one line.

In the default registry when installed. CVODE controls the local error per step, as
documented; the gate judges the global error of its tolerance sweep against the derived allowance
(`harness.rules.tolerance_allowance`: accepted steps x the flow's error amplification x tol x
|y|), which both methods meet on every catalogue problem (32 cells, 12.6 s at load ~3). Against
the earlier fixed 1e4 x tol they missed on long orbits (kepler-circular BDF 1.03e4 x tol;
planets-pair BDF 1.65e5, Adams 1.28e4 x tol).

CVODE is adaptive only (no fixed-step mode): variable-order, variable-step linear multistep
methods, BDF of orders 1-5 (Newton iteration with a dense direct solver and the problem's
symbolic Jacobian) or Adams-Moulton of orders 1-12 (functional iteration is not offered by
scikit-sundae; it uses Newton too). Each output step integrates every ensemble member separately
from t to t + h at rtol = tol (at least 100 eps, as for scipy's methods) and the per-component
atol_i = tol x max |y_i| along the orbit of scipy's peers (`external.component_atol`), exactly as
a CVODE user calls `solve([t, t + h], y)`. The claimed order is each method's highest order (5,
12); adaptive steppers are judged by their tolerance sweep, not by that order. Evaluation counts
go through the run's `Dynamics` (ensemble units, like scipy's peers).
References: A. C. Hindmarsh et al., ACM TOMS 31 (2005) 363-396 (SUNDIALS); D. J. Gardner et al.,
ACM TOMS 48 (2022) 31 (SUNDIALS 6); S. D. Cohen, A. C. Hindmarsh, Computers in Physics 10 (1996)
138-143 (CVODE); C. R. Randall et al., scikit-sundae documentation (2024).
"""

from __future__ import annotations

import numpy as np

from harness.c_streams import library_output_captured
from harness.stepper import AdaptiveStepper, StepFailure, WorkLimitFailure
from harness.tolerances import SCIPY_MIN_RTOL
from implementations import optional_library
from implementations.external import MemberByMemberStepper, MemberDynamics, is_work_limit

__all__ = ["STEPPERS", "UNAVAILABLE", "INSTALL", "SUNDAE_VERSION", "CvodeStepper"]

SUNDAE_VERSION = "1.2.0"
cvode, INSTALL, UNAVAILABLE = optional_library(
    "sksundae.cvode", package="scikit-sundae", version=SUNDAE_VERSION, extra="sundials",
    label="scikit-sundae (SUNDIALS CVODE)")
CVODE = None if cvode is None else cvode.CVODE

_REF = ("S. D. Cohen, A. C. Hindmarsh, Computers in Physics 10 (1996) 138-143 (CVODE); "
        "A. C. Hindmarsh et al., ACM TOMS 31 (2005) 363-396 (SUNDIALS)")
# name -> (CVODE method, highest order, description)
_METHODS = {
    "cvode-bdf": ("BDF", 5, "CVODE BDF, variable order 1-5, Newton iteration with the symbolic "
                            "Jacobian (dense direct solver)."),
    "cvode-adams": ("Adams", 12, "CVODE Adams-Moulton, variable order 1-12, Newton iteration with "
                                 "the symbolic Jacobian (dense direct solver)."),
}
CVODE_TOL_RANGE = (1e-15, 1e-3)  # scikit-sundae's documented range for rtol
_MAX_STEPS_PER_OUTPUT = 100_000  # CVODE's default 500 stops long output steps at tight tol


class CvodeStepper(MemberByMemberStepper):
    """CVODE (`method` BDF or Adams) advancing each member to the next output time."""

    def __init__(self, name: str, tol: float = AdaptiveStepper.tol):
        method, order, description = _METHODS[name]
        self.method = method
        self.tol = float(tol)
        self.info = self._library_info(
            name=name, claimed_order=order, explicit=False, evals_per_step=2.0, reference=_REF,
            implementation="sundials", description=description + " Each output step restarts CVODE "
            "for every member from t to t + h at rtol = tol and atol_i = tol x max |y_i| along the "
            "problem's orbit.",
        )

    def extra_info(self) -> dict:
        """The record's `extra` entries for this tolerance: CVODE's rtol/atol and method, the
        scikit-sundae version, and the unit the evaluation counts are in.

        Returns
        -------
        dict: the entries, JSON-safe.
        """
        return {"tol": self.tol, "rtol": max(self.tol, SCIPY_MIN_RTOL),
                "atol": self.tol, "atol_per_component": "tol x max|y_i| along the orbit",
                # scikit-sundae documents rtol in [1e-15, 1e-3]
                "tol_range": list(CVODE_TOL_RANGE),
                "cvode_method": self.method, "scikit_sundae_version": SUNDAE_VERSION,
                "evals_unit": "ensemble evaluations (member calls / N)"}

    def _solver(self, member: MemberDynamics):
        def rhs(t, y, yp):
            yp[:] = member.f(t, y)

        def jac(t, y, yp, J):
            J[:, :] = member.jac(t, y)

        return CVODE(rhs, method=self.method, rtol=max(self.tol, SCIPY_MIN_RTOL), atol=member.atol,
                     jacfn=jac, max_num_steps=_MAX_STEPS_PER_OUTPUT)

    def _solve_member(self, member: MemberDynamics, m: int, t: float, target: float,
                      y: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
        try:
            with library_output_captured() as printed:
                sol = self._solver(member).solve(np.array([t, target]), y)
        except Exception as exc:  # the adapter's work limit, or CVODE refusing the input
            failure = WorkLimitFailure if is_work_limit(exc) else StepFailure
            raise failure(f"stepper {self.info.name!r}: CVODE stopped for ensemble member {m} between "
                          f"t={t!r} and t={target!r}: {type(exc).__name__}: {exc}") from None
        if not sol.success:
            said = printed.last_line()
            raise StepFailure(f"stepper {self.info.name!r}: CVODE failed for ensemble member "
                              f"{m} between t={t!r} and t={target!r}: {sol.message}"
                              + (f" (SUNDIALS: {said})" if said else ""))
        return sol.y[-1], {"internal_steps": int(sol.t.size - 1)}  # every internal step is returned


STEPPERS: list = [CvodeStepper(name) for name in _METHODS] if CVODE is not None else []
if CVODE is None and __name__ != "implementations.sundials_adapter":
    raise ImportError(UNAVAILABLE["scikit-sundae"])
