#ifdef DAE_LOOP
#define DAE_NK (CONTACTS_JACOBIAN_OFF - CONTACTS_GAP_OFF)
/* most KKT rows: geometric, one motor per speed, every contact and collision feature */
#define DAE_NR (NG + NQ + DAE_NK + MB_NCF)
/* work: dynamics, constraints, contacts, then the rows' g, J, g_t, bias, then Y, A, r, lam, u */
#define DAE_C_OFF DYNAMICS_SIZE
#define DAE_K_OFF (DAE_C_OFF + CONSTRAINTS_SIZE)
#define DAE_ROWS_OFF (DAE_K_OFF + CONTACTS_SIZE)
#define DAE_SOLVE_OFF (DAE_ROWS_OFF + DAE_NR * (NQ + 3))
#define NDAEWORK (DAE_SOLVE_OFF + NQ * DAE_NR + DAE_NR * DAE_NR + 3 * DAE_NR + NQ)
#include "program.h"
#include "brentq.h"
#include "least_norm.h"
#include "cholesky.h"
#include "quaternion.h"
#include "friction.h"
/* defined below, or after this code by the recursive program (recursive.c_dae) */
int dae_accelerations(const double *q, const double *qd, const double *p, const double *u,
                      const double *tau, double *qdd, double *work);
static __thread int dae_nr = -1;
/* dae_rows (DAE_NR: legacy configuration, geometric rows), dae_legacy (DAE_SPEC_LONGS DAE_NR) and
   dae_lam (DAE_NR + 1: multipliers of the last solve, per configured row) are per-thread
   buffers of the model's sizes unit (c_sizes.py). */
static __thread const long *dae_spec;             /* per row: kind, index, coordinate, speed index, program */
static __thread const double *dae_data;           /* per row: speed, offset */
static __thread const double *dae_programs;
static __thread double dae_alpha, dae_beta, dae_scale, dae_tol = MB_RANK_TOLERANCE;
static __thread double dae_time = 0.0;            /* the time of the state being evaluated */
static __thread int dae_has_geo, dae_has_contacts, dae_has_collisions;
static __thread double dae_bad_time = NAN;        /* first time a motor program was not finite */
static __thread int dae_dropped = 0;              /* the last Gram solve dropped a direction */
static __thread int dae_quat_project = 0;         /* dae_project on quaternion coordinates (per run) */

/* The time a position motor's program first gave a non-finite value since configuring (NaN: never). */
double dae_motor_failure(void) {
    return dae_bad_time;
}

static void dae_scan(void) {
    dae_has_geo = dae_has_contacts = dae_has_collisions = 0;
    for (int k = 0; k < dae_nr; ++k) {
        if (dae_spec[DAE_SPEC_LONGS * k] == DAE_ROW_GEOMETRIC) dae_has_geo = 1;
        if (dae_spec[DAE_SPEC_LONGS * k] == DAE_ROW_CONTACT) {
            if (dae_spec[DAE_SPEC_LONGS * k + 1] < DAE_NK) dae_has_contacts = 1;
            else dae_has_collisions = 1;  /* a collision feature (codegen/c/collide.c) */
        }
    }
}

/* Rows from Python-owned arrays (nr < 0: switched off): spec (5 longs per row), data (2
   doubles per row), programs (postfix programs of position motors); gains and tolerances. */
int dae_configure_rows(int nr, const long *spec, const double *data, const double *programs, double alpha,
                       double beta, double scale, double tol) {
    if (nr > DAE_NR) return -4;
    dae_nr = nr; dae_spec = spec; dae_data = data; dae_programs = programs;
    dae_bad_time = NAN;
    dae_alpha = alpha; dae_beta = beta; dae_scale = scale; dae_tol = tol;
    if (nr >= 0) dae_scan();
    else dae_quat_project = 0;  /* (switched off with the rows) */
    return 0;
}

/* Whether the compiled DOP853 loop projects a model with quaternion coordinates after each
   accepted step (on: 1; the run's projection=True, set by Python after configuring the
   rows, switched off with them).  Models without quaternions are projected whatever this. */
void dae_quaternion_projection(int on) {
    dae_quat_project = on != 0;
}

/* q moved by the step dv in speed space (NQ), as core/statemap.py StateMap.integrate: screw
   coordinates by q + dv; each quaternion by q exp(phi / 2), phi the rotation vector of its
   three speeds (rotated frame: the angular velocity's convention, q' = q (0, w) / 2), composed
   on the right and normalised. */
