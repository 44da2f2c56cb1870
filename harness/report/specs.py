"""Which section each experiment of a run gets: the one it names, or the generic table."""

from __future__ import annotations

import pandas as pd

from harness.experiments import EXPERIMENTS
from harness.kit.section import SectionSpec, generic_key, generic_spec

__all__ = ["section_spec", "experiment_key"]


def section_spec(experiment: str) -> SectionSpec:
    """The section `experiment` names (`Experiment.section`), or the generic table section
    built from the experiment's own description (also for one no longer registered).

    Parameters
    ----------
    experiment : str, the experiment's name (registered or not).

    Returns
    -------
    SectionSpec: the experiment's own, else `generic_spec`'s.
    """
    exp = EXPERIMENTS.get(experiment)
    spec = getattr(exp, "section", None)
    if spec is not None:
        return spec
    return generic_spec(experiment, getattr(exp, "description", "") or "")


def experiment_key(name: str, summ: pd.DataFrame) -> tuple[str, ...]:
    """The columns that identify one judged row of experiment `name`'s summary `summ`.

    Parameters
    ----------
    name : str, the experiment.
    summ : DataFrame, its summary (read only when its section declares no key).

    Returns
    -------
    tuple of str
    """
    spec = getattr(EXPERIMENTS.get(name), "section", None)
    return spec.key if spec is not None else generic_key(summ)
