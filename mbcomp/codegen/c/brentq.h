#ifndef MB_BRENTQ_DEFINED
#define MB_BRENTQ_DEFINED 1
typedef double (*mb_root_fn)(double x, void *ctx);

static double mb_brentq(mb_root_fn f, void *ctx, double xa, double xb, double xtol, double rtol, int iter,
                        int *status) {
    double xpre = xa, xcur = xb, xblk = 0.0, fblk = 0.0, spre = 0.0, scur = 0.0;
    double fpre = f(xpre, ctx), fcur = f(xcur, ctx);
    *status = 0;
    if (fpre != fpre || fcur != fcur) { *status = 3; return NAN; }
    if (fpre == 0.0) return xpre;
    if (fcur == 0.0) return xcur;
    if (signbit(fpre) == signbit(fcur)) { *status = 1; return NAN; }
    for (int i = 0; i < iter; ++i) {
        if (fpre != 0.0 && fcur != 0.0 && signbit(fpre) != signbit(fcur)) {
            xblk = xpre;
            fblk = fpre;
            spre = scur = xcur - xpre;
        }
        if (fabs(fblk) < fabs(fcur)) {
            xpre = xcur; xcur = xblk; xblk = xpre;
            fpre = fcur; fcur = fblk; fblk = fpre;
        }
        const double delta = (xtol + rtol * fabs(xcur)) / 2.0;
        const double sbis = (xblk - xcur) / 2.0;
        if (fcur == 0.0 || fabs(sbis) < delta) return xcur;
        if (fabs(spre) > delta && fabs(fcur) < fabs(fpre)) {
            double stry;
            if (xpre == xblk) {  /* interpolate */
                stry = -fcur * (xcur - xpre) / (fcur - fpre);
            } else {  /* extrapolate */
                const double dpre = (fpre - fcur) / (xpre - xcur), dblk = (fblk - fcur) / (xblk - xcur);
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre));
            }
            const double limit = fabs(spre) < 3.0 * fabs(sbis) - delta ? fabs(spre) : 3.0 * fabs(sbis) - delta;
            if (2.0 * fabs(stry) < limit) {  /* good short step */
                spre = scur;
                scur = stry;
            } else {  /* bisect */
                spre = sbis;
                scur = sbis;
            }
        } else {  /* bisect */
            spre = sbis;
            scur = sbis;
        }
        xpre = xcur;
        fpre = fcur;
        if (fabs(scur) > delta) xcur += scur;
        else xcur += (sbis > 0.0 ? delta : -delta);
        fcur = f(xcur, ctx);
        if (fcur != fcur) { *status = 3; return NAN; }
    }
    *status = 2;
    return xcur;
}
#endif
