/* DOP853's dense output of a step at time s: the interpolant of y_old and the 7 rows of F
   (ny entries each) on [t_old, t_old + h], written into y.  Used where an event is located
   on its step (the dae and lagrange formulations' gap and force at a trial time). */
#ifndef MB_DOP853_DENSE_H
#define MB_DOP853_DENSE_H
static void mb_dop853_dense(double s, double t_old, double h, const double *y_old, const double *F, int ny,
                            double *y) {
    const double x = (s - t_old) / h;
    for (int i = 0; i < ny; ++i) {
        double v = 0.0;
        for (int r = 6; r >= 0; --r) {
            v += F[r * ny + i];
            v *= ((6 - r) % 2 == 0) ? x : 1.0 - x;
        }
        y[i] = v + y_old[i];
    }
}
#endif
