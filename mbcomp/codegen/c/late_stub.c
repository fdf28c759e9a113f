typedef void (*mb_late_fn)(const double *, const double *, const double *, const double *, double *);
static mb_late_fn mb_late_@NAME@ = 0;
void @SETTER@(mb_late_fn f) { mb_late_@NAME@ = f; }
void @NAME@(const double *q, const double *qd, const double *p, const double *u, double *out) {
    if (mb_late_@NAME@) { mb_late_@NAME@(q, qd, p, u, out); return; }
    for (int i = 0; i < @SIZE@; ++i) out[i] = NAN;
}
