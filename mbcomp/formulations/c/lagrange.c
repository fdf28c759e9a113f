#ifdef REDUCED_LOOP
#define LAG_TRIAL @TRIAL@
#define LAG_PAUSED @PAUSED@
#define LAG_EVENT @EVENT@
#define LAG_NEWTON_TOL 1e-12
#define LAG_NEWTON_ITER 25
#define LAG_MIJ(L, i, j) ((i) >= (j) ? (L)[IDX(i, j)] : (L)[IDX(j, i)])
#include "friction.h"
#include "brentq.h"
#include "least_norm.h"
#include "cholesky.h"
#include "quaternion.h"
static __thread int lag_on = 0, lag_nc, lag_nr, lag_ni;
static __thread const long *lag_geo, *lag_mq, *lag_mv, *lag_rows, *lag_dep, *lag_ind;
/* the coordinates' partition: Newton on the position rows lag_prows (npr) for the dependent
   coordinates lag_qdep, lag_qind (nqi) independent; the same as the speeds' partition
   unless velocity rows (rolling, no-slip: no position residual) remove speeds only */
static __thread int lag_npr, lag_nqi;
static __thread const long *lag_prows, *lag_qdep, *lag_qind;
static __thread double *lag_plu;
static __thread int *lag_ppiv;
static __thread const double *lag_speed, *lag_offset;
static __thread double *lag_acc, *lag_info, lag_scale, lag_limit;
static __thread double *lag_mem = 0;
/* scratch (in lag_mem): constraint outputs, g, J (nc x NQ), g_t, bias, Jd LU, pivots,
   X (nr x (ni + 1)), dynamics, M B (NQ x ni), reduced matrix, vectors, eigen work */
static __thread double *lag_c, *lag_g, *lag_J, *lag_gt, *lag_bias, *lag_lu, *lag_X, *lag_dyn, *lag_MB,
    *lag_Mr, *lag_h, *lag_v, *lag_eig, *lag_q, *lag_qd, *lag_x, *lag_rate, *lag_end;
/* Output times inside a step (lag_span, between lagrange_span and lagrange_span_end): the
   Newton predictor is the cubic Hermite interpolant of the step's two full states (the
   accepted one and lag_end = [q, qd] at lag_t_end), not the start state advanced by its
   speeds: near a singular position the latter can be closer to another assembly branch
   than to the step's own (a sample of the wrong branch, energy off by joules, in A02). */
static __thread int lag_span = 0;
static __thread double lag_t_end;
/* the chart of the quaternions (MB_HAS_QUAT): x (NV) is a screw coordinate itself and, for
   each quaternion, the rotation vector phi (rotated frame) with quat = base exp(phi / 2)
   (statemap.Chart); lag_base (NCOORD) is Python's chart base, lag_chart_limit the largest
   |phi| before the loop pauses for Python to re-centre the chart */
static __thread const double *lag_base = 0;
static __thread double lag_chart_limit = 1.0;
double atan2(double, double);

int lagrange_chart(const double *base, double limit) {
    lag_base = base; lag_chart_limit = limit;
    return 0;
}

/* q (NCOORD) of the chart coordinates x (NV). */
static void lag_to_q(const double *x, double *q) {
    for (int i = 0; i < NSCREW; ++i) q[SCREW_Q[i]] = x[SCREW_V[i]];
    for (int k = 0; k < NQUAT; ++k) mb_qstep(lag_base + QUAT_Q[k], x + QUAT_V[k], q + QUAT_Q[k]);
}

/* The chart coordinates x (NV) of q (NCOORD): the rotation vector of base^-1 q (the
   shorter way, rotations.quat_log). */
static void lag_to_x(const double *q, double *x) {
    for (int i = 0; i < NSCREW; ++i) x[SCREW_V[i]] = q[SCREW_Q[i]];
    for (int k = 0; k < NQUAT; ++k) {
        const double *a = lag_base + QUAT_Q[k], *b = q + QUAT_Q[k];
        const double na = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3]);
        const double nb = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2] + b[3] * b[3]);
        const double ac[4] = {a[0] / na, -a[1] / na, -a[2] / na, -a[3] / na};
        const double bn[4] = {b[0] / nb, b[1] / nb, b[2] / nb, b[3] / nb};
        double r[4];
        mb_qmul(ac, bn, r);
        if (r[0] < 0) for (int i = 0; i < 4; ++i) r[i] = -r[i];
        const double n = sqrt(r[1] * r[1] + r[2] * r[2] + r[3] * r[3]);
        const double scale = n < 1e-12 ? 2.0 / (r[0] > 1e-300 ? r[0] : 1e-300) : 2.0 * atan2(n, r[0]) / n;
        for (int i = 0; i < 3; ++i) x[QUAT_V[k] + i] = scale * r[1 + i];
    }
}

/* J_r(phi) (3 x 3, row-major): w = J_r(phi) phi' (statemap._right_jacobian). */
static void lag_right_jacobian(const double *phi, double *R) {
    const double theta = sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]);
    double a, b;
    if (theta < 1e-5) { a = 0.5 - theta * theta / 24; b = 1.0 / 6 - theta * theta / 120; }
    else { a = (1 - cos(theta)) / (theta * theta); b = (theta - sin(theta)) / (theta * theta * theta); }
    const double K[9] = {0.0, -phi[2], phi[1], phi[2], 0.0, -phi[0], -phi[1], phi[0], 0.0};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double kk = 0.0;
            for (int l = 0; l < 3; ++l) kk += K[i * 3 + l] * K[l * 3 + j];
            R[i * 3 + j] = (i == j ? 1.0 : 0.0) - a * K[i * 3 + j] + b * kk;
        }
}

