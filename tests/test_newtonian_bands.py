"""Exact h omega stability of published Runge-Kutta-Nystrom splitting methods.

The table holds published coefficients (each cited) and the first instability the exact
criterion gives. Every row is checked three ways that share no code with the root isolation:
|tr M| evaluated in 50-digit arithmetic crosses 2 at the root, a sampled scan of the same
propagator (step 1e-2) is shown to miss the narrow bands, and the method's own stepper grows in
the first band (a thousandfold in at most 16000 steps) while it stays bounded just below it.

Coefficients (a: drifts, b: kicks, in the order the step applies them, b first) as published in
S. Blanes & P.C. Moan, Practical symplectic partitioned Runge-Kutta and Runge-Kutta-Nystrom
methods, J. Comput. Appl. Math. 142 (2002) 313, Tables 2-3 (SRKN_6^b, SRKN_11^b, SRKN_14^a
and the PRK S_6), and R.I. McLachlan, SIAM J. Sci. Comput. 16 (1995) 151 (the order-4 RKN
methods with 4 and 5 force evaluations); transcribed from the table of methods of the Principia
project (integrators/methods.hpp), checked here by their orders.
"""

from __future__ import annotations

import math
from fractions import Fraction

import mpmath
import numpy as np
import pytest

from harness.coefficients import SplittingScheme
from harness.methods import Method
from harness.registry import get_problem
from harness.theory import splitting_amplification, stability_boundary
from harness.theory.newtonian import HwBands, splitting_hw_bands
from harness.theory.roots import count_roots_between, isolate_real_roots, pmul, poly, schur_all_inside


def _scheme(name: str, a: list[float], b: list[float]) -> SplittingScheme:
    seq = []
    for ai, bi in zip(a, b, strict=False):
        seq += [("K", bi), ("D", ai)]
    if len(b) > len(a):
        seq.append(("K", b[-1]))
    return SplittingScheme(name, seq)


_BM = "Blanes & Moan, J. Comput. Appl. Math. 142 (2002) 313"
PUBLISHED = [
    # name, a (drifts), b (kicks), order, first instability (exact), sampled limit it hides
    ("bm-srkn6b", [0.245298957184271, 0.60487266571108, -0.350171622895351,
                   -0.350171622895351, 0.60487266571108, 0.245298957184271],
     [0.0829844064174052, 0.396309801498368, -0.0390563049223486, 0.1195241940131508,
      -0.0390563049223486, 0.396309801498368, 0.0829844064174052], 4, 3.1634650666, 5.0269),
    ("bm-srkn11b", [0.123229775946271, 0.290553797799558, -0.127049212625417,
                    -0.246331761062075, 0.357208872795928, 0.20477705429147, 0.357208872795928,
                    -0.246331761062075, -0.127049212625417, 0.290553797799558, 0.123229775946271],
     [0.0414649985182624, 0.198128671918067, -0.0400061921041533, 0.0752539843015807,
      -0.0115113874206879, 0.2366699247869311, 0.2366699247869311, -0.0115113874206879,
      0.0752539843015807, -0.0400061921041533, 0.198128671918067, 0.0414649985182624],
     6, 3.1414310878, 9.0736),
    ("bm-srkn14a", [0.0378593198406116, 0.102635633102435, -0.0258678882665587, 0.314241403071447,
                    -0.130144459517415, 0.106417700369543, -0.00879424312851058, 0.2073050690568954,
                    -0.00879424312851058, 0.106417700369543, -0.130144459517415, 0.314241403071447,
                    -0.0258678882665587, 0.102635633102435, 0.0378593198406116],
     [0.0, 0.09171915262446165, 0.183983170005006, -0.05653436583288827, 0.004914688774712854,
      0.143761127168358, 0.328567693746804, -0.19641146648645423, -0.19641146648645423,
      0.328567693746804, 0.143761127168358, 0.004914688774712854, -0.05653436583288827,
      0.183983170005006, 0.09171915262446165], 6, 3.1409250826, 6.1500),
    ("bm-s6", [0.209515106613362, -0.143851773179818, 0.434336666566456, 0.434336666566456,
               -0.143851773179818, 0.209515106613362],
     [0.0792036964311957, 0.353172906049774, -0.0420650803577195, 0.2193769557534996,
      -0.0420650803577195, 0.353172906049774, 0.0792036964311957], 4, None, None),
    ("mclachlan-sb3a4", [0.18819521776883821787, -0.021528551102171551201, 0.66666666666666666667,
                         -0.021528551102171551201, 0.18819521776883821787],
     [0.0, 1.0, -0.5, -0.5, 1.0], 4, None, None),
]
_IDS = [row[0] for row in PUBLISHED]


