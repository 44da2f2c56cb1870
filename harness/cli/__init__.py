"""Command line: `harness` (also `python -m harness`).

    harness list steppers|problems [--json]
    harness run EXPERIMENT [--stepper NAME]... [--problem NAME]... [--plugin FILE]... [--json]
    harness reference PROBLEM --t T [--json]
    harness gate [--json]
    harness report [--quick] [--fresh] [--compare RUN]
    harness report --from RUN [--compare RUN]   (re-render a saved run, nothing measured)

Errors a user can fix exit 2 with one line on stderr naming the argument and the rule; the
gate exits 1 when a claim fails (a cell contradicts it, or a cell failed), 3 when none does but
a stepper's claim was measured on no cell (not verified on the problems given); a run or gate
over zero applicable cells exits 2 and prints why
each requested pair does not apply (a table on stdout, or JSON records with `--json`).

One output layer serves every command. While a command runs, `sys.stdout` points at stderr (a
plugin's `print()` cannot corrupt `--json`); the command's output is collected and written to
stdout at the end, then flushed. Ordinary OS conditions become one line naming the path and the
problem, no traceback, with a sysexits-style status: the reader closed the pipe (141, as a
SIGPIPE death would give), a full disk or another I/O error (74), no permission (77), a file
where a directory belongs or the reverse (73).

This module parses the command line and dispatches; `output` is the output layer, `tables` prints
records, `lookups` and `commands` hold the commands (imported only once the command line has
parsed).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import signal
import sys
import threading
from collections.abc import Sequence

from harness.cli.output import (
    EXIT_OK,
    EXIT_USAGE,
    OUTPUT,
    EscapingStream,
    os_error_status,
    report_error,
    write_stdout,
)
from harness.errors import HarnessError, NoApplicableCellsError, Terminated

__all__ = ["main", "build_parser"]


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
    """The argument parser of the `harness` command (one subparser per command).

    Returns
    -------
    argparse.ArgumentParser
    """
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
                                    "exit 1 when a measured order misses its claim, 3 when a "
                                    "claim was measured on no cell (not verified)")
    _common(p)

    p = sub.add_parser("population", help="the gate's own error rates: run it over generated correct "
                                          "methods and mutants; exit 1 on a false alarm or a miss")
    p.add_argument("--size", type=int, default=5, metavar="N",
                   help="correct methods per family (each with 2-3 mutants; default 5)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed of the population")
    p.add_argument("--high-order", action="store_true",
                   help="the high-order families instead (extrapolation of Euler and the midpoint rule, "
                        "symmetric compositions: orders 4-12)")
    p.add_argument("--max-order", type=int, default=12, metavar="P",
                   help="highest order drawn by the high-order families (4-12; default 12)")
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
    raise Terminated()


def _ignore_further_signals() -> None:
    """After the first Ctrl-C or SIGTERM the command is ending: a second one (an impatient
    double Ctrl-C) must not turn the exit status 130/143 into a death by signal."""
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the `harness` command line on `argv` (default: `sys.argv[1:]`).

    Parameters
    ----------
    argv : the arguments after the program name.

    Returns
    -------
    int: the exit status (module docstring).
    """
    parser = build_parser()
    args = parser.parse_args(_join_values(sys.argv[1:] if argv is None else argv))

    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        code = _main(args)
    except KeyboardInterrupt:  # a second Ctrl-C while the first was being handled
        _ignore_further_signals()
        print("harness: interrupted", file=sys.stderr)
        code = 130
    finally:  # restored unless the command is ending on a signal (then ignored, see above)
        if previous is not None and signal.getsignal(signal.SIGTERM) is _on_sigterm:
            signal.signal(signal.SIGTERM, previous)
    # The status kept if an interrupted compile is still running. A command that compiles has
    # loaded `harness.cache` (heyoka with it); one that never loaded it abandoned no compile, and
    # `harness --help` or a usage error stays clear of heyoka.
    cache = sys.modules.get("harness.cache")
    if cache is not None:
        cache.set_exit_status(code)
    return code


def _main(args: argparse.Namespace) -> int:
    OUTPUT.append(io.StringIO())
    try:
        err = EscapingStream(sys.stderr)
        with contextlib.redirect_stdout(err), contextlib.redirect_stderr(err):
            code = _dispatch(args)
    except NoApplicableCellsError as exc:  # why each pair does not apply: printed by the command
        code = report_error(str(exc), EXIT_USAGE)
    except HarnessError as exc:
        code = report_error(str(exc), getattr(exc, "exit_status", EXIT_USAGE))
    except OSError as exc:
        code = report_error(*os_error_status(exc))
    except KeyboardInterrupt:
        _ignore_further_signals()
        print("harness: interrupted", file=sys.stderr)
        code = 130
    except Terminated:
        _ignore_further_signals()
        print("harness: terminated", file=sys.stderr)
        code = 143
    finally:
        text = OUTPUT.pop().getvalue()
    written = write_stdout(text)
    return code if written == EXIT_OK else written


def _dispatch(args: argparse.Namespace) -> int:
    # The command line's deferred imports of project modules (tests/test_import_layers.py allows
    # exactly these two): parsing, `--help` and a usage error (exit 2, one line) need neither.
    # Looking up steppers, problems or a reference needs the registry and the ground truth
    # (heyoka, pandas: ~1 s CPU); the other commands also need the experiments, the runner and
    # the report (matplotlib, jinja2: ~2 s CPU).
    if args.command == "reference" or (args.command == "list" and args.kind != "experiments"):
        from harness.cli import lookups

        return lookups.run_lookup(args)
    from harness.cli import commands

    return commands.run_command(args)
