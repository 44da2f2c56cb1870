"""Compiled steppers: every method with a coefficient object, run by one numba loop per family.

A second implementation of each family's step loop, for long single trajectories where a
per-step NumPy loop costs ~500x a compiled loop. Nothing here holds a coefficient or reads
another module's private state: a compiled stepper wraps a NumPy stepper (`base`), reads its
public coefficient object (`ButcherTableau.A/.b/.c`, `SplittingScheme.sequence`,
`LinearMultistep.alpha/.beta`, `SecondOrderMultistep.alpha/.beta`) and public settings
(`newton`, `starter`, `info`), and passes the coefficients as arrays to the family kernel of
`implementations.kernels` (called through `implementations.compiled_kernels`). So a user's method
given as coefficients gets a compiled implementation from `compiled_variant`, and every built-in
one is registered as `<name>@compiled` below.

Families: explicit Runge-Kutta, splitting (drift/kick), staggered leapfrog, Stormer two-step
(accelerations independent of the velocity), linear multistep (explicit, and implicit by
Newton's method with the problem's Jacobian), implicit Runge-Kutta (Newton), and splittings under
a step controller (`implementations.step_control`). Where a NumPy loop's carry bookkeeping
(starts, observations, reversal) is not a plain state, the compiled class shares it: it subclasses
the NumPy loop (step-controlled splitting) or calls its public helpers (Stormer's
`TwoStepVerlet.observed_state`, the multistep `starting_values`). Each follows the
NumPy loop of its family step for step: the same operations in the same order, the same starts,
observations, time reversal and first-same-as-last reuse, the same evaluation counts, the same
Newton tolerance, iteration cap and convergence test (ensemble-wide), and `StepFailure` where
the NumPy loop raises it. Agreement to rounding is tested over the whole registry
(`tests/test_compiled.py`).

`faster(stepper)` is what the family registers with the registry (`harness.step_loops`, through
`implementations.builder.builtin_step_loops`): the registry's `fastest(stepper, problem)` runs
the compiled variant where it applies to the problem, else the stepper itself.
"""

from __future__ import annotations

import dataclasses
import math
from importlib import import_module

import numpy as np
from scipy.linalg.blas import daxpy

from harness.code_versions import module_version
from harness.coefficients import ButcherTableau, LinearMultistep, SecondOrderMultistep, SplittingScheme
from harness.errors import InputError
from harness.problem import Dynamics, Problem
from harness.stepper import Carry, StepFailure, Stepper
from implementations import FAMILY_MODULES
from implementations.compiled_kernels import (
    COMPILE_LOG,
    UnsupportedExpression,
    address,
    call_kernel,
    problem_functions,
)
from implementations.implicit_rk import ImplicitRungeKutta, NewtonSettings, extrapolation_matrix
from implementations.multistep import LinearMultistepStepper
from implementations.runge_kutta import ExplicitRungeKutta
from implementations.second_order_multistep import SecondOrderMultistepStepper
from implementations.second_order_multistep_compiled import CompiledSecondOrderMultistep
from implementations.splitting import SplittingStepper, StaggeredLeapfrog
from implementations.step_control import ControlledSplittingStepper
from implementations.verlet import TwoStepVerlet, stormer_carry

__all__ = [
    "CompiledRungeKutta",
    "CompiledSplitting",
    "CompiledLeapfrog",
    "CompiledStormer",
    "CompiledMultistep",
    "CompiledImplicitRungeKutta",
    "CompiledControlledSplitting",
    "compiled_variant",
    "faster",
    "problem_functions",
    "UnsupportedExpression",
    "COMPILE_LOG",
    "SUFFIX",
    "STEPPERS",
    "NOT_COMPILED",
    "COLUMN_MIN",
    "MAX_MULTISTEP_STEPS",
]

SUFFIX = "@compiled"
#: Ensembles of at least this many members run the explicit one-step families by their column
#: kernels (members advanced together in blocks, vectorisable); smaller ones member by member.
COLUMN_MIN = 8
#: Most steps of a multistep table the compiled loop takes: it keeps which derivatives of its
#: history ring are known as the bits of one 64-bit integer.
MAX_MULTISTEP_STEPS = 62


