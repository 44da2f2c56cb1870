/* Reference loops in plain C for the planar Kepler problem r'' = -r/|r|^3 (GM = 1).
 *
 * The baseline every stepper timing in the asv suite is divided by. The arithmetic is the
 * harness's own: the acceleration -r / (x^2 + y^2)^(3/2) is computed as -x / (s * s * s) with
 * s = sqrt(x^2 + y^2), which is how heyoka evaluates the problem's `r2**1.5` (bit for bit),
 * velocity Verlet is kick-drift-kick with the force of the
 * step's end reused (Swope et al., J. Chem. Phys. 76 (1982) 637), RK4 is the classical tableau
 * (Kutta 1901; Hairer, Norsett & Wanner I, Table II.1.2). States are laid out as the harness's
 * ensembles: component-major arrays y[c * n + j], c in (x, y, vx, vy), member j.
 *
 * Single-trajectory loops keep the state in locals; ensemble loops sweep all members once per
 * step (the order an array program uses), so the compiler may vectorise the member loop.
 */
#include <math.h>
#include <stddef.h>

static inline void kepler_accel(double x, double y, double *ax, double *ay)
{
    double r2 = x * x + y * y;
    double s = sqrt(r2);
    double d = s * s * s;
    *ax = -x / d;
    *ay = -y / d;
}

/* n_steps velocity-Verlet steps of size h from s = (x, y, vx, vy), in place. */
void vv_single(double *s, double h, long n_steps)
{
    double x = s[0], y = s[1], vx = s[2], vy = s[3], ax, ay;
    kepler_accel(x, y, &ax, &ay);
    for (long k = 0; k < n_steps; ++k) {
        vx += 0.5 * h * ax;
        vy += 0.5 * h * ay;
        x += h * vx;
        y += h * vy;
        kepler_accel(x, y, &ax, &ay);
        vx += 0.5 * h * ax;
        vy += 0.5 * h * ay;
    }
    s[0] = x; s[1] = y; s[2] = vx; s[3] = vy;
}

static inline void kepler_rhs(const double *u, double *f)
{
    f[0] = u[2];
    f[1] = u[3];
    kepler_accel(u[0], u[1], &f[2], &f[3]);
}

