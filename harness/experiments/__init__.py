"""Experiments: the one list of them, in report order; importing this package registers them.

`EXPERIMENT_MODULES` maps each experiment's CLI name to its module in this package. The CLI
(`harness run NAME`, `harness list experiments`), the runner (`run_experiments()` with no names)
and the report (its sections, in this order) are all built from it: adding an experiment is one
entry here plus its folder (`<module>/__init__.py` measures, `<module>/section.py` presents; the
experiment names its section, see `base.Experiment`). A listed module that fails to import
raises (a deleted or broken experiment is never silently dropped). Importing this package also
registers the experiments of other distributions' `harness.experiments` entry points
(`base.load_experiments`), listed and reported after the built-ins.
"""

from importlib import import_module

from harness.experiments.base import EXPERIMENTS, Cell, Experiment, Skip, get_experiment, load_experiments

__all__ = ["EXPERIMENTS", "EXPERIMENT_MODULES", "EXPERIMENT_NAMES", "Cell", "Experiment", "Skip",
           "builtin_experiments", "get_experiment"]

# CLI name -> module under harness/experiments/, in the order of the report's sections.
EXPERIMENT_MODULES = {
    "convergence": "convergence",
    "stability": "stability",
    "reversibility": "reversibility",
    "energy": "energy",
    "multistep-orbits": "multistep_orbits",
    "symplecticity": "symplecticity",
    "work-precision": "work_precision",
    "roundoff": "roundoff",
    "step-control": "step_control",
    "side-by-side": "side_by_side",
}
EXPERIMENT_NAMES = tuple(EXPERIMENT_MODULES)

for _name, _module in EXPERIMENT_MODULES.items():
    import_module(f"harness.experiments.{_module}")
    if _name not in EXPERIMENTS:
        raise ImportError(f"harness.experiments.{_module} did not register experiment {_name!r}")


def builtin_experiments() -> list[Experiment]:
    """The built-in experiments, in report order: this project's entry in the entry-point group
    `harness.experiments` (pyproject.toml), through which other distributions add theirs.

    Returns
    -------
    list of Experiment: the registered instances, in the order of EXPERIMENT_NAMES.
    """
    return [EXPERIMENTS[name] for name in EXPERIMENT_NAMES]


load_experiments()  # other distributions' experiments, after the built-ins
# registration order follows imports between modules; the list's order is the one users see
for _name in [*EXPERIMENT_NAMES, *[n for n in EXPERIMENTS if n not in EXPERIMENT_MODULES]]:
    EXPERIMENTS[_name] = EXPERIMENTS.pop(_name)
