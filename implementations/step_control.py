"""Step-size control for drift/kick splittings: the naive and the time-reversible controller.

The course's Kepler practice session (course material 004_bfdbb1594143ed8b.txt, Practice
Session #3) asks for a step control keeping the angle swept per step constant, Delta theta ~
const, "so that the algorithm produces bounded orbits". Both controllers here compose with any
`harness.coefficients.SplittingScheme` and take a `StepDensity` sigma(q, v): the physical step
per unit of control parameter. Their "h" is the control parameter eps (Delta theta for the
density r^2/|L|), so every fixed-parameter experiment applies; the physical time of each
ensemble member is carried separately and reported by `_time`.

- naive: h_n = eps sigma(y_n), chosen from the state before each step. Not symmetric: the step
  back from y_{n+1} uses sigma(y_{n+1}) != sigma(y_n), so time reversal does not retrace the
  orbit and the long-time energy behaviour of the scheme is lost (HLW VIII.2).
- reversible: a Sundman time transformation dt/dtau = sigma integrated symmetrically in the
  fictive time tau (adaptive Verlet: W. Huang & B. Leimkuhler, SIAM J. Sci. Comput. 18 (1997)
  239-256; Hairer, Lubich & Wanner, Geometric Numerical Integration, 2nd ed., VIII.3.2, the
  explicit symmetric recursion for z = 1/sigma). With z_{n+1/2} = z_{n-1/2} + eps G(y_n),
  G = dz/dtau = -(d sigma/dt)/sigma, and y_{n+1} = Phi_{eps/z_{n+1/2}}(y_n) for a symmetric
  scheme Phi, the map is symmetric: reversal retraces the orbit to rounding. Its order in eps is
  min(p, 2) (the z recursion is a second-order leapfrog); it is not symplectic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness.coefficients import SplittingScheme
from harness.errors import CoefficientError
from harness.problem import Dynamics, Problem
from harness.stepper import Carry, Stepper, StepperInfo
from harness.theory import splitting_order
from implementations.splitting import VELOCITY_VERLET

__all__ = [
    "StepDensity",
    "ControlledScheme",
    "ControlledSplittingStepper",
    "DELTA_THETA",
    "CONTROLLERS",
    "STEPPERS",
]

_HL97 = (
    "W. Huang & B. Leimkuhler, The adaptive Verlet method, SIAM J. Sci. Comput. 18 (1997) "
    "239-256; Hairer, Lubich & Wanner, Geometric Numerical Integration, 2nd ed. (2006), VIII.3.2"
)
_COURSE = (
    "course material 004_bfdbb1594143ed8b.txt, Practice Session #3 (control the time step so that "
    "Delta theta ~ const; make sure the orbits stay bounded)"
)
CONTROLLERS = ("naive", "reversible")


@dataclass(frozen=True)
class StepDensity:
    """sigma(q, v) = |q|^position_power |q ^ v|^momentum_power, the physical step per unit of
    control parameter, measured about the origin (so it needs a central force there; |q ^ v| is
    the norm of the angular momentum in any dimension). `keeps_constant` says what a step of
    control parameter eps holds fixed."""

    name: str
    position_power: float
    momentum_power: float
    keeps_constant: str
    control_parameter: str

    def __post_init__(self):
        for key in ("position_power", "momentum_power"):
            v = getattr(self, key)
            if not isinstance(v, int | float) or not math.isfinite(v):
                raise CoefficientError(
                    f"step density {self.name!r}: `{key}` must be a finite number, got {v!r}"
                )

    def radius_and_momentum(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """|q|^2, q.v and |q ^ v| per member (states shaped (nq, N)).

        Parameters
        ----------
        q, v : (nq, N) positions and velocities.

        Returns
        -------
        tuple of three (N,) arrays: (r2, qv, L).
        """
        r2 = np.einsum("ij,ij->j", q, q)
        qv = np.einsum("ij,ij->j", q, v)
        v2 = np.einsum("ij,ij->j", v, v)
        L = np.sqrt(np.maximum(r2 * v2 - qv * qv, 0.0))
        return r2, qv, L

    def sigma(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The step density sigma = |q|^position_power |L|^momentum_power per member.

        Parameters
        ----------
        q, v : (nq, N) positions and velocities.

        Returns
        -------
        ndarray (N,): sigma; the physical step is h sigma.
        """
        r2, _, L = self.radius_and_momentum(q, v)
        return r2 ** (0.5 * self.position_power) * L**self.momentum_power

    def describe(self) -> str:
        """The density's formula in words.

        Returns
        -------
        str: sigma with its powers.
        """
        return f"sigma = |q|^{self.position_power:g} |L|^{self.momentum_power:g}"


