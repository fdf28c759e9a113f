/* The step budget of the collapse check, for this thread (Python sets it before each run:
   limits.max_steps()). */
static __thread double step_budget = COLLAPSE_STEPS;
void set_step_budget(double steps) { step_budget = steps > 0 ? steps : COLLAPSE_STEPS; }
/* The collapse check's window (accepted steps) and whether it also gives up on a pace that
   fell a hundredfold (step_drop): Python sets them for runs that call Python back at every
   evaluation (codegen/callbacks.py), whose steps cost as much as Python-stepped ones. */
static __thread long step_window = COLLAPSE_WINDOW;
static __thread int step_drop = 0;
static __thread double step_best = 0.0;  /* the best pace (s per step) of the run so far, over its calls of the loop */
/* The collapse window where this thread's last loop call returned at step_t_last: a call
   starting there (the next chunk of the same run) goes on with it. */
static __thread double step_t_last = -1.0 / 0.0, step_window_t0 = 0.0;
static __thread long step_window_n = 0;
void set_step_watch(long window, int drop) {
    step_window = window > 0 ? window : COLLAPSE_WINDOW;
    step_drop = drop;
    step_best = 0.0;
}

/* Evaluate the right-hand side or leave with its status (-5: constraint rows lost rank; -8: a
   trial state without dependent coordinates; MB_INPUT_FAILED: a Python callable failed). */
#define RHS_OR_FAIL(call) do { int rs_ = (call); if (rs_) { status = (rs_ == -5 || rs_ == -8 || rs_ == MB_INPUT_FAILED) ? rs_ : -2; goto done; } } while (0)

/* y = [q, v]: f = [q'(q, v), v']; returns the accelerations() status (the dae formulation's
   when this thread configured it, -5 when its constraint rows lost rank). */
static int mech_rhs(double t, const double *y, double *f, const double *p, const double *tau, double *work) {
    (void)t;
    const double *v = y + NCOORD;
    if (MB_HAS_QUAT) {
        for (int i = 0; i < NSCREW; ++i) f[SCREW_Q[i]] = v[SCREW_V[i]];
        for (int k = 0; k < NQUAT; ++k) {  /* q' = q (0, w) / 2, w in the rotated frame */
            const double *a = y + QUAT_Q[k], *w = v + QUAT_V[k];
            double *r = f + QUAT_Q[k];
            r[0] = -0.5 * (a[1] * w[0] + a[2] * w[1] + a[3] * w[2]);
            r[1] = 0.5 * (a[0] * w[0] + a[2] * w[2] - a[3] * w[1]);
            r[2] = 0.5 * (a[0] * w[1] + a[3] * w[0] - a[1] * w[2]);
            r[3] = 0.5 * (a[0] * w[2] + a[1] * w[1] - a[2] * w[0]);
        }
    } else {
        for (int i = 0; i < NCOORD; ++i) f[i] = v[i];
    }
#ifdef DAE_LOOP
    if (dae_nr >= 0) {
        dae_time = t;
        int status = dae_accelerations(y, v, p, mb_input_u(), tau, f + NCOORD, work);
        return status == 2 ? -5 : status;
    }
#endif
    return accelerations(y, v, p, mb_input_u(), tau, f + NCOORD, work);
}

/* Quaternions back to unit length (after each accepted step). */
static void normalize_state(double *y) {
    for (int k = 0; k < NQUAT; ++k) {
        double *a = y + QUAT_Q[k];
        const double n = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3]);
        if (n > 0) for (int i = 0; i < 4; ++i) a[i] /= n;
    }
}

/* y = [mechanical state, z]: the drive elements' forces (at time t and states z) join tau;
   f[NMECH..] gets the states' rates. */
static int drive_rhs(double t, const double *y, double *f, const double *p, const double *tau, double *work) {
    double buf[1 + NZ], out[NV + NZ], tau_all[NV];
    drives(y, y + NCOORD, p, mb_drive_u(t, y + NMECH, buf), out);
    for (int i = 0; i < NV; ++i) tau_all[i] = out[i] + (tau ? tau[i] : 0.0);
    for (int k = 0; k < NZ; ++k) f[NMECH + k] = out[NV + k];
    return mech_rhs(t, y, f, p, tau_all, work);
}

