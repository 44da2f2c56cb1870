"""Exact h omega stability of Newtonian methods: every instability band on x'' = -omega^2 x.

With x = (h omega)^2 every figure is decided on polynomials in x with rational coefficients
(`harness.theory.roots`), never by sampling (a scan misses bands narrower than its step: the
resonance bands of compositions near h omega = k pi are often ~1e-2 wide or less).

- Splitting schemes (`splitting_hw_bands`): the propagator M is a product of drifts
  [[1, a h], [0, 1]] and kicks [[1, 0], [-b h, 1]], so det M = 1 and tr M = T(x) is a
  polynomial in x; M is stable (eigenvalues on the unit circle, distinct) where |T(x)| < 2.
  The band ends are the positive roots of T - 2 and T + 2. Hairer, Lubich & Wanner, *Geometric
  Numerical Integration*, I.5 and V.3; McLachlan & Gray, Appl. Numer. Math. 25 (1997) 275 (the
  resonance bands of compositions).
- Second-order multistep methods (`lmm2_hw_bands`): the characteristic polynomial
  p(zeta; x) = sum_j (alpha_j + x beta_j) zeta^j. A symmetric method has periodic solutions
  (interval of periodicity, Lambert & Watson, IMA J. Appl. Math. 18 (1976) 189) where every root
  lies on the unit circle and is simple: with w = zeta + 1/zeta, p(zeta)/zeta^(k/2) = q(w) and
  the condition is that q has k/2 distinct real roots in (-2, 2), counted exactly by a Sturm
  sequence; the band ends are among the roots in x of q(2), q(-2), the discriminant of q and
  the leading coefficient. A method that is not symmetric has no interval of periodicity
  (Lambert & Watson); its stability figure is where the spectral radius stays <= 1: roots
  strictly inside the disc (Schur-Cohn, exact), with band ends among the roots of the resultant
  of p and its reversed polynomial (a root on the circle is a common root of both).

Between two consecutive candidate ends the verdict is constant, so it is decided at one
rational point of each piece; a candidate with stable pieces on both sides is listed as a
marginal point (an eigenvalue +-1 of multiplicity two: M = +-I, or linear growth), not a band.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING

from harness import tolerances as tol
from harness.theory.amplification import hw_stability_limit, splitting_amplification
from harness.theory.checks import check_type, family_of
from harness.theory.roots import (
    Poly,
    count_roots_between,
    isolate_real_roots,
    padd,
    peval,
    pmul,
    poly,
    pscale,
    psub,
    resultant_in_x,
    schur_all_inside,
    squarefree,
    sturm_sequence,
)

if TYPE_CHECKING:  # annotations only: the theory reads coefficient objects by their `family`
    from harness.coefficients import SecondOrderMultistep, SplittingScheme

__all__ = ["HwBands", "splitting_trace_exact", "splitting_hw_bands", "lmm2_hw_bands", "hw_bands",
           "velocity_weights"]


@dataclass(frozen=True)
class HwBands:
    """The h omega stability of a Newtonian method on x'' = -omega^2 x, decided exactly.

    limit : the first instability: the largest h omega with the method stable on (0, limit)
        (0.0 when it is unstable for every small h omega, inf when it is never unstable)
    bands : every unstable band (start, end) in h omega whose start is at most `hw_max`; the end
        is inf for the band that never closes
    marginal : h omega values <= `hw_max` where the criterion is on its boundary with stable
        h omega on both sides
    criterion : the condition decided, in words
    hw_max : the h omega up to which bands are listed
    """

    limit: float
    bands: tuple[tuple[float, float], ...]
    marginal: tuple[float, ...]
    criterion: str
    hw_max: float
    exact: bool = True  # False: `limit` from a sampled scan, `bands` not derived

    def describe(self) -> str:
        """The bands as one line of text.

        Returns
        -------
        str: "stable for every h omega (<criterion>)" or "unstable on [a, b], ...".
        """
        if not self.exact:
            return f"first instability at h omega {self.limit:.10g} ({self.criterion})"
        if not self.bands:
            return f"stable for every h omega ({self.criterion})"
        parts = [f"[{a:.10g}, {b:.10g}]" if math.isfinite(b) else f"[{a:.10g}, inf)" for a, b in self.bands]
        return "unstable on " + ", ".join(parts)


def _hw(x: Fraction) -> float:
    return math.sqrt(float(x))


def _bands(critical: list[Poly], stable: Callable[[Fraction], bool], hw_max: float,
           criterion: str) -> HwBands:
    """Bands from candidate end polynomials in x and an exact verdict at rational x."""
    intervals = []
    for p in critical:
        if len(p) > 1:
            intervals += isolate_real_roots(p, Fraction(0))
    intervals.sort()
    points: list[list[Fraction]] = []
    for lo, hi in intervals:  # coincident roots of different candidates: one point
        if points and lo <= points[-1][1]:
            points[-1][1] = max(points[-1][1], hi)
        else:
            points.append([lo, hi])
    cuts = [Fraction(0)] + [p for pair in points for p in pair]
    samples = [(cuts[2 * i] + cuts[2 * i + 1]) / 2 for i in range(len(points))]
    samples.append(2 * cuts[-1] + 1)
    verdicts = [stable(s) for s in samples]
    roots = [(lo + hi) / 2 for lo, hi in points]
    x_max = Fraction(hw_max) ** 2
    bands, marginal = [], []
    limit = math.inf
    i = 0
    while i < len(verdicts):
        if verdicts[i]:
            if i < len(roots) and i + 1 < len(verdicts) and verdicts[i + 1] and roots[i] <= x_max:
                marginal.append(_hw(roots[i]))
            i += 1
            continue
        j = i
        while j + 1 < len(verdicts) and not verdicts[j + 1]:
            j += 1
        start = Fraction(0) if i == 0 else roots[i - 1]
        end = _hw(roots[j]) if j < len(roots) else math.inf
        if start <= x_max:
            bands.append((_hw(start), end))
        if math.isinf(limit):
            limit = _hw(start)
        i = j + 1
    return HwBands(limit, tuple(bands), tuple(marginal), criterion, float(hw_max))


def splitting_trace_exact(scheme: SplittingScheme) -> Poly:
    """tr M of a splitting's propagator on x'' = -x as an exact polynomial in x = h^2 (the
    trace is even in h: M(-h) = S M(h) S with S = diag(1, -1)).

    Parameters
    ----------
    scheme : SplittingScheme, the composition (its exact form when it has one).

    Returns
    -------
    Poly: the trace's coefficients in ascending powers of x = h^2.
    """
    check_type(scheme, "splitting", "scheme")
    seq = scheme.exact if scheme.exact is not None else scheme.sequence
    one, zero = (Fraction(1),), ()
    M = [[one, zero], [zero, one]]  # entries: polynomials in h
    for kind, c in seq:
        ch = (Fraction(0), Fraction(c))
        if kind == "D":
            M = [[padd(M[0][j], pmul(ch, M[1][j])) for j in range(2)], M[1]]
        else:
            M = [M[0], [psub(M[1][j], pmul(ch, M[0][j])) for j in range(2)]]
    trace = padd(M[0][0], M[1][1])
    return poly(trace[0::2])


def splitting_hw_bands(scheme: SplittingScheme, hw_max: float = tol.STABILITY_HW_SEARCH_LIMIT) -> HwBands:
    """Every h omega band where the splitting is unstable: |tr M| > 2 (det M = 1).

    Parameters
    ----------
    scheme : SplittingScheme
    hw_max : float, optional, the end of the search in h omega (STABILITY_HW_SEARCH_LIMIT).

    Returns
    -------
    HwBands: the exact unstable bands that start at or below `hw_max`.
    """
    check_type(scheme, "splitting", "scheme")
    seq = scheme.exact if scheme.exact is not None else scheme.sequence
    # the trace's degree in x is the number of kicks and its coefficients carry about the sum of
    # the operations' bit lengths (yoshida8: 16 x 4140 against degree 15 x 3982 bits)
    kicks = sum(1 for kind, _ in seq if kind != "D")
    bits = sum(max(Fraction(c).numerator.bit_length(), Fraction(c).denominator.bit_length())
               for _, c in seq)
    if kicks * bits > tol.EXACT_BANDS_MAX_WORK:
        limit = hw_stability_limit(lambda hw: splitting_amplification(scheme, hw), limit=hw_max)
        return HwBands(limit, (), (), f"sampled spectral radius, not isolated exactly: a trace of "
                       f"degree ~{kicks} with ~{bits}-bit coefficients is over the exact budget "
                       f"(EXACT_BANDS_MAX_WORK); a band narrower than the scan step can be missed",
                       float(hw_max), exact=False)
    T = splitting_trace_exact(scheme)
    two = (Fraction(2),)

    def stable(x: Fraction) -> bool:
        return abs(peval(T, x)) < 2

    return _bands([psub(T, two), padd(T, two)], stable, hw_max, "|tr M| < 2, det M = 1")


def _exact_table(method: SecondOrderMultistep) -> tuple[list[Fraction], list[Fraction]]:
    """(alpha, beta) exactly as given when the record is exact, else its float64 values."""
    if getattr(method, "exact", None) is not None:
        return list(method.exact[0]), list(method.exact[1])
    return [Fraction(a) for a in method.alpha], [Fraction(b) for b in method.beta]


def _char_poly(method: SecondOrderMultistep, x: Fraction) -> Poly:
    alpha, beta = _exact_table(method)
    return tuple(a + x * b for a, b in zip(alpha, beta, strict=False))


def _w_polynomial(c: list[Fraction]) -> Poly:
    """q(w) with p(zeta) / zeta^m = q(zeta + 1/zeta) for a palindromic p of degree 2m:
    zeta^i + zeta^-i = V_i(w), V_0 = 2, V_1 = w, V_(i+1) = w V_i - V_(i-1)."""
    m = (len(c) - 1) // 2
    V = [(Fraction(2),), (Fraction(0), Fraction(1))]
    while len(V) <= m:
        V.append(psub(pmul((Fraction(0), Fraction(1)), V[-1]), V[-2]))
    q: Poly = (c[m],)
    for i in range(1, m + 1):
        q = padd(q, pscale(V[i], c[m + i]))
    return q


def lmm2_hw_bands(method: SecondOrderMultistep, hw_max: float = tol.STABILITY_HW_SEARCH_LIMIT) -> HwBands:
    """Every h omega band where a second-order multistep method is unstable (see the module
    docstring: periodicity for symmetric methods, spectral radius <= 1 otherwise).

    Parameters
    ----------
    method : SecondOrderMultistep; hw_max : as for `splitting_hw_bands`.

    Returns
    -------
    HwBands: as for `splitting_hw_bands`.
    """
    check_type(method, "second-order multistep", "method")
    k = method.steps
    alpha, beta = _exact_table(method)
    lead = poly([alpha[k], beta[k]])
    if method.symmetric and k % 2 == 0:
        m = k // 2

        def q_of(x: Fraction) -> Poly:
            return _w_polynomial([a + x * b for a, b in zip(alpha, beta, strict=False)])

        def q_in_x(w: Fraction) -> Poly:  # q(w; x) as a polynomial in x
            return poly([peval(_w_polynomial(alpha), w), peval(_w_polynomial(beta), w)])

        def dq_of(x: Fraction) -> Poly:
            q = q_of(x)
            return tuple(i * q[i] for i in range(1, len(q))) if len(q) > 1 else (Fraction(0),)

        disc = resultant_in_x(q_of, dq_of, 2 * m - 1, (m, m - 1))

        def stable(x: Fraction) -> bool:
            q = q_of(x)
            if len(q) != m + 1:
                return False
            if peval(q, Fraction(2)) == 0 or peval(q, Fraction(-2)) == 0:
                return False
            qs = squarefree(q)
            if len(qs) != len(q):
                return False
            return count_roots_between(qs, Fraction(-2), Fraction(2), sturm_sequence(qs)) == m

        critical = [q_in_x(Fraction(2)), q_in_x(Fraction(-2)), disc, lead]
        return _bands(critical, stable, hw_max, "every root on the unit circle and simple (periodicity)")

    def p_of(x: Fraction) -> Poly:
        return _char_poly(method, x)

    def rev_of(x: Fraction) -> Poly:
        return tuple(reversed(_char_poly(method, x)))

    res = resultant_in_x(p_of, rev_of, 2 * k, (k, k))

    def stable(x: Fraction) -> bool:
        p = p_of(x)
        return p[-1] != 0 and schur_all_inside(p)

    if not res:
        raise ValueError(f"`{method.name}`: a root stays on the unit circle for every h omega; "
                         "its stability is not decided by the resultant")
    return _bands([res, lead], stable, hw_max, "every root strictly inside the unit disc")


def hw_bands(coefficients, hw_max: float = tol.STABILITY_HW_SEARCH_LIMIT) -> HwBands | None:
    """The exact bands of a Newtonian coefficient object, or None for another kind.

    Parameters
    ----------
    coefficients : coefficient object, any object; read by the `family` it declares.
    hw_max : float, optional, the end of the search in h omega (STABILITY_HW_SEARCH_LIMIT).

    Returns
    -------
    HwBands or None: `splitting_hw_bands` or `lmm2_hw_bands`; None for a first-order family.
    """
    family = family_of(coefficients)
    if family == "splitting":
        return splitting_hw_bands(coefficients, hw_max)
    if family == "second-order multistep":
        return lmm2_hw_bands(coefficients, hw_max)
    return None


def velocity_weights(m: int) -> list[Fraction]:
    """c_0..c_(m-1) of v_n = (x_n - x_(n-1)) / h + h sum_j c_j a_(n-j): c_j = int_0^1 u l_j(u) du
    with l_j the Lagrange basis on the nodes u_j = 1 - j (order m + 1).

    Parameters
    ----------
    m : int, number of weights.

    Returns
    -------
    list of Fraction: c_0, ..., c_(m-1), exact.
    """
    nodes = [Fraction(1 - j) for j in range(m)]
    out = []
    for j, uj in enumerate(nodes):
        poly = [Fraction(1)]  # l_j(u), ascending
        for i, ui in enumerate(nodes):
            if i != j:
                d = uj - ui
                poly = [(poly[p - 1] if p > 0 else 0) / d - (poly[p] if p < len(poly) else 0) * ui / d
                        for p in range(len(poly) + 1)]
        out.append(sum(c / (p + 2) for p, c in enumerate(poly)))  # int_0^1 u * u^p du
    return out