/* The chart rates x' (NV) for speeds v: v on screws, J_r(phi)^-1 w on rotations. */
static void lag_chart_rate(const double *x, const double *v, double *rate) {
    for (int i = 0; i < NSCREW; ++i) rate[SCREW_V[i]] = v[SCREW_V[i]];
    for (int k = 0; k < NQUAT; ++k) {
        const int o = QUAT_V[k];
        double R[9];
        lag_right_jacobian(x + o, R);
        const double c0 = R[4] * R[8] - R[5] * R[7], c1 = R[5] * R[6] - R[3] * R[8], c2 = R[3] * R[7] - R[4] * R[6];
        const double det = R[0] * c0 + R[1] * c1 + R[2] * c2;
        const double inv[9] = {c0 / det, (R[2] * R[7] - R[1] * R[8]) / det, (R[1] * R[5] - R[2] * R[4]) / det,
                               c1 / det, (R[0] * R[8] - R[2] * R[6]) / det, (R[2] * R[3] - R[0] * R[5]) / det,
                               c2 / det, (R[1] * R[6] - R[0] * R[7]) / det, (R[0] * R[4] - R[1] * R[3]) / det};
        for (int i = 0; i < 3; ++i) rate[o + i] = inv[i * 3] * v[o] + inv[i * 3 + 1] * v[o + 1] + inv[i * 3 + 2] * v[o + 2];
    }
}

/* The largest |phi| of the chart coordinates x (0 without quaternions). */
static double lag_largest_rotation(const double *x) {
    double largest = 0.0;
    for (int k = 0; k < NQUAT; ++k) {
        const double *phi = x + QUAT_V[k];
        const double a = sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]);
        if (!(a <= largest)) largest = a;
    }
    return largest;
}
static __thread int *lag_piv;
static double lag_u[1];
/* motors prescribing their position by an expression of t (expressions_c.py): row r runs
   the programs at lag_pdata + prog[r] (s, s', s'' one after the other; prog[r] < 0: a speed
   motor); a non-finite value stops the Newton solve and writes t to lag_info[1] */
static __thread const long *lag_prog = 0;
static __thread const double *lag_pdata;
static __thread int lag_bad = 0;

int lagrange_positions(const long *prog, const double *programs) {
    lag_prog = prog; lag_pdata = programs;
    return 0;
}

/* Program k (0: s, 1: s', 2: s'') of motor row r at time t. */
static double lag_program(long r, int k, double t) {
    const double *pc = lag_pdata + lag_prog[r];
    for (int j = 0; j < k; ++j) pc += 1 + 2 * (long)pc[0];
    const double v = mb_program(&pc, t);
    if (!isfinite(v)) {
        lag_bad = 1;
        if (lag_info) lag_info[1] = t;
    }
    return v;
}

/* drive elements (no callables): their forces join tau; their LAG_NZ states follow the
   mechanical ones in the reduced state, y = [q_i, qd_i, z] */
#define LAG_NZ (DRIVES_SIZE - DRIVES_RATES_OFF)
static __thread int lag_drives = 0;
/* lag_dv (DRIVES_SIZE + 1): a per-thread buffer of the model's sizes unit (c_sizes.py) */

int lagrange_drives(int on) {
    lag_drives = on;
    return 0;
}

/* The drive elements' forces (and their states' rates) at (t, q, qd, z) into lag_dv (zero
   without drive elements). */
static const double *lag_drive_forces(double t, const double *q, const double *qd, const double *z,
                                      const double *p) {
    if (!lag_drives) {
        for (int i = 0; i < DRIVES_SIZE; ++i) lag_dv[i] = 0.0;
    } else {
        double buf[1 + LAG_NZ];
        drives(q, qd, p, mb_drive_u(t, z, buf), lag_dv);
    }
    return lag_dv + DRIVES_FORCES_OFF;
}
/* the contact watch: nk contacts, held[k] (1: a persistent row), gaps at the last accepted
   step (updated), tolerance; ev: [t_new, y_new, f_new, F (7 rows)] of an event step */
static __thread int lag_nk = 0;
/* the model's own contacts (the watched ones after them are collision features, collide.c) */
#define LAG_NK (CONTACTS_JACOBIAN_OFF - CONTACTS_GAP_OFF)
static __thread const long *lag_held;
static __thread double *lag_gaps, *lag_ev, lag_gap_tol;  /* lag_kc (CONTACTS_SIZE + 1): c_sizes.py */

int lagrange_watch(int nk, const long *held, double *gaps, double gap_tol, double *ev) {
    lag_nk = nk; lag_held = held; lag_gaps = gaps; lag_gap_tol = gap_tol; lag_ev = ev;
    return 0;
}

/* Configure this thread's reduced loop (nc < 0: switch it off and free the scratch).
   geo[r]: the generated constraint row of equation r, -1 for a motor row with coordinate
   mq[r], speed index mv[r], speed speed[r] and start value offset[r], or -2 - k for the gap
   of contact k (held closed).
   rows (nr), dep (nr), ind (ni): the partition.  acc: [t, q, qd, z] of the last accepted
   state (read and written).  info: [condition of the last accepted state, time at which a
   motor's prescribed position was not finite (written then)]. */
int lagrange_configure(int nc, const long *geo, const long *mq, const long *mv, const double *speed,
                       const double *offset, int nr, const long *rows, const long *dep, int ni, const long *ind,
                       int npr, const long *prows, const long *qdep, int nqi, const long *qind,
                       double scale, double limit, double *acc, double *info) {
    free(lag_mem);
    lag_mem = 0;
    lag_on = 0;
    lag_nk = 0;
    if (nc < 0) { lag_prog = 0; lag_info = 0; lag_base = 0; return 0; }
    const int n = NQ, m = nc > n ? nc : n;
    const long size = CONSTRAINTS_SIZE + 4L * nc + (long)nc * n + (long)nr * nr + nr + (long)nr * (ni + 1)
        + DYNAMICS_SIZE + (long)n * ni + (long)ni * ni + 2L * n + 2L * m * m + 6L * n + 8 + 2L * NCOORD + 2L * n
        + 2L * n + NCOORD + n + 8 + (long)npr * npr + npr;
    lag_mem = malloc(sizeof(double) * size);
    if (!lag_mem) return -4;
    double *w = lag_mem;
    lag_c = w; w += CONSTRAINTS_SIZE;
    lag_g = w; w += nc;
    lag_J = w; w += (long)nc * n;
    lag_gt = w; w += nc;
    lag_bias = w; w += nc;
    lag_lu = w; w += (long)nr * nr;
    lag_piv = (int *)w; w += nr;
    lag_X = w; w += (long)nr * (ni + 1);
    lag_dyn = w; w += DYNAMICS_SIZE;
    lag_MB = w; w += (long)n * ni;
    lag_Mr = w; w += (long)ni * ni;
    lag_h = w; w += n;
    lag_v = w; w += n;
    lag_eig = w; w += 2L * m * m + 6L * n + 8;
    lag_q = w; w += 2L * NCOORD;
    lag_qd = w; w += 2L * n;
    lag_x = w; w += n;
    lag_rate = w; w += n;
    lag_end = w; w += NCOORD + n;
    lag_plu = w; w += (long)npr * npr;
    lag_ppiv = (int *)w; w += npr;
    lag_span = 0;
    lag_nc = nc; lag_geo = geo; lag_mq = mq; lag_mv = mv; lag_speed = speed; lag_offset = offset;
    lag_nr = nr; lag_rows = rows; lag_dep = dep; lag_ni = ni; lag_ind = ind;
    lag_npr = npr; lag_prows = prows; lag_qdep = qdep; lag_nqi = nqi; lag_qind = qind;
    lag_scale = scale; lag_limit = limit; lag_acc = acc; lag_info = info;
    lag_on = 1;
    return 0;
}

