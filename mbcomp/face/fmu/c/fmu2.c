/* The FMI 2.0 interface of an exported mbcomp model (face/fmu): model exchange and
   co-simulation in one library.  Appended to the model's own template unit (the tree and
   KKT solves, DOP853, the dae formulation's rows), so it calls the same static functions
   the compiled simulate runs: rhs, dop853_run, dae_project, dae_rows_eval.  Like the
   templates it depends only on the kind of model: the model's sizes, value references,
   start values and rows (FMU_*, fmu_*) are constants that face/fmu/sources.py declares
   before this text and defines in a unit of their own, so this unit's object is cached
   and shared by the FMUs of every model of one kind.

   State y = [q (NCOORD), v (NV), z (NZ)], the compiled loop's.  Constraints (loops, motors)
   and held contacts are rows of the dae formulation's KKT solve with Baumgarte gains
   (configured on entry to every call: the configuration is per thread).  Co-simulation:
   fmi2DoStep runs DOP853 (rtol, atol: parameters) with the dae loop's projection after
   each step and its contact watch; an event step is located (Brent's method on the dense
   output), the impact applied and the loop restarted, as mbcomp's simulate does.  Model
   exchange: derivatives of y, one event indicator per contact (its gap, or the normal force
   of a held contact), impacts applied in fmi2NewDiscreteStates. */
#include "fmi2_decl.h"

mb_size_t strlen(const char *);
char *strncpy(char *, const char *, mb_size_t);
int strcmp(const char *, const char *);
double tan(double);

#ifndef DAE_LOOP
#define FMU_ROWS 0
#else
#define FMU_ROWS 1
#endif

enum { FMU_INSTANTIATED, FMU_INITIALISING, FMU_EVENT_MODE, FMU_CONTINUOUS, FMU_STEPPING, FMU_TERMINATED, FMU_FAILED };

typedef struct {
    fmi2CallbackFunctions cb;
    char name[128];
    fmi2Type kind;
    int phase, logging;
    double t, h, rtol, atol, rest_speed, max_step;
    double *y, *f, *der, *p, *u, *tau, *work, *ev, *scratch, *kc;
    long *spec;       /* configured rows: the model's (FMU_NR0) then the held contacts */
    double *data;
    int nr;
    long *held;       /* 1: contact k is held closed */
    double *gaps;     /* gaps at the loop's state (the contact watch's) */
    int fresh;        /* the loop restarts (first step chosen again) */
    int f_stale;      /* f is not the rate at y (an input changed) */
    int der_ok;
    long events;
    /* Look-ahead (co-simulation without inputs or contacts): the loop steps on past the
       communication point at its own pace, its dense output gives the values at the next
       points (t, t + h, t + 2h, ...), kept in `ahead` (FMU_AHEAD rows) for the next calls;
       yi, fi, ti: the loop's own state, ahead of the visible one (t, y). */
    int look;
    double *yi, *fi, ti, stop, *ahead, ahead_t[FMU_AHEAD];
    int n_ahead, i_ahead;
    /* Model parameters (face/fmu/derived.py): env (FMU_NE), which of them and which entries
       of p the importer set (those keep their value; the others follow their expressions). */
    double *env;
    int *env_set, *p_set, any_env_set;
} fmu_t;

static void fmu_log(fmu_t *I, fmi2Status status, const char *category, const char *message) {
    if (I && I->cb.logger && (I->logging || status > fmi2Warning))
        I->cb.logger(I->cb.componentEnvironment, I->name, status, category, "%s", message);
}

/* ---- the model's state of motion ------------------------------------------------------- */
static void fmu_configure(fmu_t *I, int watch) {
#if FMU_ROWS
    dae_configure_rows(I->nr > 0 ? I->nr : -1, I->spec, I->data, fmu_programs, FMU_ALPHA, FMU_BETA,
                       FMU_SCHUR_SCALE, FMU_SINGULAR_TOL);
    if (watch && FMU_NK > 0) dae_watch(FMU_NK, I->held, I->gaps, FMU_GAP_TOL, I->ev);
    else dae_watch(0, 0, 0, 0.0, 0);
#else
    (void)I; (void)watch;
#endif
}

static void fmu_tau(fmu_t *I) {
    for (int i = 0; i < FMU_NV; ++i) I->tau[i] = 0.0;
    for (int k = 0; k < FMU_NU; ++k) I->tau[fmu_input_speed[k]] += I->u[k];
}

/* Rows: the model's constraint and motor rows, then one per held contact. */
static void fmu_rows(fmu_t *I) {
    int nr = FMU_NR0;
    for (int k = 0; k < FMU_NK; ++k) {
        if (!I->held[k]) continue;
        long *s = I->spec + FMU_SPEC_LONGS * nr;
        s[0] = FMU_ROW_CONTACT; s[1] = k; s[2] = s[3] = 0; s[4] = -1;
        I->data[FMU_DATA_DOUBLES * nr] = I->data[FMU_DATA_DOUBLES * nr + 1] = 0.0;
        ++nr;
    }
    I->nr = nr;
    I->der_ok = 0;
}

static double fmu_no_input[1];

/* Contacts' gaps, Jacobian rows and bias at y (into I->kc). */
static void fmu_contacts(fmu_t *I, const double *y) {
    if (FMU_NK > 0) contacts(y, y + NCOORD, I->p, fmu_no_input, I->kc);
}

static double fmu_gap(fmu_t *I, int k) { return I->kc[CONTACTS_GAP_OFF + k]; }

