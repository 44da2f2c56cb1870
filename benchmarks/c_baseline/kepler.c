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
