"""Claims from the course material, each checked against this run's measurements.

The four course texts (`../shared/course-material/`, see its README) make statements about the
methods the harness measures. Each `ClaimSpec` paraphrases one statement (the texts are cited,
not quoted), names its source file and a phrase that locates it (the line number is looked up
when the file is present), the experiment whose summary it reads, and a `judge` function that
turns that summary into a `ClaimResult` (a run without that experiment's results leaves the claim
`not measured`): the measurement in words and numbers, and `agree`, `disagree` or `not measured`.
A claim is judged on what its own words name: the methods (matched by their coefficients,
whatever a stepper is called) and the problems (a class derived from the definition, e.g. a
central field), leaving out the cells where the named method is exact or no measurement could
be made; those are listed with the reason they were left out.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from harness import registry
from harness import tolerances as tol
from harness.coefficients import ButcherTableau, SecondOrderMultistep, SplittingScheme
from harness.facts import central_field, method_facts, problem_facts
from harness.provenance import PROJECT_ROOT
from harness.rules import convergence_expectation

__all__ = ["ClaimSpec", "ClaimResult", "CLAIMS", "check_claims", "course_material_dir"]

AGREE, DISAGREE, NOT_MEASURED = "agree", "disagree", "not measured"

Tables = Mapping[str, pd.DataFrame]


@dataclass(frozen=True)
class ClaimSpec:
    key: str
    claim: str
    source: str
    anchor: str
    experiment: str
    judge: Callable[[pd.DataFrame], tuple[str, str, list[dict]]]


@dataclass
class ClaimResult:
    key: str
    claim: str
    source: str
    line: int | None
    status: str
    measurement: str
    values: list[dict] = field(default_factory=list)


def course_material_dir() -> Path:
    """Where the course texts live: `../shared/course-material/` beside the project.

    Returns
    -------
    Path: not checked for existence.
    """
    return PROJECT_ROOT.parent / "shared" / "course-material"


def _line_of(source: str, anchor: str) -> int | None:
    path = course_material_dir() / source
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for i, line in enumerate(fh, 1):
                if anchor in line:
                    return i
    except OSError:
        return None
    return None


def _num(x: object) -> float:
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan
    return v


def _ulps(x: float) -> str:
    return f"{x:g} ulp" + ("" if x == 1 else "s")


def _fmt(x: float, digits: int = 3) -> str:
    return "n/a" if not math.isfinite(x) else f"{x:.{digits}g}"


# The methods the course texts speak of, by their coefficients: a registered stepper is one of
# them when its coefficients are the same (same fingerprint), whatever its name.
EULER = ButcherTableau("forward Euler", A=[[0.0]], b=[1.0], c=[0.0])
RK4 = ButcherTableau("classical Runge-Kutta (Kutta 1901)",
                     A=[[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]],
                     b=[1 / 6, 1 / 3, 1 / 3, 1 / 6], c=[0, 0.5, 0.5, 1])
VELOCITY_VERLET = SplittingScheme("velocity Verlet / leapfrog (kick-drift-kick)",
                                  [("K", 0.5), ("D", 1.0), ("K", 0.5)])
POSITION_VERLET = SplittingScheme("position Verlet (drift-kick-drift)", [("D", 0.5), ("K", 1.0), ("D", 0.5)])
STORMER = SecondOrderMultistep("two-step Verlet form (Stormer)", alpha=[1, -2, 1], beta=[0, 1, 0])


def steppers_with(*records: object) -> list[str]:
    """The registered steppers whose coefficients are one of `records` (same kind, same
    values as run in float64, whether given exactly or not).

    Parameters
    ----------
    *records : coefficient objects (tableaus, multistep tables, splittings).

    Returns
    -------
    list of str: stepper names, in registry order.
    """
    def identity(c) -> tuple:
        return type(c), getattr(c, "float_fingerprint", c.fingerprint)()

    wanted = {identity(r) for r in records}
    out = []
    for name in registry.steppers.names():
        coeffs = getattr(registry.get_stepper(name), "coefficients", None)
        if coeffs is not None and hasattr(coeffs, "fingerprint") and identity(coeffs) in wanted:
            out.append(name)
    return out


# -- the judges -------------------------------------------------------------------------------------
def _verlet_local_h4(conv: pd.DataFrame) -> tuple[str, str, list[dict]]:
    if "local_exponent_q" not in conv:
        return NOT_MEASURED, "no local exponents in the convergence results", []
    s = conv[conv["stepper"].isin(steppers_with(STORMER))]
    q = s["local_exponent_q"].astype(float)
    values = [{"stepper": n, "problem": p, "local exponent (positions)": _fmt(v, 4)}
              for n, p, v in zip(s["stepper"], s["problem"], q, strict=True)]
    q = q[np.isfinite(q)]
    if q.empty:
        return NOT_MEASURED, "the two-step Verlet form's local error was not measured on any problem", values
    med = float(q.median())
    ok = abs(med - 4.0) <= tol.GATE_ORDER_TOL
    text = (f"one step of the two-step recurrence from exact history: position error ~ h^q with "
            f"q = {med:.3f} (median over {len(q)} problems, range {q.min():.3f} to {q.max():.3f}); "
            f"agreement means |q - 4| <= {tol.GATE_ORDER_TOL}")
    return (AGREE if ok else DISAGREE), text, values


def _velocity_verlet_two_orders(conv: pd.DataFrame) -> tuple[str, str, list[dict]]:
    orders: dict[str, float] = {}
    values = []
    for name, record in (("two-step", STORMER), ("velocity", VELOCITY_VERLET)):
        members = steppers_with(record)
        s = conv[conv["stepper"].isin(members) & (conv["verdict"] == "converged")]
        m = s["measured_order"].astype(float)
        m = m[np.isfinite(m)]
        if m.empty:
            continue
        orders[name] = float(m.median())
        loc = conv.loc[conv["stepper"].isin(members), "local_exponent_q"].astype(float) \
            if "local_exponent_q" in conv else pd.Series(dtype=float)
        loc = loc[np.isfinite(loc)]
        values.append({"stepper": ", ".join(sorted(set(s["stepper"]))),
                       "global order (median)": f"{orders[name]:.3f}",
                       "problems": str(len(m)),
                       "local exponent, positions (median)": _fmt(float(loc.median()), 4)
                       if not loc.empty else "n/a"})
    if len(orders) < 2:
        return NOT_MEASURED, ("needs converged cells of both the two-step Verlet form and velocity "
                              "Verlet"), values
    gap = orders["two-step"] - orders["velocity"]
    ok = abs(gap - 2.0) <= 2 * tol.GATE_ORDER_TOL
    text = (f"global orders: two-step Verlet form {orders['two-step']:.3f}, velocity Verlet "
            f"{orders['velocity']:.3f}; difference {gap:+.3f} (the claim needs about +2). "
            "The h^4 quoted for Verlet is its one-step position error, not its global error, "
            "which is h^2 like velocity Verlet's")
    return (AGREE if ok else DISAGREE), text, values


def _registered(kind: str, name: str):
    """The registered stepper or problem `name`, or None (a saved run's plugin not loaded now)."""
    try:
        return registry.get_stepper(name) if kind == "stepper" else registry.get_problem(name)
    except Exception:
        return None


def _exact_on(stepper_name: str, problem_name: str) -> bool | None:
    """True when the gate's rules expect the method to be exact on the problem (a polynomial
    solution its linear order reproduces, `harness.rules.convergence_expectation`); None when
    either is not registered."""
    stepper, problem = _registered("stepper", stepper_name), _registered("problem", problem_name)
    if stepper is None or problem is None:
        return None
    return convergence_expectation(method_facts(stepper), problem_facts(problem)).verdict == "exact"


def _rk4_drifts(en: pd.DataFrame) -> tuple[str, str, list[dict]]:
    """Judged on the cells of the RK4 tableau whose drift class was measured, leaving out the
    problems where RK4 is exact (a claim about drift cannot be refuted where the method makes no
    error) and the runs that could not show a class (`not-measurable`)."""
    s = en[en["stepper"].isin(steppers_with(RK4))]
    if s.empty:
        return NOT_MEASURED, "no stepper with the classical RK4 tableau was run in the energy experiment", []
    values, judged = [], []
    for r in s.to_dict("records"):
        exact = _exact_on(r["stepper"], r["problem"])
        cls = str(r.get("drift_class") or "")
        if exact:
            why = "no: RK4 is exact on this problem"
        elif exact is None:
            why = "no: the problem or stepper is not registered, its facts unknown"
        elif not cls or r.get("verdict") == "not-measurable":
            why = "no: not measurable on this run"
        else:
            why = "yes"
            judged.append((r["stepper"], r["problem"], cls))
        values.append({"stepper": r["stepper"], "problem": r["problem"], "drift class": cls or "—",
                       "drift exponent": _fmt(_num(r["drift_exponent"])),
                       "max relative energy error": _fmt(_num(r["max_rel_energy_error"])),
                       "judged": why})
    if not judged:
        return NOT_MEASURED, ("no run of the classical RK4 tableau measured a drift class on a "
                              "problem where it is not exact"), values
    classes = [c for _, _, c in judged]
    ok = all(c in ("linear", "unstable") for c in classes) and "linear" in classes
    by_problem = ", ".join(f"{n} on {p}: {c}" for n, p, c in judged)
    text = (f"energy error envelope of the classical RK4 tableau: {by_problem}; "
            "agreement means a secular drift (linear in t) on every problem measured, leaving out "
            f"{len(values) - len(judged)} run(s) where RK4 is exact or no class could be measured")
    return (AGREE if ok else DISAGREE), text, values


def _angular_momentum_exact(en: pd.DataFrame) -> tuple[str, str, list[dict]]:
    """Judged on the methods the claim names (the kick-drift-kick and drift-kick-drift splittings,
    whatever their names: the leapfrog runs the former's scheme) and only on central fields
    (`harness.facts.central_field`: every body's acceleration parallel to its position)."""
    if "angular_momentum_conserved" not in en:
        return NOT_MEASURED, "no angular momentum in the energy-drift results", []
    verlet = steppers_with(VELOCITY_VERLET, POSITION_VERLET)
    s = en[en["stepper"].isin(verlet) & en["max_rel_angular_momentum_error"].notna()]
    s = s[np.isfinite(s["max_rel_angular_momentum_error"].astype(float))]
    central = {p for p in set(s["problem"])
               if (problem := _registered("problem", p)) is not None and central_field(problem)}
    s = s[s["problem"].isin(central)]
    if s.empty:
        return NOT_MEASURED, ("no leapfrog/Verlet run on a central-field problem with angular "
                              "momentum (the Kepler problems) in this report"), []
    values = []
    for r in s.to_dict("records"):
        err = _num(r["max_rel_angular_momentum_error"])
        bound = _num(r["angular_momentum_rounding"])
        values.append({"stepper": r["stepper"], "problem": r["problem"], "steps": str(r["steps"]),
                       "max relative error of L": _fmt(err),
                       "in ulps": _fmt(err / tol.EPS, 3),
                       "rounding bound": _fmt(bound),
                       "conserved": "yes" if bool(r["angular_momentum_conserved"]) else "no"})
    ok = bool(s["angular_momentum_conserved"].astype(bool).all())
    worst = float(s["max_rel_angular_momentum_error"].astype(float).max())
    text = (f"largest relative change of the angular momentum over {len(s)} runs on central "
            f"fields ({', '.join(sorted(central))}): {worst:.3g} ({worst / tol.EPS:.3g} ulps); "
            f"'exactly' is read as 'to rounding': at most "
            f"{_ulps(tol.ANGULAR_MOMENTUM_ROUNDING_ULPS)} per step")
    return (AGREE if ok else DISAGREE), text, values


def _euler_interval(st: pd.DataFrame) -> tuple[str, str, list[dict]]:
    s = st[st["stepper"].isin(steppers_with(EULER))]
    if s.empty:
        return NOT_MEASURED, "no stepper with forward Euler's tableau was in this report's stability run", []
    r = s.iloc[0]
    real = _num(r["real_interval"])
    imag = _num(r["imag_interval"])
    values = [{"stepper": r["stepper"], "real interval (probe)": f"[-{real:.10g}, 0]",
               "real interval (formula)": f"[-{_num(r['analytic_real_interval']):.10g}, 0]",
               "imaginary interval": f"±{imag:.3g}"}]
    ok = math.isfinite(real) and abs(real - 2.0) <= tol.STABILITY_INTERVAL_AGREEMENT
    text = (f"real stability interval found by root finding on the black-box probe: "
            f"[-{real:.10g}, 0] (agreement within {tol.STABILITY_INTERVAL_AGREEMENT:g})")
    return (AGREE if ok else DISAGREE), text, values


def _verlet_rounding(ro: pd.DataFrame) -> tuple[str, str, list[dict]]:
    values = []
    ratios = []
    for problem, g in ro.groupby("problem", sort=False):
        two = g[g["stepper"].isin(steppers_with(STORMER))]["floor_error"].astype(float)
        one = g[g["stepper"].isin(steppers_with(VELOCITY_VERLET))]["floor_error"].astype(float)
        if two.empty or one.empty or not np.isfinite(two).all() or not np.isfinite(one).any():
            continue
        ratio = float(two.iloc[0]) / max(float(one[np.isfinite(one)].max()), tol.EPS * tol.EPS)
        ratios.append(ratio)
        values.append({"problem": problem, "steps": str(int(g["n_steps"].iloc[0])),
                       "floor, two-step Verlet form": _fmt(float(two.iloc[0])),
                       "floor, velocity Verlet / leapfrog (worst)": _fmt(float(one.max())),
                       "ratio": _fmt(ratio)})
    if not ratios:
        return NOT_MEASURED, ("needs the two-step Verlet form and velocity Verlet (or leapfrog) in "
                              "the roundoff experiment"), values
    ok = min(ratios) >= tol.ROUNDOFF_CLAIM_RATIO
    text = (f"lowest relative position error reached at a fixed step count as h shrinks: the "
            f"two-step form's floor is {min(ratios):.3g} to {max(ratios):.3g} times the one-step "
            f"forms' (agreement needs at least {tol.ROUNDOFF_CLAIM_RATIO:g} on every problem)")
    return (AGREE if ok else DISAGREE), text, values


CLAIMS: tuple[ClaimSpec, ...] = (
    ClaimSpec("verlet-local-h4",
              "The position-only Verlet step x(n+1) = 2x(n) - x(n-1) + h^2 a(n) makes a local "
              "error proportional to h^4.",
              "000_30bd195af4439699.txt", "scales like $h^4$", "convergence",
              _verlet_local_h4),
    ClaimSpec("velocity-verlet-two-orders",
              "Velocity Verlet, with an error term of order h^2, is two orders worse than the "
              "plain Verlet method.",
              "001_99dff2c5051246a9.txt", "two orders of magnitude worse", "convergence",
              _velocity_verlet_two_orders),
    ClaimSpec("rk4-drifts",
              "RK4 does not conserve the energy: over long times it drifts away.",
              "004_bfdbb1594143ed8b.txt", "do not conserve energy", "energy",
              _rk4_drifts),
    ClaimSpec("verlet-angular-momentum",
              "In a central (spherically symmetric) field, leapfrog and velocity or position "
              "Verlet keep the angular momentum exactly.",
              "004_bfdbb1594143ed8b.txt", "conserves it exactly", "energy",
              _angular_momentum_exact),
    ClaimSpec("euler-interval",
              "Forward Euler is stable on y' = lambda y (lambda real) exactly when -2 < h lambda < 0.",
              "004_bfdbb1594143ed8b.txt", "-2 < h\\lambda < 0", "stability",
              _euler_interval),
    ClaimSpec("verlet-rounding",
              "The original two-step Verlet form suffers more from rounding than leapfrog, because "
              "it adds h^2 times the acceleration, a very small number, to numbers the size of the "
              "positions.",
              "002_b3abae41bf42a307.txt", "square of the time step", "roundoff",
              _verlet_rounding),
)


def check_claims(tables: Tables) -> list[ClaimResult]:
    """Judge every claim against `tables` (experiment name -> summary DataFrame). A judge that
    fails on unexpected data gives `not measured` with the error, never an exception.

    Parameters
    ----------
    tables : mapping of str to DataFrame, the run's summaries by experiment.

    Returns
    -------
    list of ClaimResult: one per claim of CLAIMS, in order, with its source line.
    """
    out = []
    for spec in CLAIMS:
        summary = tables.get(spec.experiment)
        if not isinstance(summary, pd.DataFrame) or summary.empty:
            status, text, values = NOT_MEASURED, f"no {spec.experiment} results", []
        else:
            try:
                status, text, values = spec.judge(summary)
            except Exception as exc:  # a summary table without the expected columns
                status, text, values = NOT_MEASURED, f"could not judge: {type(exc).__name__}: {exc}", []
        out.append(ClaimResult(spec.key, spec.claim, spec.source, _line_of(spec.source, spec.anchor),
                               status, text, values))
    return out
