"""Every tolerance and threshold of the harness, in one place, each with its reason."""

import numpy as np

EPS = float(np.finfo(np.float64).eps)

# Coefficient self-checks: tableaux are typed as decimals or fractions; 1e-14 allows the last
# digits of a float64 literal and no more.
COEFFICIENT_TOL = 1e-14
# ... or, for coefficients of large magnitude (extrapolation methods: sum |b| up to ~3000), this
# many units of rounding of the sum of their magnitudes, per term summed.
COEFFICIENT_ULPS = 16.0
# A coefficient whose shortest float text has this many significant digits (and at most 15) was
# typed as a cut decimal: published tableaux print 10-15 digits; exact short decimals (0.5,
# 0.1875) print fewer, a float computed from a fraction 16-17.
PUBLISHED_MIN_DIGITS = 10

# Order conditions from coefficients: sums of products of up to 8 float64 factors; 1e-11 is far
# above their rounding and far below any genuine defect (the smallest condition value is 1/8!).
ORDER_CONDITION_TOL = 1e-11
# ... relative to the condition's value 1/gamma(t) (trees of order 12 have 1/gamma down to 2e-9);
# and, for coefficients of large magnitude, this many roundings per vertex of the sum of the
# magnitudes of the products (extrapolation tableaux reach sum |b| ~ 3000).
ORDER_CONDITION_ULPS = 64.0
ORDER_CONDITION_FLOOR = 1e-13

# A method error counts only when it is at least this many times the reference's certified error.
REFERENCE_MARGIN = 100.0

# Ground truth: the Taylor tolerance of each precision level (its unit roundoff).
REFERENCE_TOL_FACTOR = 1.0
# A problem is stiff for the explicit Taylor reference when its step is held by the Jacobian's
# eigenvalues (a Taylor step of order p stays near p / (e |lambda|): measured on van der Pol,
# eps = 1e-6, 0.9x and 1.0x that in long double and real128) and the rest of the span then needs
# more than this many steps at the certifying level (~2.5 s of real128 steps on this machine
# type, more than every non-stiff catalogue reference together).
REFERENCE_STIFF_STEPS = 3e4
# ... and a step counts as held by the eigenvalue when h e |lambda| / p exceeds this share of the
# stability bound (an accuracy-limited step is far shorter than p / (e |lambda|) on a stiff
# problem only while the solution itself varies that fast).
REFERENCE_STIFF_SHARE = 0.3
# The stiff reference (scipy Radau cross-checked by CVODE BDF): rtol for both, a decade above
# scipy's floor of 100 eps and inside CVODE's documented [1e-15, 1e-3]; atol_i = rtol x s_i.
STIFF_REFERENCE_RTOL = 1e-13
# ... with atol_i = rtol x s_i x this share: nearly pure relative control, as the Bari test set's
# own references for OREGO and E5 (atol 1.1e-40), whose components fall to 1e-22 and below
# (E5 at atol = rtol x s_i: both solvers agreed to 7e-22 on values of 9e-22 that were wrong by
# 1e-21).
STIFF_REFERENCE_ATOL_SHARE = 1e-8
# ... and each solver's evaluation bound per member (~1 min of Python-level evaluations).
STIFF_REFERENCE_MAX_EVALS = 2_000_000

