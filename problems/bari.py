"""The Bari IVP test set's ODE problems: HIRES, VDPOL, ROBER, OREGO, E5, POLLU and PLEI.

F. Mazzia and C. Magherini, Test Set for Initial Value Problem Solvers, release 2.4, Department
of Mathematics, University of Bari and INdAM, 2008 (earlier releases with W. M. Lioen and
J. J. B. de Swart, CWI Amsterdam). Each problem is taken from the test set's Fortran problem file
(`hires.f`, `vdpol.f`, `rober.f`, `orego.f`, `e5.f`, `pollu.f`, `plei.f`, revisions of 2006):
the right-hand side of `feval`, the start values of `init`, the span of `prob` and the reference
solution at the end point of `solut`, whose comment says how it was computed. Copies read:
the R package deTestSet (K. Soetaert, J. Cash, F. Mazzia; github.com/cran/deTestSet, commit
d5c4cbe8, `src/Ex_*.f` and `R/ex_*.R`) and the test set's own `hires.f`, `vdpol.f`, `rober.f`,
`orego.f` and `e5.f` as distributed with other packages' test suites.

Every decimal constant is a runtime parameter whose published decimal is kept exactly
(`Published`): references are computed from the exact values, the float64 form is their
rounding. The test set states how each reference solution was computed, not its error; the
harness holds the published values to 1e-15 relative per component (their 16 printed digits,
the last one uncertain) for the references computed at rtol = 1.1e-18, and to 1e-13 for PLEI's
(PSIDE at rtol = atol = 1e-16), and checks both where its own certified reference reaches them
(HIRES, PLEI: tests/test_test_sets.py).

Their convergence horizon is derived (`Problem.convergence_t_end`): ten periods of the fastest
rate, extended for a stiff problem to many widths of its initial layer (VDPOL: 3.3e-3 where ten
periods end at 7.4e-5, inside the layer). The published span is not used: over ROBER's 1e11,
scipy's Radau at tol 1e-3 and 1e-4 ends at y1 = -4.8e7 even with the scaled atol (y2 turns
negative and grows; measured), a true miss of a local-error control the tolerance sweep would
report, but not the question the convergence horizon asks. All are listed on request only (tag
`on-request`): the stiff ones need an implicit method, and their references the stiff path
(`harness.ground_truth.stiff`, or the published end values), and together they would add
several minutes to the default run.
"""

from __future__ import annotations

import heyoka as hy

from harness.problem import Problem, Published

__all__ = ["PROBLEMS"]

_SOURCE = "F. Mazzia & C. Magherini, Test Set for IVP Solvers, release 2.4 (Univ. Bari, 2008)"
_RADAU_CRAY = ("RADAU5 in true double precision on a Cray C90 (uround 1.01e-19), rtol = atol = "
               "h0 = 1.1e-18; 16 digits printed")
_RADAU_ALPHA = ("RADAU in double precision (uround 1.01e-19) on an Alphaserver DS20E, "
                "rtol = atol = h0 = 1.1e-18; 16 digits printed")
_RADAU_ALPHA_ATOL = ("RADAU in double precision (uround 1.01e-19) on an Alphaserver DS20E, "
                     "rtol = h0 = 1.1e-18, atol = 1.1e-40; 16 digits printed")
_ACCURACY_RADAU = 1e-15
_ACCURACY_PSIDE = 1e-13
_TAGS = ("first-order", "test-set", "bari", "on-request")


def _parameters(names: list[str]) -> list[hy.expression]:
    return [hy.par[i] for i in range(len(names))]


def _problem(name: str, variables, rhs, published: Published, *, description: str, file: str,
             stiff: bool, **extra) -> Problem:
    return Problem(
        name,
        variables=variables,
        rhs=rhs,
        y0=published.y0_float,
        t_span=(0.0, published.t_end_float),
        parameters=published.parameters_float,
        published=published,
        description=description,
        reference=f"{_SOURCE}, problem file {file}",
        tags=_TAGS + (("stiff", "nonlinear") if stiff else ("nonlinear",)),
        **extra,
    )


# -- HIRES: plant physiology, 8 species (Schaefer 1975; Gottwald 1977) -------------------------------
_HIRES_K = {"a": "1.71", "b": "0.43", "c": "8.32", "d": "0.0007", "e": "8.75", "f": "10.03",
            "g": "0.035", "h": "1.12", "i": "1.745", "k": "280", "l": "0.69", "m": "1.81"}