void dae_quaternion_step(double *q, const double *dv) {
    for (int i = 0; i < NSCREW; ++i) q[SCREW_Q[i]] += dv[SCREW_V[i]];
    for (int k = 0; k < NQUAT; ++k) {
        double r[4];
        mb_qstep(q + QUAT_Q[k], dv + QUAT_V[k], r);
        for (int i = 0; i < 4; ++i) q[QUAT_Q[k] + i] = r[i];
    }
}

/* Geometric rows only (models without motors): rows are indices of the generated constraints. */
void dae_configure(int nr, const long *rows, double alpha, double beta, double scale, double tol) {
    if (nr > NG) nr = NG;
    for (int k = 0; k < nr; ++k) {
        dae_rows[k] = rows[k];
        long *s = dae_legacy + DAE_SPEC_LONGS * k;
        s[0] = DAE_ROW_GEOMETRIC; s[1] = rows[k]; s[2] = s[3] = 0; s[4] = -1;
    }
    dae_configure_rows(nr, dae_legacy, 0, 0, alpha, beta, scale, tol);
}

/* g, J (rows of NQ), g_t and bias of the configured rows at (q, qd, dae_time) into work. */
static void dae_rows_eval(const double *q, const double *qd, const double *p, const double *u, double *work) {
    double *c = work + DAE_C_OFF, *kc = work + DAE_K_OFF;
    double *g = work + DAE_ROWS_OFF, *J = g + DAE_NR, *gt = J + DAE_NR * NQ, *bias = gt + DAE_NR;
    if (MB_HAS_NG && dae_has_geo) constraints(q, qd, p, u, c);
    if (MB_HAS_CONTACTS && dae_has_contacts) contacts(q, qd, p, u, kc);
    if (dae_has_collisions) mb_collide_eval(q, qd, p);
    (void)c; (void)kc;
    for (int k = 0; k < dae_nr; ++k) {
        const long *s = dae_spec + DAE_SPEC_LONGS * k;
        double *Jr = J + k * NQ;
        const long j = s[1];
        if (s[0] == DAE_ROW_GEOMETRIC) {
            g[k] = c[CONSTRAINTS_RESIDUAL_OFF + j];
            for (int i = 0; i < NQ; ++i) Jr[i] = c[CONSTRAINTS_JACOBIAN_OFF + j * NQ + i];
            gt[k] = 0.0;
            bias[k] = c[CONSTRAINTS_BIAS_OFF + j];
        } else if (s[0] == DAE_ROW_CONTACT && j >= DAE_NK) {  /* a collision feature */
            gt[k] = 0.0;
            if (mb_collide_row(j - DAE_NK, g + k, Jr, bias + k)) {
                g[k] = bias[k] = NAN;
                for (int i = 0; i < NQ; ++i) Jr[i] = 0.0;
            }
        } else if (s[0] == DAE_ROW_CONTACT) {
            g[k] = kc[CONTACTS_GAP_OFF + j];
            for (int i = 0; i < NQ; ++i) Jr[i] = kc[CONTACTS_JACOBIAN_OFF + j * NQ + i];
            gt[k] = 0.0;
            bias[k] = kc[CONTACTS_BIAS_OFF + j];
        } else {
            for (int i = 0; i < NQ; ++i) Jr[i] = 0.0;
            Jr[s[3]] = 1.0;
            if (s[4] < 0) {  /* speed motor: q_k - offset - speed t */
                const double speed = dae_data[DAE_DATA_DOUBLES * k], offset = dae_data[DAE_DATA_DOUBLES * k + 1];
                g[k] = q[s[2]] - offset - speed * dae_time;
                gt[k] = -speed;
                bias[k] = 0.0;
            } else {  /* position motor: q_k - s(t), s' and s'' exact */
                const double *prog = dae_programs + s[4];
                const double v0 = mb_program(&prog, dae_time), v1 = mb_program(&prog, dae_time);
                const double v2 = mb_program(&prog, dae_time);
                if (!(isfinite(v0) && isfinite(v1) && isfinite(v2)) && dae_bad_time != dae_bad_time)
                    dae_bad_time = dae_time;
                g[k] = q[s[2]] - v0;
                gt[k] = -v1;
                bias[k] = -v2;
            }
        }
    }
}

