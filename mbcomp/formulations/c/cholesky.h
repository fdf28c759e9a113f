#ifndef MB_CHOLESKY_DEFINED
#define MB_CHOLESKY_DEFINED 1
/* Cholesky factorisation and solve of a small symmetric positive (semi-)definite matrix in
   full storage with row stride lda, the one routine of the compiled solves (the dae KKT
   Schur complement, the lagrange reduced mass matrix, the friction solve's Gram matrix).

   mb_cholesky factors the lower triangle of A in place into L (A = L L^T); a pivot (the
   squared diagonal entry of L before its square root) that is not above `floor` (absolute)
   either ends the factorisation (drop = 0: returns j + 1 for the first such column j, or -1
   when that pivot is NaN) or is dropped (drop = 1: its column of L becomes zero, and the
   solve gives that component no value).  Returns 0 when every pivot was kept or dropped. */
static int mb_cholesky(double *A, int lda, int n, double floor, int drop) {
    for (int j = 0; j < n; ++j) {
        double s = A[j * lda + j];
        for (int k = 0; k < j; ++k) s -= A[j * lda + k] * A[j * lda + k];
        if (!(s > floor) || !(s > 0.0)) {
            if (!drop) return s != s ? -1 : j + 1;
            A[j * lda + j] = 0.0;
            for (int i = j + 1; i < n; ++i) A[i * lda + j] = 0.0;
            continue;
        }
        const double d = sqrt(s);
        A[j * lda + j] = d;
        for (int i = j + 1; i < n; ++i) {
            double t = A[i * lda + j];
            for (int k = 0; k < j; ++k) t -= A[i * lda + k] * A[j * lda + k];
            A[i * lda + j] = t / d;
        }
    }
    return 0;
}

/* x = (L L^T)^-1 b by forward and back substitution with the factor of mb_cholesky (x may be
   b); a dropped (zero) pivot gives its component zero. */
static void mb_cholesky_solve(const double *L, int lda, int n, const double *b, double *x) {
    for (int i = 0; i < n; ++i) {
        double s = b[i];
        for (int k = 0; k < i; ++k) s -= L[i * lda + k] * x[k];
        x[i] = L[i * lda + i] > 0.0 ? s / L[i * lda + i] : 0.0;
    }
    for (int i = n - 1; i >= 0; --i) {
        double s = x[i];
        for (int k = i + 1; k < n; ++k) s -= L[k * lda + i] * x[k];
        x[i] = L[i * lda + i] > 0.0 ? s / L[i * lda + i] : 0.0;
    }
}
#endif