@pytest.fixture(scope="module")
def bands() -> dict[str, tuple[SplittingScheme, HwBands]]:
    out = {}
    for name, a, b, *_ in PUBLISHED:
        s = _scheme(name, a, b)
        out[name] = (s, splitting_hw_bands(s, hw_max=12.0))
    return out


def _trace_mp(scheme: SplittingScheme, hw: float) -> mpmath.mpf:
    """tr M at h omega in 50-digit arithmetic, multiplied out factor by factor."""
    with mpmath.workdps(50):
        M = mpmath.eye(2)
        for kind, c in scheme.sequence:
            F = mpmath.eye(2)
            if kind == "D":
                F[0, 1] = mpmath.mpf(c) * mpmath.mpf(hw)
            else:
                F[1, 0] = -mpmath.mpf(c) * mpmath.mpf(hw)
            M = F * M
        return M[0, 0] + M[1, 1]


@pytest.mark.parametrize("row", PUBLISHED, ids=_IDS)
def test_published_orders_and_first_instability(row, bands):
    name, _, _, order, first, _ = row
    scheme, found = bands[name]
    assert scheme.order() == order
    if first is not None:
        assert found.limit == pytest.approx(first, abs=1e-9)
    # every band end is a crossing of |tr M| = 2, confirmed in 50-digit arithmetic
    for lo, hi in found.bands:
        for edge, side in ((lo, -1), (lo, 1), (hi, -1), (hi, 1)):
            if edge == 0.0 or not math.isfinite(edge):
                continue
            inside = (side > 0) == (edge == lo)
            t = abs(_trace_mp(scheme, edge * (1 + side * 1e-9)))
            assert (t > 2) == inside, (name, edge, side, t)


@pytest.mark.parametrize("row", [r for r in PUBLISHED if r[5] is not None], ids=lambda r: r[0])
def test_a_sampled_scan_misses_the_narrow_first_band(row, bands):
    name, *_, first, sampled = row
    scheme, found = bands[name]
    lo, hi = found.bands[0]
    assert hi - lo < 1e-2  # narrower than the scan step
    scanned = stability_boundary(lambda hw: splitting_amplification(scheme, hw), limit=12.0)
    assert scanned == pytest.approx(sampled, abs=1e-3)
    assert scanned > first + 1.0


@pytest.mark.parametrize("row", [r for r in PUBLISHED if r[4] is not None], ids=lambda r: r[0])
def test_the_methods_own_stepper_grows_inside_the_first_band(row, bands):
    name, _, _, order, *_ = row
    scheme, found = bands[name]
    lo, hi = found.bands[0]
    stepper = Method(scheme, order, _BM).stepper()
    problem = get_problem("harmonic")
    y0 = np.array([[1.0], [0.0]])
    inside = np.linspace(lo, hi, 201)[1:-1]
    rho = splitting_amplification(scheme, inside)
    h, rho = float(inside[np.argmax(rho)]), float(np.max(rho))  # 1 + 2e-3 .. 1 + 4e-4
    steps = int(math.ceil(math.log(1e3) / math.log(rho)))
    assert steps <= 16000
    grown = stepper.integrate(problem, h=h, n_steps=steps, y0=y0).y[-1]
    assert np.max(np.abs(grown)) > 1e2
    # just below the band the same number of steps stays bounded
    below = stepper.integrate(problem, h=lo * (1 - 1e-2), n_steps=steps, y0=y0).y[-1]
    assert np.max(np.abs(below)) < 1e2


def test_every_band_of_the_sb3a4_method_is_listed(bands):
    scheme, found = bands["mclachlan-sb3a4"]
    # bands are disjoint, ordered, and the stable pieces between them are stable in 50 digits
    edges = [e for band in found.bands for e in band]
    assert edges == sorted(edges)
    for (_, hi), (lo, _) in zip(found.bands, found.bands[1:], strict=False):
        assert abs(_trace_mp(scheme, 0.5 * (hi + lo))) < 2


