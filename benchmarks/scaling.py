"""How time grows with ensemble size, step count and the number of steppers: the README's table.

    .venv/bin/python -m benchmarks.scaling            # prints Markdown tables (a few minutes)
    .venv/bin/python -m benchmarks.scaling --quick    # smaller sweeps

Every figure is the best of three wall-clock runs on Kepler (e = 0.6, h = 1e-3), steps run by
the steppers' own loops (`Stepper._advance`), with the machine's load average printed beside
the tables (timings on a shared machine move by +-30 %). The C columns are the plain C loops of
`benchmarks/c_baseline` (`-O3`) on the same states.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from ._common import c_baseline, initial_states, prepared, seconds_per_call

STEPPERS = ["velocity-verlet", "velocity-verlet@compiled", "rk4", "rk4@compiled"]
C_METHOD = {"velocity-verlet": "vv", "rk4": "rk4"}


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f}, {five:.2f}, {fifteen:.2f} on {os.cpu_count()} cores"


def _fmt(seconds: float) -> str:
    if seconds < 1e-6:
        return f"{seconds * 1e9:.1f} ns"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.1f} us"
    if seconds < 1:
        return f"{seconds * 1e3:.1f} ms"
    return f"{seconds:.2f} s"


def ensemble_table(sizes: list[int]) -> str:
    from harness.registry import get_problem, get_stepper

    problem = get_problem("kepler-elliptic")
    base = c_baseline()
    head = ["N (members)"] + [f"{s} per step" for s in STEPPERS] + ["C vv per step", "C rk4 per step"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for n in sizes:
        row = [f"{n:,}"]
        for name in STEPPERS:
            stepper = get_stepper(name)
            dyn, carry = prepared(stepper, problem, n)

            def run(k, stepper=stepper, dyn=dyn, carry=carry):
                with np.errstate(all="ignore"):
                    stepper._advance(dyn, carry, k)

            per_step, _ = seconds_per_call(run)
            row.append(f"{_fmt(per_step)} ({_fmt(per_step / n)}/member)")
        y = problem.y0.copy() if n == 1 else initial_states(problem, n)
        for method in ("vv", "rk4"):
            per_step, _ = seconds_per_call(lambda k, method=method, y=y: base.run(method, y, 1e-3, k))
            row.append(f"{_fmt(per_step)} ({_fmt(per_step / n)}/member)")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def steps_table(counts: list[int]) -> str:
    from harness.registry import get_problem, get_stepper

    problem = get_problem("kepler-elliptic")
    base = c_baseline()
    head = ["steps (one trajectory)", "velocity-verlet (NumPy)", "velocity-verlet@compiled", "C vv"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for n in counts:
        row = [f"{n:,}"]
        for name in ("velocity-verlet", "velocity-verlet@compiled"):
            stepper = get_stepper(name)
            if name == "velocity-verlet" and n > 100_000:
                row.append("(~" + _fmt(n * _numpy_step(stepper, problem)) + ", extrapolated)")
                continue
            best = np.inf
            for _ in range(3):
                start = time.perf_counter()
                stepper.integrate(problem, h=1e-3, n_steps=n)
                best = min(best, time.perf_counter() - start)
            row.append(_fmt(best))
        best = min(_timed(lambda n=n: base.run("vv", problem.y0, 1e-3, n)) for _ in range(3))
        row.append(_fmt(best))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def _numpy_step(stepper, problem) -> float:
    dyn, carry = prepared(stepper, problem, 1)
    per_step, _ = seconds_per_call(lambda k: stepper._advance(dyn, carry, k))
    return per_step


def steppers_table(counts: list[int]) -> str:
    """The gate's experiment (convergence, quick settings, no cache, one process) on the
    harmonic oscillator for the first k registered steppers."""
    from harness.registry import steppers
    from harness.runner import run_experiment

    names = steppers.names()
    lines = ["| steppers | convergence on harmonic (quick, 1 process) | per stepper |", "|---|---|---|"]
    for k in counts:
        chosen = names[: min(k, len(names))]
        start = time.perf_counter()
        run_experiment("convergence", chosen, ["harmonic"], jobs=1, cache=False, quick=True,
                       progress=False)
        elapsed = time.perf_counter() - start
        lines.append(f"| {len(chosen)} | {_fmt(elapsed)} | {_fmt(elapsed / len(chosen))} |")
        if len(chosen) == len(names):
            break
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller sweeps")
    args = parser.parse_args(argv)
    sizes = [1, 100, 10_000, 1_000_000] if args.quick else [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000]
    counts = [1_000, 100_000] if args.quick else [100, 1_000, 10_000, 100_000, 1_000_000]
    kinds = [1, 4] if args.quick else [1, 4, 16, 10_000]
    print(f"# Scaling ({_load()})\n")
    print("## Time per step against ensemble size (Kepler, h = 1e-3)\n")
    print(ensemble_table(sizes), "\n", f"\n({_load()})\n")
    print("## Time against step count, one trajectory\n")
    print(steps_table(counts), "\n", f"\n({_load()})\n")
    print("## Time against the number of steppers\n")
    print(steppers_table(kinds), "\n", f"\n({_load()})")


if __name__ == "__main__":
    main()