_y = hy.make_vars(*[f"y{i}" for i in range(1, 9)])
_a, _b, _c, _d, _e, _f, _g, _h, _i, _k, _l, _m = _parameters(list(_HIRES_K))
_f7 = _k * _y[5] * _y[7] - _m * _y[6]
HIRES = _problem(
    "bari-hires", _y,
    [-_a * _y[0] + _b * _y[1] + _c * _y[2] + _d,
     _a * _y[0] - _e * _y[1],
     -_f * _y[2] + _b * _y[3] + _g * _y[4],
     _c * _y[1] + _a * _y[2] - _h * _y[3],
     -_i * _y[4] + _b * (_y[5] + _y[6]),
     -_k * _y[5] * _y[7] + _l * _y[3] + _a * _y[4] - _b * _y[5] + _l * _y[6],
     _f7,
     -_f7],
    Published(_SOURCE + ", hires.f", y0=("1", "0", "0", "0", "0", "0", "0", "0.0057"),
              parameters=_HIRES_K, t_end="321.8122",
              values=("0.7371312573325668e-3", "0.1442485726316185e-3", "0.5888729740967575e-4",
                      "0.1175651343283149e-2", "0.2386356198831331e-2", "0.6238968252742796e-2",
                      "0.2849998395185769e-2", "0.2850001604814231e-2"),
              accuracy=_ACCURACY_RADAU, accuracy_note=_RADAU_CRAY),
    description="HIRES: High Irradiance RESponse of photomorphogenesis, 8 reactions, mildly stiff",
    file="hires.f", stiff=True)

# -- VDPOL: van der Pol in Hairer's scaled form, eps = 1e-6 ------------------------------------------
_v1, _v2 = hy.make_vars("y1", "y2")
_eps = hy.par[0]
VDPOL = _problem(
    "bari-vdpol", [_v1, _v2], [_v2, ((1.0 - _v1 * _v1) * _v2 - _v1) / _eps],
    Published(_SOURCE + ", vdpol.f", y0=("2", "0"), parameters={"epsilon": "1.0e-6"}, t_end="2",
              values=("0.1706167732170483e1", "-0.8928097010247975e0"),
              accuracy=_ACCURACY_RADAU, accuracy_note=_RADAU_ALPHA),
    description="VDPOL: van der Pol, y1' = y2, y2' = ((1 - y1^2) y2 - y1)/eps, eps = 1e-6, "
                "two relaxation jumps over [0, 2]; stiff eigenvalue up to -3e6",
    file="vdpol.f", stiff=True)

# -- ROBER: Robertson's autocatalytic reaction ---------------------------------------------------------
_r = hy.make_vars("y1", "y2", "y3")
_k1, _k2, _k3 = _parameters(["k1", "k2", "k3"])
_rober_f1 = -_k1 * _r[0] + _k3 * _r[1] * _r[2]
_rober_f3 = _k2 * _r[1] * _r[1]
ROBER = _problem(
    "bari-rober", _r, [_rober_f1, -_rober_f1 - _rober_f3, _rober_f3],
    Published(_SOURCE + ", rober.f", y0=("1", "0", "0"),
              parameters={"k1": "0.04", "k2": "3e7", "k3": "1e4"}, t_end="1e11",
              values=("0.2083340149701255e-7", "0.8333360770334713e-13", "0.9999999791665050"),
              accuracy=_ACCURACY_RADAU, accuracy_note=_RADAU_ALPHA),
    description="ROBER: Robertson's chemical kinetics over [0, 1e11]; y2 stays below 4e-5",
    file="rober.f", stiff=True)

# -- OREGO: the Oregonator (Field & Noyes 1974) ------------------------------------------------------
_o = hy.make_vars("y1", "y2", "y3")
_s, _q, _w = _parameters(["s", "q", "w"])
OREGO = _problem(
    "bari-orego", _o,
    [_s * (_o[1] + _o[0] * (1.0 - _q * _o[0] - _o[1])),
     (_o[2] - (1.0 + _o[0]) * _o[1]) / _s,
     _w * (_o[0] - _o[2])],
    Published(_SOURCE + ", orego.f", y0=("1", "2", "3"),
              parameters={"s": "77.27", "q": "8.375e-6", "w": "0.161"}, t_end="360",
              values=("0.1000814870318523e1", "0.1228178521549917e4", "0.1320554942846706e3"),
              accuracy=_ACCURACY_RADAU, accuracy_note=_RADAU_ALPHA_ATOL),
    description="OREGO: the Oregonator, a relaxation oscillation of the Belousov-Zhabotinskii "
                "reaction over [0, 360]",
    file="orego.f", stiff=True)

