/*
 * The compiled twin of the scalar residual filter (imu_ground/filters/residual.py).
 *
 * Same math, same operation order as the pure-Python reference
 * (residual.advance), so both round alike (built with -ffp-contract=off).
 * Plain CPython API, no numpy headers: arrays come in through the buffer
 * protocol. No global mutable state: the filter's state and parameters live in
 * a float64 buffer owned by the Python ResidualKernel (layout: residual.py,
 * the S_* / L_* / P_* indices below; BUF_LEN is checked at load).
 *
 * Entry points (all METH_FASTCALL):
 *   step(buf, d, q_h, q_v, tilt_x, tilt_y, dv, dt) -> tuple (one output row) or int status
 *   run(buf, d, q_h, q_v, tilt_x, tilt_y, out, angles) -> None  (rows written into out)
 *   check(d, dv, dt) -> int status (0: good frame; 1 rotation, 2 delta_v, 3 delta_t)
 *   check_many(d, dv, dt, out) -> int  (statuses of many frames into a uint8 array; the bad count)
 */
#include "_native_util.h"

/* ---- buffer layout (mirrors residual.py) ---- */
enum {
    S_EW = 0, S_EX, S_EY, S_EZ, S_A, S_C, S_RW, S_RX, S_RY, S_RZ, S_COUNT,    /* 0..10 state */
    L_KA = 11,                                                                 /* 11..21 last */
    L_HAS = 22, P_RH, P_RV, P_UP, P_FOLLOW, P_CUM, P_HASG, P_RENORM,           /* 22..29 */
    P_G = 30,                                                                  /* 30..38 R_gs */
    BUF_LEN = 39
};

enum { ST_OK = 0, ST_ROTATION = 1, ST_DELTA_V = 2, ST_DELTA_T = 3 };

#define ORTHO_TOL 1e-6
/* estimator.MAX_DELTA_V: largest |delta_v| component of an accepted frame, m/s */
#define MAX_DELTA_V 1e6
/* estimator.MIN_DELTA_T: shortest accepted frame, s */
#define MIN_DELTA_T 1e-6
/* estimator.MAX_DELTA_T: longest accepted frame, s */
#define MAX_DELTA_T 1e6

/* ------------------------------------------------------------------------------------ inputs */

/* Copy the values of obj, a float64 array of shape (rows, 3) (rows 0: shape (3,)), into dst. */
static int read_fixed(PyObject *obj, Py_ssize_t rows, double *dst, const char *name)
{
    Py_buffer view;
    const Py_ssize_t n = rows ? 3 * rows : 3;
    if (ig_get_buffer(obj, &view, name, n, 0, 'd') < 0)
        return -1;
    if (view.ndim != (rows ? 2 : 1) || (rows && view.shape[0] != rows)) {
        if (rows)
            PyErr_Format(PyExc_ValueError, "%s must have shape (%zd, 3)", name, rows);
        else
            PyErr_Format(PyExc_ValueError, "%s must have shape (3,)", name);
        PyBuffer_Release(&view);
        return -1;
    }
    memcpy(dst, view.buf, (size_t)n * sizeof(double));
    PyBuffer_Release(&view);
    return 0;
}

/* ------------------------------------------------------------------------------- frame check */

/* The twin of frame_checks.frame_status: 0 for a good frame (NaN fails every comparison). */
static inline int frame_status(const double *r, const double *dv, double dt)
{
    const double r00 = r[0], r01 = r[1], r02 = r[2], r10 = r[3], r11 = r[4], r12 = r[5];
    const double r20 = r[6], r21 = r[7], r22 = r[8];
    const double lo = 1.0 - ORTHO_TOL, hi = 1.0 + ORTHO_TOL;
    const double c0 = r00 * r00 + r10 * r10 + r20 * r20, c1 = r01 * r01 + r11 * r11 + r21 * r21;
    const double c2 = r02 * r02 + r12 * r12 + r22 * r22;
    const double o01 = r00 * r01 + r10 * r11 + r20 * r21, o02 = r00 * r02 + r10 * r12 + r20 * r22;
    const double o12 = r01 * r02 + r11 * r12 + r21 * r22;
    const double det = r00 * (r11 * r22 - r12 * r21) - r01 * (r10 * r22 - r12 * r20) + r02 * (r10 * r21 - r11 * r20);
    if (!(lo <= c0 && c0 <= hi && lo <= c1 && c1 <= hi && lo <= c2 && c2 <= hi
          && -ORTHO_TOL <= o01 && o01 <= ORTHO_TOL && -ORTHO_TOL <= o02 && o02 <= ORTHO_TOL
          && -ORTHO_TOL <= o12 && o12 <= ORTHO_TOL && det > 0.0))
        return ST_ROTATION;
    if (dv != NULL && !(fabs(dv[0]) <= MAX_DELTA_V && fabs(dv[1]) <= MAX_DELTA_V && fabs(dv[2]) <= MAX_DELTA_V))
        return ST_DELTA_V;
    if (!(dt >= MIN_DELTA_T && dt <= MAX_DELTA_T))
        return ST_DELTA_T;
    return ST_OK;
}