/* Column ``col`` of Y = L^-1 J_r^T (rows of the configured Jacobian J, M = L L^T packed);
   returns the row's rate J_r qd. */
static double dae_row_solve(const double *L, const double *J, const double *qd, double *Y, int col) {
    const double *Jr = J + col * NQ;
    double rate = 0.0;
    for (int i = 0; i < NQ; ++i) {
        double s = Jr[i];
        for (int k = 0; k < i; ++k) s -= L[IDX(i, k)] * Y[k * DAE_NR + col];
        Y[i * DAE_NR + col] = s / L[IDX(i, i)];
        rate += Jr[i] * qd[i];
    }
    return rate;
}

/* 1 when every speed is below MB_REST_SPEED: a dropped multiplier direction then leaves the motion
   undetermined (a singular position at rest), 0 otherwise. */
static int dae_at_rest(const double *qd, int n) {
    for (int i = 0; i < n; ++i) if (fabs(qd[i]) >= MB_REST_SPEED) return 0;
    return 1;
}

/* lam = A^-1 r for the Gram matrix A (lower triangle, rows of DAE_NR, nr x nr; overwritten)
   by a Cholesky factorisation when every pivot is above tol relative to the largest
   diagonal entry (and scale) and above rounding (least_norm.h's MB_EIGEN_ROUNDING): then A
   has full rank and this is the one solution.  Returns 0, 1 at the first pivot that is not
   (lam not set), -1 on a non-finite pivot. */
static int dae_cholesky_solve(double *A, const double *r, double *lam, int nr, double scale, double tol) {
    double amax = 0.0;
    for (int j = 0; j < nr; ++j) if (A[j * DAE_NR + j] > amax) amax = A[j * DAE_NR + j];
    const double top = sqrt(amax) > scale ? sqrt(amax) : scale, floor_ = tol * top;
    const double zero = MB_EIGEN_ROUNDING * nr * DBL_EPSILON * amax;
    const int status = mb_cholesky(A, DAE_NR, nr, floor_ * floor_ > zero ? floor_ * floor_ : zero, 0);
    if (status) return status < 0 ? -1 : 1;
    mb_cholesky_solve(A, DAE_NR, nr, r, lam);
    return 0;
}

/* lam = the least-norm solution of A lam = r for the Gram matrix A (lower triangle, rows of
   DAE_NR, nr x nr; overwritten): the Cholesky solve where A has full rank by its pivots (the
   one solution; the regular case, at the cost of a Cholesky factorisation), else
   least_norm.h's Jacobi eigen-decomposition, dropping the directions whose sqrt(eigenvalue)
   falls below tol relative to the largest (and scale): they get no multiplier.  Returns the
   number dropped (dae_dropped: whether one was), or -1 when A is not finite. */
static __thread double *dae_eig_work = 0;

static int dae_least_norm(double *A, const double *r, double *lam, int nr, double scale, double tol) {
    if (nr <= 0) return 0;
    if (!dae_eig_work) dae_eig_work = malloc(sizeof(double) * (2 * DAE_NR * DAE_NR + DAE_NR + 1));
    if (!dae_eig_work) return -1;
    double *copy = dae_eig_work + DAE_NR * DAE_NR + DAE_NR;
    for (int i = 0; i < nr; ++i)
        for (int j = 0; j <= i; ++j) copy[i * DAE_NR + j] = A[i * DAE_NR + j];
    int status = dae_cholesky_solve(A, r, lam, nr, scale, tol);
    if (status > 0) {
        for (int i = 0; i < nr; ++i)
            for (int j = 0; j <= i; ++j) A[i * DAE_NR + j] = copy[i * DAE_NR + j];
        status = mb_least_norm(A, DAE_NR, r, lam, nr, scale, tol, dae_eig_work);
    }
    dae_dropped = status > 0;
    return status;
}

/* The same with the configured tolerance (dae_tol): 1 when a direction was dropped, -1 when
   A is not finite, 0 otherwise. */
static int dae_gram_solve(double *A, const double *r, double *lam, int nr, double scale) {
    const int dropped = dae_least_norm(A, r, lam, nr, scale, dae_tol);
    return dropped > 0 ? 1 : dropped;
}