/* The rate of the state: with the drive elements' states when the model has drive elements
   (inlined at every call: one call per evaluation, as before HAS_DRIVES was read at run time). */
static inline __attribute__((always_inline)) int rhs(double t, const double *y, double *f, const double *p,
                                                     const double *tau, double *work) {
    int status;
    if (MB_CALLBACKS) {  /* Python callables (inputs.h): evaluated once, at this state */
        status = mb_inputs(t, y, y + NCOORD, y + NMECH);
        if (status) return status;
        double buf[NV + 1];
        const double *all = mb_input_tau(tau, buf);
        status = HAS_DRIVES ? drive_rhs(t, y, f, p, all, work) : mech_rhs(t, y, f, p, all, work);
    } else {
        status = HAS_DRIVES ? drive_rhs(t, y, f, p, tau, work) : mech_rhs(t, y, f, p, tau, work);
    }
    return mb_mo_failed ? MB_INPUT_FAILED : status;  /* (a callable motor's callback failed: inputs.h) */
}
/* The step hook: called with the simulated time about every `hook_interval` s of processor
   time (checked every 16 steps); a nonzero return stops the run (status -6).  Python sets it
   around each run to react to Ctrl-C, to stop requests and to show progress. */
typedef int (*step_hook_t)(double);
static __thread step_hook_t step_hook = 0;
static __thread double hook_interval = 0.0;
static __thread clock_t hook_last = 0;
static __thread long hook_tick = 0;

void set_step_hook(step_hook_t hook, double interval) {
    step_hook = hook;
    hook_interval = interval;
    hook_last = clock();
    hook_tick = 0;
}

static int hook_says_stop(double t) {
    if (!step_hook || (++hook_tick & 15)) return 0;
    clock_t now = clock();
    if ((double)(now - hook_last) < hook_interval * CLOCKS_PER_SEC) return 0;
    hook_last = now;
    return step_hook(t) != 0;
}

static int all_finite(const double *v, int n) {
    for (int i = 0; i < n; ++i) if (!(fabs(v[i]) <= DBL_MAX)) return 0;
    return 1;
}

static double rms(const double *v, int n) {
    double s = 0.0;
    for (int i = 0; i < n; ++i) s += v[i] * v[i];
    return sqrt(s / n);
}

@LOOPS@
/* The right-hand side f = [q', v', z'] at (t, y) (NY values): the function the compiled loops
   step, for scipy's stepping of the compiled model (the dae rows this thread configured
   included).  Returns the rhs() status (-5: the dae rows lost rank). */
int rhs_value(const double *p, const double *tau, double t, const double *y, double *f, double *work) {
    return rhs(t, y, f, p, tau, work);
}

/* Doubles of the work array rhs_value needs. */
long rhs_work_size(void) { return NWORK; }

/* Jacobian d f / d y (NY x NY, row-major) by forward differences, for implicit methods. */
int rhs_jacobian(const double *p, const double *tau, double t, const double *y, double *J) {
    double *f0 = malloc(sizeof(double) * NY), *f1 = malloc(sizeof(double) * NY);
    double *yp = malloc(sizeof(double) * NY), *work = malloc(sizeof(double) * NWORK);
    int status = 0;
    if (!f0 || !f1 || !yp || !work) { status = -4; goto done; }
    RHS_OR_FAIL(rhs(t, y, f0, p, tau, work));
    mb_copy(yp, y, sizeof(double) * NY);
    for (int j = 0; j < NY; ++j) {
        const double h = sqrt(DBL_EPSILON) * (fabs(y[j]) > 1.0 ? fabs(y[j]) : 1.0);
        yp[j] = y[j] + h;
        RHS_OR_FAIL(rhs(t, yp, f1, p, tau, work));
        for (int i = 0; i < NY; ++i) J[i * NY + j] = (f1[i] - f0[i]) / (yp[j] - y[j]);
        yp[j] = y[j];
    }
done:
    free(f0); free(f1); free(yp); free(work);
    return status;
}

/* Rows of y_out for the output times t_out[*j ..] before t_b (all of them when last), by
   cubic Hermite interpolation between the steps (t_a, ya, fa) and (t_b, yb, fb). */
