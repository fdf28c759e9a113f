#ifndef MB_PROGRAM_DEFINED
#define MB_PROGRAM_DEFINED 1
/* unused in a unit whose formulations never run a program: no warning */
static __attribute__((unused)) double mb_program(const double **prog, double t) {
    const double *pc = *prog;
    const long n = (long)pc[0];
    double st[MB_PROGRAM_STACK + 1];
    int sp = -1;
    for (long k = 0; k < n; ++k) {
        const int op = (int)pc[1 + 2 * k];
        switch (op) {
        case MB_OP_NUM: st[++sp] = pc[2 + 2 * k]; break;
        case MB_OP_TIME: st[++sp] = t; break;
        case MB_OP_SLOT: st[++sp] = mb_motor_slot((long)pc[2 + 2 * k], t); break;  /* (inputs.h) */
        case MB_OP_NEG: st[sp] = -st[sp]; break;
        case MB_OP_SIN: st[sp] = sin(st[sp]); break;
        case MB_OP_COS: st[sp] = cos(st[sp]); break;
        case MB_OP_EXP: st[sp] = exp(st[sp]); break;
        case MB_OP_SQRT: st[sp] = st[sp] < 0.0 ? NAN : sqrt(st[sp]); break;
        case MB_OP_LOG: st[sp] = st[sp] <= 0.0 ? NAN : log(st[sp]); break;
        default: {
            const double b = st[sp--], a = st[sp];
            st[sp] = op == MB_OP_ADD ? a + b : op == MB_OP_SUB ? a - b : op == MB_OP_MUL ? a * b
                : op == MB_OP_DIV ? (b == 0.0 ? NAN : a / b) : pow(a, b);
        }
        }
    }
    *prog = pc + 1 + 2 * n;
    return sp >= 0 ? st[sp] : NAN;
}
#endif