def _pars(dyn: Dynamics) -> np.ndarray:
    P = dyn.pars
    if P.ndim != 2:
        P = P.reshape(P.shape[0] if P.size else 0, dyn.size)
    return np.ascontiguousarray(P, dtype=np.float64)


def _compiled_info(base: Stepper, kind: str):
    return dataclasses.replace(
        base.info,
        name=base.info.name + SUFFIX,
        implementation="compiled",
        description=(
            f"{base.info.description}; compiled ({kind} kernel compiled by numba, fed the same "
            "coefficient object)"
        ).lstrip("; "),
        extra={**base.info.extra, "numpy_implementation": base.info.name},
    )


def _newton_settings(base: Stepper) -> NewtonSettings:
    settings = getattr(base, "newton", None)
    return settings if isinstance(settings, NewtonSettings) else NewtonSettings()


class _Compiled(Stepper):
    """What the compiled families share: the wrapped NumPy stepper's claims and coefficient
    object, compatibility through code generation, a fingerprint that includes the kernels'
    code, and `_advance` as one kernel call (`_run`) for many steps."""

    kind = ""
    part = "functions"

    def __init__(self, base: Stepper):
        if not isinstance(base, Stepper):
            raise InputError(f"`base` must be a Stepper, got {type(base).__name__}")
        if base.info.implementation == "compiled":
            raise InputError(f"`stepper` {base.info.name!r} is already compiled")
        self.base = base
        self.coefficients = base.coefficients
        self.history_length = base.history_length
        self.info = _compiled_info(base, self.kind)

    def incompatibility(self, problem: Problem) -> str | None:
        reason = self.base.incompatibility(problem)
        if reason:
            return reason
        parts = ("functions", "jacobian") if self.part == "jacobian" else ("functions",)
        try:
            for part in parts:
                problem_functions(problem, part)
        except UnsupportedExpression as exc:
            return f"no compiled right-hand side: {exc}"
        return None

    def reference_times(self, problem: Problem, t0: float, y0: np.ndarray, h: float) -> np.ndarray:
        return self.base.reference_times(problem, t0, y0, h)

    def fingerprint(self) -> str:
        # the source of this module and of every project module it imports (the kernels, their
        # call intrinsics, the NumPy loops whose helpers it shares): a change to any kernel
        # changes every compiled stepper's fingerprint, and so the key of every cell it ran
        return "\n".join([super().fingerprint(), self.base.fingerprint(),
                          module_version("implementations.compiled")])

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        self._run(dyn, c, 1)

    def _advance(self, dyn: Dynamics, c: Carry, n: int) -> None:
        if n > 0:
            self._run(dyn, c, n)
            c.n += n


# -- explicit Runge-Kutta ------------------------------------------------------------------------
class CompiledRungeKutta(_Compiled):
    """An explicit Runge-Kutta method (a `ButcherTableau`) run by the compiled RK kernel:
    k_i = f(t + c_i h, y + h sum_j a_ij k_j), y <- y + h sum_i b_i k_i (Hairer, Norsett & Wanner
    I, Sect. II.1, eq. (1.8))."""

    kind = "explicit Runge-Kutta"

    def __init__(self, base: Stepper):
        tab = base.coefficients
        if not isinstance(tab, ButcherTableau) or not tab.explicit:
            raise InputError(f"`stepper` {base.info.name!r} needs an explicit ButcherTableau")
        super().__init__(base)

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        return Carry(t0, h, np.ascontiguousarray(y0))

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        tab = self.coefficients
        args = (tab.A, tab.b, tab.c, float(c.t0), int(c.n), float(c.h), int(n), c.y)
        if c.y.shape[1] >= COLUMN_MIN:
            if getattr(c, "k", None) is None:
                c.k = np.empty((tab.stages, *c.y.shape))
                c.stage = np.empty_like(c.y)
            evals = call_kernel(
                "rk_advance_cols", address(dyn.problem, "rhs_cols"), *args, c.k, c.stage, _pars(dyn)
            )
        else:
            evals = call_kernel("rk_advance", address(dyn.problem, "rhs"), *args, _pars(dyn))
        dyn.counts["rhs"] += int(evals)


