"""DETEST, classes A-E: the 25 non-stiff problems of Hull, Enright, Fellen & Sedgwick.

T. E. Hull, W. H. Enright, B. M. Fellen and A. E. Sedgwick, Comparing numerical methods for
ordinary differential equations, SIAM J. Numer. Anal. 9 (1972) 603-637 (appendix: the problems,
all over [0, 20]). Definitions cross-read from diffrax's test suite (P. Kidger,
github.com/patrick-kidger/diffrax, `test/test_detest.py`), which takes them from the paper:

- A: single equations (decay, a cubic, a periodic coefficient, the logistic equation, a
  spiral); B: small systems (growth-predation, a linear chain, a nonlinear chain, a spiral on a
  cylinder, Euler's rigid body); C: moderate systems (radioactive decay chains, a 10- and a
  51-component tridiagonal heat chain, the five outer planets); D: orbit equations, Kepler from
  pericentre with eccentricity 0.1, 0.3, 0.5, 0.7, 0.9; E: second-order equations written as
  systems (a Bessel equation, van der Pol with mu = 1, Duffing, two with a decoupled velocity).

Start values and constants are kept as published (`Published`): a decimal that float64 cannot
hold (0.05, 0.51, 2.78535, the planets' masses and states, D's 1 - e and sqrt((1 + e)/(1 - e)),
E3's 1/6) is a runtime parameter or start value with its exact value, so references certify the
problem as published. Where the paper gives a closed form (A1-A4, D1-D5, E1), it is the
problem's exact solution. DETEST publishes no end values to compare with; its references are the
harness's certified Taylor references (the problems are not stiff).

Listed on request only (tag `on-request`): 25 more problems would multiply the default run.
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext
from fractions import Fraction

import heyoka as hy
import numpy as np

from harness.problem import NewtonianForm, Problem, Published
from problems.kepler import kepler_exact

__all__ = ["PROBLEMS"]

_SOURCE = ("T. E. Hull, W. H. Enright, B. M. Fellen & A. E. Sedgwick, SIAM J. Numer. Anal. 9 "
           "(1972) 603-637, DETEST")
_TAGS = ("test-set", "detest", "on-request")
_T_END = "20"


def _problem(name: str, variables, y0, *, rhs=None, newtonian=None, parameters=None,
             description: str, exact=None, tags=(), **extra) -> Problem:
    published = Published(_SOURCE + f" problem {name.split('-')[1].upper()}", y0=tuple(y0),
                          parameters=parameters or {}, t_end=_T_END)
    return Problem(
        name,
        variables=variables,
        rhs=rhs,
        newtonian=newtonian,
        y0=published.y0_float,
        t_span=(0.0, 20.0),
        # the paper compares methods at the end point, t = 20
        convergence_t_end=20.0,
        parameters=published.parameters_float,
        published=published,
        exact=exact,
        description=description,
        reference=_SOURCE + ", with diffrax's test/test_detest.py",
        tags=_TAGS + tuple(tags),
        **extra,
    )


def _exact(formula):
    """An exact solution from a closed form `formula(t, t0, y0 (dim, N), pars (P, N))`."""

    def exact(t, y0, t0, pars=None):
        y0 = np.asarray(y0, dtype=np.float64)
        pars = np.zeros((0, y0.shape[1])) if pars is None else np.asarray(pars, dtype=np.float64)
        return np.asarray(formula(float(t), float(t0), y0, pars), dtype=np.float64)

    return exact


def _bessel(t, t0, y0, pars):
    """E1's general solution: y = x^(-1/2) (a sin x + b cos x), x = t + 1 (Bessel functions of
    order 1/2), fitted to the start."""
    x0, x = t0 + 1.0, t + 1.0
    u0 = y0[0] * np.sqrt(x0)
    w0 = y0[1] * np.sqrt(x0) + y0[0] / (2.0 * np.sqrt(x0))
    u = u0 * np.cos(x - x0) + w0 * np.sin(x - x0)
    w = -u0 * np.sin(x - x0) + w0 * np.cos(x - x0)
    y1 = u / np.sqrt(x)
    return np.stack([y1, (w - y1 / (2.0 * np.sqrt(x))) / np.sqrt(x)])


_t = hy.time
_y = hy.make_vars("y")
_y1, _y2, _y3 = hy.make_vars("y1", "y2", "y3")

# -- class A: single equations ---------------------------------------------------------------------
A = [
    _problem("detest-a1", [_y], ["1"], rhs=[-_y], description="A1: y' = -y, y(0) = 1",
             exact=_exact(lambda t, t0, y0, p: y0 * math.exp(-(t - t0)))),
    _problem("detest-a2", [_y], ["1"], rhs=[-0.5 * _y * _y * _y],
             description="A2: y' = -y^3/2, y(0) = 1",
             exact=_exact(lambda t, t0, y0, p: y0 / np.sqrt(1.0 + y0 * y0 * (t - t0)))),
    _problem("detest-a3", [_y], ["1"], rhs=[_y * hy.cos(_t)], description="A3: y' = y cos t",
             exact=_exact(lambda t, t0, y0, p: y0 * math.exp(math.sin(t) - math.sin(t0)))),
    _problem("detest-a4", [_y], ["1"], rhs=[0.25 * _y * (1.0 - hy.par[0] * _y)],
             parameters={"c": "0.05"}, description="A4: logistic y' = y/4 (1 - y/20), y(0) = 1",
             exact=_exact(lambda t, t0, y0, p: 1.0 / (p[0] + (1.0 / y0 - p[0])
                                                        * math.exp(-(t - t0) / 4.0)))),
    _problem("detest-a5", [_y], ["4"], rhs=[(_y - _t) / (_y + _t)],
             description="A5: spiral y' = (y - t)/(y + t), y(0) = 4"),
]

# -- class B: small systems ------------------------------------------------------------------------
_r = hy.sqrt(_y1 * _y1 + _y2 * _y2)
B = [
    _problem("detest-b1", [_y1, _y2], ["1", "3"],
             rhs=[2.0 * (_y1 - _y1 * _y2), -_y2 + _y1 * _y2],
             description="B1: growth of two conflicting populations"),
    _problem("detest-b2", [_y1, _y2, _y3], ["2", "0", "1"],
             rhs=[-_y1 + _y2, _y1 - 2.0 * _y2 + _y3, _y2 - _y3],
             description="B2: a linear chain", tags=("linear",)),
    _problem("detest-b3", [_y1, _y2, _y3], ["1", "0", "0"],
             rhs=[-_y1, _y1 - _y2 * _y2, _y2 * _y2], description="B3: a nonlinear chain"),
    _problem("detest-b4", [_y1, _y2, _y3], ["3", "0", "0"],
             rhs=[-_y2 - _y1 * _y3 / _r, _y1 - _y2 * _y3 / _r, _y1 / _r],
             description="B4: a spiral on a cylinder"),
    _problem("detest-b5", [_y1, _y2, _y3], ["0", "1", "1"],
             rhs=[_y2 * _y3, -_y1 * _y3, -hy.par[0] * _y1 * _y2], parameters={"c": "0.51"},
             description="B5: Euler's equations of a rigid body without external forces"),
]

# -- class C: moderate systems ---------------------------------------------------------------------
_c = hy.make_vars(*[f"y{i}" for i in range(1, 11)])
_c51 = hy.make_vars(*[f"y{i}" for i in range(1, 52)])


def _tridiagonal(v) -> list[hy.expression]:
    n = len(v)
    return [(v[i - 1] if i > 0 else 0.0) - 2.0 * v[i] + (v[i + 1] if i < n - 1 else 0.0)
            for i in range(n)]


_ONE_HOT_10 = ["1"] + ["0"] * 9

# C5: the five outer planets about the Sun (masses relative to the Sun, AU, days, k^2 scaled)
_C5_PARAMETERS = {
    "k2": "2.95912208286", "m0": "1.00000597682", "m1": "0.000954786104043",
    "m2": "0.000285583733151", "m3": "0.0000437273164546", "m4": "0.0000517759138449",
    "m5": "0.00000277777777778",
}
_C5_POSITIONS = (("3.42947415189", "3.35386959711", "1.35494901715"),
                 ("6.64145542550", "5.97156957878", "2.18231499728"),
                 ("11.2630437207", "14.6952576794", "6.27960525067"),
                 ("-30.1552268759", "1.65699966404", "1.43785752721"),
                 ("-21.1238353380", "28.4465098142", "15.3882659679"))
_C5_VELOCITIES = (("-0.557160570446", "0.505696783289", "0.230578543901"),
                  ("-0.415570776342", "0.365682722812", "0.169143213293"),
                  ("-0.325325669158", "0.189706021964", "0.087726532278"),
                  ("-0.024047625417", "-0.287659532608", "-0.117219543175"),
                  ("-0.176860753121", "-0.216393453025", "-0.014864789309"))
_q = [hy.make_vars(f"x{j}", f"y{j}", f"z{j}") for j in range(1, 6)]
_p = [hy.make_vars(f"vx{j}", f"vy{j}", f"vz{j}") for j in range(1, 6)]
_k2, _m0, *_mass = (hy.par[i] for i in range(7))


def _c5_acceleration() -> list[hy.expression]:
    r3 = [(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]) ** 1.5 for q in _q]
    out = []
    for j in range(5):
        for i in range(3):
            acc = -(_m0 + _mass[j]) * _q[j][i] / r3[j]
            for k in range(5):
                if k != j:
                    d2 = sum(((_q[k][c] - _q[j][c]) ** 2 for c in range(3)), hy.expression(0.0))
                    acc = acc + _mass[k] * ((_q[k][i] - _q[j][i]) / d2 ** 1.5 - _q[k][i] / r3[k])
            out.append(_k2 * acc)
    return out


_C5_Q = [v for q in _q for v in q]
_C5_P = [v for p in _p for v in p]
C = [
    _problem("detest-c1", _c, _ONE_HOT_10,
             rhs=[-_c[0]] + [_c[i - 1] - _c[i] for i in range(1, 9)] + [_c[8]],
             description="C1: radioactive decay chain, 10 components", tags=("linear",)),
    _problem("detest-c2", _c, _ONE_HOT_10,
             rhs=[-_c[0]] + [float(i) * _c[i - 1] - float(i + 1) * _c[i] for i in range(1, 9)]
             + [9.0 * _c[8]],
             description="C2: decay chain with rates 1..9, 10 components", tags=("linear",)),
    _problem("detest-c3", _c, _ONE_HOT_10, rhs=_tridiagonal(_c),
             description="C3: tridiagonal (heat) chain, 10 components", tags=("linear",)),
    _problem("detest-c4", _c51, ["1"] + ["0"] * 50, rhs=_tridiagonal(_c51),
             description="C4: tridiagonal (heat) chain, 51 components", tags=("linear",)),
    _problem("detest-c5", _C5_Q + _C5_P,
             [v for q in _C5_POSITIONS for v in q] + [v for p in _C5_VELOCITIES for v in p],
             newtonian=NewtonianForm(positions=tuple(_C5_Q), velocities=tuple(_C5_P),
                                     acceleration=tuple(_c5_acceleration())),
             parameters=_C5_PARAMETERS,
             description="C5: the five outer planets about the Sun (heliocentric, 30 components)",
             tags=("newtonian", "n-body")),
]

# -- class D: Kepler orbits from pericentre ---------------------------------------------------------
_dx, _dy, _dvx, _dvy = hy.make_vars("x", "y", "vx", "vy")
_D_ACCELERATION = tuple(-c * (_dx * _dx + _dy * _dy) ** -1.5 for c in (_dx, _dy))


def _pericentre(e: str) -> list[str]:
    """(1 - e, 0, 0, sqrt((1 + e)/(1 - e))) to 50 digits: the paper's start from the formula."""
    with localcontext() as ctx:
        ctx.prec = 50
        ecc = Decimal(e)
        return [str(1 - ecc), "0", "0", str(((1 + ecc) / (1 - ecc)).sqrt())]


