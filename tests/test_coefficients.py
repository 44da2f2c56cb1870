"""Methods as data: every registered coefficient table checks itself, broken tables are refused,
and the facts derived from a table (explicit, symmetric, force evaluations, order) are right.

Tables are swept over the registry; the expected derived facts below are the textbook ones
(Hairer, Norsett & Wanner I, II.1; Hairer, Lubich & Wanner, II.4-II.5; course file 004).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from harness.coefficients import (
    ButcherTableau,
    LinearMultistep,
    SecondOrderMultistep,
    SplittingScheme,
)
from harness.errors import CoefficientError
from harness.registry import steppers
from harness.theory import order_from_coefficients
from harness.tolerances import COEFFICIENT_TOL, ORDER_CONDITION_TOL
from implementations.runge_kutta import ExplicitRungeKutta
from implementations.splitting import VELOCITY_VERLET, SplittingStepper, StaggeredLeapfrog
from implementations.verlet import STORMER, TwoStepVerlet

ALL = steppers.all()
TABLEAU_STEPPERS = [s for s in ALL if isinstance(s.coefficients, ButcherTableau)]
SPLITTING_STEPPERS = [s for s in ALL if isinstance(s.coefficients, SplittingScheme)]
TABLE_STEPPERS = [s for s in ALL if s.coefficients is not None]


def ids(items):
    return [s.info.name for s in items]


# Textbook facts per table: stages (Runge-Kutta), or (force evaluations, symmetric) (splitting).
RK_STAGES = {"euler": 1, "midpoint": 2, "heun": 2, "ralston": 2, "rk3": 3, "rk4": 4, "rk38": 4}
SPLITTING_FACTS = {
    "velocity-verlet": (1, True),
    "position-verlet": (1, True),
    "symplectic-euler-a": (1, False),
    "symplectic-euler-b": (1, False),
    "forest-ruth": (3, True),
    "pefrl": (4, True),
    "yoshida6": (7, True),
    "yoshida8": (15, True),
    "leapfrog": (1, True),
}
# Symmetric compositions of a symmetric second-order method: order 2k needs
# sum w_i^(2j+1) = 0 for j = 1 .. k-1 (Yoshida 1990; HLW II.4). The weights are the drifts.
COMPOSITION_ODD_POWERS = {"forest-ruth": (3,), "yoshida6": (3, 5), "yoshida8": (3, 5, 7)}


def test_the_in_house_tables_are_registered():
    names = set(steppers.names())
    assert set(RK_STAGES) <= names
    assert set(SPLITTING_FACTS) <= names
    assert {"stormer-verlet", "verlet-damped"} <= names


# -- self-checks of every registered table ---------------------------------------------------------
@pytest.mark.parametrize("stepper", TABLEAU_STEPPERS, ids=ids(TABLEAU_STEPPERS))
def test_tableau_explicitness_matches_the_claim_and_the_arrays_are_frozen(stepper):
    """Row sums, weight sum and shapes are the constructor's checks (the perturbed-table tests
    below show it refuses each); here: what the stepper declares against the table."""
    tab = stepper.coefficients
    strictly_lower = bool(np.all(np.triu(tab.A) == 0.0))
    assert tab.explicit == strictly_lower == stepper.info.explicit
    with pytest.raises(ValueError):
        tab.A[0, 0] = 1.0  # frozen: the arrays are read-only


@pytest.mark.parametrize("stepper", TABLEAU_STEPPERS, ids=ids(TABLEAU_STEPPERS))
def test_tableau_with_a_perturbed_weight_is_refused(stepper):
    tab = stepper.coefficients
    b = tab.b.copy()
    b[-1] += 1e-6
    with pytest.raises(CoefficientError, match=r"must sum to 1"):
        ButcherTableau(tab.name, tab.A, b, tab.c)


@pytest.mark.parametrize("stepper", TABLEAU_STEPPERS, ids=ids(TABLEAU_STEPPERS))
def test_tableau_with_a_perturbed_stage_coefficient_is_refused(stepper):
    tab = stepper.coefficients
    A = tab.A.copy()
    A[-1, 0] += 1e-6
    with pytest.raises(CoefficientError, match=r"row \d+ of A sums to .* the row sums of A must equal"):
        ButcherTableau(tab.name, A, tab.b, tab.c)


@pytest.mark.parametrize("stepper", SPLITTING_STEPPERS, ids=ids(SPLITTING_STEPPERS))
def test_splitting_sequence_is_normal_and_rebuilds_to_itself(stepper):
    """The coefficient sums are the constructor's checks (the perturbed-scheme test below shows
    it refuses them); here: no two operations of one kind in a row, even after zero-weight
    operations were dropped, and the stored sequence is a fixed point of the constructor."""
    scheme = stepper.coefficients
    kinds = [k for k, _ in scheme.sequence]
    assert all(a != b for a, b in zip(kinds, kinds[1:], strict=False)), "adjacent kinds merged"
    rebuilt = SplittingScheme(scheme.name, scheme.sequence)
    assert rebuilt.sequence == scheme.sequence


@pytest.mark.parametrize("stepper", SPLITTING_STEPPERS, ids=ids(SPLITTING_STEPPERS))
@pytest.mark.parametrize("kind", ["D", "K"])
def test_splitting_with_a_perturbed_coefficient_is_refused(stepper, kind):
    seq = list(stepper.coefficients.sequence)
    i = next(j for j, (k, _) in enumerate(seq) if k == kind)
    seq[i] = (kind, seq[i][1] + 1e-6)
    word = "drift" if kind == "D" else "kick"
    with pytest.raises(CoefficientError, match=rf"{word} coefficients must sum to 1"):
        SplittingScheme(stepper.info.name, seq)


# -- derived facts ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(RK_STAGES))
def test_runge_kutta_derived_facts(name):
    stepper = steppers.get(name)
    tab = stepper.coefficients
    assert tab.stages == RK_STAGES[name]
    assert tab.explicit and stepper.info.explicit
    assert stepper.info.evals_per_step == tab.stages
    assert not stepper.info.symmetric and not stepper.info.symplectic
    assert stepper.info.form == "first-order"


@pytest.mark.parametrize("name", sorted(SPLITTING_FACTS))
def test_splitting_derived_facts(name):
    stepper = steppers.get(name)
    scheme = stepper.coefficients
    force_evals, symmetric = SPLITTING_FACTS[name]
    assert scheme.force_evals == force_evals
    assert scheme.symmetric is symmetric
    assert stepper.info.evals_per_step == force_evals
    assert stepper.info.symmetric is symmetric
    assert stepper.info.symplectic and stepper.info.explicit
    assert stepper.info.form == "newtonian" and not stepper.info.velocity_dependent


@pytest.mark.parametrize("name", sorted(COMPOSITION_ODD_POWERS))
def test_composition_weights_satisfy_the_odd_power_conditions(name):
    weights = steppers.get(name).coefficients.drift_coefficients
    assert abs(weights.sum() - 1.0) <= COEFFICIENT_TOL
    for power in COMPOSITION_ODD_POWERS[name]:
        assert abs(np.sum(weights**power)) <= ORDER_CONDITION_TOL, power
    # ... and the next odd power does not vanish: the order is not higher than claimed.
    assert abs(np.sum(weights ** (COMPOSITION_ODD_POWERS[name][-1] + 2))) > 1e-3


def test_yoshida_compositions_are_velocity_verlet_compositions():
    for name, stages in (("yoshida6", 7), ("yoshida8", 15)):
        scheme = steppers.get(name).coefficients
        weights = scheme.drift_coefficients
        assert weights.size == stages
        rebuilt = SplittingScheme.compose(name, VELOCITY_VERLET, weights)
        assert rebuilt.sequence == scheme.sequence


def test_stormer_table_is_consistent():
    assert STORMER.steps == 2 and STORMER.explicit
    np.testing.assert_array_equal(STORMER.alpha, [1.0, -2.0, 1.0])
    np.testing.assert_array_equal(STORMER.beta, [0.0, 1.0, 0.0])
    for name in ("stormer-verlet", "verlet-damped"):
        assert steppers.get(name).coefficients.fingerprint() == STORMER.fingerprint()


# Every (registered table, fact) whose coefficients say whether the map is symplectic or symmetric.
DERIVED_GEOMETRY = [(s, fact) for s in TABLE_STEPPERS for fact in ("symplectic", "symmetric")
                    if getattr(s.coefficients, fact, None) is not None]


@pytest.mark.parametrize("stepper, fact", DERIVED_GEOMETRY,
                         ids=[f"{s.info.name}-{fact}" for s, fact in DERIVED_GEOMETRY])
def test_declared_geometry_equals_what_the_coefficients_derive(stepper, fact):
    """Swept over every registered table, so a new method is checked without a new entry above:
    the declaration agrees with the coefficients (the textbook tables above check the
    derivations themselves)."""
    assert getattr(stepper.info, fact) == bool(getattr(stepper.coefficients, fact))


@pytest.mark.parametrize("stepper", TABLE_STEPPERS, ids=ids(TABLE_STEPPERS))
def test_order_from_coefficients_equals_claim(stepper):
    assert order_from_coefficients(stepper) == stepper.info.claimed_order


# -- broken tables ------------------------------------------------------------------------------------
BROKEN = [
    (
        "row sum differs from node",
        lambda: ButcherTableau("bad", [[0, 0], [Fraction(1, 2), 0]], [0, 1], [0, 1]),
        r"row 1 of A sums to 0.5 but node c\[1\] is 1.0",
    ),
    (
        "weights do not sum to one",
        lambda: ButcherTableau("bad", [[0, 0], [1, 0]], [0.5, 0.4]),
        r"`bad.b` must sum to 1 \(consistency\)",
    ),
    (
        "stage matrix not square",
        lambda: ButcherTableau("bad", [[0, 0, 0], [1, 0, 0]], [0.5, 0.5]),
        r"`bad.A` must be 2x2",
    ),
    (
        "non-finite coefficient",
        lambda: ButcherTableau("bad", [[0, 0], [float("nan"), 0]], [0.5, 0.5]),
        r"`bad.A` must be finite",
    ),
    (
        "drifts do not sum to one",
        lambda: SplittingScheme("bad", [("K", 0.5), ("D", 0.9), ("K", 0.5)]),
        r"`bad`: drift coefficients must sum to 1",
    ),
    (
        "kicks do not sum to one",
        lambda: SplittingScheme("bad", [("D", 0.5), ("K", 1.1), ("D", 0.5)]),
        r"`bad`: kick coefficients must sum to 1",
    ),
    (
        "unknown operation",
        lambda: SplittingScheme("bad", [("X", 1.0), ("K", 1.0)]),
        r"kinds must be 'D' or 'K'",
    ),
    (
        "inconsistent multistep",
        lambda: LinearMultistep("bad", [-1, 1], [0.5, 0.4]),
        r"sum j\*alpha_j must equal sum beta_j \(consistency\)",
    ),
    (
        "multistep alpha not summing to zero",
        lambda: LinearMultistep("bad", [-0.9, 1], [1, 0]),
        r"sum of alpha must be 0 \(consistency\)",
    ),
    (
        "inconsistent second-order multistep",
        lambda: SecondOrderMultistep("bad", [1, -2, 1], [0, 0.9, 0]),
        r"consistency needs sum j\^2 alpha_j / 2 = sum beta_j",
    ),
    (
        "implicit tableau in the explicit loop",
        lambda: ExplicitRungeKutta(
            ButcherTableau("bad", [[Fraction(1, 2)]], [1]), claimed_order=2, reference="x"
        ),
        r"`bad`: an explicit Runge-Kutta stepper needs a strictly lower triangular",
    ),
    (
        "not a tableau",
        lambda: ExplicitRungeKutta(STORMER, claimed_order=2, reference="x"),
        r"`tableau` must be a ButcherTableau, got SecondOrderMultistep",
    ),
    (
        "not a scheme",
        lambda: SplittingStepper(STORMER, claimed_order=2, reference="x"),
        r"`scheme` must be a SplittingScheme",
    ),
    (
        "leapfrog from a drift-kick-drift scheme",
        lambda: StaggeredLeapfrog(
            "bad", SplittingScheme("pv", [("D", 0.5), ("K", 1.0), ("D", 0.5)]), reference="x"
        ),
        r"the staggered leapfrog needs a symmetric kick-drift-kick scheme",
    ),
    (
        "three-step table in the two-step Verlet loop",
        lambda: TwoStepVerlet(
            "bad",
            SecondOrderMultistep("s3", [0, 1, -2, 1], [0, 0, 1, 0]),
            implicit_velocity=False,
            reference="x",
        ),
        r"`s3`: the two-step Verlet loop needs a two-step table",
    ),
]


@pytest.mark.parametrize("build, pattern", [b[1:] for b in BROKEN], ids=[b[0] for b in BROKEN])
def test_broken_tables_are_refused(build, pattern):
    with pytest.raises(CoefficientError, match=pattern):
        build()


def test_a_tableau_published_with_12_digits_is_accepted_with_its_defect_stated():
    """Bogacki-Shampine's fractions (2/9, 4/9, ...) printed to 12 significant digits: the row
    sums miss their nodes by ~1e-12, far above float rounding, a defect of the printing only."""
    from harness.registry import get_stepper

    exact = get_stepper("bogacki-shampine").coefficients
    cut = lambda v: [float(f"{x:.12g}") for x in v]  # noqa: E731
    A, b, c = [cut(row) for row in exact.A], cut(exact.b), cut(exact.c)
    published = ButcherTableau("bs-12-digits", A, b, c)
    assert 1e-14 < published.consistency_defect < 1e-11
    assert "1e-12" in published.defect_note or "e-12" in published.defect_note
    assert published.order() == exact.order() == 3
    assert ButcherTableau("bs-exact", exact.A, exact.b, exact.c).consistency_defect == 0.0
    off = [row[:] for row in A]
    off[3][0] += 1e-9  # a real defect, 1000 times the printing's
    with pytest.raises(CoefficientError, match="row 3 of A sums to"):
        ButcherTableau("bs-off", off, b, c)


@pytest.mark.parametrize("family, seed", [("extrap-euler", 0), ("extrap-midpoint", 0),
                                          ("extrap-euler", 1)])
def test_exact_rationals_are_not_read_as_cut_decimals(family, seed):
    """An exact extrapolation weight such as 1e8/807 prints as a float of 10-15 significant
    digits; read as a cut decimal it gave a 56-stage order-10 tableau a printing of 5e-8, which
    let its order-11 and order-12 conditions (missed by 3e-9) pass: order 12 from the
    coefficients. Fractions are exact: no printing, and the order is the one built."""
    import numpy as np

    from harness.high_order import build_high_order, draw_high_order

    rng = np.random.default_rng(seed)
    for made in range(3):
        spec, claimed = draw_high_order(family, rng, 12)
        tableau = build_high_order(spec, f"t-{family}-{seed}-{made}")
        assert tableau.published_precision == 0.0
        assert tableau.order() == claimed
    # the same values typed as floats of 12 digits are a printing
    cut = ButcherTableau("cut", [[float(f"{float(x):.12g}") for x in row] for row in tableau.A],
                         [float(f"{float(x):.12g}") for x in tableau.b])
    assert cut.published_precision > 0.0