# -- E5: the stiff DETEST chemical pyrolysis (Enright, Hull & Lindberg 1975) -------------------------
_p = hy.make_vars("y1", "y2", "y3", "y4")
_A, _B, _CM, _C = _parameters(["A", "B", "CM", "C"])
_prod1, _prod2 = _A * _p[0], _B * _p[0] * _p[2]
_prod3, _prod4 = _CM * _p[1] * _p[2], _C * _p[3]
E5 = _problem(
    "bari-e5", _p,
    [-_prod1 - _prod2, _prod1 - _prod3, _prod1 - _prod3 - _prod2 + _prod4, _prod2 - _prod4],
    Published(_SOURCE + ", e5.f", y0=("1.76e-3", "0", "0", "0"),
              parameters={"A": "7.89e-10", "B": "1.1e7", "CM": "1.13e9", "C": "1.13e3"},
              t_end="1e13",
              values=("0.1152903278711829e-290", "0.8867655517642120e-22",
                      "0.8854814626268838e-22", "0"),
              accuracy=_ACCURACY_RADAU, accuracy_note=_RADAU_ALPHA_ATOL),
    description="E5: chemical pyrolysis over [0, 1e13] (stiff DETEST E5); components down to 1e-291",
    file="e5.f", stiff=True)

# -- POLLU: the air pollution model of the Dutch National Institute (Verwer 1994) -------------------
_POLLU_K = {
    "k1": ".35", "k2": ".266e2", "k3": ".123e5", "k4": ".86e-3", "k5": ".82e-3", "k6": ".15e5",
    "k7": ".13e-3", "k8": ".24e5", "k9": ".165e5", "k10": ".9e4", "k11": ".22e-1",
    "k12": ".12e5", "k13": ".188e1", "k14": ".163e5", "k15": ".48e7", "k16": ".35e-3",
    "k17": ".175e-1", "k18": ".1e9", "k19": ".444e12", "k20": ".124e4", "k21": ".21e1",
    "k22": ".578e1", "k23": ".474e-1", "k24": ".178e4", "k25": ".312e1",
}
_u = hy.make_vars(*[f"y{i}" for i in range(1, 21)])
_kk = _parameters(list(_POLLU_K))
_RATE_TERMS = ((0,), (1, 3), (4, 1), (6,), (6,), (6, 5), (8,), (8, 5), (10, 1), (10, 0), (12,),
               (9, 1), (13,), (0, 5), (2,), (3,), (3,), (15,), (15,), (16, 5), (18,), (18,),
               (0, 3), (18, 0), (19,))
_rr = [_kk[j] * (_u[t[0]] if len(t) == 1 else _u[t[0]] * _u[t[1]]) for j, t in enumerate(_RATE_TERMS)]


def _net(minus: tuple[int, ...], plus: tuple[int, ...]) -> hy.expression:
    """sum of r(plus) - sum of r(minus), reaction numbers counted from 1 as in pollu.f."""
    out = hy.expression(0.0)
    for j in plus:
        out = out + _rr[j - 1]
    for j in minus:
        out = out - _rr[j - 1]
    return out


