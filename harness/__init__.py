"""A benchmark and validation harness for time integrators.

Import packages: `harness` (framework), `problems` (catalogue), `implementations` (steppers).
"""

import os as _os

# The steppers call BLAS on arrays of every size; OpenBLAS's threads cost 20-60x on a 2-core
# machine for the ensemble sizes the harness uses (measured: 2.5 us vs 2.7 ns per member-step
# at N = 1e4), and worker processes already use the cores. A user's own setting wins; this only
# takes effect when the harness is imported before NumPy.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
# The distribution (pyproject.toml's project name) whose entry points are the built-ins.
DISTRIBUTION = "integrator-harness"
