"""Judge the judge: populations of methods nobody registered, and the gate's error rates on them.

Correct methods are random members of parametric families, each with a correct claim:
- explicit Runge-Kutta, two stages order 2 (c2 free), three stages order 3 (c2, c3 free) and
  four stages order 4 (Kutta's family with c2, c3 free, c4 = 1) (Hairer, Norsett & Wanner I,
  II.1, eqs. (1.10)-(1.11) and Table 1.2; Butcher, *Numerical Methods for ODEs*, 2016, 32);
- symmetric splitting compositions: order 2 drift-kick-drift-kick-drift with a free drift
  a (McLachlan, SIAM J. Sci. Comput. 16 (1995) 151) and order 4 five-fold symmetric
  compositions of velocity Verlet (w1, w2, w0, w2, w1) with w1 free (Suzuki, Phys. Lett. A 146
  (1990) 319; HLW II.4, V.3);
- zero-stable explicit two-step methods of order 2, rho(zeta) = (zeta - 1)(zeta - a) with
  |a| < 1 (HNW I, III.2).
Each is checked on creation against its family's order from its coefficients (a sample the
formulas make degenerate is redrawn). Mutants of each: one coefficient perturbed so an order
condition breaks (`perturbed`, typically down to order 1), a subtle mutant that keeps every
condition below the claimed order and breaks only the top ones (`subtle`: Runge-Kutta weights
moved within the null space of the lower-order conditions, which are linear in b; a symmetric
composition moved symmetrically, which keeps order 2 and loses 4), and the correct
coefficients with a claim one too high (`overclaimed`).

At high order (`harness.high_order`, `generate(..., families=HIGH_FAMILIES)`): Aitken-Neville
extrapolation of explicit Euler (orders 5-12) and of the midpoint rule (orders 6-12) with random
step sequences, written as exact Runge-Kutta tableaus, and symmetric compositions of velocity
Verlet (orders 4-10, a random triple jump or Suzuki five-fold at each level); mutants: an entry of
A moved (`perturbed`), weights moved in the exact null space of the conditions below the claimed
order (`subtle`, Runge-Kutta) or the top level's outer weights moved symmetrically (`subtle`,
compositions: two orders below), and a claim one too high.

`error_rates` runs the gate over a population: a false alarm is a correct method that fails,
a miss a mutant that passes. It reports both for the full gate (coefficients and measurement)
and for the measurement alone (every method judged as a black box from its claims).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from scipy.optimize import brentq

from harness.coefficients import ButcherTableau, LinearMultistep, SplittingScheme
from harness.experiments.base import Cell
from harness.experiments.convergence import ConvergenceExperiment
from harness.facts import method_facts, problem_facts
from harness.gate import claim_contradictions
from harness.high_order import (
    HIGH_ORDER_PROBLEMS,
    build_high_order,
    draw_high_order,
    perturb_high_order,
    subtle_high_order,
)
from harness.methods import Method
from harness.registry import get_problem
from harness.registry import steppers as registry
from harness.rules import convergence_expectation, judge_convergence
from harness.theory import rooted_trees

__all__ = ["Member", "generate", "error_rates", "FAMILIES", "HIGH_FAMILIES", "PROBLEMS"]

# Problems each family is measured on: one nonlinear problem (every order condition shows) and,
# for the first-order families, one linear problem (the linear order shows).
PROBLEMS = {
    "rk-s2p2": ("forced-duffing", "dahlquist"),
    "rk-s3p3": ("forced-duffing", "dahlquist"),
    "rk-s4p4": ("forced-duffing", "harmonic"),
    "split-p2": ("pendulum", "harmonic"),
    "split-p4": ("pendulum",),
    "lmm-k2p2": ("forced-duffing", "dahlquist"),
}
FAMILIES = tuple(PROBLEMS)
HIGH_FAMILIES = tuple(HIGH_ORDER_PROBLEMS)
PROBLEMS = {**PROBLEMS, **HIGH_ORDER_PROBLEMS}
_REFERENCE = "generated member of a parametric family (harness.populations)"
_PERTURBATION = 0.05


@dataclass(frozen=True)
class Member:
    """One generated method: its family, the stepper, and whether its claim is correct."""

    family: str
    kind: str  # correct | perturbed | subtle | overclaimed
    stepper: object

    @property
    def correct(self) -> bool:
        return self.kind == "correct"


def _rk2(u: float) -> tuple[list, list]:
    return [[0, 0], [u, 0]], [1 - 1 / (2 * u), 1 / (2 * u)]


def _rk3(u: float, v: float) -> tuple[list, list]:
    b3 = (2 - 3 * u) / (6 * v * (v - u))
    b2 = (3 * v - 2) / (6 * u * (v - u))
    a32 = 1 / (6 * b3 * u)
    return [[0, 0, 0], [u, 0, 0], [v - a32, a32, 0]], [1 - b2 - b3, b2, b3]


def _rk4(u: float, v: float) -> tuple[list, list]:
    d = 6 * u * v - 4 * u - 4 * v + 3
    b2 = (2 * v - 1) / (12 * u * (v - u) * (1 - u))
    b3 = (1 - 2 * u) / (12 * v * (v - u) * (1 - v))
    b4 = d / (12 * (1 - u) * (1 - v))
    a32 = v * (v - u) / (2 * u * (1 - 2 * u))
    a42 = (1 - u) * (u + v - 1 - (2 * v - 1) ** 2) / (2 * u * (v - u) * d)
    a43 = (1 - 2 * u) * (1 - u) * (1 - v) / (v * (v - u) * d)
    A = [[0, 0, 0, 0], [u, 0, 0, 0], [v - a32, a32, 0, 0], [1 - a42 - a43, a42, a43, 0]]
    return A, [1 - b2 - b3 - b4, b2, b3, b4]


def _split2(a: float) -> list:
    return [("D", a), ("K", 0.5), ("D", 1 - 2 * a), ("K", 0.5), ("D", a)]


def _split4(w1: float) -> list | None:
    """Weights (w1, w2, w0, w2, w1) with 2 w1 + 2 w2 + w0 = 1 and 2 w1^3 + 2 w2^3 + w0^3 = 0."""
    def g(w2: float) -> float:
        w0 = 1 - 2 * w1 - 2 * w2
        return 2 * w1**3 + 2 * w2**3 + w0**3

    grid = np.linspace(-2, 2, 4001)
    vals = [g(x) for x in grid]
    for i in range(len(grid) - 1):
        if vals[i] * vals[i + 1] < 0:
            w2 = brentq(g, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-15)
            w0 = 1 - 2 * w1 - 2 * w2
            seq = []
            for w in (w1, w2, w0, w2, w1):
                seq += [("K", w / 2), ("D", w), ("K", w / 2)]
            return seq
    return None


def _lmm2(a: float) -> tuple[list, list]:
    return [a, -1 - a, 1], [(-1 - a) / 2, (3 - a) / 2, 0]


def _draw(family: str, rng: np.random.Generator):
    """Coefficients of one correct member, or None for a degenerate draw."""
    if family == "rk-s2p2":
        return _rk2(rng.uniform(0.2, 1.0))
    if family == "rk-s3p3":
        u, v = rng.uniform(0.2, 1.0, size=2)
        if abs(u - v) < 0.15 or abs(u - 2 / 3) < 0.05:
            return None
        return _rk3(u, v)
    if family == "rk-s4p4":
        u, v = rng.uniform(0.2, 0.9, size=2)
        d = 6 * u * v - 4 * u - 4 * v + 3
        if abs(u - v) < 0.15 or abs(u - 0.5) < 0.05 or abs(d) < 0.1:
            return None
        return _rk4(u, v)
    if family == "split-p2":
        return _split2(rng.uniform(0.1, 0.4))
    if family == "split-p4":
        return _split4(rng.uniform(0.2, 0.45))
    if family == "lmm-k2p2":
        return _lmm2(rng.uniform(-0.6, 0.6))
    raise ValueError(f"`family` must be one of {FAMILIES}, got {family!r}")


_CLAIMED = {"rk-s2p2": 2, "rk-s3p3": 3, "rk-s4p4": 4, "split-p2": 2, "split-p4": 4, "lmm-k2p2": 2}


def _stepper(family: str, name: str, coeffs, claimed: int):
    """The generated method as a `Method` record, built by its family's step loop (as a
    plugin's method record is)."""
    if family.startswith("rk-"):
        A, b = coeffs
        return Method(ButcherTableau(name, A, b), claimed, _REFERENCE).stepper()
    if family.startswith("split-"):
        return Method(SplittingScheme(name, coeffs), claimed, _REFERENCE).stepper()
    alpha, beta = coeffs
    return Method(LinearMultistep(name, alpha, beta), claimed, _REFERENCE,
                  description="generated two-step method").stepper()


