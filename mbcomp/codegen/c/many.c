void @NAME@_many(long m, const double *q, long sq, const double *qd, long sqd, const double *p,
                const double *u, long su, double *out) {
    for (long i = 0; i < m; ++i) @NAME@(q + i * sq, qd + i * sqd, p, u + i * su, out + i * @SIZE@);
}