# Convergence sweep: start where the error first falls below this, relative to the size of the
# state (the asymptotic law rarely holds at larger errors) ...
SWEEP_START_ERROR = 1e-2
# ... refine by this ratio between consecutive step sizes ...
SWEEP_RATIO = 2.0
# ... and treat a point as at the roundoff floor when its error is within this factor of what
# rounding alone produces over the same number of steps (n * eps * |y|).
ROUNDOFF_MARGIN = 100.0
# A local slope (between neighbouring points) further than this from the plateau (the median of
# the slopes next to the floor) marks the point as pre-asymptotic: 0.15 in absolute terms, or
# 3 % of the plateau for high orders, where a halving of h moves the error by 2^8 and rounding
# in the last points shows more.
PLATEAU_SLOPE_TOL = 0.15
PLATEAU_SLOPE_RTOL = 0.03
# ... and local slopes that rise or fall monotonically by more than this across the window are
# still drifting: half the gate's order tolerance, the most a fit over them may be off by.
PLATEAU_DRIFT_TOL = 0.1
# ... and the slope fitted over the window must lie within this of an integer: the global error
# expands in integer powers of h (HNW I, II.8), so a slope further from every integer is a
# mixture of terms still changing weight, not an order (the gate's own tolerance: such a slope
# could match no claim anyway, and it is reported as not measurable instead of as a wrong order).
INTEGER_ORDER_TOL = 0.2
# A slope above the coefficients' order (or their linear order, the highest any problem class
# shows) by more than this, where the floor ends the sweep, is higher-order terms still
# dominating (an optimized pair's tiny leading constant): the points are not asymptotic.
ABOVE_ORDER_TOL = 0.2
# A point whose error is within this factor of the floor the coefficients' own defects in the
# order conditions leave (harness.theory.defects; the estimate takes the fastest rate for every
# elementary differential, so it errs high) measures the record's digits, not the method.
COEFFICIENT_FLOOR_MARGIN = 10.0
# Defects in the order conditions within this many roundings (per vertex, of the size of the
# products) of the arithmetic a sweep runs in are that arithmetic's own rounding, not the record's.
DEFECT_NOISE_ULPS = 64.0
# A state whose max-norm is below this is measured against this instead (no division by 0).
SCALE_FLOOR = 1e-300
# The fit needs at least this many points in the asymptotic range: three local slopes that agree
# establish a plateau; two can agree by chance where an error term changes sign.
MIN_FIT_POINTS = 4
# Errors above this are a blow-up (`unstable`), as is any NaN or inf.
BLOWUP_ERROR = 1e6

# Gate: a measured order may differ from the claim by at most this.
GATE_ORDER_TOL = 0.2
# A problem is stiff for a method when a stable step (its real stability interval over the
# largest -Re(lambda) along the reference) needs more than this many steps over the horizon:
# a fourth-order method's error on an O(1) problem is then ~1e-12, within a few halvings of the
# float64 floor, so `unstable` above the floor is not evidence against its order.
STIFF_STEP_COUNT = 1000.0
# A problem is stiff over its horizon when its fastest decaying mode decays by e^-this over the
# horizon (-Re(lambda) x horizon): the transient it leaves is then far below any error measured,
# and an implicit method's stages see h|lambda| >> 1 at the sweep's coarse steps.
STIFF_HORIZON_DECAYS = 100.0
# A problem starts in an initial layer when, at its start, the velocity's part along those fast
# decaying modes exceeds this multiple of its part along the others: on a smooth solution of a
# stiff problem the fast part is the slow part times slow rate / fast rate (<< 1; 2e-4 on
# van-der-pol-stiff), off it the offset times the fast rate (3e6 on Bari's VDPOL).
LAYER_VELOCITY_RATIO = 1.0
# An implicit method's stage equations y = h a f(y) + ... are guaranteed solvable by iteration for
# h L |a| < 1 (HNW I, II.7, Thm 7.2), L >= the stiffness; at h x stiffness >= this no registered
# implicit method (|a| >= 0.1: backward Euler 1, BDF2 2/3, AM3 5/12, Gauss 4 ~0.25) is covered, so
# a solve that fails every step size there is not evidence against the method.
NEWTON_GUARANTEE_STEPS = 10.0

# Ensemble: members and the relative size of the perturbation of the initial state.
ENSEMBLE_SIZE = 16
ENSEMBLE_PERTURBATION = 1e-2

# Work budget per convergence sweep, in right-hand-side evaluations summed over the sweep (a
# stepper's steps = this / its evaluations per step), so a slow method on a long span reports
# `insufficient-range` instead of running for minutes. 2^19 lets Euler reach n = 2^18 steps.
SWEEP_WORK_BUDGET = 524_288
# Tolerance sweeps of adaptive steppers: the solvers are per-member black boxes whose cost grows
# like tol^(-1/p), so the sweep runs loose to tight and stops before a tolerance whose predicted
# cost (the last one's internal steps times the last growth factor) would take the sweep past
# this many internal steps per member. The tolerances not run are recorded with that reason.
TOLERANCE_SWEEP_STEPS = 2_500
# Members of a tolerance sweep: the verdict is the worst member's error against its tolerance,
# which a few members already bound; every member is a separate solve of a black-box solver.
TOLERANCE_SWEEP_ENSEMBLE = 4
# An implicit step also solves Newton systems (a batched Jacobian and LU per iteration, ~2
# iterations per step): it counts as this many of its declared evaluations.
IMPLICIT_STEP_COST = 4.0
# When the budget ends a sweep before the asymptotic range while the error is still far above the
# floor, the horizon is cut by this factor (a first-order method's error at fixed h falls about
# as fast as the horizon, and its steps needed fall with its square) and the sweep runs again,
# at most this many times.
HORIZON_SHRINK = 4.0
MAX_HORIZON_SHRINKS = 2

