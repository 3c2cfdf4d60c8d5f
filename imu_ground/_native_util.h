/*
 * Helpers shared by the compiled kernels (imu_ground/ ** /_*_native.c): rotations, argument
 * reading through the buffer protocol, result tuples and module creation.
 *
 * Header-only (every function static inline), plain CPython API, no mutable state. Each
 * rotation helper is the twin of the so3.py function it names, term for term and in the
 * same operation order (the kernels are compiled with -ffp-contract=off), so a kernel
 * using it rounds exactly as its pure-Python twin; a kernel whose Python twin orders a
 * formula differently writes that formula out itself (residual.advance's Shepperd step and
 * quaternion products with a zero component, preint_kernel's quaternion -> matrix).
 *
 * setup.py lists this file in every extension's `depends`: editing it rebuilds every kernel.
 * Names start with ig_ (imu_ground) to stay clear of the kernels' own.
 */
#ifndef IMU_GROUND_NATIVE_UTIL_H
#define IMU_GROUND_NATIVE_UTIL_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

/* A METH_FASTCALL entry point as the PyCFunction a PyMethodDef holds. */
#define IG_FASTCALL(f) ((PyCFunction)(void (*)(void))(f))

/* ================================================================================ rotations */
/* Row-major 3x3 matrices (9 doubles), quaternions (w, x, y, z), rotation vectors in rad. */

