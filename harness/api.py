"""Claims checked from another project's test suite: "order 4 on these problems, symmetric,
energy bounded", measured by the harness's own experiments and judged by its own rules.

`check(stepper, problems, order=4, symmetric=True, energy="bounded")` runs

- the convergence experiment and judges each problem with `harness.gate.gate_table` (the CI gate's
  rule: converged, measured order within GATE_ORDER_TOL of the claim);
- the reversibility experiment (N steps forward and back, against the rounding bound);
- the energy experiment (the envelope's drift class: `bounded` claims are judged as the energy
  experiment judges a symplectic claim; `sqrt`/`linear` claims must match the measured class);
- with `symplectic=True/False`, the symplecticity experiment (the one-step map's Jacobian);

and returns a `ClaimReport` (one row per claim and problem, measured beside claimed). When a claim
is false it raises `ClaimError`, an `AssertionError` whose message is the measured table, so a
plain `pytest` run shows why; an order claim that no problem given could measure (the gate's
`not-verified`) fails the same way, its message saying "not verified" apart from "false".

The stepper may be a harness `Stepper`, a registered stepper's name, or a plain step function
wrapped by `FunctionStepper` (no harness import needed in the library under test):

    first-order form:  step(f, t, y, h) -> y_next      f(t, y) -> dy/dt
    Newtonian form:    step(a, t, q, v, h) -> (q_next, v_next)      a(t, q) -> q''

States are arrays shaped (dim, N) (ensemble axis last); plain NumPy arithmetic handles them.
A solver with state (its own init/step, a multistep history), an implicit solver that wants the
Jacobian and a linear solve, and a JAX solver stepping in compiled loops are wrapped by
`StateStepper` (`harness.stepper.contracts`).
While a check runs, the stepper (and any `Problem` objects given) are registered under their names
and the previous entries restored afterwards. Cells run in this process (`jobs=1`) without the
cell cache unless asked, so a changed function is always measured afresh.
Reference: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed. (2006), II.3
(symmetric methods), IX.3 (energy of symplectic methods); Hairer, Norsett & Wanner, *Solving ODEs
I*, II.1 (order).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import hashlib
import textwrap
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from harness.errors import InputError, NoApplicableCellsError
from harness.gate import NOT_VERIFIED, gate_table
from harness.problem import Dynamics, Problem
from harness.problem.checks import check_positive
from harness.registry import get_stepper
from harness.registry import problems as problem_registry
from harness.registry import steppers as stepper_registry
from harness.runner import run_experiment
from harness.sources import source_of
from harness.stepper import FORMS, Carry, Stepper
from harness.stepper.contracts import (
    AdaptiveStateStepper,
    Field,
    StateStepper,
    batched_solve,
    checked_float64,
    user_step_info,
)

__all__ = ["check", "ClaimReport", "ClaimError", "FunctionStepper", "StateStepper", "Field",
           "AdaptiveStateStepper",
           "CLAIM_COLUMNS", "ENERGY_CLAIMS"]

CLAIM_COLUMNS = ["claim", "problem", "claimed", "measured", "passed", "detail"]
# `measured` of a claim no cell could measure (the gate's `not-verified`): a failure, told apart.
NOT_VERIFIED_TEXT = "not verified"
ENERGY_CLAIMS = ("bounded", "sqrt", "linear")


class ClaimError(AssertionError):
    """A claim about a stepper is false; the message holds the measured table."""

    def __init__(self, report: ClaimReport):
        self.report = report
        super().__init__(str(report))


@dataclass
class ClaimReport:
    """The outcome of `check`: one row per (claim, problem), and the experiments' summaries."""

    stepper: str
    table: pd.DataFrame
    summaries: dict[str, pd.DataFrame]
    failures: pd.DataFrame

    @property
    def passed(self) -> bool:
        return bool(self.table["passed"].all()) and self.failures.empty

    def __str__(self) -> str:
        unverified = int((self.table["measured"] == NOT_VERIFIED_TEXT).sum())
        failed = int((~self.table["passed"]).sum()) + len(self.failures) - unverified
        total = len(self.table) + len(self.failures)
        verdicts = ([f"{failed} of {total} claims false"] if failed else []) + (
            [f"{unverified} claim(s) not verified: no problem given measured them"] if unverified else [])
        head = f"stepper {self.stepper!r}: " + (", ".join(verdicts) or "every claim holds")
        shown = self.table.assign(passed=self.table["passed"].map({True: "yes", False: "NO"}))
        lines = [head, shown.drop(columns="detail").to_string(index=False, max_colwidth=None)]
        for rec in self.table.to_dict("records"):  # details wrapped at spaces, never cut
            lines += textwrap.wrap(f"- {rec['claim']} on {rec['problem']}: {rec['detail']}", width=100,
                                   subsequent_indent="    ", break_long_words=False,
                                   break_on_hyphens=False)
        for rec in self.failures.to_dict("records"):
            lines.append(f"failed cell {rec.get('cell', '')}: {rec.get('kind', '')}: "
                         f"{rec.get('message', '')}")
        return "\n".join(lines)


