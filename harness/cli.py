"""Command line: `harness` (also `python -m harness`).

    harness list steppers|problems [--json]
    harness run EXPERIMENT [--stepper NAME]... [--problem NAME]... [--plugin FILE]... [--json]
    harness reference PROBLEM --t T [--json]
    harness gate [--json]
    harness report [--quick] [--fresh] [--compare RUN]
    harness report --from RUN [--compare RUN]   (re-render a saved run, nothing measured)

Errors a user can fix exit 2 with one line on stderr naming the argument and the rule; the
gate exits 1 when a claim fails; a run or gate over zero applicable cells exits 2 and prints why
each requested pair does not apply (a table on stdout, or JSON records with `--json`).

One output layer serves every command. While a command runs, `sys.stdout` points at stderr (a
plugin's `print()` cannot corrupt `--json`); the command's output is collected and written to
stdout at the end, then flushed. Ordinary OS conditions become one line naming the path and the
problem, no traceback, with a sysexits-style status: the reader closed the pipe (141, as a
SIGPIPE death would give), a full disk or another I/O error (74), no permission (77), a file
where a directory belongs or the reverse (73).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import sys
from collections.abc import Sequence
from typing import Any

__all__ = ["main", "build_parser"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2
EXIT_CANTCREAT, EXIT_IOERR, EXIT_NOPERM, EXIT_PIPE = 73, 74, 77, 141
# A run's footer lists at most this many pairs that do not apply (all are in the saved run).
SHOWN_SKIPS = 10

# The command's stdout while it runs (see the module docstring); `print(..., file=_out())`.
_OUTPUT: list[io.StringIO] = []


def _out() -> io.StringIO:
    if not _OUTPUT:
        _OUTPUT.append(io.StringIO())
    return _OUTPUT[-1]


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        self.exit(EXIT_USAGE, f"harness: error: {message} (see `{self.prog} --help`)\n")


def _common(p: argparse.ArgumentParser, *, grid: bool = True) -> None:
    p.add_argument("--plugin", action="append", default=[], metavar="FILE",
                   help="load a Python file defining extra steppers and/or problems (repeatable)")
    p.add_argument("--json", action="store_true", help="print JSON records instead of a table")
    if grid:
        p.add_argument("--stepper", action="append", default=[], metavar="NAME",
                       help="restrict to this stepper (repeatable; default: all)")
        p.add_argument("--problem", action="append", default=[], metavar="NAME",
                       help="restrict to this problem (repeatable; default: all)")
        p.add_argument("--jobs", type=int, default=None, metavar="N",
                       help="worker processes (default: all cores; 1 runs in-process)")
        p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                       help="run the cells on an existing Dask cluster")
        p.add_argument("--fresh", action="store_true", help="ignore cached cells and recompute")
        p.add_argument("--quick", action="store_true", help="coarser, CI-sized settings")
        p.add_argument("--cell-timeout", type=float, default=None, metavar="SECONDS",
                       help="record a cell as failed when it runs longer than this")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="harness", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("list", help="list registered steppers or problems with their declared properties")
    p.add_argument("kind", choices=["steppers", "problems", "experiments"])
    _common(p, grid=False)

    p = sub.add_parser("run", help="run one experiment over steppers x problems")
    p.add_argument("experiment", help="the experiment's name (see `harness list experiments`)")
    _common(p)
    for flag, meta, what in (("--h", "H", "fixed step size (default: from the problem's time scale)"),
                             ("--steps", "N[,N...]", "step count(s) of a fixed-step run"),
                             ("--t-end", "T", "final time of a fixed-step run (sets the step count)"),
                             ("--perturbation", "P", "relative size of the ensemble perturbation "
                                                     "(default: derived per problem)")):
        p.add_argument(flag, default=None, metavar=meta, help=what)

    p = sub.add_parser("reference", help="certified ground-truth state of a problem at time T")
    p.add_argument("problem")
    p.add_argument("--t", required=True, type=str, metavar="T", help="the time (>= the start time)")
    _common(p, grid=False)

    p = sub.add_parser("gate", help="convergence of every stepper on every compatible problem; "
                                    "exit 1 when a measured order misses its claim")
    _common(p)

    p = sub.add_parser("population", help="the gate's own error rates: run it over generated correct "
                                          "methods and mutants; exit 1 on a false alarm or a miss")
    p.add_argument("--size", type=int, default=5, metavar="N",
                   help="correct methods per family (each with 2-3 mutants; default 5)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed of the population")
    _common(p, grid=False)

    p = sub.add_parser("report", help="run every experiment and write the HTML report")
    _common(p)
    p.add_argument("--output", default=None, metavar="DIR", help="reports directory (default: reports/)")
    p.add_argument("--compare", default=None, metavar="RUN",
                   help="earlier run (id or path) for 'what changed' (default: the newest older run)")
    p.add_argument("--from", dest="from_run", default=None, metavar="RUN",
                   help="re-render the report of a saved run (id, path or 'latest'); nothing is measured")
    return parser


# Options whose value may look like an option ("-inf", "-1"): `--t -inf` is read as `--t=-inf`,
# so the value reaches the check that states the rule.
_VALUE_OPTIONS = ("--t", "--jobs", "--cell-timeout")


def _join_values(argv: Sequence[str]) -> list[str]:
    out: list[str] = []
    items = list(argv)
    i = 0
    while i < len(items):
        a = items[i]
        if a in _VALUE_OPTIONS and i + 1 < len(items) and items[i + 1].startswith("-") \
                and not items[i + 1].startswith("--"):
            out.append(f"{a}={items[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def _on_sigterm(signum, frame):
    from harness.errors import Terminated

    raise Terminated()


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(_join_values(sys.argv[1:] if argv is None else argv))
    import signal
    import threading

    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return _main(args)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _main(args: argparse.Namespace) -> int:
    from harness.errors import HarnessError, NoApplicableCellsError, Terminated

    _OUTPUT.append(io.StringIO())
    try:
        with contextlib.redirect_stdout(sys.stderr):
            code = _dispatch(args)
    except NoApplicableCellsError as exc:
        _explain_skips(exc.skips, getattr(args, "json", False))
        code = _error(str(exc), EXIT_USAGE)
    except HarnessError as exc:
        code = _error(str(exc), getattr(exc, "exit_status", EXIT_USAGE))
    except OSError as exc:
        code = _error(*_describe_os_error(exc))
    except KeyboardInterrupt:
        print("harness: interrupted", file=sys.stderr)
        code = 130
    except Terminated:
        print("harness: terminated", file=sys.stderr)
        code = 143
    finally:
        text = _OUTPUT.pop().getvalue()
    written = _write_stdout(text)
    return code if written == EXIT_OK else written


def _error(message: str, code: int) -> int:
    print(f"harness: error: {_one_line(message)}", file=sys.stderr)
    return code


def _describe_os_error(exc: OSError) -> tuple[str, int]:
    from harness.errors import describe_os_error

    return describe_os_error(exc)


def _stdout_name() -> str:
    try:
        target = os.readlink(f"/proc/self/fd/{sys.stdout.fileno()}")
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        return "stdout"
    return f"stdout ({target})" if target.startswith("/") else "stdout"


def _write_stdout(text: str) -> int:
    """Write the command's output and flush it; an OS error becomes one line on stderr."""
    try:
        if text:
            sys.stdout.write(text)
        sys.stdout.flush()
    except OSError as exc:
        exc.filename = _stdout_name()
        _silence_stdout()
        return _error(*_describe_os_error(exc))
    return EXIT_OK