/* ------------------------------------------------------------------------------------ kernel */

typedef struct {
    double e[4], a, c, r[4];               /* E and the cumulative R as quaternions (w, x, y, z) */
    long long count;
    double last[11];
    /* parameters */
    double r_h, r_v, g[9];
    int up, follow, cum, hasg;
    long long renorm_every;
} Kernel;

static void kernel_load(Kernel *k, const double *b)
{
    memcpy(k->e, b + S_EW, sizeof k->e);
    k->a = b[S_A]; k->c = b[S_C];
    memcpy(k->r, b + S_RW, sizeof k->r);
    k->count = (long long)b[S_COUNT];
    k->r_h = b[P_RH]; k->r_v = b[P_RV];
    k->up = b[P_UP] != 0.0; k->follow = b[P_FOLLOW] != 0.0; k->cum = b[P_CUM] != 0.0; k->hasg = b[P_HASG] != 0.0;
    k->renorm_every = (long long)b[P_RENORM];
    memcpy(k->g, b + P_G, sizeof k->g);
}

static void kernel_store(const Kernel *k, double *b)
{
    memcpy(b + S_EW, k->e, sizeof k->e);
    b[S_A] = k->a; b[S_C] = k->c;
    memcpy(b + S_RW, k->r, sizeof k->r);
    b[S_COUNT] = (double)k->count;
    memcpy(b + L_KA, k->last, sizeof k->last);
    b[L_HAS] = 1.0;
}

/* One frame of residual.advance, unrolled: the quaternion of the increment (Shepperd), its
   rotation into the body frame, the twist, the scalar covariance and gain recursion, the
   residual update in quaternion products, the cumulative rotation, pitch and roll.
   row receives 8 values (12 with the cumulative rotation). */
