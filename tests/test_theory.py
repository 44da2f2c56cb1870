"""Order and linear stability from the coefficients (harness.theory), swept over the registry.

Oracles: rooted-tree counts (OEIS A000081), error constants and stability intervals published in
Hairer, Norsett & Wanner I (II.2, III.2) and Hairer & Wanner II (IV.2, V.1), and NodePy's
values for RK4 (2.7852935634, 2 sqrt 2).
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from harness import theory
from harness.coefficients import (
    ButcherTableau,
    LinearMultistep,
    SecondOrderMultistep,
    SplittingScheme,
)
from harness.errors import InputError
from harness.registry import get_stepper, steppers

COEFFICIENT_TYPES = (ButcherTableau, LinearMultistep, SecondOrderMultistep, SplittingScheme)
WITH_COEFFICIENTS = [s.info.name for s in steppers.all() if s.coefficients is not None]
TABLEAUX = [s.info.name for s in steppers.all() if isinstance(s.coefficients, ButcherTableau)]


# -- rooted trees ------------------------------------------------------------------------------
def test_tree_counts_match_a000081():
    trees = theory.rooted_trees(8)
    counts = Counter(t.order for t in trees)
    assert [counts[n] for n in range(1, 9)] == [1, 1, 2, 4, 9, 20, 48, 115]
    assert len(trees) == 200
    assert len({(t.order, t.children) for t in trees}) == 200  # each tree once


@pytest.mark.parametrize(
    "label, gamma",
    [("*", 1), ("[*]", 2), ("[**]", 3), ("[[*]]", 6), ("[***]", 4), ("[[[*]]]", 24),
     ("[[*][*]]", 20), ("[****]", 5), ("[[[[*]]]]", 120)],
)
def test_tree_densities(label, gamma):
    by_label = {t.label: t for t in theory.rooted_trees(5)}
    assert by_label[label].gamma == gamma


# -- order from the coefficients, over the registry --------------------------------------------
@pytest.mark.parametrize("name", WITH_COEFFICIENTS)
def test_order_from_coefficients_matches_claim(name):
    stepper = get_stepper(name)
    if not isinstance(stepper.coefficients, COEFFICIENT_TYPES):
        pytest.fail(f"{name}: coefficients of unknown type {type(stepper.coefficients).__name__}")
    assert theory.order_from_coefficients(stepper) == stepper.info.claimed_order


def test_steppers_without_coefficients_give_none():
    for s in steppers.all():
        if s.coefficients is None:
            assert theory.order_from_coefficients(s) is None


@pytest.mark.parametrize("name", TABLEAUX)
def test_tree_conditions_agree_with_exact_series(name):
    """Two independent routes to the Runge-Kutta order: rooted trees and the exact local-error
    series on a generic nonlinear system."""
    tableau = get_stepper(name).coefficients
    assert theory.rk_order_series(tableau) == theory.rk_order(tableau)


def _perturbed(tableau: ButcherTableau, delta: float) -> ButcherTableau:
    b = np.array(tableau.b)
    b[0] += delta
    return ButcherTableau(tableau.name + "-perturbed", tableau.A, b / b.sum(), tableau.c)


def test_perturbed_weights_lower_the_order():
    rk4 = get_stepper("rk4").coefficients
    bad = _perturbed(rk4, 1e-3)
    assert theory.rk_order(rk4) == 4
    assert theory.rk_order(bad) < 4
    assert theory.rk_order_series(bad) == theory.rk_order(bad)
    (cond,) = theory.rk_order_conditions(bad, 2)
    assert cond.tree == "[*]" and not cond.satisfied
    assert abs(cond.residual) > 1e-4
    assert all(c.satisfied for c in theory.rk_order_conditions(rk4, 4))


def test_order_conditions_report_every_tree_of_the_order():
    conds = theory.rk_order_conditions(get_stepper("rk4").coefficients, 5)
    assert len(conds) == 9
    assert {c.expected for c in conds} == {1.0 / t.gamma for t in theory.rooted_trees(5) if t.order == 5}
    assert not all(c.satisfied for c in conds)  # rk4 is not fifth order


def _triple_jump(base: SplittingScheme, order: int, name: str) -> SplittingScheme:
    """Yoshida's construction: base of even order `order` -> order + 2."""
    w1 = 1.0 / (2.0 - 2.0 ** (1.0 / (order + 1)))
    return SplittingScheme.compose(name, base, [w1, 1.0 - 2.0 * w1, w1])