def _silence_stdout() -> None:
    """After a failed write, point the real stdout at /dev/null so the interpreter's own flush
    at exit does not print a second error (only for the process's real stdout)."""
    if sys.stdout is not sys.__stdout__:
        return
    with contextlib.suppress(OSError, ValueError, AttributeError, io.UnsupportedOperation):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def _explain_skips(skips: Sequence[dict], as_json: bool) -> None:
    """Why each requested pair does not apply: JSON records or a table, on stdout."""
    if as_json:
        _print_json([dict(r, verdict="not-applicable", passed=False) for r in skips])
        return
    import pandas as pd

    print("not applicable:", file=_out())
    _print_table(pd.DataFrame(list(skips), columns=["experiment", "stepper", "problem", "reason"]),
                 ["experiment", "stepper", "problem", "reason"])


def _one_line(text: str) -> str:
    line = " ".join(text.split())
    return line if len(line) <= 500 else line[:497] + "..."


def _load_plugins(paths: Sequence[str]) -> None:
    from harness.registry import load_plugin

    for path in paths:
        load_plugin(path)


def _names(kind: str, requested: Sequence[str]) -> list[str]:
    from harness.registry import problems, steppers

    reg = steppers if kind == "stepper" else problems
    if not requested:
        return reg.names()
    for name in requested:
        reg.get(name)  # raises UnknownNameError with the closest names
    return list(dict.fromkeys(requested))


def _dispatch(args: argparse.Namespace) -> int:
    _load_plugins(args.plugin)
    if args.command == "list":
        return _cmd_list(args)
    if args.command == "reference":
        return _cmd_reference(args)
    if args.command == "run":
        return _cmd_run(args)
    if args.command == "gate":
        return _cmd_gate(args)
    if args.command == "report":
        return _cmd_report(args)
    if args.command == "population":
        return _cmd_population(args)
    raise AssertionError(args.command)