/* n_steps classical RK4 steps of size h from s = (x, y, vx, vy), in place. */
void rk4_single(double *s, double h, long n_steps)
{
    double u[4], k1[4], k2[4], k3[4], k4[4], w[4];
    for (int i = 0; i < 4; ++i) u[i] = s[i];
    for (long k = 0; k < n_steps; ++k) {
        kepler_rhs(u, k1);
        for (int i = 0; i < 4; ++i) w[i] = u[i] + 0.5 * h * k1[i];
        kepler_rhs(w, k2);
        for (int i = 0; i < 4; ++i) w[i] = u[i] + 0.5 * h * k2[i];
        kepler_rhs(w, k3);
        for (int i = 0; i < 4; ++i) w[i] = u[i] + h * k3[i];
        kepler_rhs(w, k4);
        for (int i = 0; i < 4; ++i)
            u[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
    for (int i = 0; i < 4; ++i) s[i] = u[i];
}

/* Ensemble velocity Verlet: y is (4, n) component-major, a is (2, n) scratch for the force. */
void vv_ensemble(double *restrict y, double *restrict a, long n, double h, long n_steps)
{
    double *restrict qx = y, *restrict qy = y + n, *restrict vx = y + 2 * n, *restrict vy = y + 3 * n;
    double *restrict ax = a, *restrict ay = a + n;
    for (long j = 0; j < n; ++j) kepler_accel(qx[j], qy[j], &ax[j], &ay[j]);
    for (long k = 0; k < n_steps; ++k) {
        for (long j = 0; j < n; ++j) {
            vx[j] += 0.5 * h * ax[j];
            vy[j] += 0.5 * h * ay[j];
            qx[j] += h * vx[j];
            qy[j] += h * vy[j];
            kepler_accel(qx[j], qy[j], &ax[j], &ay[j]);
            vx[j] += 0.5 * h * ax[j];
            vy[j] += 0.5 * h * ay[j];
        }
    }
}

/* Ensemble RK4: y is (4, n) component-major, work is (20, n) scratch (4 stages + stage state). */
void rk4_ensemble(double *restrict y, double *restrict work, long n, double h, long n_steps)
{
    double *k[4] = {work, work + 4 * n, work + 8 * n, work + 12 * n};
    double *w = work + 16 * n;
    static const double c_stage[3] = {0.5, 0.5, 1.0};
    for (long step = 0; step < n_steps; ++step) {
        for (int s = 0; s < 4; ++s) {
            const double *src = y;
            if (s > 0) {
                for (int i = 0; i < 4; ++i)
                    for (long j = 0; j < n; ++j)
                        w[i * n + j] = y[i * n + j] + c_stage[s - 1] * h * k[s - 1][i * n + j];
                src = w;
            }
            double *f = k[s];
            for (long j = 0; j < n; ++j) {
                f[j] = src[2 * n + j];
                f[n + j] = src[3 * n + j];
                kepler_accel(src[j], src[n + j], &f[2 * n + j], &f[3 * n + j]);
            }
        }
        for (int i = 0; i < 4; ++i)
            for (long j = 0; j < n; ++j)
                y[i * n + j] += h / 6.0 * (k[0][i * n + j] + 2.0 * k[1][i * n + j]
                                           + 2.0 * k[2][i * n + j] + k[3][i * n + j]);
    }
}

/* ---- one loop per family beyond velocity Verlet and RK4 (single trajectory) ---------------- */

/* Staggered leapfrog: x += h v_{n+1/2}, v_{n+3/2} = v_{n+1/2} + h a(x_{n+1}); s holds the
 * positions and the half-step velocities (the start v_1/2 = v_0 + h a_0 / 2 is the caller's). */
void leapfrog_single(double *s, double h, long n_steps)
{
    double x = s[0], y = s[1], vx = s[2], vy = s[3], ax, ay;
    for (long k = 0; k < n_steps; ++k) {
        x += h * vx;
        y += h * vy;
        kepler_accel(x, y, &ax, &ay);
        vx += h * ax;
        vy += h * ay;
    }
    s[0] = x; s[1] = y; s[2] = vx; s[3] = vy;
}

/* Stormer's two-step rule x_{n+1} = 2 x_n - x_{n-1} + h^2 a(x_n) (Hairer, Norsett & Wanner I,
 * III.10); s = (x_{n-1}, y_{n-1}, x_n, y_n) in, the last two positions out. */
void stormer_single(double *s, double h, long n_steps)
{
    double xp = s[0], yp = s[1], x = s[2], y = s[3], ax, ay, hh = h * h;
    for (long k = 0; k < n_steps; ++k) {
        kepler_accel(x, y, &ax, &ay);
        double xn = 2.0 * x - xp + hh * ax;
        double yn = 2.0 * y - yp + hh * ay;
        xp = x; yp = y; x = xn; y = yn;
    }
    s[0] = xp; s[1] = yp; s[2] = x; s[3] = y;
}

/* Fourth-order Adams-Bashforth (Hairer, Norsett & Wanner I, III.1): y_{n+1} = y_n +
 * h/24 (55 f_n - 59 f_{n-1} + 37 f_{n-2} - 9 f_{n-3}); s = (y_{n-3}, ..., y_n), 16 values, with
 * the derivatives of the three oldest evaluated once at the start, one evaluation per step. */
void ab4_single(double *s, double h, long n_steps)
{
    double f[4][4], u[4];
    for (int j = 0; j < 3; ++j) kepler_rhs(s + 4 * j, f[j]);
    for (int i = 0; i < 4; ++i) u[i] = s[12 + i];
    double c0 = -9.0 / 24.0 * h, c1 = 37.0 / 24.0 * h, c2 = -59.0 / 24.0 * h, c3 = 55.0 / 24.0 * h;
    for (long k = 0; k < n_steps; ++k) {
        kepler_rhs(u, f[3]);
        for (int i = 0; i < 4; ++i)
            u[i] += c0 * f[0][i] + c1 * f[1][i] + c2 * f[2][i] + c3 * f[3][i];
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 4; ++i) f[j][i] = f[j + 1][i];
    }
    for (int i = 0; i < 4; ++i) s[12 + i] = u[i];
}

static inline void kepler_jac(const double *u, double *J)
{
    /* J = d(vx, vy, ax, ay)/d(x, y, vx, vy), row-major 4x4 */
    double x = u[0], y = u[1];
    double r2 = x * x + y * y, r = sqrt(r2), r3 = r2 * r, r5 = r3 * r2;
    for (int i = 0; i < 16; ++i) J[i] = 0.0;
    J[0 * 4 + 2] = 1.0;
    J[1 * 4 + 3] = 1.0;
    J[2 * 4 + 0] = -1.0 / r3 + 3.0 * x * x / r5;
    J[2 * 4 + 1] = 3.0 * x * y / r5;
    J[3 * 4 + 0] = 3.0 * x * y / r5;
    J[3 * 4 + 1] = -1.0 / r3 + 3.0 * y * y / r5;
}

static int solve4(double *M, double *b)
{
    for (int c = 0; c < 4; ++c) {
        int p = c;
        for (int r = c + 1; r < 4; ++r)
            if (fabs(M[r * 4 + c]) > fabs(M[p * 4 + c])) p = r;
        if (M[p * 4 + c] == 0.0) return 0;
        if (p != c) {
            for (int q = 0; q < 4; ++q) { double t = M[c * 4 + q]; M[c * 4 + q] = M[p * 4 + q]; M[p * 4 + q] = t; }
            double t = b[c]; b[c] = b[p]; b[p] = t;
        }
        for (int r = c + 1; r < 4; ++r) {
            double l = M[r * 4 + c] / M[c * 4 + c];
            for (int q = c + 1; q < 4; ++q) M[r * 4 + q] -= l * M[c * 4 + q];
            b[r] -= l * b[c];
        }
    }
    for (int i = 3; i >= 0; --i) {
        double acc = b[i];
        for (int q = i + 1; q < 4; ++q) acc -= M[i * 4 + q] * b[q];
        b[i] = acc / M[i * 4 + i];
    }
    return 1;
}

/* Implicit midpoint rule (the one-stage Gauss method; Hairer & Wanner II, IV.8): Z = h/2
 * f(y + Z), y <- y + 2 Z, by full Newton from the previous step's Z, converged when the
 * increment scaled by 1 + |y| is at most tol or the contraction estimate theta/(1-theta)|dZ| is.
 * Returns the Newton iterations taken, or -1 when an iteration fails to converge in max_iter. */
long midpoint_single(double *s, double h, long n_steps, double tol, long max_iter)
{
    double u[4], Z[4] = {0.0, 0.0, 0.0, 0.0}, w[4], f[4], J[16], M[16], g[4], inv[4];
    long iterations = 0;
    for (int i = 0; i < 4; ++i) u[i] = s[i];
    for (long k = 0; k < n_steps; ++k) {
        for (int i = 0; i < 4; ++i) inv[i] = 1.0 / (1.0 + fabs(u[i]));
        double previous = INFINITY;
        int converged = 0;
        for (long it = 0; it < max_iter && !converged; ++it) {
            for (int i = 0; i < 4; ++i) w[i] = u[i] + Z[i];
            kepler_rhs(w, f);
            kepler_jac(w, J);
            for (int i = 0; i < 4; ++i) g[i] = -(Z[i] - 0.5 * h * f[i]);
            for (int i = 0; i < 16; ++i) M[i] = -0.5 * h * J[i];
            for (int i = 0; i < 4; ++i) M[i * 4 + i] += 1.0;
            if (!solve4(M, g)) return -1;
            double norm = 0.0;
            for (int i = 0; i < 4; ++i) {
                Z[i] += g[i];
                double e = fabs(g[i] * inv[i]);
                if (e > norm) norm = e;
            }
            ++iterations;
            if (norm <= tol) converged = 1;
            else if (isfinite(previous)) {
                double theta = norm / previous;
                if (theta < 1.0 && theta / (1.0 - theta) * norm <= tol) converged = 1;
            }
            previous = norm;
        }
        if (!converged) return -1;
        for (int i = 0; i < 4; ++i) u[i] += 2.0 * Z[i];
    }
    for (int i = 0; i < 4; ++i) s[i] = u[i];
    return iterations;
}