/* The multipliers of the acceleration solve (A the Schur complement J M^-1 J^T, r its
   right-hand side): in motion, least norm with the configured tolerance (dae_tol, a
   transient singular position passes with its near-singular directions dropped); at rest
   (every speed below MB_REST_SPEED), least norm with the rank tolerance MB_RANK_TOLERANCE,
   and a direction below it means a dead point at rest, where the motion is not determined.
   Returns 0, or 2 (not finite, or a dead point at rest: the caller's Python path names it). */
static int dae_schur_solve(double *A, const double *r, double *lam, int nr, const double *qd, int n) {
    const int rest = dae_at_rest(qd, n);
    const int dropped = dae_least_norm(A, r, lam, nr, dae_scale, rest ? MB_RANK_TOLERANCE : dae_tol);
    return dropped < 0 || (dropped > 0 && rest) ? 2 : 0;
}

#ifndef MBCOMP_RECURSIVE_DAE  /* the recursive program brings its own (recursive.c_dae) */
int dae_accelerations(const double *q, const double *qd, const double *p, const double *u,
                      const double *tau, double *qdd, double *work) {
    const int n = NQ, nr = dae_nr;
    double *L = work + DYNAMICS_MASS_MATRIX_OFF, *f = work + DYNAMICS_FORCES_OFF;
    const double *g = work + DAE_ROWS_OFF, *J = g + DAE_NR, *gt = J + DAE_NR * NQ, *bias = gt + DAE_NR;
    double *Y = work + DAE_SOLVE_OFF, *A = Y + n * DAE_NR;
    double *r = A + DAE_NR * DAE_NR, *lam = r + DAE_NR, *uvec = lam + DAE_NR;
    dynamics(q, qd, p, u, work);
    dae_rows_eval(q, qd, p, u, work);
    for (int i = 0; i < n; ++i) uvec[i] = f[i] + (tau ? tau[i] : 0.0);
    if (mass_cholesky(L)) return 1;
    lower_solve(L, uvec);  /* uvec <- L^-1 (f + tau) */
    if (mb_fr_n > 0) {  /* friction on held contacts (friction.h): the rows' targets, then its own solve */
        for (int col = 0; col < nr; ++col) {
            const double *Jr = J + col * NQ;
            double gdot = gt[col];
            for (int i = 0; i < n; ++i) gdot += Jr[i] * qd[i];
            r[col] = -bias[col] - 2.0 * dae_alpha * gdot - dae_beta * dae_beta * g[col];
        }
        const int status = mb_friction_solve(dae_time, q, qd, p, L, uvec, nr, J, r, qdd, lam);
        if (status) return status;
        for (int k = 0; k < nr; ++k) dae_lam[k] = lam[k];
        return 0;
    }
    for (int col = 0; col < nr; ++col) {  /* Y[:, col] = L^-1 J_row^T; rhs of the row */
        const double gdot = dae_row_solve(L, J, qd, Y, col) + gt[col];
        r[col] = -bias[col] - 2.0 * dae_alpha * gdot - dae_beta * dae_beta * g[col];
        for (int i = 0; i < n; ++i) r[col] -= Y[i * DAE_NR + col] * uvec[i];
    }
    for (int a = 0; a < nr; ++a)  /* A = Y^T Y (lower) */
        for (int b = 0; b <= a; ++b) {
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Y[i * DAE_NR + a] * Y[i * DAE_NR + b];
            A[a * DAE_NR + b] = s;
        }
    if (dae_schur_solve(A, r, lam, nr, qd, n)) return 2;  /* not finite, or a dead point at rest */
    for (int k = 0; k < nr; ++k) dae_lam[k] = lam[k];
    for (int i = 0; i < n; ++i) {  /* qdd = L^-T (uvec + Y lam) */
        double s = uvec[i];
        for (int k = 0; k < nr; ++k) s += Y[i * DAE_NR + k] * lam[k];
        qdd[i] = s;
    }
    upper_solve(L, qdd);
    return 0;
}
#endif

/* The KKT solve at one state, for the evaluation calls (System.accelerations, reactions and
   the analyses through them: formulations/compiled_eval.py): the rows, gains and tolerances
   given here (as dae_configure_rows takes them), at time t; the configuration of a run on
   this thread is left as it was (and no friction: dae_evaluate_friction below).  qdd (NQ) and
   lam (nr: the multiplier of each given row, the sign of the KKT system's J^T lam).
   Returns 0; 1 when M is not positive definite; 2 when a direction of the rows was dropped
   (a singular position: the caller falls back to the Python solve); -4 too many rows. */
