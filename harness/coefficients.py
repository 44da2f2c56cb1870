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
- `LinearMultistep`: sum_j alpha_j y_{n+j} = h sum_j beta_j f_{n+j} (Adams, BDF).
  Hairer, Norsett & Wanner I, III.2.
- `SecondOrderMultistep`: sum_j alpha_j x_{n+j} = h^2 sum_j beta_j a_{n+j} (Stormer's two-step
  form of Verlet). Hairer, Norsett & Wanner I, III.10.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from harness.coefficient_input import as_float_array, exact_rows, exact_value, published_precision
from harness.errors import CoefficientError
from harness.tolerances import COEFFICIENT_TOL, COEFFICIENT_ULPS, EPS

__all__ = [
    "ButcherTableau",
    "SplittingScheme",
    "LinearMultistep",
    "SecondOrderMultistep",
    "as_float_array",
    "exact_value",
]

Number = float | int | Fraction


def _close(a: float, b: float, size: float = 1.0, terms: int = 1) -> bool:
    """a == b up to the rounding of the coefficients that produced them: `size` is the sum of
    the magnitudes of the `terms` numbers summed (a tableau whose weights sum |b| to 2842 rounds
    its sum to ~1e-13, and that is no defect)."""
    scale = max(1.0, abs(a), abs(b), float(size))
    return abs(a - b) <= max(COEFFICIENT_TOL, COEFFICIENT_ULPS * EPS * (terms + 1) * scale)


