"""Linear stability (the lambda h test), measured from the outside and checked against theory.

First-order steppers run Dahlquist's test equation y' = lambda y (registry problem `dahlquist`,
state (Re y, Im y), parameters lambda_re, lambda_im) with h = 1, so z = lambda h = lambda:

1. Black-box probe. The recurrence y_k = sum_j C_j y_j (2x2 real blocks C_j, k = the
   stepper's `history_length`, 1 for one-step methods) is read off by stepping unit vectors of
   the history through the public `Stepper.step_from_history`: every grid point and every unit
   vector is one ensemble member, with its own lambda, so the whole complex grid is one call.
   The amplification is the spectral radius of the block companion matrix (|R(z)| for a
   one-step method, whose C_0 is R(z) written as a real 2x2 block).
2. Analytic, where the coefficients allow (`harness.theory`): R(z) = 1 + z b^T (I - zA)^{-1} e
   for Runge-Kutta tableaux, c_j = -(alpha_j - z beta_j) / (alpha_k - z beta_k) and the root
   condition for linear multistep methods. Probe and formula must agree entry by entry to
   STABILITY_AGREEMENT_TOL (relative to max(1, |analytic|)) on the whole grid; comparing the
   recurrence coefficients rather than root moduli keeps the test sharp where roots are nearly
   double (a root there moves by sqrt(eps)).
3. Real and imaginary stability intervals by root finding on the probe itself
   (`harness.theory.stability_boundary`: a scan for the first crossing of 1, then Brent's
   method), compared with the same figures from the formula.

Newtonian steppers run x'' = -omega^2 x (registry problem `harmonic`, omega = 1, so h = h
omega). The one-step propagator on (x, v) comes from stepping the two unit states; a stepper
with a longer history (`history_length` > 1) is probed by unit history vectors; a two-step
position recurrence (a `SecondOrderMultistep` table run by a stepper without a history hook,
e.g. Stormer's rule with a Taylor start) is identified from the observed positions x_0..x_2 of
the two unit starts and confirmed on x_3, and its companion matrix acts on (x_(n-1), x_n).
The probe's `hw_limit` is the largest h omega with spectral radius <= 1 (+
STABILITY_AMPLIFICATION_TOL) on (0, h omega], by a scan and root finding (a band narrower than
the scan step is not seen); the formula side decides every unstable band exactly
(`harness.theory.newtonian`: roots of tr M = +-2 for splittings, of the characteristic
polynomial's unit-circle conditions for multistep methods), and where probe and formula agree
the figure reported is the exact one, with every band (`hw_bands`). Agreement is judged to
STABILITY_AGREEMENT_TOL times the coefficients' size (`coefficient_size`,
`newtonian_rounding_scale`): a method whose weights sum to thousands in magnitude rounds
thousands of times more.

A claim in `info.extra['stability']` ({'real_interval': ..., 'imag_interval': ...} or
{'hw_limit': ...}; float('inf') for unbounded) is compared with the probe's figure.
Verdicts: `agrees`, `disagree` (probe and formula differ: the implementation is not the method
its coefficients describe), `claim-false` (the declared figure is wrong), `measured` (nothing
to compare with). Adaptive steppers are skipped (their step is not a fixed linear map).

References: Hairer & Wanner, *Solving ODEs II*, IV.2 (stability function, A-stability) and V.1
(root condition); Hairer, Lubich & Wanner, *Geometric Numerical Integration*, I.5 (linear
stability of Verlet); the course's ODE notes (course-material file 004, the lambda h test).

This module runs the experiment and judges it; `probes` (the black-box probes) and `analytic`
(the formula side) serve it.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from harness import theory
from harness import tolerances as tol
from harness.coefficients import LinearMultistep
from harness.errors import InputError
from harness.experiments.base import Cell, Experiment, Skip, register_experiment
from harness.experiments.stability.analytic import (
    analytic_blocks,
    coefficient_size,
    first_order_analytic_amp,
    newtonian_analytic_amp,
    newtonian_pair,
    newtonian_rounding_scale,
    relative_diff,
)
from harness.experiments.stability.probes import (
    STEP_FAILURES,
    FirstOrderProbe,
    NewtonianProbe,
    block_companion,
)
from harness.experiments.stability.section import SECTION
from harness.registry import get_problem, get_stepper
from harness.registry import problems as problem_registry
from harness.stepper import AdaptiveStepper, Stepper

__all__ = [
    "StabilityExperiment",
    "FirstOrderProbe",
    "NewtonianProbe",
    "GRID_COLUMNS",
    "SUMMARY_COLUMNS",
    "FIRST_ORDER_PROBLEM",
    "NEWTONIAN_PROBLEM",
    "SECTION",
]

FIRST_ORDER_PROBLEM = "dahlquist"
NEWTONIAN_PROBLEM = "harmonic"

GRID_COLUMNS = ["stepper", "problem", "kind", "z_re", "z_im", "hw", "abs_r_probe", "abs_r_analytic"]
SUMMARY_COLUMNS = [
    "stepper", "problem", "form", "probe", "real_interval", "imag_interval", "hw_limit",
    "hw_bands", "analytic_real_interval", "analytic_imag_interval", "analytic_hw_limit", "analytic_agrees",
    "max_probe_analytic_diff", "claimed", "verdict", "passed", "unbounded", "search_limit",
    "message", "wall_s",
]

_CLAIM_KEYS = {"first-order": ("real_interval", "imag_interval"), "newtonian": ("hw_limit",)}


def _intervals_agree(a: float, b: float) -> bool:
    if math.isinf(a) or math.isinf(b):
        return math.isinf(a) and math.isinf(b)
    return abs(a - b) <= tol.STABILITY_INTERVAL_AGREEMENT


def _claim_check(claim: Any, measured: Mapping[str, float], form: str) -> tuple[bool | None, str]:
    """(claim holds?, message). None when there is no claim."""
    if claim is None:
        return None, ""
    if not isinstance(claim, Mapping):
        return False, f"info.extra['stability'] must be a mapping, got {type(claim).__name__}"
    problems = []
    checked = 0
    for key, value in claim.items():
        if key not in _CLAIM_KEYS[form]:
            problems.append(f"claim {key!r} is not a {form} figure (known: {_CLAIM_KEYS[form]})")
            continue
        try:
            c = float(value)
        except (TypeError, ValueError):
            problems.append(f"claimed {key} {value!r} is not a number")
            continue
        m = measured[key]
        checked += 1
        if math.isinf(c) or math.isinf(m):
            ok = math.isinf(c) and math.isinf(m)
        else:
            ok = abs(c - m) <= tol.STABILITY_CLAIM_RTOL * max(abs(m), 1e-3)
        if not ok:
            problems.append(f"claimed {key} {c:.10g}, measured {m:.10g}")
    return (not problems and checked > 0), "; ".join(problems)


# =============================================================================================
# The experiment
# =============================================================================================
def _check_config(config: Mapping[str, Any]) -> dict:
    out = dict(config)
    for key in ("grid", "hw_grid"):
        v = out[key]
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 3 <= v <= 1001:
            raise InputError(f"`{key}` must be a whole number in [3, 1001], got {v!r}")
    for key in ("im_max", "search_limit", "hw_search_limit", "hw_grid_max", "scan_step",
                "hw_scan_step"):
        v = out[key]
        if not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
            raise InputError(f"`{key}` must be a positive finite number, got {v!r}")
    lo, hi = out["re_min"], out["re_max"]
    if not all(isinstance(v, int | float) and math.isfinite(v) for v in (lo, hi)) or lo >= hi:
        raise InputError(f"`re_min` must be below `re_max` (both finite), got {lo!r} and {hi!r}")
    for key, lim in (("scan_step", "search_limit"), ("hw_scan_step", "hw_search_limit")):
        if out[key] > min(1.0, out[lim]):
            raise InputError(f"`{key}` must be at most min(1, `{lim}`), got {out[key]!r}")
    return out


class StabilityExperiment(Experiment):
    """The lambda h test for every fixed-step stepper (see the module docstring)."""
    description = (
        "Linear stability: |R(z)| over the complex lambda h plane, real/imaginary intervals and "
        "h omega limits by root finding, probe against the coefficients' formula."
    )
    default_config: Mapping[str, Any] = {
        "re_min": -5.0, "re_max": 1.0, "im_max": 4.0, "grid": 121,
        "search_limit": tol.STABILITY_SEARCH_LIMIT,
        "scan_step": tol.STABILITY_SCAN_STEP,
        "hw_grid_max": 4.0, "hw_grid": 201, "hw_search_limit": tol.STABILITY_HW_SEARCH_LIMIT,
        "hw_scan_step": tol.STABILITY_SCAN_STEP,
    }
    # the quick run scans h omega (one call per point) more coarsely: gaps narrower than the
    # scan step go unseen, the limit itself is still root-found to STABILITY_XTOL
    quick_config: Mapping[str, Any] = {"grid": 61, "hw_grid": 81, "hw_scan_step": 0.05}

    def cells(
        self, steppers: Sequence[str], problems: Sequence[str], config: Mapping[str, Any]
    ) -> tuple[list[Cell], list[Skip]]:
        """One cell per stepper; `problems` is ignored (the test equations are fixed).

        Parameters
        ----------
        steppers : sequence of str, the methods.
        problems : sequence of str, not used.
        config : mapping, the settings.

        Returns
        -------
        (list of Cell, list of Skip)
        """
        cells, skips = [], []
        for s in steppers:
            stepper = get_stepper(s)
            p = NEWTONIAN_PROBLEM if stepper.info.form == "newtonian" else FIRST_ORDER_PROBLEM
            if isinstance(stepper, AdaptiveStepper) or stepper.info.adaptive:
                skips.append(Skip(self.name, s, p, "adaptive stepper: its step is not a fixed "
                                  "linear map of lambda h, so it has no stability function"))
                continue
            if p not in problem_registry:
                skips.append(Skip(self.name, s, p, f"test problem {p!r} is not registered"))
                continue
            incompatible = stepper.incompatibility(problem_registry.get(p))
            if incompatible:  # e.g. a map that needs an N-body structure: no linear test equation
                skips.append(Skip(self.name, s, p, f"cannot run the test equation {p!r}: {incompatible}"))
                continue
            coeffs = stepper.coefficients
            k = int(getattr(stepper, "history_length", 1))
            steps = getattr(coeffs, "steps", 1)
            if isinstance(coeffs, LinearMultistep) and steps > k:
                skips.append(Skip(self.name, s, p, f"{steps}-step method without a history hook "
                                  f"(history_length = {k}): its recurrence cannot be probed"))
                continue
            cells.append(Cell(self.name, s, p))
        return cells, skips

    def run_cell(self, cell: Cell, config: Mapping[str, Any]) -> pd.DataFrame:
        """Probe one stepper (first-order or Newtonian, by its form) and compare with its formula.

        Parameters
        ----------
        cell : Cell, one stepper on the test equation of its form.
        config : mapping, checked here (over the defaults).

        Returns
        -------
        DataFrame: the probed grid's rows and one row of kind 'summary'.
        """
        config = _check_config({**self.default_config, **dict(config)})
        stepper = get_stepper(cell.stepper)
        problem = get_problem(cell.problem)
        started = time.perf_counter()
        if stepper.info.form == "newtonian":
            grid, summary = _run_newtonian(stepper, problem, config)
        else:
            grid, summary = _run_first_order(stepper, problem, config)
        summary["wall_s"] = time.perf_counter() - started
        summary.update(stepper=stepper.info.name, problem=problem.name, kind="summary")
        grid["stepper"] = stepper.info.name
        grid["problem"] = problem.name
        return pd.concat([grid, pd.DataFrame([summary])], ignore_index=True)

    def summarize(self, rows: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
        """One summary record per cell, with its verdict.

        Parameters
        ----------
        rows : DataFrame, all cells' rows (only kind 'summary' is kept).
        config : mapping, not used.

        Returns
        -------
        DataFrame: SUMMARY_COLUMNS.
        """
        if rows.empty or "kind" not in rows:
            return pd.DataFrame(columns=SUMMARY_COLUMNS)
        out = rows[rows["kind"] == "summary"].reset_index(drop=True)
        for col in SUMMARY_COLUMNS:
            if col not in out:
                out[col] = None
        out = out[SUMMARY_COLUMNS].copy()
        out["passed"] = out["passed"].astype(bool)
        return out


def _verdict(agrees: bool | None, claim_ok: bool | None) -> str:
    if agrees is False:
        return "disagree"
    if claim_ok is False:
        return "claim-false"
    if agrees is None and claim_ok is None:
        return "measured"
    return "agrees"


def _unbounded(figures: Mapping[str, float]) -> str:
    return ",".join(k for k, v in figures.items() if v is not None and math.isinf(v))


def _agreement(diff: float, allowed: float, failed: int, differs: str, points: str,
               messages: list[str]) -> bool:
    """Whether probe and formula agree (within `allowed`: STABILITY_AGREEMENT_TOL scaled by
    the size of the coefficients; no failed step); what does not agree is appended to
    `messages` (`differs` and `points` word it)."""
    if diff > allowed:
        messages.append(f"{differs} by {diff:.3g} (allowed {allowed:.3g}: "
                        f"{tol.STABILITY_AGREEMENT_TOL:g} x the coefficients' size)")
    if failed:
        messages.append(f"the step failed at {failed} {points}")
    return bool(diff <= allowed) and failed == 0


def _run_first_order(stepper: Stepper, problem, config) -> tuple[pd.DataFrame, dict]:
    probe = FirstOrderProbe(stepper, problem)
    coeffs = stepper.coefficients
    n = int(config["grid"])
    re = np.linspace(config["re_min"], config["re_max"], n)
    im = np.linspace(-config["im_max"], config["im_max"], n)
    Z = (re[None, :] + 1j * im[:, None]).reshape(-1)
    C = probe.blocks(Z)
    if probe.k == 1:
        abs_probe = np.hypot(C[:, 0, 0, 0], C[:, 0, 1, 0])
    else:
        abs_probe = theory.spectral_radius(block_companion(C))
    abs_analytic = first_order_analytic_amp(coeffs, Z)
    grid = pd.DataFrame({
        "kind": "grid", "z_re": Z.real, "z_im": Z.imag, "abs_r_probe": abs_probe,
        "abs_r_analytic": abs_analytic if abs_analytic is not None else np.nan,
    })
    limit = float(config["search_limit"])
    step = float(config["scan_step"])
    real_iv = theory.real_stability_interval(probe.amplification, limit=limit, scan_step=step)
    imag_iv = theory.imag_stability_interval(probe.amplification, limit=limit, scan_step=step)
    messages = []
    agrees: bool | None = None
    diff = math.nan
    a_real = a_imag = math.nan
    expected = analytic_blocks(coeffs, Z, probe.k)
    if expected is not None:
        diff, failed, poles = relative_diff(C, expected)
        a = theory.analytic_stability(coeffs, limit=limit)
        a_real, a_imag = a["real_interval"], a["imag_interval"]
        # Probe and formula are judged on the amplification values themselves: where they agree
        # to rounding they are the same function, and its intervals are the formula's, decided
        # exactly (a flat crossing makes two root-findings of the same function differ by far
        # more than the functions do).
        agrees = _agreement(diff, tol.STABILITY_AGREEMENT_TOL * coefficient_size(coeffs), failed,
                            "probe differs from the coefficients' formula",
                            "grid point(s) where the formula is finite", messages)
        if poles:
            messages.append(f"{poles} grid point(s) at a pole of the formula left out")
        if agrees:
            real_iv, imag_iv = a_real, a_imag
        else:
            for key, m, f in (("real interval", real_iv, a_real), ("imaginary interval", imag_iv, a_imag)):
                if not _intervals_agree(m, f):
                    messages.append(f"{key}: probe {m:.10g}, formula {f:.10g}")
    elif coeffs is not None:
        messages.append(f"no stability formula for coefficients of type {type(coeffs).__name__} "
                        f"with history length {probe.k}")
    claim = stepper.info.extra.get("stability")
    claim_ok, claim_msg = _claim_check(
        claim, {"real_interval": real_iv, "imag_interval": imag_iv}, "first-order")
    if claim_msg:
        messages.append(claim_msg)
    verdict = _verdict(agrees, claim_ok)
    summary = {
        "form": "first-order", "probe": "one-step" if probe.k == 1 else f"history-{probe.k}",
        "real_interval": real_iv, "imag_interval": imag_iv, "hw_limit": math.nan, "hw_bands": "",
        "analytic_real_interval": a_real, "analytic_imag_interval": a_imag,
        "analytic_hw_limit": math.nan, "analytic_agrees": agrees,
        "max_probe_analytic_diff": diff, "claimed": json.dumps(claim) if claim is not None else "",
        "verdict": verdict, "passed": verdict in ("agrees", "measured"),
        "unbounded": _unbounded({"real_interval": real_iv, "imag_interval": imag_iv}),
        "search_limit": limit, "message": "; ".join(messages),
    }
    return grid, summary


def _run_newtonian(stepper: Stepper, problem, config) -> tuple[pd.DataFrame, dict]:
    probe = NewtonianProbe(stepper, problem)
    coeffs = stepper.coefficients
    hw_max, n = float(config["hw_grid_max"]), int(config["hw_grid"])
    hws = np.linspace(hw_max / n, hw_max, n)
    mats, pairs = [], []
    for x in hws:
        try:
            m = probe.matrix(float(x))
        except STEP_FAILURES:
            m = None
        mats.append(m)
        pairs.append(newtonian_pair(coeffs, probe, float(x), m) if m is not None else None)
    abs_probe = np.array([float(theory.spectral_radius(m)) if m is not None else np.nan for m in mats])
    abs_analytic = newtonian_analytic_amp(coeffs, hws)
    grid = pd.DataFrame({
        "kind": "grid-hw", "hw": hws, "abs_r_probe": abs_probe,
        "abs_r_analytic": abs_analytic if abs_analytic is not None else np.nan,
    })
    limit = float(config["hw_search_limit"])
    hw_limit = theory.hw_stability_limit(probe.amplification, limit=limit,
                                         scan_step=float(config["hw_scan_step"]))
    messages = []
    agrees: bool | None = None
    diff = math.nan
    a_limit = math.nan
    bands = ""
    if any(pr is not None for pr in pairs):
        ok = [(x, pr) for x, pr in zip(hws, pairs, strict=True)
              if pr is not None and np.all(np.isfinite(pr[0]))]
        failed = len(pairs) - len(ok)
        # each h omega is judged against the rounding its own product of coefficients allows
        ratios = [(float(np.max(np.abs(m - e))) / max(1.0, float(np.max(np.abs(e)))),
                   newtonian_rounding_scale(coeffs, float(x), e)) for x, (m, e) in ok]
        diff, scale = max(ratios, key=lambda r: r[0] / r[1], default=(0.0, 1.0))
        a = theory.analytic_stability(coeffs, limit=limit)
        a_limit = a["hw_limit"]
        agrees = _agreement(diff, tol.STABILITY_AGREEMENT_TOL * scale, failed,
                            "probe propagator differs from the coefficients'",
                            "h omega value(s)", messages)
        if a.get("hw_bands") is not None:
            bands = a["hw_bands"].describe()
        if agrees:
            hw_limit = a_limit
        elif not _intervals_agree(hw_limit, a_limit):
            messages.append(f"h omega limit: probe {hw_limit:.10g}, formula {a_limit:.10g}")
    elif all(m is None for m in mats):
        messages.append("the step failed at every h omega of the grid")
    elif coeffs is not None:
        messages.append(f"no propagator formula for coefficients of type {type(coeffs).__name__} "
                        f"probed as {probe.mode}")
    if probe.mode == "position-recurrence" and probe.recurrence_mismatch > tol.STABILITY_AGREEMENT_TOL:
        agrees = False
        messages.append(f"observed positions do not follow a two-step recurrence "
                        f"(mismatch {probe.recurrence_mismatch:.3g})")
    claim = stepper.info.extra.get("stability")
    claim_ok, claim_msg = _claim_check(claim, {"hw_limit": hw_limit}, "newtonian")
    if claim_msg:
        messages.append(claim_msg)
    verdict = _verdict(agrees, claim_ok)
    summary = {
        "form": "newtonian", "probe": probe.mode, "real_interval": math.nan,
        "imag_interval": math.nan, "hw_limit": hw_limit, "hw_bands": bands,
        "analytic_real_interval": math.nan,
        "analytic_imag_interval": math.nan, "analytic_hw_limit": a_limit,
        "analytic_agrees": agrees, "max_probe_analytic_diff": diff,
        "claimed": json.dumps(claim) if claim is not None else "", "verdict": verdict,
        "passed": verdict in ("agrees", "measured"), "unbounded": _unbounded({"hw_limit": hw_limit}),
        "search_limit": limit, "message": "; ".join(messages),
    }
    return grid, summary


register_experiment(StabilityExperiment())
