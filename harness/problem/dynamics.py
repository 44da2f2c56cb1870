"""`Dynamics`: a problem's NumPy-callable, ensemble-batched right-hand side, acceleration and
Jacobian (heyoka compiled functions), with evaluation counters."""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING

import numpy as np

from harness.errors import InputError

if TYPE_CHECKING:
    from harness.problem.definition import Problem


class Dynamics:
    """A problem's numerical functions for one ensemble: f(t, Y), a(t, Q, V), J(t, Y).

    States are shaped (dim, N), ensemble axis last. Each call counts as one right-hand-side (or
    force, or Jacobian) evaluation of the whole ensemble: `counts` keeps the books.
    Parameters shared by all members are compiled in as constants (faster calls); differing
    parameters are passed at run time. The call path is chosen once, here, because steppers
    call these functions millions of times: a plain compiled call costs ~2.5 us, and every
    keyword argument or dictionary built per call adds to it.
    """

    def __init__(self, problem: Problem, pars: np.ndarray):
        self.problem = problem
        self.pars = np.ascontiguousarray(pars, dtype=np.float64)
        self.size = self.pars.shape[1] if self.pars.ndim == 2 else 1
        uniform = self.pars.size == 0 or bool(np.all(self.pars == self.pars[:, :1]))
        self.constants = tuple(float(v) for v in self.pars[:, 0]) if uniform and self.size else None
        self.time_dependent = problem.time_dependent
        self.dim = problem.dim
        self.nq = len(problem.newtonian.positions) if problem.newtonian is not None else 0
        self.counts = {"rhs": 0, "accel": 0, "jac": 0}
        self._runtime_pars = self.constants is None and self.pars.size > 0
        self._tbuf = np.zeros(self.size)
        self._f = problem.compiled("rhs", self.constants)
        self._a = None
        self._a_positions_only = False
        if problem.newtonian is not None:
            self._a_positions_only = not problem.velocity_dependent
            kind = "accel_q" if self._a_positions_only else "accel"
            self._a = problem.compiled(kind, self.constants)
        self._qv = np.empty((self.dim, self.size)) if problem.newtonian is not None else None

    def member(self, index: int) -> Dynamics:
        """One ensemble member's view: the same compiled functions and the same `counts` (so
        every call is booked on the run), that member's parameters and its own buffers.

        Parameters
        ----------
        index : the member's column in `pars`.

        Returns
        -------
        A shallow copy of this object sized for one member.
        """
        view = copy.copy(self)
        view.pars = np.ascontiguousarray(self.pars[:, index : index + 1])
        view.size = 1
        view.reset_buffers()
        return view

    def reset_buffers(self) -> None:
        """Give this object its own work buffers, sized for `size` members (a copy must not
        write into the buffers of the object it was copied from)."""
        self._tbuf = np.zeros(self.size)
        self._qv = None

    def _kwargs(self, t: float, n: int) -> dict:
        kw = {}
        if self._runtime_pars:
            kw["pars"] = self.pars
        if self.time_dependent:
            if self._tbuf.shape[0] != n:
                self._tbuf = np.zeros(n)
            self._tbuf.fill(t)
            kw["time"] = self._tbuf
        return kw

    def _call(self, fn, t: float, x: np.ndarray, out: np.ndarray | None) -> np.ndarray:
        if not (self.time_dependent or self._runtime_pars):
            if out is None:
                return fn(x)
            fn(x, outputs=out)
            return out
        if out is None:
            return fn(x, **self._kwargs(t, x.shape[1]))
        fn(x, outputs=out, **self._kwargs(t, x.shape[1]))
        return out

    def f(self, t: float, y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """First-order right-hand side, y shaped (dim, N).

        Parameters
        ----------
        t : float, time.
        y : ndarray, shape (dim, N), states.
        out : ndarray, shape (dim, N), optional, where to write the result.

        Returns
        -------
        ndarray, shape (dim, N): f(t, y) (`out` when given).
        """
        self.counts["rhs"] += 1
        return self._call(self._f, t, y, out)

    def accel(self, t: float, q: np.ndarray, v: np.ndarray | None = None, out=None) -> np.ndarray:
        """Acceleration a(q, v, t), q and v shaped (nq, N). v may be None when a ignores it.

        Parameters
        ----------
        t : float, time.
        q : ndarray, shape (nq, N), positions.
        v : ndarray, shape (nq, N), optional, velocities.
        out : ndarray, shape (nq, N), optional, where to write the result.

        Returns
        -------
        ndarray, shape (nq, N): a(q, v, t); `InputError` for a problem without a Newtonian form.
        """
        if self._a is None:
            raise InputError(f"problem {self.problem.name!r} has no Newtonian form")
        self.counts["accel"] += 1
        if self._a_positions_only:
            if not q.flags.c_contiguous:
                q = np.ascontiguousarray(q)
            return self._call(self._a, t, q, out)
        n = q.shape[1]
        if self._qv is None or self._qv.shape[1] != n:
            self._qv = np.empty((self.dim, n))
        self._qv[: self.nq] = q
        if v is None:
            self._qv[self.nq :] = 0.0
        else:
            self._qv[self.nq :] = v
        return self._call(self._a, t, self._qv, out)

    def jac(self, t: float, y: np.ndarray) -> np.ndarray:
        """Jacobian df/dy shaped (dim, dim, N).

        Parameters
        ----------
        t : float, time.
        y : ndarray, shape (dim, N), states.

        Returns
        -------
        ndarray, shape (dim, dim, N): the Jacobians.
        """
        self.counts["jac"] += 1
        fn = self.problem.compiled("jac", self.constants)
        out = self._call(fn, t, y, None)
        return out.reshape(self.dim, self.dim, y.shape[1])
