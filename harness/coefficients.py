"""Methods as data: frozen coefficient objects that check themselves when built.

Every in-house stepper is one of these objects plus the step loop of its family
(`implementations/`). The objects know nothing about problems or arrays of states; they hold
coefficients, validate them, and expose derived facts (stage count, explicitness, symmetry).

Families
--------
- `ButcherTableau`: Runge-Kutta methods, y' = f(t, y). Hairer, Norsett & Wanner, *Solving
  Ordinary Differential Equations I*, II.1.
- `SplittingScheme`: drift/kick compositions for q'' = a(q, t) (Verlet family, Forest-Ruth,
  Yoshida, PEFRL). Hairer, Lubich & Wanner, *Geometric Numerical Integration*, II.5 and V.3.
- `LinearMultistep` (in `harness.multistep_coefficients`, re-exported here):
  sum_j alpha_j y_{n+j} = h sum_j beta_j f_{n+j} (Adams, BDF). Hairer, Norsett & Wanner I, III.2.
- `SecondOrderMultistep` (there too): sum_j alpha_j x_{n+j} = h^2 sum_j beta_j a_{n+j}
  (Stormer's two-step form of Verlet). Hairer, Norsett & Wanner I, III.10.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import ClassVar

import numpy as np

from harness.coefficient_input import (
    Number,
    as_float_array,
    close_to_rounding,
    exact_rows,
    exact_value,
    published_precision,
)
from harness.errors import CoefficientError
from harness.multistep_coefficients import LinearMultistep, SecondOrderMultistep
from harness.theory import rk_linear_order, rk_order, splitting_linear_order, splitting_order
from harness.tolerances import COEFFICIENT_ULPS, EPS

__all__ = [
    "ButcherTableau",
    "SplittingScheme",
    "LinearMultistep",
    "SecondOrderMultistep",
    "as_float_array",
    "exact_value",
]

@dataclass(frozen=True, eq=False)
class ButcherTableau:
    """A Runge-Kutta method: stage matrix `A`, weights `b`, nodes `c`.

    Checks on creation: `A` square with as many rows as `b` and `c`; row sums of `A` equal `c`
    (the stages are consistent in time); weights sum to one (the method is consistent); with
    coefficients cut to `published_precision`, up to their printing: that miss is stated
    (`consistency_defect`, `defect_note`) and the order conditions allow for it.
    Derived: `stages`, `explicit` (A strictly lower triangular), `diagonally_implicit`.
    """

    family: ClassVar[str] = "runge-kutta"  # what `harness.theory` reads a coefficient object as

    name: str
    A: np.ndarray
    b: np.ndarray
    c: np.ndarray
    b_hat: np.ndarray | None = None
    stages: int = field(init=False)
    explicit: bool = field(init=False)
    exact: tuple | None = field(init=False, repr=False)  # (A, b, c) as Fractions, when given exactly
    exact_b_hat: tuple | None = field(init=False, repr=False)  # b_hat as Fractions, when given exactly
    consistency_defect: float = field(init=False, default=0.0)
    published_precision: float = field(init=False, default=0.0)

    def __init__(self, name: str, A: Sequence, b: Sequence, c: Sequence | None = None,
                 b_hat: Sequence | None = None):
        A_arr = as_float_array(A, f"{name}.A", 2)
        b_arr = as_float_array(b, f"{name}.b", 1)
        s = b_arr.shape[0]
        if A_arr.shape != (s, s):
            raise CoefficientError(
                f"`{name}.A` must be {s}x{s} to match {s} weights in `b`, got {A_arr.shape}"
            )
        row_sums = A_arr.sum(axis=1)
        for key, v in (("c", c), ("b_hat", b_hat)):
            if v is not None:
                as_float_array(v, f"{name}.{key}", 1)  # a bad c or b_hat is named first
        # the printing is read from the values as typed (Fractions and integers are exact)
        precision = published_precision(A, b, *(v for v in (c, b_hat) if v is not None))
        defect = 0.0

        def near(total: float, want: float, size: float, terms: int) -> bool:  # rounding, or printing
            nonlocal defect
            if close_to_rounding(total, want, size, terms):
                return True
            defect = max(defect, abs(total - want))  # refused (raises) unless within the printing
            return abs(total - want) <= (terms + 1) * precision

        if c is None:
            c_arr = row_sums.copy()
            c_arr.setflags(write=False)
        else:
            c_arr = as_float_array(c, f"{name}.c", 1)
            if c_arr.shape != (s,):
                raise CoefficientError(f"`{name}.c` must have {s} nodes, got {c_arr.shape[0]}")
            for i in range(s):
                if not near(row_sums[i], c_arr[i], float(np.abs(A_arr[i]).sum()), s):
                    raise CoefficientError(
                        f"`{name}`: row {i} of A sums to {float(row_sums[i])!r} but node c[{i}] is "
                        f"{float(c_arr[i])!r}; the row sums of A must equal the nodes"
                    )
        if not near(b_arr.sum(), 1.0, float(np.abs(b_arr).sum()), s):
            raise CoefficientError(f"`{name}.b` must sum to 1 (consistency), sums to {float(b_arr.sum())!r}")
        bh_arr = None
        if b_hat is not None:
            bh_arr = as_float_array(b_hat, f"{name}.b_hat", 1)
            if bh_arr.shape != (s,):
                raise CoefficientError(f"`{name}.b_hat` must have {s} weights, got {bh_arr.shape[0]}")
            if not near(bh_arr.sum(), 1.0, float(np.abs(bh_arr).sum()), s):
                raise CoefficientError(
                    f"`{name}.b_hat` must sum to 1 (consistency), sums to {float(bh_arr.sum())!r}"
                )
        object.__setattr__(self, "b_hat", bh_arr)
        object.__setattr__(self, "consistency_defect", float(defect))
        object.__setattr__(self, "published_precision", float(precision))
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "A", A_arr)
        object.__setattr__(self, "b", b_arr)
        object.__setattr__(self, "c", c_arr)
        object.__setattr__(self, "stages", s)
        object.__setattr__(self, "explicit", bool(np.all(np.triu(A_arr) == 0.0)))
        exact_A, exact_b = exact_rows(A, 2), exact_rows(b, 1)
        exact_c = tuple(sum(row, Fraction(0)) for row in exact_A) if exact_A and c is None else (
            exact_rows(c, 1) if c is not None else None)
        object.__setattr__(self, "exact", (exact_A, exact_b, exact_c)
                           if exact_A and exact_b and exact_c else None)
        object.__setattr__(self, "exact_b_hat", exact_rows(b_hat, 1)
                           if b_hat is not None and self.exact is not None else None)

    def embedded(self, name: str | None = None) -> ButcherTableau:
        """The embedded method (A, b_hat, c) as a tableau of its own, exact where this one and
        `b_hat` are exact (so extended-precision runs measure it as well).

        Parameters
        ----------
        name : str, optional, the new tableau's name; default ``"<name>@embedded"``.

        Returns
        -------
        ButcherTableau: the embedded method. Raises `CoefficientError` when the tableau has no `b_hat`.
        """
        if self.b_hat is None:
            raise CoefficientError(f"`{self.name}` has no embedded weights `b_hat`")
        name = name or f"{self.name}@embedded"
        if self.exact is not None and self.exact_b_hat is not None:
            A, _, c = self.exact
            return ButcherTableau(name, A, self.exact_b_hat, c)
        return ButcherTableau(name, self.A, self.b_hat, self.c)

    @property
    def defect_note(self) -> str:
        """The consistency defect in words ('' when there is none)."""
        return (f"published as cut decimals (to {self.published_precision:.0e}): sums miss their "
                f"nodes or 1 by up to {self.consistency_defect:.1e}") if self.consistency_defect else ""

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        """R(z) = 1 + z b^T (I - zA)^{-1} e, evaluated for an array of complex z.

        Parameters
        ----------
        z : array_like, points of the complex plane, any shape.

        Returns
        -------
        ndarray, complex, shape of `z`: R at each point.
        """
        z = np.asarray(z, dtype=complex)
        s = self.stages
        flat = z.reshape(-1)
        eye = np.eye(s)
        M = eye[None, :, :] - flat[:, None, None] * self.A[None, :, :]
        ones = np.ones((flat.size, s, 1))
        k = np.linalg.solve(M, ones)[..., 0]
        out = 1.0 + flat * (k @ self.b)
        return out.reshape(z.shape)

    def fingerprint(self) -> str:
        """A stable text form of the coefficients, for cache keys: the float64 arrays the loops
        run and the exact form (or that there is none). Two records with the same floats, one
        exact and one given only to float64, differ in what follows from them (the real128
        rerun, the coefficients' error floor), so they must not share a cached result.

        Returns
        -------
        str: `float_fingerprint` followed by ``:float64`` or ``:exact:<sha256 of the exact form>``.
        """
        if self.exact is None:
            exact = "float64"
        else:
            exact = "exact:" + hashlib.sha256(repr((self.exact, self.exact_b_hat)).encode()).hexdigest()
        return f"{self.float_fingerprint()}:{exact}"

    def float_fingerprint(self) -> str:
        """The float64 arrays alone: equal for the same method however precisely it was given
        (what a claim about a method matches on).

        Returns
        -------
        str: ``rk:`` and the hex bytes of A, b, c (and b_hat when embedded).
        """
        embedded = "" if self.b_hat is None else ":" + self.b_hat.tobytes().hex()
        return f"rk:{self.A.tobytes().hex()}:{self.b.tobytes().hex()}:{self.c.tobytes().hex()}{embedded}"

    # -- what the coefficients say about the method (asked like a NodePy method object) -----
    def order(self) -> int:
        """Order from Butcher's rooted-tree conditions (`harness.theory.rk_order`).

        Returns
        -------
        int: the largest p whose order conditions all hold, to the coefficients' rounding.
        """
        return rk_order(self)

    def embedded_order(self) -> int | None:
        """Order of the embedded method (A, b_hat, c).

        Returns
        -------
        int or None: its order from the rooted-tree conditions, or None without `b_hat`.
        """
        if self.b_hat is None:
            return None

        return rk_order(self.embedded(f"{self.name}-embedded"))

    def linear_order(self) -> int:
        """Order on linear constant-coefficient problems: of R(z) against e^z.

        Returns
        -------
        int: the largest p with R(z) - e^z = O(z^{p+1}) (`harness.theory.rk_linear_order`).
        """
        return rk_linear_order(self)

    @property
    def symplectic(self) -> bool:
        """b_i a_ij + b_j a_ji = b_i b_j for all i, j (HLW VI.4, Theorem 4.3)."""
        M = self.b[:, None] * self.A + (self.b[:, None] * self.A).T - np.outer(self.b, self.b)
        size = np.abs(self.b[:, None] * self.A).sum() + np.abs(self.b).sum() ** 2
        return bool(np.max(np.abs(M)) <= COEFFICIENT_ULPS * EPS * max(1.0, float(size)))

    @property
    def symmetric(self) -> bool:
        """a_{s+1-i, s+1-j} + a_ij = b_j and b_{s+1-i} = b_i (HLW V.2, Theorem 2.3), up to a
        permutation of stages that this check does not search."""
        P = self.A[::-1, ::-1]
        lhs = P + self.A - self.b[None, :]
        size = max(1.0, float(np.abs(self.A).sum() + np.abs(self.b).sum()))
        tol_ = COEFFICIENT_ULPS * EPS * size
        return bool(np.max(np.abs(lhs)) <= tol_ and np.max(np.abs(self.b - self.b[::-1])) <= tol_)


@dataclass(frozen=True, eq=False)
class SplittingScheme:
    """A drift/kick composition for q'' = a(q, t).

    `sequence` is a tuple of ("D", a_i) drifts (q += a_i h v) and ("K", b_i) kicks
    (v += b_i h a(q, t)). Checks on creation: only D and K, adjacent equal kinds merged, drift
    and kick coefficients each sum to one (consistency). Derived: `symmetric` (the sequence is a
    palindrome), `force_evals` per step with the first-same-as-last saving when the sequence
    begins and ends with a kick.
    """

    family: ClassVar[str] = "splitting"  # what `harness.theory` reads a coefficient object as

    name: str
    sequence: tuple[tuple[str, float], ...]
    symmetric: bool = field(init=False)
    force_evals: int = field(init=False)
    exact: tuple | None = field(init=False, repr=False)  # the merged sequence with Fractions, if exact

    def __init__(self, name: str, sequence: Sequence[tuple[str, Number]]):
        merged: list[list] = []
        exact: list[list] | None = []
        for item in sequence:
            try:
                kind, coeff = item
            except (TypeError, ValueError):
                raise CoefficientError(
                    f"`{name}.sequence` entries must be (kind, coefficient) pairs, got {item!r}"
                ) from None
            if kind not in ("D", "K"):
                raise CoefficientError(f"`{name}.sequence` kinds must be 'D' or 'K', got {kind!r}")
            value = float(coeff)
            if not np.isfinite(value):
                raise CoefficientError(f"`{name}.sequence` coefficients must be finite, got {coeff!r}")
            exact_coeff = exact_value(coeff) if exact is not None else None
            if exact_coeff is None:
                exact = None
            elif exact and exact[-1][0] == kind:
                exact[-1][1] += exact_coeff
            else:
                exact.append([kind, exact_coeff])
            if merged and merged[-1][0] == kind:
                merged[-1][1] += value
            else:
                merged.append([kind, value])
        if exact is not None:  # the float sequence is built as from floats, so it is unchanged
            exact = [e for e in exact if e[1] != 0]
        seq = tuple((k, v) for k, v in merged if v != 0.0)
        drift = sum(v for k, v in seq if k == "D")
        kick = sum(v for k, v in seq if k == "K")
        n_terms = len(seq)
        drift_size = sum(abs(v) for k, v in seq if k == "D")
        kick_size = sum(abs(v) for k, v in seq if k == "K")
        if not close_to_rounding(drift, 1.0, drift_size, n_terms):
            raise CoefficientError(f"`{name}`: drift coefficients must sum to 1, sum to {drift!r}")
        if not close_to_rounding(kick, 1.0, kick_size, n_terms):
            raise CoefficientError(f"`{name}`: kick coefficients must sum to 1, sum to {kick!r}")
        n_kicks = sum(1 for k, _ in seq if k == "K")
        fsal = len(seq) > 1 and seq[0][0] == "K" and seq[-1][0] == "K"
        symmetric = all(
            seq[i][0] == seq[-1 - i][0] and close_to_rounding(seq[i][1], seq[-1 - i][1])
            for i in range(len(seq))
        )
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "sequence", seq)
        object.__setattr__(self, "symmetric", symmetric)
        object.__setattr__(self, "force_evals", n_kicks - 1 if fsal else n_kicks)
        object.__setattr__(self, "exact", tuple((k, v) for k, v in exact) if exact is not None else None)

    @property
    def kick_coefficients(self) -> np.ndarray:
        """The kick coefficients b_i, in sequence order."""
        return np.array([v for k, v in self.sequence if k == "K"])

    @property
    def drift_coefficients(self) -> np.ndarray:
        """The drift coefficients a_i, in sequence order."""
        return np.array([v for k, v in self.sequence if k == "D"])

    def fingerprint(self) -> str:
        """The coefficients as run and their exact form (or that there is none), as text (what a
        cell key records of the method: only an exact record is rerun in real128).

        Returns
        -------
        str: `float_fingerprint` followed by ``:float64`` or ``:exact:<sha256 of the exact form>``.
        """
        exact = "float64" if self.exact is None else "exact:" + hashlib.sha256(
            repr(self.exact).encode()).hexdigest()
        return f"{self.float_fingerprint()}:{exact}"

    def float_fingerprint(self) -> str:
        """The float64 sequence alone: equal for the same method however precisely it was given.

        Returns
        -------
        str: ``split:`` and the (kind, coefficient) pairs of the merged sequence.
        """
        return "split:" + ";".join(f"{k}{v!r}" for k, v in self.sequence)

    # -- what the coefficients say about the method --------------------------------------------
    symplectic = True  # every drift and every kick is a symplectic map (HLW VI.3)

    def order(self) -> int:
        """Order from the exact local-error series (`harness.theory.splitting_order`).

        Returns
        -------
        int: the order of the composition on q'' = a(q, t).
        """
        return splitting_order(self)

    def linear_order(self) -> int:
        """Order on linear problems q'' = -K q: of the one-step propagator against the exact
        rotation (`harness.theory.splitting_linear_order`).

        Returns
        -------
        int: the order of the propagator's match with the exact rotation.
        """
        return splitting_linear_order(self)

    @classmethod
    def compose(cls, name: str, base: SplittingScheme, weights: Sequence[Number]) -> SplittingScheme:
        """The composition base(w_1 h) o ... o base(w_m h) (Yoshida's construction).

        Parameters
        ----------
        name : str, the new scheme's name.
        base : SplittingScheme, the scheme composed.
        weights : sequence of numbers, w_1, ..., w_m; the result is exact when `base` and every weight are.

        Returns
        -------
        SplittingScheme: the composed scheme (adjacent drifts or kicks merged, checked on creation).
        """
        seq: list[tuple[str, Number]] = []
        exact_weights = [exact_value(w) for w in weights]
        if base.exact is not None and all(w is not None for w in exact_weights):
            for w in exact_weights:  # exact products: the record keeps its exact form
                seq.extend((k, w * v) for k, v in base.exact)
            return cls(name, seq)
        for w in weights:
            seq.extend((k, float(w) * v) for k, v in base.sequence)
        return cls(name, seq)