def _perturb(family: str, coeffs, rng: np.random.Generator):
    """The same method with one coefficient moved so that an order condition breaks (the
    consistency conditions the constructors check are kept)."""
    delta = _PERTURBATION * (1 if rng.uniform() < 0.5 else -1)
    if family.startswith("rk-"):
        A, b = coeffs
        A = [list(map(float, row)) for row in A]
        i = int(rng.integers(1, len(A)))
        j = int(rng.integers(0, i))
        A[i][j] += delta  # the nodes follow the row sums: consistent, but c_i moved
        return A, b
    if family.startswith("split-"):
        seq = [list(x) for x in coeffs]
        drifts = [k for k, (kind, _) in enumerate(seq) if kind == "D"]
        i, j = drifts[0], drifts[-1]
        seq[i][1] += delta  # drifts still sum to one; the symmetry (and an order) breaks
        seq[j][1] -= delta
        return [tuple(x) for x in seq]
    alpha, beta = coeffs
    beta = list(beta)
    beta[0] += delta  # sum beta = sum j alpha_j needs a compensating move: order 1 remains
    beta[1] -= delta
    return alpha, beta


def _subtle(family: str, coeffs, claimed: int):
    """Coefficients of order exactly claimed - 1 (Runge-Kutta) or claimed - 2 (a symmetric
    composition), or None where the family leaves no such freedom."""
    if family.startswith("rk-"):
        A, b = np.array(coeffs[0], dtype=float), np.array(coeffs[1], dtype=float)
        g: list[np.ndarray] = []
        for t in rooted_trees(claimed - 1):
            v = np.ones(len(b))
            for k in t.children:
                v = v * (A @ g[k])
            g.append(v)
        _, sv, vt = np.linalg.svd(np.array(g))
        rank = int(np.sum(sv > 1e-10 * sv[0]))
        if rank >= len(b):
            return None
        d = vt[rank]
        return A.tolist(), (b + _PERTURBATION * d / np.linalg.norm(d)).tolist()
    if family == "split-p4":
        seq = [list(x) for x in coeffs]
        n = len(seq)
        block = n // 5  # five compositions of velocity Verlet, three entries each
        for i in range(block):  # w1 -> w1 + delta at both ends, w0 -> w0 - 2 delta in the middle
            seq[i][1] *= 1 + _PERTURBATION
            seq[n - 1 - i][1] *= 1 + _PERTURBATION
        w1 = sum(v for k, v in coeffs[:block] if k == "D")
        mid = 2 * block
        for i in range(mid, mid + block):
            seq[i][1] -= 2 * _PERTURBATION * w1 * (coeffs[i][1] / sum(v for k, v in coeffs[mid:mid + block]
                                                                     if k == coeffs[i][0]))
        return [tuple(x) for x in seq]
    return None


