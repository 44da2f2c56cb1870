"""Maps that split an N-body problem into Kepler motion and a perturbation: the expected
convergence from their error law in the perturbation's size, not from their order alone.

A Wisdom-Holman-type map drifts every body along its Kepler orbit about the central mass (solved
exactly) and kicks with the interactions, whose size relative to the central attraction is
eps = (largest other mass) / (central mass). Its global error is a sum of terms eps^a h^b
(Wisdom & Holman 1991: eps h^2; Laskar & Robutel 2001: SABAn eps h^(2n) + eps^2 h^2, and with the
corrector SABACn eps h^(2n) + eps^2 h^4), so the slope a step sweep measures is b of the term that
dominates at its steps, not one "order". The facts read:
- the method's declared law, `info.extra["perturbation_error"]` = [[a, b], ...], and
  `info.extra["kepler_flow_exact"]` (its drift is the Kepler flow); a method without a law is
  judged by `harness.rules` as before;
- the problem's N-body structure (`Problem.structure`, `harness.problem.NBody`): eps from its
  masses, 0 when `perturbation_free` (one body with mass about the central one, or test
  particles), and the time scale tau = period / (2 pi) that makes h dimensionless.
Rule (`perturbation_expectation`), first that applies:
1. eps = 0 and the drift is the Kepler flow: `exact` (nothing is approximated; only rounding
   remains).
2. The cell measured an order over steps [h_min, h_max]: with unit constants in eps^a (h/tau)^b,
   one term exceeds every other by SPLIT_TERM_DOMINANCE at both ends: `converged` at its b.
3. The dominant term changes inside the fitted steps (or leads another by less than that factor):
   the constants are unknown, so either term may set the slope there. A slope equal to one
   term's power passes; one between the powers (a mixed regime) is not measurable; one outside
   [min b, max b] fails (no sum of the terms has it). The crossover steps
   h* = tau eps^((a2-a1)/(b1-b2)) are printed.
4. No fitted steps (the sweep stopped at the rounding floor or its budget): the usual tolerated
   verdicts; expected order that of the term dominating at h = tau.
References: J. Wisdom, M. Holman, AJ 102 (1991) 1528; J. Laskar, P. Robutel, Celest. Mech. Dyn.
Astron. 80 (2001) 39-62; H. Rein, D. Tamayo, MNRAS 452 (2015) 376.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

from harness import tolerances as tol
from harness.problem import NBody, Problem
from harness.rules import Expectation, judge_convergence

__all__ = ["ErrorLaw", "error_law", "perturbation_size", "perturbation_expectation", "judge_split_map"]


@dataclass(frozen=True)
class ErrorLaw:
    """Global error ~ sum of eps^a h^b over `terms` ((a, b) pairs); `kepler_flow_exact`: the
    unperturbed motion is integrated exactly."""

    terms: tuple[tuple[int, int], ...]
    kepler_flow_exact: bool

    def describe(self) -> str:
        """The law in words, as a sum of terms eps^a h^b.

        Returns
        -------
        str: e.g. 'eps h^2 + eps^2 h^4'.
        """
        return " + ".join(f"eps{'' if a == 1 else '^' + str(a)} h^{b}" for a, b in self.terms)


def error_law(stepper) -> ErrorLaw | None:
    """The declared error law of `stepper` in the perturbation, or None when it declares none.

    Parameters
    ----------
    stepper : a stepper; its `info.extra['perturbation_error']` lists the law's (a, b) powers and
    `info.extra['kepler_flow_exact']` whether its drift is the Kepler flow.

    Returns
    -------
    ErrorLaw or None.
    """
    extra = getattr(getattr(stepper, "info", None), "extra", None) or {}
    raw = extra.get("perturbation_error")
    if not raw:
        return None
    terms = tuple((int(a), int(b)) for a, b in raw)
    return ErrorLaw(terms, bool(extra.get("kepler_flow_exact", False)))


def perturbation_size(problem: Problem) -> float | None:
    """eps: the largest mass other than the central one over the central mass (0 for a problem
    whose bodies move on unperturbed Kepler orbits); None without an N-body structure.

    Parameters
    ----------
    problem : Problem, read through its `structure`.

    Returns
    -------
    float or None: eps.
    """
    s = getattr(problem, "structure", None)
    if not isinstance(s, NBody):
        return None
    if s.perturbation_free:
        return 0.0
    others = [m for i, m in enumerate(s.masses) if i != s.central]
    return max(others) / s.masses[s.central]


def _crossings(law: ErrorLaw, eps: float, tau: float) -> list[str]:
    out = []
    for i, (a1, b1) in enumerate(law.terms):
        for a2, b2 in law.terms[i + 1:]:
            if b1 != b2:
                h = tau * eps ** ((a2 - a1) / (b1 - b2))
                out.append(f"eps^{a1} h^{b1} = eps^{a2} h^{b2} at h* = {h:.3g}")
    return out


def _dominant(law: ErrorLaw, eps: float, x: float) -> tuple[int, float]:
    """(index of the largest term at dimensionless step x, its ratio to the next largest)."""
    logs = [a * math.log(eps) + b * math.log(x) for a, b in law.terms]
    order = sorted(range(len(logs)), key=lambda k: logs[k], reverse=True)
    ratio = math.exp(logs[order[0]] - logs[order[1]]) if len(logs) > 1 else math.inf
    return order[0], ratio


def perturbation_expectation(law: ErrorLaw, eps: float, tau: float,
                             h_range: tuple[float, float] | None) -> Expectation:
    """The expectation for a map with error law `law` on a problem with perturbation `eps` and
    time scale `tau` over the fitted steps `h_range` (None: no fit): verdict `between` when no
    single term dominates there (see the module docstring).

    Parameters
    ----------
    law : ErrorLaw, the map's declared law; eps : float, the perturbation size; tau : float, the
    problem's time scale (period / 2 pi); h_range : (h_min, h_max) of the fit, or None.

    Returns
    -------
    Expectation: the expected verdict ('exact', 'converged' with the dominant power, or
    'between'), the verdicts tolerated and the reason.
    """
    tolerated = ("insufficient-range", "exact")
    if eps == 0.0 and law.kepler_flow_exact:
        return Expectation("exact", None, ("insufficient-range",),
                           "the perturbation vanishes (eps = 0: every body orbits the central mass "
                           "alone) and the map's drift is the Kepler flow, so it is exact up to "
                           "rounding")
    if eps == 0.0:
        return Expectation("exact", None, ("insufficient-range",),
                           f"the perturbation vanishes (eps = 0) and every term of the law "
                           f"{law.describe()} carries eps")
    crossings = "; ".join(_crossings(law, eps, tau))
    where = f"law {law.describe()} with eps = {eps:.3g}, tau = {tau:.3g}" + (
        f" ({crossings})" if crossings else "")
    if h_range is None or not all(math.isfinite(h) and h > 0 for h in h_range):
        k, _ = _dominant(law, eps, 1.0)
        a, b = law.terms[k]
        return Expectation("converged", float(b), tolerated,
                           f"{where}: eps^{a} h^{b} dominates at h = tau")
    lo, hi = sorted(h_range)
    k_lo, r_lo = _dominant(law, eps, lo / tau)
    k_hi, r_hi = _dominant(law, eps, hi / tau)
    span = f"the fitted steps h = {lo:.3g}..{hi:.3g}"
    if k_lo == k_hi and min(r_lo, r_hi) >= tol.SPLIT_TERM_DOMINANCE:
        a, b = law.terms[k_lo]
        return Expectation("converged", float(b), tolerated,
                           f"{where}: eps^{a} h^{b} dominates over {span}")
    a_lo, b_lo = law.terms[k_lo]
    a_hi, b_hi = law.terms[k_hi]
    if k_lo == k_hi:
        why = (f"eps^{a_lo} h^{b_lo} leads the next term by only {min(r_lo, r_hi):.3g}x "
               f"(< {tol.SPLIT_TERM_DOMINANCE:g}) over {span}")
    else:
        why = f"eps^{a_hi} h^{b_hi} leads at h = {hi:.3g} and eps^{a_lo} h^{b_lo} at h = {lo:.3g}"
    # The constants are unknown, so near a crossover either term may set the slope; a sum of
    # terms eps^a h^b has a local slope between the smallest and the largest b.
    return Expectation("between", None, tolerated, f"{why} ({where})")


def _judge_between(record: Mapping, law: ErrorLaw, expectation: Expectation) -> tuple[str, str]:
    """Near a crossover: a measured slope equal to one term's power (the fit's plateau shows one
    term dominating) passes; one between the powers is a mixed regime, not measurable; one
    outside [min b, max b] contradicts the law."""
    if record.get("verdict") != "converged":
        return judge_convergence(dict(record), dataclasses.replace(expectation, verdict="converged"))
    measured = float(record["measured_order"])
    powers = sorted({b for _, b in law.terms})
    near = [b for b in powers if abs(measured - b) <= tol.GATE_ORDER_TOL]
    if near:
        return "pass", (f"measured {measured:.3f} = the power of one term, h^{near[0]}: unit constants put "
                        f"the steps near a crossover, {expectation.reason}")
    if powers[0] - tol.GATE_ORDER_TOL < measured < powers[-1] + tol.GATE_ORDER_TOL:
        return "not-measurable", (f"not measurable: measured {measured:.3f} lies between the law's powers "
                                  f"{powers} (a mixed regime near a crossover): {expectation.reason}")
    return "fail", (f"measured order {measured:.3f} lies outside the powers {powers[0]}..{powers[-1]} "
                    f"that any sum of the law's terms allows: {expectation.reason}")


def judge_split_map(record: Mapping, stepper, problem: Problem
                    ) -> tuple[str, str, str, float | None] | None:
    """(outcome, expected verdict, reason, expected order) of one convergence record of a map with
    a declared error law on an N-body problem; None when the rule does not apply (no law, no
    N-body structure, an adaptive run, or a claimed order that is none of the law's powers: that
    claim is then judged plainly, and fails where the law holds).

    Parameters
    ----------
    record : one convergence record (its verdict and fitted h range are read); stepper : the
    stepper run; problem : Problem, the problem run.

    Returns
    -------
    tuple or None: (outcome, expected verdict, reason, expected order or None).
    """
    law = error_law(stepper)
    eps = perturbation_size(problem)
    if law is None or eps is None or record.get("verdict") == "meets-tolerance":
        return None
    claimed = getattr(stepper.info, "claimed_order", None)
    if claimed is not None and claimed not in {b for _, b in law.terms}:
        return None  # a claimed order the law does not contain is judged as a plain claim
    tau = float(problem.time_scale.period) / (2.0 * math.pi)
    h_range = (float(record.get("fit_h_min", math.nan)), float(record.get("fit_h_max", math.nan)))
    fitted = record.get("verdict") == "converged"
    expectation = perturbation_expectation(law, eps, tau, h_range if fitted else None)
    if expectation.verdict == "between":
        outcome, reason = _judge_between(record, law, expectation)
        return outcome, "converged", reason, None
    outcome, reason = judge_convergence(dict(record), expectation)
    return outcome, expectation.verdict, reason or expectation.reason, expectation.order