# Largest ensemble accepted (memory: a 1e7-member state of dimension 12 is ~1 GB per copy).
MAX_ENSEMBLE_SIZE = 10_000_000

# Adaptive steppers: the global error may exceed the requested tolerance by this factor (times
# the state's scale) before the tolerance counts as missed. Local error control bounds each
# step's error, so the global error accumulates up to (number of steps) x tol; 1e4 allows ten
# thousand steps' worth, and more means the control itself is not working.
TOLERANCE_FACTOR = 1e4
# ... and tightening the tolerance must pay: error ~ tol^e with e at least this (a 100-fold
# tighter tolerance gains at least 10-fold), fitted over the points above the reference floor.
MIN_TOLERANCE_EXPONENT = 0.5
# ... fitted only over tolerances where the error is at least this fraction of tol x |y|: a
# solver far more accurate than requested (DOP853 on y' = -y: 1e-6 of the tolerance) has
# nothing to gain from a tighter one.
PROPORTIONALITY_MIN_RATIO = 1e-2

# Newton's method for implicit stages (implicit Runge-Kutta, implicit multistep): the increment,
# componentwise scaled by 1 + |y_n|, must fall to 1e-14 (~50 ulps, just above the rounding noise
# of a well-conditioned solve), so the stage error stays far below every error a sweep measures.
NEWTON_TOL = 1e-14
# Iterations allowed before a step counts as failed: full Newton from the step's start needs 2-5;
# simplified Newton contracts by ~0.1 per iteration at large stiff steps, so ~15 to reach 1e-14.
NEWTON_MAX_ITER = 20
# ... or, rounding-aware (Hairer & Wanner II, IV.8), once the increment stops decreasing (theta >= 0.5)
# at ~1e4 roundings of the iterate, eps (1 + |x|), below every error a sweep measures: where
# an ill-conditioned solve's noise keeps it above 1e-14, while a divergent iteration still fails.
NEWTON_STALL_CONTRACTION, NEWTON_ROUNDING_ULPS = 0.5, 1e4

# Order from an exact local-error series (harness.theory): a coefficient of h^n in the local
# error counts as zero below this, relative to the exact solution's coefficient; float64
# coefficients leave ~1e-15 there, a violated order condition leaves ~1e-4 or more.
SERIES_ORDER_TOL = 1e-10

# Linear stability intervals (harness.theory.stability_boundary): |R| <= 1 + this counts as
# stable (a few roundings of a one-step evaluation; Euler's 1 + y^2/2 exceeds it at y ~ 1e-6) ...
STABILITY_AMPLIFICATION_TOL = 1e-12
# Exact intervals from polynomials (Runge-Kutta, splitting): a coefficient counts as zero when it
# is within this many roundings (per term) of the sum of the magnitudes that produced it.
STABILITY_POLY_ULPS = 64.0
# ... and a polynomial is proven non-negative from its roots only up to this degree (beyond it
# the monomial form is too ill-conditioned; the interval is then located by the scan) ...
STABILITY_POLY_MAX_DEGREE = 12
# ... while the scan itself has no search limit short of this (an explicit method's |R| grows
# without bound, so its interval always ends; an implicit one is proven unbounded or scanned).
STABILITY_SCAN_CEILING = 1e12
# ... the crossing is bracketed on a scan, linear with this step up to ...
STABILITY_SCAN_STEP = 1e-2
STABILITY_SCAN_LINEAR_END = 10.0
# ... then geometric with this ratio up to the search limit (beyond it: "unbounded") ...
STABILITY_SCAN_RATIO = 1.02
STABILITY_SEARCH_LIMIT = 1e3
# ... and refined by Brent's method to this absolute accuracy (the figures are quoted to 1e-8).
STABILITY_XTOL = 1e-10