def _cmd_population(args) -> int:
    """Generate a population (harness.populations), judge it, save the per-method table and the
    rates under results/<run-id>/ as `gate-population`, and exit 1 on any false alarm or miss."""
    import time

    import pandas as pd

    from harness.errors import InputError
    from harness.populations import error_rates, generate
    from harness.runner import RunResult
    from harness.store import save_run

    if not 1 <= args.size <= 1000:
        raise InputError(f"`--size` must lie in [1, 1000], got {args.size}")
    started = time.perf_counter()
    table, rates = error_rates(generate(args.size, seed=args.seed))
    empty = pd.DataFrame()
    result = RunResult(experiment="gate-population",
                       description="the gate's error rates on generated methods",
                       config={"size": args.size, "seed": args.seed}, rows=table, summary=rates,
                       failures=empty, skips=empty, cells=empty, wall_s=time.perf_counter() - started,
                       cached_cells=0, computed_cells=len(table))
    path = save_run({"gate-population": result}, config={"command": "population", "size": args.size,
                                                          "seed": args.seed})
    print(f"harness: results saved in {os.fspath(path)}", file=sys.stderr)
    overall = rates[rates.family == "all"].iloc[0]
    bad = int(overall.gate_false_alarms + overall.gate_misses)
    if args.json:
        _print_json(rates.to_dict("records"))
    else:
        _print_table(rates, list(rates.columns))
        print(f"population: {int(overall.correct_methods)} correct methods, {int(overall.mutants)} mutants; "
              f"gate false alarms {int(overall.gate_false_alarms)}, misses {int(overall.gate_misses)}; "
              f"measurement alone: false alarms {int(overall.measurement_false_alarms)}, "
              f"misses {int(overall.measurement_misses)}", file=_out())
    return EXIT_FAILED if bad else EXIT_OK


def _jsonable(value: Any) -> Any:
    import numpy as np

    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _print_json(records: Any) -> None:
    print(json.dumps(_jsonable(records), indent=2), file=_out())


def _print_table(frame, columns: Sequence[str]) -> None:
    import pandas as pd

    if frame.empty:
        print("(none)", file=_out())
        return
    cols = [c for c in columns if c in frame.columns]
    with pd.option_context("display.max_rows", None, "display.max_columns", None,
                           "display.width", 200, "display.max_colwidth", 70):
        print(frame[cols].to_string(index=False, float_format=lambda x: f"{x:.4g}"), file=_out())


def _cmd_list(args) -> int:
    from harness.registry import plugin_errors, problems, steppers

    if args.kind == "steppers":
        records = [dict(s.info.as_dict(), origin=steppers.origin(s.info.name)) for s in steppers.all()]
        cols = ["name", "family", "claimed_order", "explicit", "symplectic", "symmetric",
                "evals_per_step", "form", "velocity_dependent", "adaptive"]
    elif args.kind == "problems":
        records = [dict(p.describe(), origin=problems.origin(p.name)) for p in problems.all()]
        cols = ["name", "form", "dim", "t_span", "velocity_dependent", "conservative",
                "exact_solution", "invariants"]
    else:
        from harness.experiments import EXPERIMENTS, get_experiment  # noqa: F401

        records = [{"name": e.name, "description": e.description} for e in EXPERIMENTS.values()]
        cols = ["name", "description"]
    if args.json:
        _print_json(records)
    else:
        import pandas as pd

        _print_table(pd.DataFrame(records), cols)
    for err in plugin_errors():
        print(f"harness: warning: {_one_line(err)}", file=sys.stderr)
    return EXIT_OK


def _cmd_reference(args) -> int:
    import numpy as np

    from harness.ground_truth import reference
    from harness.problem import check_time
    from harness.registry import get_problem

    problem = get_problem(args.problem)
    t = check_time(args.t, "--t")
    if t < problem.t0:
        from harness.errors import InputError

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
    if problem.exact is not None:
        exact = problem.exact(t, problem.y0[:, None], problem.t0, problem.pars_for(1))[:, 0]
        record["exact_state"] = exact.tolist()
        record["exact_difference"] = float(np.max(np.abs(exact - ref.y[-1][:, 0])))
    if args.json:
        _print_json([record])
    else:
        for k, v in record.items():
            print(f"{k:>18}: {v}", file=_out())
    return EXIT_OK