def test_root_isolation_on_known_polynomials():
    # (x - 1)^2 (x - 2)(x - 1/3): distinct roots 1/3, 1, 2; the double root counts once
    prod = (Fraction(1),)
    for r in (Fraction(1), Fraction(1), Fraction(2), Fraction(1, 3)):
        prod = pmul(prod, (-r, Fraction(1)))
    roots = isolate_real_roots(prod, Fraction(0))
    assert [float((a + b) / 2) for a, b in roots] == pytest.approx([1 / 3, 1.0, 2.0], abs=1e-15)
    assert count_roots_between(prod, Fraction(0), Fraction(1)) == 2
    assert count_roots_between(prod, Fraction(1), None) == 1
    # Schur-Cohn: z^2 - 1/2 (roots +-0.707) inside, z^2 - 2 outside, (z - 1)^2 on the circle
    assert schur_all_inside(poly([Fraction(-1, 2), 0, 1]))
    assert not schur_all_inside(poly([-2, 0, 1]))
    assert not schur_all_inside(poly([1, -2, 1]))


@pytest.mark.parametrize("c2", [2e-4, 1e-4])
def test_large_weights_do_not_make_probe_and_formula_disagree(c2, registered):
    """Heun's two-stage family with a tiny c2 has b = (1 - 1/(2 c2), 1/(2 c2)): the weights sum
    to ~1/c2 in magnitude and its step rounds that much more than RK4's. Both implement the
    coefficients exactly, so the stability probe must agree with the formula."""
    from harness.coefficients import ButcherTableau
    from harness.experiments.base import Cell, get_experiment

    b2 = 1 / (2 * c2)
    tableau = ButcherTableau(f"heun-c2-{c2:g}", [[0, 0], [c2, 0]], [1 - b2, b2])
    name = registered(Method(tableau, 2, "Hairer, Norsett & Wanner I, II.1 (two-stage family)").stepper())
    exp = get_experiment("stability")
    cfg = exp.config({"grid": 41, "hw_grid": 41}, quick=True)
    rows = exp.run_cell(Cell("stability", name, "dahlquist"), cfg)
    summary = rows[rows["kind"] == "summary"].iloc[0]
    assert summary["max_probe_analytic_diff"] > 1e-12  # above the unscaled tolerance
    assert summary["verdict"] == "agrees", summary["message"]


def test_the_stability_experiment_reports_every_band():
    from harness.experiments.base import Cell, get_experiment

    exp = get_experiment("stability")
    cfg = exp.config({"grid": 41, "hw_grid": 41}, quick=True)
    rows = exp.run_cell(Cell("stability", "yoshida6", "harmonic"), cfg)
    summary = rows[rows["kind"] == "summary"].iloc[0]
    assert summary["verdict"] == "agrees", summary["message"]
    # Yoshida's order-6 composition: unstable from 2.269, stable again on (2.328, 2.817) and
    # (3.170, 3.233); the probe's scan and the exact figure agree on the first end
    assert summary["hw_limit"] == pytest.approx(2.2690579964, abs=1e-9)
    assert summary["hw_bands"].count("[") == 3 and "[3.233166079, inf)" in summary["hw_bands"]


def test_a_composition_over_the_exact_budget_gets_a_sampled_limit_said_so():
    """Triple-jump compositions of velocity Verlet nested four times (order 10, 82 kicks after
    merging, coefficients exact only as the floats given) are over the exact-isolation budget:
    the limit comes from the sampled spectral radius, marked inexact, and equals the
    propagator's own first instability on a fine grid; yoshida8 stays exact."""
    from harness.registry import get_stepper

    seq = [("K", 0.5), ("D", 1.0), ("K", 0.5)]  # velocity Verlet
    for p in (2, 4, 6, 8):
        w = 2.0 ** (1.0 / (p + 1))
        seq = [(k, c * g) for g in (1 / (2 - w), -w / (2 - w), 1 / (2 - w)) for k, c in seq]
    scheme = SplittingScheme("nested-triple-jump-10", seq)
    bands = splitting_hw_bands(scheme)
    assert not bands.exact and "sampled" in bands.describe()
    grid = np.linspace(1e-3, 2 * bands.limit, 4001)
    first = grid[np.argmax(splitting_amplification(scheme, grid) > 1 + 1e-9)]
    assert abs(first - bands.limit) <= 2 * (grid[1] - grid[0])
    assert splitting_hw_bands(get_stepper("yoshida8").coefficients).exact