static int dae_evaluate_with(int nf, int cap, const double *fdata, double *fout, double *fscratch, double *ffail,
                             int nr, const long *spec, const double *data, const double *programs, double alpha,
                             double beta, double scale, double tol, const double *p, const double *tau, double t,
                             const double *q, const double *qd, double *qdd, double *lam, double *work) {
    if (nr > DAE_NR || nr < 0) return -4;
    const int fcap0 = mb_fr_cap;
    const double *fdata0 = mb_fr_data;
    double *fout0 = mb_fr_out, *fscratch0 = mb_fr_scratch, *ffail0 = mb_fr_fail;
    const int nr0 = dae_nr, geo0 = dae_has_geo, contacts0 = dae_has_contacts, collisions0 = dae_has_collisions;
    const long *spec0 = dae_spec;
    const double *data0 = dae_data, *programs0 = dae_programs;
    const double alpha0 = dae_alpha, beta0 = dae_beta, scale0 = dae_scale, tol0 = dae_tol, time0 = dae_time;
    const double bad0 = dae_bad_time;
    const int fr0 = mb_fr_n;
    double lam0[DAE_NR + 1], u[1] = {0.0};
    for (int k = 0; k < DAE_NR; ++k) lam0[k] = dae_lam[k];
    dae_configure_rows(nr, spec, data, programs, alpha, beta, scale, tol);
    mb_friction_configure(nf, cap, fdata, fout, fscratch, ffail);
    dae_time = t;
    dae_dropped = 0;
    int status = dae_accelerations(q, qd, p, u, tau, qdd, work);
    if (status == 0 && dae_dropped) status = 2;
    for (int k = 0; k < nr; ++k) lam[k] = dae_lam[k];
    dae_nr = nr0; dae_spec = spec0; dae_data = data0; dae_programs = programs0;
    dae_alpha = alpha0; dae_beta = beta0; dae_scale = scale0; dae_tol = tol0; dae_time = time0;
    dae_has_geo = geo0; dae_has_contacts = contacts0; dae_has_collisions = collisions0; dae_bad_time = bad0;
    mb_friction_configure(fr0, fcap0, fdata0, fout0, fscratch0, ffail0);
    for (int k = 0; k < DAE_NR; ++k) dae_lam[k] = lam0[k];
    return status;
}

int dae_evaluate(int nr, const long *spec, const double *data, const double *programs, double alpha, double beta,
                 double scale, double tol, const double *p, const double *tau, double t, const double *q,
                 const double *qd, double *qdd, double *lam, double *work) {
    return dae_evaluate_with(0, 0, 0, 0, 0, 0, nr, spec, data, programs, alpha, beta, scale, tol, p, tau, t, q, qd,
                             qdd, lam, work);
}

/* dae_evaluate with friction on held contacts (the evaluation calls' contact forces:
   formulations/compiled_eval.py): nf contacts with friction modes configured as
   mb_friction_configure takes them (friction_c.FrictionRows' arrays; cap its row capacity)
   for this call only; the thread's friction configuration is left as it was.  Each
   contact's out row holds its forces of this solve (friction.h).  Returns as dae_evaluate,
   or MB_FR_PAINLEVE / MB_FR_INCONSISTENT when the friction solve failed (fail says where). */
int dae_evaluate_friction(int nf, int cap, const double *fdata, double *fout, double *fscratch, double *ffail, int nr,
                          const long *spec, const double *data, const double *programs, double alpha, double beta,
                          double scale, double tol, const double *p, const double *tau, double t, const double *q,
                          const double *qd, double *qdd, double *lam, double *work) {
    return dae_evaluate_with(nf, cap, fdata, fout, fscratch, ffail, nr, spec, data, programs, alpha, beta, scale, tol,
                             p, tau, t, q, qd, qdd, lam, work);
}

/* Move y = [q (NCOORD), qd (NQ)] back onto the constraints after an accepted step at
   dae_time: positions by Newton (minimum-norm steps -J^T (J J^T)^-1 g on the configured rows,
   in speed space; with quaternions applied by dae_quaternion_step), speeds by the
   mass-orthogonal projection onto J qd + g_t = 0.  Returns 1 when y changed (the caller
   re-evaluates its derivative). */
