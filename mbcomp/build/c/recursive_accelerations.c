/* ABA_NV speeds, ABA_NU inputs, ABA_OUT outputs of aba: the model's sizes unit (aba_sizes) */
int accelerations(const double *q, const double *qd, const double *p, const double *u,
                  const double *tau, double *qdd, double *work) {
    double ue[ABA_NU + ABA_NV + 1], out[ABA_OUT + 1];
    (void)work;
    for (int i = 0; i < ABA_NU; ++i) ue[i] = u[i];
    for (int i = 0; i < ABA_NV; ++i) ue[ABA_NU + i] = tau ? tau[i] : 0.0;
    aba(q, qd, p, ue, out);
    double scale = 1e-300;
    for (int i = 0; i < ABA_NV; ++i) if (fabs(out[ABA_NV + i]) > scale) scale = fabs(out[ABA_NV + i]);
    for (int i = 0; i < ABA_NV; ++i) if (!(out[ABA_NV + i] > MB_PIVOT_TOLERANCE * scale)) return i + 1;
    for (int i = 0; i < ABA_NV; ++i) qdd[i] = out[i];
    return 0;
}
