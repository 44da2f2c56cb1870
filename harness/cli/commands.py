"""The commands of the `harness` command line, one function each (`harness run`, `gate`, `report`,
`population`; `list` and `reference` come from `harness.cli.lookups`), writing through
`harness.cli.output`."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Sequence

import pandas as pd

from harness.cli.lookups import cmd_list, cmd_reference, load_plugins
from harness.cli.output import (
    EXIT_FAILED,
    EXIT_NOT_VERIFIED,
    EXIT_OK,
    SHOWN_SKIPS,
    one_line,
    output_buffer,
)
from harness.cli.tables import explain_skips, print_json, print_table
from harness.errors import InputError, NoApplicableCellsError
from harness.experiments import EXPERIMENTS, get_experiment
from harness.experiments.base import EXPERIMENT_ERRORS
from harness.experiments.common import OVERRIDE_KEYS, check_overrides
from harness.gate import GATE_COLUMNS, NOT_VERIFIED, gate_table
from harness.populations import FAMILIES, HIGH_FAMILIES, error_rates, generate
from harness.registry import problems, steppers
from harness.report import build_report, rerender_report
from harness.runner import RunResult, run_experiment
from harness.store import save_run


def _names(kind: str, requested: Sequence[str]) -> list[str]:
    reg = steppers if kind == "stepper" else problems
    if not requested:
        return reg.names()
    for name in requested:
        reg.get(name)  # raises UnknownNameError with the closest names
    return list(dict.fromkeys(requested))



def cmd_population(args) -> int:
    """Generate a population (harness.populations), judge it, save the per-method table and the
    rates under results/<run-id>/ as `gate-population`, and exit 1 on any false alarm or miss.

    Parameters
    ----------
    args : argparse.Namespace
        `harness population`'s options: `size`, `seed`, `high_order`, `max_order`, `json`.

    Returns
    -------
    int
        EXIT_OK when the gate had no false alarm and no miss on the population, else EXIT_FAILED.
    """
    if not 1 <= args.size <= 1000:
        raise InputError(f"`--size` must lie in [1, 1000], got {args.size}")
    if not 4 <= args.max_order <= 12:
        raise InputError(f"`--max-order` must lie in [4, 12], got {args.max_order}")
    started = time.perf_counter()
    families = HIGH_FAMILIES if args.high_order else FAMILIES
    members = generate(args.size, seed=args.seed, families=families, max_order=args.max_order)
    table, rates = error_rates(members)
    empty = pd.DataFrame()
    result = RunResult(experiment="gate-population",
                       description="the gate's error rates on generated methods",
                       config={"size": args.size, "seed": args.seed, "high_order": args.high_order,
                               "max_order": args.max_order}, rows=table, summary=rates,
                       failures=empty, skips=empty, cells=empty, wall_s=time.perf_counter() - started,
                       cached_cells=0, computed_cells=len(table))
    path = save_run({"gate-population": result}, config={"command": "population", "size": args.size,
                                                          "seed": args.seed, "high_order": args.high_order,
                                                          "max_order": args.max_order})
    print(f"harness: results saved in {os.fspath(path)}", file=sys.stderr)
    overall = rates[rates.family == "all"].iloc[0]
    bad = int(overall.gate_false_alarms + overall.gate_misses)
    if args.json:
        print_json(rates.to_dict("records"))
    else:
        print_table(rates, list(rates.columns))
        print(f"population: {int(overall.correct_methods)} correct methods, {int(overall.mutants)} mutants; "
              f"gate false alarms {int(overall.gate_false_alarms)}, misses {int(overall.gate_misses)}; "
              f"measurement alone: false alarms {int(overall.measurement_false_alarms)}, "
              f"misses {int(overall.measurement_misses)}", file=output_buffer())
    return EXIT_FAILED if bad else EXIT_OK



def _shared_run_settings(args) -> dict[str, object]:
    """The run settings every running command takes from its options (quick, jobs, scheduler,
    fresh, plugins)."""
    return {"quick": args.quick, "jobs": args.jobs, "scheduler": args.scheduler, "fresh": args.fresh,
            "plugins": tuple(args.plugin)}


def _run(args, experiment: str):
    """Run one experiment's grid and save it under results/<run-id>/ (path on stderr)."""
    overrides = check_overrides(get_experiment(experiment),
                                {k: getattr(args, k, None) for k in OVERRIDE_KEYS})
    result = run_experiment(
        experiment,
        _names("stepper", args.stepper),
        _names("problem", args.problem),
        **_shared_run_settings(args),
        cell_timeout=args.cell_timeout,
        config=overrides or None,
    )
    path = save_run({experiment: result}, config={"command": args.command, "experiment": experiment,
                                                   "quick": args.quick, "plugins": list(args.plugin),
                                                   "overrides": overrides})
    print(f"harness: results saved in {os.fspath(path)}", file=sys.stderr)
    return result