static void hermite_rows(double t_a, double t_b, const double *ya, const double *fa, const double *yb,
                         const double *fb, const double *t_out, long n_out, long *j, int last, double *y_out) {
    const double h = t_b - t_a;
    for (; *j < n_out && (last || t_out[*j] < t_b); ++*j) {
        const double s = (t_out[*j] - t_a) / h, s2 = s * s, s3 = s2 * s;
        const double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s, h01 = -2 * s3 + 3 * s2, h11 = s3 - s2;
        double *out = y_out + *j * NY;
        for (int i = 0; i < NY; ++i) out[i] = h00 * ya[i] + h10 * h * fa[i] + h01 * yb[i] + h11 * h * fb[i];
        normalize_state(out);
    }
}

/* Classical RK4 with fixed step dt for n steps from t0.  y: the start state in, the state
   reached out (on failure: the state at step counts[1]).  Output only where asked: with
   t_out == NULL every step's state goes to y_out (n + 1 rows, y0 first); else y_out gets one
   row per output time t_out[0 .. n_out) (increasing, within [t0, t0 + n dt]) by cubic
   Hermite interpolation between the two steps around it, whose rates the steps compute
   anyway (one more evaluation, not counted in nfev, for the rate at the last step). */
int rk4_run(const double *p, const double *tau, double t0, double *y, double dt, long n,
            const double *t_out, long n_out, double *y_out, long *counts) {
    double *k = malloc(sizeof(double) * 4 * NY), *stage = malloc(sizeof(double) * NY);
    double *next = malloc(sizeof(double) * NY), *f_next = malloc(sizeof(double) * NY);
    double *work = malloc(sizeof(double) * NWORK);
    double *const y_start = y;
    int status = 0, have_f = 0;  /* have_f: f_next holds the rate at y (computed for output) */
    long j = 0;  /* the next output time */
    if (!k || !stage || !next || !f_next || !work) { status = -4; goto done; }
    for (long s = 0; s < n; ++s) {
        const double t = t0 + s * dt, t_new = t0 + (s + 1) * dt;
        if (hook_says_stop(t)) { status = -6; goto done; }
        if (have_f) mb_copy(k, f_next, sizeof(double) * NY);
        else RHS_OR_FAIL(rhs(t, y, k, p, tau, work));
        have_f = 0;
        if (!t_out) mb_copy(y_out + s * NY, y, sizeof(double) * NY);
        for (int i = 0; i < NY; ++i) stage[i] = y[i] + 0.5 * dt * k[i];
        RHS_OR_FAIL(rhs(t + 0.5 * dt, stage, k + NY, p, tau, work));
        for (int i = 0; i < NY; ++i) stage[i] = y[i] + 0.5 * dt * k[NY + i];
        RHS_OR_FAIL(rhs(t + 0.5 * dt, stage, k + 2 * NY, p, tau, work));
        for (int i = 0; i < NY; ++i) stage[i] = y[i] + dt * k[2 * NY + i];
        RHS_OR_FAIL(rhs(t + dt, stage, k + 3 * NY, p, tau, work));
        for (int i = 0; i < NY; ++i)
            next[i] = y[i] + dt / 6.0 * (k[i] + 2 * k[NY + i] + 2 * k[2 * NY + i] + k[3 * NY + i]);
        normalize_state(next);
        counts[0] += 4;
        counts[1] += 1;
        double *swap = y; y = next; next = swap;  /* y: the state at step s + 1; next: at step s */
        if (!all_finite(y, NY)) { status = -3; goto done; }
        const int last = s == n - 1;
        if (t_out && j < n_out && (last || t_out[j] < t_new)) {  /* outputs between the two steps */
            RHS_OR_FAIL(rhs(t_new, y, f_next, p, tau, work));
            have_f = 1;
            hermite_rows(t, t_new, next, k, y, f_next, t_out, n_out, &j, last, y_out);
        }
    }
    if (!t_out) mb_copy(y_out + n * NY, y, sizeof(double) * NY);
done:
    if (y != y_start) {  /* the reached state lives in the scratch buffer: hand it back */
        mb_copy(y_start, y, sizeof(double) * NY);
        next = y;
    }
    free(k); free(stage); free(next); free(f_next); free(work);
    return status;
}
