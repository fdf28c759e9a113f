#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

/* The generated functions: int accelerations(q, qd, p, u, tau, qdd, work) and
   void name(q, qd, p, u, out) (dynamics, kinematics). */
typedef int (*acc_fn)(const double *, const double *, const double *, const double *, const double *,
                      double *, double *);
typedef void (*out_fn)(const double *, const double *, const double *, const double *, double *);

#define STACK_DOUBLES 2048

typedef struct {
    PyObject_HEAD
    acc_fn acc;
    out_fn dyn, kin;
    PyObject *p_obj, *owner;
    const double *p;
    double *zeros;  /* nv zeros: the speeds when qd is None; also the (empty) inputs */
    Py_ssize_t nq, nv, dyn_size, mm_off, kin_size, bodies_off, body_row, rot_off, origin_off, vel_off, n_bodies;
} Calls;

/* The data of an exact float64 ndarray of shape (n,), aligned, C-contiguous, native byte
   order, every entry finite; NULL for anything else (the caller's checked path decides). */
static const double *vector(PyObject *o, Py_ssize_t n) {
    if (!PyArray_CheckExact(o)) return NULL;
    PyArrayObject *a = (PyArrayObject *)o;
    if (PyArray_NDIM(a) != 1 || PyArray_DIM(a, 0) != n || PyArray_TYPE(a) != NPY_DOUBLE
        || !PyArray_ISCARRAY_RO(a) || !PyArray_ISNOTSWAPPED(a)) return NULL;
    const double *d = (const double *)PyArray_DATA(a);
    for (Py_ssize_t i = 0; i < n; ++i) if (!isfinite(d[i])) return NULL;
    return d;
}

static int all_finite(const double *v, Py_ssize_t n) {
    for (Py_ssize_t i = 0; i < n; ++i) if (!isfinite(v[i])) return 0;
    return 1;
}

static PyObject *new_vector(Py_ssize_t n) {
    npy_intp dims[1] = {n};
    return PyArray_SimpleNew(1, dims, NPY_DOUBLE);
}

#define DATA(o) ((double *)PyArray_DATA((PyArrayObject *)(o)))

static int arity(Py_ssize_t nargs, Py_ssize_t want, const char *name) {
    if (nargs == want) return 1;
    PyErr_Format(PyExc_TypeError, "%s takes %zd arguments (%zd given)", name, want, nargs);
    return 0;
}

/* accelerations(q, qd) -> qdd (nv,), or None */
static PyObject *calls_accelerations(Calls *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!arity(nargs, 2, "accelerations")) return NULL;
    const double *q = vector(args[0], self->nq);
    const double *qd = args[1] == Py_None ? self->zeros : vector(args[1], self->nv);
    if (!q || !qd) Py_RETURN_NONE;
    PyObject *out = new_vector(self->nv);
    if (!out) return NULL;
    double stack[STACK_DOUBLES], *work = stack;
    if (self->dyn_size > STACK_DOUBLES && !(work = malloc(sizeof(double) * self->dyn_size))) {
        Py_DECREF(out);
        return PyErr_NoMemory();
    }
    const int status = self->acc(q, qd, self->p, self->zeros, NULL, DATA(out), work);
    if (work != stack) free(work);
    if (status || !all_finite(DATA(out), self->nv)) {
        Py_DECREF(out);
        Py_RETURN_NONE;
    }
    return out;
}

/* mass_matrix(q) -> M (nv, nv) at zero speeds, or None */
static PyObject *calls_mass_matrix(Calls *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!arity(nargs, 1, "mass_matrix")) return NULL;
    const double *q = vector(args[0], self->nq);
    if (!q) Py_RETURN_NONE;
    const Py_ssize_t n = self->nv;
    npy_intp dims[2] = {n, n};
    PyObject *out = PyArray_SimpleNew(2, dims, NPY_DOUBLE);
    if (!out) return NULL;
    double stack[STACK_DOUBLES], *work = stack;
    if (self->dyn_size > STACK_DOUBLES && !(work = malloc(sizeof(double) * self->dyn_size))) {
        Py_DECREF(out);
        return PyErr_NoMemory();
    }
    self->dyn(q, self->zeros, self->p, self->zeros, work);
    const double *tri = work + self->mm_off;
    double *M = DATA(out);
    int finite = all_finite(tri, n * (n + 1) / 2);
    for (Py_ssize_t i = 0, k = 0; i < n; ++i)
        for (Py_ssize_t j = 0; j <= i; ++j, ++k) M[i * n + j] = M[j * n + i] = tri[k];
    if (work != stack) free(work);
    if (!finite) {
        Py_DECREF(out);
        Py_RETURN_NONE;
    }
    return out;
}

/* check(q, qd) -> True when both would take the fast path (qd may be None) */
static PyObject *calls_check(Calls *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!arity(nargs, 2, "check")) return NULL;
    if (vector(args[0], self->nq) && (args[1] == Py_None || vector(args[1], self->nv))) Py_RETURN_TRUE;
    Py_RETURN_FALSE;
}

/* body(q, qd, index, local) -> (position, velocity, rotation, angular velocity, kinematics)
   of a body point (local: float64 (3,), body frame), all world frame; or None */