static double fmu_approach(fmu_t *I, int k, const double *qd) {
    double s = 0.0;
    for (int i = 0; i < NV; ++i) s += I->kc[CONTACTS_JACOBIAN_OFF + k * NV + i] * qd[i];
    return s;
}

/* The accelerations at (t, y) with the configured rows (0: ok). */
static int fmu_rate(fmu_t *I, double t, const double *y, double *f) {
    return rhs(t, y, f, I->p, I->tau, I->work);
}

/* The normal forces (N, pushing positive) of the held contacts at (t, y): forces[k]
   (0 for a contact not held or dropped as dependent); the status of the solve. */
static int fmu_contact_forces(fmu_t *I, double t, const double *y, double *forces) {
    for (int k = 0; k < FMU_NK; ++k) forces[k] = 0.0;
#if FMU_ROWS
    const int status = fmu_rate(I, t, y, I->scratch);
    if (status) return status;
    for (int r = FMU_NR0; r < I->nr; ++r) forces[I->spec[FMU_SPEC_LONGS * r + 1]] = dae_lam[r];
#else
    (void)I; (void)t; (void)y;
#endif
    return 0;
}

#if FMU_ROWS
/* Newton's impact law (formulations/impact.py, solve_impact) on the contacts flagged in
   `involved`, every configured row of the model respected (its rate -g_t), restitution
   e_k (0 where `plastic`), impulses >= 0: contacts whose impulse would pull are released,
   closed contacts the impact would drive in join.  qd (at q = y) is replaced by the speeds
   after; `involved` becomes the final set.  Returns 0, or -1 when no set settles. */
static int fmu_impact_solve(fmu_t *I, double t, double *y, int *involved, const int *plastic) {
    double *q = y, *qd = y + NCOORD, *work = I->work;
    double *L = work + DYNAMICS_MASS_MATRIX_OFF;
    double *g = work + DAE_ROWS_OFF, *J = g + DAE_NR, *gt = J + DAE_NR * NQ;
    double *Y = work + DAE_SOLVE_OFF, *A = Y + NQ * DAE_NR, *r = A + DAE_NR * DAE_NR, *lam = r + DAE_NR;
    double *dq = lam + DAE_NR;
    double approach[FMU_NK + 1], after[FMU_NK + 1], qd0[FMU_NV + 1];
    long spec[FMU_SPEC_LONGS * (FMU_NR0 + FMU_NK + 1)];
    double data[FMU_DATA_DOUBLES * (FMU_NR0 + FMU_NK + 1)];
    (void)g;
    fmu_contacts(I, y);
    double amax = 0.0;
    for (int k = 0; k < FMU_NK; ++k) {
        approach[k] = fmu_approach(I, k, qd);
        if (fabs(approach[k]) > amax) amax = fabs(approach[k]);
    }
    for (int i = 0; i < NV; ++i) qd0[i] = qd[i];
    for (int round = 0; round < 4 * FMU_NK + 4; ++round) {
        int nr = FMU_NR0, contact_row[FMU_NK + 1];
        for (int k = 0; k < FMU_SPEC_LONGS * FMU_NR0; ++k) spec[k] = I->spec[k];
        for (int k = 0; k < FMU_DATA_DOUBLES * FMU_NR0; ++k) data[k] = I->data[k];
        for (int k = 0; k < FMU_NK; ++k) {
            contact_row[k] = -1;
            if (!involved[k]) continue;
            long *s = spec + FMU_SPEC_LONGS * nr;
            s[0] = FMU_ROW_CONTACT; s[1] = k; s[2] = s[3] = 0; s[4] = -1;
            contact_row[k] = nr++;
        }
        dae_configure_rows(nr, spec, data, fmu_programs, FMU_ALPHA, FMU_BETA, FMU_SCHUR_SCALE, FMU_SINGULAR_TOL);
        dae_time = t;
        dynamics(q, qd0, I->p, fmu_no_input, work);
        dae_rows_eval(q, qd0, I->p, fmu_no_input, work);
        if (mass_cholesky(L)) return -1;
        for (int col = 0; col < nr; ++col) {
            const double rate = dae_row_solve(L, J, qd0, Y, col);
            double target = -gt[col];
            if (spec[FMU_SPEC_LONGS * col] == FMU_ROW_CONTACT) {
                const int k = (int)spec[FMU_SPEC_LONGS * col + 1];
                const double e = (plastic[k] || I->held[k]) ? 0.0 : I->p[fmu_restitution[k]];
                target = -e * (approach[k] < 0.0 ? approach[k] : 0.0);
            }
            r[col] = target - rate;
        }
        for (int a = 0; a < nr; ++a)
            for (int b = 0; b <= a; ++b) {
                double s = 0.0;
                for (int i = 0; i < NQ; ++i) s += Y[i * DAE_NR + a] * Y[i * DAE_NR + b];
                A[a * DAE_NR + b] = s;
            }
        if (dae_gram_solve(A, r, lam, nr, FMU_SCHUR_SCALE) < 0) return -1;
        for (int i = 0; i < NQ; ++i) {
            double s = 0.0;
            for (int k = 0; k < nr; ++k) s += Y[i * DAE_NR + k] * lam[k];
            dq[i] = s;
        }
        upper_solve(L, dq);
        for (int i = 0; i < NV; ++i) qd[i] = qd0[i] + dq[i];
        /* an impulse that pulls: release the most pulling contact and solve again */
        double pmax = 1.0, pmin = 0.0;
        int worst = -1;
        for (int k = 0; k < FMU_NK; ++k)
            if (contact_row[k] >= 0 && fabs(lam[contact_row[k]]) > pmax) pmax = fabs(lam[contact_row[k]]);
        for (int k = 0; k < FMU_NK; ++k)
            if (contact_row[k] >= 0 && lam[contact_row[k]] < pmin) { pmin = lam[contact_row[k]]; worst = k; }
        if (worst >= 0 && pmin < -1e-12 * pmax) { involved[worst] = 0; continue; }
        int joining = 0;
        for (int k = 0; k < FMU_NK; ++k) {
            after[k] = fmu_approach(I, k, qd);
            if (!involved[k] && fmu_gap(I, k) < FMU_GAP_TOL && after[k] < -1e-12 * (amax > 1.0 ? amax : 1.0)) {
                involved[k] = 1;
                joining = 1;
            }
        }
        if (!joining) {
            fmu_configure(I, 0);
            return 0;
        }
    }
    fmu_configure(I, 0);
    return -1;
}
#endif