@dataclass(frozen=True, eq=False)
class ButcherTableau:
    """A Runge-Kutta method: stage matrix `A`, weights `b`, nodes `c`.

    Checks on creation: `A` square with as many rows as `b` and `c`; row sums of `A` equal `c`
    (the stages are consistent in time); weights sum to one (the method is consistent); with
    coefficients cut to `published_precision`, up to their printing: that miss is stated
    (`consistency_defect`, `defect_note`) and the order conditions allow for it.
    Derived: `stages`, `explicit` (A strictly lower triangular), `diagonally_implicit`.
    """

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
        precision = published_precision(A_arr, b_arr, *[as_float_array(v, f"{name}.{k}", 1) for k, v in
                                                         (("c", c), ("b_hat", b_hat)) if v is not None])
        defect = 0.0

        def near(total: float, want: float, size: float, terms: int) -> bool:  # rounding, or printing
            nonlocal defect
            if _close(total, want, size, terms):
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

        Raises `CoefficientError` when the tableau has no `b_hat`."""
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
        """R(z) = 1 + z b^T (I - zA)^{-1} e, evaluated for an array of complex z."""
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
        rerun, the coefficients' error floor), so they must not share a cached result."""
        if self.exact is None:
            exact = "float64"
        else:
            exact = "exact:" + hashlib.sha256(repr((self.exact, self.exact_b_hat)).encode()).hexdigest()
        return f"{self.float_fingerprint()}:{exact}"

    def float_fingerprint(self) -> str:
        """The float64 arrays alone: equal for the same method however precisely it was given
        (what a claim about a method matches on)."""
        embedded = "" if self.b_hat is None else ":" + self.b_hat.tobytes().hex()
        return f"rk:{self.A.tobytes().hex()}:{self.b.tobytes().hex()}:{self.c.tobytes().hex()}{embedded}"

    # -- what the coefficients say about the method (asked like a NodePy method object) -----
    def order(self) -> int:
        """Order from Butcher's rooted-tree conditions (`harness.theory.rk_order`)."""
        from harness.theory import rk_order

        return rk_order(self)

    def embedded_order(self) -> int | None:
        """Order of the embedded method (A, b_hat, c), or None without `b_hat`."""
        if self.b_hat is None:
            return None
        from harness.theory import rk_order

        return rk_order(self.embedded(f"{self.name}-embedded"))

    def linear_order(self) -> int:
        """Order on linear constant-coefficient problems: of R(z) against e^z."""
        from harness.theory import rk_linear_order

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
        if not _close(drift, 1.0, drift_size, n_terms):
            raise CoefficientError(f"`{name}`: drift coefficients must sum to 1, sum to {drift!r}")
        if not _close(kick, 1.0, kick_size, n_terms):
            raise CoefficientError(f"`{name}`: kick coefficients must sum to 1, sum to {kick!r}")
        n_kicks = sum(1 for k, _ in seq if k == "K")
        fsal = len(seq) > 1 and seq[0][0] == "K" and seq[-1][0] == "K"
        symmetric = all(
            seq[i][0] == seq[-1 - i][0] and _close(seq[i][1], seq[-1 - i][1]) for i in range(len(seq))
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
        cell key records of the method: only an exact record is rerun in real128)."""
        exact = "float64" if self.exact is None else "exact:" + hashlib.sha256(
            repr(self.exact).encode()).hexdigest()
        return f"{self.float_fingerprint()}:{exact}"

    def float_fingerprint(self) -> str:
        """The float64 sequence alone: equal for the same method however precisely it was given."""
        return "split:" + ";".join(f"{k}{v!r}" for k, v in self.sequence)

    # -- what the coefficients say about the method --------------------------------------------
    symplectic = True  # every drift and every kick is a symplectic map (HLW VI.3)

    def order(self) -> int:
        """Order from the exact local-error series (`harness.theory.splitting_order`)."""
        from harness.theory import splitting_order

        return splitting_order(self)

    def linear_order(self) -> int:
        """Order on linear problems q'' = -K q: of the one-step propagator against the exact
        rotation (`harness.theory.splitting_linear_order`)."""
        from harness.theory import splitting_linear_order

        return splitting_linear_order(self)

    @classmethod
    def compose(cls, name: str, base: SplittingScheme, weights: Sequence[Number]) -> SplittingScheme:
        """The composition base(w_1 h) o ... o base(w_m h) (Yoshida's construction)."""
        seq: list[tuple[str, Number]] = []
        exact_weights = [exact_value(w) for w in weights]
        if base.exact is not None and all(w is not None for w in exact_weights):
            for w in exact_weights:  # exact products: the record keeps its exact form
                seq.extend((k, w * v) for k, v in base.exact)
            return cls(name, seq)
        for w in weights:
            seq.extend((k, float(w) * v) for k, v in base.sequence)
        return cls(name, seq)


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
    if not _close(a[-1], 1.0):
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

    def __init__(self, name: str, alpha: Sequence[Number], beta: Sequence[Number]):
        a, b = _multistep_arrays(name, alpha, beta, 2)
        j = np.arange(a.size)
        size = float(np.abs(a).sum() * a.size + np.abs(b).sum())
        if not _close(a.sum(), 0.0, size, a.size):
            raise CoefficientError(f"`{name}`: sum of alpha must be 0 (consistency), got {float(a.sum())!r}")
        if not _close(float(j @ a), float(b.sum()), size, 2 * a.size):
            raise CoefficientError(
                f"`{name}`: sum j*alpha_j must equal sum beta_j (consistency), got "
                f"{float(j @ a)!r} and {float(b.sum())!r}"
            )
        _set_multistep(self, name, a, b)

    def fingerprint(self) -> str:
        """alpha and beta, exactly, as text (what a cell key records of the method)."""
        return f"lmm:{self.alpha.tobytes().hex()}:{self.beta.tobytes().hex()}"

    symplectic = False  # no linear multistep method is symplectic (HLW XV.4, Tang 1993)

    def order(self) -> int:
        """Order from the error constants (`harness.theory.lmm_order`)."""
        from harness.theory import lmm_order

        return lmm_order(self)



@dataclass(frozen=True, eq=False)
class SecondOrderMultistep(_MultistepFacts):
    """A k-step method for x'' = a: sum_j alpha_j x_{n+j} = h^2 sum_j beta_j a_{n+j}.

    Checks on creation: alpha_k = 1, consistency of order >= 1 for second-order equations
    (sum alpha = 0, sum j alpha_j = 0, sum j^2 alpha_j / 2 = sum beta_j).
    Stormer's rule (the two-step Verlet form) is alpha = (1, -2, 1), beta = (0, 1, 0).
    """

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
            if not _close(float(lhs), float(rhs), size, 2 * a.size):
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
        form or that there is none (an extended-precision run differs between the two)."""
        exact = ("float64" if self.exact is None
                 else "exact:" + hashlib.sha256(repr(self.exact).encode()).hexdigest())
        return f"lmm2:{self.alpha.tobytes().hex()}:{self.beta.tobytes().hex()}:{exact}"

    ALPHA_SIGN = 1.0
    # A multistep recurrence is not a map of phase space: symplecticity is a property of the
    # one-step method it may be equivalent to, which the coefficients alone do not decide.
    symplectic = None

    def order(self) -> int:
        """Order from the error constants (`harness.theory.second_order_lmm_order`)."""
        from harness.theory import second_order_lmm_order

        return second_order_lmm_order(self)

