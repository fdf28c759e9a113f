/* Python callables evaluated from compiled code: callable forces and torques (the generated
   functions' input vector u), a callable tau, and drive signals given as Python callables
   (their values after the states in the drive input vector).  Python sets, for this thread,
   a callback and the buffers it reads and fills (set_input_hook, compiled/callbacks.py);
   every right-hand side evaluation copies its state into mb_in_state and calls it once.  A
   nonzero return (the callable raised, or returned a wrong or non-finite value: Python keeps
   the exception) stops the loop with MB_INPUT_FAILED. */
#define MB_INPUT_FAILED -9
typedef int (*input_hook_t)(double);
static __thread input_hook_t mb_in_hook = 0;
/* mb_in_state: [q (NCOORD), qd (NV), z (NZ)] copied in for the callback; mb_in_u: the
   generated functions' inputs; mb_in_tau: NV values of a callable tau (or NULL); mb_in_du:
   the drive inputs [t, z, callable signals] (or NULL) */
static __thread double *mb_in_state = 0, *mb_in_u = 0, *mb_in_tau = 0, *mb_in_du = 0;
static double mb_no_input[1];

void set_input_hook(input_hook_t hook, double *state, double *u, double *tau, double *du) {
    mb_in_hook = hook; mb_in_state = state; mb_in_u = u; mb_in_tau = tau; mb_in_du = du;
}

/* Motors whose position is a Python callable: their programs read slots (MB_OP_SLOT of
   program.h) of mb_mo_values, which a second callback fills with s, s', s'' of every such
   motor at a time t (3 values a motor), called once per new time whatever C code evaluates
   the motor rows (the loops' right-hand sides, Newton solves, event locators).  A failed
   callback gives NaN (which the rows' code treats as a failed evaluation) and makes every
   later mb_inputs fail, so the loop stops with MB_INPUT_FAILED. */
static __thread input_hook_t mb_mo_hook = 0;
static __thread double *mb_mo_values = 0;
static __thread double mb_mo_time = NAN;   /* the time of the values in mb_mo_values */
static __thread int mb_mo_failed = 0;

void set_motor_hook(input_hook_t hook, double *values) {
    mb_mo_hook = hook; mb_mo_values = values; mb_mo_time = NAN; mb_mo_failed = 0;
}

/* Slot k of the callable motors' values at time t (NaN without a callback or after a failure). */
static __attribute__((unused)) double mb_motor_slot(long k, double t) {
    if (!mb_mo_hook || mb_mo_failed) return NAN;
    if (t != mb_mo_time) {
        if (mb_mo_hook(t)) {
            mb_mo_failed = 1;
            return NAN;
        }
        mb_mo_time = t;
    }
    return mb_mo_values[k];
}

/* Whether a right-hand side must call mb_inputs: callables to evaluate, or a failed motor callback. */
#define MB_CALLBACKS (mb_in_hook || mb_mo_failed)

/* The callables at (t, q, qd, z) (z: NULL keeps the last drive states): 0, or
   MB_INPUT_FAILED when the callback failed (or a callable motor's did). */
static int mb_inputs(double t, const double *q, const double *qd, const double *z) {
    if (mb_mo_failed) return MB_INPUT_FAILED;
    if (!mb_in_hook) return 0;
    for (int i = 0; i < NCOORD; ++i) mb_in_state[i] = q[i];
    for (int i = 0; i < NV; ++i) mb_in_state[NCOORD + i] = qd[i];
    if (z) for (int k = 0; k < NZ; ++k) mb_in_state[NCOORD + NV + k] = z[k];
    return mb_in_hook(t) ? MB_INPUT_FAILED : 0;
}

/* The generated functions' input vector: the callables' last values (none: zeros). */
static const double *mb_input_u(void) { return mb_in_u ? mb_in_u : mb_no_input; }

/* tau plus a callable tau's last values, in buf (NV), or tau itself without one. */
static const double *mb_input_tau(const double *tau, double *buf) {
    if (!mb_in_tau) return tau;
    for (int i = 0; i < NV; ++i) buf[i] = mb_in_tau[i] + (tau ? tau[i] : 0.0);
    return buf;
}

/* The drive inputs at time t and states z: [t, z, the callable signals' last values] in
   mb_in_du when the model has callable signals, else in buf (1 + NZ). */
static double *mb_drive_u(double t, const double *z, double *buf) {
    double *u = mb_in_du ? mb_in_du : buf;
    u[0] = t;
    for (int k = 0; k < NZ; ++k) u[1 + k] = z[k];
    return u;
}