# -- a plain function as a stepper ------------------------------------------------------------------
class FunctionStepper(Stepper):
    """A user's step function, run under the harness's stepper contract.

    `form='first-order'`: `step(f, t, y, h)` returns the next state; `form='newtonian'`:
    `step(a, t, q, v, h)` returns `(q, v)` and needs a problem written as q'' = a(q, t). The
    claims (order, symmetric, symplectic) are stated here, never inferred from the name.
    `evals_per_step` sizes the convergence sweep's budget (work budget / evaluations per step).
    `implicit=True`: the step is called as `step(f, t, y, h, jac=jac, solve=solve)`, `jac(t, y)`
    the problem's Jacobian (dim, dim, N), `solve(A, b)` the solve of A x = b per member (Jacobian
    calls are counted). A solver object with its own init/step is refused: use `StateStepper`. A float32
    state is refused (`checked_float64`). The fingerprint includes the function's source, so an
    edited function is a new method.
    """

    def __init__(
        self,
        step: Callable[..., Any],
        *,
        name: str | None = None,
        order: int | None = None,
        symmetric: bool = False,
        symplectic: bool = False,
        form: str = "first-order",
        evals_per_step: float = 1.0,
        implicit: bool = False,
        reference: str = "",
        description: str = "",
    ):
        if callable(getattr(step, "init", None)) and callable(getattr(step, "step", None)):
            raise InputError(
                f"`step` is a {type(step).__name__} with its own init/step: a solver with state "
                "(an FSAL derivative, a second state, a multistep history) that a stateless step "
                "function would drop; wrap it with `StateStepper(init, step, ...)`"
            )
        if not callable(step):
            raise InputError(f"`step` must be a function, got {type(step).__name__}")
        if form not in FORMS:
            raise InputError(f"`form` must be one of {FORMS}, got {form!r}")
        evals = check_positive(evals_per_step, "`evals_per_step`")
        self.step_function = step
        claims = {"implicit": implicit, "symplectic": symplectic, "symmetric": symmetric, "form": form,
                  "velocity_dependent": False, "reference": reference, "description": description}
        self.info = user_step_info(step, name, order, evals, claims, "step function", "user function")

    def fingerprint(self) -> str:
        """`Stepper.fingerprint` plus a hash of the step function's source (or, without source, its
        byte code and constants).

        Returns
        -------
        str
        """
        try:
            source = source_of(self.step_function)
        except (OSError, TypeError):
            code = getattr(self.step_function, "__code__", None)
            source = repr(code.co_code + repr(code.co_consts).encode()) if code else repr(self.step_function)
        digest = hashlib.sha256(source.encode()).hexdigest()
        return super().fingerprint() + "\n" + digest

    def _start(self, dyn: Dynamics, t0: float, y0: np.ndarray, h: float) -> Carry:
        return Carry(t0, h, y0)

    def _step(self, dyn: Dynamics, c: Carry) -> None:
        if self.info.form == "newtonian":
            nq = dyn.nq
            q, v = self.step_function(lambda t, q: dyn.accel(t, q), c.t, c.y[:nq], c.y[nq:], c.h)
            when = f"at t = {c.t + c.h:.6g}"
            c.y = np.concatenate([checked_float64(q, self.info.name, when),
                                  checked_float64(v, self.info.name, when)])
        else:
            extra = {"jac": dyn.jac, "solve": batched_solve} if not self.info.explicit else {}
            c.y = checked_float64(self.step_function(dyn.f, c.t, c.y, c.h, **extra),
                                  self.info.name, f"at t = {c.t + c.h:.6g}")
        if c.y.shape != (dyn.dim, dyn.size):
            raise InputError(
                f"stepper {self.info.name!r}: the step function returned a state shaped "
                f"{c.y.shape}, expected {(dyn.dim, dyn.size)}"
            )

    def _observe(self, dyn: Dynamics, c: Carry) -> np.ndarray:
        return c.y.copy()