static inline void kernel_frame(Kernel *k, const double *r, double q_h, double q_v,
                                int tilt, double bx, double by, int angles, double *row)
{
    const double r00 = r[0], r01 = r[1], r02 = r[2], r10 = r[3], r11 = r[4], r12 = r[5];
    const double r20 = r[6], r21 = r[7], r22 = r[8];
    double dw, dx, dy, dz, s;
    /* -- quaternion of the increment (Shepperd), w >= 0 */
    const double tr = r00 + r11 + r22;
    if (tr > 0.0) {
        s = 2.0 * sqrt(tr + 1.0);
        const double si = 1.0 / s;
        dw = 0.25 * s; dx = (r21 - r12) * si; dy = (r02 - r20) * si; dz = (r10 - r01) * si;
    } else if (r00 >= r11 && r00 >= r22) {
        s = 2.0 * sqrt(1.0 + r00 - r11 - r22);
        dw = (r21 - r12) / s; dx = 0.25 * s; dy = (r01 + r10) / s; dz = (r02 + r20) / s;
    } else if (r11 >= r22) {
        s = 2.0 * sqrt(1.0 + r11 - r00 - r22);
        dw = (r02 - r20) / s; dx = (r01 + r10) / s; dy = 0.25 * s; dz = (r12 + r21) / s;
    } else {
        s = 2.0 * sqrt(1.0 + r22 - r00 - r11);
        dw = (r10 - r01) / s; dx = (r02 + r20) / s; dy = (r12 + r21) / s; dz = 0.25 * s;
    }
    if (dw < 0.0) {
        dw = -dw; dx = -dx; dy = -dy; dz = -dz;
    }
    if (k->hasg) {                                  /* body increment: vector part turned by R_gs */
        const double *g = k->g;
        const double tx = g[0] * dx + g[1] * dy + g[2] * dz, ty = g[3] * dx + g[4] * dy + g[5] * dz;
        const double tz = g[6] * dx + g[7] * dy + g[8] * dz;
        dx = tx; dy = ty; dz = tz;
    }
    /* -- covariance and gains */
    double a = k->a + q_h, c = k->c + q_v;
    const double a_pr = a, c_pr = c;
    const double ka = a / (a + k->r_h);
    a = ka * k->r_h;
    double kc;
    if (k->up) {
        kc = 0.0;
    } else {
        kc = c / (c + k->r_v);
        c = kc * k->r_v;
    }
    k->a = a; k->c = c;
    /* -- E^- = T^T E dR: p = E d, then m = conj(t) p with t = (ch, 0, 0, sh) the heading twist */
    const double q[4] = {dw, dx, dy, dz};
    double p[4];
    ig_quat_mul(k->e, q, p);
    const double pw = p[0], px = p[1], py = p[2], pz = p[3];
    double mw, mx, my, mz;
    if (k->follow && (dw > 0.0 || dz != 0.0)) {     /* (a half turn about a level axis has no twist) */
        const double h = 1.0 / sqrt(dw * dw + dz * dz);
        const double ch = dw * h, sh = dz * h;
        mw = ch * pw + sh * pz; mx = ch * px + sh * py; my = ch * py - sh * px; mz = ch * pz - sh * pw;
    } else {
        mw = pw; mx = px; my = py; mz = pz;
    }
    if (mw < 0.0) {
        mw = -mw; mx = -mx; my = -my; mz = -mz;
    }
    /* -- innovation y and correction g = K y */
    double yx, yy, yz, gx, gy, gz;
    if (k->up) {
        yx = 2.0 * (mx * mz + mw * my); yy = 2.0 * (my * mz - mw * mx); yz = -2.0 * (mx * mx + my * my);
        gx = -ka * yy; gy = ka * yx; gz = 0.0;
    } else {
        double Mw, Mx, My, Mz;
        if (tilt) {                                 /* M = E^- Exp(-b), b = (bx, by, 0) */
            const double bn = sqrt(bx * bx + by * by);
            const double hb = bn < 1e-4 ? 0.5 - bn * bn / 48.0 : sin(0.5 * bn) / bn;
            const double cw = cos(0.5 * bn), cx = -hb * bx, cy = -hb * by;
            Mw = mw * cw - mx * cx - my * cy;
            Mx = mw * cx + mx * cw - mz * cy;
            My = mw * cy + my * cw + mz * cx;
            Mz = mz * cw + mx * cy - my * cx;
            if (Mw < 0.0) {
                Mw = -Mw; Mx = -Mx; My = -My; Mz = -Mz;
            }
        } else {
            Mw = mw; Mx = mx; My = my; Mz = mz;
        }
        const double vn = sqrt(Mx * Mx + My * My + Mz * Mz);
        const double f = vn > 1e-300 ? 2.0 * atan2(vn, Mw) / vn : 2.0;
        yx = f * Mx; yy = f * My; yz = f * Mz;
        gx = ka * yx; gy = ka * yy; gz = kc * yz;
    }
    /* -- E = Exp(-g) E^- (re-normalised every renorm_every frames) */
    double xq[4], *n = k->e;
    const double m[4] = {mw, mx, my, mz};
    ig_quat_exp(-gx, -gy, -gz, 1e-4, xq);           /* h (-g) = (-h) g and |-g| = |g|, exactly */
    ig_quat_mul(xq, m, n);
    k->count += 1;
    const int renorm = k->count % k->renorm_every == 0;
    if (renorm)
        ig_quat_normalise(n);
    const double nw = n[0], nx = n[1], ny = n[2], nz = n[3];
    /* -- pitch and roll from n_b = E^T e_z, the third row of E */
    double pitch = NAN, roll = NAN;
    if (angles) {
        const double n0 = 2.0 * (nx * nz - nw * ny);
        const double n1 = 2.0 * (ny * nz + nw * nx);
        const double n2 = 1.0 - 2.0 * (nx * nx + ny * ny);
        pitch = atan2(-n0, sqrt(n1 * n1 + n2 * n2));
        roll = atan2(n1, n2);
    }
    row[0] = nw; row[1] = nx; row[2] = ny; row[3] = nz; row[4] = a; row[5] = c; row[6] = pitch; row[7] = roll;
    if (k->cum) {                                   /* R = R dR */
        ig_quat_mul(k->r, q, k->r);
        if (renorm)
            ig_quat_normalise(k->r);
        memcpy(row + 8, k->r, sizeof k->r);
    }
    double *l = k->last;
    l[0] = ka; l[1] = kc; l[2] = a_pr; l[3] = c_pr; l[4] = yx; l[5] = yy; l[6] = yz;
    l[7] = mw; l[8] = mx; l[9] = my; l[10] = mz;
}