# scipy's solve_ivp raises any rtol below 100 machine epsilons to that value (with a warning);
# the external peers apply the same floor themselves and record the rtol actually used.
SCIPY_MIN_RTOL = 100.0 * EPS
# h*omega limits of Newtonian steppers are searched up to this (the catalogue's are below 4).
STABILITY_HW_SEARCH_LIMIT = 100.0
# Exact bands (the trace polynomial and Sturm chains over the rationals) cost steeply more with the
# trace's degree times its coefficients' bit length (kicks x summed bits of the operations):
# yoshida8 (16 x 4140 = 7e4) takes 2 s; a 251-operation composition of Verlet (126 x 112115)
# took 83 s for the trace alone and did not finish isolating in 10 minutes. Above this product
# the first instability comes from a sampled scan instead, and the bands say so.
EXACT_BANDS_MAX_WORK = 1.5e5
# Stability probe against the coefficients' formula: largest relative difference of recurrence
# coefficients (R(z), c_j, propagator entries) allowed; a step is a few dozen roundings of
# numbers of the coefficients' size, so this is multiplied by that size (sum of |coefficients|,
# or the magnitude of a splitting's product of factors at that h omega).
STABILITY_AGREEMENT_TOL = 1e-12
# Interval figures from the probe and from the formula must agree to this (each is root-found
# to STABILITY_XTOL; the amplification tolerance shifts a transversal crossing by ~1e-12).
STABILITY_INTERVAL_AGREEMENT = 1e-7
# A declared stability figure is quoted to ~5 significant digits (rk3: 2.5127): relative
# difference allowed between the claim and the measured figure.
STABILITY_CLAIM_RTOL = 1e-4

# Energy drift (harness.experiments.energy). An energy off by 10 % belongs to a different orbit:
# the motion is destroyed and the run counts as `unstable` (past that point the envelope's shape
# describes the wreck, e.g. an escaping or collapsed Kepler orbit, not a drift) ...
ENERGY_BLOWUP_ERROR = 0.1
# ... unless the error was that large within the first natural period already and its running
# maximum at the end is within this factor of that level: the bounded oscillation of a modified
# energy (H - H~ = O(h^p) uniformly in time, HLW IX.8) keeps its size; with every phase seen in
# the first period its later maxima equal it (measured: velocity Verlet on the oscillator at
# h w = 0.5-1.99, ratio 1.0), while drift to a different orbit multiplies it ...
ENERGY_BOUNDED_RISE = 2.0
# ... and only if within the fit window it swings back below this fraction of its maximum there:
# the error of a conserved modified energy returns near 0 where the orbit revisits its start's
# phase (velocity Verlet on the oscillator: down to ~0), a wrecked orbit's error stays put
# (Euler's escape on Kepler: min/max ~ 1) ...
ENERGY_RETURN_FRACTION = 0.5
# ... errors are floored here before taking logarithms (an exactly conserved quantity has no
# envelope to fit; 1e-20 is far below any float64 rounding of an O(1) quantity) ...
ENERGY_ERROR_FLOOR = 1e-20
# ... the envelope's growth exponent (log-log slope of the running maximum) separates the
# classes halfway between the ideal exponents 0 (bounded), 1/2 (random walk) and 1 (linear);
# above 1.5 the growth is faster than any drift a consistent method produces (blow-up) ...
DRIFT_SQRT_EXPONENT = 0.25
DRIFT_LINEAR_EXPONENT = 0.75
DRIFT_UNSTABLE_EXPONENT = 1.5
# ... the fit window starts no earlier than this many natural periods, so the envelope has
# seen every phase of the motion at least once ...
FIT_MIN_PERIODS = 2.0
# ... rounding adds a few ulps to an invariant per step, as a random walk (Brouwer's law):
# growth up to ENERGY_ROUNDING_ULPS * sqrt(n) * eps is what rounding explains (measured: the
# rounding-level walks of implicit midpoint and Gauss on the oscillator grow by ~0.3 sqrt(n) eps;
# the margin covers a systematic bias over 10^6 steps) ...
ENERGY_ROUNDING_ULPS = 100.0
# ... and a method that conserves a quadratic invariant exactly keeps it to within this many
# ulps per step (systematic rounding grows at most linearly in n; measured on Kepler: at most 0.25
# ulps per step over 10^4-10^5 steps, Stormer's central-difference velocity the largest).
ANGULAR_MOMENTUM_ROUNDING_ULPS = 2.0
# A central field (`harness.facts.central_field`): each body's q x a(q), at this many positions
# about the start, within this fraction of |q| |a| (evaluating a rounds it by a few ulps; a
# field that is not central, e.g. Henon-Heiles or the planets' mutual pulls, is off by >1e-3).
CENTRAL_FIELD_SAMPLES = 16
CENTRAL_FIELD_TOL = 1e-12

