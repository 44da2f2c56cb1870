"""Command line: `harness` (also `python -m harness`).

    harness list steppers|problems [--json]
    harness run EXPERIMENT [--stepper NAME]... [--problem NAME]... [--plugin FILE]... [--json]
    harness reference PROBLEM --t T [--json]
    harness gate [--json]
    harness report [--quick] [--fresh]

Errors a user can fix exit 2 with one line on stderr naming the argument and the rule; the
gate exits 1 when a claim fails.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from typing import Any

__all__ = ["main", "build_parser"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


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
    p.add_argument("experiment", help="convergence, stability, reversibility, energy, "
                                      "symplecticity or work-precision")
    _common(p)

    p = sub.add_parser("reference", help="certified ground-truth state of a problem at time T")
    p.add_argument("problem")
    p.add_argument("--t", required=True, type=str, metavar="T", help="the time (>= the start time)")
    _common(p, grid=False)

    p = sub.add_parser("gate", help="convergence of every stepper on every compatible problem; "
                                    "exit 1 when a measured order misses its claim")
    _common(p)

    p = sub.add_parser("report", help="run every experiment and write the HTML report")
    _common(p)
    p.add_argument("--output", default=None, metavar="DIR", help="reports directory (default: reports/)")
    p.add_argument("--compare", default=None, metavar="RUN",
                   help="earlier run (id or path) for 'what changed' (default: the newest older run)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from harness.errors import HarnessError

    try:
        return _dispatch(args)
    except HarnessError as exc:
        print(f"harness: error: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("harness: interrupted", file=sys.stderr)
        return 130


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
    raise AssertionError(args.command)


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
    print(json.dumps(_jsonable(records), indent=2))


def _print_table(frame, columns: Sequence[str]) -> None:
    import pandas as pd

    if frame.empty:
        print("(none)")
        return
    cols = [c for c in columns if c in frame.columns]
    with pd.option_context("display.max_rows", None, "display.max_columns", None,
                           "display.width", 200, "display.max_colwidth", 70):
        print(frame[cols].to_string(index=False, float_format=lambda x: f"{x:.4g}"))


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
            print(f"{k:>18}: {v}")
    return EXIT_OK


def _run(args, experiment: str):
    """Run one experiment's grid and save it under results/<run-id>/ (path on stderr)."""
    from harness.runner import run_experiment
    from harness.store import save_run

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
    )
    path = save_run({experiment: result}, config={"command": args.command, "experiment": experiment,
                                                   "quick": args.quick, "plugins": list(args.plugin)})
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
    return EXIT_FAILED if failures else EXIT_OK


def _print_footer(result, failures) -> None:
    print(f"\n{len(result.summary)} cells, {len(failures)} failed, "
          f"{getattr(result, 'cached_cells', 0)} from cache, {result.wall_s:.1f} s")
    for f in failures:
        print(f"FAILED {f.get('stepper')} x {f.get('problem')}: {_one_line(str(f.get('message', '')))}")


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
        print(f"gate: {'PASSED' if passed else 'FAILED'} ({len(table)} cells, {n_bad} failing)")
    return EXIT_OK if passed else EXIT_FAILED


def _cmd_report(args) -> int:
    from harness.report import build_report

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
    print(os.fspath(path))
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