# -- registering what a check needs ---------------------------------------------------------------
@contextlib.contextmanager
def _registered(registry, obj) -> Iterator[str]:
    """Register `obj` under its name for the duration; restore any previous entry afterwards."""
    name = obj.info.name if isinstance(obj, Stepper) else obj.name
    previous = None
    if name in registry:
        previous = (registry.get(name), registry.origin(name))
    if previous is not None and previous[0] is obj:
        yield name
        return
    registry.register(obj, origin="harness.api.check", replace=True)
    try:
        yield name
    finally:
        registry.unregister(name)
        if previous is not None:
            registry.register(previous[0], origin=previous[1], replace=True)


def _resolve_stepper(stepper: Any, order, symmetric, energy, symplectic=None) -> Stepper:
    if isinstance(stepper, str):
        stepper = get_stepper(stepper)
    elif not isinstance(stepper, Stepper):
        if not callable(stepper) and not hasattr(stepper, "init"):  # init/step: FunctionStepper says
            raise InputError(
                f"`stepper` must be a Stepper, a registered name or a step function, got "
                f"{type(stepper).__name__}"
            )
        stepper = FunctionStepper(stepper)
    changes: dict[str, Any] = {}
    if order is not None and order != stepper.info.claimed_order:
        changes["claimed_order"] = order
    if symmetric is not None and bool(symmetric) != stepper.info.symmetric:
        changes["symmetric"] = bool(symmetric)
    if symplectic is not None and bool(symplectic) != stepper.info.symplectic:
        changes["symplectic"] = bool(symplectic)
    if energy == "bounded" and not stepper.info.symplectic:
        # the energy experiment judges a bounded-energy claim as it judges a symplectic one
        changes["symplectic"] = True
    if changes:
        stepper = copy.copy(stepper)
        stepper.info = dataclasses.replace(stepper.info, **changes)
    return stepper


def _check_claims(order, symmetric, energy, symplectic=None) -> None:
    if order is not None and (isinstance(order, bool) or not isinstance(order, int) or order < 1):
        raise InputError(f"`order` must be a positive whole number, got {order!r}")
    if symmetric is not None and not isinstance(symmetric, bool | np.bool_):
        raise InputError(f"`symmetric` must be True or False, got {symmetric!r}")
    if symplectic is not None and not isinstance(symplectic, bool | np.bool_):
        raise InputError(f"`symplectic` must be True or False, got {symplectic!r}")
    if energy is not None and energy not in ENERGY_CLAIMS:
        raise InputError(f"`energy` must be one of {ENERGY_CLAIMS}, got {energy!r}")
    if order is None and symmetric is None and energy is None and symplectic is None:
        raise InputError("state at least one claim: `order`, `symmetric`, `energy` or `symplectic`")


# -- judging ----------------------------------------------------------------------------------------
def _order_rows(summary: pd.DataFrame) -> list[dict]:
    rows = []
    for rec in gate_table(summary).to_dict("records"):
        measured = rec.get("measured_order")
        shown = "nan" if measured is None or pd.isna(measured) else f"{float(measured):.3f}"
        lo, hi = rec.get("order_ci_low"), rec.get("order_ci_high")
        ci = "" if lo is None or pd.isna(lo) else f" [{float(lo):.2f}, {float(hi):.2f}]"
        unverified = rec.get("outcome") == NOT_VERIFIED
        rows.append({
            "claim": "order", "problem": rec["problem"], "claimed": str(rec["claimed_order"]),
            "measured": NOT_VERIFIED_TEXT if unverified else f"{shown}{ci} ({rec['verdict']})",
            "passed": bool(rec["passed"]),
            "detail": rec.get("reason") or f"{rec.get('fit_points')} points in the fit",
        })
    return rows