def _high_order_members(family: str, size: int, rng, seed: int, max_order: int) -> list[Member]:
    """`size` correct members of a high-order family (`harness.high_order`) and their mutants."""
    out: list[Member] = []
    for made in range(size):
        spec, claimed = draw_high_order(family, rng, max_order)
        tag = f"pop-{family}-{seed}-{made}"

        def member(label, member_spec, claim, tag=tag):
            return Method(build_high_order(member_spec, tag + label), claim, _REFERENCE).stepper()

        good = member("", spec, claimed)
        if good.coefficients.order() != claimed:
            raise RuntimeError(f"{tag}: order {good.coefficients.order()} from the coefficients, "
                               f"built for {claimed}")
        out += [Member(family, "correct", good),
                Member(family, "perturbed", member("-perturbed", perturb_high_order(spec, rng), claimed)),
                Member(family, "overclaimed", member("-overclaimed", spec, claimed + 1))]
        subtle = subtle_high_order(spec, claimed)
        if subtle is not None:
            sub = member("-subtle", subtle, claimed)
            if 0 < sub.coefficients.order() < claimed:
                out.append(Member(family, "subtle", sub))
    return out


def generate(size_per_family: int, *, seed: int = 0, families: Sequence[str] = FAMILIES,
             max_order: int = 12) -> list[Member]:
    """`size_per_family` correct members of each family, and a perturbed and an overclaimed
    mutant of each. Every correct member's order from its coefficients equals its claim.
    High-order families (HIGH_FAMILIES) draw orders up to `max_order`.

    Parameters
    ----------
    size_per_family : int, correct members per family; seed : int, the random seed;
    families : names from FAMILIES; max_order : int, the highest order of the high-order
    families.

    Returns
    -------
    list of Member: correct members and their mutants. Raises RuntimeError when a family keeps
    drawing degenerate members.
    """
    rng = np.random.default_rng(seed)
    out: list[Member] = []
    for family in families:
        if family in HIGH_ORDER_PROBLEMS:
            out += _high_order_members(family, size_per_family, rng, seed, max_order)
            continue
        made = 0
        attempts = 0
        while made < size_per_family:
            attempts += 1
            if attempts > 100 * size_per_family:
                raise RuntimeError(f"family {family!r}: too many degenerate draws")
            coeffs = _draw(family, rng)
            if coeffs is None:
                continue
            claimed = _CLAIMED[family]
            tag = f"pop-{family}-{seed}-{made}"
            try:
                good = _stepper(family, tag, coeffs, claimed)
            except Exception:  # a draw the constructors refuse: redraw
                continue
            if good.coefficients.order() != claimed:
                continue
            bad = _stepper(family, f"{tag}-perturbed", _perturb(family, coeffs, rng), claimed)
            if bad.coefficients.order() >= claimed:
                continue
            over = _stepper(family, f"{tag}-overclaimed", coeffs, claimed + 1)
            out += [Member(family, "correct", good), Member(family, "perturbed", bad),
                    Member(family, "overclaimed", over)]
            subtle = _subtle(family, coeffs, claimed)
            if subtle is not None:
                try:
                    sub = _stepper(family, f"{tag}-subtle", subtle, claimed)
                except Exception:  # the move broke a consistency check: no subtle mutant here
                    sub = None
                if sub is not None and 0 < sub.coefficients.order() < claimed:
                    out.append(Member(family, "subtle", sub))
            made += 1
    return out


