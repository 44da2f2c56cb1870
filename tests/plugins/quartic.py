"""A user's problem as a plugin file: the quartic anharmonic oscillator x'' = -x^3.

H = v^2 / 2 + x^4 / 4 is conserved. Its period depends on the amplitude (for x0 = 1, v0 = 0,
T = 4 K(1/2) sqrt(2) = 7.4163), and nothing about it is registered anywhere in the harness:
the experiments derive its time scale and which of them apply from this definition alone.

Reference: E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed., Springer
2006, section I.1 (one-degree-of-freedom Hamiltonian systems and their phase portraits).
"""

import heyoka as hy

from harness.problem import NewtonianForm, Problem

_x, _v = hy.make_vars("x", "v")

PROBLEMS = [
    Problem(
        "quartic-oscillator",
        variables=[_x, _v],
        newtonian=NewtonianForm(positions=(_x,), velocities=(_v,), acceleration=(-_x * _x * _x,)),
        y0=[1.0, 0.0],
        t_span=(0.0, 40.0),
        invariants={"energy": _v * _v / 2.0 + _x * _x * _x * _x / 4.0},
        conservative=True,
        description="Quartic oscillator x'' = -x^3 from x = 1, v = 0 on [0, 40].",
        reference="Hairer, Lubich & Wanner, Geometric Numerical Integration (2006), I.1.",
    )
]
