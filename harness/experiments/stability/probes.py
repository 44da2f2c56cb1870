"""Black-box stability probes: a stepper's one-step recurrence read off by stepping unit vectors
of its history (first-order steppers on Dahlquist's equation) or unit states (Newtonian
steppers on x'' = -omega^2 x), each grid point one ensemble member (Hairer & Wanner, *Solving
ODEs II*, IV.2 and V.1)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from harness import theory
from harness.coefficients import (
    LinearMultistep,
    SecondOrderMultistep,
)
from harness.errors import InputError
from harness.stepper import StepFailure, Stepper

# a step that fails or a singular solve counts as unstable at that point
STEP_FAILURES = (StepFailure, np.linalg.LinAlgError)


def block_companion(C: np.ndarray) -> np.ndarray:
    """Companion matrix of y_k = sum_j C_j y_j: C shaped (M, k, d, d) -> (M, k d, k d) acting
    on the stacked history (y_0, ..., y_{k-1}).

    Parameters
    ----------
    C : ndarray, shape (M, k, d, d), the recurrence blocks at M points.

    Returns
    -------
    ndarray, shape (M, k d, k d)
    """
    M, k, d, _ = C.shape
    out = np.zeros((M, k * d, k * d))
    for i in range(k - 1):
        out[:, i * d : (i + 1) * d, (i + 1) * d : (i + 2) * d] = np.eye(d)
    for j in range(k):
        out[:, (k - 1) * d :, j * d : (j + 1) * d] = C[:, j]
    return out


def _split_on_failure(run: Callable[[np.ndarray], np.ndarray], idx: np.ndarray, out: np.ndarray):
    """Run `run` on points `idx`; when a step fails for the ensemble, bisect so only the
    failing points are marked NaN (an implicit solve exactly at a pole of R, say)."""
    try:
        out[idx] = run(idx)
    except STEP_FAILURES:
        if idx.size == 1:
            out[idx] = np.nan
            return
        half = idx.size // 2
        _split_on_failure(run, idx[:half], out)
        _split_on_failure(run, idx[half:], out)


class FirstOrderProbe:
    """Black-box recurrence of a first-order stepper on y' = lambda y with h = 1."""

    chunk_points = 4096

    def __init__(self, stepper: Stepper, problem):
        self.stepper = stepper
        self.problem = problem
        self.k = int(getattr(stepper, "history_length", 1))
        names = list(problem.parameters)
        if problem.dim != 2 or "lambda_re" not in names or "lambda_im" not in names:
            raise InputError(
                f"problem {problem.name!r} must be the complex test equation with state "
                f"(Re y, Im y) and parameters lambda_re, lambda_im"
            )
        self._i_re, self._i_im = names.index("lambda_re"), names.index("lambda_im")
        self._defaults = problem.parameter_values

    def _pars(self, z: np.ndarray) -> np.ndarray:
        P = np.repeat(self._defaults[:, None], z.size, axis=1)
        P[self._i_re] = z.real
        P[self._i_im] = z.imag
        return P

    def _blocks_once(self, z: np.ndarray) -> np.ndarray:
        k, d = self.k, 2
        m = z.size
        per = k * d
        N = m * per
        history = [np.zeros((d, N)) for _ in range(k)]
        for j in range(k):
            for a in range(d):
                history[j][a, np.arange(m) * per + j * d + a] = 1.0
        pars = np.repeat(self._pars(z), per, axis=1)
        if N < 2 or np.all(pars == pars[:, :1]):
            # one distinct lambda would be compiled in as a constant (a new compile per value):
            # a padding member with another lambda keeps the runtime-parameter function
            pad = pars[:, :1] + 1.0
            pars = np.concatenate([pars, pad], axis=1)
            history = [np.concatenate([hj, np.zeros((d, 1))], axis=1) for hj in history]
        y = self.stepper.step_from_history(
            self.problem, h=1.0, history=history, t0=self.problem.t0, pars=pars
        )[:, :N]
        # member m*per + j*d + a holds column a of C_j at point m
        return y.reshape(d, m, k, d).transpose(1, 2, 0, 3)

    def blocks(self, z: Any) -> np.ndarray:
        """C_j at each z: shape (M, k, 2, 2); NaN where the step failed.

        Parameters
        ----------
        z : array_like of complex, the points h lambda (flattened).

        Returns
        -------
        ndarray, shape (M, k, 2, 2)
        """
        z = np.asarray(z, dtype=complex).reshape(-1)
        out = np.empty((z.size, self.k, 2, 2))
        for start in range(0, z.size, self.chunk_points):
            idx = np.arange(start, min(start + self.chunk_points, z.size))
            _split_on_failure(lambda i: self._blocks_once(z[i]), idx, out)
        return out

    def amplification(self, z: Any) -> np.ndarray:
        """Spectral radius of the block companion matrix (|R(z)| for one-step methods).

        Parameters
        ----------
        z : array_like of complex, the points h lambda.

        Returns
        -------
        ndarray of float: same shape as `z`; NaN where a step failed.
        """
        z = np.asarray(z, dtype=complex)
        C = self.blocks(z)
        if self.k == 1:
            r = np.hypot(C[:, 0, 0, 0], C[:, 0, 1, 0])  # |R|: C_0 = [[Re R, -Im R], [Im R, Re R]]
        else:
            r = theory.spectral_radius(block_companion(C))
        return r.reshape(z.shape)