# Memory guard (harness.runner): a run is refused up front when its estimated peak exceeds this
# fraction of the memory available when it starts (the rest is for Python, libraries, the OS).
MEMORY_HEADROOM = 0.8

# Convergence sweep: stop refining once this many points lie in the asymptotic range; six
# points over a factor 32 in h pin an order to a few hundredths, and more only cost steps.
TARGET_FIT_POINTS = 6
# A scipy solver that evaluates f this many times in a row at one time value has a collapsed step
# size (scipy's LSODA then loops forever instead of failing); no solver needs more than a few
# tens of evaluations at one time (Newton iterations, Jacobian retries) in a healthy step.
SCIPY_STALL_CALLS = 1000

# Ground truth: a certifying run uses the tolerance max(its own unit roundoff, the certified
# level's unit roundoff x this): its step error is then 65536x below the certified level's,
# enough to measure that level's error to ~1e-4 relative, at 2-4x less real128 cost than its
# full precision would take.
CERTIFIER_TOL_FACTOR = 2.0**-16

# Roundoff experiment: the smallest step counts as rounding-limited when its error exceeds the
# truncation error predicted there (error(h_max) (h / h_max)^3 at a fixed step count) by this
# factor: an order of magnitude leaves no doubt which of the two dominates.
ROUNDOFF_TRUNCATION_FACTOR = 10.0
# Report claim "two-step Verlet is more prone to rounding than leapfrog": its roundoff floor must
# exceed the one-step form's by this factor on every problem measured (the rounding models
# predict a ratio of ~1/(h omega), thousands at the sweep's small end; 10 is far above noise).
ROUNDOFF_CLAIM_RATIO = 10.0

# Reversibility (harness.experiments.reversibility). A symmetric method's step rounds its state
# to about one ulp, and the flow carries that along; 2 ulps per step times the flow's
# sensitivity is what rounding explains (measured over the registry, 10^2-10^5 steps: at most
# 0.33 ulps per step and a tenth of this bound; non-symmetric methods miss it 10^4-fold or more) ...
REVERSIBILITY_ULPS_PER_STEP = 2.0
# ... the flow's sensitivity is measured by central differences of relative size 1e-7 on
# float64 Taylor orbits: the perturbation stays in the linear range where the flow amplifies it
# 3e4-fold (Kepler over 400 orbits: 3e-3 of the orbit's size), and the difference, 1e-7 A,
# stands ~1e9 above the orbits' own error, ~eps A.
REVERSIBILITY_FLOW_DELTA = 1e-7

# Symplecticity (harness.experiments.symplecticity). The one-step Jacobian comes from
# fourth-order central differences with steps of 2e-4 of the largest state component: truncation
# ~(delta/r)^4 stays below 1e-12 even at the Kepler pericentre (r = 0.4, where 1e-3 gave 1.5e-10
# for every method alike), rounding ~eps |y| / delta ~ 1e-12 ...
SYMPLECTIC_FD_DELTA = 2e-4
# ... so a symplectic map shows ||J^T Omega J - Omega|| / ||J||^2 at that level (measured on the
# registry: at most 7e-12, Stormer's central-difference velocity; implicit solves included);
# 1e-10 leaves a tenfold margin, and the least non-symplectic map measured (rk4, h omega = 0.1:
# (h omega)^6 / 72 ~ 1e-8) is a hundred times above it ...
SYMPLECTIC_FD_TOL = 1e-10
# ... refined by factors of 4 this many times where the state has a length scale far below its
# overall size (a close encounter: at r = 0.034 of a 4-wide Pleiades the first step gave 1.4e-8
# for every symplectic method alike) ...
SYMPLECTIC_FD_REFINEMENTS = 2
# ... and a method claimed not symplectic must exceed it tenfold to count as clearly above it.
SYMPLECTIC_CLEAR_FACTOR = 10.0
# A map that does more arithmetic per step (a black box's corrector stages, a long composition)
# has more rounding in its difference quotients than the registry's maps the 1e-10 was set on.
# Its own finite-difference error is estimated per base state by the gap between the Jacobians at
# the two neighbouring difference steps (relative to ||J||); the error E in J enters the deviation
# twice (E^T Omega J + J^T Omega E) and the gap estimates E to within a factor two, so the
# cell's finite-difference level is max(SYMPLECTIC_FD_TOL, this factor x the largest gap).
SYMPLECTIC_GAP_FACTOR = 4.0
# Report, ground truth: an exact solution evaluated in float64 (trigonometric functions, Kepler's
# equation solved by Newton's method) is off by a few ulps per operation; a reference may differ
# from it by its certified error plus this many ulps of the state's scale.
GROUND_TRUTH_EXACT_ULPS = 100.0
# Compiled vs NumPy implementation of one method (implementations.compiled): the same operations
# in the same order, except that the compiled right-hand side is a translation of the same
# expression whose last bit may differ (measured: up to 0.015 ulps per evaluation, 21.9 ulps after
# 100 steps of a 15-evaluation composition on kepler-elliptic). 16 ulps of the state's scale per
# four evaluations a step leaves room for that and still flags any real difference in the
# arithmetic (tests/test_compiled.py scales it by the method's evaluations per step).
COMPILED_AGREEMENT_ULPS = 16.0