/* ContactWatch.impact: the impact of the contacts closed and closing at (t, y); contacts
   leaving slower than the rest speed are held closed from now on (a plastic impact on
   them).  Returns 1 when the speeds changed, 0 when nothing closes, -1 on failure. */
static int fmu_impact(fmu_t *I, double t, double *y) {
#if FMU_ROWS
    int active[FMU_NK + 1], involved[FMU_NK + 1], plastic[FMU_NK + 1], any = 0;
    double qd_before[FMU_NV + 1];
    fmu_contacts(I, y);
    for (int k = 0; k < FMU_NK; ++k) {
        active[k] = !I->held[k] && fmu_gap(I, k) < FMU_GAP_TOL + 1e-7 && fmu_approach(I, k, y + NCOORD) < 0.0;
        involved[k] = active[k] || I->held[k];
        plastic[k] = 0;
        any |= active[k];
    }
    if (!any) return 0;
    for (int i = 0; i < NV; ++i) qd_before[i] = y[NCOORD + i];
    if (fmu_impact_solve(I, t, y, involved, plastic)) return -1;
    int resting = 0;
    for (int k = 0; k < FMU_NK; ++k)
        if (involved[k] && !I->held[k] && fabs(fmu_approach(I, k, y + NCOORD)) < I->rest_speed) {
            plastic[k] = 1;
            resting = 1;
        }
    if (resting) {
        for (int i = 0; i < NV; ++i) y[NCOORD + i] = qd_before[i];
        for (int k = 0; k < FMU_NK; ++k) involved[k] = active[k] || I->held[k];
        if (fmu_impact_solve(I, t, y, involved, plastic)) return -1;
    }
    for (int k = 0; k < FMU_NK; ++k) I->held[k] = (I->held[k] && involved[k]) || plastic[k];
    fmu_rows(I);
    fmu_configure(I, 0);
    I->events += 1;
    return 1;
#else
    (void)I; (void)t; (void)y;
    return 0;
#endif
}

/* ContactWatch.release: open the held contacts whose force would pull, the most pulling
   first.  Returns 1 when one was opened. */
static int fmu_release(fmu_t *I, double t, const double *y) {
    int changed = 0;
    double forces[FMU_NK + 1];
    for (;;) {
        int n = 0, worst = -1;
        double fmax = 1.0, fmin = 0.0;
        for (int k = 0; k < FMU_NK; ++k) n += I->held[k] != 0;
        if (!n || fmu_contact_forces(I, t, y, forces)) break;
        for (int k = 0; k < FMU_NK; ++k) if (I->held[k] && fabs(forces[k]) > fmax) fmax = fabs(forces[k]);
        for (int k = 0; k < FMU_NK; ++k) if (I->held[k] && forces[k] < fmin) { fmin = forces[k]; worst = k; }
        if (worst < 0 || fmin >= -1e-12 * fmax) break;
        I->held[worst] = 0;
        fmu_rows(I);
        fmu_configure(I, 0);
        changed = 1;
    }
    return changed;
}

/* Contacts at the start (ContactWatch.start): a penetration is an error; closed contacts
   resting on their surface are held; closing ones take their impact. */
static int fmu_start_contacts(fmu_t *I) {
    fmu_contacts(I, I->y);
    for (int k = 0; k < FMU_NK; ++k) {
        if (fmu_gap(I, k) < -FMU_GAP_TOL) {
            fmu_log(I, fmi2Error, "logStatusError", "the initial state penetrates a contact: move the body out of contact");
            return -1;
        }
    }
    int closing = 0;
    for (int k = 0; k < FMU_NK; ++k) {
        const double speed = fmu_approach(I, k, I->y + NCOORD);
        if (fmu_gap(I, k) < FMU_GAP_TOL) {
            if (fabs(speed) < I->rest_speed) I->held[k] = 1;
            else if (speed < 0) closing = 1;
        }
    }
    fmu_rows(I);
    fmu_configure(I, 0);
    if (closing && fmu_impact(I, I->t, I->y) < 0) return -1;
    fmu_release(I, I->t, I->y);
    fmu_contacts(I, I->y);
    for (int k = 0; k < FMU_NK; ++k) I->gaps[k] = fmu_gap(I, k);
    return 0;
}

/* ---- co-simulation: contact events on a step ----------------------------------------- */
#if FMU_ROWS
struct fmu_root_ctx { fmu_t *I; double t_old, h; const double *y_old, *F; int k; };