static PyObject *calls_body(Calls *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!arity(nargs, 4, "body")) return NULL;
    const double *q = vector(args[0], self->nq);
    const double *qd = args[1] == Py_None ? self->zeros : vector(args[1], self->nv);
    const double *l = vector(args[3], 3);
    const Py_ssize_t index = PyLong_AsSsize_t(args[2]);
    if (index == -1 && PyErr_Occurred()) return NULL;
    if (!q || !qd || !l || index < 0 || index >= self->n_bodies) Py_RETURN_NONE;
    PyObject *kin = new_vector(self->kin_size), *pos = new_vector(3), *vel = new_vector(3), *w = new_vector(3);
    npy_intp dims[2] = {3, 3};
    PyObject *rot = PyArray_SimpleNew(2, dims, NPY_DOUBLE);
    if (!kin || !pos || !vel || !w || !rot) {
        Py_XDECREF(kin); Py_XDECREF(pos); Py_XDECREF(vel); Py_XDECREF(w); Py_XDECREF(rot);
        return NULL;
    }
    self->kin(q, qd, self->p, self->zeros, DATA(kin));
    const double *row = DATA(kin) + self->bodies_off + index * self->body_row;
    const double *R = row + self->rot_off, *o = row + self->origin_off, *V = row + self->vel_off;
    double *x = DATA(pos), *v = DATA(vel), *r = DATA(rot), *om = DATA(w);
    for (int i = 0; i < 9; ++i) r[i] = R[i];
    for (int i = 0; i < 3; ++i) {
        om[i] = V[i];
        x[i] = o[i] + (R[3 * i] * l[0] + R[3 * i + 1] * l[1] + R[3 * i + 2] * l[2]);
    }
    v[0] = V[3] + (om[1] * x[2] - om[2] * x[1]);
    v[1] = V[4] + (om[2] * x[0] - om[0] * x[2]);
    v[2] = V[5] + (om[0] * x[1] - om[1] * x[0]);
    return Py_BuildValue("(NNNNN)", pos, vel, rot, w, kin);
}

static PyObject *calls_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    unsigned long long acc, dyn, kin;
    PyObject *p, *owner;
    Py_ssize_t s[11];
    if (kwargs && PyDict_GET_SIZE(kwargs)) {
        PyErr_SetString(PyExc_TypeError, "Calls takes positional arguments only");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "KKKOOnnnnnnnnnnn", &acc, &dyn, &kin, &p, &owner, &s[0], &s[1], &s[2], &s[3],
                          &s[4], &s[5], &s[6], &s[7], &s[8], &s[9], &s[10]))
        return NULL;
    if (!PyArray_CheckExact(p) || PyArray_TYPE((PyArrayObject *)p) != NPY_DOUBLE
        || PyArray_NDIM((PyArrayObject *)p) != 1 || !PyArray_ISCARRAY_RO((PyArrayObject *)p)
        || !PyArray_ISNOTSWAPPED((PyArrayObject *)p)) {
        PyErr_SetString(PyExc_TypeError, "p must be a contiguous float64 vector");
        return NULL;
    }
    if (!acc || !dyn || !kin) {
        PyErr_SetString(PyExc_ValueError, "null function address");
        return NULL;
    }
    for (int i = 0; i < 11; ++i) if (s[i] < 0) {
        PyErr_SetString(PyExc_ValueError, "negative size");
        return NULL;
    }
    Calls *self = (Calls *)type->tp_alloc(type, 0);
    if (!self) return NULL;
    self->acc = (acc_fn)(uintptr_t)acc;
    self->dyn = (out_fn)(uintptr_t)dyn;
    self->kin = (out_fn)(uintptr_t)kin;
    Py_INCREF(p);
    Py_INCREF(owner);
    self->p_obj = p;
    self->owner = owner;
    self->p = (const double *)PyArray_DATA((PyArrayObject *)p);
    self->nq = s[0]; self->nv = s[1]; self->dyn_size = s[2]; self->mm_off = s[3]; self->kin_size = s[4];
    self->bodies_off = s[5]; self->body_row = s[6]; self->rot_off = s[7]; self->origin_off = s[8];
    self->vel_off = s[9]; self->n_bodies = s[10];
    self->zeros = calloc(self->nv + 1, sizeof(double));
    if (!self->zeros) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    return (PyObject *)self;
}

static void calls_dealloc(Calls *self) {
    Py_XDECREF(self->p_obj);
    Py_XDECREF(self->owner);
    free(self->zeros);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyMethodDef calls_methods[] = {
    {"accelerations", (PyCFunction)(void (*)(void))calls_accelerations, METH_FASTCALL, "qdd or None"},
    {"mass_matrix", (PyCFunction)(void (*)(void))calls_mass_matrix, METH_FASTCALL, "M or None"},
    {"check", (PyCFunction)(void (*)(void))calls_check, METH_FASTCALL, "inputs on the fast path"},
    {"body", (PyCFunction)(void (*)(void))calls_body, METH_FASTCALL, "body point kinematics or None"},
    {NULL, NULL, 0, NULL}};

static PyTypeObject CallsType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "mbcomp_fastcall.Calls",
    .tp_basicsize = sizeof(Calls),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Direct calls of one compiled model's functions with one parameter vector.",
    .tp_new = calls_new,
    .tp_dealloc = (destructor)calls_dealloc,
    .tp_methods = calls_methods,
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, .m_name = "mbcomp_fastcall", .m_doc = NULL,
                                    .m_size = -1, .m_methods = NULL};

PyMODINIT_FUNC PyInit_mbcomp_fastcall(void) {
    import_array();
    if (PyType_Ready(&CallsType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    Py_INCREF(&CallsType);
    if (PyModule_AddObject(m, "Calls", (PyObject *)&CallsType) < 0) {
        Py_DECREF(&CallsType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