# Adaptive steppers (scipy peers, heyoka's Taylor): one output step of one ensemble member may
# cost at most this many right-hand-side evaluations (or Taylor steps), ~1-5 s of work; beyond
# it the step fails with a message instead of running for hours on an absurd span.
ADAPTIVE_MAX_EVALS = 100_000

# Periodic problems are measured for convergence at this many periods (orbits), never a whole
# number: at a whole period a periodic error term returns to zero, and conjugate-symplectic
# methods (symplectic Euler, conjugate to velocity Verlet) then measure one order too high.
CONVERGENCE_PERIODS = 1.3

# Derived time scales and perturbations (harness.scales). The long-run experiments step with
# h = STEP_RATE_PRODUCT / max|lambda(J)| along the orbit: h omega = 0.12 resolves the fastest
# motion for every stable method (the old per-problem table had h omega 0.09-0.14) ...
STEP_RATE_PRODUCT = 0.12
# ... the orbit is sampled at every Taylor step and this many dense-output points inside each,
# so a close approach (where the steps shrink) is seen near its minimum ...
ORBIT_DENSE_POINTS = 3
# ... a run stops after this many Taylor steps (a span of 10^5 orbital periods or more) ...
ORBIT_MAX_STEPS = 200_000
# ... and at most this many samples enter the Jacobian's spectrum (evenly over the steps, which
# cluster where the motion is fast).
ORBIT_MAX_SAMPLES = 4000
# An ensemble member is in the unperturbed start's dynamical regime when its fastest rate along
# its orbit is within this factor of the unperturbed one (for gravity rate ~ r^-3/2: a closest
# approach within a factor 2^(2/3) = 1.6) ...
REGIME_RATE_FACTOR = 2.0
# ... and the derived perturbation is never made smaller than this (1e-8 of a component's scale
# is still ~5e7 ulps, far above rounding).
MIN_ENSEMBLE_PERTURBATION = 1e-8
# Convergence horizon of a problem that declares none: at most this many natural periods of its
# span (order does not depend on the horizon; a long span only costs steps).
HORIZON_PERIODS = 10.0
# ... and a problem whose fastest rate times its span exceeds this (stiff over its span: an
# explicit step of stability interval ~1 needs this many steps) but times that horizon does not,
# is measured to STIFF_HORIZON_STEPS / rate instead: 1e4 widths of its initial layer, so the
# points lie on the slow manifold (VDPOL, eps = 1e-6: 3.3e-3 instead of 7.4e-5, span 2). No
# catalogue problem without a declared horizon reaches it (largest: van-der-pol-stiff, 1.5e3).
STIFF_HORIZON_STEPS = 1e4
# A probe member's fastest rate is read from the spectra at this many samples of its orbit where
# ||J|| (a bound on the spectral radius) is largest: the fastest motion is among them.
REGIME_CANDIDATES = 64
# A long run (energy, reversibility) towards a horizon beyond the problem's span stops this many
# fastest-time units (1 / rate) before its orbit first leaves the span's dynamical regime ...
LONG_RUN_MARGIN = 10.0
# ... or where the state (each block: positions, velocities) first grows past this factor of
# its size over the span.
REGIME_SIZE_FACTOR = 2.0
# The report's "what changed since the last run": a measured figure without a confidence
# interval counts as moved when it changed by more than this relative amount. Deterministic
# quantities (stability intervals, evaluation counts) repeat to many digits on one machine;
# 1e-6 leaves room for another BLAS or compiler, not for a changed method.
REPORT_CHANGE_RTOL = 1e-6
# ... and for quantities at the rounding level (return errors in ulps, energy errors of
# symplectic methods, symplectic deviations), which move by small factors with the order of
# floating-point operations: a change by more than this factor either way.
REPORT_CHANGE_ROUNDING = 10.0
# Step-controlled steppers (h is a control parameter) keep their own clocks: a run whose clock
# passes t0 + this many times the problem's t_span length has left the motion the problem
# describes (a naive control lets an orbit escape, and its clock runs away: 7.8e6 after 16
# steps on kepler-e0.99); its error counts as a blow-up, never compared with a reference. Ten
# spans: a control parameter read against the convergence span in angle units covers ~1 t_span
# on kepler-circular (whose orbit takes 16 pi), and a runaway clock exceeds it by far more.
CLOCK_LIMIT_SPANS = 10.0