int dae_project(double *y, const double *p, const double *u, double *work) {
    const int n = NQ, nr = dae_nr;
    double *q = y, *qd = y + NCOORD;
    double *L = work + DYNAMICS_MASS_MATRIX_OFF;
    const double *g = work + DAE_ROWS_OFF, *J = g + DAE_NR, *gt = J + DAE_NR * NQ;
    double *Y = work + DAE_SOLVE_OFF, *A = Y + n * DAE_NR;
    double *r = A + DAE_NR * DAE_NR, *lam = r + DAE_NR, *dq = lam + DAE_NR;
    if (nr <= 0) return 0;
    int changed = 0;
    for (int it = 0; it < 4; ++it) {
        dae_rows_eval(q, qd, p, u, work);
        double gmax = 0.0;
        for (int k = 0; k < nr; ++k) if (fabs(g[k]) > gmax) gmax = fabs(g[k]);
        if (!(gmax > MB_PROJECTION_RESIDUAL)) break;
        for (int a = 0; a < nr; ++a)
            for (int b = 0; b <= a; ++b) {
                const double *Ja = J + a * NQ, *Jb = J + b * NQ;
                double s = 0.0;
                for (int i = 0; i < n; ++i) s += Ja[i] * Jb[i];
                A[a * DAE_NR + b] = s;
            }
        for (int k = 0; k < nr; ++k) r[k] = g[k];
        if (dae_gram_solve(A, r, lam, nr, 0.0) < 0) return changed;
        if (MB_HAS_QUAT) {
            for (int i = 0; i < n; ++i) {
                double s = 0.0;
                for (int k = 0; k < nr; ++k) s += J[k * NQ + i] * lam[k];
                dq[i] = -s;
            }
            dae_quaternion_step(q, dq);
        } else {
            for (int i = 0; i < n; ++i) {
                double s = 0.0;
                for (int k = 0; k < nr; ++k) s += J[k * NQ + i] * lam[k];
                q[i] -= s;
            }
        }
        changed = 1;
    }
    if (changed) dae_rows_eval(q, qd, p, u, work);
    dynamics(q, qd, p, u, work);
    if (mass_cholesky(L)) return changed;
    for (int col = 0; col < nr; ++col) r[col] = dae_row_solve(L, J, qd, Y, col) + gt[col];  /* Y = L^-1 J_r^T */
    for (int a = 0; a < nr; ++a)
        for (int b = 0; b <= a; ++b) {
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Y[i * DAE_NR + a] * Y[i * DAE_NR + b];
            A[a * DAE_NR + b] = s;
        }
    if (dae_gram_solve(A, r, lam, nr, dae_scale) < 0) return changed;
    for (int i = 0; i < n; ++i) {
        double s = 0.0;
        for (int k = 0; k < nr; ++k) s += Y[i * DAE_NR + k] * lam[k];
        dq[i] = s;
    }
    upper_solve(L, dq);
    for (int i = 0; i < n; ++i) qd[i] -= dq[i];
    return 1;
}

/* The contact watch of the dae loop (dae_watch; nk = 0: off): after every accepted step
   the gaps of the free contacts and the normal forces of the held ones (rows of kind
   contact, from the multipliers of the step end's solve) are checked as
   events.ContactWatch does; an event step is not taken: the loop returns EVENT with
   [t_new, y_new, f_new, F (7 rows of NY)] in ev (y = [q (NCOORD), v (NQ), z (NZ)]).  gaps: of every contact at the last
   accepted step (updated); held[k] = 1 for a contact held closed. */
static __thread int dae_nk = 0;
static __thread const long *dae_held;
static __thread double *dae_gaps, *dae_ev, dae_gap_tol;

int dae_watch(int nk, const long *held, double *gaps, double gap_tol, double *ev) {
    dae_nk = nk; dae_held = held; dae_gaps = gaps; dae_gap_tol = gap_tol; dae_ev = ev;
    return 0;
}

/* 1 when the step to (t, y) closes a free contact or leaves a held one pulling, else 0
   (and the gaps become the step end's).  dae_lam holds the multipliers at (t, y). */