/* g, J, g_t and bias of every equation at (q, qd, t); 1 when a motor's prescribed
   position is not finite at t (lag_info[1] = t), else 0. */
static int lag_values(double t, const double *q, const double *qd, const double *p) {
    lag_bad = 0;
    constraints(q, qd, p, lag_u, lag_c);
    if (lag_nk && MB_HAS_CONTACTS) contacts(q, qd, p, lag_u, lag_kc);
    for (int r = 0; r < lag_nc; ++r)
        if (lag_geo[r] <= -2 - LAG_NK) {  /* a held collision feature: measure the candidates (collide.c) */
            mb_collide_eval(q, qd, p);
            break;
        }
    for (int r = 0; r < lag_nc; ++r) {
        double *Jr = lag_J + (long)r * NQ;
        const long j = lag_geo[r];
        if (j <= -2 - LAG_NK) {  /* a collision feature held closed */
            lag_gt[r] = 0.0;
            if (mb_collide_row(-2 - j - LAG_NK, lag_g + r, Jr, lag_bias + r)) {
                lag_g[r] = lag_bias[r] = NAN;
                for (int i = 0; i < NQ; ++i) Jr[i] = 0.0;
            }
        } else if (j <= -2) {  /* a contact held closed: its gap */
            const long k = -2 - j;
            lag_g[r] = lag_kc[CONTACTS_GAP_OFF + k];
            for (int i = 0; i < NQ; ++i) Jr[i] = lag_kc[CONTACTS_JACOBIAN_OFF + k * NQ + i];
            lag_gt[r] = 0.0;
            lag_bias[r] = lag_kc[CONTACTS_BIAS_OFF + k];
        } else if (j >= 0) {
            lag_g[r] = lag_c[CONSTRAINTS_RESIDUAL_OFF + j];
            for (int i = 0; i < NQ; ++i) Jr[i] = lag_c[CONSTRAINTS_JACOBIAN_OFF + j * NQ + i];
            lag_gt[r] = 0.0;
            lag_bias[r] = lag_c[CONSTRAINTS_BIAS_OFF + j];
        } else {
            for (int i = 0; i < NQ; ++i) Jr[i] = 0.0;
            Jr[lag_mv[r]] = 1.0;
            if (lag_prog && lag_prog[r] >= 0) {  /* q_k - s(t) */
                lag_g[r] = q[lag_mq[r]] - lag_program(r, 0, t);
                lag_gt[r] = -lag_program(r, 1, t);
                lag_bias[r] = -lag_program(r, 2, t);
            } else {
                lag_g[r] = q[lag_mq[r]] - lag_offset[r] - lag_speed[r] * t;
                lag_gt[r] = -lag_speed[r];
                lag_bias[r] = 0.0;
            }
        }
    }
    return lag_bad;
}

/* LU factorisation with partial pivoting of the dependent block J[rows][:, dep] into lag_lu;
   1 when it is exactly singular (as numpy's solve reports). */
static int lag_factor_block(int n, const long *rows, const long *dep, double *A, int *pivots) {
    for (int a = 0; a < n; ++a)
        for (int b = 0; b < n; ++b) A[a * n + b] = lag_J[rows[a] * NQ + dep[b]];
    for (int k = 0; k < n; ++k) {
        int piv = k;
        double best = fabs(A[k * n + k]);
        for (int i = k + 1; i < n; ++i) if (fabs(A[i * n + k]) > best) { best = fabs(A[i * n + k]); piv = i; }
        pivots[k] = piv;
        if (!(best > 0.0)) return 1;
        if (piv != k)
            for (int j = 0; j < n; ++j) { double s = A[k * n + j]; A[k * n + j] = A[piv * n + j]; A[piv * n + j] = s; }
        for (int i = k + 1; i < n; ++i) {
            const double l = A[i * n + k] / A[k * n + k];
            A[i * n + k] = l;
            for (int j = k + 1; j < n; ++j) A[i * n + j] -= l * A[k * n + j];
        }
    }
    return 0;
}

static int lag_factor(void) {
    return lag_factor_block(lag_nr, lag_rows, lag_dep, lag_lu, lag_piv);
}

/* b <- A^-1 b with the factors of lag_factor_block. */
static void lag_solve_block(int n, const double *A, const int *pivots, double *b) {
    for (int k = 0; k < n; ++k) if (pivots[k] != k) { double s = b[k]; b[k] = b[pivots[k]]; b[pivots[k]] = s; }
    for (int i = 0; i < n; ++i) { double s = b[i]; for (int k = 0; k < i; ++k) s -= A[i * n + k] * b[k]; b[i] = s; }
    for (int i = n - 1; i >= 0; --i) {
        double s = b[i];
        for (int k = i + 1; k < n; ++k) s -= A[i * n + k] * b[k];
        b[i] = s / A[i * n + i];
    }
}

/* b <- J_d^-1 b with the factors of lag_factor. */
static void lag_solve(double *b) {
    lag_solve_block(lag_nr, lag_lu, lag_piv, b);
}

/* Full q (NCOORD) and qd (NV) at time t from the reduced state y = [x_i, qd_i] (the
   independent chart coordinates, which are the coordinates themselves without quaternions):
   Newton from the last accepted state advanced by its speeds.  Leaves J (speed space, and
   the LU of J_d) at q and the chart coordinates in lag_x.  Returns 0 or LAG_TRIAL. */
