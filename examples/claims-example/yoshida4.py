"""A fourth-order symplectic integrator in one file: Yoshida's triple jump of velocity Verlet.

The library's only public function is `step(accel, t, q, v, h) -> (q, v)` for q'' = accel(t, q).
Three velocity-Verlet substeps of sizes w1 h, w0 h, w1 h with w1 = 1/(2 - 2^(1/3)) and
w0 = 1 - 2 w1: the composition is symmetric, symplectic and of order 4.
Reference: H. Yoshida, Phys. Lett. A 150 (1990) 262-268; Hairer, Lubich & Wanner, Geometric
Numerical Integration (2006), II.4 (triple jump).
"""

W1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
W0 = 1.0 - 2.0 * W1


def step(accel, t, q, v, h):
    """One step of size h; q and v are arrays (any shape accel accepts), returned as new arrays."""
    for w in (W1, W0, W1):
        v = v + 0.5 * w * h * accel(t, q)
        q = q + w * h * v
        v = v + 0.5 * w * h * accel(t, q)
    return q, v
