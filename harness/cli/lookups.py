"""The commands that look things up: `harness list` and `harness reference`, over the registry and
the ground truth only. `harness list steppers|problems` and `harness reference` run from here
without importing the experiments and the report (`harness.cli` dispatches); `harness list
experiments` runs through `harness.cli.commands`, which passes the registered experiments."""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from harness.cli.output import EXIT_OK, one_line, output_buffer
from harness.cli.tables import print_json, print_table
from harness.errors import InputError, ReferenceError_
from harness.ground_truth import reference
from harness.problem import check_time
from harness.problem.validation import exact_state
from harness.registry import get_problem, load_plugin, plugin_errors, problems, steppers

__all__ = ["LOOKUPS", "cmd_list", "cmd_reference", "load_plugins", "run_lookup"]


def load_plugins(paths: Sequence[str]) -> None:
    """Load every plugin file in `paths` into the registry.

    Parameters
    ----------
    paths : sequence of str
        Plugin .py files.
    """
    for path in paths:
        load_plugin(path)


def cmd_list(args, experiments: Mapping | None = None, experiment_errors: Sequence[str] = ()) -> int:
    """`harness list steppers|problems|experiments`: the registry as a table or JSON.

    Parameters
    ----------
    args : argparse.Namespace
        `kind` ("steppers", "problems" or "experiments") and `json` (records instead of a table).
    experiments : mapping of name to Experiment, for `kind` "experiments" (`harness.cli.commands`
        passes the registered ones: importing them imports the report's figures).
    experiment_errors : sequence of str, the experiments that failed to load (warnings).

    Returns
    -------
    int
        EXIT_OK; plugins that failed to load are listed, not fatal.
    """
    if args.kind == "steppers":
        # every stepper, those run only when named (`on_request`: a family's further published
        # members) included and marked; a compiled variant is its method's implementation, not a
        # stepper of its own, and is left out
        records = [dict(s.info.as_dict(), origin=steppers.origin(s.info.name),
                        on_request=bool(s.info.extra.get("on_request")))
                   for s in steppers.all(variants=True) if "numpy_implementation" not in s.info.extra]
        cols = ["name", "family", "claimed_order", "explicit", "symplectic", "symmetric",
                "evals_per_step", "form", "velocity_dependent", "adaptive", "on_request"]
    elif args.kind == "problems":
        # every problem, those run only when named (`on_request`: the test sets, experiment-
        # specific orbits) included and marked
        records = [dict(p.describe(), origin=problems.origin(p.name))
                   for p in problems.all(variants=True)]
        cols = ["name", "form", "dim", "t_span", "velocity_dependent", "conservative",
                "exact_solution", "invariants", "on_request"]
    else:
        records = [{"name": e.name, "description": e.description} for e in (experiments or {}).values()]
        cols = ["name", "description"]
    if args.json:
        print_json(records)
    else:
        print_table(pd.DataFrame(records), cols)

    for err in [*plugin_errors(), *(experiment_errors if args.kind == "experiments" else [])]:
        print(f"harness: warning: {one_line(err)}", file=sys.stderr)
    return EXIT_OK


def cmd_reference(args) -> int:
    """`harness reference PROBLEM --t T`: the certified reference state at the given times.

    Parameters
    ----------
    args : argparse.Namespace
        `problem`, the times `t` and `json`.

    Returns
    -------
    int
        EXIT_OK once the states are printed; a problem without a certifiable reference raises
        (`main` turns it into its one line and status).
    """
    problem = get_problem(args.problem)
    t = check_time(args.t, "--t")
    if t < problem.t0:
        raise InputError(f"`--t` must be >= the start time {problem.t0:g} of {problem.name!r}, got {t:g}")
    ref = reference(problem, np.array([t]))
    record = {
        "problem": problem.name,
        "t": t,
        "variables": [str(v) for v in problem.variables],
        "state": ref.y[-1][:, 0].tolist(),
        "reference_error": float(np.max(ref.error[-1])),
        "precision": ref.precision,
        "certified_by": ref.certified_by,
    }
    float64_form = ref.y[-1][:, 0]
    if problem.published is not None:
        float64_form = _published_record(problem, t, ref, record)
    if problem.exact is not None and float64_form is not None:
        # the closed form is evaluated from the float64 start, so it is compared with the
        # reference of the float64 form
        exact = exact_state(problem, t, problem.y0[:, None])[:, 0]
        record["exact_state"] = exact.tolist()
        record["exact_difference"] = float(np.max(np.abs(exact - float64_form)))
    if args.json:
        print_json([record])
    else:
        for k, v in record.items():
            print(f"{k:>18}: {v}", file=output_buffer())
    return EXIT_OK


def _published_record(problem, t: float, ref, record: dict):
    """Add to `record` how the reference of a test-set problem stands to its published form:
    the float64 rounding of its inputs, the difference the rounding makes to the solution at `t`
    (the float64 form's reference against the published form's), and, at the published end
    time, the published values, the difference from them and whether it is within their stated
    accuracy plus the reference's own error. Returns the float64 form's state at `t` (None when
    it cannot be had)."""
    pub = problem.published
    record["form"] = ref.form
    record["float64_rounding"] = pub.rounding()
    state = ref.y[-1][:, 0]
    float64_form = state
    if ref.form == "published":
        try:
            f64 = reference(problem, np.array([t]), problem.y0.reshape(-1, 1))
            float64_form = f64.y[-1][:, 0]
            record["float64_form_difference"] = float(np.max(np.abs(float64_form - state)))
        except ReferenceError_:
            float64_form = None
    if pub.values is not None and t == pub.t_end_float:
        values = np.array(pub.values_float)
        diff = float(np.max(np.abs(values - state)))
        allowed = pub.accuracy * float(np.max(np.abs(values)))
        record.update(published_state=values.tolist(), published_difference=diff,
                      published_accuracy=pub.accuracy, published_accuracy_note=pub.accuracy_note,
                      within_published_accuracy=bool(diff <= allowed + float(np.max(ref.error[-1]))))
    return float64_form


LOOKUPS = {"list": cmd_list, "reference": cmd_reference}


def run_lookup(args) -> int:
    """Load the plugins `args.plugin` names, then run the lookup `args.command` (list or
    reference).

    Parameters
    ----------
    args : argparse.Namespace, the parsed command line.

    Returns
    -------
    int: the command's exit status.
    """
    load_plugins(args.plugin)
    return LOOKUPS[args.command](args)