def _symmetry_rows(summary: pd.DataFrame, claimed: bool) -> list[dict]:
    rows = []
    for problem, g in summary.groupby("problem", sort=False):
        worst = g.sort_values(["passed", "steps"], ascending=[True, False]).iloc[0]
        parts = [f"N={int(r.steps)}: {r.return_error_ulps:.3g} ulps (bound {r.rounding_bound_ulps:.3g})"
                 for r in g.sort_values("steps").itertuples()]
        rows.append({
            "claim": "symmetric", "problem": problem, "claimed": "yes" if claimed else "no",
            "measured": "reversible" if (g.return_error_ulps <= g.rounding_bound_ulps).all()
            else "irreversible",
            "passed": bool(g["passed"].all()),
            "detail": str(worst["message"]) if not bool(worst["passed"]) else "; ".join(parts),
        })
    return rows


def _energy_rows(summary: pd.DataFrame, claimed: str) -> list[dict]:
    rows = []
    for rec in summary.to_dict("records"):
        if claimed == "bounded":
            ok = rec["verdict"] == "as-claimed" and bool(rec["passed"])
        else:
            ok = rec["drift_class"] == claimed
        detail = (f"max relative energy error {rec['max_rel_energy_error']:.3g} over {rec['steps']} "
                  f"steps, growth exponent {rec['drift_exponent']:.2f}")
        if not ok and rec.get("message"):
            detail = str(rec["message"])
        rows.append({"claim": "energy", "problem": rec["problem"], "claimed": claimed,
                     "measured": rec["drift_class"], "passed": bool(ok), "detail": detail})
    return rows


def _symplectic_rows(summary: pd.DataFrame, claimed: bool) -> list[dict]:
    rows = []
    for rec in summary.to_dict("records"):
        detail = (f"deviation {rec['deviation']:.3g} (threshold {rec['threshold']:.3g}) over "
                  f"{rec['states']} states")
        rows.append({"claim": "symplectic", "problem": rec["problem"],
                     "claimed": "yes" if claimed else "no", "measured": rec["verdict"],
                     "passed": bool(rec["passed"]), "detail": str(rec.get("message") or detail)})
    return rows


def _missing_rows(claim: str, claimed: str, problems: Sequence[str], summary: pd.DataFrame,
                  skips: pd.DataFrame) -> list[dict]:
    """A claim on a problem the experiment did not measure is a failed row saying why."""
    seen = set(summary["problem"]) if len(summary) else set()
    rows = []
    for p in problems:
        if p in seen:
            continue
        why = skips[skips.problem == p].reason.tolist() if len(skips) else []
        rows.append({"claim": claim, "problem": p, "claimed": claimed, "measured": "not measured",
                     "passed": False, "detail": why[0] if why else "no result (see the failed cells)"})
    return rows