static double fmu_gap_fn(double s, void *c) {
    struct fmu_root_ctx *x = c;
    mb_dop853_dense(s, x->t_old, x->h, x->y_old, x->F, FMU_NY, x->I->scratch);
    fmu_contacts(x->I, x->I->scratch);
    return fmu_gap(x->I, x->k);
}

static double fmu_force_fn(double s, void *c) {
    struct fmu_root_ctx *x = c;
    double forces[FMU_NK + 1], y[FMU_NY + 1];
    mb_dop853_dense(s, x->t_old, x->h, x->y_old, x->F, FMU_NY, y);
    if (fmu_contact_forces(x->I, s, y, forces)) return NAN;
    return forces[x->k];
}

/* The loop stopped at an event step [t_old, ev[0]] (I->y: its start): locate the first
   closing or lift-off (as run/simulate.py's _contact_step), move there and apply it. */
static int fmu_event(fmu_t *I, double t_old) {
    const double t_new = I->ev[0], h = t_new - t_old;
    const double *y_new = I->ev + 1, *F = I->ev + 1 + 2 * FMU_NY;
    double te = INFINITY, forces[FMU_NK + 1], g_new[FMU_NK + 1];
    int closing = 0, release = -1, status = 0;
    struct fmu_root_ctx ctx = {I, t_old, h, I->y, F, 0};
    fmu_contacts(I, y_new);
    for (int k = 0; k < FMU_NK; ++k) g_new[k] = fmu_gap(I, k);
    for (int k = 0; k < FMU_NK; ++k) {
        const double g0 = I->gaps[k], g1 = g_new[k];
        if (I->held[k] || !((g1 < 0.0 && 0.0 <= g0) || (g1 < -FMU_GAP_TOL && -FMU_GAP_TOL < g0))) continue;
        ctx.k = k;
        double tk = t_old;
        if (fmu_gap_fn(t_old, &ctx) > 0.0) {
            tk = mb_brentq(fmu_gap_fn, &ctx, t_old, t_new, FMU_GAP_XTOL, 4 * DBL_EPSILON, MB_BRENTQ_ITERATIONS, &status);
            if (status) return -1;
        }
        if (tk < te) { te = tk; closing = 1; }
    }
    if (!fmu_contact_forces(I, t_new, y_new, forces)) {
        int k = -1;
        double fmin = 0.0;
        for (int j = 0; j < FMU_NK; ++j) if (I->held[j] && forces[j] < fmin) { fmin = forces[j]; k = j; }
        if (k >= 0) {
            ctx.k = k;
            double tk = t_old;
            if (fmu_force_fn(t_old, &ctx) > 0.0) {
                tk = mb_brentq(fmu_force_fn, &ctx, t_old, t_new, FMU_FORCE_XTOL, 4 * DBL_EPSILON, MB_BRENTQ_ITERATIONS,
                               &status);
                if (status) return -1;
            }
            if (tk < te) { te = tk; closing = 0; release = k; }
        }
    }
    if (!(te < INFINITY)) {  /* the watch and this disagree: carry on from the step's end */
        mb_copy(I->y, y_new, sizeof(double) * FMU_NY);
        I->t = t_new;
    } else {
        double y_event[FMU_NY + 1];
        if (te == t_new) mb_copy(y_event, y_new, sizeof(double) * FMU_NY);
        else mb_dop853_dense(te, t_old, h, I->y, F, FMU_NY, y_event);
        normalize_state(y_event);
        mb_copy(I->y, y_event, sizeof(double) * FMU_NY);
        I->t = te;
        if (closing) {
            const int changed = fmu_impact(I, te, I->y);
            if (changed < 0) return -1;
            if (!changed) {  /* closed but not closing: it rests on its surface */
                fmu_contacts(I, I->y);
                for (int k = 0; k < FMU_NK; ++k) if (fmu_gap(I, k) < FMU_GAP_TOL) I->held[k] = 1;
                fmu_rows(I);
            }
        } else {
            I->held[release] = 0;
            fmu_rows(I);
            fmu_configure(I, 0);
            fmu_release(I, te, I->y);
        }
    }
    fmu_contacts(I, I->y);
    for (int k = 0; k < FMU_NK; ++k) I->gaps[k] = fmu_gap(I, k);
    I->fresh = 1;
    return 0;
}
#endif

/* ---- instance life ------------------------------------------------------------------- */
static void fmu_defaults(fmu_t *I) {
    for (int i = 0; i < FMU_NY; ++i) I->y[i] = fmu_y_start[i];
    for (int i = 0; i < FMU_NP; ++i) I->p[i] = fmu_p_start[i];
    for (int i = 0; i < FMU_NU; ++i) I->u[i] = 0.0;
    for (int k = 0; k < FMU_SPEC_LONGS * FMU_NR0; ++k) I->spec[k] = fmu_spec0[k];
    for (int k = 0; k < FMU_DATA_DOUBLES * FMU_NR0; ++k) I->data[k] = fmu_data0[k];
    for (int k = 0; k < FMU_NK; ++k) { I->held[k] = 0; I->gaps[k] = 0.0; }
    I->nr = FMU_NR0;
    I->t = 0.0; I->h = 0.0;
    I->rtol = FMU_RTOL0; I->atol = FMU_ATOL0; I->rest_speed = FMU_REST0; I->max_step = INFINITY;
    I->phase = FMU_INSTANTIATED;
    I->fresh = 1; I->f_stale = 1; I->der_ok = 0; I->events = 0;
    I->look = 0; I->n_ahead = I->i_ahead = 0; I->ti = 0.0; I->stop = INFINITY;
    for (int k = 0; k < FMU_NE; ++k) { I->env[k] = fmu_env_start[k]; I->env_set[k] = 0; }
    for (int i = 0; i < FMU_NP; ++i) I->p_set[i] = 0;
    I->any_env_set = 0;
}

