"""What to integrate: a problem defined once, symbolically, and everything derived from it.

A `Problem` is written with heyoka expressions: state variables, the first-order right-hand side
(or, for Newtonian problems, the acceleration a(q, t) or a(q, v, t), from which the first-order
system is built), parameters (`hy.par[i]`), invariants, an optional exact solution, and a
literature reference. From that single definition the harness derives, on demand and cached per
process:

- `Dynamics`: NumPy-callable, ensemble-batched right-hand side, acceleration and Jacobian
  (heyoka compiled functions), with evaluation counters;
- invariant functions;
- the ground-truth integrator (`harness.ground_truth`).

Contract for a problem definition (checked in `Problem.__init__`):
1. `variables` are distinct heyoka variables; `rhs` has one expression per variable.
2. A Newtonian problem orders its state as (positions..., velocities...); its acceleration uses
   only positions, velocities, parameters and `hy.time`.
3. `y0` has one finite value per variable; `t_span` is finite with t_end > t0.
4. Parameters are `hy.par[0..P-1]` in the order of `parameters` (name -> default value).
5. `exact(t, y0, t0, pars)`, when given, maps initial states shaped (dim, N) to states at t.
6. `published`, when given, holds the exact published start values and constants; `y0` and the
   parameters are their float64 rounding (`harness.problem.published`).

Modules: `definition` (the `Problem` class), `nbody` (N-body descriptions), `dynamics` (the
compiled right-hand side), `checks` (input checks), `published` (a test set's exact values).
"""

from __future__ import annotations

from harness.problem.checks import check_count, check_ensemble_size, check_state, check_time
from harness.problem.definition import ExactSolution, Problem
from harness.problem.dynamics import Dynamics
from harness.problem.nbody import NBody, NewtonianForm
from harness.problem.published import Published

__all__ = ["Problem", "NewtonianForm", "NBody", "Dynamics", "ExactSolution", "check_state", "check_time",
           "check_ensemble_size", "check_count", "Published"]
