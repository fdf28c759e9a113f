#ifndef MB_QUATERNION_DEFINED
#define MB_QUATERNION_DEFINED 1
/* Unit quaternions [w, x, y, z] of the Ball and Free joints' coordinates: the product and the
   step by a rotation vector that the lagrange chart and the dae projection apply (the
   Python side's core/statemap.py StateMap.integrate). */
/* Hamilton product out = a b (out may not alias a or b). */
static __attribute__((unused)) void mb_qmul(const double *a, const double *b, double *out) {
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    out[1] = a[0] * b[1] + b[0] * a[1] + a[2] * b[3] - a[3] * b[2];
    out[2] = a[0] * b[2] + b[0] * a[2] + a[3] * b[1] - a[1] * b[3];
    out[3] = a[0] * b[3] + b[0] * a[3] + a[1] * b[2] - a[2] * b[1];
}

/* out = a exp(phi / 2), normalised (statemap.StateMap.integrate on one quaternion). */
static __attribute__((unused)) void mb_qstep(const double *a, const double *phi, double *out) {
    const double angle = sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]);
    const double k = angle < 1e-4 ? 0.5 - angle * angle / 48 : sin(angle / 2) / angle;
    const double step[4] = {cos(angle / 2), k * phi[0], k * phi[1], k * phi[2]};
    mb_qmul(a, step, out);
    const double n = sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] + out[3] * out[3]);
    for (int i = 0; i < 4; ++i) out[i] /= n;
}
#endif
