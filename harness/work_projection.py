"""How much work a bounded run still needs, projected from the rate of its recent work.

A run that cannot finish within its budget (a reference whose solution blows up, an adaptive
solver asked for an absurd span) should stop as soon as that is clear, not after the budget is
spent. Its progress is recorded at checkpoints (work done, position reached); the rest of the
way is projected at the rate of the recent work, from the latest checkpoint with at most half
the work done so far: at least half the work, so a short burst of small steps does not decide
it, and the recent half, so a run that keeps slowing down (time no longer advancing) is seen
within a few checkpoints instead of when the average finally catches up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["projected_work"]


def projected_work(checkpoints: Sequence[tuple[float, float]], work: float, position: float,
                   end: float) -> float:
    """The total work to reach `end`: `work` done so far (at `position`) plus the rest at the
    rate since the latest of `checkpoints` ((work, position) pairs, the first at zero work) with
    at most half of `work`; inf when the position has not advanced since then. Positions may
    run either way (towards an `end` below the start too).

    Parameters
    ----------
    checkpoints : sequence of (work, position); work : float, the work done; position : float,
    where it is now; end : float, where it goes.

    Returns
    -------
    float: the projected total work, or inf.
    """
    since_work, since_position = max((c for c in checkpoints if c[0] <= work / 2),
                                     key=lambda c: c[0])
    covered = abs(position - since_position)
    if not covered > 0:
        return math.inf
    return work + (work - since_work) * max(0.0, abs(end - position)) / covered
