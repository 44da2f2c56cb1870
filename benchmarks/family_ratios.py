"""The compiled implementation against the C loops: per family, one trajectory; and the ensemble
step at N = 10^5 (velocity Verlet and RK4, the C ensemble loops).

    .venv/bin/python -m benchmarks.family_ratios
    HARNESS_BENCH_CLOCK=cpu .venv/bin/python -m benchmarks.family_ratios   # CPU time, loaded machine

Prints a Markdown table (best of three calibrated runs per figure, steps run by the steppers'
own `_advance`) with the machine's load average before and after: timings on a shared machine
move by +-30 % and more. The asv suite tracks the same ratios (`bench_targets.FamilyTargets`,
`bench_targets.CompiledTargets`).
"""

from __future__ import annotations

import os

from ._common import (
    FAMILY_C_LOOPS,
    c_family_seconds_per_step,
    c_seconds_per_step,
    stepper_seconds_per_step,
)


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f}, {five:.2f}, {fifteen:.2f} on {os.cpu_count()} cores"


def family_table() -> str:
    from harness.registry import get_problem, get_stepper

    problem = get_problem("kepler-elliptic")
    lines = [
        "| family | method | compiled per step | C per step | ratio |",
        "|---|---|---|---|---|",
    ]
    for family, (method, c_method) in FAMILY_C_LOOPS.items():
        stepper = get_stepper(method + "@compiled")
        compiled = stepper_seconds_per_step(stepper, problem, 1)
        c = c_family_seconds_per_step(c_method)
        lines.append(
            f"| {family} | {method} | {compiled * 1e9:.0f} ns | {c * 1e9:.0f} ns | {compiled / c:.2f} |"
        )
    return "\n".join(lines)


def ensemble_table(size: int = 100_000) -> str:
    from harness.registry import get_problem, get_stepper

    problem = get_problem("kepler-elliptic")
    lines = [
        "| method | N | compiled per member-step | C per member-step | ratio |",
        "|---|---|---|---|---|",
    ]
    for method, c_method in (("velocity-verlet", "vv"), ("rk4", "rk4")):
        compiled = stepper_seconds_per_step(get_stepper(method + "@compiled"), problem, size)
        c = c_seconds_per_step(c_method, size)
        lines.append(
            f"| {method} | {size:,} | {compiled * 1e9:.1f} ns | {c * 1e9:.1f} ns | {compiled / c:.2f} |"
        )
    return "\n".join(lines)


def main() -> None:
    print(_load(), "| clock:", os.environ.get("HARNESS_BENCH_CLOCK", "wall"))
    print(family_table())
    print()
    print(ensemble_table())
    print(_load())


if __name__ == "__main__":
    main()