def _failures_table(result) -> list[dict]:
    f = result.failures
    if isinstance(f, pd.DataFrame):
        return f.to_dict("records")
    return list(f or [])


def cmd_run(args) -> int:
    """`harness run EXPERIMENT`: run one experiment, print its summary; exit 1 on a failed cell
    or claim.

    Parameters
    ----------
    args : argparse.Namespace
        `experiment`, the selection (`stepper`, `problem`, `quick`) and the scheduling options
        (`jobs`, `scheduler`, `cell_timeout`, `fresh`), `json`.

    Returns
    -------
    int
        EXIT_FAILED on a failed cell or a claim found false, else EXIT_OK.
    """
    get_experiment(args.experiment)  # unknown name -> exit 2 with the closest names
    result = _run(args, args.experiment)
    records = result.summary.to_dict("records")
    failures = _failures_table(result)
    if args.json:
        print_json(records + [dict(f, verdict="failed", passed=False) for f in failures])
    else:
        print_table(result.summary, list(result.summary.columns))
        _print_footer(result, failures)
    # A claim an experiment checks (stability figures, bounded energy, reversibility, ...) that
    # does not hold fails the run like a failed cell does.
    failed_claims = 0
    if "passed" in result.summary.columns:
        failed_claims = int((result.summary["passed"] == False).sum())  # noqa: E712 (object column)
        if failed_claims and not args.json:
            print(f"{args.experiment}: {failed_claims} cell(s) whose claim does not hold",
                  file=output_buffer())
    return EXIT_FAILED if failures or failed_claims else EXIT_OK


def _print_footer(result, failures) -> None:
    out = output_buffer()
    print(f"\n{len(result.summary)} cells, {len(failures)} failed, "
          f"{getattr(result, 'cached_cells', 0)} from cache, {result.wall_s:.1f} s", file=out)
    for f in failures:
        print(f"FAILED {f.get('stepper')} x {f.get('problem')}: {one_line(str(f.get('message', '')))}",
              file=out)
    skips = result.skips.to_dict("records") if hasattr(result.skips, "to_dict") else []
    for r in skips[:SHOWN_SKIPS]:
        print(f"not applicable: {r.get('stepper')} x {r.get('problem')}: {one_line(str(r.get('reason')))}",
              file=out)
    if len(skips) > SHOWN_SKIPS:
        print(f"not applicable: {len(skips) - SHOWN_SKIPS} more pairs (every reason: "
              "`harness.results.load(table='skips')`)", file=out)


