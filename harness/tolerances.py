"""Every tolerance and threshold of the harness, in one place, each with its reason."""

import numpy as np

EPS = float(np.finfo(np.float64).eps)

# Coefficient self-checks: tableaux are typed as decimals or fractions; 1e-14 allows the last
# digits of a float64 literal and no more.
COEFFICIENT_TOL = 1e-14

# Order conditions from coefficients: sums of products of up to 8 float64 factors; 1e-11 is far
# above their rounding and far below any genuine defect (the smallest condition value is 1/8!).
ORDER_CONDITION_TOL = 1e-11

# A method error counts only when it is at least this many times the reference's certified error.
REFERENCE_MARGIN = 100.0

# Ground truth: the Taylor tolerance of each precision level (its unit roundoff).
REFERENCE_TOL_FACTOR = 1.0

# Convergence sweep: start where the error first falls below this (the asymptotic law rarely
# holds at larger errors) ...
SWEEP_START_ERROR = 1e-2
# ... refine by this ratio between consecutive step sizes ...
SWEEP_RATIO = 2.0
# ... and treat a point as at the roundoff floor when its error is within this factor of what
# rounding alone produces over the same number of steps (n * eps * |y|).
ROUNDOFF_MARGIN = 100.0
# A local slope (between neighbouring points) further than this from the median plateau slope
# marks the point as pre-asymptotic.
PLATEAU_SLOPE_TOL = 0.35
# The fit needs at least this many points in the asymptotic range.
MIN_FIT_POINTS = 3
# Errors above this are a blow-up (`unstable`), as is any NaN or inf.
BLOWUP_ERROR = 1e6
# Errors at or below this many units of rounding at every step size: the method is exact.
EXACT_ULPS = 1e3

# Gate: a measured order may differ from the claim by at most this.
GATE_ORDER_TOL = 0.2

# Ensemble: members and the relative size of the perturbation of the initial state.
ENSEMBLE_SIZE = 16
ENSEMBLE_PERTURBATION = 1e-2

# Work budget per convergence sweep (steps summed over the sweep), so a slow method on a long
# span reports `insufficient-range` instead of running for hours.
SWEEP_STEP_BUDGET = 400_000

# Largest ensemble accepted (memory: a 1e7-member state of dimension 12 is ~1 GB per copy).
MAX_ENSEMBLE_SIZE = 10_000_000

# Adaptive steppers: the global error may exceed the requested tolerance by this factor (times
# the state's scale) before the tolerance counts as missed; local error control does not bound
# the global error, and a factor of 100 is what a user of such a solver usually tolerates.
TOLERANCE_FACTOR = 100.0