# Extended-precision convergence runs (`harness.extended`): right-hand-side (or force)
# evaluations one real128 sweep may spend. A real128 evaluation with its stage arithmetic costs
# ~20-40 us in Python, so 1e6 is ~20-40 s: an order-8 method needs ~2^7 x the float64 sweep's
# last n to go ~17 decades lower, an order-10 one fewer.
EXTENDED_WORK_BUDGET = 1_000_000
# ... which goes on halving h while two successive local slopes differ by more than this (the
# points are cheap there, and an order-10 method's slopes still climb 9.90 -> 9.99 over 3 halvings).
EXTENDED_SETTLED_SLOPE = 0.02

# Energy drift of a non-symplectic, non-symmetric one-step method (`harness.rules.judge_drift`):
# the drift predicted from the first period must exceed what rounding explains by this factor
# to be measurable (the classifier cannot tell a drift within a few rounding units from noise).
DRIFT_MEASURABLE_FACTOR = 10.0

# Adaptive steppers (`harness.rules.tolerance_allowance`): the global error may reach this many
# times (accepted steps per trajectory) x (flow amplification) x tol x |y|. An embedded error
# estimate is only asymptotically the local error (at coarse tolerances it is off by a few);
# measured worst over scipy's RK45/DOP853/LSODA and heyoka's Taylor on Kepler e = 0-0.99,
# the harmonic oscillator and y' = -y: 0.52 of N A tol |y| (RK45, circular orbit, tol 1e-3).
TOLERANCE_ESTIMATE_FACTOR = 10.0

# Close encounters in the energy experiment (`harness.experiments.energy`): a run whose fastest
# rate (spectral radius along the orbit) rises more than ENCOUNTER_RATE_RISE-fold over its start
# reads the bounded-energy envelope only after the rate first comes within
# ENCOUNTER_RATE_FRACTION of its maximum over the run (a bounded error ~(h rho)^p rises with
# each closer approach), and needs at least ENCOUNTER_MIN_DECADES decades of steps after it.
ENCOUNTER_RATE_RISE = 10.0
ENCOUNTER_RATE_FRACTION = 0.9
ENCOUNTER_MIN_DECADES = 0.3

# Maps with an error law eps^a h^b + ... (harness.perturbation_law): a term is taken to set the
# measured slope where, with unit constants, it exceeds every other term by this factor over
# the fitted steps; the constants are unknown, so a single decade is the least that makes the
# dominant term's exponent the slope to within GATE_ORDER_TOL (a 10 % second term moves a
# two-point slope by at most log(1.1)/log(2) ~ 0.14 per unit of exponent difference, damped).
SPLIT_TERM_DOMINANCE = 10.0