# -- splitting and the staggered leapfrog ----------------------------------------------------------
def _newtonian_carry(t0: float, h: float, y0: np.ndarray, dyn: Dynamics) -> Carry:
    c = Carry(t0, h, np.ascontiguousarray(y0))
    c.a = np.zeros((dyn.nq, c.y.shape[1]))
    return c


def _accel_all(dyn: Dynamics, t: float, q: np.ndarray, out: np.ndarray) -> None:
    call_kernel(
        "accel_all", address(dyn.problem, "accel"), float(t), np.ascontiguousarray(q), _pars(dyn), out
    )
    dyn.counts["accel"] += 1


class CompiledSplitting(_Compiled):
    """A drift/kick splitting scheme (a `SplittingScheme`) run by the compiled splitting kernel:
    drifts q += a_i h v, kicks v += b_i h a(q, t + tau_i h) with tau_i the drifts before the
    kick (the last kick at t + h), first same as last when the scheme begins and ends with a
    kick (Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed., II.5)."""

    kind = "splitting"

    def __init__(self, base: Stepper):
        scheme = base.coefficients
        if not isinstance(scheme, SplittingScheme):
            raise InputError(f"`stepper` {base.info.name!r} needs a SplittingScheme")
        super().__init__(base)
        seq = scheme.sequence
        self.fsal = len(seq) > 1 and seq[0][0] == "K" and seq[-1][0] == "K"
        kicks, coeffs, fractions = [], [], []
        elapsed = 0.0
        for kind, coeff in seq:
            kicks.append(kind == "K")
            coeffs.append(coeff)
            fractions.append(elapsed)
            if kind == "D":
                elapsed += coeff
        if kicks and kicks[-1]:
            fractions[-1] = 1.0  # the drifts sum to one: the last kick is at t + h exactly
        self.kicks = np.array(kicks, dtype=np.bool_)
        self.op_coefficients = tuple(coeffs)
        self.op_fractions = tuple(fractions)

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = _newtonian_carry(t0, h, y0, dyn)
        c.force_valid = False
        return c

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        hcoef = np.array([coeff * c.h for coeff in self.op_coefficients])
        htau = np.array([frac * c.h for frac in self.op_fractions])
        columns = c.y.shape[1] >= COLUMN_MIN
        evals = call_kernel(
            "split_advance_cols" if columns else "split_advance",
            address(dyn.problem, "accel_cols" if columns else "accel"), self.kicks, hcoef, htau,
            bool(self.fsal), bool(c.force_valid),
            float(c.t0), int(c.n), float(c.h), int(n), c.y, c.a, _pars(dyn),
        )
        dyn.counts["accel"] += int(evals)
        c.force_valid = self.fsal


class CompiledLeapfrog(_Compiled):
    """The staggered leapfrog built from a kick-drift-kick scheme K(b) D(1) K(b): positions at
    whole steps, velocities at half steps (start v_1/2 = v_0 + b h a_0), synchronised on output
    and on reversal (course-material files 002 and 004)."""

    kind = "staggered leapfrog"

    def __init__(self, base: Stepper):
        scheme = base.coefficients
        if not isinstance(scheme, SplittingScheme):
            raise InputError(f"`stepper` {base.info.name!r} needs a SplittingScheme")
        seq = scheme.sequence
        if len(seq) != 3 or [k for k, _ in seq] != ["K", "D", "K"] or not scheme.symmetric:
            raise InputError(
                f"`stepper` {base.info.name!r}: the staggered leapfrog needs a symmetric "
                f"kick-drift-kick scheme K(b) D(1) K(b), got {seq}"
            )
        super().__init__(base)
        self.half = seq[0][1]
        self.drift = seq[1][1]
        self.kick = seq[0][1] + seq[2][1]

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = _newtonian_carry(t0, h, y0, dyn)
        nq = dyn.nq
        _accel_all(dyn, t0, c.y[:nq], c.a)
        self._kick_velocity(c, nq, self.half * h)
        return c

    @staticmethod
    def _kick_velocity(c: Carry, nq: int, coef: float) -> None:
        v_flat = c.y[nq:].reshape(-1)
        daxpy(c.a.reshape(-1), v_flat, a=coef)

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        columns = c.y.shape[1] >= COLUMN_MIN
        evals = call_kernel(
            "leapfrog_advance_cols" if columns else "leapfrog_advance",
            address(dyn.problem, "accel_cols" if columns else "accel"), float(self.drift * c.h),
            float(self.kick * c.h),
            float(c.t0), int(c.n), float(c.h), int(n), c.y, c.a, _pars(dyn),
        )
        dyn.counts["accel"] += int(evals)

    def _observe(self, dyn: Dynamics, c: Carry) -> np.ndarray:
        out = c.y.copy()
        out[dyn.nq :] -= (self.half * c.h) * c.a
        return out

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        self._kick_velocity(c, dyn.nq, -self.half * c.h)  # synchronise: v_n
        super()._reverse(dyn, c)
        self._kick_velocity(c, dyn.nq, self.half * c.h)  # half step the new way: v_{n-1/2}