def _run(args, experiment: str):
    """Run one experiment's grid and save it under results/<run-id>/ (path on stderr)."""
    from harness.experiments import get_experiment
    from harness.experiments.common import OVERRIDE_KEYS, check_overrides
    from harness.runner import run_experiment
    from harness.store import save_run

    overrides = check_overrides(get_experiment(experiment),
                                {k: getattr(args, k, None) for k in OVERRIDE_KEYS})
    result = run_experiment(
        experiment,
        _names("stepper", args.stepper),
        _names("problem", args.problem),
        quick=args.quick,
        jobs=args.jobs,
        scheduler=args.scheduler,
        fresh=args.fresh,
        plugins=tuple(args.plugin),
        cell_timeout=args.cell_timeout,
        config=overrides or None,
    )
    path = save_run({experiment: result}, config={"command": args.command, "experiment": experiment,
                                                   "quick": args.quick, "plugins": list(args.plugin),
                                                   "overrides": overrides})
    print(f"harness: results saved in {os.fspath(path)}", file=sys.stderr)
    return result


def _failures_table(result) -> list[dict]:
    import pandas as pd

    f = result.failures
    if isinstance(f, pd.DataFrame):
        return f.to_dict("records")
    return list(f or [])


def _cmd_run(args) -> int:
    from harness.experiments import get_experiment

    get_experiment(args.experiment)  # unknown name -> exit 2 with the closest names
    result = _run(args, args.experiment)
    records = result.summary.to_dict("records")
    failures = _failures_table(result)
    if args.json:
        _print_json(records + [dict(f, verdict="failed", passed=False) for f in failures])
    else:
        _print_table(result.summary, list(result.summary.columns))
        _print_footer(result, failures)
    # A claim an experiment checks (stability figures, bounded energy, reversibility, ...) that
    # does not hold fails the run like a failed cell does.
    failed_claims = 0
    if "passed" in result.summary.columns:
        failed_claims = int((result.summary["passed"] == False).sum())  # noqa: E712 (object column)
        if failed_claims and not args.json:
            print(f"{args.experiment}: {failed_claims} cell(s) whose claim does not hold", file=_out())
    return EXIT_FAILED if failures or failed_claims else EXIT_OK


def _print_footer(result, failures) -> None:
    out = _out()
    print(f"\n{len(result.summary)} cells, {len(failures)} failed, "
          f"{getattr(result, 'cached_cells', 0)} from cache, {result.wall_s:.1f} s", file=out)
    for f in failures:
        print(f"FAILED {f.get('stepper')} x {f.get('problem')}: {_one_line(str(f.get('message', '')))}",
              file=out)
    skips = result.skips.to_dict("records") if hasattr(result.skips, "to_dict") else []
    for r in skips[:SHOWN_SKIPS]:
        print(f"not applicable: {r.get('stepper')} x {r.get('problem')}: {_one_line(str(r.get('reason')))}",
              file=out)
    if len(skips) > SHOWN_SKIPS:
        print(f"not applicable: {len(skips) - SHOWN_SKIPS} more pairs (every reason: "
              "`harness.results.load(table='skips')`)", file=out)


def _cmd_gate(args) -> int:
    from harness.gate import GATE_COLUMNS, gate_table

    result = _run(args, "convergence")
    table = gate_table(result.summary)
    failures = _failures_table(result)
    passed = bool(table["passed"].all()) and not failures
    if args.json:
        _print_json(table.to_dict("records") + [
            dict(f, verdict="failed", passed=False) for f in failures
        ])
    else:
        _print_table(table, GATE_COLUMNS)
        _print_footer(result, failures)
        n_bad = int((~table["passed"]).sum()) + len(failures)
        n_unmeasured = int((table["outcome"] == "not-measurable").sum())
        print(f"gate: {'PASSED' if passed else 'FAILED'} ({len(table)} cells, {n_bad} failing, "
              f"{n_unmeasured} not measurable: see their reasons)", file=_out())
    return EXIT_OK if passed else EXIT_FAILED


def _cmd_report(args) -> int:
    from harness.report import build_report, rerender_report

    if args.from_run is not None:
        path = rerender_report(args.from_run, output=args.output, compare=args.compare,
                               grid_options=_grid_options_given(args))
        print(os.fspath(path), file=_out())
        return EXIT_OK
    path = build_report(
        steppers=_names("stepper", args.stepper),
        problems=_names("problem", args.problem),
        quick=args.quick,
        jobs=args.jobs,
        scheduler=args.scheduler,
        fresh=args.fresh,
        plugins=tuple(args.plugin),
        output=args.output,
        compare=args.compare,
    )
    print(os.fspath(path), file=_out())
    return EXIT_OK


def _grid_options_given(args) -> list[str]:
    """The measuring options given on the command line (`report --from` takes none)."""
    given = [f"--{k}" for k in ("stepper", "problem", "plugin") if getattr(args, k)]
    given += [f"--{k}" for k in ("quick", "fresh") if getattr(args, k)]
    given += [f"--{k.replace('_', '-')}" for k in ("jobs", "scheduler", "cell_timeout")
              if getattr(args, k) is not None]
    return given


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
