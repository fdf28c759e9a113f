"""The dae formulation's C code: the KKT system solved in the compiled integrators."""
from __future__ import annotations


def c_dae_accelerations(nq: int, ng: int) -> str:
    """C source of the ``dae`` formulation's accelerations for models whose constraints are
    all geometric (loops and sliders): the KKT system solved through the Schur complement,
    ``M = L L^T``, ``Y = L^-1 J_r^T``, ``(Y^T Y) lam = rhs - Y^T L^-1 f``,
    ``qdd = L^-T (L^-1 f + Y lam)``, on the rows configured per thread by ``dae_configure``
    (the independent rows found at compile time) with Baumgarte gains.  Returns 0, 1 when
    M is not positive definite, 2 when the rows lost rank (a singular position: the caller
    falls back to the Python path, which diagnoses it).  ``dae_project`` moves a state back
    onto the constraints after an accepted step.  Offsets into the packed outputs come from
    the ``OutputLayout`` defines.
    """
    if ng == 0:
        return "\n#define NG 0\n#define NDAEWORK 0\n"
    return f"""
#define NG {ng}
#define NDAEWORK (DYNAMICS_SIZE + CONSTRAINTS_SIZE + {nq} * {ng} + {ng} * {ng} + 3 * {ng} + {nq})
static __thread int dae_nr = -1;
static __thread long dae_rows[NG];
static __thread double dae_alpha, dae_beta, dae_scale, dae_tol = 1e-9;

void dae_configure(int nr, const long *rows, double alpha, double beta, double scale, double tol) {{
    dae_nr = nr;
    for (int k = 0; k < nr; ++k) dae_rows[k] = rows[k];
    dae_alpha = alpha; dae_beta = beta; dae_scale = scale; dae_tol = tol;
}}

/* lam = A^-1 r for the Gram matrix A (lower triangle of rows of NG, nr x nr) by a Cholesky
   factorisation in place that drops the directions whose pivot falls below dae_tol relative
   to the largest (and scale): their multiplier is zero.  Returns 1 when one was dropped,
   -1 on a non-finite pivot, 0 otherwise. */
/* Column ``col`` of Y = L^-1 J_r^T (the configured row of the constraint Jacobian J, with M =
   L L^T packed); returns the row's rate J_r qd. */
static double dae_row_solve(const double *L, const double *J, const double *qd, double *Y, int col) {{
    const double *Jr = J + dae_rows[col] * NQ;
    double rate = 0.0;
    for (int i = 0; i < NQ; ++i) {{
        double s = Jr[i];
        for (int k = 0; k < i; ++k) s -= L[IDX(i, k)] * Y[k * NG + col];
        Y[i * NG + col] = s / L[IDX(i, i)];
        rate += Jr[i] * qd[i];
    }}
    return rate;
}}

/* 1 when every speed is below 1e-9: a dropped multiplier direction then leaves the motion
   undetermined (a singular position at rest), 0 otherwise. */
static int dae_at_rest(const double *qd, int n) {{
    for (int i = 0; i < n; ++i) if (fabs(qd[i]) >= 1e-9) return 0;
    return 1;
}}

static int dae_gram_solve(double *A, const double *r, double *lam, int nr, double scale) {{
    double amax = 0.0;
    for (int j = 0; j < nr; ++j) if (A[j * NG + j] > amax) amax = A[j * NG + j];
    amax = sqrt(amax);
    const double floor_ = dae_tol * (amax > scale ? amax : scale);
    int dropped = 0;
    for (int j = 0; j < nr; ++j) {{
        double s = A[j * NG + j];
        for (int k = 0; k < j; ++k) s -= A[j * NG + k] * A[j * NG + k];
        if (s != s) return -1;
        if (!(s > floor_ * floor_)) {{
            dropped = 1;
            A[j * NG + j] = 0.0;
            for (int k = 0; k < j; ++k) A[j * NG + k] = 0.0;
            for (int i = j + 1; i < nr; ++i) A[i * NG + j] = 0.0;
            continue;
        }}
        const double d = sqrt(s);
        A[j * NG + j] = d;
        for (int i = j + 1; i < nr; ++i) {{
            double t = A[i * NG + j];
            for (int k = 0; k < j; ++k) t -= A[i * NG + k] * A[j * NG + k];
            A[i * NG + j] = t / d;
        }}
    }}
    for (int i = 0; i < nr; ++i) {{
        double s = r[i];
        for (int k = 0; k < i; ++k) s -= A[i * NG + k] * lam[k];
        lam[i] = A[i * NG + i] > 0.0 ? s / A[i * NG + i] : 0.0;
    }}
    for (int i = nr - 1; i >= 0; --i) {{
        double s = lam[i];
        for (int k = i + 1; k < nr; ++k) s -= A[k * NG + i] * lam[k];
        lam[i] = A[i * NG + i] > 0.0 ? s / A[i * NG + i] : 0.0;
    }}
    return dropped;
}}

#ifndef MBCOMP_RECURSIVE_DAE  /* the recursive program brings its own (recursive.c_dae) */
int dae_accelerations(const double *q, const double *qd, const double *p, const double *u,
                      const double *tau, double *qdd, double *work) {{
    const int n = NQ, nr = dae_nr;
    double *L = work + DYNAMICS_MASS_MATRIX_OFF, *f = work + DYNAMICS_FORCES_OFF, *c = work + DYNAMICS_SIZE;
    double *Y = c + CONSTRAINTS_SIZE, *A = Y + n * NG;
    double *r = A + NG * NG, *lam = r + NG, *uvec = lam + NG;
    dynamics(q, qd, p, u, work);
    constraints(q, qd, p, u, c);
    const double *g = c + CONSTRAINTS_RESIDUAL_OFF, *J = c + CONSTRAINTS_JACOBIAN_OFF, *bias = c + CONSTRAINTS_BIAS_OFF;
    for (int i = 0; i < n; ++i) uvec[i] = f[i] + (tau ? tau[i] : 0.0);
    if (mass_cholesky(L)) return 1;
    lower_solve(L, uvec);  /* uvec <- L^-1 (f + tau) */
    for (int col = 0; col < nr; ++col) {{  /* Y[:, col] = L^-1 J_row^T; rhs of the row */
        const double gdot = dae_row_solve(L, J, qd, Y, col);
        r[col] = -bias[dae_rows[col]] - 2.0 * dae_alpha * gdot - dae_beta * dae_beta * g[dae_rows[col]];
        for (int i = 0; i < n; ++i) r[col] -= Y[i * NG + col] * uvec[i];
    }}
    for (int a = 0; a < nr; ++a)  /* A = Y^T Y (lower) */
        for (int b = 0; b <= a; ++b) {{
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Y[i * NG + a] * Y[i * NG + b];
            A[a * NG + b] = s;
        }}
    const int dropped = dae_gram_solve(A, r, lam, nr, dae_scale);
    if (dropped < 0) return 2;
    if (dropped && dae_at_rest(qd, n)) return 2;  /* at rest on a singular position the motion is not determined */
    for (int i = 0; i < n; ++i) {{  /* qdd = L^-T (uvec + Y lam) */
        double s = uvec[i];
        for (int k = 0; k < nr; ++k) s += Y[i * NG + k] * lam[k];
        qdd[i] = s;
    }}
    upper_solve(L, qdd);
    return 0;
}}
#endif

/* Move y = [q, qd] back onto the constraints after an accepted step: positions by Newton
   (minimum-norm steps on the configured rows), speeds by the mass-orthogonal projection
   onto J qd = 0.  Returns 1 when y changed (the caller re-evaluates its derivative). */
int dae_project(double *y, const double *p, const double *u, double *work) {{
    const int n = NQ, nr = dae_nr;
    double *q = y, *qd = y + NQ;
    double *L = work + DYNAMICS_MASS_MATRIX_OFF, *f = work + DYNAMICS_FORCES_OFF, *c = work + DYNAMICS_SIZE;
    double *Y = c + CONSTRAINTS_SIZE, *A = Y + n * NG;
    double *r = A + NG * NG, *lam = r + NG, *dq = lam + NG;
    const double *g = c + CONSTRAINTS_RESIDUAL_OFF, *J = c + CONSTRAINTS_JACOBIAN_OFF;
    if (nr <= 0) return 0;
    int changed = 0;
    for (int it = 0; it < 4; ++it) {{
        constraints(q, qd, p, u, c);
        double gmax = 0.0;
        for (int k = 0; k < nr; ++k) if (fabs(g[dae_rows[k]]) > gmax) gmax = fabs(g[dae_rows[k]]);
        if (!(gmax > 1e-13)) break;
        for (int a = 0; a < nr; ++a)
            for (int b = 0; b <= a; ++b) {{
                const double *Ja = J + dae_rows[a] * NQ, *Jb = J + dae_rows[b] * NQ;
                double s = 0.0;
                for (int i = 0; i < n; ++i) s += Ja[i] * Jb[i];
                A[a * NG + b] = s;
            }}
        for (int k = 0; k < nr; ++k) r[k] = g[dae_rows[k]];
        if (dae_gram_solve(A, r, lam, nr, 0.0) < 0) return changed;
        for (int i = 0; i < n; ++i) {{
            double s = 0.0;
            for (int k = 0; k < nr; ++k) s += J[dae_rows[k] * NQ + i] * lam[k];
            q[i] -= s;
        }}
        changed = 1;
    }}
    if (changed) constraints(q, qd, p, u, c);
    dynamics(q, qd, p, u, work);
    (void)f;
    if (mass_cholesky(L)) return changed;
    for (int col = 0; col < nr; ++col) r[col] = dae_row_solve(L, J, qd, Y, col);  /* Y = L^-1 J_r^T, r = J_r qd */
    for (int a = 0; a < nr; ++a)
        for (int b = 0; b <= a; ++b) {{
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Y[i * NG + a] * Y[i * NG + b];
            A[a * NG + b] = s;
        }}
    if (dae_gram_solve(A, r, lam, nr, dae_scale) < 0) return changed;
    for (int i = 0; i < n; ++i) {{
        double s = 0.0;
        for (int k = 0; k < nr; ++k) s += Y[i * NG + k] * lam[k];
        dq[i] = s;
    }}
    upper_solve(L, dq);
    for (int i = 0; i < n; ++i) qd[i] -= dq[i];
    return 1;
}}
"""