DELTA_THETA = StepDensity(
    "dtheta",
    position_power=2.0,
    momentum_power=-1.0,
    keeps_constant="Delta theta, the angle swept about the origin per step (d theta/dt = |L|/r^2)",
    control_parameter="Delta theta (radians per step)",
)


@dataclass(frozen=True, eq=False)
class ControlledScheme:
    """A method record: a splitting scheme, a step density and a controller kind."""

    scheme: SplittingScheme
    density: StepDensity
    controller: str

    def __post_init__(self):
        if not isinstance(self.scheme, SplittingScheme):
            raise CoefficientError(f"`scheme` must be a SplittingScheme, got {type(self.scheme).__name__}")
        if not isinstance(self.density, StepDensity):
            raise CoefficientError(f"`density` must be a StepDensity, got {type(self.density).__name__}")
        if self.controller not in CONTROLLERS:
            raise CoefficientError(f"`controller` must be one of {CONTROLLERS}, got {self.controller!r}")
        if self.controller == "reversible" and not self.scheme.symmetric:
            raise CoefficientError(
                f"`{self.scheme.name}`: the reversible controller needs a symmetric scheme "
                "(a palindromic sequence)"
            )

    @property
    def name(self) -> str:
        return f"{self.scheme.name}+{self.density.name}-{self.controller}"

    def fingerprint(self) -> str:
        """What identifies the scheme in cache keys: controller, powers and the underlying scheme's own.

        Returns
        -------
        str: the fingerprint.
        """
        d = self.density
        return (f"controlled:{self.controller}:{d.position_power!r}:{d.momentum_power!r}:"
                + self.scheme.fingerprint())


