"""Splitting (drift/kick) methods for q'' = a(q, t): one step loop for every scheme.

A method is a `harness.coefficients.SplittingScheme` (a sequence of drifts q += a_i h v and kicks
v += b_i h a(q, t)) plus its claimed order and reference. The loop `SplittingStepper` runs any
scheme; when a scheme begins and ends with a kick, the last kick's force is the next step's first
force (first same as last), so a step costs `scheme.force_evals` force evaluations. Time advances
with the drifts, so a kick after drifts summing to d is evaluated at t + d h.

Schemes: velocity and position Verlet (course-material file 004; Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, 2nd ed., I.1.4), the two symplectic Euler methods (HLW I.1.2),
Forest-Ruth (Forest & Ruth 1990; course file 004), PEFRL (Omelyan, Mryglod & Folk 2002), and
Yoshida's sixth- and eighth-order compositions of velocity Verlet (Yoshida 1990).

`StaggeredLeapfrog` is the leapfrog in its staggered form (course files 002 and 004): velocities
live at half steps, positions at whole steps; it is driven by the velocity-Verlet scheme's data.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from scipy.linalg.blas import daxpy as _axpy

from harness.coefficients import SplittingScheme
from harness.errors import CoefficientError
from harness.methods import Method
from harness.problem import Dynamics
from harness.stepper import Carry, Stepper, StepperInfo
from implementations import coefficient_info

__all__ = ["SplittingStepper", "StaggeredLeapfrog", "METHODS", "STEPPERS"]

_HLW = "Hairer, Lubich & Wanner, Geometric Numerical Integration, 2nd ed. (2006)"


def _newtonian_carry(t0: float, h: float, y0: np.ndarray, dyn: Dynamics) -> Carry:
    """State (q, v) as views of one contiguous array, with flat views for in-place BLAS axpy
    updates (y <- y + a x: one cheap call instead of a NumPy multiply-and-add pair)."""
    nq = dyn.nq
    c = Carry(t0, h, np.ascontiguousarray(y0))
    c.q, c.v = c.y[:nq], c.y[nq:]
    c.q_flat, c.v_flat = c.q.reshape(-1), c.v.reshape(-1)
    c.a = np.empty_like(c.q)
    c.a_flat = c.a.reshape(-1)
    return c


def _splitting_info(scheme: SplittingScheme, **fields) -> StepperInfo:
    """What both loops of a splitting scheme declare: explicit, Newtonian, and the scheme's own
    force evaluations per step, symplecticity and symmetry."""
    return coefficient_info(scheme, family="splitting", form="newtonian", explicit=True,
                            evals_per_step=float(scheme.force_evals), **fields)


class SplittingStepper(Stepper):
    """Any drift/kick splitting scheme for velocity-independent accelerations a(q, t).

    The state is (q, v); drifts move q with the current v, kicks move v with the force at the
    current q and stage time. Declared evaluations per step are the scheme's `force_evals`
    (the first-same-as-last saving included); a scheme that begins and ends with a kick pays one
    more in the first step of a run.
    """

    def __init__(
        self,
        scheme: SplittingScheme,
        *,
        claimed_order: int,
        reference: str,
        description: str = "",
    ):
        if not isinstance(scheme, SplittingScheme):
            raise CoefficientError(f"`scheme` must be a SplittingScheme, got {type(scheme).__name__}")
        self.coefficients = scheme
        seq = scheme.sequence
        self._fsal = len(seq) > 1 and seq[0][0] == "K" and seq[-1][0] == "K"
        # Each operation: (is_kick, coefficient, fraction of the step elapsed before it).
        ops = []
        elapsed = 0.0
        for kind, coeff in seq:
            ops.append((kind == "K", coeff, elapsed))
            if kind == "D":
                elapsed += coeff
        if ops and ops[-1][0]:
            ops[-1] = (True, ops[-1][1], 1.0)  # the drifts sum to one: end the step exactly at t + h
        self._ops = tuple(ops)
        self.info = _splitting_info(scheme, claimed_order=claimed_order, reference=reference,
                                    description=description)

    def _scale(self, c: Carry) -> None:
        """Refresh what depends on the signed step size (at the start and on reversal): each
        operation's coefficient times h, its stage-time offset, and the step plan of both."""
        c.hcoef = tuple(coeff * c.h for _, coeff, _ in self._ops)
        c.htau = tuple(frac * c.h for _, _, frac in self._ops)
        c.plan = tuple(zip((kick for kick, _, _ in self._ops), c.hcoef, c.htau, strict=True))

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = _newtonian_carry(t0, h, y0, dyn)
        c.force_valid = False  # c.a holds a(q, t) at the carry's time when True
        self._scale(c)
        return c

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        q, a, q_flat, v_flat, a_flat = c.q, c.a, c.q_flat, c.v_flat, c.a_flat
        t = c.t0 + c.n * c.h
        accel, axpy = dyn.accel, _axpy
        reuse = c.force_valid  # only the first operation can reuse the previous step's force
        for is_kick, hcoef, htau in c.plan:
            if is_kick:
                if not reuse:
                    accel(t + htau, q, out=a)
                axpy(a_flat, v_flat, a=hcoef)
            else:
                axpy(v_flat, q_flat, a=hcoef)
            reuse = False
        c.force_valid = self._fsal

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        # The cached force a(q_n, t_n) stays valid: reversing changes neither q nor t.
        super()._reverse(dyn, c)
        self._scale(c)