int lagrange_full(double t, const double *y, double *q, double *qd, const double *p) {
    const int nr = lag_nr, ni = lag_ni, npr = lag_npr, nqi = lag_nqi;
    const double ta = lag_acc[0], *qa = lag_acc + 1, *va = lag_acc + 1 + NCOORD;
    double *s = lag_h, *x = lag_x;
    const int span = lag_span && lag_t_end > ta;
    const double h = lag_t_end - ta, u = span ? (t - ta) / h : 0.0, u2 = u * u, u3 = u2 * u;
    const double h00 = 2 * u3 - 3 * u2 + 1, h10 = (u3 - 2 * u2 + u) * h, h01 = -2 * u3 + 3 * u2, h11 = (u3 - u2) * h;
    const double *qe = lag_end, *ve = lag_end + NCOORD;
    if (MB_HAS_QUAT) {  /* the predictor in the chart: q_a advanced along v_a (or the nearer end of an output's step), then x */
        const int from_end = span && u > 0.5;
        const double *q0 = from_end ? qe : qa, *v0 = from_end ? ve : va, dt = t - (from_end ? lag_t_end : ta);
        for (int i = 0; i < NSCREW; ++i)
            q[SCREW_Q[i]] = span ? h00 * qa[SCREW_Q[i]] + h10 * va[SCREW_V[i]] + h01 * qe[SCREW_Q[i]] + h11 * ve[SCREW_V[i]]
                                 : qa[SCREW_Q[i]] + va[SCREW_V[i]] * (t - ta);
        for (int k = 0; k < NQUAT; ++k) {
            double phi[3];
            for (int i = 0; i < 3; ++i) phi[i] = v0[QUAT_V[k] + i] * dt;
            mb_qstep(q0 + QUAT_Q[k], phi, q + QUAT_Q[k]);
        }
        lag_to_x(q, x);
        for (int k = 0; k < nqi; ++k) x[lag_qind[k]] = y[k];
        lag_to_q(x, q);
    } else if (span) {
        for (int i = 0; i < NQ; ++i) q[i] = h00 * qa[i] + h10 * va[i] + h01 * qe[i] + h11 * ve[i];
        for (int k = 0; k < nqi; ++k) q[lag_qind[k]] = y[k];
    } else {
        for (int i = 0; i < NQ; ++i) q[i] = qa[i] + va[i] * (t - ta);
        for (int k = 0; k < nqi; ++k) q[lag_qind[k]] = y[k];
    }
    for (int i = 0; i < NQ; ++i) lag_v[i] = 0.0;
    int converged = 0;
    for (int it = 0; it < LAG_NEWTON_ITER; ++it) {
        if (lag_values(t, q, lag_v, p)) return LAG_TRIAL;
        double gmax = 0.0;
        for (int a = 0; a < npr; ++a) { const double e = fabs(lag_g[lag_prows[a]]); if (!(e <= gmax)) gmax = e; }
        if (gmax < LAG_NEWTON_TOL) { converged = 1; break; }
        if (MB_HAS_QUAT)  /* Newton in the chart: J dv/dx = J D, D = J_r(phi) on each rotation */
            for (int k = 0; k < NQUAT; ++k) {
                const int o = QUAT_V[k];
                double R[9];
                lag_right_jacobian(x + o, R);
                for (int a = 0; a < npr; ++a) {
                    double *Jr = lag_J + lag_prows[a] * NQ + o;
                    const double j0 = Jr[0], j1 = Jr[1], j2 = Jr[2];
                    for (int c = 0; c < 3; ++c) Jr[c] = j0 * R[c] + j1 * R[3 + c] + j2 * R[6 + c];
                }
            }
        if (lag_factor_block(npr, lag_prows, lag_qdep, lag_plu, lag_ppiv)) return LAG_TRIAL;
        for (int a = 0; a < npr; ++a) s[a] = lag_g[lag_prows[a]];
        lag_solve_block(npr, lag_plu, lag_ppiv, s);
        if (MB_HAS_QUAT) {
            for (int a = 0; a < npr; ++a) x[lag_qdep[a]] -= s[a];
            lag_to_q(x, q);
        } else {
            for (int a = 0; a < npr; ++a) q[lag_qdep[a]] -= s[a];
        }
    }
    if (!converged) return LAG_TRIAL;
    for (int i = 0; i < NQ; ++i) qd[i] = 0.0;
    for (int k = 0; k < ni; ++k) qd[lag_ind[k]] = y[nqi + k];
    if (nr) {
        if (lag_factor()) return LAG_TRIAL;
        for (int a = 0; a < nr; ++a) {
            const double *Jr = lag_J + lag_rows[a] * NQ;
            double v = lag_gt[lag_rows[a]];
            for (int k = 0; k < ni; ++k) v += Jr[lag_ind[k]] * y[nqi + k];
            s[a] = -v;
        }
        lag_solve(s);
        for (int a = 0; a < nr; ++a) qd[lag_dep[a]] = s[a];
    }
    return 0;
}

/* Before the output times of a step to (t_end, y_end): its end state (by the usual predictor
   from the accepted state, as the step's own evaluation there) becomes the other end of
   the outputs' Hermite predictor.  Returns 0 or LAG_TRIAL. */
int lagrange_span(double t_end, const double *y_end, const double *p) {
    lag_span = 0;
    const int status = lagrange_full(t_end, y_end, lag_end, lag_end + NCOORD, p);
    if (status) return status;
    lag_t_end = t_end;
    lag_span = 1;
    return 0;
}

/* After the output times of a step: the predictor is the accepted state's again. */
void lagrange_span_end(void) {
    lag_span = 0;
}

/* Friction on held contacts (friction.h): qdd_i from the full KKT system with the friction
   rows, as the Python path's solve_friction (the partition gives the state and its speeds;
   the accelerations satisfy every held row, the normal ones and a sticking contact's
   tangential ones, at the acceleration level).  The multipliers of every equation stay in
   the friction scratch (mb_fr_lam) for the held contacts' forces.  Returns 0, 1 (M not
   positive definite) or the friction solve's failure. */