def error_rates(members: Sequence[Member], *, config: dict | None = None,
                mutant_problems: int = 1) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Run the convergence experiment and the gate over `members` (correct ones on every problem
    of their family, mutants on the first `mutant_problems`) in this process. Returns the
    per-method table and the rates (per family and overall) for the full gate and for the
    measurement alone.

    Parameters
    ----------
    members : the population (from `generate`); config : convergence settings overriding the
    defaults (local off, ensemble 4); mutant_problems : int, how many problems each mutant runs.

    Returns
    -------
    tuple of DataFrame: (one row per method and problem, `rates` of that table).
    """
    exp = ConvergenceExperiment()
    cfg = exp.config({"local": False, "ensemble": 4, **(config or {})})
    rows = []
    for m in members:
        stepper = m.stepper
        name = stepper.info.name
        registry.register(stepper, origin="population", replace=True)
        try:
            problems = PROBLEMS[m.family] if m.correct else PROBLEMS[m.family][:mutant_problems]
            facts = method_facts(stepper)
            black_box = replace(facts, source="claims", order=stepper.info.claimed_order,
                                linear_order=stepper.info.claimed_order
                                if facts.linear_order == facts.order else facts.linear_order)
            contradictions = claim_contradictions(stepper)
            outcomes, blind, notes = [], [], []
            for p in problems:
                summary = exp.summarize(exp.run_cell(Cell("convergence", name, p), cfg), cfg)
                rec = summary.iloc[0].to_dict()
                pf = problem_facts(get_problem(p))
                o, why = judge_convergence(rec, convergence_expectation(facts, pf))
                ob, why_b = judge_convergence(rec, convergence_expectation(black_box, pf))
                outcomes.append(o)
                blind.append(ob)
                notes.append(f"{p}: {rec['verdict']} {rec['measured_order']:.3g} ({o}; black box {ob})")
            gate_fails = bool(contradictions) or "fail" in outcomes or "pass" not in outcomes
            blind_fails = "fail" in blind or "pass" not in blind
            rows.append({
                "family": m.family, "kind": m.kind, "stepper": name,
                "claimed_order": stepper.info.claimed_order, "coefficient_order": facts.order,
                "gate_passed": not gate_fails, "measurement_passed": not blind_fails,
                "detail": "; ".join(notes + contradictions),
            })
        finally:
            registry.unregister(name)
    table = pd.DataFrame(rows)
    return table, rates(table)


def rates(table: pd.DataFrame) -> pd.DataFrame:
    """False-alarm and miss rates per family and overall, for the gate and the measurement alone.

    Parameters
    ----------
    table : the per-method table of `error_rates`.

    Returns
    -------
    DataFrame: one row per family and 'all', with counts and rates of false alarms and misses.
    """
    out = []
    for family, g in [*table.groupby("family", sort=False), ("all", table)]:
        good, bad = g[g.kind == "correct"], g[g.kind != "correct"]
        row = {"family": family, "correct_methods": len(good), "mutants": len(bad)}
        for col, label in (("gate_passed", "gate"), ("measurement_passed", "measurement")):
            row[f"{label}_false_alarms"] = int((~good[col]).sum())
            row[f"{label}_misses"] = int(bad[col].sum())
            alarms, misses = row[f"{label}_false_alarms"], row[f"{label}_misses"]
            row[f"{label}_false_alarm_rate"] = alarms / len(good) if len(good) else math.nan
            row[f"{label}_miss_rate"] = misses / len(bad) if len(bad) else math.nan
        out.append(row)
    return pd.DataFrame(out)