class NewtonianProbe:
    """Black-box propagator of a Newtonian stepper on x'' = -x (omega = 1), step h = h omega.

    Modes: 'one-step' (unit states (x, v) through one step), 'history' (unit history vectors
    through `step_from_history`), 'position-recurrence' (two-step position recurrence
    x_2 = c_0 x_0 + c_1 x_1 identified from the two unit starts, confirmed on x_3).
    """

    def __init__(self, stepper: Stepper, problem):
        self.stepper = stepper
        self.problem = problem
        if problem.newtonian is None or len(problem.newtonian.positions) != 1:
            raise InputError(f"problem {problem.name!r} must be the 1-D oscillator x'' = -x")
        self.k = int(getattr(stepper, "history_length", 1))
        coeffs = stepper.coefficients
        if self.k > 1:
            self.mode = "history"
        elif isinstance(coeffs, SecondOrderMultistep) and coeffs.steps == 2:
            self.mode = "position-recurrence"
        elif isinstance(coeffs, SecondOrderMultistep | LinearMultistep) and coeffs.steps > 1:
            raise InputError(
                f"stepper {stepper.info.name!r} is a {coeffs.steps}-step method without a history "
                "hook (`history_length`); its propagator cannot be probed"
            )
        else:
            self.mode = "one-step"
        self.recurrence_mismatch = 0.0
        self.last_blocks: np.ndarray | None = None  # C_j of the last 'history' probe, (k, 2, 2)

    def matrix(self, hw: float) -> np.ndarray:
        """The propagator at step h omega = `hw`: (x, v) -> (x, v) for 'one-step'; the block
        companion for 'history'; [[0, 1], [c_0, c_1]] on (x_(n-1), x_n) for
        'position-recurrence'.

        Parameters
        ----------
        hw : float, h omega on x'' = -omega^2 x.

        Returns
        -------
        ndarray: 2 x 2, or 2k x 2k for 'history'; a step failure propagates.
        """
        s, p = self.stepper, self.problem
        if self.mode == "one-step":
            return s.step_from_history(p, h=hw, history=[np.eye(2)], t0=p.t0)
        if self.mode == "history":
            k, d = self.k, 2
            N = k * d
            history = [np.zeros((d, N)) for _ in range(k)]
            for j in range(k):
                for a in range(d):
                    history[j][a, j * d + a] = 1.0
            y = s.step_from_history(p, h=hw, history=history, t0=p.t0)
            C = y.reshape(d, 1, k, d).transpose(1, 2, 0, 3)
            self.last_blocks = C[0]
            return block_companion(C)[0]
        tr = s.integrate(p, h=hw, n_steps=3, y0=np.eye(2), t0=p.t0, save_steps=[0, 1, 2, 3])
        X = tr.y[:, 0, :]  # positions, (4 steps, 2 starts)
        c = np.linalg.solve(np.stack([X[0], X[1]], axis=1), X[2])
        pred = c[0] * X[1] + c[1] * X[2]
        mismatch = float(np.max(np.abs(pred - X[3])) / max(1.0, float(np.max(np.abs(X[3])))))
        self.recurrence_mismatch = max(self.recurrence_mismatch, mismatch)
        return np.array([[0.0, 1.0], [c[0], c[1]]])

    def amplification(self, hw: Any) -> np.ndarray:
        """The probe's spectral radius at each h omega in `hw` (inf where a step fails).

        Parameters
        ----------
        hw : array_like of float, the values of h omega.

        Returns
        -------
        ndarray of float: same shape as `hw`.
        """
        hw = np.asarray(hw, dtype=float)
        out = np.empty(hw.size)
        for i, x in enumerate(hw.reshape(-1)):
            try:
                out[i] = theory.spectral_radius(self.matrix(float(x)))
            except STEP_FAILURES:
                out[i] = np.nan
        return out.reshape(hw.shape)


# =============================================================================================
# Comparison with the coefficients
# =============================================================================================