/* A program of face/fmu/derived.py over the model parameters env (the operations of
   spec/components/expr.py's Expr.evaluate, in its order; NaN where Python raises). */
static double fmu_eval(const double *pc, const double *env) {
    const long n = (long)pc[0];
    double st[64];
    int sp = -1;
    for (long k = 0; k < n; ++k) {
        const int op = (int)pc[1 + 2 * k];
        const double arg = pc[2 + 2 * k];
        if (op <= 1) {
            if (sp >= 63) return NAN;
            st[++sp] = op == 0 ? arg : env[(long)arg];
        } else if (op <= 9) {
            const double x = st[sp];
            st[sp] = op == 2 ? -x : op == 3 ? fabs(x) : op == 4 ? (x < 0.0 ? NAN : sqrt(x)) : op == 5 ? sin(x)
                : op == 6 ? cos(x) : op == 7 ? tan(x) : op == 8 ? exp(x) : (x <= 0.0 ? NAN : log(x));
        } else {
            const double b = st[sp--], a = st[sp];
            st[sp] = op == 10 ? a + b : op == 11 ? a - b : op == 12 ? a * b : op == 13 ? (b == 0.0 ? NAN : a / b)
                : pow(a, b);
        }
    }
    return sp == 0 ? st[0] : NAN;
}

/* The model parameters the importer changed reach p: followers of an expression and the
   derived entries of p are evaluated again (a value set by the importer wins). */
static int fmu_derive(fmu_t *I) {
    if (!I->any_env_set) return 0;
    for (int k = 0; k < FMU_NE; ++k)
        if (!I->env_set[k] && fmu_env_binding[k] >= 0) I->env[k] = fmu_eval(fmu_derive_programs + fmu_env_binding[k], I->env);
    for (int j = 0; j < FMU_ND; ++j) {
        const int i = fmu_derived_p[j];
        if (!I->p_set[i]) I->p[i] = fmu_eval(fmu_derive_programs + fmu_derived_prog[j], I->env);
    }
    for (int i = 0; i < FMU_NP; ++i) if (!isfinite(I->p[i])) return -1;
    return 0;
}

static void fmu_free(fmu_t *I) {
    if (!I) return;
    free(I->y); free(I->f); free(I->der); free(I->p); free(I->u); free(I->tau); free(I->work); free(I->ev);
    free(I->scratch); free(I->kc); free(I->spec); free(I->data); free(I->held); free(I->gaps);
    free(I->yi); free(I->fi); free(I->ahead); free(I->env); free(I->env_set); free(I->p_set);
    free(I);
}

FMI2_EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
FMI2_EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

FMI2_EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, mb_size_t n, const fmi2String categories[]) {
    (void)n; (void)categories;
    if (!c) return fmi2Error;
    ((fmu_t *)c)->logging = on;
    return fmi2OK;
}

FMI2_EXPORT fmi2Component fmi2Instantiate(fmi2String name, fmi2Type kind, fmi2String guid, fmi2String location,
                                          const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                          fmi2Boolean logging) {
    (void)location; (void)visible;
    fmu_t *I = calloc(1, sizeof(fmu_t));
    if (!I) return 0;
    if (functions) mb_copy(&I->cb, functions, sizeof(fmi2CallbackFunctions));
    strncpy(I->name, name ? name : "mbcomp", sizeof(I->name) - 1);
    I->kind = kind;
    I->logging = logging;
    if (!guid || strcmp(guid, FMU_GUID) != 0) {
        fmu_log(I, fmi2Error, "logStatusError", "the GUID does not match this FMU's modelDescription.xml");
        fmu_free(I);
        return 0;
    }
    const mb_size_t nw = (mb_size_t)(NWORK > DYNAMICS_SIZE + NDAEWORK ? NWORK : DYNAMICS_SIZE + NDAEWORK) + 1;
    I->y = calloc(FMU_NY + 1, sizeof(double)); I->f = calloc(FMU_NY + 1, sizeof(double));
    I->der = calloc(FMU_NY + 1, sizeof(double)); I->p = calloc(FMU_NP + 1, sizeof(double));
    I->u = calloc(FMU_NU + 1, sizeof(double)); I->tau = calloc(FMU_NV + 1, sizeof(double));
    I->work = calloc(nw, sizeof(double)); I->ev = calloc(1 + 9 * FMU_NY, sizeof(double));
    I->scratch = calloc(FMU_NY + 1, sizeof(double)); I->kc = calloc((mb_size_t)CONTACTS_SIZE + 1, sizeof(double));
    I->spec = calloc(FMU_SPEC_LONGS * (FMU_NR0 + FMU_NK + 1), sizeof(long));
    I->data = calloc(FMU_DATA_DOUBLES * (FMU_NR0 + FMU_NK + 1), sizeof(double));
    I->held = calloc(FMU_NK + 1, sizeof(long)); I->gaps = calloc(FMU_NK + 1, sizeof(double));
    I->yi = calloc(FMU_NY + 1, sizeof(double)); I->fi = calloc(FMU_NY + 1, sizeof(double));
    I->ahead = calloc((mb_size_t)FMU_AHEAD * (FMU_NY + 1), sizeof(double));
    I->env = calloc(FMU_NE + 1, sizeof(double)); I->env_set = calloc(FMU_NE + 1, sizeof(int));
    I->p_set = calloc(FMU_NP + 1, sizeof(int));
    if (!I->env || !I->env_set || !I->p_set || !I->yi || !I->fi || !I->ahead || !I->y || !I->f || !I->der || !I->p || !I->u || !I->tau || !I->work || !I->ev || !I->scratch || !I->kc
        || !I->spec || !I->data || !I->held || !I->gaps) {
        fmu_free(I);
        return 0;
    }
    fmu_defaults(I);
    return I;
}

