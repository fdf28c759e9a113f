"""The dae formulation's C code: the KKT system solved in the compiled integrators."""
from __future__ import annotations


def c_dae_accelerations(nq: int, ng: int) -> str:
    """C source of the ``dae`` formulation's accelerations for models whose constraints are
    all geometric (loops and sliders): the KKT system solved through the Schur complement,
    ``M = L L^T``, ``Y = L^-1 J_r^T``, ``(Y^T Y) lam = rhs - Y^T L^-1 f``,
    ``qdd = L^-T (L^-1 f + Y lam)``, on the rows configured per thread by ``dae_configure``
    (the independent rows found at compile time) with Baumgarte gains.  Returns 0, 1 when
    M is not positive definite, 2 when the rows lost rank (a singular position: the caller
    falls back to the Python path, which diagnoses it).  Offsets into the packed outputs come
    from the ``OutputLayout`` defines.
    """
    if ng == 0:
        return "\n#define NG 0\n#define NDAEWORK 0\n"
    return f"""
#define NG {ng}
#define NDAEWORK (DYNAMICS_SIZE + CONSTRAINTS_SIZE + {nq} * {ng} + {ng} * {ng} + 3 * {ng} + {nq})
static __thread int dae_nr = -1;
static __thread long dae_rows[NG];
static __thread double dae_alpha, dae_beta, dae_scale;

void dae_configure(int nr, const long *rows, double alpha, double beta, double scale) {{
    dae_nr = nr;
    for (int k = 0; k < nr; ++k) dae_rows[k] = rows[k];
    dae_alpha = alpha; dae_beta = beta; dae_scale = scale;
}}

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
        const double *Jr = J + dae_rows[col] * NQ;
        double gdot = 0.0;
        for (int i = 0; i < n; ++i) {{
            double s = Jr[i];
            for (int k = 0; k < i; ++k) s -= L[IDX(i, k)] * Y[k * NG + col];
            Y[i * NG + col] = s / L[IDX(i, i)];
            gdot += Jr[i] * qd[i];
        }}
        r[col] = -bias[dae_rows[col]] - 2.0 * dae_alpha * gdot - dae_beta * dae_beta * g[dae_rows[col]];
        for (int i = 0; i < n; ++i) r[col] -= Y[i * NG + col] * uvec[i];
    }}
    double amax = 0.0;
    for (int a = 0; a < nr; ++a)  /* A = Y^T Y (lower), then A = LA LA^T in place */
        for (int b = 0; b <= a; ++b) {{
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Y[i * NG + a] * Y[i * NG + b];
            A[a * NG + b] = s;
        }}
    for (int j = 0; j < nr; ++j) {{
        double s = A[j * NG + j];
        for (int k = 0; k < j; ++k) s -= A[j * NG + k] * A[j * NG + k];
        if (!(s > 0.0)) return 2;
        const double d = sqrt(s);
        if (d > amax) amax = d;
        A[j * NG + j] = d;
        for (int i = j + 1; i < nr; ++i) {{
            double t = A[i * NG + j];
            for (int k = 0; k < j; ++k) t -= A[i * NG + k] * A[j * NG + k];
            A[i * NG + j] = t / d;
        }}
    }}
    const double floor_ = 1e-9 * (amax > dae_scale ? amax : dae_scale);
    for (int j = 0; j < nr; ++j) if (!(A[j * NG + j] > floor_)) return 2;
    for (int i = 0; i < nr; ++i) {{  /* lam = A^-1 r */
        double s = r[i];
        for (int k = 0; k < i; ++k) s -= A[i * NG + k] * lam[k];
        lam[i] = s / A[i * NG + i];
    }}
    for (int i = nr - 1; i >= 0; --i) {{
        double s = lam[i];
        for (int k = i + 1; k < nr; ++k) s -= A[k * NG + i] * lam[k];
        lam[i] = s / A[i * NG + i];
    }}
    for (int i = 0; i < n; ++i) {{  /* qdd = L^-T (uvec + Y lam) */
        double s = uvec[i];
        for (int k = 0; k < nr; ++k) s += Y[i * NG + k] * lam[k];
        qdd[i] = s;
    }}
    upper_solve(L, qdd);
    return 0;
}}
"""
