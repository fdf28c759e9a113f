/* scipy's select_initial_step (order 7). */
static double @INIT@(double t0, const double *y0, const double *f0, double t_end, double max_step,
                           double rtol, double atol, const double *p, const double *tau, double *work,
                           double *y1, double *f1, long *nfev) {
    double scaled[NY], d0, d1, d2, h0, h1;
    (void)work;  /* the reduced loop's right-hand side has its own */
    if (LOOP_NY == 0) return INFINITY;  /* nothing to integrate (every coordinate held): as scipy */
    for (int i = 0; i < LOOP_NY; ++i) scaled[i] = y0[i] / (atol + fabs(y0[i]) * rtol);
    d0 = rms(scaled, LOOP_NY);
    for (int i = 0; i < LOOP_NY; ++i) scaled[i] = f0[i] / (atol + fabs(y0[i]) * rtol);
    d1 = rms(scaled, LOOP_NY);
    h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (h0 > t_end - t0) h0 = t_end - t0;
    for (int i = 0; i < LOOP_NY; ++i) y1[i] = y0[i] + h0 * f0[i];
    if (LOOP_RHS(t0 + h0, y1, f1)) mb_copy(f1, f0, sizeof(double) * LOOP_NY);  /* (a failed trial: no curvature estimate) */
    ++*nfev;
    for (int i = 0; i < LOOP_NY; ++i) scaled[i] = (f1[i] - f0[i]) / (atol + fabs(y0[i]) * rtol);
    d2 = rms(scaled, LOOP_NY) / h0;
    if (d1 <= 1e-15 && d2 <= 1e-15) {
        h1 = h0 * 1e-3 > 1e-6 ? h0 * 1e-3 : 1e-6;
    } else {
        h1 = pow(0.01 / (d1 > d2 ? d1 : d2), 1.0 / 8.0);
    }
    double h = 100 * h0 < h1 ? 100 * h0 : h1;
    if (h > t_end - t0) h = t_end - t0;
    return h < max_step ? h : max_step;
}

/*
 * Adaptive DOP853 from state[0] = t to t_end.  state[1] = h (<= 0: choose one).
 * y (LOOP_NY) and f (LOOP_NY, the derivative at y; computed when state[1] <= 0) are updated in place.
 * Output: dense values at t_out[*i_out .. n_out) into y_out (rows of NY), or, when
 * n_out == 0, every accepted step into t_steps / y_steps (capacity cap, count *n_steps).
 * counts: [nfev, accepted, rejected].  Returns FINISHED (0), BUFFER_FULL (1, resume by
 * calling again), STEP_TOO_SMALL (-1), SINGULAR (-2) or NOT_FINITE (-3); the reduced loop
 * (state [q_i, qd_i] of the lagrange formulation, full [q, qd] output rows) also PAUSED (2:
 * after an accepted step, for Python to choose the partition afresh; resume by calling
 * again) and TRIAL_FAILED (-8: no dependent coordinates at a trial state).
 */