# -- Stormer two-step ------------------------------------------------------------------------------
class CompiledStormer(_Compiled):
    """Stormer's two-step rule sum_j alpha_j x_{n+j} = h^2 beta_1 a(x_{n+1}) (a
    `SecondOrderMultistep` with beta_0 = beta_2 = 0; Hairer, Norsett & Wanner I, III.10) with the
    Taylor start x_1 = x_0 + h v_0 + h^2 a_0 / 2 and the central-difference velocity (course-material
    files 000 and 001). Accelerations independent of the velocity only: where the force depends
    on it, the NumPy loop's implicit velocity (closed form or Newton) is not compiled."""

    kind = "Stormer two-step"

    def __init__(self, base: Stepper):
        table = base.coefficients
        if not isinstance(table, SecondOrderMultistep):
            raise InputError(f"`stepper` {base.info.name!r} needs a SecondOrderMultistep")
        if table.steps != 2 or not table.explicit or table.beta[0] != 0.0:
            raise InputError(
                f"`stepper` {base.info.name!r}: the Stormer loop needs a two-step table with "
                f"beta_0 = beta_2 = 0, got alpha={table.alpha.tolist()}, beta={table.beta.tolist()}"
            )
        super().__init__(base)
        self.alpha0, self.alpha1 = float(table.alpha[0]), float(table.alpha[1])
        self.beta1 = float(table.beta[1])

    def incompatibility(self, problem: Problem) -> str | None:
        """Why the compiled Stormer loop cannot run `problem`, or None.

        Parameters
        ----------
        problem : Problem, the candidate.

        Returns
        -------
        str or None: a velocity-dependent force (its implicit velocity is NumPy only), else what
        every compiled stepper checks.
        """
        if problem.velocity_dependent:
            return (
                "the compiled Stormer loop needs an acceleration independent of the velocity "
                "(the implicit central-difference velocity is NumPy only)"
            )
        return super().incompatibility(problem)

    def _new_carry(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = stormer_carry(dyn, t0, y0, h)
        c.nxt = np.empty_like(c.cur)
        c.a = np.zeros_like(c.cur)
        return c

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = self._new_carry(dyn, t0, y0, h)
        c.at_start = True
        c.a_start = np.empty_like(c.cur)
        _accel_all(dyn, t0, c.cur, c.a_start)
        c.nxt = c.cur + h * c.v0 + (0.5 * h * h) * c.a_start
        return c

    def _start_from_history(self, dyn: Dynamics, t0: float, h: float, history: list) -> Carry:
        c = self._new_carry(dyn, t0 + h, history[-1], h)
        c.at_start = False
        c.prev = np.ascontiguousarray(history[0][: dyn.nq])
        _accel_all(dyn, c.t, c.cur, c.a)
        np.multiply(c.prev, -self.alpha0, out=c.nxt)
        flat = c.nxt.reshape(-1)
        daxpy(c.cur.reshape(-1), flat, a=-self.alpha1)
        daxpy(c.a.reshape(-1), flat, a=self.beta1 * c.h * c.h)
        return c

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        evals = call_kernel(
            "stormer_advance", address(dyn.problem, "accel"), self.alpha0, self.alpha1,
            float(self.beta1 * c.h * c.h),
            float(c.t0), int(c.n), float(c.h), int(n), c.prev, c.cur, c.nxt, c.a, _pars(dyn),
        )
        dyn.counts["accel"] += int(evals)
        c.at_start = False

    def _observe(self, dyn: Dynamics, c: Carry) -> np.ndarray:
        return TwoStepVerlet.observed_state(c, dyn.nq)

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        super()._reverse(dyn, c)
        TwoStepVerlet.reverse_neighbours(c)


# -- Newton failures ---------------------------------------------------------------------------------
def _newton_failure(name: str, settings: NewtonSettings, t: float, stats: np.ndarray) -> StepFailure:
    iteration, norm, residual, theta, status = (
        int(stats[4]), float(stats[5]), float(stats[6]), float(stats[7]), int(stats[8])
    )
    if status == 2:
        return StepFailure(
            f"stepper {name!r}: singular Newton matrix at t={t:.17g} (iteration {iteration}); "
            f"scaled residual {residual:.3e}"
        )
    return StepFailure(
        f"stepper {name!r}: Newton iteration did not converge at t={t:.17g} after "
        f"{iteration} iteration(s) ({settings.mode}): scaled increment {norm:.3e}, "
        f"scaled residual {residual:.3e} (before the last increment), contraction "
        f"{theta:.3g}, tolerance {settings.tol:.1e}"
    )


def _add_newton_counts(dyn: Dynamics, stats: np.ndarray) -> None:
    dyn.counts["rhs"] += int(stats[1])
    dyn.counts["jac"] += int(stats[2])
    if stats[3] > 0:
        dyn.counts["newton_iterations"] = dyn.counts.get("newton_iterations", 0) + int(stats[3])


# -- linear multistep --------------------------------------------------------------------------------
class CompiledMultistep(_Compiled):
    """A linear multistep method sum_j alpha_j y_{n+j} = h sum_j beta_j f_{n+j} (a
    `LinearMultistep`; Hairer, Norsett & Wanner I, III.1-III.2): explicit tables by the compiled
    explicit kernel, implicit ones by Newton's method with the problem's Jacobian (full or
    simplified, as the wrapped stepper's `newton` settings). Starting values come from the
    wrapped stepper's `starter` (the certified reference or a one-step stepper, whose evaluations
    are counted with the method's); the history after a reversal is the NumPy loop's."""

    kind = "linear multistep"

    def __init__(self, base: Stepper):
        table = base.coefficients
        if not isinstance(table, LinearMultistep) or not isinstance(base, LinearMultistepStepper):
            raise InputError(f"`stepper` {base.info.name!r} needs a LinearMultistepStepper")
        if table.steps > MAX_MULTISTEP_STEPS:
            raise InputError(
                f"`stepper` {base.info.name!r}: the compiled multistep loop takes at most "
                f"{MAX_MULTISTEP_STEPS} steps, got {table.steps}"
            )
        super().__init__(base)
        self.history_length = table.steps
        self.implicit = not bool(table.explicit)
        self.part = "jacobian" if self.implicit else "functions"
        self.kind = "implicit linear multistep" if self.implicit else "explicit linear multistep"
        self.newton = _newton_settings(base)
        self.starter = getattr(base, "starter", "rk4")
        k = table.steps
        self.predictor = np.array(
            [float((-1) ** (k - 1 - j) * math.comb(k, j)) for j in range(k)], dtype=np.float64
        )

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        pending = [(y, None) for y in self.base.starting_values(dyn, t0, y0, h)]
        return Carry(t0, h, y0, hist_y=[y0], hist_f=[None], pending=pending)

    def _start_from_history(self, dyn: Dynamics, t0: float, h: float, history: list) -> Carry:
        k = len(history)
        return Carry(
            t0 + (k - 1) * h, h, history[-1], hist_y=list(history), hist_f=[None] * k, pending=[]
        )

    def _push(self, c: Carry, y: np.ndarray, f: np.ndarray | None) -> None:
        c.hist_y.append(y)
        c.hist_f.append(f)
        if len(c.hist_y) > self.coefficients.steps:
            del c.hist_y[0]
            del c.hist_f[0]
        c.y = y

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        done = 0
        while done < n and c.pending:
            y, f = c.pending.pop(0)
            self._push(c, y, f)
            done += 1
        if done == n:
            return
        table = self.coefficients
        H = np.ascontiguousarray(np.stack(c.hist_y))
        F = np.zeros_like(H)
        fvalid = np.zeros(H.shape[0], dtype=np.bool_)
        for j, f in enumerate(c.hist_f):
            if f is not None:
                F[j] = f
                fvalid[j] = True
        n0 = int(c.n) + done
        steps = n - done
        failure = None
        if self.implicit:
            stats = np.zeros(9)
            settings = self.newton
            call_kernel(
                "lmm_implicit_advance", address(dyn.problem, "rhs"), address(dyn.problem, "jac"),
                table.alpha, table.beta, self.predictor,
                settings.mode == "full", float(settings.tol), int(settings.max_iter), float(c.t0), n0,
                float(c.h), steps, H, F, fvalid, _pars(dyn), stats,
            )
            _add_newton_counts(dyn, stats)
            if stats[8] != 0:
                failure = _newton_failure(
                    self.info.name, settings, c.t0 + (n0 + int(stats[0])) * c.h, stats
                )
        else:
            evals = call_kernel(
                "lmm_explicit_advance", address(dyn.problem, "rhs"), table.alpha, table.beta, float(c.t0), n0,
                float(c.h), steps, H, F, fvalid, _pars(dyn),
            )
            dyn.counts["rhs"] += int(evals)
        c.hist_y = [H[j] for j in range(H.shape[0])]
        c.hist_f = [F[j] if fvalid[j] else None for j in range(H.shape[0])]
        c.y = c.hist_y[-1]
        if failure is not None:
            raise failure

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        super()._reverse(dyn, c)
        known = list(zip(c.hist_y, c.hist_f, strict=True))
        ahead = [(y, f) for y, f in reversed(known[:-1])]
        behind = [(y, f) for y, f in reversed(c.pending)] + [known[-1]]
        behind = behind[-self.coefficients.steps :]
        c.hist_y = [y for y, _ in behind]
        c.hist_f = [f for _, f in behind]
        c.pending = ahead
        c.y = c.hist_y[-1]


# -- implicit Runge-Kutta ----------------------------------------------------------------------------
class CompiledImplicitRungeKutta(_Compiled):
    """An implicit Runge-Kutta method (a `ButcherTableau` with a nonzero upper triangle) run by
    the compiled Newton kernel: unknowns Z_i = h sum_j a_ij f(t + c_j h, y + Z_j) on the stages
    with a nonzero row of A, y_{n+1} = y + sum_i d_i Z_i + h w f(t, y) with d = A_ii^{-T} b
    (Hairer & Wanner, *Solving ODEs II*, IV.8), the previous step's collocation polynomial as
    first iterate, first same as last when the tableau allows it; Newton settings (tolerance,
    iteration cap, full or simplified) from the wrapped stepper."""

    kind = "implicit Runge-Kutta"
    part = "jacobian"

    def __init__(self, base: Stepper):
        tab = base.coefficients
        if not isinstance(tab, ButcherTableau) or tab.explicit:
            raise InputError(f"`stepper` {base.info.name!r} needs an implicit ButcherTableau")
        super().__init__(base)
        self.newton = _newton_settings(base)
        A, b, c = tab.A, tab.b, tab.c
        zero_rows = np.all(A == 0.0, axis=1)
        expl = np.flatnonzero(zero_rows)
        impl = np.flatnonzero(~zero_rows)
        A_ii = A[np.ix_(impl, impl)]
        A_ie = A[np.ix_(impl, expl)]
        try:
            A_ii_inv = np.linalg.inv(A_ii)
        except np.linalg.LinAlgError:
            raise InputError(
                f"`stepper` {base.info.name!r}: the implicit block of A must be invertible"
            ) from None
        d = A_ii_inv.T @ b[impl]
        w = b[expl] - A_ie.T @ d
        self.A_ii = np.ascontiguousarray(A_ii)
        self.aie_sum = np.ascontiguousarray(A_ie.sum(axis=1))
        self.c_impl = np.ascontiguousarray(c[impl])
        self.d = np.ascontiguousarray(d)
        self.w_sum = float(w.sum())
        self.has_explicit = bool(expl.size)
        self.fsal = bool(
            expl.size == 1 and expl[0] == 0 and impl.size == tab.stages - 1
            and np.array_equal(A[-1], b) and c[-1] == 1.0
        )
        E = extrapolation_matrix(self.c_impl)
        self.has_predictor = E is not None
        self.E = np.zeros((impl.size, impl.size)) if E is None else E
        self.last_row_inv = np.ascontiguousarray(A_ii_inv[-1])

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        y = np.ascontiguousarray(y0)
        c = Carry(t0, h, y)
        c.f_start = np.zeros_like(y)
        c.z_prev = np.zeros((self.c_impl.size, *y.shape))
        c.flags = np.zeros(2, dtype=np.int64)  # [f_start valid, z_prev valid]
        return c

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        settings = self.newton
        stats = np.zeros(9)
        call_kernel(
            "irk_advance", address(dyn.problem, "rhs"), address(dyn.problem, "jac"), self.A_ii,
            self.aie_sum, self.c_impl, self.d, self.w_sum,
            self.last_row_inv, self.E, self.has_predictor, self.has_explicit, self.fsal,
            settings.mode == "full", float(settings.tol), int(settings.max_iter), float(c.t0),
            int(c.n), float(c.h), int(n), c.y, c.f_start, c.z_prev, c.flags, _pars(dyn), stats,
        )
        _add_newton_counts(dyn, stats)
        if stats[8] != 0:
            raise _newton_failure(self.info.name, settings, c.t0 + (c.n + int(stats[0])) * c.h, stats)

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        super()._reverse(dyn, c)
        c.flags[1] = 0  # the predictor extrapolates forward only


# -- step-controlled splitting ---------------------------------------------------------------------------
class CompiledControlledSplitting(_Compiled, ControlledSplittingStepper):
    """A splitting scheme under a step controller (`ControlledSplittingStepper`, naive or
    reversible; Huang & Leimkuhler, SIAM J. Sci. Comput. 18 (1997) 239-256; Hairer, Lubich &
    Wanner, GNI, VIII.3.2) run by the compiled controlled kernel. A subclass of the NumPy loop: the
    carry, the reversal and the members' clocks are its own (`_start`, `_reverse`, `_time`); only
    the steps are compiled."""

    kind = "step-controlled splitting"

    def __init__(self, base: Stepper):
        if not isinstance(base, ControlledSplittingStepper):
            raise InputError(f"`stepper` {base.info.name!r} needs a ControlledSplittingStepper")
        ControlledSplittingStepper.__init__(
            self, base.record, reference=base.info.reference, description=base.info.description
        )
        _Compiled.__init__(self, base)
        seq = self.record.scheme.sequence
        self.kicks = np.array([kind == "K" for kind, _ in seq], dtype=np.bool_)
        self.op_coefficients = np.array([coeff for _, coeff in seq], dtype=np.float64)

    def incompatibility(self, problem: Problem) -> str | None:
        """Whether the compiled controlled loop can run `problem`.

        Parameters
        ----------
        problem : Problem, whose force must not depend on the velocity.

        Returns
        -------
        None when it can, else the NumPy stepper's reason, a velocity-dependent force, or a
        general one.
        """
        reason = self.base.incompatibility(problem)
        if reason is None and problem.velocity_dependent:
            reason = "the compiled controlled loop needs an acceleration independent of the velocity"
        return reason or super().incompatibility(problem)

    def _run(self, dyn: Dynamics, c: Carry, n: int) -> None:
        density = self.record.density
        z = c.z if self._reversible else np.zeros(c.y.shape[1])
        evals = call_kernel(
            "controlled_advance", address(dyn.problem, "accel"), self.kicks, self.op_coefficients,
            bool(self._fsal), bool(c.force_valid), bool(self._reversible),
            float(density.position_power), float(density.momentum_power), float(c.t0), float(c.h),
            int(n), c.y, c.a, c.time, z, _pars(dyn),
        )
        dyn.counts["accel"] += int(evals)
        c.force_valid = self._fsal


# -- choosing the family -------------------------------------------------------------------------------
def compiled_variant(stepper: Stepper) -> Stepper:
    """The compiled implementation (named `<name>@compiled`) of a stepper whose method is a
    coefficient object: explicit or implicit `ButcherTableau`, `SplittingScheme` (a
    `StaggeredLeapfrog` keeps its staggered form), `LinearMultistep`, `SecondOrderMultistep`, or
    a splitting scheme under a step controller (`ControlledSplittingStepper`).

    Parameters
    ----------
    stepper : Stepper, a NumPy stepper of one of those families (InputError otherwise, or when
    it is already compiled).

    Returns
    -------
    Stepper: the compiled stepper.
    """
    if not isinstance(stepper, Stepper):
        raise InputError(f"`stepper` must be a Stepper, got {type(stepper).__name__}")
    if stepper.info.implementation == "compiled":
        raise InputError(f"`stepper` {stepper.info.name!r} is already compiled")
    if isinstance(stepper, ControlledSplittingStepper):
        return CompiledControlledSplitting(stepper)
    coeffs = stepper.coefficients
    if isinstance(coeffs, ButcherTableau):
        return CompiledRungeKutta(stepper) if coeffs.explicit else CompiledImplicitRungeKutta(stepper)
    if isinstance(coeffs, SplittingScheme):
        if isinstance(stepper, StaggeredLeapfrog):
            return CompiledLeapfrog(stepper)
        return CompiledSplitting(stepper)
    if isinstance(coeffs, LinearMultistep):
        return CompiledMultistep(stepper)
    if isinstance(coeffs, SecondOrderMultistep):
        if isinstance(stepper, SecondOrderMultistepStepper):  # the family's own compiled loop
            return CompiledSecondOrderMultistep(stepper)
        return CompiledStormer(stepper)
    raise InputError(
        f"`stepper` {stepper.info.name!r} has no coefficient object a compiled family runs "
        f"(ButcherTableau, SplittingScheme, LinearMultistep, SecondOrderMultistep); got "
        f"{type(coeffs).__name__}"
    )


def _family_loops() -> tuple[type, ...]:
    """The NumPy loop classes the compiled families mirror step for step."""
    return (ExplicitRungeKutta, ImplicitRungeKutta, SplittingStepper, StaggeredLeapfrog,
            LinearMultistepStepper, TwoStepVerlet, ControlledSplittingStepper,
            SecondOrderMultistepStepper)


def faster(stepper: Stepper) -> Stepper | None:
    """The compiled implementation of `stepper`'s method, as the registry asks it
    (`harness.step_loops.StepLoop.faster`): its compiled variant (agreeing with the NumPy loop
    to rounding, tested over the registry) when the method is a coefficient object a compiled
    family runs, else None. Only a stepper whose loop is exactly its family's own NumPy loop
    has one: a subclass that changes the step (a user's variant, a deliberately broken test
    stepper) runs as written, since its coefficients alone do not describe what it computes.

    Parameters
    ----------
    stepper : Stepper

    Returns
    -------
    Stepper or None
    """
    if stepper.info.implementation == "compiled" or type(stepper) not in _family_loops():
        return None
    try:
        return compiled_variant(stepper)
    except InputError:
        return None


# -- the registered variants -----------------------------------------------------------------------------
#: Built-in steppers with a coefficient object that no compiled family runs: name -> reason
NOT_COMPILED: dict[str, str] = {}


def _registered() -> list[Stepper]:
    out = []
    for name in FAMILY_MODULES:
        if name == "compiled":
            continue
        module = import_module(f"implementations.{name}")
        for stepper in module.STEPPERS:
            if stepper.coefficients is None and not isinstance(stepper, ControlledSplittingStepper):
                continue
            try:
                out.append(compiled_variant(stepper))
            except InputError as exc:
                NOT_COMPILED[stepper.info.name] = str(exc)
    return out


#: `<name>@compiled` for every built-in stepper with a coefficient object.
STEPPERS: list[Stepper] = _registered()