def cmd_gate(args) -> int:
    """`harness gate`: run convergence and judge every stepper's claims; exit 1 when one is
    contradicted (or a cell failed), else EXIT_NOT_VERIFIED when a stepper's claim was measured
    on no cell of the problems given, else 0.

    Parameters
    ----------
    args : argparse.Namespace
        The selection and scheduling options as for `cmd_run`, and `json` (the gate table's
        records, the prediction note included).

    Returns
    -------
    int
        EXIT_FAILED, EXIT_NOT_VERIFIED or EXIT_OK, as above.
    """
    result = _run(args, "convergence")
    table = gate_table(result.summary)
    failures = _failures_table(result)
    contradicted = bool((table["outcome"] == "fail").any()) or bool(failures)
    n_unverified = int((table["outcome"] == NOT_VERIFIED).sum())
    if args.json:
        print_json(table.to_dict("records") + [
            dict(f, verdict="failed", passed=False) for f in failures
        ])
    else:
        print_table(table, [c for c in GATE_COLUMNS if c != "prediction_note"])  # the note: --json
        _print_footer(result, failures)
        n_bad = int((table["outcome"] == "fail").sum()) + len(failures)
        n_unmeasured = int((table["outcome"] == "not-measurable").sum())
        word = "FAILED" if contradicted else "NOT VERIFIED" if n_unverified else "PASSED"
        print(f"gate: {word} ({len(table)} cells, {n_bad} failing, {n_unverified} stepper(s) not "
              f"verified on these problems, {n_unmeasured} not measurable: see their reasons)",
              file=output_buffer())
    if contradicted:
        return EXIT_FAILED
    return EXIT_NOT_VERIFIED if n_unverified else EXIT_OK


def cmd_report(args) -> int:
    """`harness report`: build the HTML report and print its path.

    Parameters
    ----------
    args : argparse.Namespace
        `output` (the report directory), `from_run` (re-render a saved run instead of running),
        `compare` (a previous run to list changed verdicts against) and the grid options.

    Returns
    -------
    int
        EXIT_OK once the report is written (its path printed).
    """
    if args.from_run is not None:
        path = rerender_report(args.from_run, output=args.output, compare=args.compare,
                               grid_options=_grid_options_given(args))
        print(os.fspath(path), file=output_buffer())
        return EXIT_OK
    path = build_report(
        steppers=_names("stepper", args.stepper),
        problems=_names("problem", args.problem),
        **_shared_run_settings(args),
        output=args.output,
        compare=args.compare,
    )
    print(os.fspath(path), file=output_buffer())
    return EXIT_OK


def _grid_options_given(args) -> list[str]:
    """The measuring options given on the command line (`report --from` takes none; `--plugin`
    is not one: it loads the steppers of a run measured with plugins, which `--from` never
    imports from the run's own meta.json)."""
    given = [f"--{k}" for k in ("stepper", "problem") if getattr(args, k)]
    given += [f"--{k}" for k in ("quick", "fresh") if getattr(args, k)]
    given += [f"--{k.replace('_', '-')}" for k in ("jobs", "scheduler", "cell_timeout")
              if getattr(args, k) is not None]
    return given


# the parser's subcommands and the functions that run them
def cmd_list_experiments(args) -> int:
    """`harness list` with the registered experiments at hand (`lookups.cmd_list`).

    Parameters
    ----------
    args : argparse.Namespace, as for `lookups.cmd_list`.

    Returns
    -------
    int: EXIT_OK.
    """
    return cmd_list(args, EXPERIMENTS, EXPERIMENT_ERRORS)


COMMANDS = {"list": cmd_list_experiments, "reference": cmd_reference, "run": cmd_run, "gate": cmd_gate,
            "report": cmd_report, "population": cmd_population}


def run_command(args) -> int:
    """Load the plugins `args.plugin` names, then run the command `args.command`.

    Parameters
    ----------
    args : argparse.Namespace, the parsed command line.

    Returns
    -------
    int: the command's exit status. A run or gate over zero applicable cells prints why each
    requested pair does not apply, then its `NoApplicableCellsError` propagates.
    """
    load_plugins(args.plugin)
    try:
        return COMMANDS[args.command](args)
    except NoApplicableCellsError as exc:
        explain_skips(exc.skips, getattr(args, "json", False))
        raise