FMI2_EXPORT void fmi2FreeInstance(fmi2Component c) {
    fmu_free((fmu_t *)c);
}

FMI2_EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                           fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    I->t = startTime;
    I->stop = stopTimeDefined ? stopTime : INFINITY;
    if (toleranceDefined && tolerance > 0 && I->kind == fmi2CoSimulation) I->rtol = tolerance;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    I->phase = FMU_INITIALISING;
    return fmi2OK;
}

/* The start state made consistent: speed motors start where their coordinate is, positions
   and speeds projected onto the constraints (dae_project), the contacts' start. */
FMI2_EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    if (fmu_derive(I)) {
        fmu_log(I, fmi2Error, "logStatusError", "a parameter computed from the model parameters is not finite");
        I->phase = FMU_FAILED;
        return fmi2Error;
    }
    for (int r = 0; r < FMU_NR0; ++r)  /* a speed motor: its speed (a parameter, or fixed), its start */
        if (fmu_motor_speed_p[r] > -2) {
            const double speed = fmu_motor_speed_p[r] >= 0 ? I->p[fmu_motor_speed_p[r]] : fmu_data0[FMU_DATA_DOUBLES * r];
            I->data[FMU_DATA_DOUBLES * r] = speed;
            I->data[FMU_DATA_DOUBLES * r + 1] = I->y[I->spec[FMU_SPEC_LONGS * r + 2]] - speed * I->t;
        }
    fmu_tau(I);
    fmu_rows(I);
    fmu_configure(I, 0);
#if FMU_ROWS
    if (FMU_NR0 > 0) {  /* (quaternion coordinates stepped by the exp map: dae_quaternion_step) */
        dae_time = I->t;
        for (int it = 0; it < 3; ++it) dae_project(I->y, I->p, fmu_no_input, I->work);
    }
#endif
    if (fmu_start_contacts(I)) { I->phase = FMU_FAILED; return fmi2Error; }
    I->phase = I->kind == fmi2CoSimulation ? FMU_STEPPING : FMU_EVENT_MODE;
    I->fresh = 1; I->der_ok = 0;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2Terminate(fmi2Component c) {
    if (!c) return fmi2Error;
    ((fmu_t *)c)->phase = FMU_TERMINATED;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2Reset(fmi2Component c) {
    if (!c) return fmi2Error;
    fmu_defaults((fmu_t *)c);
    return fmi2OK;
}

/* ---- variables ----------------------------------------------------------------------- */
static int fmu_derivatives(fmu_t *I) {
    if (I->der_ok) return 0;
    fmu_tau(I);
    fmu_configure(I, 0);
    const int status = fmu_rate(I, I->t, I->y, I->der);
    if (status) {
        fmu_log(I, fmi2Error, "logStatusError", "the accelerations cannot be computed at this state (a singular "
                "mass matrix or constraint Jacobian)");
        return status;
    }
    I->der_ok = 1;
    return 0;
}

FMI2_EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n, fmi2Real value[]) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    for (mb_size_t i = 0; i < n; ++i) {
        const long r = (long)vr[i];
        if (r < FMU_VR_DER) value[i] = I->y[r - FMU_VR_STATE];
        else if (r < FMU_VR_PAR) {
            if (I->phase == FMU_INSTANTIATED || fmu_derivatives(I)) return fmi2Error;
            value[i] = I->der[r - FMU_VR_DER];
        } else if (r < FMU_VR_ENV) value[i] = I->p[r - FMU_VR_PAR];
        else if (r < FMU_VR_IN) value[i] = I->env[fmu_env_exported[r - FMU_VR_ENV]];
        else if (r < FMU_VR_RTOL) value[i] = I->u[r - FMU_VR_IN];
        else if (r == FMU_VR_RTOL) value[i] = I->rtol;
        else if (r == FMU_VR_ATOL) value[i] = I->atol;
        else if (r == FMU_VR_REST) value[i] = I->rest_speed;
        else if (r == FMU_VR_MAXSTEP) value[i] = I->max_step < INFINITY ? I->max_step : 0.0;
        else return fmi2Error;
    }
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n, const fmi2Real value[]) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    const int before = I->phase == FMU_INSTANTIATED || I->phase == FMU_INITIALISING;
    for (mb_size_t i = 0; i < n; ++i) {
        const long r = (long)vr[i];
        if (r < FMU_VR_DER) {
            if (!before) { fmu_log(I, fmi2Error, "logStatusError", "coordinates and speeds are set before initialisation"); return fmi2Error; }
            I->y[r - FMU_VR_STATE] = value[i];
        } else if (r < FMU_VR_PAR) {
            return fmi2Error;
        } else if (r < FMU_VR_IN) {
            if (!before) { fmu_log(I, fmi2Error, "logStatusError", "parameters are set before initialisation"); return fmi2Error; }
            if (r < FMU_VR_ENV) {
                I->p[r - FMU_VR_PAR] = value[i];
                I->p_set[r - FMU_VR_PAR] = 1;
            } else {
                const int k = fmu_env_exported[r - FMU_VR_ENV];
                I->env[k] = value[i];
                I->env_set[k] = 1;
                I->any_env_set = 1;
            }
        } else if (r < FMU_VR_RTOL) {
            I->u[r - FMU_VR_IN] = value[i];
            I->f_stale = 1;
        } else if (r == FMU_VR_RTOL) I->rtol = value[i];
        else if (r == FMU_VR_ATOL) I->atol = value[i];
        else if (r == FMU_VR_REST) I->rest_speed = value[i];
        else if (r == FMU_VR_MAXSTEP) I->max_step = value[i] > 0 ? value[i] : INFINITY;
        else return fmi2Error;
    }
    I->der_ok = 0;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n, fmi2Integer value[]) {
    (void)c; (void)vr; (void)value;
    return n ? fmi2Error : fmi2OK;
}
FMI2_EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n, fmi2Boolean value[]) {
    (void)c; (void)vr; (void)value;
    return n ? fmi2Error : fmi2OK;
}
FMI2_EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n, fmi2String value[]) {
    (void)c; (void)vr; (void)value;
    return n ? fmi2Error : fmi2OK;
}
FMI2_EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n, const fmi2Integer value[]) {
    (void)c; (void)vr; (void)value;
    return n ? fmi2Error : fmi2OK;
}
FMI2_EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n, const fmi2Boolean value[]) {
    (void)c; (void)vr; (void)value;
    return n ? fmi2Error : fmi2OK;
}
FMI2_EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n, const fmi2String value[]) {
    (void)c; (void)vr; (void)value;
    return n ? fmi2Error : fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
FMI2_EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
FMI2_EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
FMI2_EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, mb_size_t *n) {
    (void)c; (void)s; (void)n; return fmi2Error;
}
FMI2_EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], mb_size_t n) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error;
}
FMI2_EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], mb_size_t n, fmi2FMUstate *s) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error;
}
FMI2_EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], mb_size_t nu,
                                                    const fmi2ValueReference z[], mb_size_t nz, const fmi2Real dv[],
                                                    fmi2Real dz[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz; return fmi2Error;
}

