"""The result of one experiment's run (`RunResult`) and its tables' columns."""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

FAILURE_COLUMNS = ["experiment", "cell", "stepper", "problem", "params", "key", "kind", "message",
                   "traceback"]
SKIP_COLUMNS = ["experiment", "stepper", "problem", "reason"]
CELL_COLUMNS = ["experiment", "cell", "stepper", "problem", "params", "key", "status", "cached",
                "wall_s", "n_rows", "worker"]
ID_COLUMNS = ["experiment", "cell", "stepper", "problem"]


@dataclass
class RunResult:
    """One experiment's run.

    `rows`: tidy rows of every successful cell in the order of the experiment's cell list, with
    `experiment`, `cell` (label), `stepper`, `problem` and scalar cell parameters added as
    columns when the experiment's rows lack them. `summary`: `experiment.summarize(rows)`.
    `failures`: one record per failed cell (FAILURE_COLUMNS; `kind` in FAILURE_KINDS).
    `skips`: pairs the experiment does not apply to, with the reason. `cells`: one record per
    cell (status 'ok' or 'failed', whether cached, compute wall time, row count, worker).
    `rows_stored`: True when `rows` is in its stored form (decoded from the run's pack), so the
    file a saved run writes from it decodes to an equal frame (`harness.store.load_run`'s
    `stored_rows`).
    """

    experiment: str
    description: str
    config: dict
    rows: pd.DataFrame
    summary: pd.DataFrame
    failures: pd.DataFrame
    skips: pd.DataFrame
    cells: pd.DataFrame
    wall_s: float
    cached_cells: int
    computed_cells: int
    options: dict = field(default_factory=dict)
    rows_stored: bool = False

    @property
    def n_cells(self) -> int:
        """How many cells the run had."""
        return len(self.cells)

    @property
    def n_failed(self) -> int:
        """How many cells failed."""
        return len(self.failures)

    @property
    def ok(self) -> bool:
        """True when no cell failed."""
        return self.n_failed == 0


