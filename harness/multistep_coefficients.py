"""The multistep families of the coefficient objects (`harness.coefficients` re-exports them).

- `LinearMultistep`: sum_j alpha_j y_{n+j} = h sum_j beta_j f_{n+j} (Adams, BDF).
  Hairer, Norsett & Wanner I, III.2.
- `SecondOrderMultistep`: sum_j alpha_j x_{n+j} = h^2 sum_j beta_j a_{n+j} (Stormer's two-step
  form of Verlet). Hairer, Norsett & Wanner I, III.10.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from harness.coefficient_input import Number, as_float_array, close_to_rounding, exact_rows
from harness.errors import CoefficientError
from harness.theory import lmm_order, second_order_lmm_order
from harness.tolerances import COEFFICIENT_ULPS, EPS

__all__ = ["LinearMultistep", "SecondOrderMultistep"]


def _palindromic(alpha: np.ndarray, beta: np.ndarray, *, alpha_sign: float) -> bool:
    """alpha_j = alpha_sign * alpha_{k-j} and beta_j = beta_{k-j}, to the rounding of the
    coefficients: the symmetry of a multistep method (first order: alpha_sign = -1; second
    order: +1)."""
    size = max(1.0, float(np.abs(alpha).sum() + np.abs(beta).sum()))
    tol_ = COEFFICIENT_ULPS * EPS * size
    return bool(np.max(np.abs(alpha - alpha_sign * alpha[::-1])) <= tol_
                and np.max(np.abs(beta - beta[::-1])) <= tol_)


def _multistep_arrays(name: str, alpha: Sequence[Number], beta: Sequence[Number],
                      min_length: int) -> tuple[np.ndarray, np.ndarray]:
    """alpha and beta as float arrays of one length k+1 >= `min_length`, with alpha_k = 1."""
    a = as_float_array(alpha, f"{name}.alpha", 1)
    b = as_float_array(beta, f"{name}.beta", 1)
    if a.shape != b.shape or a.size < min_length:
        raise CoefficientError(
            f"`{name}`: alpha and beta must have the same length k+1 >= {min_length}, "
            f"got {a.size} and {b.size}"
        )
    if not close_to_rounding(a[-1], 1.0):
        raise CoefficientError(f"`{name}.alpha` must end with alpha_k = 1, got {float(a[-1])!r}")
    return a, b


def _set_multistep(method: object, name: str, a: np.ndarray, b: np.ndarray) -> None:
    """Fill a frozen multistep record: its name, coefficients, step count and explicitness."""
    object.__setattr__(method, "name", name)
    object.__setattr__(method, "alpha", a)
    object.__setattr__(method, "beta", b)
    object.__setattr__(method, "steps", a.size - 1)
    object.__setattr__(method, "explicit", b[-1] == 0.0)


@dataclass(frozen=True, eq=False)
class _MultistepFacts:
    """The record both multistep classes share (name, alpha, beta, with the derived `steps` and
    `explicit` filled by `_set_multistep`) and their common facts: the linear order is the order
    (the error constants do not depend on the problem), and the method is symmetric when its
    coefficients are palindromic, alpha_j = ALPHA_SIGN alpha_{k-j} and beta_j = beta_{k-j}
    (first-order methods: -1, HLW XV.1; second-order methods: +1, HNW I, III.10)."""

    name: str
    alpha: np.ndarray
    beta: np.ndarray
    steps: int = field(init=False)
    explicit: bool = field(init=False)

    ALPHA_SIGN = -1.0

    def linear_order(self) -> int:
        """The same as `order`: the error constants do not depend on the problem."""
        return self.order()

    @property
    def symmetric(self) -> bool:
        """Palindromic coefficients, to their rounding (see the class docstring)."""
        return _palindromic(self.alpha, self.beta, alpha_sign=self.ALPHA_SIGN)


@dataclass(frozen=True, eq=False)
class LinearMultistep(_MultistepFacts):
    """A k-step method sum_{j=0}^{k} alpha_j y_{n+j} = h sum_{j=0}^{k} beta_j f_{n+j}.

    Coefficients are ordered from the oldest value (j = 0) to the newest (j = k), with
    alpha_k normalised to 1. Checks on creation: equal lengths, alpha_k = 1, consistency
    (sum alpha = 0 and sum j alpha_j = sum beta_j). Derived: `steps` (k), `explicit` (beta_k = 0).
    """

    family: ClassVar[str] = "multistep"  # what `harness.theory` reads a coefficient object as

    def __init__(self, name: str, alpha: Sequence[Number], beta: Sequence[Number]):
        a, b = _multistep_arrays(name, alpha, beta, 2)
        j = np.arange(a.size)
        size = float(np.abs(a).sum() * a.size + np.abs(b).sum())
        if not close_to_rounding(a.sum(), 0.0, size, a.size):
            raise CoefficientError(f"`{name}`: sum of alpha must be 0 (consistency), got {float(a.sum())!r}")
        if not close_to_rounding(float(j @ a), float(b.sum()), size, 2 * a.size):
            raise CoefficientError(
                f"`{name}`: sum j*alpha_j must equal sum beta_j (consistency), got "
                f"{float(j @ a)!r} and {float(b.sum())!r}"
            )
        _set_multistep(self, name, a, b)

    def fingerprint(self) -> str:
        """alpha and beta, exactly, as text (what a cell key records of the method).

        Returns
        -------
        str: ``lmm:`` and the hex bytes of alpha and beta.
        """
        return f"lmm:{self.alpha.tobytes().hex()}:{self.beta.tobytes().hex()}"

    symplectic = False  # no linear multistep method is symplectic (HLW XV.4, Tang 1993)

    def order(self) -> int:
        """Order from the error constants (`harness.theory.lmm_order`).

        Returns
        -------
        int: the largest p with C_0 = ... = C_p = 0.
        """
        return lmm_order(self)



@dataclass(frozen=True, eq=False)
class SecondOrderMultistep(_MultistepFacts):
    """A k-step method for x'' = a: sum_j alpha_j x_{n+j} = h^2 sum_j beta_j a_{n+j}.

    Checks on creation: alpha_k = 1, consistency of order >= 1 for second-order equations
    (sum alpha = 0, sum j alpha_j = 0, sum j^2 alpha_j / 2 = sum beta_j).
    Stormer's rule (the two-step Verlet form) is alpha = (1, -2, 1), beta = (0, 1, 0).
    """

    family: ClassVar[str] = "second-order multistep"  # what `harness.theory` reads a coefficient object as

    def __init__(self, name: str, alpha: Sequence[Number], beta: Sequence[Number]):
        a, b = _multistep_arrays(name, alpha, beta, 3)
        j = np.arange(a.size, dtype=float)
        checks = [
            ("sum alpha_j = 0", a.sum(), 0.0),
            ("sum j alpha_j = 0", j @ a, 0.0),
            ("sum j^2 alpha_j / 2 = sum beta_j", (j * j) @ a / 2.0, b.sum()),
        ]
        size = float(np.abs(a).sum() * a.size**2 + np.abs(b).sum())
        for rule, lhs, rhs in checks:
            if not close_to_rounding(float(lhs), float(rhs), size, 2 * a.size):
                raise CoefficientError(
                    f"`{name}`: consistency needs {rule}, got {float(lhs)!r} vs {float(rhs)!r}"
                )
        _set_multistep(self, name, a, b)
        exact_a, exact_b = exact_rows(alpha, 1), exact_rows(beta, 1)
        object.__setattr__(self, "exact", (exact_a, exact_b) if exact_a and exact_b else None)

    #: (alpha, beta) as Fractions when given exactly (extended-precision runs need them), else None
    exact: tuple | None = field(init=False, repr=False)

    def fingerprint(self) -> str:
        """alpha and beta, exactly, as text (what a cell key records of the method), and the exact
        form or that there is none (an extended-precision run differs between the two).

        Returns
        -------
        str
            ``lmm2:``, the hex bytes of alpha and beta, and ``:float64`` or
            ``:exact:<sha256 of the exact form>``.
        """
        exact = ("float64" if self.exact is None
                 else "exact:" + hashlib.sha256(repr(self.exact).encode()).hexdigest())
        return f"lmm2:{self.alpha.tobytes().hex()}:{self.beta.tobytes().hex()}:{exact}"

    ALPHA_SIGN = 1.0
    # A multistep recurrence is not a map of phase space: symplecticity is a property of the
    # one-step method it may be equivalent to, which the coefficients alone do not decide.
    symplectic = None

    def order(self) -> int:
        """Order from the error constants (`harness.theory.second_order_lmm_order`).

        Returns
        -------
        int: the order p of the method for x'' = a (error constants C_0 ... C_{p+1} zero).
        """
        return second_order_lmm_order(self)