VV = SplittingScheme("vv", [("K", 0.5), ("D", 1.0), ("K", 0.5)])
_G = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
FOREST_RUTH = SplittingScheme(
    "fr", [("D", _G / 2), ("K", _G), ("D", (1 - _G) / 2), ("K", 1 - 2 * _G),
           ("D", (1 - _G) / 2), ("K", _G), ("D", _G / 2)])
SPLITTING_ORACLES = [
    (SplittingScheme("symplectic-euler", [("K", 1.0), ("D", 1.0)]), 1),
    (VV, 2),
    (FOREST_RUTH, 4),
    (_triple_jump(VV, 2, "vv-triple-jump"), 4),
    (_triple_jump(FOREST_RUTH, 4, "yoshida6-triple-jump"), 6),
    (_triple_jump(_triple_jump(FOREST_RUTH, 4, "y6"), 6, "yoshida8-triple-jump"), 8),
    # a kick moved off its symmetric place: consistent, but only first order
    (SplittingScheme("vv-skewed", [("K", 0.5 + 1e-3), ("D", 1.0), ("K", 0.5 - 1e-3)]), 1),
]


@pytest.mark.parametrize("scheme, order", SPLITTING_ORACLES, ids=[s.name for s, _ in SPLITTING_ORACLES])
def test_splitting_order_oracles(scheme, order):
    assert theory.splitting_order(scheme) == order


def test_splitting_series_vanishes_below_the_order():
    errs = theory.splitting_local_error_series(FOREST_RUTH, 7)
    assert max(errs[:5]) < 1e-14  # h^0 .. h^4 vanish
    assert errs[5] > 1e-3  # the h^5 term does not


MULTISTEP_ORACLES = [  # (alpha, beta, order, error constant C_{p+1}), Hairer-Norsett-Wanner III.2
    ([0, -1, 1], [-0.5, 1.5, 0], 2, 5 / 12),
    ([0, 0, 0, -1, 1], [-9 / 24, 37 / 24, -59 / 24, 55 / 24, 0], 4, 251 / 720),
    ([1 / 3, -4 / 3, 1], [0, 0, 2 / 3], 2, -2 / 9),
    ([0, -1, 1], [-1 / 12, 8 / 12, 5 / 12], 3, -1 / 24),
]


@pytest.mark.parametrize("alpha, beta, order, constant", MULTISTEP_ORACLES)
def test_lmm_order_and_error_constant(alpha, beta, order, constant):
    m = LinearMultistep("m", alpha, beta)
    assert theory.lmm_order(m) == order
    assert theory.lmm_error_constants(m)[order + 1] == pytest.approx(constant, rel=1e-12)


def test_stormer_order_and_error_constant():
    st = SecondOrderMultistep("stormer", [1, -2, 1], [0, 1, 0])
    assert theory.second_order_lmm_order(st) == 2
    assert theory.second_order_lmm_error_constants(st)[4] == pytest.approx(1 / 12, rel=1e-12)
    # a fourth-order two-step method for x'' = a (Numerov, HNW I, III.10)
    numerov = SecondOrderMultistep("numerov", [1, -2, 1], [1 / 12, 10 / 12, 1 / 12])
    assert theory.second_order_lmm_order(numerov) == 4


# -- stability from the coefficients -----------------------------------------------------------
STABILITY_ORACLES = [  # stepper, real interval, imaginary interval, absolute tolerance
    ("euler", 2.0, 0.0, 1e-8),
    ("heun", 2.0, 0.0, 1e-8),
    ("rk3", 2.5127, math.sqrt(3.0), 1e-4),
    ("rk4", 2.785293563, 2.0 * math.sqrt(2.0), 1e-8),
    ("backward-euler", math.inf, math.inf, 0.0),
    ("trapezoid", math.inf, math.inf, 0.0),
    ("implicit-midpoint", math.inf, math.inf, 0.0),
    ("gauss-legendre-4", math.inf, math.inf, 0.0),
    ("ab2", 1.0, 0.0, 1e-8),
]


