"""Step loops registered by the families: which loop runs a method record, and which faster
implementation of a stepper's method runs where it applies.

A family registers its step loops through the entry-point group `harness.step_loops`, the
built-ins too (this project declares `implementations.builder:builtin_step_loops` there), so the
framework names no family module: `Method.stepper()` asks `build_stepper`, the experiments ask
`fastest`, and the cache keys ask `implementations_of` (a cell run by a faster implementation is
keyed on that implementation's code as well). An entry point names a `StepLoop`, a list of them,
or a callable returning either; this project's own are asked first (one that fails to load
raises), then other distributions' in the order of `harness.entry_points.group_entry_points`
(one that fails is recorded in `STEP_LOOP_ERRORS` and the others load).
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from harness.entry_points import group_entry_points, missing_builtins
from harness.errors import InputError, PluginError
from harness.stepper import Stepper

__all__ = ["StepLoop", "step_loops", "build_stepper", "faster_implementations", "implementations_of",
           "fastest", "STEP_LOOP_ERRORS", "GROUP"]

GROUP = "harness.step_loops"


@dataclass(frozen=True)
class StepLoop:
    """A family's step loop, as the registry asks it.

    Rules for whoever writes one:

    1. `build(method)` returns the `Stepper` that runs `method` (a `harness.methods.Method`)
       when the method's coefficients are of this loop's family, else None. Loops are asked in
       registration order and the first that answers builds the stepper.
    2. `faster(stepper)` (optional) returns a second implementation of `stepper`'s method that
       gives the same numbers to rounding (a test must say so over the registry), or None where
       it has none. It must be cheap (nothing compiled yet): compiling happens on the first run.
       The result's `incompatibility(problem)` says where it cannot run; there the stepper
       itself runs.
    3. Neither raises for a method or stepper it does not handle: it answers None.

    Parameters
    ----------
    name : str, what the loop runs, for messages (e.g. 'explicit Runge-Kutta').
    build : callable Method -> Stepper or None, optional
    faster : callable Stepper -> Stepper or None, optional
    """

    name: str
    build: Callable[[Any], Stepper | None] | None = None
    faster: Callable[[Stepper], Stepper | None] | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"`name` must be a non-empty string, got {self.name!r}")
        for label in ("build", "faster"):
            value = getattr(self, label)
            if value is not None and not callable(value):
                raise InputError(f"step loop {self.name!r}: `{label}` must be callable or None")


#: Entry points of other distributions that failed to load, with their reason.
STEP_LOOP_ERRORS: list[str] = []
_loops: list[StepLoop] = []
_loaded: list[bool] = []
_lock = threading.RLock()
_variants: weakref.WeakKeyDictionary[Stepper, tuple[Stepper, ...]] = weakref.WeakKeyDictionary()


def _expand(loaded: Any) -> list[StepLoop]:
    if isinstance(loaded, StepLoop):
        return [loaded]
    if callable(loaded):
        return _expand(loaded())
    if isinstance(loaded, Iterable) and not isinstance(loaded, str | bytes):
        return [loop for item in loaded for loop in _expand(item)]
    raise PluginError(f"expected a StepLoop, a list of them, or a callable; got {type(loaded).__name__}")


def step_loops() -> list[StepLoop]:
    """Every registered step loop, this project's own first (loaded on the first call).

    Returns
    -------
    list of StepLoop, in the order they are asked.
    """
    with _lock:
        if not _loaded:
            _loaded.append(True)
            own, others = group_entry_points(GROUP)
            if not own:
                STEP_LOOP_ERRORS.append(missing_builtins("step loop", GROUP))
            try:
                for ep in own:
                    _loops.extend(_expand(ep.load()))
            except BaseException:
                _loaded.clear()  # a failing built-in raises again on the next call
                _loops.clear()
                raise
            for ep in others:
                try:
                    _loops.extend(_expand(ep.load()))
                except Exception as exc:
                    STEP_LOOP_ERRORS.append(f"entry point {ep.name!r} ({ep.value}): "
                                            f"{type(exc).__name__}: {exc}")
        return list(_loops)


def build_stepper(method) -> Stepper:
    """The stepper that runs a method record: the first registered loop of its family.

    Parameters
    ----------
    method : harness.methods.Method

    Returns
    -------
    Stepper

    Raises `InputError` naming the method when no registered loop runs its coefficients.
    """
    for loop in step_loops():
        if loop.build is not None:
            stepper = loop.build(method)
            if stepper is not None:
                return stepper
    kind = type(getattr(method, "coefficients", None)).__name__
    raise InputError(f"method {method.name!r}: no registered step loop runs coefficients of type "
                     f"{kind} (loops: {', '.join(loop.name for loop in step_loops())})")


def faster_implementations(stepper: Stepper) -> tuple[Stepper, ...]:
    """The other implementations of `stepper`'s method that the registered loops offer (built
    once per stepper object).

    Parameters
    ----------
    stepper : Stepper

    Returns
    -------
    tuple of Stepper, in the order of the loops (empty when none applies).
    """
    if not isinstance(stepper, Stepper):
        raise InputError(f"`stepper` must be a Stepper, got {type(stepper).__name__}")
    with _lock:
        if stepper in _variants:
            return _variants[stepper]
    found = tuple(v for loop in step_loops() if loop.faster is not None
                  for v in [loop.faster(stepper)] if v is not None)
    with _lock:
        return _variants.setdefault(stepper, found)


def implementations_of(stepper: Stepper) -> tuple[Stepper, ...]:
    """`stepper` and its faster implementations: every loop a cell of it may run (what its
    cache key covers).

    Parameters
    ----------
    stepper : Stepper

    Returns
    -------
    tuple of Stepper, `stepper` first.
    """
    return (stepper, *faster_implementations(stepper))


def fastest(stepper: Stepper, problem) -> Stepper:
    """The implementation experiments run: the first faster implementation of `stepper`'s
    method (rule 2 of `StepLoop`) that runs on `problem`, else `stepper` itself. Read
    `.info.implementation` of the result to record which one ran.

    Parameters
    ----------
    stepper : Stepper
    problem : harness.problem.Problem

    Returns
    -------
    Stepper
    """
    for variant in faster_implementations(stepper):
        if variant.compatible(problem):
            return variant
    return stepper