static int dae_event(double t, const double *y, const double *p) {
    double kc[CONTACTS_SIZE + 1], u[1] = {0.0};
    (void)t;
    int event = 0;
    const int own = dae_nk < DAE_NK ? dae_nk : DAE_NK, features = dae_nk > DAE_NK && mb_collide_count();
    if (!MB_HAS_CONTACTS && !features) return 0;
    if (MB_HAS_CONTACTS) contacts(y, y + NCOORD, p, u, kc);
    if (features) mb_collide_eval(y, y + NCOORD, p);  /* the candidate collision features (collide.c) */
    for (int k = 0; k < dae_nk; ++k) {
        if (dae_held[k]) continue;
        const double g0 = dae_gaps[k], g1 = k < own ? kc[CONTACTS_GAP_OFF + k] : mb_collide_gap_of(k - DAE_NK);
        if ((g1 < 0.0 && 0.0 <= g0) || (g1 < -dae_gap_tol && -dae_gap_tol < g0)) event = 1;
    }
    if (!event) {  /* a held force pulling (beyond rounding: MB_FORCE_ROUNDING) */
        double most = 0.0;
        for (int k = 0; k < dae_nr; ++k)
            if (dae_spec[DAE_SPEC_LONGS * k] == DAE_ROW_CONTACT && fabs(dae_lam[k]) > most) most = fabs(dae_lam[k]);
        for (int k = 0; k < dae_nr; ++k)
            if (dae_spec[DAE_SPEC_LONGS * k] == DAE_ROW_CONTACT && dae_lam[k] < -MB_FORCE_ROUNDING * most) event = 1;
    }
    if (!event && mb_fr_n > 0) event = mb_friction_event();  /* (the friction solve's, at (t, y) too) */
    if (!event && features && mb_collide_leaves()) event = 1;  /* a new broad phase: Python finds no event */
    if (!event)
        for (int k = 0; k < dae_nk; ++k) {
            const double g1 = k < own ? kc[CONTACTS_GAP_OFF + k] : mb_collide_gap_of(k - DAE_NK);
            if (g1 == g1) dae_gaps[k] = g1;  /* (a feature that is not a candidate keeps its bound) */
        }
    return event;
}

#include "dop853_dense.h"

/* Locating an event on its step: the gap (m) of contact k, or the multiplier (N) of the
   configured row `row` (a held contact's normal force), at time s of the event step. */
double dae_gap_at(double s, double t_old, double h, const double *y_old, const double *F, int ny, long k,
                  const double *p) {
    double y[NMECH + NZ + 1], kc[CONTACTS_SIZE + 1], u[1] = {0.0};
    mb_dop853_dense(s, t_old, h, y_old, F, ny, y);
    if (k >= DAE_NK) return mb_collide_gap(k - DAE_NK, y, y + NCOORD, p);  /* a collision feature */
    if (!MB_HAS_CONTACTS) return NAN;
    contacts(y, y + NCOORD, p, u, kc);
    return kc[CONTACTS_GAP_OFF + k];
}

/* The KKT solve at time s of the event step (its multipliers in dae_lam, the friction
   solve's state in friction.h); 0, or nonzero when it failed.  With drive elements their
   forces at the step's drive states (y after [q, v]) join tau, as in the loop (drive_rhs). */
static int dae_solve_at(double s, double t_old, double h, const double *y_old, const double *F, int ny,
                        const double *p, const double *tau) {
    double y[NMECH + NZ + 1], qdd[NQ + 1], tau_buf[NQ + 1], tau_all[NQ + 1];
    mb_dop853_dense(s, t_old, h, y_old, F, ny, y);
    const double *z = ny > NMECH ? y + NMECH : 0;
    if (mb_inputs(s, y, y + NCOORD, z)) return MB_INPUT_FAILED;  /* (Python callables at this state: inputs.h) */
    tau = mb_input_tau(tau, tau_buf);
    if (HAS_DRIVES && z) {
        double buf[1 + NZ], out[NV + NZ + 1];
        drives(y, y + NCOORD, p, mb_drive_u(s, z, buf), out);
        for (int i = 0; i < NV; ++i) tau_all[i] = out[i] + (tau ? tau[i] : 0.0);
        tau = tau_all;
    }
    double *work = malloc(sizeof(double) * (NDAEWORK + 1));
    if (!work) return -4;
    dae_time = s;
    const int status = dae_accelerations(y, y + NCOORD, p, mb_input_u(), tau, qdd, work);
    free(work);
    return status;
}

