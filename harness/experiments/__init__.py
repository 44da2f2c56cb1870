"""Experiments: one module each; importing this package registers them in `EXPERIMENTS`."""

from importlib import import_module

from harness.experiments.base import EXPERIMENTS, Cell, Experiment, Skip, get_experiment

__all__ = ["EXPERIMENTS", "Cell", "Experiment", "Skip", "get_experiment"]

# Each module registers its experiment with `register_experiment` on import.
_MODULES = (
    "convergence",
    "stability",
    "reversibility",
    "energy",
    "symplecticity",
    "work_precision",
    "step_control",
)

for _name in _MODULES:
    try:
        import_module(f"harness.experiments.{_name}")
    except ModuleNotFoundError as exc:  # a module not written yet; never hides other errors
        if exc.name != f"harness.experiments.{_name}":
            raise