int @RUN@(const double *p, const double *tau, double *state, double *y, double *f, double t_end,
               double rtol, double atol, double max_step, const double *t_out, long n_out, long *i_out,
               double *y_out, double *t_steps, double *y_steps, long cap, long *n_steps, long *counts) {
    double *K = malloc(sizeof(double) * 16 * NY);
    double *work = malloc(sizeof(double) * NWORK);
    double *y_new = malloc(sizeof(double) * NY), *y_stage = malloc(sizeof(double) * NY);
    double *F = malloc(sizeof(double) * 7 * NY);
    int status = 0;
    double t = state[0], h_abs = state[1], window_t0 = state[0];
    long window_n = 0;
    if (t == step_t_last) { window_t0 = step_window_t0; window_n = step_window_n; }  /* (the next chunk of one run) */
    if (!K || !work || !y_new || !y_stage || !F) { status = -4; goto done; }
    if (h_abs <= 0) {
        RHS_OR_FAIL(LOOP_RHS(t, y, f));
        counts[0] += 1;
        h_abs = @INIT@(t, y, f, t_end, max_step, rtol, atol, p, tau, work, y_stage, y_new, &counts[0]);
    }
    while (t < t_end) {
        if (n_out == 0 && *n_steps >= cap) { status = 1; goto done; }
        double min_step = 10 * fabs(nextafter(t, INFINITY) - t);
        if (h_abs > max_step) h_abs = max_step;
        else if (h_abs < min_step) h_abs = min_step;
        int rejected = 0;
        double h, t_new, err;
        for (;;) {
            if (hook_says_stop(t)) { status = -6; goto done; }
            if (h_abs < min_step) { status = -1; goto done; }
            t_new = t + h_abs;
            if (t_new > t_end) t_new = t_end;
            h = t_new - t;
            h_abs = fabs(h);
            mb_copy(K, f, sizeof(double) * LOOP_NY);
            for (int s = 1; s < 12; ++s) {
                for (int i = 0; i < LOOP_NY; ++i) {
                    double acc = 0.0;
                    for (int j = 0; j < s; ++j) acc += DOP_A[s][j] * K[j * LOOP_NY + i];
                    y_stage[i] = y[i] + h * acc;
                }
                RHS_OR_FAIL(LOOP_RHS(t + DOP_C[s] * h, y_stage, K + s * LOOP_NY));
            }
            for (int i = 0; i < LOOP_NY; ++i) {
                double acc = 0.0;
                for (int j = 0; j < 12; ++j) acc += DOP_B[j] * K[j * LOOP_NY + i];
                y_new[i] = y[i] + h * acc;
            }
            RHS_OR_FAIL(LOOP_RHS(t_new, y_new, K + 12 * LOOP_NY));
            counts[0] += 12;
            if (!all_finite(y_new, LOOP_NY) || !all_finite(K + 12 * LOOP_NY, LOOP_NY)) { status = -3; goto done; }
            double e5 = 0.0, e3 = 0.0;
            for (int i = 0; i < LOOP_NY; ++i) {
                double scale = atol + rtol * (fabs(y[i]) > fabs(y_new[i]) ? fabs(y[i]) : fabs(y_new[i]));
                double a5 = 0.0, a3 = 0.0;
                for (int j = 0; j < 13; ++j) { a5 += DOP_E5[j] * K[j * LOOP_NY + i]; a3 += DOP_E3[j] * K[j * LOOP_NY + i]; }
                a5 /= scale; a3 /= scale;
                e5 += a5 * a5; e3 += a3 * a3;
            }
            err = (e5 == 0.0 && e3 == 0.0) ? 0.0 : h_abs * e5 / sqrt((e5 + 0.01 * e3) * LOOP_NY);
            if (err < 1) {
                double factor = err == 0.0 ? 10.0 : 0.9 * pow(err, -1.0 / 8.0);
                if (factor > 10.0) factor = 10.0;
                if (rejected && factor > 1.0) factor = 1.0;
                h_abs *= factor;
                break;
            }
            double factor = 0.9 * pow(err, -1.0 / 8.0);
            h_abs *= factor > 0.2 ? factor : 0.2;
            rejected = 1;
            counts[2] += 1;
        }
        counts[1] += 1;
#if LOOP_REDUCED
        /* contacts watched: a step in which one closes or a held one would pull is not taken */
        const int event = lag_nk ? lagrange_event(t_new, y_new, p, tau) : 0;
        if (event < 0) { status = event; goto done; }
#elif defined(DAE_LOOP)
        /* contacts watched (dae): the multipliers of the last evaluation, at (t_new, y_new) */
        const int event = dae_nk ? dae_event(t_new, y_new, p) : 0;
#else
        const int event = 0;
#endif
        /* dense output for the requested times within (t, t_new] (and of an event step) */
        if (event || (n_out > 0 && *i_out < n_out && t_out[*i_out] <= t_new)) {
#if LOOP_REDUCED
            {  /* the Newton predictor of the dense-output stages and the outputs spans the accepted step */
                const int ss_ = lagrange_span(t_new, y_new, p);
                if (ss_) { status = ss_; goto done; }
            }
#endif
            for (int s = 13; s < 16; ++s) {
                for (int i = 0; i < LOOP_NY; ++i) {
                    double acc = 0.0;
                    for (int j = 0; j < s; ++j) acc += DOP_A[s][j] * K[j * LOOP_NY + i];
                    y_stage[i] = y[i] + h * acc;
                }
                RHS_OR_FAIL(LOOP_RHS(t + DOP_C[s] * h, y_stage, K + s * LOOP_NY));
            }
            counts[0] += 3;
            for (int i = 0; i < LOOP_NY; ++i) {
                double dy = y_new[i] - y[i];
                F[0 * LOOP_NY + i] = dy;
                F[1 * LOOP_NY + i] = h * K[i] - dy;
                F[2 * LOOP_NY + i] = 2 * dy - h * (K[12 * LOOP_NY + i] + K[i]);
                for (int r = 0; r < 4; ++r) {
                    double acc = 0.0;
                    for (int j = 0; j < 16; ++j) acc += DOP_D[r][j] * K[j * LOOP_NY + i];
                    F[(3 + r) * LOOP_NY + i] = h * acc;
                }
            }
#if LOOP_REDUCED || defined(DAE_LOOP)
            if (event) {  /* [t_new, y_new, f_new, F] for Python; the loop stays at the step's start */
#if LOOP_REDUCED
                double *ev_ = lag_ev;
#else
                double *ev_ = dae_ev;
#endif
                ev_[0] = t_new;
                mb_copy(ev_ + 1, y_new, sizeof(double) * LOOP_NY);
                mb_copy(ev_ + 1 + LOOP_NY, K + 12 * LOOP_NY, sizeof(double) * LOOP_NY);
                mb_copy(ev_ + 1 + 2 * LOOP_NY, F, sizeof(double) * 7 * LOOP_NY);
                status = LOOP_EVENT;
                goto done;
            }
#endif
            while (*i_out < n_out && t_out[*i_out] <= t_new) {
                double x = (t_out[*i_out] - t) / h;
                double *out = y_out + (*i_out) * NY;
#if LOOP_REDUCED
                double *dense = y_stage;
#else
                double *dense = out;
#endif
                for (int i = 0; i < LOOP_NY; ++i) {
                    double v = 0.0;
                    for (int r = 6; r >= 0; --r) {
                        v += F[r * LOOP_NY + i];
                        v *= ((6 - r) % 2 == 0) ? x : 1.0 - x;
                    }
                    dense[i] = v + y[i];
                }
#if LOOP_REDUCED
                if (t_out[*i_out] == t_new) dense = y_new;
                const int os_ = lagrange_full(t_out[*i_out], dense, out, out + NCOORD, p);
                if (os_) { status = os_; goto done; }
                for (int i = 0; i < NZ; ++i) out[NMECH + i] = dense[lag_nqi + lag_ni + i];  /* the drive states */
#else
                normalize_state(out);
                if (t_out[*i_out] == t_new) mb_copy(out, y_new, sizeof(double) * LOOP_NY);
#endif
                ++*i_out;
            }
#if LOOP_REDUCED
            lagrange_span_end();
#endif
        }
        t = t_new;
#if LOOP_REDUCED
        mb_copy(y, y_new, sizeof(double) * LOOP_NY);
        mb_copy(f, K + 12 * LOOP_NY, sizeof(double) * LOOP_NY);
        {  /* the full state becomes the accepted one (the next Newton starts there) */
            const int as_ = lagrange_accept(t, y, n_out == 0 ? y_steps + (*n_steps) * NY : 0, p);
            if (as_ < 0) { status = as_; goto done; }
            if (n_out == 0) t_steps[(*n_steps)++] = t;
            if (as_ == LAG_PAUSED) { status = LAG_PAUSED; goto done; }
        }
#else
        normalize_state(y_new);
        mb_copy(y, y_new, sizeof(double) * LOOP_NY);
        mb_copy(f, K + 12 * LOOP_NY, sizeof(double) * LOOP_NY);
#endif
#if defined(DAE_LOOP) && !LOOP_REDUCED  /* (quaternion coordinates: only when the run asked projection=True) */
        if ((!MB_HAS_QUAT || dae_quat_project) && dae_nr > 0 && (dae_time = t, dae_project(y, p, mb_input_u(), work))) {  /* back onto the constraints */
            RHS_OR_FAIL(LOOP_RHS(t, y, f));
            counts[0] += 1;
        }
#endif
        if (n_out == 0 && !LOOP_REDUCED) {
            t_steps[*n_steps] = t;
            mb_copy(y_steps + (*n_steps) * LOOP_NY, y, sizeof(double) * LOOP_NY);
            ++*n_steps;
        }
        if (++window_n == step_window) {  /* step-size collapse: the run could never finish */
            const double pace = (t - window_t0) / step_window, rest = t_end - t;
            if (pace > step_best) step_best = pace;
            /* (with step_drop, also once the pace fell a hundredfold below the run's best and
               the rest would need a thirtieth of the budget: the Python-stepped loops' rule) */
            if (t < t_end && (rest > step_budget * pace
                              || (step_drop && rest > step_budget / 30 * pace && pace < 1e-2 * step_best))) {
                status = -7;
                goto done;
            }
            window_n = 0;
            window_t0 = t;
        }
    }
done:
#if LOOP_REDUCED
    lagrange_span_end();  /* (an event step or a failure leaves the loop inside a step's outputs) */
#endif
    step_t_last = t; step_window_t0 = window_t0; step_window_n = window_n;
    state[0] = t;
    state[1] = h_abs;
    free(K); free(work); free(y_new); free(y_stage); free(F);
    return status;
}