double dae_force_at(double s, double t_old, double h, const double *y_old, const double *F, int ny, long row,
                    const double *p, const double *tau) {
    return dae_solve_at(s, t_old, h, y_old, F, ny, p, tau) ? NAN : dae_lam[row];
}

/* Friction events on the event step: sticking contact j's distance outside the cone (N,
   from the friction solve at time s) and sliding contact j's slip velocity (m/s) along the
   tangent-coordinate direction (e0, e1) at time s. */
double dae_cone_at(double s, double t_old, double h, const double *y_old, const double *F, int ny, long j,
                   const double *p, const double *tau) {
    return dae_solve_at(s, t_old, h, y_old, F, ny, p, tau) ? NAN : mb_friction_margin((int)j);
}

double dae_slip_at(double s, double t_old, double h, const double *y_old, const double *F, int ny, long j,
                   const double *p, double e0, double e1) {
    double y[NMECH + NZ + 1];
    mb_dop853_dense(s, t_old, h, y_old, F, ny, y);
    return mb_friction_along((int)j, y, y + NCOORD, p, e0, e1);
}

/* The event's time on its step by Brent's method in C (events_c.py): where the gap of
   contact `index` (dae_gap_root) or the multiplier of configured row `index` (dae_force_root)
   crosses zero in [a, b]; *status as mb_brentq's. */
struct dae_root_ctx { double t_old, h; const double *y_old, *F; int ny; long index; const double *p, *tau; };

static double dae_gap_fn(double s, void *c) {
    const struct dae_root_ctx *x = c;
    return dae_gap_at(s, x->t_old, x->h, x->y_old, x->F, x->ny, x->index, x->p);
}

static double dae_force_fn(double s, void *c) {
    const struct dae_root_ctx *x = c;
    return dae_force_at(s, x->t_old, x->h, x->y_old, x->F, x->ny, x->index, x->p, x->tau);
}

struct dae_slip_ctx { struct dae_root_ctx c; double e0, e1; };

static double dae_cone_fn(double s, void *c) {
    const struct dae_root_ctx *x = c;
    return dae_cone_at(s, x->t_old, x->h, x->y_old, x->F, x->ny, x->index, x->p, x->tau);
}

static double dae_slip_fn(double s, void *c) {
    const struct dae_slip_ctx *x = c;
    return dae_slip_at(s, x->c.t_old, x->c.h, x->c.y_old, x->c.F, x->c.ny, x->c.index, x->c.p, x->e0, x->e1);
}

/* Where sticking contact j leaves the cone (dae_cone_root) or sliding contact j's slip along
   (e0, e1) reaches zero (dae_slip_root) in [a, b]; *status as mb_brentq's. */
double dae_cone_root(double a, double b, double t_old, double h, const double *y_old, const double *F, int ny, long j,
                     const double *p, const double *tau, double xtol, double rtol, int *status) {
    struct dae_root_ctx c = {t_old, h, y_old, F, ny, j, p, tau};
    return mb_brentq(dae_cone_fn, &c, a, b, xtol, rtol, MB_BRENTQ_ITERATIONS, status);
}

double dae_slip_root(double a, double b, double t_old, double h, const double *y_old, const double *F, int ny, long j,
                     const double *p, double e0, double e1, double xtol, double rtol, int *status) {
    struct dae_slip_ctx c = {{t_old, h, y_old, F, ny, j, p, 0}, e0, e1};
    return mb_brentq(dae_slip_fn, &c, a, b, xtol, rtol, MB_BRENTQ_ITERATIONS, status);
}

double dae_gap_root(double a, double b, double t_old, double h, const double *y_old, const double *F, int ny, long index,
                    const double *p, double xtol, double rtol, int *status) {
    struct dae_root_ctx c = {t_old, h, y_old, F, ny, index, p, 0};
    return mb_brentq(dae_gap_fn, &c, a, b, xtol, rtol, MB_BRENTQ_ITERATIONS, status);
}

double dae_force_root(double a, double b, double t_old, double h, const double *y_old, const double *F, int ny,
                      long index, const double *p, const double *tau, double xtol, double rtol, int *status) {
    struct dae_root_ctx c = {t_old, h, y_old, F, ny, index, p, tau};
    return mb_brentq(dae_force_fn, &c, a, b, xtol, rtol, MB_BRENTQ_ITERATIONS, status);
}
#else
#define NDAEWORK 0
#endif