static int lag_friction_rhs(double t, const double *q, const double *qd, const double *p, const double *tau,
                            const double *drive, double *f) {
    const int n = NQ, nc = lag_nc;
    const double *M = lag_dyn + DYNAMICS_MASS_MATRIX_OFF, *force = lag_dyn + DYNAMICS_FORCES_OFF;
    double *L = mb_fr_aux(), *u = L + n * (n + 1) / 2, *qdd = u + n, *rhs = qdd + n, *lam = rhs + nc;
    for (int i = 0; i < n * (n + 1) / 2; ++i) L[i] = M[i];
    if (mass_cholesky(L)) return 1;
    for (int i = 0; i < n; ++i) u[i] = force[i] + drive[i] + (tau ? tau[i] : 0.0);
    lower_solve(L, u);
    for (int r = 0; r < nc; ++r) rhs[r] = -lag_bias[r];
    const int status = mb_friction_solve(t, q, qd, p, L, u, nc, lag_J, rhs, qdd, lam);
    if (status) return status;
    for (int k = 0; k < lag_ni; ++k) f[lag_nqi + k] = qdd[lag_ind[k]];
    return 0;
}

/* A failed lagrange_rhs as the loop's status: a failed friction solve (Painleve) stops the
   run (-2: Python reads the failure record), anything else is a failed trial state. */
static int lag_failed(int status) {
    if (status == MB_FR_PAINLEVE || status == MB_FR_INCONSISTENT) return -2;
    return status < 0 ? status : LAG_TRIAL;
}

/* The multipliers of every equation of the last lag_friction_rhs. */
static double *lag_friction_lam(void) {
    return mb_fr_aux() + NQ * (NQ + 1) / 2 + 2 * NQ + lag_nc;
}

/* f = [qd_i, qdd_i] at (t, y): returns 0, 1 (reduced mass matrix not positive definite)
   or LAG_TRIAL. */
int lagrange_rhs(double t, const double *y, double *f, const double *p, const double *tau) {
    const int nr = lag_nr, ni = lag_ni, nqi = lag_nqi, n = NQ;
    double *q = lag_q, *qd = lag_qd;
    int status = lagrange_full(t, y, q, qd, p);
    if (mb_mo_failed) return MB_INPUT_FAILED;  /* a callable motor's callback failed (inputs.h) */
    if (status) return status;
    if (lag_values(t, q, qd, p)) return LAG_TRIAL;  /* the bias at these speeds (J, and J_d's factors, unchanged) */
    double tau_buf[NQ + 1];
    if (MB_CALLBACKS) {  /* Python callables (inputs.h) at this full state */
        if (mb_inputs(t, q, qd, lag_drives ? y + nqi + ni : 0)) return MB_INPUT_FAILED;
        tau = mb_input_tau(tau, tau_buf);
    }
    if (nr == 0 && lag_nc == 0 && ni == n && !HAS_DRIVES) {
        /* no row held (colliding shapes apart): the tree's own accelerations, by the recursive
           program where the model has it, instead of the dense reduced solve */
        double *qdd = lag_eig;
        if (accelerations(q, qd, p, mb_input_u(), tau, qdd, lag_dyn)) return 1;
        for (int k = 0; k < ni; ++k) f[nqi + k] = qdd[lag_ind[k]];
        if (MB_HAS_QUAT) {
            lag_chart_rate(lag_x, qd, lag_rate);
            for (int k = 0; k < nqi; ++k) f[k] = lag_rate[lag_qind[k]];
        } else {
            for (int k = 0; k < nqi; ++k) f[k] = qd[lag_qind[k]];
        }
        return 0;
    }
    dynamics(q, qd, p, mb_input_u(), lag_dyn);
    const double *M = lag_dyn + DYNAMICS_MASS_MATRIX_OFF, *force = lag_dyn + DYNAMICS_FORCES_OFF;
    const double *drive = lag_drive_forces(t, q, qd, y + nqi + ni, p);
    if (mb_fr_n > 0) {
        const int fs = lag_friction_rhs(t, q, qd, p, tau, drive, f);
        if (fs) return fs;
        goto rates;
    }
    double *X = lag_X, *col = lag_v, *h = lag_h;
    for (int k = 0; k <= ni; ++k) {  /* X = J_d^-1 [J_i, bias] (column k stored X[a * (ni + 1) + k]) */
        for (int a = 0; a < nr; ++a)
            col[a] = k < ni ? lag_J[lag_rows[a] * NQ + lag_ind[k]] : lag_bias[lag_rows[a]];
        if (nr) lag_solve(col);
        for (int a = 0; a < nr; ++a) X[a * (ni + 1) + k] = col[a];
    }
    /* h = f + tau - M c, with c = -X[:, ni] on the dependent speeds */
    for (int i = 0; i < n; ++i) {
        double s = force[i] + drive[i] + (tau ? tau[i] : 0.0);
        for (int a = 0; a < nr; ++a) s += LAG_MIJ(M, i, lag_dep[a]) * X[a * (ni + 1) + ni];
        h[i] = s;
    }
    /* M B: column l is M e_ind[l] - sum_a X[a, l] M e_dep[a] */
    for (int l = 0; l < ni; ++l)
        for (int i = 0; i < n; ++i) {
            double s = LAG_MIJ(M, i, lag_ind[l]);
            for (int a = 0; a < nr; ++a) s -= X[a * (ni + 1) + l] * LAG_MIJ(M, i, lag_dep[a]);
            lag_MB[i * ni + l] = s;
        }
    double *Mr = lag_Mr, *r = f + nqi, scale = 1e-300;
    for (int k = 0; k < ni; ++k) {  /* B^T (M B) and B^T h */
        for (int l = 0; l <= k; ++l) {
            double s = lag_MB[lag_ind[k] * ni + l];
            for (int a = 0; a < nr; ++a) s -= X[a * (ni + 1) + k] * lag_MB[lag_dep[a] * ni + l];
            Mr[k * ni + l] = s;
        }
        double s = h[lag_ind[k]];
        for (int a = 0; a < nr; ++a) s -= X[a * (ni + 1) + k] * h[lag_dep[a]];
        r[k] = s;
        if (fabs(Mr[k * ni + k]) > scale) scale = fabs(Mr[k * ni + k]);
    }
    /* Cholesky, with the tree solve's singularity threshold */
    if (mb_cholesky(Mr, ni, ni, MB_PIVOT_TOLERANCE * scale, 0)) return 1;
    mb_cholesky_solve(Mr, ni, ni, r, r);
rates:
    if (MB_HAS_QUAT) {  /* x' of the independent chart coordinates */
        lag_chart_rate(lag_x, qd, lag_rate);
        for (int k = 0; k < nqi; ++k) f[k] = lag_rate[lag_qind[k]];
    } else {  /* (a dependent speed where velocity rows leave the coordinate independent) */
        for (int k = 0; k < nqi; ++k) f[k] = qd[lag_qind[k]];
    }
    for (int k = 0; k < LAG_NZ; ++k) f[nqi + ni + k] = lag_dv[DRIVES_RATES_OFF + k];
    return 0;
}

