double fabs(double); double sqrt(double);  /* its own, so that it also follows c_source alone */
#define IDX(i, j) ((i) * ((i) + 1) / 2 + (j))
/* M = L L^T in place on the packed lower triangle; 0, or k + 1 when pivot k is not
   positive against the largest diagonal entry. */
static int mass_cholesky(double *L) {
    double scale = 1e-300;
    for (int i = 0; i < NQ; ++i) if (fabs(L[IDX(i, i)]) > scale) scale = fabs(L[IDX(i, i)]);
    for (int j = 0; j < NQ; ++j) {
        double s = L[IDX(j, j)];
        for (int k = 0; k < j; ++k) s -= L[IDX(j, k)] * L[IDX(j, k)];
        if (!(s > MB_PIVOT_TOLERANCE * scale)) return j + 1;
        const double d = sqrt(s);
        L[IDX(j, j)] = d;
        for (int i = j + 1; i < NQ; ++i) {
            double t = L[IDX(i, j)];
            for (int k = 0; k < j; ++k) t -= L[IDX(i, k)] * L[IDX(j, k)];
            L[IDX(i, j)] = t / d;
        }
    }
    return 0;
}

/* b <- L^-1 b and b <- L^-T b with the packed factor. */
static void lower_solve(const double *L, double *b) {
    for (int i = 0; i < NQ; ++i) {
        double s = b[i];
        for (int k = 0; k < i; ++k) s -= L[IDX(i, k)] * b[k];
        b[i] = s / L[IDX(i, i)];
    }
}

static void upper_solve(const double *L, double *b) {
    for (int i = NQ - 1; i >= 0; --i) {
        double s = b[i];
        for (int k = i + 1; k < NQ; ++k) s -= L[IDX(k, i)] * b[k];
        b[i] = s / L[IDX(i, i)];
    }
}

int accelerations(const double *q, const double *qd, const double *p, const double *u,
                  const double *tau, double *qdd, double *work) {
    double *L = work + DYNAMICS_MASS_MATRIX_OFF, *f = work + DYNAMICS_FORCES_OFF;
    dynamics(q, qd, p, u, work);
    for (int i = 0; i < NQ; ++i) qdd[i] = f[i] + (tau ? tau[i] : 0.0);
    const int status = mass_cholesky(L);
    if (status) return status;
    lower_solve(L, qdd);
    upper_solve(L, qdd);
    return 0;
}