def check(
    stepper: Stepper | str | Callable[..., Any],
    problems: Sequence[str | Problem],
    *,
    order: int | None = None,
    symmetric: bool | None = None,
    energy: str | None = None,
    symplectic: bool | None = None,
    quick: bool = True,
    configs: Mapping[str, Mapping[str, Any]] | None = None,
    jobs: int = 1,
    cache: bool = False,
    cell_timeout: float | None = None,
    raise_on_failure: bool = True,
) -> ClaimReport:
    """Measure `stepper` on `problems` and judge the stated claims (see the module docstring).

    Parameters
    ----------
    stepper : Stepper, str or callable
        A stepper, a registered name, or a step function (wrapped as a `FunctionStepper`).
    problems : sequence of str or Problem, registered names or `Problem` objects (a non-empty sequence).
    order : int, optional, the convergence order claimed on every problem.
    symmetric : bool, optional, true (returns to its start within rounding) or False.
    energy : str, optional, 'bounded', 'sqrt' or 'linear'.
    symplectic : bool, optional
        True or False, judged by the symplecticity experiment (the one-step map's Jacobian).
    quick : bool, optional, start from the experiments' quick settings (default True).
    configs : mapping, optional
        Experiment name ('convergence', 'reversibility', 'energy', 'symplecticity') -> setting
        overrides.
    jobs : int, optional, worker processes (default 1: in this process).
    cache : bool, optional, read and write the cell cache (default False).
    cell_timeout : float, optional, seconds per cell.
    raise_on_failure : bool, optional, raise `ClaimError` when a claim is false (default True).

    Returns
    -------
    ClaimReport
        One row per (claim, problem) with the measured value and verdict.

    Raises `ClaimError` (an AssertionError with the measured table) when a claim is false and
    `raise_on_failure`; `InputError` for bad input.
    """
    _check_claims(order, symmetric, energy, symplectic)
    if isinstance(problems, str | Problem) or not isinstance(problems, Sequence) or not problems:
        raise InputError("`problems` must be a non-empty list of problem names or Problem objects")
    for p in problems:
        if not isinstance(p, str | Problem):
            raise InputError(f"`problems` must hold problem names or Problem objects, got {type(p).__name__}")
    configs = dict(configs or {})
    unknown = set(configs) - {"convergence", "reversibility", "energy", "symplecticity"}
    if unknown:
        raise InputError(
            f"`configs` may set convergence, reversibility, energy and symplecticity only, got "
            f"{sorted(unknown)}"
        )
    resolved = _resolve_stepper(stepper, order, symmetric, energy, symplectic)
    options = {"quick": quick, "jobs": jobs, "cache": cache, "cell_timeout": cell_timeout,
               "progress": False}
    with contextlib.ExitStack() as stack:
        name = stack.enter_context(_registered(stepper_registry, resolved))
        names = [p if isinstance(p, str) else stack.enter_context(_registered(problem_registry, p))
                 for p in problems]
        for p in names:
            problem_registry.get(p)  # an unknown name fails here, with the closest names
        rows: list[dict] = []
        summaries: dict[str, pd.DataFrame] = {}
        failures = []
        plan = []
        if order is not None:
            plan.append(("convergence", "order", str(order)))
        if symmetric is not None:
            plan.append(("reversibility", "symmetric", "yes" if symmetric else "no"))
        if energy is not None:
            plan.append(("energy", "energy", energy))
        if symplectic is not None:
            plan.append(("symplecticity", "symplectic", "yes" if symplectic else "no"))
        for experiment, claim, claimed in plan:
            config = dict(configs.get(experiment, {}))  # experiments apply by facts, to `names`
            try:
                result = run_experiment(experiment, [name], names, config=config, **options)
            except NoApplicableCellsError as exc:  # nothing measured: the claim fails, saying why
                skips = pd.DataFrame(exc.skips, columns=["experiment", "stepper", "problem", "reason"])
                summaries[experiment] = pd.DataFrame()
                rows += _missing_rows(claim, claimed, names, pd.DataFrame(), skips)
                continue
            summary = result.summary
            summaries[experiment] = summary
            failures.append(result.failures)
            if len(summary):
                if claim == "order":
                    rows += _order_rows(summary)
                elif claim == "symmetric":
                    rows += _symmetry_rows(summary, bool(symmetric))
                elif claim == "symplectic":
                    rows += _symplectic_rows(summary, bool(symplectic))
                else:
                    rows += _energy_rows(summary, energy)
            rows += _missing_rows(claim, claimed, names, summary, result.skips)
    table = pd.DataFrame(rows, columns=CLAIM_COLUMNS)
    fail_df = pd.concat([f for f in failures if len(f)], ignore_index=True) if any(
        len(f) for f in failures) else pd.DataFrame()
    report = ClaimReport(stepper=name, table=table, summaries=summaries, failures=fail_df)
    if raise_on_failure and not report.passed:
        raise ClaimError(report)
    return report