/* Smallest and largest eigenvalue of the symmetric n x n matrix A (destroyed): cyclic Jacobi
   (mb_jacobi_eigen, least_norm.h), the eigenvalues left on A's diagonal. */
static void lag_eig_range(double *A, int n, double *lo, double *hi) {
    mb_jacobi_eigen(n, A, n, NULL, NULL, 0);
    double l = INFINITY, h = -INFINITY;
    for (int i = 0; i < n; ++i) { if (A[i * n + i] < l) l = A[i * n + i]; if (A[i * n + i] > h) h = A[i * n + i]; }
    *lo = l; *hi = h;
}

/* The dependent block's condition against the Jacobian's size (as LagrangeWorkspace.condition),
   from J as lag_values left it. */
static double lag_condition(void) {
    const int nr = lag_nr, nc = lag_nc, n = NQ;
    double lo, hi, *A = lag_eig;
    for (int a = 0; a < nr; ++a)  /* J_d^T J_d */
        for (int b = 0; b < nr; ++b) {
            double s = 0.0;
            for (int k = 0; k < nr; ++k) s += lag_J[lag_rows[k] * NQ + lag_dep[a]] * lag_J[lag_rows[k] * NQ + lag_dep[b]];
            A[a * nr + b] = s;
        }
    lag_eig_range(A, nr, &lo, &hi);
    const double smallest = lo > 0.0 ? sqrt(lo) : 0.0;
    const int m = nc < n ? nc : n;
    for (int a = 0; a < m; ++a)  /* the smaller of J J^T and J^T J */
        for (int b = 0; b < m; ++b) {
            double s = 0.0;
            if (nc < n) for (int k = 0; k < n; ++k) s += lag_J[a * NQ + k] * lag_J[b * NQ + k];
            else for (int k = 0; k < nc; ++k) s += lag_J[k * NQ + a] * lag_J[k * NQ + b];
            A[a * m + b] = s;
        }
    lag_eig_range(A, m, &lo, &hi);
    double largest = hi > 0.0 ? sqrt(hi) : 0.0;
    if (lag_scale > largest) largest = lag_scale;
    return smallest > 0.0 ? largest / smallest : INFINITY;
}

/* An upper bound of lag_condition() from J and the LU factors of J_d as lagrange_full left
   them: the largest eigenvalue of a symmetric matrix is at most its largest absolute row
   sum, so |J|_2 <= sqrt(|J J^T|_inf) and 1 / sigma_min(J_d) <= sqrt(|J_d^-1 J_d^-T|_inf); at
   the cost of nr triangular solves and two small products instead of two Jacobi
   eigenvalue computations. */
static double lag_condition_bound(void) {
    const int nr = lag_nr, nc = lag_nc;
    double largest = 0.0, inverse = 0.0, *X = lag_eig, *e = lag_eig + (long)nr * nr;
    for (int a = 0; a < nc; ++a) {  /* the rows of J J^T */
        const double *Ja = lag_J + (long)a * NQ;
        double sum = 0.0;
        for (int b = 0; b < nc; ++b) {
            const double *Jb = lag_J + (long)b * NQ;
            double v = 0.0;
            for (int i = 0; i < NQ; ++i) v += Ja[i] * Jb[i];
            sum += fabs(v);
        }
        if (sum > largest) largest = sum;
    }
    largest = sqrt(largest);
    if (lag_scale > largest) largest = lag_scale;
    for (int c = 0; c < nr; ++c) {  /* X = J_d^-1, column c at X[a * nr + c] */
        for (int a = 0; a < nr; ++a) e[a] = a == c ? 1.0 : 0.0;
        lag_solve(e);
        for (int a = 0; a < nr; ++a) X[a * nr + c] = e[a];
    }
    for (int a = 0; a < nr; ++a) {  /* the rows of X X^T */
        double sum = 0.0;
        for (int b = 0; b < nr; ++b) {
            double v = 0.0;
            for (int k = 0; k < nr; ++k) v += X[a * nr + k] * X[b * nr + k];
            sum += fabs(v);
        }
        if (sum > inverse) inverse = sum;
    }
    const double bound = largest * sqrt(inverse);
    return bound == bound ? bound : INFINITY;
}

/* After an accepted step to (t, y): the full state becomes the accepted one (written to
   out, NQ + NQ + LAG_NZ, when out is not NULL); returns LAG_PAUSED when the dependent block's
   condition reached the limit (Python looks for a better partition), 0, or LAG_TRIAL. */
int lagrange_accept(double t, const double *y, double *out, const double *p) {
    double *q = lag_q + NCOORD, *qd = lag_qd + NQ;
    int status = lagrange_full(t, y, q, qd, p);
    if (status) return status;
    lag_acc[0] = t;
    mb_copy(lag_acc + 1, q, sizeof(double) * NCOORD);
    mb_copy(lag_acc + 1 + NCOORD, qd, sizeof(double) * NQ);
    for (int k = 0; k < LAG_NZ; ++k) lag_acc[1 + NCOORD + NQ + k] = y[lag_nqi + lag_ni + k];
    if (out) {
        mb_copy(out, q, sizeof(double) * NCOORD);
        mb_copy(out + NCOORD, qd, sizeof(double) * NQ);
        for (int k = 0; k < LAG_NZ; ++k) out[NCOORD + NQ + k] = y[lag_nqi + lag_ni + k];
    }
    if (MB_HAS_QUAT && lag_largest_rotation(lag_x) > lag_chart_limit) return LAG_PAUSED;  /* Python re-centres the chart */
    if (!lag_nr) return 0;
    const double bound = lag_condition_bound();  /* J and J_d's factors at q from lagrange_full */
    if (bound < lag_limit) {  /* clearly conditioned: the exact value (two eigenvalue sweeps) is not needed */
        lag_info[0] = bound;
        return 0;
    }
    const double condition = lag_condition();
    lag_info[0] = condition;
    return condition < lag_limit ? 0 : LAG_PAUSED;
}