/* ------------------------------------------------------------------------------- entry points */

static double *state_buffer(PyObject *obj, Py_buffer *view)
{
    if (ig_get_buffer(obj, view, "buf", BUF_LEN, 1, 'd') < 0)
        return NULL;
    return (double *)view->buf;
}

/* obj as a double into dst: 1, or 0 for None (dst untouched), -1 on error. */
static int optional_double(PyObject *obj, double *dst)
{
    if (obj == Py_None)
        return 0;
    return ig_read_double(obj, dst) < 0 ? -1 : 1;
}

/* A frame's delta_R into d (9 values), then its status (frame_status over delta_v, None or (3,), and
   delta_t): >= 0, or -1 with an exception set. */
static int read_frame_status(PyObject *od, PyObject *odv, PyObject *odt, double *d)
{
    double dv[3];
    if (read_fixed(od, 3, d, "delta_R") < 0)
        return -1;
    const int has_dv = odv != Py_None;
    if (has_dv && read_fixed(odv, 0, dv, "delta_v") < 0)
        return -1;
    double dt;
    if (ig_read_double(odt, &dt) < 0)
        return -1;
    return frame_status(d, has_dv ? dv : NULL, dt);
}

/* The frames of a many-frame entry, 9 float64 values a frame, taken into vs (*d: their values):
   their count, or -1 with an exception set. */
static Py_ssize_t get_frames(ig_views *vs, PyObject *obj, const double **d)
{
    const Py_buffer *v = ig_take(vs, obj, "delta_R", -1, 0, 'd');
    if (v == NULL)
        return -1;
    const Py_ssize_t n = v->len / 8 / 9;
    if (v->len != n * 9 * 8) {
        PyErr_Format(PyExc_ValueError, "delta_R must hold 9 values a frame, got %zd values", v->len / 8);
        return -1;
    }
    *d = (const double *)v->buf;
    return n;
}

PyDoc_STRVAR(step_doc,
"step(buf, d, q_h, q_v, tilt_x, tilt_y, dv, dt) -> tuple or int\n\n"
"One frame (residual.step): the row (ew, ex, ey, ez, a, c, pitch, roll[, rw, rx, ry, rz]),\n"
"or the frame's status (int > 0) with the state untouched when the frame fails the check.");

static PyObject *py_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 8, 8, "step", "buf, d, q_h, q_v, tilt_x, tilt_y, dv, dt"))
        return NULL;
    double d[9], q_h, q_v, bx = 0.0, by = 0.0, row[12];
    const int status = read_frame_status(args[1], args[6], args[7], d);
    if (status < 0)
        return NULL;
    if (ig_read_double(args[2], &q_h) < 0 || ig_read_double(args[3], &q_v) < 0)
        return NULL;
    const int tilt = optional_double(args[4], &bx);
    if (tilt < 0 || optional_double(args[5], &by) < 0)
        return NULL;
    if (status != ST_OK)
        return PyLong_FromLong(status);
    Py_buffer view;
    double *b = state_buffer(args[0], &view);
    if (b == NULL)
        return NULL;
    Kernel k;
    kernel_load(&k, b);
    kernel_frame(&k, d, q_h, q_v, tilt && !k.up, bx, by, 1, row);
    kernel_store(&k, b);
    PyBuffer_Release(&view);
    return ig_tuple_of(row, k.cum ? 12 : 8);
}

PyDoc_STRVAR(run_doc,
"run(buf, d, q_h, q_v, tilt_x, tilt_y, out, angles) -> None\n\n"
"Many frames (residual.run): d (F, 3, 3) float64 (already checked), q_h a float or (F,),\n"
"tilt_x and tilt_y None or (F,), out (F, 8) or (F, 12) float64 receives the rows.");