D = [
    _problem(f"detest-d{k}", [_dx, _dy, _dvx, _dvy], _pericentre(e),
             newtonian=NewtonianForm(positions=(_dx, _dy), velocities=(_dvx, _dvy),
                                     acceleration=_D_ACCELERATION),
             exact=kepler_exact,
             # a = 1: period 2 pi; the perturbation of the eccentric Kepler orbits
             # (problems/kepler.py), which keeps every member bound near pericentre
             period=2.0 * math.pi, perturbation=0.05 * (1.0 - float(e)) ** 2 / 4.0,
             description=f"D{k}: Kepler orbit from pericentre, eccentricity {e}",
             tags=("newtonian", "central-force", "hamiltonian"))
    for k, e in enumerate(("0.1", "0.3", "0.5", "0.7", "0.9"), start=1)
]


# -- class E: second-order equations as systems ----------------------------------------------------
E = [
    _problem("detest-e1", [_y1, _y2], ["0.6713967071418030", "0.09540051444747446"],
             rhs=[_y2, -(_y2 / (_t + 1.0) + (1.0 - 0.25 / ((_t + 1.0) * (_t + 1.0))) * _y1)],
             description="E1: Bessel's equation of order 1/2 in x = t + 1",
             exact=_exact(_bessel)),
    _problem("detest-e2", [_y1, _y2], ["2", "0"], rhs=[_y2, (1.0 - _y1 * _y1) * _y2 - _y1],
             description="E2: van der Pol, mu = 1"),
    _problem("detest-e3", [_y1, _y2], ["0", "0"],
             # omega first: a compiled Jacobian counts parameters up to the last one it reads,
             # and omega (in the forcing only) is not read by it
             rhs=[_y2, hy.par[1] * _y1 * _y1 * _y1 - _y1 + 2.0 * hy.sin(hy.par[0] * _t)],
             parameters={"omega": "2.78535", "sixth": Fraction(1, 6)},
             description="E3: Duffing's equation y'' = y^3/6 - y + 2 sin(2.78535 t)"),
    _problem("detest-e4", [_y1, _y2], ["30", "0"],
             rhs=[_y2, hy.par[0] - hy.par[1] * _y2 * _y2],
             parameters={"g": "0.032", "k": "0.4"},
             description="E4: y'' = 0.032 - 0.4 y'^2 (falling with quadratic drag)"),
    _problem("detest-e5", [_y1, _y2], ["0", "0"],
             rhs=[_y2, hy.sqrt(1.0 + _y2 * _y2) / (25.0 - _t)],
             description="E5: y'' = sqrt(1 + y'^2)/(25 - t)"),
]

PROBLEMS: list[Problem] = [*A, *B, *C, *D, *E]