# Names of steppers, problems and method records (`harness.names`): a name becomes a file name
# in the cache and the results (255 bytes on most file systems, with a suffix and a hash added),
# a table column and an HTML heading; 120 characters leave room for all three.
MAX_NAME_LENGTH = 120
# Largest order a method may claim: beyond it no float64 (or real128) sweep can resolve a slope
# (Runge-Kutta order conditions are checked up to order 12); a larger claim is a typo.
MAX_CLAIMED_ORDER = 50
# A method record's coefficient arrays: at most this many entries per axis (stages, steps,
# splitting substeps), so a record cannot ask for gigabytes or an hours-long order check.
MAX_RECORD_ENTRIES = 256
# A declared invariant I is conserved by the exact flow when dI/dt = grad I . f (+ dI/dt) stays
# below this fraction of |grad I| |f| (+ |dI/dt|) at every sampled point of the orbit: rounding
# of the compiled derivative is ~1e-16 per term, a wrong invariant gives O(1).
INVARIANT_FLOW_RTOL = 1e-8
# ... and when it also moves along the float64 Taylor orbit (tolerance eps, which keeps a true
# invariant to ~1e-13 over the catalogue's spans) by more than this fraction of its size.
INVARIANT_FLOW_DRIFT = 1e-6
# The largest file the store reads (a run's table, a cell, meta.json, an earlier report's
# verdicts): far above any run the harness writes (a full report's rows are ~10 MB), and a
# bound so that a link to an endless device is refused, not read until memory runs out.
MAX_STORED_FILE_BYTES = 2 * 1024**3

# The timing protocol's repeats and budgets are settings of `harness.timing`, beside it.
# Implementations of one method agree "to rounding" when their errors at the same step differ by
# at most this many float64 ulps of the state's scale, times sqrt(n_steps) (rounding accumulated
# as a random walk), or this many times the point's rounding level (which carries the flow's
# amplification) -- or relatively by TIMING_SAME_ERROR_RTOL where the error is far above
# rounding (a different summation order changes the last bits of each step only).
TIMING_SAME_ERROR_ULPS = 64.0
TIMING_SAME_ERROR_RTOL = 1e-6
# The target errors of the time-to-target table.
TIMING_TARGET_ERRORS = (1e-4, 1e-8, 1e-12)
# A NumPy loop of a method whose compiled loop ran the sweep is timed beside it at the largest
# point whose work (steps x evaluations per step, x IMPLICIT_STEP_COST for implicit steps) is at
# most TIMING_TWIN_WORK: a NumPy step on one trajectory costs ~5-40 us explicit, ~0.2-1 ms
# implicit (Newton in NumPy), so a run costs ~3-50 ms; one point shows the agreement.
TIMING_TWIN_WORK = 512

# Predicted leading error (harness.prediction): symbolic elementary differentials of trees with
# m vertices grow like dim^(m-1), so they are built only up to this size (12 variables at order
# 5: ~30 s once, cached; order 6 took ~100 s under load; 4 variables at order 8: ~6 s).
PREDICTION_MAX_WORK = 12**4
# The prediction beside every convergence cell (information, not a verdict) keeps to a smaller
# budget: 12 variables at order 5 cost ~6 s of compile cold, most of the prediction's share of a
# cold gate; 18 variables at order 4 (18^3) ~1 s.
PREDICTION_ROUTINE_MAX_WORK = 18**3
# The variational integration needs only a few digits of E_t(T): the prediction is asymptotic.
PREDICTION_TAYLOR_TOL = 1e-10
# A slope above the order is explained when the predicted leading term C h^p is below this
# fraction of the measured error over the fit: the fitted points are then set by later terms.
SLOPE_EXPLAINED_RATIO = 0.3

# Second-order multistep tables on orbits (harness.experiments.multistep_orbits), one reason each:
PARASITIC_UNIT_CIRCLE = 1e-8  # |root| - 1 of a root on the circle: float64 roots of simple roots ~1e-13
# A resonance: energy error this far above the log-log trend of RESONANCE_WINDOW neighbours a side
# (bounded runs scatter ~2x about it; QT8's resonances stand 1e2-1e8 above it).
RESONANCE_SPIKE_FACTOR, RESONANCE_WINDOW = 10.0, 3
RESONANCE_MATCH_REL = 0.02  # parasitic roots move O((h omega)^2): QT8's band centre sits 0.5 % off
JACOBIAN_HARMONIC_FLOOR = 0.05  # share of the largest harmonic (a circular orbit's others: 1e-15)
# Drift read where the run stays near the orbit and above rounding (leading-order law holds), and
# called secular when slope x T explains this share of the largest error (bounded: a small share).
SPIRAL_MAX_ERROR, SPIRAL_MIN_CHANGE, SECULAR_FRACTION = 1e-2, 1e-10, 0.5
SPIRAL_RATE_FACTOR = 2.0  # measured / predicted drift rate (leading order; stormer4-6: 1.00 +- 0.02)