/* ---- model exchange ------------------------------------------------------------------ */
FMI2_EXPORT fmi2Status fmi2EnterEventMode(fmi2Component c) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    I->phase = FMU_EVENT_MODE;
    return fmi2OK;
}

/* The event: held contacts whose force would pull let go; closing contacts take their impact. */
FMI2_EXPORT fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    if (FMU_NK == 0) return fmi2OK;
    fmu_tau(I);
    fmu_configure(I, 0);
    fmu_release(I, I->t, I->y);
    const int changed = fmu_impact(I, I->t, I->y);
    if (changed < 0) {
        fmu_log(I, fmi2Error, "logStatusError", "the impact has no consistent set of contacts");
        return fmi2Error;
    }
    if (changed) info->valuesOfContinuousStatesChanged = fmi2True;
    I->der_ok = 0;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    I->phase = FMU_CONTINUOUS;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                                   fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    fmu_t *I = c;
    if (!I) return fmi2Error;
    I->t = time;
    I->der_ok = 0;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], mb_size_t nx) {
    fmu_t *I = c;
    if (!I || nx != (mb_size_t)FMU_NY) return fmi2Error;
    mb_copy(I->y, x, sizeof(double) * FMU_NY);
    I->der_ok = 0;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], mb_size_t nx) {
    fmu_t *I = c;
    if (!I || nx != (mb_size_t)FMU_NY) return fmi2Error;
    mb_copy(x, I->y, sizeof(double) * FMU_NY);
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], mb_size_t nx) {
    fmu_t *I = c;
    if (!I || nx != (mb_size_t)FMU_NY) return fmi2Error;
    if (fmu_derivatives(I)) return fmi2Error;
    mb_copy(dx, I->der, sizeof(double) * FMU_NY);
    return fmi2OK;
}

/* One per contact: its gap (m) while free, its normal force (N) while held. */
FMI2_EXPORT fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], mb_size_t nz) {
    fmu_t *I = c;
    double forces[FMU_NK + 1];
    if (!I || nz != (mb_size_t)FMU_NK) return fmi2Error;
    if (nz == 0) return fmi2OK;
    fmu_tau(I);
    fmu_configure(I, 0);
    int any = 0;
    for (int k = 0; k < FMU_NK; ++k) any |= I->held[k] != 0;
    if (any && fmu_contact_forces(I, I->t, I->y, forces)) return fmi2Error;
    fmu_contacts(I, I->y);
    for (int k = 0; k < FMU_NK; ++k) z[k] = I->held[k] ? forces[k] : fmu_gap(I, k);
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], mb_size_t nx) {
    if (!c || nx != (mb_size_t)FMU_NY) return fmi2Error;
    for (mb_size_t i = 0; i < nx; ++i) x[i] = 1.0;
    return fmi2OK;
}

/* ---- co-simulation ------------------------------------------------------------------- */
FMI2_EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n,
                                                   const fmi2Integer order[], const fmi2Real value[]) {
    (void)c; (void)vr; (void)order; (void)value;
    return n ? fmi2Error : fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], mb_size_t n,
                                                    const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)order; (void)value;
    return n ? fmi2Error : fmi2OK;
}

