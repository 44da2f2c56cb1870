"""The compiled implementation of the second-order multistep family (explicit and implicit tables).

`CompiledSecondOrderMultistep` is the family's NumPy loop (`SecondOrderMultistepStepper`) with its
steps run by the compiled kernel `implementations.kernels.second_order_multistep`
(`lmm2_explicit_advance`, `lmm2_implicit_advance` for Cowell's implicit tables, called through
`implementations.compiled_kernels.call_kernel`):
the start (starter stepper or Taylor polynomial), the pending starting values, the velocity
reconstruction, time reversal and the stability probe's history are the NumPy loop's own
(inherited), so both implementations share every convention and agree to rounding. Registered as
`<name>@compiled` by `implementations.compiled.compiled_variant`. The implicit kernel runs the
NumPy loop's simplified Newton iteration (predictor, one Jacobian per step, the ensemble-wide
correction test) in its order of operations; its linear solve is the kernels' LU with partial
pivoting where the NumPy loop calls LAPACK, so the two are promised to agree to rounding only
(on Kepler and harmonic ensembles every Cowell record agrees bit for bit, with equal counts).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from harness.code_versions import module_version
from harness.errors import InputError
from harness.problem import Dynamics, Problem
from harness.stepper import Carry, StepFailure, Stepper
from harness.tolerances import NEWTON_MAX_ITER, NEWTON_TOL
from implementations.compiled_kernels import call_kernel
from implementations.native_functions import UnsupportedExpression, function_address
from implementations.second_order_multistep import SecondOrderMultistepStepper

__all__ = ["CompiledSecondOrderMultistep", "SUFFIX"]

SUFFIX = "@compiled"


class CompiledSecondOrderMultistep(SecondOrderMultistepStepper):
    """A `SecondOrderMultistep` table's loop with its steps compiled (see the module docstring).
    Raises InputError for an already compiled stepper."""

    def __init__(self, base: Stepper):
        compiled = isinstance(base, CompiledSecondOrderMultistep)
        if not isinstance(base, SecondOrderMultistepStepper) or compiled:
            raise InputError(f"`base` must be a NumPy SecondOrderMultistepStepper, got {type(base).__name__}")
        self.__dict__.update(base.__dict__)
        self.base = base
        self.info = dataclasses.replace(
            base.info, name=base.info.name + SUFFIX, implementation="compiled",
            description=f"{base.info.description}; compiled (second-order multistep kernel)".lstrip("; "),
            extra={**base.info.extra, "numpy_implementation": base.info.name})

    def incompatibility(self, problem: Problem) -> str | None:
        """Why this loop cannot run `problem`.

        Parameters
        ----------
        problem : Problem, whose acceleration must compile.

        Returns
        -------
        str or None: the NumPy stepper's reason, or the unsupported expression; None when it runs.
        """
        reason = self.base.incompatibility(problem)
        if reason:
            return reason
        try:
            function_address(problem, "accel")
            if not self.coefficients.explicit:
                function_address(problem, "jac")
        except UnsupportedExpression as exc:
            return f"no compiled right-hand side: {exc}"
        return None

    def fingerprint(self) -> str:
        """The stepper's fingerprint with the code versions of this module and of its kernel, so a
        change to either changes every cell's key.

        Returns
        -------
        str: the fingerprint.
        """
        return "\n".join([super().fingerprint(),
                          module_version("implementations.second_order_multistep_compiled"),
                          module_version("implementations.kernels.second_order_multistep")])

    def _advance(self, dyn: Dynamics, c: Carry, n: int) -> None:
        while n > 0 and (c.pending or len(c.hist) < self._keep):  # the NumPy loop's own start
            self._step(dyn, c)
            c.n += 1
            n -= 1
        if n <= 0:
            return
        table = self.coefficients
        keep = self._keep
        X = np.ascontiguousarray(np.stack([e[0] for e in c.hist]), dtype=np.float64)
        A = np.zeros_like(X)
        known = np.zeros(keep, dtype=np.int64)
        for s, e in enumerate(c.hist):
            if e[1] is not None:
                A[s] = e[1]
                known[s] = 1
        P = dyn.pars
        if P.ndim != 2:
            P = P.reshape(P.shape[0] if P.size else 0, dyn.size)
        P = np.ascontiguousarray(P, dtype=np.float64)
        alpha = np.ascontiguousarray(table.alpha, dtype=np.float64)
        beta = np.ascontiguousarray(table.beta, dtype=np.float64)
        if table.explicit:
            evals, head = call_kernel(
                "lmm2_explicit_advance", function_address(dyn.problem, "accel"), alpha, beta,
                float(c.h * c.h), float(c.t0), int(c.n), float(c.h), int(n), X, A, known, 0, P)
            dyn.counts["accel"] += int(evals)
        else:
            stats = np.zeros(4)
            head = call_kernel(
                "lmm2_implicit_advance", function_address(dyn.problem, "accel"),
                function_address(dyn.problem, "jac"), alpha, beta,
                np.ascontiguousarray(self._predict, dtype=np.float64), float(c.h * c.h),
                float(c.t0), int(c.n), float(c.h), int(n), X, A, known, 0, P, float(NEWTON_TOL),
                int(NEWTON_MAX_ITER), stats)
            dyn.counts["accel"] += int(stats[0])
            dyn.counts["jac"] = dyn.counts.get("jac", 0) + int(stats[1])
            if stats[2] >= 0:
                t_new = (c.t0 + (c.n + int(stats[2])) * c.h) + c.h
                raise StepFailure(
                    f"stepper {self.info.name!r}: the implicit position at t={t_new!r} did not "
                    f"converge in {NEWTON_MAX_ITER} simplified Newton iterations (last relative "
                    f"correction {stats[3]:.3g}, tolerance {NEWTON_TOL:g})")
        kept = c.hist[n:] if n < keep else []  # original entries still stored keep their observed state
        new_hist = []
        for i in range(keep):
            s = (head + i) % keep
            a = A[s].copy() if known[s] else None
            if i < len(kept):
                entry = kept[i]
                entry[1] = a if entry[1] is None else entry[1]
            else:
                entry = [X[s].copy(), a, None]
            new_hist.append(entry)
        c.hist = new_hist
        c.n += n