class ControlledSplittingStepper(Stepper):
    """Any splitting scheme under a step controller; `h` is the control parameter eps.

    Each member of an ensemble has its own physical step and clock (`c.time`), so an ensemble
    run equals the members' single runs. Declared evaluations per step are the scheme's
    (the controller needs no force: sigma and G use positions and velocities only)."""

    def __init__(self, record: ControlledScheme, *, reference: str, description: str = ""):
        if not isinstance(record, ControlledScheme):
            raise CoefficientError(f"`record` must be a ControlledScheme, got {type(record).__name__}")
        # The record is kept as `record`, not `coefficients`: harness.theory derives orders from
        # coefficient objects it knows (tables, schemes), and this composite is not one of them
        # yet; the claimed order below is derived from the scheme by the same theory.
        self.record = record
        scheme = record.scheme
        seq = scheme.sequence
        self._fsal = len(seq) > 1 and seq[0][0] == "K" and seq[-1][0] == "K"
        self._ops = tuple((kind == "K", coeff) for kind, coeff in seq)
        self._reversible = record.controller == "reversible"
        scheme_order = splitting_order(scheme)
        order = min(scheme_order, 2) if self._reversible else scheme_order
        d = record.density
        self.info = StepperInfo(
            name=record.name,
            family="splitting-controlled",
            claimed_order=order,
            explicit=True,
            symplectic=False,
            symmetric=self._reversible,
            evals_per_step=float(scheme.force_evals),
            form="newtonian",
            velocity_dependent=False,
            reference=reference,
            description=description,
            extra={
                "controller": record.controller,
                "base_scheme": scheme.name,
                "base_order": scheme_order,
                "step_density": d.describe(),
                "control_parameter": d.control_parameter,
                "keeps_constant": d.keeps_constant,
                "order_in": "control parameter",
                "uniform_time": False,
                # studied by the step-control experiment; listed (and scheduled by the gate and
                # the other experiments) only on request
                "on_request": True,
            },
        )

    def fingerprint(self) -> str:
        """The stepper's fingerprint followed by the controlled scheme's.

        Returns
        -------
        str: the fingerprint.
        """
        return super().fingerprint() + "\n" + self.record.fingerprint()

    def incompatibility(self, problem: Problem) -> str | None:
        """Why this stepper cannot run `problem`, or None when it can.

        Parameters
        ----------
        problem : the Problem in question.

        Returns
        -------
        str or None: the problem must declare a central force and not depend on t.
        """
        if not problem.central_force:
            return ("the step density is measured about the origin and needs a central force "
                    "there (the problem does not declare `central_force`)")
        if problem.time_dependent:
            return "each member keeps its own clock, so the acceleration must not depend on t"
        return None

    # -- the controller ----------------------------------------------------------------------------
    def _sigma(self, c: Carry) -> np.ndarray:
        d = self.record.density
        if self._reversible:  # positions only, |L| frozen at its start value: see `_start`
            r2 = np.einsum("ij,ij->j", c.q, c.q)
            return r2 ** (0.5 * d.position_power) * c.momentum_factor
        return d.sigma(c.q, c.v)

    def _g(self, c: Carry) -> np.ndarray:
        """G = dz/dtau for z = 1/sigma and dt/dtau = sigma: -(d sigma/dt)/sigma."""
        r2 = np.einsum("ij,ij->j", c.q, c.q)
        qv = np.einsum("ij,ij->j", c.q, c.v)
        return -self.record.density.position_power * qv / r2

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        c = Carry(t0, h, np.ascontiguousarray(y0))
        nq = dyn.nq
        c.q, c.v = c.y[:nq], c.y[nq:]
        c.a = np.empty_like(c.q)
        c.force_valid = False
        c.time = np.full(c.y.shape[1], float(t0))
        d = self.record.density
        # sigma's |L| factor is taken at the start for the reversible controller: a function of
        # q alone keeps G force-free, and splittings keep |L| to rounding for central forces.
        _, _, L = d.radius_and_momentum(c.q, c.v)
        c.momentum_factor = L**d.momentum_power
        if self._reversible:
            c.z = 1.0 / self._sigma(c) + 0.5 * h * self._g(c)  # z_{1/2}
        return c

    def _apply(self, dyn: Dynamics, c: Carry, hs: np.ndarray) -> None:
        """One step of the scheme with physical step hs (N,) per member."""
        q, v, a = c.q, c.v, c.a
        reuse = c.force_valid
        for is_kick, coeff in self._ops:
            if is_kick:
                if not reuse:
                    dyn.accel(c.t0, q, out=a)
                v += (coeff * hs) * a
            else:
                q += (coeff * hs) * v
            reuse = False
        c.force_valid = self._fsal
        c.time += hs

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        if self._reversible:
            # z = 1/sigma must stay positive: a fictive step too large for the recursion turns
            # it over, and the physical step is then unbounded (inf: a blow-up, not a NaN the
            # stepper made from a finite state).
            self._apply(dyn, c, np.where(c.z > 0.0, c.h / c.z, np.inf))
            c.z += c.h * self._g(c)
        else:
            self._apply(dyn, c, c.h * self._sigma(c))

    def _reverse(self, dyn: Dynamics, c: Carry) -> None:
        if self._reversible:
            c.z -= c.h * self._g(c)  # back to the z of the last step taken
        super()._reverse(dyn, c)

    def _time(self, c: Carry) -> np.ndarray:
        return c.time.copy()


def _record(scheme: SplittingScheme, controller: str, description: str) -> ControlledSplittingStepper:
    ref = f"{_COURSE}; {_HL97}" if controller == "reversible" else (
        f"{_COURSE}; Hairer, Lubich & Wanner, Geometric Numerical Integration, 2nd ed. (2006), "
        "VIII.1-VIII.2 (variable steps chosen from the state destroy the long-time behaviour)"
    )
    return ControlledSplittingStepper(ControlledScheme(scheme, DELTA_THETA, controller),
                                      reference=ref, description=description)


STEPPERS: list[Stepper] = [
    _record(VELOCITY_VERLET, "naive",
            "velocity Verlet with the naive controller h_n = Delta theta r_n^2/|L_n| chosen before "
            "each step"),
    _record(VELOCITY_VERLET, "reversible",
            "velocity Verlet under a symmetric Sundman transformation (adaptive Verlet), "
            "Delta theta ~ const in the fictive time"),
]