class StaggeredLeapfrog(Stepper):
    """The leapfrog in staggered form: x_{n+1} = x_n + h v_{n+1/2},
    v_{n+3/2} = v_{n+1/2} + h a(x_{n+1}) (course-material files 002 and 004).

    Built from a kick-drift-kick scheme K(b) D(1) K(b) (velocity Verlet, b = 1/2): the half-step
    start is v_{1/2} = v_0 + b h a_0, a whole kick is 2b h a, and the observed velocity is
    synchronised on output only, v_n = v_{n+1/2} - b h a_n (the average of the neighbouring
    half-step velocities). Reversing time re-staggers: v_{n-1/2} = v_{n+1/2} - 2b h a_n.
    """

    def __init__(self, name: str, scheme: SplittingScheme, *, reference: str, description: str = ""):
        seq = scheme.sequence
        if len(seq) != 3 or [k for k, _ in seq] != ["K", "D", "K"] or not scheme.symmetric:
            raise CoefficientError(
                f"`{scheme.name}`: the staggered leapfrog needs a symmetric kick-drift-kick "
                f"scheme K(b) D(1) K(b), got {seq}"
            )
        self.coefficients = scheme
        self._half = seq[0][1]
        self._drift = seq[1][1]
        self._kick = seq[0][1] + seq[2][1]
        self.info = _splitting_info(scheme, name=name, claimed_order=2, reference=reference,
                                    description=description)

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = _newtonian_carry(t0, h, y0, dyn)  # c.v holds v_{n+1/2}
        dyn.accel(t0, c.q, out=c.a)
        _axpy(c.a_flat, c.v_flat, a=self._half * h)
        return c

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        h = c.h
        _axpy(c.v_flat, c.q_flat, a=self._drift * h)
        dyn.accel(c.t0 + (c.n + 1) * h, c.q, out=c.a)
        _axpy(c.a_flat, c.v_flat, a=self._kick * h)

    def _observe(self, dyn: Dynamics, c: Carry) -> np.ndarray:
        out = c.y.copy()
        out[dyn.nq :] -= (self._half * c.h) * c.a
        return out

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        _axpy(c.a_flat, c.v_flat, a=-self._half * c.h)  # synchronise: v_n
        super()._reverse(dyn, c)
        _axpy(c.a_flat, c.v_flat, a=self._half * c.h)  # half step in the new direction: v_{n-1/2}


# -- the schemes ---------------------------------------------------------------------------------
def _forest_ruth() -> SplittingScheme:
    g = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
    return SplittingScheme(
        "forest-ruth",
        [
            ("K", g / 2),
            ("D", g),
            ("K", (1 - g) / 2),
            ("D", 1 - 2 * g),
            ("K", (1 - g) / 2),
            ("D", g),
            ("K", g / 2),
        ],
    )


def _pefrl() -> SplittingScheme:
    # Omelyan, Mryglod & Folk (2002), eq. (20): position-extended Forest-Ruth-like scheme.
    xi = 0.1786178958448091
    lam = -0.2123418310626054
    chi = -0.06626458266981849
    return SplittingScheme(
        "pefrl",
        [
            ("D", xi),
            ("K", (1 - 2 * lam) / 2),
            ("D", chi),
            ("K", lam),
            ("D", 1 - 2 * (chi + xi)),
            ("K", lam),
            ("D", chi),
            ("K", (1 - 2 * lam) / 2),
            ("D", xi),
        ],
    )


def _symmetric_weights(w: list[float]) -> list[float]:
    """Yoshida's symmetric composition w_m ... w_1 w_0 w_1 ... w_m from w = (w_1, ..., w_m),
    with w_0 = 1 - 2 sum w_i."""
    if all(isinstance(x, str) for x in w):  # exact decimal strings: keep them exact
        w = [Fraction(x) for x in w]
    w0 = 1 - 2 * sum(w)
    return [*reversed(w), w0, *w]