static PyObject *py_run(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 8, 8, "run", "buf, d, q_h, q_v, tilt_x, tilt_y, out, angles"))
        return NULL;
    ig_views vs = {0};
    PyObject *result = NULL;
    const Py_buffer *vb = ig_take(&vs, args[0], "buf", BUF_LEN, 1, 'd'), *v;
    if (vb == NULL)
        return NULL;
    Kernel k;
    kernel_load(&k, (const double *)vb->buf);
    const Py_ssize_t width = k.cum ? 12 : 8;
    const double *d, *q = NULL, *tx = NULL, *ty = NULL;
    double q_v, q_const = 0.0;
    int angles, have_t = 0;
    if (ig_read_double(args[3], &q_v) < 0 || (angles = PyObject_IsTrue(args[7])) < 0)
        goto done;
    const Py_ssize_t n = get_frames(&vs, args[1], &d);
    if (n < 0)
        goto done;
    if (PyFloat_Check(args[2]) || PyLong_Check(args[2])) {
        if (ig_read_double(args[2], &q_const) < 0)
            goto done;
    } else {
        if ((v = ig_take(&vs, args[2], "q_h", n, 0, 'd')) == NULL)
            goto done;
        q = (const double *)v->buf;
    }
    if (args[4] != Py_None) {
        if ((v = ig_take(&vs, args[4], "tilt_x", n, 0, 'd')) == NULL)
            goto done;
        tx = (const double *)v->buf;
        if ((v = ig_take(&vs, args[5], "tilt_y", n, 0, 'd')) == NULL)
            goto done;
        ty = (const double *)v->buf;
        have_t = 1;
    }
    if ((v = ig_take(&vs, args[6], "out", n * width, 1, 'd')) == NULL)
        goto done;
    double *out = (double *)v->buf;
    const int tilt = have_t && !k.up;
    for (Py_ssize_t i = 0; i < n; i++)
        kernel_frame(&k, d + 9 * i, q ? q[i] : q_const, q_v, tilt, tilt ? tx[i] : 0.0, tilt ? ty[i] : 0.0,
                     angles, out + width * i);
    if (n > 0)
        kernel_store(&k, (double *)vb->buf);
    result = Py_NewRef(Py_None);
done:
    ig_release(&vs);
    return result;
}

PyDoc_STRVAR(check_doc,
"check(d, dv, dt) -> int\n\n"
"The frame's status (frame_checks.frame_status): 0 good, 1 delta_R not a rotation,\n"
"2 delta_v not finite, 3 delta_t not a positive number of seconds. dv may be None.");

static PyObject *py_check(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 3, 3, "check", "d, dv, dt"))
        return NULL;
    double d[9];
    const int status = read_frame_status(args[0], args[1], args[2], d);
    return status < 0 ? NULL : PyLong_FromLong(status);
}

PyDoc_STRVAR(check_many_doc,
"check_many(d, dv, dt, out) -> int\n\n"
"check() of every frame: d (F, 3, 3), dv (F, 3) or None, dt (F,) or None (float64);\n"
"out (F,) uint8 receives the statuses. Returns the number of bad frames.");

static PyObject *py_check_many(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 4, 4, "check_many", "d, dv, dt, out"))
        return NULL;
    ig_views vs = {0};
    PyObject *result = NULL;
    const Py_buffer *v;
    const double *d, *dv = NULL, *dt = NULL;
    const Py_ssize_t n = get_frames(&vs, args[0], &d);
    if (n < 0)
        goto done;
    if (args[1] != Py_None) {
        if ((v = ig_take(&vs, args[1], "delta_v", 3 * n, 0, 'd')) == NULL)
            goto done;
        dv = (const double *)v->buf;
    }
    if (args[2] != Py_None) {
        if ((v = ig_take(&vs, args[2], "delta_t", n, 0, 'd')) == NULL)
            goto done;
        dt = (const double *)v->buf;
    }
    if ((v = ig_take(&vs, args[3], "out", n, 1, 'B')) == NULL)
        goto done;
    unsigned char *out = (unsigned char *)v->buf;
    long bad = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        const int st = frame_status(d + 9 * i, dv ? dv + 3 * i : NULL, dt ? dt[i] : 1.0);
        out[i] = (unsigned char)st;
        bad += st != ST_OK;
    }
    result = PyLong_FromLong(bad);
done:
    ig_release(&vs);
    return result;
}

static PyMethodDef methods[] = {
    {"step", IG_FASTCALL(py_step), METH_FASTCALL, step_doc},
    {"run", IG_FASTCALL(py_run), METH_FASTCALL, run_doc},
    {"check", IG_FASTCALL(py_check), METH_FASTCALL, check_doc},
    {"check_many", IG_FASTCALL(py_check_many), METH_FASTCALL, check_many_doc},
    {NULL, NULL, 0, NULL}
};

PyMODINIT_FUNC PyInit__residual_native(void)
{
    static struct PyModuleDef def = {.m_base = PyModuleDef_HEAD_INIT, .m_name = "_residual_native", .m_size = -1,
        .m_methods = methods, .m_doc = "Compiled twin of imu_ground.filters.residual (the scalar residual filter)."};
    return ig_module_create(&def, "BUF_LEN", BUF_LEN);
}
