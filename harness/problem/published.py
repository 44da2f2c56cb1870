"""A problem as a test set publishes it: exact start values and constants, end time and reference
values, with their source and stated accuracy.

Published test sets (DETEST, the Bari IVP test set) give their constants and start values as
decimals (0.0057, 77.27, 8.375e-6) that float64 cannot hold. A `Published` record keeps them as
the decimal strings of the source; the problem's float64 form (`Problem.y0`, its parameters) is
derived from them by rounding, and references are computed from the exact values at every
precision level (`Level.exact`), so a reference certifies the problem as published rather than
its float64 rounding. `rounding()` says whether, and by how much, the float64 form differs.

Contract:
1. `y0` holds one exact value per state variable, `parameters` one per declared parameter (same
   names), each a decimal string, an integer or a Fraction (converted to a 60-digit decimal).
2. `values`, when given, is the published solution at `t_end` (one decimal string per variable),
   with `accuracy`: the relative accuracy per component the harness holds it to, and
   `accuracy_note`: how the source computed it and what it states.
3. The problem's float64 form must be the rounding of these values (checked when the problem is
   built).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from decimal import Decimal, localcontext
from fractions import Fraction
from typing import Any

from harness.errors import InputError

__all__ = ["Published", "exact_decimal"]


def exact_decimal(value: Any) -> str:
    """`value` (a decimal string, int, Decimal or Fraction) as a decimal string; a float is refused
    (it is already rounded).

    Parameters
    ----------
    value : str, int, Decimal or Fraction
        The published value ("1.5", "2D-3", 7, Fraction(1, 3): 60 significant digits).

    Returns
    -------
    str: the value as a decimal string; `InputError` for a float or an unreadable string.
    """
    if isinstance(value, bool) or isinstance(value, float):
        raise InputError(f"a published value must be exact (a decimal string, an integer or a "
                         f"Fraction), got the float {value!r}")
    if isinstance(value, int):
        return str(value)
    if isinstance(value, Fraction):
        with localcontext() as ctx:
            ctx.prec = 60
            return str(Decimal(value.numerator) / Decimal(value.denominator))
    if isinstance(value, (str, Decimal)):
        text = str(value).strip().replace("D", "e").replace("d", "e")
        try:
            Decimal(text)
        except Exception:
            raise InputError(f"a published value must be a decimal number, got {value!r}") from None
        return text
    raise InputError(f"a published value must be a decimal string, an integer or a Fraction, "
                     f"got {type(value).__name__}")


def _relative_rounding(text: str) -> float:
    """|fl64(x) - x| / |x| for the decimal x, computed exactly (0 for x = 0)."""
    exact = Fraction(Decimal(text))
    if exact == 0:
        return 0.0
    return float(abs(Fraction(float(exact)) - exact) / abs(exact))


@dataclass(frozen=True)
class Published:
    """The published form of a problem (see the module docstring for the contract)."""

    source: str
    y0: tuple[str, ...]
    parameters: Mapping[str, str] = field(default_factory=dict)
    t_end: str | None = None
    values: tuple[str, ...] | None = None
    accuracy: float | None = None
    accuracy_note: str = ""

    def __post_init__(self):
        object.__setattr__(self, "y0", tuple(exact_decimal(v) for v in self.y0))
        object.__setattr__(self, "parameters",
                           {str(k): exact_decimal(v) for k, v in dict(self.parameters).items()})
        if self.t_end is not None:
            object.__setattr__(self, "t_end", exact_decimal(self.t_end))
        if self.values is not None:
            object.__setattr__(self, "values", tuple(exact_decimal(v) for v in self.values))
            if self.t_end is None or self.accuracy is None or not self.accuracy > 0:
                raise InputError("published `values` need the `t_end` they hold at and a positive "
                                 "stated `accuracy`")

    # -- the float64 form ----------------------------------------------------------------------
    @property
    def y0_float(self) -> list[float]:
        """The start values rounded to float64 (the problem's `y0`)."""
        return [float(Decimal(v)) for v in self.y0]

    @property
    def parameters_float(self) -> dict[str, float]:
        """The parameters rounded to float64 (the problem's `parameters`)."""
        return {k: float(Decimal(v)) for k, v in self.parameters.items()}

    @property
    def t_end_float(self) -> float | None:
        """The published end time rounded to float64."""
        return None if self.t_end is None else float(Decimal(self.t_end))

    @property
    def values_float(self) -> list[float] | None:
        """The published end values rounded to float64."""
        return None if self.values is None else [float(Decimal(v)) for v in self.values]

    def rounding(self) -> dict[str, float]:
        """How far the float64 form is from the published one: the largest relative rounding of
        the start values, of the constants and of the end time (0.0 where float64 holds them
        exactly).

        Returns
        -------
        dict: 'y0', 'parameters', 't_end' -> the largest relative rounding.
        """
        return {
            "y0": max((_relative_rounding(v) for v in self.y0), default=0.0),
            "parameters": max((_relative_rounding(v) for v in self.parameters.values()), default=0.0),
            "t_end": 0.0 if self.t_end is None else _relative_rounding(self.t_end),
        }

    @property
    def exact_in_float64(self) -> bool:
        """True when float64 holds every published input exactly."""
        return not any(self.rounding().values())

    def check(self, problem: str, y0: Sequence[float], parameters: Mapping[str, float],
              t_end: float) -> None:
        """Rule 1 and 3 of the contract, against the problem being built.

        Parameters
        ----------
        problem : str, the problem's name (for messages).
        y0 : sequence of float, the problem's float64 start.
        parameters : mapping, its float64 parameter values by name.
        t_end : float, its end time.
        """
        if len(self.y0) != len(y0):
            raise InputError(f"problem {problem!r}: `published.y0` needs {len(y0)} values, got "
                             f"{len(self.y0)}")
        if list(self.parameters) != list(parameters):
            raise InputError(f"problem {problem!r}: `published.parameters` must name the "
                             f"parameters {list(parameters)}, got {list(self.parameters)}")
        if self.y0_float != [float(v) for v in y0] or self.parameters_float != {
                k: float(v) for k, v in parameters.items()}:
            raise InputError(f"problem {problem!r}: `y0` and `parameters` must be the float64 "
                             "rounding of the published values")
        if self.values is not None and len(self.values) != len(y0):
            raise InputError(f"problem {problem!r}: `published.values` needs {len(y0)} values")
        if self.t_end is not None and self.t_end_float != t_end:
            raise InputError(f"problem {problem!r}: the span must end at the published t_end "
                             f"{self.t_end}")

    def describe(self) -> dict[str, Any]:
        """Plain data for `harness list problems` and the report.

        Returns
        -------
        dict: source, y0, parameters, t_end, values, accuracy and its note, float64_rounding.
        """
        return {
            "source": self.source,
            "y0": list(self.y0),
            "parameters": dict(self.parameters),
            "t_end": self.t_end,
            "values": None if self.values is None else list(self.values),
            "accuracy": self.accuracy,
            "accuracy_note": self.accuracy_note,
            "float64_rounding": self.rounding(),
        }
