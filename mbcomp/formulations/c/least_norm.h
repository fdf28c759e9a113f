#ifndef MB_LEAST_NORM_DEFINED
#define MB_LEAST_NORM_DEFINED 1
/* Least-norm solve of a symmetric positive semi-definite system A x = r (the KKT Schur
   complement J M^-1 J^T of the dae solve, or J J^T of its projection), rank-revealing by a
   cyclic Jacobi eigen-decomposition A = V diag(w) V^T:

       x = sum over kept i of v_i (v_i . r) / w_i,

   keeping the eigen-directions with sqrt(w_i) > tol * max(sqrt(w_max), scale) (the same
   relative test as a Cholesky pivot, ``sqrt`` of the Gram matrix's entries) and w_i above
   the decomposition's rounding, MB_EIGEN_ROUNDING n eps w_max (the eigenvalues are exact
   to a few eps w_max: a direction that rounding alone left is no direction); the dropped
   directions get no multiplier, so x is the minimum-norm least-squares solution of the
   truncated system, as numpy.linalg.lstsq (the Python oracle, core.small_linalg.least_norm)
   gives it with rcond = max(tol^2 max(w_max, scale^2) / w_max, MB_EIGEN_ROUNDING n eps). */

#define MB_JACOBI_SWEEPS 60
#define MB_EIGEN_ROUNDING 16.0

/* Eigen-decomposition of the symmetric n x n matrix a (full storage, row stride lda;
   destroyed: its diagonal becomes the eigenvalues, copied to w) with the eigenvectors in
   the columns of v (row stride ldv); w or v NULL: not wanted.  Returns the sweeps used, or -1 when not converged. */
static int mb_jacobi_eigen(int n, double *a, int lda, double *w, double *v, int ldv) {
    if (v)
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) v[i * ldv + j] = i == j ? 1.0 : 0.0;
    int sweep = 0;
    for (; sweep < MB_JACOBI_SWEEPS; ++sweep) {
        double off = 0.0, diag = 0.0;
        for (int p = 0; p < n; ++p) {
            diag += a[p * lda + p] * a[p * lda + p];
            for (int q = p + 1; q < n; ++q) off += a[p * lda + q] * a[p * lda + q];
        }
        if (!(off > 1e-36 * diag)) break;  /* off-diagonal below (eps^2)^2 of the diagonal's size */
        for (int p = 0; p < n; ++p)
            for (int q = p + 1; q < n; ++q) {
                const double apq = a[p * lda + q], app = a[p * lda + p], aqq = a[q * lda + q];
                if (apq == 0.0) continue;
                if (sweep > 3 && fabs(app) + 1e2 * fabs(apq) == fabs(app) && fabs(aqq) + 1e2 * fabs(apq) == fabs(aqq)) {
                    a[p * lda + q] = a[q * lda + p] = 0.0;  /* below rounding of both diagonal entries */
                    continue;
                }
                const double theta = (aqq - app) / (2.0 * apq);
                const double t = fabs(theta) > 1e150 ? 0.5 / theta
                                                     : (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                const double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (int k = 0; k < n; ++k) {  /* columns p, q */
                    const double akp = a[k * lda + p], akq = a[k * lda + q];
                    a[k * lda + p] = c * akp - s * akq;
                    a[k * lda + q] = s * akp + c * akq;
                }
                for (int k = 0; k < n; ++k) {  /* rows p, q */
                    const double apk = a[p * lda + k], aqk = a[q * lda + k];
                    a[p * lda + k] = c * apk - s * aqk;
                    a[q * lda + k] = s * apk + c * aqk;
                }
                a[p * lda + q] = a[q * lda + p] = 0.0;
                for (int k = 0; v && k < n; ++k) {
                    const double vkp = v[k * ldv + p], vkq = v[k * ldv + q];
                    v[k * ldv + p] = c * vkp - s * vkq;
                    v[k * ldv + q] = s * vkp + c * vkq;
                }
            }
    }
    for (int i = 0; w && i < n; ++i) w[i] = a[i * lda + i];
    return sweep < MB_JACOBI_SWEEPS ? sweep : -1;
}

/* x = the least-norm solution of A x = r for the symmetric positive semi-definite n x n A
   given by its lower triangle (row stride lda; overwritten), dropping the eigen-directions
   with sqrt(w_i) <= tol * max(sqrt(w_max), scale) or w_i within rounding.  work: n * n + n doubles.  Returns the
   number of dropped directions, or -1 when A is not finite or the decomposition failed. */
static int mb_least_norm(double *A, int lda, const double *r, double *x, int n, double scale, double tol,
                         double *work) {
    double *v = work, *w = work + n * n;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < i; ++j) {
            if (!isfinite(A[i * lda + j])) return -1;
            A[j * lda + i] = A[i * lda + j];
        }
    for (int i = 0; i < n; ++i) if (!isfinite(A[i * lda + i]) || !isfinite(r[i])) return -1;
    if (mb_jacobi_eigen(n, A, lda, w, v, n) < 0) return -1;
    double wmax = 0.0;
    for (int i = 0; i < n; ++i) if (w[i] > wmax) wmax = w[i];
    const double top = sqrt(wmax) > scale ? sqrt(wmax) : scale, floor_ = tol * top;
    const double zero = MB_EIGEN_ROUNDING * n * DBL_EPSILON * wmax;
    int dropped = 0;
    for (int i = 0; i < n; ++i) x[i] = 0.0;
    for (int k = 0; k < n; ++k) {
        if (!(w[k] > floor_ * floor_ && w[k] > zero)) {
            ++dropped;
            continue;
        }
        double s = 0.0;
        for (int i = 0; i < n; ++i) s += v[i * n + k] * r[i];
        s /= w[k];
        for (int i = 0; i < n; ++i) x[i] += v[i * n + k] * s;
    }
    return dropped;
}
#endif
