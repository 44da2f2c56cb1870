"""Cache keys: which code a cell's measurement depends on, computed from the import graph.

A cell's key (`cell_key`) hashes the cell, the experiment's resolved configuration, the cell
file schema and two code versions:
- `code_version(stepper, problem)`: the fingerprints of the cell's stepper and of the faster
  implementations the registry may run in its place (`harness.step_loops.fastest`), each with the
  source of the module its class is defined in and of what that imports (a family's helpers; a
  compiled variant's kernels), and of the problem (coefficients, class source, symbolic
  definition): a changed method changes its cells and those of the steppers its family module
  (or a module importing it) defines, never another family's;
- `experiment_fingerprint(experiment)`: the measuring code of the experiment, found by reading
  the source (never by importing anything new):
  1. the experiment's own module, minus the top-level functions and methods that only its
     `summarize` reaches (judging code: verdicts are recomputed from cached rows, never the
     other way round);
  2. the source of every project module (`harness`, `problems`, `implementations`) that the
     measuring part imports, directly or through other project modules (imports inside
     functions count), except judging-only modules (`JUDGING_MODULES`), the registry (a name
     lookup: what it returns is covered by `code_version`) and the experiment list;
  3. for `harness.tolerances`, which holds measuring and judging thresholds side by side, the
     values of only the names that the measuring code reads (`tol.NAME`, `from
     harness.tolerances import NAME`), so changing a verdict threshold recomputes nothing;
  4. `MEASURING_MODULES`, reached through objects rather than imports (with the submodules a
     package among them imports from itself), and the harness version.
Forgetting a module in `JUDGING_MODULES` costs recomputation, never a stale cell.
"""

from __future__ import annotations

import hashlib
import importlib
from collections.abc import Mapping
from typing import Any

from harness import __version__
from harness.code_versions import (  # noqa: F401  (re-exported: the cache keys' vocabulary)
    JUDGING_MODULES,
    MEASURING_MODULES,
    PROJECT_PACKAGES,
    TOLERANCES,
    experiment_modules,
    measuring_modules,
    module_version,
    project_files,
    tolerance_values,
)
from harness.errors import HarnessError
from harness.experiments.base import Cell, Experiment
from harness.provenance import to_jsonable
from harness.registry import get_problem, get_stepper
from harness.step_loops import implementations_of
from harness.store import CELL_SCHEMA

__all__ = ["cell_key", "code_version", "experiment_fingerprint", "measuring_modules", "module_version",
           "judging_version", "project_files",
           "MEASURING_MODULES", "JUDGING_MODULES", "PROJECT_PACKAGES"]


def judging_version(experiment: Experiment) -> str:
    """sha256 of everything an experiment's `summarize` may run: the experiment's modules and
    every project module they import (judging modules such as the rules and the gate included,
    listing modules not), the modules every cell steps through (`MEASURING_MODULES`) and every
    threshold. A summary cached under it is recomputed whenever a rule or threshold changes.

    Parameters
    ----------
    experiment : Experiment, whose classes' modules are followed.

    Returns
    -------
    str: hex sha256 digest.
    """
    every = {n for n in dir(importlib.import_module(TOLERANCES)) if n.isupper()}
    return module_version(*experiment_modules(experiment), *MEASURING_MODULES, judging=True,
                          extra=tolerance_values(every))


def experiment_fingerprint(experiment: Experiment) -> str:
    """The experiment's measuring-code version: its own `fingerprint()` when it defines one,
    else the measuring source found from its import graph (module docstring), plus the values
    of the thresholds it reads and the harness version.

    Parameters
    ----------
    experiment : Experiment, the experiment measured.

    Returns
    -------
    str: hex sha256 digest.
    """
    parts = [__version__, type(experiment).__qualname__, str(experiment.name)]
    own = getattr(experiment, "fingerprint", None)
    if callable(own):
        parts.append(str(own()))
    else:
        counted, tol_names = measuring_modules(experiment)
        for name in sorted(counted):
            parts.append(name + "\n" + hashlib.sha256(counted[name].encode()).hexdigest())
        parts.append(tolerance_values(tol_names))
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def code_version(stepper: str, problem: str) -> str:
    """Hash of the fingerprints of a stepper (with those of its faster implementations, which
    the experiments may run in its place: `harness.step_loops.fastest`) and a problem (looked up
    in the registry); an empty name stands for 'none' (a cell that uses no stepper, or no
    problem).

    Parameters
    ----------
    stepper : str, a registered stepper's name, or ''; problem : str, a registered problem's
    name, or ''.

    Returns
    -------
    str: 32 hex digits. Raises HarnessError when a fingerprint is not a string.
    """
    # every implementation a cell of the stepper may run (`fastest`), each with the code of the
    # module its class is defined in and what that imports (module-level helpers of a family's
    # loop; a compiled variant's kernels): a change to either changes the key of each cell it
    # could have measured
    s = "\n".join(f"{i.fingerprint()}\n{module_version(type(i).__module__)}"
                  for i in implementations_of(get_stepper(stepper))) if stepper else ""
    p = get_problem(problem).fingerprint() if problem else ""
    if not isinstance(s, str) or not isinstance(p, str):
        raise HarnessError(
            f"`fingerprint()` must return a string (stepper {stepper!r}, problem {problem!r})"
        )
    return hashlib.sha256(f"stepper\n{s}\nproblem\n{p}".encode()).hexdigest()[:32]


def cell_key(cell: Cell, config: Mapping[str, Any], experiment_version: str, sp_version: str) -> str:
    """The cache key of `cell`: `Cell.key` over the experiment's resolved configuration and a
    code version combining the stepper/problem version, the experiment's fingerprint and the
    cell file schema.

    Parameters
    ----------
    cell : Cell, the cell; config : mapping, the experiment's resolved configuration;
    experiment_version : str, from `experiment_fingerprint`; sp_version : str, from
    `code_version`.

    Returns
    -------
    str: the key `Cell.key` makes.
    """
    code = hashlib.sha256(f"{sp_version}\n{experiment_version}\n{CELL_SCHEMA}".encode()).hexdigest()[:32]
    return cell.key(code, to_jsonable(dict(config)))