/* The multipliers of the chosen rows at (t, y) (*lam: nr values in scratch), from
   J_r^T lam = M qdd - f - tau (least squares): the held contacts' normal forces among them.
   Returns 0, 1 (rows dependent: cannot happen for chosen rows) or LAG_TRIAL. */
static int lag_held_forces(double t, const double *y, const double *p, const double *tau, double **lam_out) {
    const int nr = lag_nr, ni = lag_ni, nqi = lag_nqi, n = NQ;
    double *f = lag_eig + 0, *qdd = lag_eig + 2 * NQ, *res = lag_eig + 3 * NQ;
    double *A = lag_eig + 4 * NQ, *lam = A + (long)nr * nr;
    int status = lagrange_rhs(t, y, f, p, tau);  /* leaves M, f, the drive forces, X, J at this state */
    if (status) return lag_failed(status);
    double tau_buf[NQ + 1];
    tau = mb_input_tau(tau, tau_buf);  /* (with a callable tau: its values at this state, just evaluated) */
    if (mb_fr_n > 0) {  /* with friction: the friction solve's multipliers (J^T lam is not all of M qdd - f) */
        const double *all = lag_friction_lam();
        for (int a = 0; a < nr; ++a) lam[a] = all[lag_rows[a]];
        *lam_out = lam;
        return 0;
    }
    const double *M = lag_dyn + DYNAMICS_MASS_MATRIX_OFF, *force = lag_dyn + DYNAMICS_FORCES_OFF;
    const double *drive = lag_dv + DRIVES_FORCES_OFF;
    for (int i = 0; i < n; ++i) qdd[i] = 0.0;
    for (int k = 0; k < ni; ++k) qdd[lag_ind[k]] = f[nqi + k];
    for (int a = 0; a < nr; ++a) {
        double v = -lag_X[a * (ni + 1) + ni];
        for (int k = 0; k < ni; ++k) v -= lag_X[a * (ni + 1) + k] * f[nqi + k];
        qdd[lag_dep[a]] = v;
    }
    for (int i = 0; i < n; ++i) {
        double v = -force[i] - drive[i] - (tau ? tau[i] : 0.0);
        for (int j = 0; j < n; ++j) v += LAG_MIJ(M, i, j) * qdd[j];
        res[i] = v;
    }
    for (int a = 0; a < nr; ++a) {  /* Gram matrix J_r J_r^T (lower) and J_r res */
        const double *Ja = lag_J + lag_rows[a] * NQ;
        for (int b = 0; b <= a; ++b) {
            const double *Jb = lag_J + lag_rows[b] * NQ;
            double v = 0.0;
            for (int i = 0; i < n; ++i) v += Ja[i] * Jb[i];
            A[a * nr + b] = v;
        }
        double v = 0.0;
        for (int i = 0; i < n; ++i) v += Ja[i] * res[i];
        lam[a] = v;
    }
    if (mb_cholesky(A, nr, nr, 0.0, 0)) return 1;
    mb_cholesky_solve(A, nr, nr, lam, lam);
    *lam_out = lam;
    return 0;
}

#include "dop853_dense.h"

/* Locating an event on its step (Python's root finder calls these): the gap of contact k
   (m), or the normal force (N) of the held contact whose row is `row`, at time s of the
   event step; NaN when the state cannot be found there.  The loop must have stopped at
   the step (the accepted state is its start). */
double lagrange_gap_at(double s, double t_old, double h, const double *y_old, const double *F, int ny, long k,
                       const double *p) {
    double y[2 * NQ + LAG_NZ + 1];
    mb_dop853_dense(s, t_old, h, y_old, F, ny, y);
    double *q = lag_q + NCOORD, *qd = lag_qd + NQ;
    if (lagrange_full(s, y, q, qd, p)) return NAN;
    if (k >= LAG_NK) return mb_collide_gap(k - LAG_NK, q, qd, p);  /* a collision feature */
    contacts(q, qd, p, lag_u, lag_kc);
    return lag_kc[CONTACTS_GAP_OFF + k];
}

double lagrange_force_at(double s, double t_old, double h, const double *y_old, const double *F, int ny, long row,
                         const double *p, const double *tau) {
    double y[2 * NQ + LAG_NZ + 1], *lam;
    mb_dop853_dense(s, t_old, h, y_old, F, ny, y);
    if (lag_held_forces(s, y, p, tau, &lam)) return NAN;
    for (int a = 0; a < lag_nr; ++a) if (lag_rows[a] == row) return lam[a];
    return 0.0;
}

/* Friction events on the event step: sticking contact j's distance outside the cone (N,
   from the friction solve at time s) and sliding contact j's slip velocity (m/s) along the
   tangent-coordinate direction (e0, e1) at time s; NaN when the state cannot be found. */
double lagrange_cone_at(double s, double t_old, double h, const double *y_old, const double *F, int ny, long j,
                        const double *p, const double *tau) {
    double y[2 * NQ + LAG_NZ + 1], *lam;
    mb_dop853_dense(s, t_old, h, y_old, F, ny, y);
    if (lag_held_forces(s, y, p, tau, &lam)) return NAN;
    return mb_friction_margin((int)j);
}

double lagrange_slip_at(double s, double t_old, double h, const double *y_old, const double *F, int ny, long j,
                        const double *p, double e0, double e1) {
    double y[2 * NQ + LAG_NZ + 1];
    mb_dop853_dense(s, t_old, h, y_old, F, ny, y);
    double *q = lag_q + NCOORD, *qd = lag_qd + NQ;
    if (lagrange_full(s, y, q, qd, p)) return NAN;
    return mb_friction_along((int)j, q, qd, p, e0, e1);
}

/* The event's time on its step by Brent's method in C (codegen/c/brentq.h, as scipy's
   brentq): where the gap of contact `index` (lagrange_gap_root), the normal force of the
   held contact whose row is `index` (lagrange_force_root), sticking contact `index`'s
   distance outside the cone (lagrange_cone_root) or sliding contact `index`'s slip along
   (e0, e1) (lagrange_slip_root) crosses zero in [a, b]; *status as mb_brentq's (3: the
   state could not be found at a trial time). */