VELOCITY_VERLET = SplittingScheme("velocity-verlet", [("K", 0.5), ("D", 1.0), ("K", 0.5)])

# Yoshida (1990), Table 1 (sixth order) and Table 2 (eighth order), solution A: w_1 ... w_m.
_YOSHIDA6_A = [-1.17767998417887, 0.235573213359357, 0.784513610477560]
# Yoshida's Table 2 solution A, refined to 40 digits from his 15-digit values by Newton's method
# on the exact order conditions (`harness.extended.refine_composition_weights`; the published
# values satisfy them to ~2e-12): exact enough for extended-precision convergence runs.
_YOSHIDA8_A = [
    "-1.615823741500653784787940197458742165897",
    "-2.446991823704245889294691452381462484561",
    "-7.169894197095332099806129249649109481199e-3",
    "2.440027326166344063816895897619430943538",
    "1.577399281237083213428257830795420048405e-1",
    "1.820206309706980069331733166121399780809",
    "1.042426208699704264348953268397656476106",
]

_YOSHIDA = "H. Yoshida, Construction of higher order symplectic integrators, Phys. Lett. A 150 (1990) 262-268"

METHODS: list[Method] = [
    Method(
        VELOCITY_VERLET,
        claimed_order=2,
        reference="W.C. Swope, H.C. Andersen, P.H. Berens & K.R. Wilson, J. Chem. Phys. 76 (1982) 637; "
        f"{_HLW}, I.1.4; course-material files 001 and 004",
        description="velocity Verlet, kick-drift-kick; one force evaluation per step (first same as last)",
    ),
    Method(
        SplittingScheme("position-verlet", [("D", 0.5), ("K", 1.0), ("D", 0.5)]),
        claimed_order=2,
        reference=f"M. Tuckerman, B.J. Berne & G.J. Martyna, J. Chem. Phys. 97 (1992) 1990; {_HLW}, I.1.4; "
        "course-material file 004",
        description="position Verlet, drift-kick-drift",
    ),
    Method(
        SplittingScheme("symplectic-euler-a", [("K", 1.0), ("D", 1.0)]),
        claimed_order=1,
        reference=f"{_HLW}, I.1.2 (the symplectic Euler method implicit in p, explicit for separable H)",
        description="symplectic Euler, variant A: kick with a(q_n), then drift with the new velocity",
    ),
    Method(
        SplittingScheme("symplectic-euler-b", [("D", 1.0), ("K", 1.0)]),
        claimed_order=1,
        reference=f"{_HLW}, I.1.2 (the adjoint symplectic Euler method, implicit in q)",
        description="symplectic Euler, variant B: drift with v_n, then kick with a(q_{n+1})",
    ),
    Method(
        _forest_ruth(),
        claimed_order=4,
        reference="E. Forest & R.D. Ruth, Fourth-order symplectic integration, Physica D 43 (1990) "
        "105-117; course-material file 004 (gamma = 1/(2 - 2^(1/3)))",
        description="Forest-Ruth fourth-order scheme; three force evaluations per step",
    ),
    Method(
        _pefrl(),
        claimed_order=4,
        reference="I.P. Omelyan, I.M. Mryglod & R. Folk, Optimized Forest-Ruth- and Suzuki-like "
        "algorithms for integration of motion in many-body systems, Comput. Phys. Commun. 146 "
        "(2002) 188-202, eq. (20)",
        description="position-extended Forest-Ruth-like fourth-order scheme (PEFRL), four forces per step",
    ),
    Method(
        SplittingScheme.compose("yoshida6", VELOCITY_VERLET, _symmetric_weights(_YOSHIDA6_A)),
        claimed_order=6,
        reference=f"{_YOSHIDA}, Table 1, solution A",
        description="Yoshida's sixth-order symmetric composition of seven velocity-Verlet steps",
    ),
    Method(
        SplittingScheme.compose("yoshida8", VELOCITY_VERLET, _symmetric_weights(_YOSHIDA8_A)),
        claimed_order=8,
        reference=f"{_YOSHIDA}, Table 2, solution A",
        description="Yoshida's eighth-order symmetric composition of fifteen velocity-Verlet steps",
    ),
    Method(
        SplittingScheme("leapfrog", VELOCITY_VERLET.sequence),
        claimed_order=2,
        reference="L. Verlet, Phys. Rev. 159 (1967) 98; course-material files 002 and 004 (leapfrog); "
        f"{_HLW}, I.1.4",
        description="staggered leapfrog: velocities at half steps (start v_1/2 = v_0 + h a_0 / 2), "
        "synchronised only for output",
        options={"loop": "staggered"},
    ),
]

STEPPERS: list[Stepper] = [s for m in METHODS for s in m.steppers()]