static const char *fmu_loop_failure(int status) {
    return status == -1 ? "DOP853: the step size fell below its minimum"
        : status == -3 ? "DOP853: the state is not finite"
        : "DOP853: the accelerations cannot be computed (a singular mass matrix or constraint Jacobian)";
}

/* fmi2DoStep without inputs or contacts: the value at t + h from the look-ahead rows when it
   is one of them, else from the loop run on past t + h at its own step size, its dense output
   giving the rows of t + h, t + 2h, ... as far as it went (as simulate's t_eval). */
static fmi2Status fmu_step_ahead(fmu_t *I, double target, double h) {
    const double tol = 1e-9 * (fabs(h) > 1e-300 ? fabs(h) : 1.0);
    for (; I->i_ahead < I->n_ahead; ++I->i_ahead) {
        if (I->ahead_t[I->i_ahead] > target + tol) break;
        if (fabs(I->ahead_t[I->i_ahead] - target) <= tol) {
            mb_copy(I->y, I->ahead + (mb_size_t)I->i_ahead * FMU_NY, sizeof(double) * FMU_NY);
            I->t = target;
            ++I->i_ahead;
            return fmi2OK;
        }
    }
    if (!I->look || I->ti > target) {  /* start, or a point the rows miss: the loop from the visible state */
        mb_copy(I->yi, I->y, sizeof(double) * FMU_NY);
        I->ti = I->t;
        I->fresh = !I->look || I->fresh;
        if (!I->fresh && fmu_rate(I, I->ti, I->yi, I->fi)) { I->phase = FMU_FAILED; return fmi2Error; }
        I->look = 1;
    }
    double t_end = I->fresh ? target : I->ti + I->h;
    if (t_end < target) t_end = target;
    if (t_end > I->stop && I->stop >= target) t_end = I->stop;
    int n = 0;
    for (; n < FMU_AHEAD; ++n) {
        const double tk = target + n * h;
        if (tk > t_end + tol || (n && !(h > 0))) break;
        I->ahead_t[n] = tk < t_end ? tk : t_end;
    }
    long counts[3] = {0, 0, 0}, n_steps = 0, i_out = 0;
    double state[2] = {I->ti, I->fresh ? 0.0 : I->h};
    const int status = dop853_run(I->p, I->tau, state, I->yi, I->fi, t_end, I->rtol, I->atol, I->max_step, I->ahead_t,
                                  n, &i_out, I->ahead, 0, 0, 0, &n_steps, counts);
    I->fresh = 0;
    I->h = state[1];
    I->ti = state[0];
    if (status != 0) {
        fmu_log(I, fmi2Error, "logStatusError", fmu_loop_failure(status));
        I->phase = FMU_FAILED;
        return fmi2Error;
    }
    I->n_ahead = (int)i_out;
    I->i_ahead = 1;
    mb_copy(I->y, I->ahead, sizeof(double) * FMU_NY);
    I->t = target;
    return fmi2OK;
}

/* DOP853 from the current time to t + h (the loop's own step control, its step carried
   from call to call), contact events located and applied inside the step. */
FMI2_EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    fmu_t *I = c;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!I || I->phase != FMU_STEPPING) return fmi2Error;
    const double target = t + h;
    if (FMU_NU == 0 && FMU_NK == 0) {
        fmu_tau(I);
        fmu_configure(I, 0);
        const fmi2Status status = fmu_step_ahead(I, target, h);
        I->der_ok = 0;
        return status;
    }
    long counts[3] = {0, 0, 0}, n_steps = 0, i_out = 0;
    double t_out[1] = {target};
    fmu_tau(I);
    fmu_configure(I, 1);
    if (I->f_stale && !I->fresh) {
        if (fmu_rate(I, I->t, I->y, I->f)) { I->phase = FMU_FAILED; return fmi2Error; }
    }
    I->f_stale = 0;
#if FMU_ROWS
    int events = 0;
#endif
    while (I->t < target) {
        double state[2] = {I->t, I->fresh ? 0.0 : I->h};
        i_out = 0;
        const int status = dop853_run(I->p, I->tau, state, I->y, I->f, target, I->rtol, I->atol, I->max_step, t_out, 1,
                                      &i_out, I->scratch, 0, 0, 0, &n_steps, counts);
        I->fresh = 0;
        I->h = state[1];
        if (status == 0) { I->t = target; break; }
#if FMU_ROWS
        if (status == LOOP_EVENT) {
            I->t = state[0];
            if (++events > 100000 || fmu_event(I, state[0])) {
                fmu_log(I, fmi2Error, "logStatusError", "a contact event could not be located or applied");
                I->phase = FMU_FAILED;
                return fmi2Error;
            }
            fmu_configure(I, 1);
            continue;
        }
#endif
        I->t = state[0];
        fmu_log(I, fmi2Error, "logStatusError", fmu_loop_failure(status));
        I->phase = FMU_FAILED;
        return fmi2Error;
    }
    I->der_ok = 0;
    return fmi2OK;
}

FMI2_EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

FMI2_EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}
FMI2_EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    fmu_t *I = c;
    if (!I || s != fmi2LastSuccessfulTime) return fmi2Discard;
    *value = I->t;
    return fmi2OK;
}
FMI2_EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}
FMI2_EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    fmu_t *I = c;
    if (!I || s != fmi2Terminated) return fmi2Discard;
    *value = fmi2False;
    return fmi2OK;
}
FMI2_EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}
