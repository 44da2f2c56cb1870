"""Every convergence cell that did not converge at its expected order, with the fact that explains it.

`python -m harness.not_converged [RESULTS_DIR] [--plugin FILE]` judges a saved convergence summary
(`RESULTS_DIR/convergence.summary.parquet`; default: the newest run under `results/` that has
one) with the gate's rules (`harness.gate.gate_table`) and prints one line per cell whose verdict
is not `converged`, grouped as

- `predicted`: the rules expected that verdict (`exact` on a polynomial solution, `meets-tolerance`
  for an adaptive stepper), with the rule's reason;
- `not-measurable`: a tolerated verdict (`insufficient-range`, `unstable` where the problem is
  stiff for the method, an unpredicted `exact`), with the limit that stopped it;
- `fail`: a verdict that contradicts the facts.

Exit status 1 when any cell fails, as for `harness gate`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

from harness.errors import InputError
from harness.gate import gate_table
from harness.registry import load_plugin

__all__ = ["not_converged", "format_not_converged", "main"]


def not_converged(gate: pd.DataFrame) -> pd.DataFrame:
    """The rows of a gate table (`harness.gate.gate_table`) whose verdict is not `converged`
    (the stepper-level `(any)` rows included), with a `group` column: predicted,
    not-measurable, not-verified or fail.

    Parameters
    ----------
    gate : DataFrame, the gate table.

    Returns
    -------
    DataFrame: the rows, fail first, then not-verified, not-measurable, predicted.
    """
    rows = gate[(gate.verdict != "converged") | (gate.outcome != "pass")].copy()
    rows["group"] = rows.outcome.map({"pass": "predicted"}).fillna(rows.outcome)
    order = {"fail": 0, "not-verified": 1, "not-measurable": 2, "predicted": 3}
    rows["_k"] = rows.group.map(order)
    return rows.sort_values(["_k", "stepper", "problem"]).drop(columns="_k").reset_index(drop=True)


def format_not_converged(rows: pd.DataFrame, total: int) -> str:
    """One line per cell, grouped, and a count line.

    Parameters
    ----------
    rows : DataFrame from `not_converged`; total : int, the number of cells of the gate table.

    Returns
    -------
    str: the lines joined.
    """
    lines = []
    for group, g in rows.groupby("group", sort=False):
        lines.append(f"{group} ({len(g)}):")
        for r in g.itertuples():
            expected = r.expected + (f" at order {r.expected_order:g}"
                                     if pd.notna(r.expected_order) and r.expected_order else "")
            lines.append(f"  {r.stepper} x {r.problem}: {r.verdict or '-'} (expected {expected}): {r.reason}")
    counts = rows.group.value_counts()
    lines.append(f"{total} cells: {total - len(rows)} converged as expected, "
                 + ", ".join(f"{int(counts.get(k, 0))} {k}"
                             for k in ("predicted", "not-measurable", "not-verified", "fail")))
    return "\n".join(lines)


def _latest(results: Path) -> Path:
    runs = sorted((p for p in results.glob("*/convergence.summary.parquet")), key=lambda p: p.stat().st_mtime)
    if not runs:
        raise InputError(f"`RESULTS_DIR`: no convergence.summary.parquet under {results}")
    return runs[-1].parent


def main(argv: list[str] | None = None) -> int:
    """List the cells of a run whose convergence verdict is not `converged`, grouped.

    Parameters
    ----------
    argv : the command-line arguments (default: sys.argv[1:]): a run directory, `--plugin FILE`.

    Returns
    -------
    int: 0, 1 when a cell fails, 2 on bad input.
    """
    parser = argparse.ArgumentParser(prog="python -m harness.not_converged",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="?", help="a run directory (default: the newest under results/)")
    parser.add_argument("--plugin", action="append", default=[], help="plugin file the run used")
    args = parser.parse_args(argv)
    try:
        for p in args.plugin:
            load_plugin(p)
        run = Path(args.results) if args.results else _latest(Path("results"))
        path = run / "convergence.summary.parquet"
        if not path.exists():
            raise InputError(f"`RESULTS_DIR`: {path} does not exist")
        summary = pd.read_parquet(path)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    gate = gate_table(summary)
    rows = not_converged(gate)
    print(f"{path}")
    print(format_not_converged(rows, len(gate)))
    return 1 if (rows.group == "fail").any() else 0


if __name__ == "__main__":
    sys.exit(main())
