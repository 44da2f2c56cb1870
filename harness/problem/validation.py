"""A problem's definition checked before anything is compiled or measured, and against its own
exact flow before a method run on it is judged.

At construction (`check_definition`, cheap, no compile): the name (`harness.names`), a non-empty
state of distinct heyoka variables, real finite start values (complex values are refused, never
cast), and a Newtonian form with one velocity per position.

Against the flow (declared invariants checked along the problem's own orbit, and singularities
within the span) is `harness.invariant_checks` and `harness.scales`: they need the orbit, a
layer above the contracts.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import heyoka as hy
import numpy as np

from harness.errors import InputError, ProblemError
from harness.names import check_name

__all__ = ["check_definition", "check_start", "exact_state"]


def check_definition(name: Any, variables: Sequence[Any], newtonian: Any) -> str:
    """The checks of a definition's name, state variables and Newtonian form.

    Parameters
    ----------
    name : the problem's name; variables : its state variables; newtonian : its NewtonianForm
    or None.

    Returns
    -------
    str: the name.
    """
    name = check_name(name, "problem `name`")
    if len(variables) == 0:
        raise InputError(f"problem {name!r}: `variables` must hold at least one state variable, "
                         "got none (an empty state has nothing to integrate)")
    for v in variables:
        if not isinstance(v, hy.expression) or hy.get_variables(v) != [str(v)]:
            raise InputError(f"problem {name!r}: `variables` must be heyoka variables "
                             f"(hy.make_vars), got {v!r}")
    if newtonian is not None:
        nq, nv = len(newtonian.positions), len(newtonian.velocities)
        if nq != nv or nq == 0:
            raise InputError(f"problem {name!r}: a Newtonian form needs one velocity per "
                             f"position, got {nq} position(s) and {nv} velocity(ies)")
    return name


def check_start(name: str, y0: Any, dim: int) -> np.ndarray:
    """`y0` as a read-only float64 array (dim,): real, finite numbers; complex values refused.

    Parameters
    ----------
    name : the problem's name; y0 : the start values given; dim : the number of variables.

    Returns
    -------
    numpy.ndarray
    """
    try:
        raw = np.asarray(y0)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"problem {name!r}: `y0` must be numbers, got {y0!r}"[:300]) from None
    if np.iscomplexobj(raw) or (raw.dtype == object and any(isinstance(x, complex)
                                                            for x in raw.ravel())):
        raise InputError(f"problem {name!r}: `y0` must be real numbers (complex values are not "
                         f"cast to real), got {y0!r}"[:300])
    if raw.dtype.kind in "USVb" or raw.dtype == bool:
        raise InputError(f"problem {name!r}: `y0` must be numbers, got {y0!r}"[:300])
    try:
        arr = np.array(raw, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"problem {name!r}: `y0` must be numbers, got {y0!r}"[:300]) from None
    if arr.shape != (dim,):
        raise InputError(f"problem {name!r}: `y0` needs {dim} values, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"problem {name!r}: `y0` must be finite, got {arr.tolist()}")
    return arr


def exact_state(problem, t: float, y0: np.ndarray) -> np.ndarray:
    """The problem's declared exact solution at `t` from states `y0` (dim, N), checked: an
    exception it raises, or a result that is not a real finite (dim, N) array, is the problem's
    `ProblemError` (one line), never a traceback.

    Parameters
    ----------
    problem : the Problem (its `exact` is not None); t : the time; y0 : start states (dim, N).

    Returns
    -------
    numpy.ndarray: states shaped (dim, N).
    """
    try:
        out = problem.exact(t, y0, problem.t0, problem.pars_for(y0.shape[1]))
        arr = np.asarray(out)
    except Exception as exc:  # noqa: BLE001  (a user's function: anything may be raised)
        raise ProblemError(f"problem {problem.name!r}: its exact solution raised at t = {t:g}: "
                           f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}") from None
    if np.iscomplexobj(arr) or arr.dtype.kind not in "fiu" or arr.shape != y0.shape:
        raise ProblemError(f"problem {problem.name!r}: its exact solution must return real "
                           f"states shaped {y0.shape}, got {arr.dtype} shaped {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ProblemError(f"problem {problem.name!r}: its exact solution is not finite at "
                           f"t = {t:g}")
    return arr.astype(np.float64)