POLLU = _problem(
    "bari-pollu", _u,
    [_net((1, 10, 14, 23, 24), (2, 3, 9, 11, 12, 22, 25)),
     _net((2, 3, 9, 12), (1, 21)),
     _net((15,), (1, 17, 19, 22)),
     _net((2, 16, 17, 23), (15,)),
     _net((3,), (4, 4, 6, 7, 13, 20)),
     _net((6, 8, 14, 20), (3, 18, 18)),
     _net((4, 5, 6), (13,)),
     _net((), (4, 5, 6, 7)),
     _net((7, 8), ()),
     _net((12,), (7, 9)),
     _net((9, 10), (8, 11)),
     _net((), (9,)),
     _net((11,), (10,)),
     _net((13,), (12,)),
     _net((), (14,)),
     _net((18, 19), (16,)),
     _net((20,), ()),
     _net((), (20,)),
     _net((21, 22, 24), (23, 25)),
     _net((25,), (24,))],
    Published(_SOURCE + ", pollu.f",
              y0=("0", "0.2", "0", "0.04", "0", "0", "0.1", "0.3", "0.01", "0", "0", "0", "0",
                  "0", "0", "0", "0.007", "0", "0", "0"),
              parameters=_POLLU_K, t_end="60",
              values=("0.5646255480022769e-01", "0.1342484130422339e+00", "0.4139734331099427e-08",
                      "0.5523140207484359e-02", "0.2018977262302196e-06", "0.1464541863493966e-06",
                      "0.7784249118997964e-01", "0.3245075353396018e+00", "0.7494013383880406e-02",
                      "0.1622293157301561e-07", "0.1135863833257075e-07", "0.2230505975721359e-02",
                      "0.2087162882798630e-03", "0.1396921016840158e-04", "0.8964884856898295e-02",
                      "0.4352846369330103e-17", "0.6899219696263405e-02", "0.1007803037365946e-03",
                      "0.1772146513969984e-05", "0.5682943292316392e-04"),
              accuracy=_ACCURACY_RADAU, accuracy_note=_RADAU_CRAY),
    description="POLLU: air pollution chemistry, 20 species and 25 reactions over [0, 60]; "
                "rate constants up to 4.4e11",
    file="pollu.f", stiff=True)

# -- PLEI: seven stars in the plane (Hairer, Norsett & Wanner I, II.10) ------------------------------
_px = hy.make_vars(*[f"x{i}" for i in range(1, 8)])
_py = hy.make_vars(*[f"y{i}" for i in range(1, 8)])
_pu = hy.make_vars(*[f"u{i}" for i in range(1, 8)])
_pv = hy.make_vars(*[f"v{i}" for i in range(1, 8)])


def _plei_acceleration(coord) -> list[hy.expression]:
    out = []
    for i in range(7):
        acc = hy.expression(0.0)
        for j in range(7):
            if j != i:
                r2 = (_px[i] - _px[j]) ** 2 + (_py[i] - _py[j]) ** 2
                acc = acc + float(j + 1) * (coord[j] - coord[i]) * r2 ** -1.5
        out.append(acc)
    return out


PLEI = _problem(
    "bari-plei", [*_px, *_py, *_pu, *_pv],
    [*_pu, *_pv, *_plei_acceleration(_px), *_plei_acceleration(_py)],
    Published(_SOURCE + ", plei.f",
              y0=("3", "3", "-1", "-3", "2", "-2", "2", "3", "-3", "2", "0", "0", "-4", "4",
                  "0", "0", "0", "0", "0", "1.75", "-1.5", "0", "0", "0", "-1.25", "1", "0", "0"),
              t_end="3",
              values=("0.3706139143970502", "0.3237284092057233e1", "-0.3222559032418324e1",
                      "0.6597091455775310", "0.3425581707156584", "0.1562172101400631e1",
                      "-0.7003092922212495", "-0.3943437585517392e1", "-0.3271380973972550e1",
                      "0.5225081843456543e1", "-0.2590612434977470e1", "0.1198213693392275e1",
                      "-0.2429682344935824", "0.1091449240428980e1", "0.3417003806314313e1",
                      "0.1354584501625501e1", "-0.2590065597810775e1", "0.2025053734714242e1",
                      "-0.1155815100160448e1", "-0.8072988170223021", "0.5952396354208710",
                      "-0.3741244961234010e1", "0.3773459685750630", "0.9386858869551073",
                      "0.3667922227200571", "-0.3474046353808490", "0.2344915448180937e1",
                      "-0.1947020434263292e1"),
              accuracy=_ACCURACY_PSIDE,
              accuracy_note="PSIDE in Cray double precision on a Cray C90, rtol = atol = 1e-16"),
    description="PLEI: seven stars in the plane (masses 1..7) over [0, 3], with close encounters",
    file="plei.f", stiff=False)

PROBLEMS: list[Problem] = [HIRES, VDPOL, ROBER, OREGO, E5, POLLU, PLEI]