struct lag_root_ctx { double t_old, h; const double *y_old, *F; int ny; long index; const double *p, *tau; double e0, e1; };

static double lag_gap_fn(double s, void *c) {
    const struct lag_root_ctx *x = c;
    return lagrange_gap_at(s, x->t_old, x->h, x->y_old, x->F, x->ny, x->index, x->p);
}

static double lag_force_fn(double s, void *c) {
    const struct lag_root_ctx *x = c;
    return lagrange_force_at(s, x->t_old, x->h, x->y_old, x->F, x->ny, x->index, x->p, x->tau);
}

static double lag_cone_fn(double s, void *c) {
    const struct lag_root_ctx *x = c;
    return lagrange_cone_at(s, x->t_old, x->h, x->y_old, x->F, x->ny, x->index, x->p, x->tau);
}

static double lag_slip_fn(double s, void *c) {
    const struct lag_root_ctx *x = c;
    return lagrange_slip_at(s, x->t_old, x->h, x->y_old, x->F, x->ny, x->index, x->p, x->e0, x->e1);
}

double lagrange_gap_root(double a, double b, double t_old, double h, const double *y_old, const double *F, int ny,
                         long index, const double *p, double xtol, double rtol, int *status) {
    struct lag_root_ctx c = {t_old, h, y_old, F, ny, index, p, 0, 0.0, 0.0};
    return mb_brentq(lag_gap_fn, &c, a, b, xtol, rtol, MB_BRENTQ_ITERATIONS, status);
}

double lagrange_force_root(double a, double b, double t_old, double h, const double *y_old, const double *F, int ny,
                           long index, const double *p, const double *tau, double xtol, double rtol, int *status) {
    struct lag_root_ctx c = {t_old, h, y_old, F, ny, index, p, tau, 0.0, 0.0};
    return mb_brentq(lag_force_fn, &c, a, b, xtol, rtol, MB_BRENTQ_ITERATIONS, status);
}

double lagrange_cone_root(double a, double b, double t_old, double h, const double *y_old, const double *F, int ny,
                          long index, const double *p, const double *tau, double xtol, double rtol, int *status) {
    struct lag_root_ctx c = {t_old, h, y_old, F, ny, index, p, tau, 0.0, 0.0};
    return mb_brentq(lag_cone_fn, &c, a, b, xtol, rtol, MB_BRENTQ_ITERATIONS, status);
}

double lagrange_slip_root(double a, double b, double t_old, double h, const double *y_old, const double *F, int ny,
                          long index, const double *p, double e0, double e1, double xtol, double rtol, int *status) {
    struct lag_root_ctx c = {t_old, h, y_old, F, ny, index, p, 0, e0, e1};
    return mb_brentq(lag_slip_fn, &c, a, b, xtol, rtol, MB_BRENTQ_ITERATIONS, status);
}

/* The contact watch after an accepted step to (t, y) (before it is taken): 1 when a free
   contact's gap closed in the step or a held contact's force would pull at its end (the
   step is an event step), 0 otherwise (the gaps become the accepted ones), or LAG_TRIAL. */
int lagrange_event(double t, const double *y, const double *p, const double *tau) {
    const int nr = lag_nr;
    double *q = lag_q + NCOORD, *qd = lag_qd + NQ;
    int status = lagrange_full(t, y, q, qd, p);
    if (status) return status;
    const int own = lag_nk < LAG_NK ? lag_nk : LAG_NK, features = lag_nk > LAG_NK && mb_collide_count();
    if (MB_HAS_CONTACTS) contacts(q, qd, p, lag_u, lag_kc);
    if (features) mb_collide_eval(q, qd, p);  /* the candidate collision features (collide.c) */
    const double *gap = lag_kc + CONTACTS_GAP_OFF;
    int event = 0, held = 0;
    for (int k = 0; k < lag_nk; ++k) {
        if (lag_held[k]) { held = 1; continue; }
        const double g0 = lag_gaps[k], g1 = k < own ? gap[k] : mb_collide_gap_of(k - LAG_NK);
        if ((g1 < 0.0 && 0.0 <= g0) || (g1 < -lag_gap_tol && -lag_gap_tol < g0)) event = 1;
    }
    if (!event && held && nr) {  /* the held contacts' forces */
        double *lam;
        status = lag_held_forces(t, y, p, tau, &lam);
        if (status) return status;
        double most = 0.0;  /* a held force pulling (beyond rounding: MB_FORCE_ROUNDING) */
        for (int a = 0; a < nr; ++a)
            if (lag_geo[lag_rows[a]] <= -2 && fabs(lam[a]) > most) most = fabs(lam[a]);
        for (int a = 0; a < nr; ++a)
            if (lag_geo[lag_rows[a]] <= -2 && lam[a] < -MB_FORCE_ROUNDING * most) event = 1;
    }
    if (!event && mb_fr_n > 0) {  /* friction modes: from a solve at (t, y) */
        if (!(held && nr)) {
            status = lagrange_rhs(t, y, lag_eig, p, tau);
            if (status) return lag_failed(status);
        }
        event = mb_friction_event();
    }
    if (!event && features && mb_collide_leaves()) event = 1;  /* a new broad phase: Python finds no event */
    if (!event)
        for (int k = 0; k < lag_nk; ++k) {
            const double g1 = k < own ? gap[k] : mb_collide_gap_of(k - LAG_NK);
            if (g1 == g1) lag_gaps[k] = g1;  /* (a feature that is not a candidate keeps its bound) */
        }
    return event;
}

/* No degree of freedom: the full state at each of the n times t_out (rows of NCOORD + NQ
   in out), each Newton continued from the previous one.  Returns 0, or LAG_TRIAL with
   *done the rows written. */
int lagrange_prescribed(const double *p, long n, const double *t_out, double *out, long *done) {
    for (long k = 0; k < n; ++k) {
        double *row = out + k * (NCOORD + NQ);
        int status = lagrange_full(t_out[k], lag_u, row, row + NCOORD, p);
        if (status) return status;
        lag_acc[0] = t_out[k];
        mb_copy(lag_acc + 1, row, sizeof(double) * (NCOORD + NQ));
        *done = k + 1;
    }
    return 0;
}
#endif