@pytest.mark.parametrize("name, real, imag, atol", STABILITY_ORACLES)
def test_published_stability_intervals(name, real, imag, atol):
    a = theory.analytic_stability(get_stepper(name).coefficients)
    assert a["kind"] == "first-order"
    assert a["real_interval"] == pytest.approx(real, abs=atol)
    assert a["imag_interval"] == pytest.approx(imag, abs=atol)


def test_rk3_imaginary_interval_to_root_finding_accuracy():
    a = theory.analytic_stability(get_stepper("rk3").coefficients)
    assert a["imag_interval"] == pytest.approx(math.sqrt(3.0), abs=1e-8)
    assert a["real_interval"] == pytest.approx(2.5127453266, abs=1e-8)


@pytest.mark.parametrize("scheme, limit", [(VV, 2.0), (SplittingScheme("se", [("D", 1), ("K", 1)]), 2.0)])
def test_verlet_hw_limit(scheme, limit):
    assert theory.analytic_stability(scheme)["hw_limit"] == pytest.approx(limit, abs=1e-8)
    st = SecondOrderMultistep("stormer", [1, -2, 1], [0, 1, 0])
    assert theory.analytic_stability(st)["hw_limit"] == pytest.approx(2.0, abs=1e-8)


def test_splitting_propagator_is_area_preserving():
    hw = np.linspace(0.1, 0.9, 5)  # inside every stability interval: no cancellation in det
    for scheme, _ in SPLITTING_ORACLES:
        det = np.linalg.det(theory.splitting_propagator(scheme, hw))
        assert np.allclose(det, 1.0, atol=1e-12)


def test_lmm_amplification_root_at_infinity():
    am = LinearMultistep("am", [0, -1, 1], [-1 / 12, 8 / 12, 5 / 12])
    z = np.array([12 / 5, -1.0])
    amp = theory.lmm_amplification(am, z)
    assert math.isinf(amp[0]) and amp[1] <= 1.0
    # the consistent root zeta = 1 at z = 0
    assert theory.lmm_amplification(am, np.array([0.0]))[0] == pytest.approx(1.0, abs=1e-14)


def test_stability_boundary_on_known_functions():
    # |1 + z| on the real axis: crossing at x = 2; never stable on the imaginary axis
    euler = lambda z: 1.0 + z  # noqa: E731
    assert theory.real_stability_interval(euler) == pytest.approx(2.0, abs=1e-10)
    assert theory.imag_stability_interval(euler) == 0.0
    assert theory.stability_boundary(lambda x: np.full_like(x, 0.5)) == math.inf
    # a crossing between scan points is found by root finding, not read off the scan
    assert theory.stability_boundary(lambda x: x / 3.14159265358979) == pytest.approx(
        3.14159265358979, abs=1e-9)


# -- the families the theory reads ---------------------------------------------------------------
@pytest.mark.parametrize("cls", [ButcherTableau, SplittingScheme, LinearMultistep, SecondOrderMultistep])
def test_every_coefficient_class_declares_a_family_the_theory_knows(cls):
    """The theory never imports the coefficient classes: it reads their `family` tag, so each
    class must declare a tag the theory maps back to that class (else its checks refuse it)."""
    from harness.theory.checks import FAMILIES

    assert FAMILIES[cls.family] == cls.__name__


# -- bad input ---------------------------------------------------------------------------------
def test_bad_input_is_named():
    with pytest.raises(InputError, match="`tableau` must be a ButcherTableau"):
        theory.rk_order("rk4")
    with pytest.raises(InputError, match=r"`max_order` must lie in \[1, 12\]"):
        theory.rk_order(get_stepper("rk4").coefficients, max_order=13)
    with pytest.raises(InputError, match="`order` must be a whole number"):
        theory.rk_order_conditions(get_stepper("rk4").coefficients, 2.5)
    with pytest.raises(InputError, match="`scheme` must be a SplittingScheme"):
        theory.splitting_order(get_stepper("rk4").coefficients)
    with pytest.raises(InputError, match="`method` must be a LinearMultistep"):
        theory.lmm_order(VV)
    with pytest.raises(InputError, match="`limit` must be a positive finite number"):
        theory.stability_boundary(lambda x: x, limit=-1.0)
    with pytest.raises(InputError, match="`amplification` must return one value per point"):
        theory.stability_boundary(lambda x: np.ones(3))
