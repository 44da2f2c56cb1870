"""Precision levels for references (float64, long double, real128, real192) and the exact
comparison of values computed at two levels (a double-double expansion of the higher one)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import heyoka as hy
import numpy as np

from harness.errors import InputError

# Bump when the stored format or the error formula changes: old cache files are then ignored.
REFERENCE_SCHEMA = 1

# heyoka's compact mode compiles the Taylor recurrences as loops instead of unrolled code. It is
# used for every software-emulated level (real128, real192): there it compiles 3-5x faster
# (pendulum: 0.24 s instead of 0.73 s cold) for 10-25 % more time per step; and at any level
# for large right-hand sides (`harness.cache.compact_mode`).
SOFTWARE_LEVELS = ("real128", "real192")


@dataclass(frozen=True)
class Level:
    """One precision level: its name, heyoka floating-point type, significand bits and, for
    `real`, the precision in bits.
    """
    name: str
    fp_type: Any
    bits: int  # significand bits
    prec: int = 0  # only for hy.real

    @property
    def parts(self) -> int:
        """float64 terms needed to hold one value exactly."""
        return -(-self.bits // 53) + 1

    @property
    def eps(self) -> float:
        """Unit roundoff (machine epsilon) as a float."""
        return 2.0 ** (1 - self.bits)

    def scalar(self, x: float) -> Any:
        """`x` as a scalar of this level's type.

        Parameters
        ----------
        x : float, converted exactly.

        Returns
        -------
        float, np.longdouble, hy.real128 or hy.real: `x` in this level's number type.
        """
        x = float(x)
        if self.name == "float64":
            return x
        if self.name == "longdouble":
            return np.longdouble(x)
        if self.name == "real128":
            return hy.real128(x)
        return hy.real(x, self.prec)

    def array(self, a: np.ndarray) -> np.ndarray:
        """float64 values converted (exactly) to this level.

        Parameters
        ----------
        a : array_like, float64 values.

        Returns
        -------
        ndarray: the same values in this level's number type (a copy), same shape.
        """
        a = np.asarray(a, dtype=np.float64)
        if self.name == "float64":
            return a.copy()
        if self.name == "longdouble":
            return a.astype(np.longdouble)
        if self.name == "real128":
            return a.astype(hy.real128)
        flat = [hy.real(float(v), self.prec) for v in a.ravel()]
        return np.array(flat).reshape(a.shape)

    def exact(self, values) -> np.ndarray:
        """Decimal strings (a test set's published values) rounded once, to this level.

        Parameters
        ----------
        values : sequence, decimal numbers (strings or anything whose `str` is one).

        Returns
        -------
        ndarray: the values, each rounded once to this level.
        """
        texts = [str(v) for v in values]
        if self.name == "float64":
            return np.array([float(v) for v in texts], dtype=np.float64)
        if self.name == "longdouble":
            return np.array(texts).astype(np.longdouble)
        if self.name == "real128":
            return np.array([hy.real128(v) for v in texts])
        return np.array([hy.real(v, self.prec) for v in texts])


_ALL_LEVELS = (
    Level("float64", float, 53),
    Level("longdouble", np.longdouble, int(np.finfo(np.longdouble).nmant) + 1),
    Level("real128", getattr(hy, "real128", None), 113),
    Level("real192", getattr(hy, "real", None), 192, prec=192),
)
LEVELS_BY_NAME = {lv.name: lv for lv in _ALL_LEVELS}

#: Levels a reference can be computed at, cheapest first (each certified by the next one).
LEVELS = ("float64", "longdouble", "real128")


def _level_available(lv: Level) -> bool:
    if lv.name == "float64":
        return True
    if lv.name == "longdouble":
        return lv.bits > 53
    # heyoka defines `real128` and `real` only when it was built with them
    return lv.fp_type is not None


def level_chain() -> list[Level]:
    """Available levels of strictly increasing precision (where long double is IEEE quad, it
    replaces real128 rather than being certified by an equally precise level).

    Returns
    -------
    list of Level: the chain, least precise first.
    """
    chain: list[Level] = []
    for lv in _ALL_LEVELS:
        if _level_available(lv) and (not chain or lv.bits > chain[-1].bits):
            chain.append(lv)
    return chain


def available_levels() -> list[str]:
    """Levels that can be computed *and* certified on this installation, cheapest first.

    Returns
    -------
    list of str: level names: every level of `level_chain` but the last that is in LEVELS.
    """
    chain = level_chain()
    return [lv.name for lv in chain[:-1] if lv.name in LEVELS]


def certifier_of(level: str) -> str:
    """The level that certifies a reference computed at `level` (the next one in the chain).

    Parameters
    ----------
    level : str, a level name of `available_levels`.

    Returns
    -------
    str: the certifying level's name; `InputError` for any other `level`.
    """
    chain = level_chain()
    names = [lv.name for lv in chain]
    if level not in names[:-1]:
        raise InputError(f"`level` must be one of {available_levels()}, got {level!r}")
    return names[names.index(level) + 1]


def _default_level() -> str:
    levels = available_levels()
    if "longdouble" in levels:
        return "longdouble"
    return levels[-1] if levels else "float64"


#: The level used when no `required_error` is given.
DEFAULT_LEVEL = _default_level()


@dataclass
class Reference:
    """The ground truth at `t` for an ensemble, with its certified error.

    `y` is shaped (nt, dim, N): the extended-precision result rounded to float64. `error` is
    shaped (nt, N): per time and member, the max over components of the difference with the
    certifying level plus the float64 rounding of the stored value.
    """

    problem: str
    t: np.ndarray
    y: np.ndarray
    error: np.ndarray
    precision: str
    certified_by: str
    wall_s: float
    cached: bool = False
    compute_s: float = 0.0
    cost: dict = field(default_factory=dict)
    #: 'float64' (the problem's float64 form integrated), 'published' (its exact published
    #: constants and start integrated) or 'published values' (the test set's own end values,
    #: served where no certified path applies; `error` is then their stated accuracy)
    form: str = "float64"

    @property
    def max_error(self) -> float:
        """The largest certified error bound over every time and member (0.0 when empty)."""
        return float(np.max(self.error)) if self.error.size else 0.0


# -- exact comparison of levels ---------------------------------------------------------------------
def _expansion(values: np.ndarray, level: Level) -> list[np.ndarray]:
    """`values` as a sum of float64 arrays, largest first (exact; the first is the rounding)."""
    if level.name == "float64":
        return [np.asarray(values, dtype=np.float64)]
    parts, rest = [], values
    for _ in range(level.parts):
        p = rest.astype(np.float64)
        parts.append(p)
        rest = rest - level.array(p)
    return parts


def _lift(parts: list[np.ndarray], level: Level) -> np.ndarray:
    """Sum float64 parts exactly in a higher level (its precision exceeds the source's)."""
    acc = level.array(parts[0])
    for p in parts[1:]:
        acc = acc + level.array(p)
    return acc


def certify(values: np.ndarray, level: Level, higher: np.ndarray, cert: Level):
    """Check `values` (nt, dim, N) against the certifying level's `higher`.

    Parameters
    ----------
    values : ndarray, shape (nt, dim, N), states at `level`.
    level : Level, their level.
    higher : ndarray, shape (nt, dim, N), the same states at the certifying level.
    cert : Level, the certifying level.

    Returns
    -------
    (y, error, floor)
        The float64 rounding y of `values`, the certified error (nt, N), and a lower bound
        (nt, N) on the error any level at least as accurate as `values` can reach: the float64
        rounding distance of `higher`, less the spread between the two levels.
    """
    parts = _expansion(values, level)
    y = parts[0]
    rounding = np.zeros_like(y)
    for p in parts[1:]:
        rounding += np.abs(p)
    diff = np.abs(higher - _lift(parts, cert)).astype(np.float64)
    error = np.max(diff + rounding, axis=1)
    higher_rounding = np.zeros_like(y)
    for p in _expansion(higher, cert)[1:]:
        higher_rounding += np.abs(p)
    floor = np.max(higher_rounding - diff, axis=1)
    return y, error, floor
