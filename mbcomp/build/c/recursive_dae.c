/* ABA_PRED: the parent speed of each speed (-1 at a root), a table of the sizes unit (aba_sizes) */

/* x = M^-1 b from the factors of an aba call (D, W = U / D and S, speed-major): the
   articulated-body recursion without velocity terms.  pa: 6 ABA_NV doubles of scratch. */
static void aba_solve(const double *D, const double *W, const double *S, const double *b, double *x, double *pa) {
    for (int i = 0; i < 6 * ABA_NV; ++i) pa[i] = 0.0;
    for (int k = ABA_NV - 1; k >= 0; --k) {
        const double *s = S + 6 * k, *w = W + 6 * k, *pk = pa + 6 * k;
        const double uk = b[k] - (s[0] * pk[0] + s[1] * pk[1] + s[2] * pk[2] + s[3] * pk[3] + s[4] * pk[4] + s[5] * pk[5]);
        x[k] = uk;
        const int j = ABA_PRED[k];
        if (j >= 0) for (int i = 0; i < 6; ++i) pa[6 * j + i] += pk[i] + w[i] * uk;
    }
    for (int k = 0; k < ABA_NV; ++k) {  /* forward: pa now holds each node's acceleration */
        const int j = ABA_PRED[k];
        const double *s = S + 6 * k, *w = W + 6 * k;
        double *dk = pa + 6 * k;
        double xk = x[k] / D[k];
        if (j >= 0) {
            const double *dj = pa + 6 * j;
            xk -= w[0] * dj[0] + w[1] * dj[1] + w[2] * dj[2] + w[3] * dj[3] + w[4] * dj[4] + w[5] * dj[5];
            for (int i = 0; i < 6; ++i) dk[i] = dj[i] + s[i] * xk;
        } else {
            for (int i = 0; i < 6; ++i) dk[i] = s[i] * xk;
        }
        x[k] = xk;
    }
}

int dae_accelerations(const double *q, const double *qd, const double *p, const double *u,
                      const double *tau, double *qdd, double *work) {
    const int n = ABA_NV, nr = dae_nr;
    double ue[ABA_NU + ABA_NV + 1], fac[14 * ABA_NV], X[ABA_NV * DAE_NR], A[DAE_NR * DAE_NR];
    double r[DAE_NR], lam[DAE_NR], col[ABA_NV], pa[6 * ABA_NV];
    for (int i = 0; i < ABA_NU; ++i) ue[i] = u[i];
    for (int i = 0; i < n; ++i) ue[ABA_NU + i] = tau ? tau[i] : 0.0;
    aba(q, qd, p, ue, fac);
    const double *free_ = fac, *D = fac + n, *W = fac + 2 * n, *S = fac + 8 * n;
    double scale = 1e-300;
    for (int i = 0; i < n; ++i) if (fabs(D[i]) > scale) scale = fabs(D[i]);
    for (int i = 0; i < n; ++i) if (!(D[i] > MB_PIVOT_TOLERANCE * scale)) return 1;
    dae_rows_eval(q, qd, p, u, work);  /* the configured rows (formulations/dae_c.py) */
    const double *g = work + DAE_ROWS_OFF, *J = g + DAE_NR, *gt = J + DAE_NR * NQ, *bias = gt + DAE_NR;
    for (int k = 0; k < nr; ++k) {  /* X[:, k] = M^-1 J_row^T; the row's right-hand side */
        const double *Jr = J + k * n;
        aba_solve(D, W, S, Jr, col, pa);
        double gdot = gt[k], jfree = 0.0;
        for (int i = 0; i < n; ++i) {
            X[i * DAE_NR + k] = col[i];
            gdot += Jr[i] * qd[i];
            jfree += Jr[i] * free_[i];
        }
        r[k] = -bias[k] - 2.0 * dae_alpha * gdot - dae_beta * dae_beta * g[k] - jfree;
    }
    for (int a = 0; a < nr; ++a)  /* A = J_r M^-1 J_r^T (lower) */
        for (int b = 0; b <= a; ++b) {
            const double *Ja = J + a * n;
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Ja[i] * X[i * DAE_NR + b];
            A[a * DAE_NR + b] = s;
        }
    if (dae_schur_solve(A, r, lam, nr, qd, n)) return 2;  /* not finite, or a dead point at rest */
    for (int k = 0; k < nr; ++k) dae_lam[k] = lam[k];
    for (int i = 0; i < n; ++i) {
        double s = free_[i];
        for (int k = 0; k < nr; ++k) s += X[i * DAE_NR + k] * lam[k];
        qdd[i] = s;
    }
    return 0;
}
