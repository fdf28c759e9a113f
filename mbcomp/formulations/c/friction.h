#ifndef MB_FRICTION_H
#define MB_FRICTION_H
/* Coulomb friction on held contacts in the compiled loops (formulations/friction_c.py; the
   laws of formulations/friction.py, docs/contacts.md "Friction in the compiled loops").

   Python configures, per thread, the held contacts that have a friction mode
   (mb_friction_configure): per contact MB_FR_DATA + NQ doubles (data) and MB_FR_OUT doubles
   it reads back (out), a scratch array (friction_c.scratch_size) and a failure record.  The data row of a contact:
     [0] mode (MB_FR_STICK, MB_FR_SLIP), [1] its normal row among the solve's rows,
     [2] its body's index in the generated kinematics (-1: the ground), [3] mu,
     [4..6] the point in the body frame (m), [7] the sphere's radius (m),
     [8..16] the rows n, t1, t2 of its world basis, [17..19] the world slip direction it
     started sliding in, [20] its contact index, [21] its collision feature (the index
     collide.c knows it by; -1: a point or sphere on a plane), [MB_FR_DATA..+NQ) 1 on the
     speeds that move its body (the others' motion columns do not act on it).
   out: [0..1] the tangential force (N, tangent coordinates) and [2] the normal force of the
   last solve, [3..4] the slip velocity (m/s, tangent coordinates) of the last solve,
   [5..6] the slip velocity at the last accepted step (tangent coordinates), [7..8] the unit
   slip direction (tangent coordinates) of the last solve of a sliding contact, [9..11] the
   world slip velocity of the last solve (B^T slip, B the tangent rows of the basis as
   Python keeps it), [12..14] the world slip velocity at the last accepted step (the
   watch's), [15..20] B of the last solve.

   A collision feature's basis turns with its normal: its rows come from collide.c's
   measurement at the state (mb_fr_feature_rows: CollisionKernel.tangent_rows), and its
   data basis [11..16] holds the world direction a slip locator asks about
   (FrictionRows.tangent_coordinates: the direction, then zeros; mb_friction_along).
   fail: [kind (1 Painleve, 2 inconsistent rows), t, value, contact index] of a failed solve.

   The touching point is c = p - r n, its velocity v0 + w x c along the tangents t1, t2
   (J_t), its rate's bias a0 + alpha x c + w x v_p (plane_contact_rows).  A sticking contact
   adds its two tangential rows (target -bias_t - MB_STICK_RATE J_t qd); a sliding one's
   normal row gets the force column J_n - mu s^T J_t (s the unit slip direction: the slip
   velocity's, or below MB_DIRECTION_SPEED the contact's own).  The system
   M qdd = f + W^T lam, J qdd = rhs is solved through A = J M^-1 W^T, A lam = rhs - J M^-1 f
   for the least-norm multipliers (numpy's lstsq in Python): lam = A^T y with
   (A A^T) y = b by a Cholesky factorisation that drops the directions below
   MB_FRICTION_RCOND (squared) of the largest pivot. */
#include "cholesky.h"
#define MB_FR_DATA 24
#define MB_FR_OUT 21
#define MB_FR_FEATURE 21
#define MB_FR_STICK 1
#define MB_FR_SLIP 2
#define MB_FR_PAINLEVE 7
#define MB_FR_INCONSISTENT 8
static __thread int mb_fr_n = 0, mb_fr_cap = 0;
static __thread const double *mb_fr_data;
static __thread double *mb_fr_out, *mb_fr_scratch, *mb_fr_fail;
static double mb_fr_u[1];

/* Configure this thread's friction contacts (n = 0: none).  cap: the most rows a solve may
   have (its own and two per sticking contact); scratch: KINEMATICS_SIZE + 4 cap NQ +
   2 cap^2 + 3 cap + 2 NQ + 8 doubles for the solve, then mb_fr_aux's
   (friction_c.scratch_size). */
