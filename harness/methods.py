"""A method declared as one record of data, built into a stepper of its family.

`Method` is the single source of truth for a method: its coefficient object (frozen and
self-checking), its claims (order, stability figures where declared), its literature reference
and, rarely, options of its family's step loop. Every built-in method is one `Method` entry in
its family module's `METHODS` list; `Method.stepper()` asks the registry for the family's step
loop (`harness.step_loops.build_stepper`: families register their loops as entry points), and
the registry, gate, experiments, compiled loops, benchmarks and report all start from there.
Symmetry and symplecticity are never typed: they are asked of the coefficients.

A plugin may give the same record as a plain mapping (`from_record`):

A record is a mapping with the method's `name`, `claimed_order`, `reference` (and optionally
`description`, `stability` claims) and its coefficients; the keys of the coefficients decide the
family and so the step loop:

- `A`, `b` (optional `c`, `b_hat`): a Runge-Kutta method, explicit when A is strictly lower
  triangular (`implementations.runge_kutta`), implicit otherwise (`implementations.implicit_rk`);
- `sequence` of ("D", a) drifts and ("K", b) kicks: a splitting scheme (`implementations.splitting`);
- `alpha`, `beta`: a linear multistep method: for y' = f (`implementations.multistep`), or for
  x'' = f when sum j alpha_j = 0 (`implementations.second_order_multistep`).

The coefficient object checks itself when the record is built, so a plugin file that lists its
methods as records (`METHODS = [...]`) loads every good record and reports each bad one by name
(`harness.registry.load_plugin`), instead of failing to import as a whole.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from harness.coefficients import (
    ButcherTableau,
    LinearMultistep,
    SecondOrderMultistep,
    SplittingScheme,
    exact_value,
)
from harness.errors import InputError
from harness.method_checks import check_claimed_order, check_record
from harness.step_loops import build_stepper
from harness.stepper import Stepper
from harness.tolerances import COEFFICIENT_TOL

__all__ = ["Method", "from_record", "method_from_record", "RECORD_KEYS"]


@dataclass(frozen=True)
class Method:
    """One method: coefficients, claims, reference.

    Parameters
    ----------
    coefficients : a coefficient object of `harness.coefficients` (its `name` is the method's)
    claimed_order : the order the literature claims (checked against the coefficients' order)
    reference : the literature source
    description : one line on what the method is
    stability : declared stability figures ({'real_interval': ..., 'imag_interval': ...} or
        {'hw_limit': ...}), checked by the stability experiment; optional
    options : options of the family's step loop (e.g. `starter` of a multistep method,
        `loop='staggered'` for the leapfrog form of a kick-drift-kick scheme)
    claimed_embedded_order : for a Runge-Kutta pair (a tableau with `b_hat`), the order claimed
        for the embedded method; the pair then also registers `<name>@embedded`, the method
        (A, b_hat, c), so every experiment measures the embedded order too
    """

    coefficients: Any
    claimed_order: int
    reference: str
    description: str = ""
    stability: Mapping[str, float] | None = None
    options: Mapping[str, Any] = field(default_factory=dict)
    claimed_embedded_order: int | None = None

    def __post_init__(self):
        if not hasattr(self.coefficients, "fingerprint") or not hasattr(self.coefficients, "name"):
            kind = type(self.coefficients).__name__
            raise InputError(f"`coefficients` must be a coefficient object, got {kind}")

        check_claimed_order(self.claimed_order, f"method {self.name!r}: `claimed_order`")
        check_claimed_order(self.claimed_embedded_order,
                            f"method {self.name!r}: `claimed_embedded_order`", optional=True)
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))
        if self.stability is not None:
            object.__setattr__(self, "stability", MappingProxyType(dict(self.stability)))

    @property
    def name(self) -> str:
        return self.coefficients.name

    def stepper(self) -> Stepper:
        """The stepper running this method with its family's step loop.

        Returns
        -------
        Stepper: built by `harness.step_loops.build_stepper`.
        """
        return build_stepper(self)

    def steppers(self) -> list[Stepper]:
        """This method's stepper and, for a Runge-Kutta pair, its embedded method's.

        Returns
        -------
        list of Stepper: one, or two for a pair with b_hat (the embedded one's name ends '@embedded').
        """
        out = [self.stepper()]
        b_hat = getattr(self.coefficients, "b_hat", None)
        if b_hat is not None:
            c = self.coefficients
            embedded = c.embedded(f"{c.name}@embedded")  # exact where the pair is exact
            claimed = self.claimed_embedded_order or embedded.order()
            out.append(Method(embedded, claimed, self.reference,
                              f"embedded method (weights b_hat) of {c.name}").stepper())
        return out

_COMMON = {"name", "claimed_order", "reference", "description", "stability",
           "claimed_embedded_order"}
RECORD_KEYS = {
    "runge-kutta": {"A", "b", "c", "b_hat"},
    "splitting": {"sequence"},
    "multistep": {"alpha", "beta", "starter"},
}


def _family(record: Mapping[str, Any]) -> str:
    keys = set(record) - _COMMON
    for family, allowed in RECORD_KEYS.items():
        if keys and keys <= allowed and keys & allowed:
            return family
    raise InputError(
        f"method record {record.get('name')!r}: its coefficient keys {sorted(keys)} match no family "
        f"(one of {', '.join(f'{k}: {sorted(v)}' for k, v in RECORD_KEYS.items())})"
    )


def from_record(record: Mapping[str, Any]) -> Stepper:
    """The stepper a method record declares (`method_from_record(record).stepper()`).

    Parameters
    ----------
    record : mapping, a method record.

    Returns
    -------
    Stepper: raises as `method_from_record` does.
    """
    return method_from_record(record).stepper()


def _multistep(name: str, alpha, beta):
    """A first-order (`LinearMultistep`) or second-order (`SecondOrderMultistep`) table, told
    apart by the coefficients: consistency for y' = f needs sum j alpha_j = sum beta_j != 0,
    for x'' = f it needs sum j alpha_j = 0 and sum beta_j = sum j^2 alpha_j / 2 (HNW I, III.2
    and III.10)."""
    try:
        exact = [exact_value(a) for a in alpha]
        moment = (sum(j * a for j, a in enumerate(exact)) if all(e is not None for e in exact)
                  else sum(j * float(a) for j, a in enumerate(alpha)))
        size = sum(j * abs(float(a)) for j, a in enumerate(alpha))
    except (TypeError, ValueError):
        return LinearMultistep(name, alpha, beta)  # reports the bad coefficient

    if abs(float(moment)) <= COEFFICIENT_TOL * max(1.0, size) and any(b != 0 for b in beta):
        return SecondOrderMultistep(name, alpha, beta)
    return LinearMultistep(name, alpha, beta)


def method_from_record(record: Mapping[str, Any]) -> Method:
    """The `Method` a plain mapping declares (see the module docstring).

    Raises `InputError` (or `CoefficientError`) naming the record and the rule it breaks.

    Parameters
    ----------
    record : mapping, with 'name', 'claimed_order', 'reference' and the family's coefficients.

    Returns
    -------
    Method: the coefficient object with its claims.
    """
    name = check_record(record)  # types, sizes and numbers first (`harness.method_checks`)
    for key in ("claimed_order", "reference"):
        if key not in record:
            raise InputError(f"method record {name!r}: `{key}` is required")
    family = _family(record)
    try:
        if family == "runge-kutta":
            coeffs = ButcherTableau(name, record["A"], record["b"], record.get("c"),
                                    b_hat=record.get("b_hat"))
        elif family == "splitting":
            coeffs = SplittingScheme(name, record["sequence"])
        else:
            coeffs = _multistep(name, record["alpha"], record["beta"])
    except KeyError as exc:
        raise InputError(
            f"method record {name!r}: `{exc.args[0]}` is required for a {family} method"
        ) from None
    options = {"starter": record["starter"]} if "starter" in record else {}
    return Method(coeffs, record["claimed_order"], record["reference"], record.get("description", ""),
                  record.get("stability"), options, record.get("claimed_embedded_order"))