/* so3.mul_flat: o = a @ b (o may be a or b). */
static inline void ig_mul33(const double *a, const double *b, double *o)
{
    double r[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            r[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
    memcpy(o, r, sizeof r);
}

/* o = a^T (o may be a). */
static inline void ig_transpose33(const double *a, double *o)
{
    double r[9] = {a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]};
    memcpy(o, r, sizeof r);
}

/* so3.renormalise_flat: r <- r (3 I - r^T r) / 2, in place. */
static inline void ig_renormalise33(double *r)
{
    double m[9];
    m[0] = 1.5 - 0.5 * (r[0] * r[0] + r[3] * r[3] + r[6] * r[6]);
    m[4] = 1.5 - 0.5 * (r[1] * r[1] + r[4] * r[4] + r[7] * r[7]);
    m[8] = 1.5 - 0.5 * (r[2] * r[2] + r[5] * r[5] + r[8] * r[8]);
    m[1] = m[3] = -0.5 * (r[0] * r[1] + r[3] * r[4] + r[6] * r[7]);
    m[2] = m[6] = -0.5 * (r[0] * r[2] + r[3] * r[5] + r[6] * r[8]);
    m[5] = m[7] = -0.5 * (r[1] * r[2] + r[4] * r[5] + r[7] * r[8]);
    ig_mul33(r, m, r);
}

/* so3.exp_flat: o = Exp((x, y, z)); series below the angle `small` (so3.SMALL_ANGLE, rad). */
static inline void ig_exp33(double x, double y, double z, double small, double *o)
{
    double t2 = x * x + y * y + z * z, a, b;
    if (t2 < small * small) {
        a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0;
        b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0;
    } else {
        double t = sqrt(t2);
        a = sin(t) / t;
        b = (1.0 - cos(t)) / t2;
    }
    double bxy = b * x * y, bxz = b * x * z, byz = b * y * z;
    double ax = a * x, ay = a * y, az = a * z;
    o[0] = 1.0 - b * (y * y + z * z); o[1] = bxy - az; o[2] = bxz + ay;
    o[3] = bxy + az; o[4] = 1.0 - b * (x * x + z * z); o[5] = byz - ax;
    o[6] = bxz - ay; o[7] = byz + ax; o[8] = 1.0 - b * (x * x + y * y);
}

/* so3.log_flat: o = Log(r), the rotation vector; series below the angle `small`; near pi
   (cos < -0.9) the axis from the largest column of (r + r^T)/2 - c I, signed by the skew part. */
static inline void ig_log33(const double *r, double small, double *o)
{
    double wx = 0.5 * (r[7] - r[5]), wy = 0.5 * (r[2] - r[6]), wz = 0.5 * (r[3] - r[1]);
    double c = 0.5 * (r[0] + r[4] + r[8] - 1.0);
    c = c > 1.0 ? 1.0 : (c < -1.0 ? -1.0 : c);
    double s = sqrt(wx * wx + wy * wy + wz * wz);
    double theta = atan2(s, c);
    if (c >= -0.9) {
        double a;
        if (theta < small) {
            double t2 = theta * theta;
            a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0;
        } else {
            a = sin(theta) / theta;
        }
        o[0] = wx / a; o[1] = wy / a; o[2] = wz / a;
        return;
    }
    double d = 1.0 - c;
    double cols[3][3] = {
        {(r[0] - c) / d, 0.5 * (r[3] + r[1]) / d, 0.5 * (r[6] + r[2]) / d},
        {0.5 * (r[1] + r[3]) / d, (r[4] - c) / d, 0.5 * (r[7] + r[5]) / d},
        {0.5 * (r[2] + r[6]) / d, 0.5 * (r[5] + r[7]) / d, (r[8] - c) / d}};
    int j = 0;                             /* max(range(3), key=diagonal): the first largest */
    if (cols[1][1] > cols[j][j]) j = 1;
    if (cols[2][2] > cols[j][j]) j = 2;
    double ux = cols[j][0], uy = cols[j][1], uz = cols[j][2];
    double n = sqrt(ux * ux + uy * uy + uz * uz);
    double sign = (ux * wx + uy * wy + uz * wz) < 0 ? -1.0 : 1.0;
    double f = sign * theta / n;
    o[0] = f * ux; o[1] = f * uy; o[2] = f * uz;
}

/* so3.quat_from_flat: Shepperd's method on the largest of the trace and the diagonal, w >= 0
   (NaN w negated too). */
static inline void ig_quat_from33(const double *r, double *q)
{
    double r0 = r[0], r1 = r[1], r2 = r[2], r3 = r[3], r4 = r[4], r5 = r[5], r6 = r[6], r7 = r[7], r8 = r[8];
    double t = r0 + r4 + r8, s;
    if (t >= r0 && t >= r4 && t >= r8) {
        s = 0.5 / sqrt(1.0 + t);
        q[0] = 0.25 / s; q[1] = (r7 - r5) * s; q[2] = (r2 - r6) * s; q[3] = (r3 - r1) * s;
        return;
    }
    if (r0 >= r4 && r0 >= r8) {
        s = 0.5 / sqrt(1.0 + r0 - r4 - r8);
        q[0] = (r7 - r5) * s; q[1] = 0.25 / s; q[2] = (r1 + r3) * s; q[3] = (r2 + r6) * s;
    } else if (r4 >= r8) {
        s = 0.5 / sqrt(1.0 + r4 - r0 - r8);
        q[0] = (r2 - r6) * s; q[1] = (r1 + r3) * s; q[2] = 0.25 / s; q[3] = (r5 + r7) * s;
    } else {
        s = 0.5 / sqrt(1.0 + r8 - r0 - r4);
        q[0] = (r3 - r1) * s; q[1] = (r2 + r6) * s; q[2] = (r5 + r7) * s; q[3] = 0.25 / s;
    }
    if (!(q[0] >= 0.0)) {
        q[0] = -q[0]; q[1] = -q[1]; q[2] = -q[2]; q[3] = -q[3];
    }
}

/* so3.flat_from_quat: the rotation matrix of a unit quaternion. */
static inline void ig_33_from_quat(const double *q, double *o)
{
    double w = q[0], x = q[1], y = q[2], z = q[3];
    double xx = x * x, yy = y * y, zz = z * z, xy = x * y, xz = x * z, yz = y * z;
    double wx = w * x, wy = w * y, wz = w * z;
    o[0] = 1.0 - 2.0 * (yy + zz); o[1] = 2.0 * (xy - wz); o[2] = 2.0 * (xz + wy);
    o[3] = 2.0 * (xy + wz); o[4] = 1.0 - 2.0 * (xx + zz); o[5] = 2.0 * (yz - wx);
    o[6] = 2.0 * (xz - wy); o[7] = 2.0 * (yz + wx); o[8] = 1.0 - 2.0 * (xx + yy);
}

/* so3.quat_mul: o = a b (Hamilton product; o may be a or b). */
static inline void ig_quat_mul(const double *a, const double *b, double *o)
{
    double aw = a[0], ax = a[1], ay = a[2], az = a[3], bw = b[0], bx = b[1], by = b[2], bz = b[3];
    o[0] = aw * bw - ax * bx - ay * by - az * bz;
    o[1] = aw * bx + ax * bw + ay * bz - az * by;
    o[2] = aw * by - ax * bz + ay * bw + az * bx;
    o[3] = aw * bz + ax * by - ay * bx + az * bw;
}

/* so3.quat_exp: o = the quaternion of the rotation vector (x, y, z); series below `small`. */
static inline void ig_quat_exp(double x, double y, double z, double small, double *o)
{
    double t = sqrt(x * x + y * y + z * z);
    double h = t < small ? 0.5 - t * t / 48.0 : sin(0.5 * t) / t;
    o[0] = cos(0.5 * t); o[1] = h * x; o[2] = h * y; o[3] = h * z;
}

/* q <- q / |q| (multiplied by the reciprocal of the norm, as the Python twins). */
static inline void ig_quat_normalise(double *q)
{
    double n = 1.0 / sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    q[0] = q[0] * n; q[1] = q[1] * n; q[2] = q[2] * n; q[3] = q[3] * n;
}

/* ================================================================================ arguments */

/* nargs within [lo, hi], else 0 with "name expects lo [or hi] arguments (params), got n". */
static inline int ig_check_nargs(Py_ssize_t nargs, Py_ssize_t lo, Py_ssize_t hi, const char *name,
                                 const char *params)
{
    if (lo <= nargs && nargs <= hi)
        return 1;
    if (lo == hi)
        PyErr_Format(PyExc_TypeError, "%s expects %zd arguments (%s), got %zd", name, lo, params, nargs);
    else
        PyErr_Format(PyExc_TypeError, "%s expects %zd or %zd arguments (%s), got %zd", name, lo, hi, params,
                     nargs);
    return 0;
}

/* A buffer format (struct syntax) is the one-character code `code` in native byte order. */
static inline int ig_is_format(const char *fmt, char code)
{
    if (fmt == NULL)
        fmt = "B";
    if (fmt[0] == '@' || fmt[0] == '=')
        fmt++;
    else if (fmt[0] == '<') {
        const unsigned int one = 1;
        if (*(const unsigned char *)&one != 1)         /* big-endian host: '<' is not native */
            return 0;
        fmt++;
    }
    return fmt[0] == code && fmt[1] == '\0';
}

/* C-contiguous buffer of obj into view, `n` items (n < 0: any number) of kind 'd' (float64),
   '?' (one-byte flags: bool, int8 or uint8) or 'B' (uint8), writable if asked.
   0 with the view held (release it), or -1 with an exception set and nothing held: TypeError
   when obj is no such buffer or holds another type, ValueError when the count differs (the
   count is checked first). */
static inline int ig_get_buffer(PyObject *obj, Py_buffer *view, const char *name, Py_ssize_t n, int writable,
                                char kind)
{
    const char *type = kind == 'd' ? "float64" : (kind == 'B' ? "uint8" : "bool");
    const char *noun = kind == 'd' ? "doubles" : (kind == 'B' ? "bytes" : "flags");
    const Py_ssize_t itemsize = kind == 'd' ? 8 : 1;
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous %sbuffer of %s, got %.100s", name,
                     writable ? "writable " : "", type, Py_TYPE(obj)->tp_name);
        return -1;
    }
    const Py_ssize_t have = view->itemsize > 0 ? view->len / view->itemsize : -1;
    if (n >= 0 && have >= 0 && have != n) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd items, got %zd (a C-contiguous %sbuffer of %zd %s)",
                     name, n, have, writable ? "writable " : "", n, noun);
        PyBuffer_Release(view);
        return -1;
    }
    int ok = view->itemsize == itemsize;
    if (ok && kind == '?')
        ok = ig_is_format(view->format, '?') || ig_is_format(view->format, 'b') || ig_is_format(view->format, 'B');
    else if (ok)
        ok = ig_is_format(view->format, kind);
    if (!ok) {
        PyErr_Format(PyExc_TypeError, "%s must hold %s values, got buffer format '%s'", name, type,
                     view->format ? view->format : "B");
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* A C-contiguous buffer of `n` int64 values (n < 0: any number), writable if asked, into view: 0 with the
   view held (release it), or -1 with an exception set and nothing held (TypeError: no such buffer;
   ValueError: another type or count). */
static inline int ig_get_int64(PyObject *obj, Py_buffer *view, const char *name, Py_ssize_t n, int writable)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous %sbuffer of int64, got %.100s", name,
                     writable ? "writable " : "", Py_TYPE(obj)->tp_name);
        return -1;
    }
    if (view->itemsize != 8 || !(ig_is_format(view->format, 'q') || ig_is_format(view->format, 'l'))
        || (n >= 0 && view->len / 8 != n)) {
        PyErr_Format(PyExc_ValueError, "%s must hold %zd int64 values, got buffer format '%s' of %zd bytes", name, n,
                     view->format ? view->format : "B", view->len);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* The buffers a many-buffer entry point holds: taken one by one with ig_take, all released
   by one ig_release on every path out (start with ig_views vs = {0}). */
enum { IG_MAX_VIEWS = 16 };
typedef struct {
    Py_buffer view[IG_MAX_VIEWS];
    int n;                                 /* views held: view[0 .. n-1] */
} ig_views;

/* ig_get_buffer into the next view of vs (held there): that view, or NULL with an exception set. */
static inline const Py_buffer *ig_take(ig_views *vs, PyObject *obj, const char *name, Py_ssize_t n, int writable,
                                       char kind)
{
    if (vs->n >= IG_MAX_VIEWS) {
        PyErr_SetString(PyExc_SystemError, "ig_take: more than IG_MAX_VIEWS buffers");
        return NULL;
    }
    Py_buffer *v = &vs->view[vs->n];
    if (ig_get_buffer(obj, v, name, n, writable, kind) < 0)
        return NULL;
    vs->n++;
    return v;
}

/* Release every view vs holds (last taken first). */
static inline void ig_release(ig_views *vs)
{
    while (vs->n > 0)
        PyBuffer_Release(&vs->view[--vs->n]);
}

/* A Python number as a double: 0, or -1 with the exception of PyFloat_AsDouble. */
static inline int ig_read_double(PyObject *obj, double *dst)
{
    *dst = PyFloat_AsDouble(obj);
    return (*dst == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

/* n Python numbers (the items of a list or tuple) into out; -1 with a TypeError naming name[i]. */
static inline int ig_read_items(PyObject *const *items, Py_ssize_t n, double *out, const char *name)
{
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *it = items[i];
        out[i] = PyFloat_CheckExact(it) ? PyFloat_AS_DOUBLE(it) : PyFloat_AsDouble(it);
        if (out[i] == -1.0 && PyErr_Occurred()) {
            PyErr_Format(PyExc_TypeError, "%s[%zd] must be a float, got %.100s", name, i, Py_TYPE(it)->tp_name);
            return -1;
        }
    }
    return 0;
}

/* n floats of a list, a tuple or a C-contiguous float64 buffer (any shape) into out;
   -1 with a TypeError or ValueError naming `name`. */
static inline int ig_read_floats(PyObject *o, double *out, Py_ssize_t n, const char *name)
{
    if (PyList_CheckExact(o) || PyTuple_CheckExact(o)) {
        const Py_ssize_t len = PySequence_Fast_GET_SIZE(o);
        if (len != n) {
            PyErr_Format(PyExc_ValueError, "%s must have %zd floats, got %zd", name, n, len);
            return -1;
        }
        return ig_read_items(PySequence_Fast_ITEMS(o), n, out, name);
    }
    Py_buffer view;
    if (ig_get_buffer(o, &view, name, n, 0, 'd') < 0)
        return -1;
    memcpy(out, view.buf, (size_t)n * sizeof(double));
    PyBuffer_Release(&view);
    return 0;
}

/* ================================================================================== results */

/* A new tuple of n floats, or NULL with an exception set. */
static inline PyObject *ig_tuple_of(const double *v, Py_ssize_t n)
{
    PyObject *t = PyTuple_New(n);
    if (t == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *f = PyFloat_FromDouble(v[i]);
        if (f == NULL) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, f);
    }
    return t;
}

/* The module of `def` with the integer constant `name` = value (the kernel's buffer size,
   checked by its Python wrapper at load), or NULL with an exception set. */
static inline PyObject *ig_module_create(PyModuleDef *def, const char *name, long value)
{
    PyObject *m = PyModule_Create(def);
    if (m != NULL && PyModule_AddIntConstant(m, name, value) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}

#endif /* IMU_GROUND_NATIVE_UTIL_H */