int mb_friction_configure(int n, int cap, const double *data, double *out, double *scratch, double *fail) {
    mb_fr_n = n > 0 ? n : 0; mb_fr_cap = cap; mb_fr_data = data; mb_fr_out = out; mb_fr_scratch = scratch;
    mb_fr_fail = fail;
    return 0;
}

/* Scratch for the caller after the solve's own (NQ (NQ + 1) / 2 + 2 NQ + 2 cap doubles). */
static inline double *mb_fr_aux(void) {
    return mb_fr_scratch + KINEMATICS_SIZE + 4L * mb_fr_cap * NQ + 2L * mb_fr_cap * mb_fr_cap + 3L * mb_fr_cap
        + 2L * NQ + 8;
}

/* a x b */
static void mb_fr_cross(const double *a, const double *b, double *out) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Collision feature k's tangential rows (CollisionKernel.tangent_rows) from the body
   kinematics kin: the slip velocity of B's touching point (pb - rb n) relative to A's
   (pa + ra n) along the tangents t1, t2 of the feature's normal n (A to B; t1 = n x e / |.|
   with e the axis of n's smallest component, t2 = n x t1: collision_kernel.tangent_plane),
   Jt (2 x NQ), their bias (2: each touching point's a0 + alpha x c + w x v at its material
   point, at zero generalised acceleration), and B = -(t1, t2): the tangent rows of the basis
   Python keeps (seen from A, the collision's side a).  Zero rows when the pair has none. */
static void mb_fr_feature_rows(long k, const double *kin, double *Jt, double *bias, double *B) {
    mbc_feature f;
    int ia, ib;
    for (int i = 0; i < 2 * NQ; ++i) Jt[i] = 0.0;
    bias[0] = bias[1] = 0.0;
    for (int i = 0; i < 6; ++i) B[i] = 0.0;
    double *saved = mbc_kin;
    mbc_kin = (double *)kin;  /* (collide.c places the shapes from mbc_kin) */
    if (mbc_measure(k, &f, &ia, &ib)) { mbc_kin = saved; return; }
    const double *n = f.n;
    int m = 0;
    for (int a = 1; a < 3; ++a) if (fabs(n[a]) < fabs(n[m])) m = a;
    double e[3] = {0.0, 0.0, 0.0}, T[6], c[2][3], acc[2][3];
    e[m] = 1.0;
    mb_fr_cross(n, e, T);
    const double size = sqrt(T[0] * T[0] + T[1] * T[1] + T[2] * T[2]);
    for (int a = 0; a < 3; ++a) T[a] /= size;
    mb_fr_cross(n, T, T + 3);
    const int body[2] = {ia, ib};
    const double *material[2] = {f.pa, f.pb};
    for (int a = 0; a < 3; ++a) { c[0][a] = f.pa[a] + f.ra * n[a]; c[1][a] = f.pb[a] - f.rb * n[a]; }
    for (int s = 0; s < 2; ++s) {
        acc[s][0] = acc[s][1] = acc[s][2] = 0.0;
        if (body[s] < 0) continue;
        const double *row = mbc_body(body[s]), *V = row + 12, *A = row + 18;
        double vp[3], x[3], y[3];
        mb_fr_cross(V, material[s], vp);
        for (int a = 0; a < 3; ++a) vp[a] += V[3 + a];
        mb_fr_cross(A, c[s], x);
        mb_fr_cross(V, vp, y);
        for (int a = 0; a < 3; ++a) acc[s][a] = A[3 + a] + x[a] + y[a];
    }
    for (int r = 0; r < 2; ++r) {
        const double *t = T + 3 * r;
        bias[r] = t[0] * (acc[1][0] - acc[0][0]) + t[1] * (acc[1][1] - acc[0][1]) + t[2] * (acc[1][2] - acc[0][2]);
    }
    const double *cols = kin + KINEMATICS_COLUMNS_OFF;
    const double *ma = ia < 0 ? 0 : mbc_mask + (long)ia * NQ, *mb = ib < 0 ? 0 : mbc_mask + (long)ib * NQ;
    for (int i = 0; i < NQ; ++i) {
        const double *S = cols + 6 * i;
        double w[3] = {0.0, 0.0, 0.0}, x[3];
        if (mb && mb[i] != 0.0) {
            mb_fr_cross(S, c[1], x);
            for (int a = 0; a < 3; ++a) w[a] += mb[i] * (S[3 + a] + x[a]);
        }
        if (ma && ma[i] != 0.0) {
            mb_fr_cross(S, c[0], x);
            for (int a = 0; a < 3; ++a) w[a] -= ma[i] * (S[3 + a] + x[a]);
        }
        for (int r = 0; r < 2; ++r) Jt[r * NQ + i] = T[3 * r] * w[0] + T[3 * r + 1] * w[1] + T[3 * r + 2] * w[2];
    }
    for (int i = 0; i < 6; ++i) B[i] = -T[i];
    mbc_kin = saved;
}

/* The tangential rows Jt (2 x NQ) and their bias (2) of friction contact j from the body
   kinematics kin (the generated `kinematics` at the state), and the tangent rows B (2 x 3)
   of its world basis as Python keeps it (world vectors are B^T times tangent coordinates). */
static void mb_fr_rows(int j, const double *kin, double *Jt, double *bias, double *B) {
    const double *d = mb_fr_data + (MB_FR_DATA + NQ) * j, *n = d + 8, *T = d + 11;
    if (d[MB_FR_FEATURE] >= 0.0) {
        mb_fr_feature_rows((long)d[MB_FR_FEATURE], kin, Jt, bias, B);
        return;
    }
    const long b = (long)d[2];
    for (int i = 0; i < 2 * NQ; ++i) Jt[i] = 0.0;
    bias[0] = bias[1] = 0.0;
    for (int i = 0; i < 6; ++i) B[i] = T[i];
    if (b < 0) return;  /* a point of the ground: nothing moves */
    const double *body = kin + KINEMATICS_BODIES_OFF + 24 * b, *R = body, *origin = body + 9, *V = body + 12, *A = body + 18;
    double p[3], c[3], vp[3], t[3], u[3];
    for (int a = 0; a < 3; ++a) {
        p[a] = origin[a] + R[3 * a] * d[4] + R[3 * a + 1] * d[5] + R[3 * a + 2] * d[6];
        c[a] = p[a] - d[7] * n[a];
    }
    mb_fr_cross(V, p, vp);
    for (int a = 0; a < 3; ++a) vp[a] += V[3 + a];
    mb_fr_cross(A, c, t);
    mb_fr_cross(V, vp, u);
    for (int a = 0; a < 3; ++a) t[a] += A[3 + a] + u[a];
    for (int r = 0; r < 2; ++r) bias[r] = T[3 * r] * t[0] + T[3 * r + 1] * t[1] + T[3 * r + 2] * t[2];
    const double *mask = d + MB_FR_DATA;
    for (int i = 0; i < NQ; ++i) {
        if (mask[i] == 0.0) continue;
        const double *S = kin + KINEMATICS_COLUMNS_OFF + 6 * i;
        double w[3];
        mb_fr_cross(S, c, w);
        for (int a = 0; a < 3; ++a) w[a] += S[3 + a];
        for (int r = 0; r < 2; ++r) Jt[r * NQ + i] = T[3 * r] * w[0] + T[3 * r + 1] * w[1] + T[3 * r + 2] * w[2];
    }
}

/* Friction contact j's tangential rows at (q, qd) (the generated kinematics there), for
   the watch and tests: Jt (2 x NQ), bias (2), the slip velocity Jt qd (2) and the basis's
   tangent rows B (6, as Python keeps them; NULL: not wanted). */
void mb_friction_rows_at(const double *q, const double *qd, const double *p, int j, double *Jt, double *bias,
                         double *slip, double *B) {
    double kin[KINEMATICS_SIZE + 1], B0[6];
    kinematics(q, qd, p, mb_fr_u, kin);
    mb_fr_rows(j, kin, Jt, bias, B ? B : B0);
    for (int r = 0; r < 2; ++r) {
        double s = 0.0;
        for (int i = 0; i < NQ; ++i) s += Jt[r * NQ + i] * qd[i];
        slip[r] = s;
    }
}

/* y = G^-1 b for the symmetric positive semi-definite m x m matrix G (lower triangle used,
   destroyed) by a Cholesky factorisation that drops pivots below MB_FRICTION_RCOND^2 of the
   largest diagonal entry (their component of y is zero). */
static void mb_fr_psd_solve(double *G, const double *b, double *y, int m) {
    double gmax = 0.0;
    for (int j = 0; j < m; ++j) if (G[j * m + j] > gmax) gmax = G[j * m + j];
    mb_cholesky(G, m, m, MB_FRICTION_RCOND * MB_FRICTION_RCOND * gmax, 1);
    mb_cholesky_solve(G, m, m, b, y);
}

/* The friction solve at the state (q, qd, time t): L the packed Cholesky factor of the mass
   matrix, u = L^-1 (f + tau) (NQ), nr rows J (rows of NQ) with acceleration targets rhs
   (the formulation's: Baumgarte terms for dae, -bias for lagrange).  Writes qdd (NQ), the
   rows' multipliers lam (nr) and each friction contact's out.  Returns 0, MB_FR_PAINLEVE or
   MB_FR_INCONSISTENT (the failure record says where), -4 when the rows exceed the scratch. */
static int mb_friction_solve(double t, const double *q, const double *qd, const double *p, const double *L,
                             const double *u, int nr, const double *J, const double *rhs, double *qdd, double *lam) {
    const int n = NQ;
    int m = nr;
    for (int j = 0; j < mb_fr_n; ++j) if (mb_fr_data[(MB_FR_DATA + n) * j] == MB_FR_STICK) m += 2;
    if (m > mb_fr_cap) return -4;
    double *kin = mb_fr_scratch, *Jall = kin + KINEMATICS_SIZE, *Wall = Jall + (long)m * n;
    double *Yj = Wall + (long)m * n, *Yw = Yj + (long)m * n, *A = Yw + (long)m * n, *G = A + (long)m * m;
    double *b = G + (long)m * m, *y = b + m, *x = y + m, *Jt = x + m, *bt = Jt + 2 * n;
    kinematics(q, qd, p, mb_fr_u, kin);
    for (int k = 0; k < nr; ++k) {
        for (int i = 0; i < n; ++i) Jall[k * n + i] = Wall[k * n + i] = J[k * n + i];
        b[k] = rhs[k];
    }
    int row = nr;
    for (int j = 0; j < mb_fr_n; ++j) {
        const double *d = mb_fr_data + (MB_FR_DATA + n) * j;
        double *o = mb_fr_out + MB_FR_OUT * j;
        mb_fr_rows(j, kin, Jt, bt, o + 15);
        for (int r = 0; r < 2; ++r) {
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Jt[r * n + i] * qd[i];
            o[3 + r] = s;
        }
        for (int a = 0; a < 3; ++a) o[9 + a] = o[15 + a] * o[3] + o[18 + a] * o[4];
        if (d[0] == MB_FR_STICK) {
            for (int r = 0; r < 2; ++r) {
                for (int i = 0; i < n; ++i) Jall[(row + r) * n + i] = Wall[(row + r) * n + i] = Jt[r * n + i];
                b[row + r] = -bt[r] - MB_STICK_RATE * o[3 + r];
            }
            row += 2;
        } else {  /* sliding: the normal row's force column carries the friction -mu s J_t */
            double s0 = o[3], s1 = o[4];
            const double speed = sqrt(s0 * s0 + s1 * s1);
            if (speed > MB_DIRECTION_SPEED) {
                s0 /= speed; s1 /= speed;
            } else {
                const double *T = o + 15, *dir = d + 17;
                s0 = T[0] * dir[0] + T[1] * dir[1] + T[2] * dir[2];
                s1 = T[3] * dir[0] + T[4] * dir[1] + T[5] * dir[2];
                const double size = sqrt(s0 * s0 + s1 * s1);
                if (size > 0) { s0 /= size; s1 /= size; } else { s0 = s1 = 0.0; }
            }
            o[7] = s0; o[8] = s1;  /* (the direction of this solve) */
            const long k = (long)d[1];
            for (int i = 0; i < n; ++i) Wall[k * n + i] -= d[3] * (s0 * Jt[i] + s1 * Jt[n + i]);
        }
    }
    for (int k = 0; k < m; ++k) {  /* Yj = L^-1 J^T, Yw = L^-1 W^T (column k) */
        for (int i = 0; i < n; ++i) {
            double s = Jall[k * n + i], w = Wall[k * n + i];
            for (int l = 0; l < i; ++l) { s -= L[IDX(i, l)] * Yj[l * m + k]; w -= L[IDX(i, l)] * Yw[l * m + k]; }
            Yj[i * m + k] = s / L[IDX(i, i)];
            Yw[i * m + k] = w / L[IDX(i, i)];
        }
    }
    double scale = 1e-300;
    for (int a = 0; a < m; ++a) {  /* A = Yj^T Yw, b = rhs - Yj^T u */
        for (int c = 0; c < m; ++c) {
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Yj[i * m + a] * Yw[i * m + c];
            A[a * m + c] = s;
        }
        for (int i = 0; i < n; ++i) b[a] -= Yj[i * m + a] * u[i];
        if (fabs(A[a * m + a]) > scale) scale = fabs(A[a * m + a]);
    }
    for (int j = 0; j < mb_fr_n; ++j) {  /* Painleve: a sliding row without positive effective mass */
        const double *d = mb_fr_data + (MB_FR_DATA + n) * j;
        const long k = (long)d[1];
        if (d[0] == MB_FR_SLIP && A[k * m + k] <= MB_PAINLEVE * scale) {
            mb_fr_fail[0] = 1; mb_fr_fail[1] = t; mb_fr_fail[2] = A[k * m + k]; mb_fr_fail[3] = d[20];
            return MB_FR_PAINLEVE;
        }
    }
    for (int a = 0; a < m; ++a)  /* G = A A^T (lower) */
        for (int c = 0; c <= a; ++c) {
            double s = 0.0;
            for (int l = 0; l < m; ++l) s += A[a * m + l] * A[c * m + l];
            G[a * m + c] = s;
        }
    mb_fr_psd_solve(G, b, y, m);
    double bmax = 1.0, res = 0.0;
    for (int c = 0; c < m; ++c) {  /* x = A^T y: the least-norm multipliers */
        double s = 0.0;
        for (int a = 0; a < m; ++a) s += A[a * m + c] * y[a];
        x[c] = s;
    }
    for (int a = 0; a < m; ++a) {
        double s = -b[a];
        for (int c = 0; c < m; ++c) s += A[a * m + c] * x[c];
        if (fabs(s) > res) res = fabs(s);
        if (fabs(b[a]) > bmax) bmax = fabs(b[a]);
    }
    if (!(res <= MB_FRICTION_RESIDUAL * bmax)) {
        mb_fr_fail[0] = 2; mb_fr_fail[1] = t; mb_fr_fail[2] = res; mb_fr_fail[3] = -1;
        return MB_FR_INCONSISTENT;
    }
    for (int i = 0; i < n; ++i) {  /* qdd = L^-T (u + Yw x) */
        double s = u[i];
        for (int k = 0; k < m; ++k) s += Yw[i * m + k] * x[k];
        qdd[i] = s;
    }
    upper_solve(L, qdd);
    for (int k = 0; k < nr; ++k) lam[k] = x[k];
    row = nr;
    for (int j = 0; j < mb_fr_n; ++j) {
        const double *d = mb_fr_data + (MB_FR_DATA + n) * j;
        double *o = mb_fr_out + MB_FR_OUT * j;
        const double lam_n = x[(long)d[1]];
        o[2] = lam_n;
        if (d[0] == MB_FR_STICK) {
            o[0] = x[row]; o[1] = x[row + 1];
            row += 2;
        } else {
            o[0] = -d[3] * lam_n * o[7]; o[1] = -d[3] * lam_n * o[8];
        }
    }
    return 0;
}

/* Sticking contact j's distance outside the cone after the last solve (N): |lam_t| - mu lam_n
   - tolerance (ContactWatch.cone_excess; positive: outside). */
static double mb_friction_margin(int j) {
    const double *d = mb_fr_data + (MB_FR_DATA + NQ) * j, *o = mb_fr_out + MB_FR_OUT * j;
    const double mu = d[3], size = sqrt(o[0] * o[0] + o[1] * o[1]), lam_n = o[2];
    const double a = fabs(lam_n) * mu, tol = MB_CONE_TOLERANCE * (a > size ? a : size) + MB_CONE_FLOOR;
    return size - mu * (lam_n > 0.0 ? lam_n : 0.0) - tol;
}

/* Friction contact j's slip velocity (m/s) at (q, qd) along the world direction B0^T (e0, e1)
   (ContactWatch.slip_speed), B0 the tangent rows of its data basis (a plane's fixed tangents;
   a collision feature's: the direction asked about, FrictionRows.tangent_coordinates): the
   world slip velocity B^T (Jt qd) at the state, along it. */
static double mb_friction_along(int j, const double *q, const double *qd, const double *p, double e0, double e1) {
    double Jt[2 * NQ + 1], bias[2], slip[2], B[6];
    const double *T = mb_fr_data + (MB_FR_DATA + NQ) * j + 11;
    mb_friction_rows_at(q, qd, p, j, Jt, bias, slip, B);
    double along = 0.0;
    for (int a = 0; a < 3; ++a) along += (e0 * T[a] + e1 * T[3 + a]) * (B[a] * slip[0] + B[3 + a] * slip[1]);
    return along;
}

/* The friction watch after a solve at an accepted step's end (out holds that solve): 1 when
   a sticking contact's force left the cone (|lam_t| - mu lam_n - tolerance > 0, as
   ContactWatch.cone_excess) or a sliding contact stops (ContactWatch.locate_friction: its
   slip along its direction at the step's start is no longer positive, or its slip speed
   fell to MB_STOP_SPEED; one set sliding at most that fast stops only sliding back faster),
   else 0 (and the slip velocities become the accepted ones). */
static int mb_friction_event(void) {
    int event = 0;
    for (int j = 0; j < mb_fr_n; ++j) {
        const double *d = mb_fr_data + (MB_FR_DATA + NQ) * j, *o = mb_fr_out + MB_FR_OUT * j;
        if (d[0] == MB_FR_STICK) {
            if (mb_friction_margin(j) > 0.0) event = 1;
        } else {
            /* (world vectors, as ContactWatch: a collision feature's tangents turn with its normal) */
            const double *v0 = o + 12, *v1 = o + 9, *dir = d + 17;
            const double speed = sqrt(v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2]);
            const double *e = speed > MB_SLIP_FLOOR ? v0 : dir, scale = speed > MB_SLIP_FLOOR ? speed : 1.0;
            const double along = (e[0] * v1[0] + e[1] * v1[1] + e[2] * v1[2]) / scale;
            if (speed <= MB_STOP_SPEED) {  /* set sliding at (nearly) zero slip: stops only sliding back */
                if (along >= -MB_STOP_SPEED) continue;
            } else if (along > 0.0 && sqrt(v1[0] * v1[0] + v1[1] * v1[1] + v1[2] * v1[2]) > MB_STOP_SPEED) {
                continue;  /* still sliding forward, faster than MB_STOP_SPEED */
            }
            event = 1;
        }
    }
    if (!event)
        for (int j = 0; j < mb_fr_n; ++j) {
            double *o = mb_fr_out + MB_FR_OUT * j;
            o[5] = o[3]; o[6] = o[4];
            o[12] = o[9]; o[13] = o[10]; o[14] = o[11];
        }
    return event;
}
#endif
