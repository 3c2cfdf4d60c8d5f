/* The gravity/velocity filter's per-frame kernel in C: the twin of imu_ground/filters/gravity_kernel.py.
 *
 * Same recursion (gravity_kernel._predict_update, _velocity_update), forces (step_frame) and operation
 * order term by term, compiled without FMA contraction (equality rule: imu_ground/_native.py).
 *
 * All state lives in the caller's float64 buffer (layout: gravity_kernel's docstring;
 * indices below); this module has no mutable global state.
 *
 * Entry points (METH_FASTCALL):
 *   step_frame(s, d9, dv3, dt, stationary, valid, speed) -> ((f0, f1, f2), (a0, a1, a2), |v|)
 *   step_frame(..., speed, out) -> |v|, out (12 float64) = [v, g, acceleration, specific force]
 *   step_sensor(...)  the same on a sensor-frame frame (the buffer's extrinsic applied first)
 *   to_body(s, d9, dv3) -> ((9 floats), (3 floats))  that extrinsic applied (gravity_kernel.to_body)
 *   run_frames(s, d, dv, dt, stationary, valid, speed|None, v, g, P, cum, f, a, speed_out, priors|None,
 *              body_out|None)   body_out given: d, dv are sensor-frame (the extrinsic applied, d written there)
 * d9/dv3: sequences of 9/3 floats (list, tuple or a float64 buffer); run_frames takes C-contiguous
 * buffers (float64, bool flags) and writes into the output buffers.
 */
#include "_native_util.h"

/* buffer layout (gravity_kernel.py) */
enum {
    I_V = 0, I_G = 3, I_P = 6, I_R = 27, I_COUNT = 36, I_INIT = 37, I_WPREV = 38, I_REJECTED = 42,
    I_PRM = 43, I_LEVER = 50, I_EXTR = 54, I_RENORM = 64, I_SMALL = 65,
    I_LAST = 66, I_KIND = 67, I_K = 68, I_Y = 86, I_S = 89, I_DT = 95, I_QV = 96, I_QG = 97, I_PRIOR = 98,
    I_QGAPG = 125, BUF_LEN = 126
};

/* gravity_kernel.body_increment: (R d R^T, R dv) */
static inline void body_increment(const double *R, const double *d, const double *dv, double *db, double *dvb)
{
    double t[9], rt[9];
    ig_transpose33(R, rt);
    ig_mul33(R, d, t);
    ig_mul33(t, rt, db);
    dvb[0] = R[0] * dv[0] + R[1] * dv[1] + R[2] * dv[2];
    dvb[1] = R[3] * dv[0] + R[4] * dv[1] + R[5] * dv[2];
    dvb[2] = R[6] * dv[0] + R[7] * dv[1] + R[8] * dv[2];
}

/* ----------------------------------------------------------------------------------------- kernel */
/* gravity_kernel._velocity_update: update of xp (6 state + 21 P entries) with the world-frame velocity z,
 * noise n6 (upper triangle). Returns 0 when gated out (xp untouched), else 1 with xn, K (6x3), y, S. */
static inline int velocity_update(const double *xp, const double *n6, const double *z, double gate,
                                  double *xn, double *K, double *y, double *S)
{
    double v0 = xp[0], v1 = xp[1], v2 = xp[2];
    double a00 = xp[6], a01 = xp[7], a02 = xp[8], a11 = xp[9], a12 = xp[10], a22 = xp[11];
    const double *b = xp + 12;
    double c00 = xp[21], c01 = xp[22], c02 = xp[23], c11 = xp[24], c12 = xp[25], c22 = xp[26];
    double s0 = a00 + n6[0], s1 = a01 + n6[1], s2 = a02 + n6[2], s4 = a11 + n6[3], s5 = a12 + n6[4],
           s8 = a22 + n6[5];
    double j00 = s4 * s8 - s5 * s5, j01 = s2 * s5 - s1 * s8, j02 = s1 * s5 - s2 * s4;
    double det = s0 * j00 + s1 * j01 + s2 * j02;
    double j11 = s0 * s8 - s2 * s2, j12 = s1 * s2 - s0 * s5, j22 = s0 * s4 - s1 * s1;
    double d = 1.0 / det;
    double i00 = j00 * d, i01 = j01 * d, i02 = j02 * d, i11 = j11 * d, i12 = j12 * d, i22 = j22 * d;
    double y0 = z[0] - v0, y1 = z[1] - v1, y2 = z[2] - v2;
    double w0 = i00 * y0 + i01 * y1 + i02 * y2, w1 = i01 * y0 + i11 * y1 + i12 * y2,
           w2 = i02 * y0 + i12 * y1 + i22 * y2;
    if (y0 * w0 + y1 * w1 + y2 * w2 > gate)
        return 0;
    const double pht[6][3] = {{a00, a01, a02}, {a01, a11, a12}, {a02, a12, a22},
                              {b[0], b[3], b[6]}, {b[1], b[4], b[7]}, {b[2], b[5], b[8]}};
    for (int i = 0; i < 6; i++) {
        double r0 = pht[i][0], r1 = pht[i][1], r2 = pht[i][2];
        K[3 * i] = r0 * i00 + r1 * i01 + r2 * i02;
        K[3 * i + 1] = r0 * i01 + r1 * i11 + r2 * i12;
        K[3 * i + 2] = r0 * i02 + r1 * i12 + r2 * i22;
        xn[i] = xp[i] + K[3 * i] * y0 + K[3 * i + 1] * y1 + K[3 * i + 2] * y2;
    }
    const double *k = K;   /* k[3 i + j] = K_ij */
    double *p = xn + 6;
    p[0] = a00 - (k[0] * a00 + k[1] * a01 + k[2] * a02);
    p[1] = a01 - (k[0] * a01 + k[1] * a11 + k[2] * a12);
    p[2] = a02 - (k[0] * a02 + k[1] * a12 + k[2] * a22);
    p[3] = a11 - (k[3] * a01 + k[4] * a11 + k[5] * a12);
    p[4] = a12 - (k[3] * a02 + k[4] * a12 + k[5] * a22);
    p[5] = a22 - (k[6] * a02 + k[7] * a12 + k[8] * a22);
    for (int i = 0; i < 3; i++)            /* cov(v, g) rows: b_ij - (K_i . B[:, j]) */
        for (int j = 0; j < 3; j++)
            p[6 + 3 * i + j] = b[3 * i + j] - (k[3 * i] * b[j] + k[3 * i + 1] * b[3 + j] + k[3 * i + 2] * b[6 + j]);
    p[15] = c00 - (k[9] * b[0] + k[10] * b[3] + k[11] * b[6]);
    p[16] = c01 - (k[9] * b[1] + k[10] * b[4] + k[11] * b[7]);
    p[17] = c02 - (k[9] * b[2] + k[10] * b[5] + k[11] * b[8]);
    p[18] = c11 - (k[12] * b[1] + k[13] * b[4] + k[14] * b[7]);
    p[19] = c12 - (k[12] * b[2] + k[13] * b[5] + k[14] * b[8]);
    p[20] = c22 - (k[15] * b[2] + k[16] * b[5] + k[17] * b[8]);
    y[0] = y0; y[1] = y1; y[2] = y2;
    S[0] = s0; S[1] = s1; S[2] = s2; S[3] = s4; S[4] = s5; S[5] = s8;
    return 1;
}

/* gravity_kernel._predict_update for one frame (unrolled: the predict on the 21 unique entries of P
 * for F = [[I, -dt I], [0, I]], then the speed update, the gated ZUPT or the non-holonomic constraint
 * on the body y and z axes), state and last-step record in s; prior (27) copied out when not NULL. */
static inline void predict_update(double *s, const double *d, const double *dv, double dt, int stationary,
                                  int valid, double speed, double *prior)
{
    double *x = s, *r = s + I_R;
    const double *prm = s + I_PRM;
    double rp[9];
    memcpy(rp, r, sizeof rp);
    double count = s[I_COUNT] + 1.0;
    s[I_COUNT] = count;
    ig_mul33(rp, d, r);
    if (fmod(count, s[I_RENORM]) == 0.0)
        ig_renormalise33(r);
    double w0 = rp[0] * dv[0] + rp[1] * dv[1] + rp[2] * dv[2], w1 = rp[3] * dv[0] + rp[4] * dv[1] + rp[5] * dv[2],
           w2 = rp[6] * dv[0] + rp[7] * dv[1] + rp[8] * dv[2];
    if (s[I_INIT] == 0.0) {                /* gravity from the first frame's mean specific force */
        x[3] = w0 / dt; x[4] = w1 / dt; x[5] = w2 / dt;
        s[I_INIT] = 1.0;
    }
    double g0 = x[3], g1 = x[4], g2 = x[5];
    x[0] = x[0] + w0 - dt * g0; x[1] = x[1] + w1 - dt * g1; x[2] = x[2] + w2 - dt * g2;
    double qv = (valid ? prm[0] : prm[0] + prm[1]) * dt, qg = (valid ? prm[2] : prm[2] + s[I_QGAPG]) * dt;
    double *a = x + 6, *b = x + 12, *c = x + 21;   /* a: 00 01 02 11 12 22; b: row-major; c: as a */
    a[0] = a[0] - dt * (2.0 * b[0] - dt * c[0]) + qv;
    a[3] = a[3] - dt * (2.0 * b[4] - dt * c[3]) + qv;
    a[5] = a[5] - dt * (2.0 * b[8] - dt * c[5]) + qv;
    a[1] = a[1] - dt * (b[1] + b[3] - dt * c[1]);
    a[2] = a[2] - dt * (b[2] + b[6] - dt * c[2]);
    a[4] = a[4] - dt * (b[5] + b[7] - dt * c[4]);
    b[0] = b[0] - dt * c[0]; b[1] = b[1] - dt * c[1]; b[2] = b[2] - dt * c[2];
    b[3] = b[3] - dt * c[1]; b[4] = b[4] - dt * c[3]; b[5] = b[5] - dt * c[4];
    b[6] = b[6] - dt * c[2]; b[7] = b[7] - dt * c[4]; b[8] = b[8] - dt * c[5];
    c[0] = c[0] + qg; c[3] = c[3] + qg; c[5] = c[5] + qg;
    double *pr = s + I_PRIOR;
    memcpy(pr, x, 27 * sizeof(double));
    if (prior)
        memcpy(prior, x, 27 * sizeof(double));
    s[I_LAST] = 1.0; s[I_DT] = dt; s[I_QV] = qv; s[I_QG] = qg;
    double *K = s + I_K, *y = s + I_Y, *S = s + I_S;
    int kind = 0;
    if (!isnan(speed)) {                   /* measured forward speed along the body x axis */
        double rs = prm[6], rn = prm[4], ds = rs - rn;
        double n6[6] = {rn + ds * r[0] * r[0], ds * r[0] * r[3], ds * r[0] * r[6], rn + ds * r[3] * r[3],
                        ds * r[3] * r[6], rn + ds * r[6] * r[6]};
        double z[3] = {speed * r[0], speed * r[3], speed * r[6]};
        kind = 2 * velocity_update(pr, n6, z, INFINITY, x, K, y, S);
    } else if (stationary) {
        double rz = prm[3], n6[6] = {rz, 0.0, 0.0, rz, 0.0, rz}, z[3] = {0.0, 0.0, 0.0};
        kind = velocity_update(pr, n6, z, prm[5], x, K, y, S);
        if (!kind)
            s[I_REJECTED] += 1.0;          /* a smooth cruise flagged as standstill: constraint instead */
    }
    s[I_KIND] = (double)kind;
    if (kind)
        return;
    /* non-holonomic constraint: body y and z velocity, h = columns 1 and 2 of R_k */
    double uy[6], uz[6];                   /* P H^T: [A; B^T] times the columns 1 and 2 of R_k */
    const double A[3][3] = {{a[0], a[1], a[2]}, {a[1], a[3], a[4]}, {a[2], a[4], a[5]}};
    for (int i = 0; i < 3; i++) {
        uy[i] = A[i][0] * r[1] + A[i][1] * r[4] + A[i][2] * r[7];
        uz[i] = A[i][0] * r[2] + A[i][1] * r[5] + A[i][2] * r[8];
        uy[3 + i] = b[i] * r[1] + b[3 + i] * r[4] + b[6 + i] * r[7];
        uz[3 + i] = b[i] * r[2] + b[3 + i] * r[5] + b[6 + i] * r[8];
    }
    double rn = prm[4];
    double s00 = r[1] * uy[0] + r[4] * uy[1] + r[7] * uy[2] + rn;
    double s01 = r[1] * uz[0] + r[4] * uz[1] + r[7] * uz[2];
    double s11 = r[2] * uz[0] + r[5] * uz[1] + r[8] * uz[2] + rn;
    double det = s00 * s11 - s01 * s01;
    double i00 = s11 / det, i01 = -s01 / det, i11 = s00 / det;
    double e0 = -(r[1] * x[0] + r[4] * x[1] + r[7] * x[2]);
    double e1 = -(r[2] * x[0] + r[5] * x[1] + r[8] * x[2]);
    double ky[6], kz[6];
    for (int i = 0; i < 6; i++) {
        ky[i] = uy[i] * i00 + uz[i] * i01;
        kz[i] = uy[i] * i01 + uz[i] * i11;
        K[2 * i] = ky[i]; K[2 * i + 1] = kz[i];
    }
    for (int i = 0; i < 6; i++)
        x[i] = x[i] + ky[i] * e0 + kz[i] * e1;
    /* P - K S K^T = P - K PHT^T (upper triangle) */
    a[0] = a[0] - ky[0] * uy[0] - kz[0] * uz[0]; a[1] = a[1] - ky[0] * uy[1] - kz[0] * uz[1];
    a[2] = a[2] - ky[0] * uy[2] - kz[0] * uz[2]; a[3] = a[3] - ky[1] * uy[1] - kz[1] * uz[1];
    a[4] = a[4] - ky[1] * uy[2] - kz[1] * uz[2]; a[5] = a[5] - ky[2] * uy[2] - kz[2] * uz[2];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            b[3 * i + j] = b[3 * i + j] - ky[i] * uy[3 + j] - kz[i] * uz[3 + j];
    c[0] = c[0] - ky[3] * uy[3] - kz[3] * uz[3]; c[1] = c[1] - ky[3] * uy[4] - kz[3] * uz[4];
    c[2] = c[2] - ky[3] * uy[5] - kz[3] * uz[5]; c[3] = c[3] - ky[4] * uy[4] - kz[4] * uz[4];
    c[4] = c[4] - ky[4] * uy[5] - kz[4] * uz[5]; c[5] = c[5] - ky[5] * uy[5] - kz[5] * uz[5];
    y[0] = e0; y[1] = e1;
    S[0] = s00; S[1] = s01; S[2] = s11;
}

/* gravity_kernel.step_frame: one frame, then its mean specific force f and acceleration acc (body, mid-frame);
 * returns |v| */
static inline double frame(double *s, const double *d, const double *dv, double dt, int stationary, int valid,
                           double speed, double *prior, double *f, double *acc)
{
    double rp[9], phi[3], h[9], w[3];
    memcpy(rp, s + I_R, sizeof rp);
    predict_update(s, d, dv, dt, stationary, valid, speed, prior);
    double small = s[I_SMALL];
    ig_log33(d, small, phi);
    w[0] = phi[0] / dt; w[1] = phi[1] / dt; w[2] = phi[2] / dt;
    ig_exp33(0.5 * phi[0], 0.5 * phi[1], 0.5 * phi[2], small, h);       /* body_{k-1} <- mid */
    double u0 = dv[0] / dt, u1 = dv[1] / dt, u2 = dv[2] / dt;
    double f0 = h[0] * u0 + h[3] * u1 + h[6] * u2, f1 = h[1] * u0 + h[4] * u1 + h[7] * u2,
           f2 = h[2] * u0 + h[5] * u1 + h[8] * u2;
    if (s[I_LEVER] != 0.0) {
        const double *l = s + I_LEVER + 1, *wp = s[I_WPREV] != 0.0 ? s + I_WPREV + 1 : w;
        double al0 = (w[0] - wp[0]) / dt, al1 = (w[1] - wp[1]) / dt, al2 = (w[2] - wp[2]) / dt;
        double ax = al1 * l[2] - al2 * l[1], ay = al2 * l[0] - al0 * l[2], az = al0 * l[1] - al1 * l[0];
        double m0 = w[1] * l[2] - w[2] * l[1], m1 = w[2] * l[0] - w[0] * l[2], m2 = w[0] * l[1] - w[1] * l[0];
        double cx = w[1] * m2 - w[2] * m1, cy = w[2] * m0 - w[0] * m2, cz = w[0] * m1 - w[1] * m0;
        f0 = f0 - ax - cx; f1 = f1 - ay - cy; f2 = f2 - az - cz;
    }
    s[I_WPREV] = 1.0;
    s[I_WPREV + 1] = w[0]; s[I_WPREV + 2] = w[1]; s[I_WPREV + 3] = w[2];
    double g0 = s[I_G], g1 = s[I_G + 1], g2 = s[I_G + 2];
    double q0 = rp[0] * g0 + rp[3] * g1 + rp[6] * g2, q1 = rp[1] * g0 + rp[4] * g1 + rp[7] * g2,
           q2 = rp[2] * g0 + rp[5] * g1 + rp[8] * g2;                  /* R_{k-1}^T g */
    f[0] = f0; f[1] = f1; f[2] = f2;
    acc[0] = f0 - (h[0] * q0 + h[3] * q1 + h[6] * q2);
    acc[1] = f1 - (h[1] * q0 + h[4] * q1 + h[7] * q2);
    acc[2] = f2 - (h[2] * q0 + h[5] * q1 + h[8] * q2);
    return sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
}

/* -------------------------------------------------------------------------------- argument parsing */
/* the state buffer: writable float64, BUF_LEN items */
static double *get_state(PyObject *o, Py_buffer *view)
{
    if (ig_get_buffer(o, view, "state", BUF_LEN, 1, 'd') < 0)
        return NULL;
    return (double *)view->buf;
}

/* ------------------------------------------------------------------------------------ entry points */
static PyObject *step_common(PyObject *const *args, Py_ssize_t nargs, int sensor, const char *fname)
{
    if (!ig_check_nargs(nargs, 7, 8, fname, "s, d9, dv3, dt, stationary, valid, speed[, out]"))
        return NULL;
    double d[9], dv[3], f[3], acc[3], dt;
    if (ig_read_floats(args[1], d, 9, "d9") < 0 || ig_read_floats(args[2], dv, 3, "dv3") < 0 ||
        ig_read_double(args[3], &dt) < 0)
        return NULL;
    if (!(dt > 0.0)) {                     /* (the Python twin divides by it: the same error in both) */
        PyErr_Format(PyExc_ValueError, "dt must be > 0 s, got %R", args[3]);
        return NULL;
    }
    int stationary = PyObject_IsTrue(args[4]), valid = PyObject_IsTrue(args[5]);
    if (stationary < 0 || valid < 0)
        return NULL;
    double speed = NAN;
    if (args[6] != Py_None && ig_read_double(args[6], &speed) < 0)
        return NULL;
    Py_buffer view, out;
    if (nargs == 8 && ig_get_buffer(args[7], &out, "out", 12, 1, 'd') < 0)
        return NULL;
    double *s = get_state(args[0], &view);
    if (!s) {
        if (nargs == 8)
            PyBuffer_Release(&out);
        return NULL;
    }
    double v;
    if (sensor && s[I_EXTR] != 0.0) {
        double db[9], dvb[3];
        body_increment(s + I_EXTR + 1, d, dv, db, dvb);
        v = frame(s, db, dvb, dt, stationary, valid, speed, NULL, f, acc);
    } else {
        v = frame(s, d, dv, dt, stationary, valid, speed, NULL, f, acc);
    }
    if (nargs == 8) {                      /* [v, g, acceleration, specific force] into out, |v| returned */
        double *o = out.buf;
        memcpy(o, s, 6 * sizeof(double));
        memcpy(o + 6, acc, sizeof acc);
        memcpy(o + 9, f, sizeof f);
        PyBuffer_Release(&out);
        PyBuffer_Release(&view);
        return PyFloat_FromDouble(v);
    }
    PyBuffer_Release(&view);
    PyObject *ft = ig_tuple_of(f, 3), *at = ig_tuple_of(acc, 3), *vv = PyFloat_FromDouble(v);
    if (!ft || !at || !vv) {
        Py_XDECREF(ft); Py_XDECREF(at); Py_XDECREF(vv);
        return NULL;
    }
    PyObject *res = PyTuple_New(3);
    if (!res) {
        Py_DECREF(ft); Py_DECREF(at); Py_DECREF(vv);
        return NULL;
    }
    PyTuple_SET_ITEM(res, 0, ft);
    PyTuple_SET_ITEM(res, 1, at);
    PyTuple_SET_ITEM(res, 2, vv);
    return res;
}

static PyObject *step_frame(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    return step_common(args, nargs, 0, "step_frame");
}

static PyObject *step_sensor(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    return step_common(args, nargs, 1, "step_sensor");
}

static PyObject *to_body(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    if (!ig_check_nargs(nargs, 3, 3, "to_body", "s, d9, dv3"))
        return NULL;
    double d[9], dv[3], db[9], dvb[3];
    if (ig_read_floats(args[1], d, 9, "d9") < 0 || ig_read_floats(args[2], dv, 3, "dv3") < 0)
        return NULL;
    Py_buffer view;
    double *s = get_state(args[0], &view);
    if (!s)
        return NULL;
    if (s[I_EXTR] != 0.0) {
        body_increment(s + I_EXTR + 1, d, dv, db, dvb);
    } else {
        memcpy(db, d, sizeof db);
        memcpy(dvb, dv, sizeof dvb);
    }
    PyBuffer_Release(&view);
    PyObject *a = ig_tuple_of(db, 9), *b = ig_tuple_of(dvb, 3);
    if (!a || !b) {
        Py_XDECREF(a); Py_XDECREF(b);
        return NULL;
    }
    PyObject *res = PyTuple_Pack(2, a, b);
    Py_DECREF(a);
    Py_DECREF(b);
    return res;
}

enum { RUN_NARGS = 16, RUN_BUFFERS = 16 };

static PyObject *run_frames(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    static const char *names[RUN_BUFFERS] = {"state", "d", "dv", "dt", "stationary", "valid", "speed", "v_out",
                                             "g_out", "p_out", "cum_out", "f_out", "a_out", "speed_out", "priors",
                                             "body_out"};
    /* items per frame and kind of each argument (after the state) */
    static const int width[RUN_BUFFERS] = {0, 9, 3, 1, 1, 1, 1, 3, 3, 36, 9, 3, 3, 1, 27, 9};
    static const char kinds[RUN_BUFFERS + 1] = "dddd??dddddddddd";
    if (!ig_check_nargs(nargs, RUN_NARGS, RUN_NARGS, "run_frames", "s, d, dv, dt, stationary, valid, speed, v_out, "
                        "g_out, p_out, cum_out, f_out, a_out, speed_out, priors, body_out"))
        return NULL;
    ig_views vs = {0};
    void *buf[RUN_BUFFERS] = {NULL};       /* each argument's values (NULL: None) */
    const Py_buffer *v = ig_take(&vs, args[0], "state", BUF_LEN, 1, 'd');
    PyObject *result = NULL;
    if (!v)
        return NULL;
    double *s = buf[0] = v->buf;
    if (!(v = ig_take(&vs, args[3], "dt", -1, 0, 'd')))   /* the frame count from dt */
        goto done;
    buf[3] = v->buf;
    Py_ssize_t n = v->len / 8;
    for (int i = 1; i < RUN_BUFFERS; i++) {
        if (i == 3 || ((i == 6 || i == 14 || i == 15) && args[i] == Py_None))
            continue;
        if (!(v = ig_take(&vs, args[i], names[i], n * width[i], i >= 7, kinds[i])))
            goto done;
        buf[i] = v->buf;
    }
    const double *d = buf[1], *dv = buf[2], *dt = buf[3], *sp = buf[6];
    const unsigned char *st = buf[4], *va = buf[5];
    double *vo = buf[7], *go = buf[8], *po = buf[9], *co = buf[10], *fo = buf[11], *ao = buf[12], *so = buf[13],
           *pri = buf[14], *bo = buf[15];
    const double *extr = s[I_EXTR] != 0.0 ? s + I_EXTR + 1 : NULL;
    static const int full[36] = {0, 1, 2, 6, 7, 8, 1, 3, 4, 9, 10, 11, 2, 4, 5, 12, 13, 14,
                                 6, 9, 12, 15, 16, 17, 7, 10, 13, 16, 18, 19, 8, 11, 14, 17, 19, 20};
    Py_BEGIN_ALLOW_THREADS                 /* plain arithmetic on the held buffers from here */
    for (Py_ssize_t k = 0; k < n; k++) {
        const double *dk = d + 9 * k, *dvk = dv + 3 * k;
        double dvb[3];
        if (bo) {                          /* sensor -> body */
            if (extr) {
                body_increment(extr, dk, dvk, bo + 9 * k, dvb);
                dvk = dvb;
            } else {
                memcpy(bo + 9 * k, dk, 9 * sizeof(double));
            }
            dk = bo + 9 * k;
        }
        so[k] = frame(s, dk, dvk, dt[k], st[k] != 0, va[k] != 0, sp ? sp[k] : NAN,
                      pri ? pri + 27 * k : NULL, fo + 3 * k, ao + 3 * k);
        memcpy(vo + 3 * k, s + I_V, 3 * sizeof(double));
        memcpy(go + 3 * k, s + I_G, 3 * sizeof(double));
        memcpy(co + 9 * k, s + I_R, 9 * sizeof(double));
        for (int j = 0; j < 36; j++)
            po[36 * k + j] = s[I_P + full[j]];
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    ig_release(&vs);
    return result;
}

static PyMethodDef methods[] = {
    {"step_frame", IG_FASTCALL(step_frame), METH_FASTCALL,
     "step_frame(s, d9, dv3, dt, stationary, valid, speed[, out]) -> ((f0, f1, f2), (a0, a1, a2), speed):\n"
     "one body-frame frame (gravity_kernel.step_frame); speed None or NaN: none. With out (12 float64):\n"
     "[v, g, acceleration, specific force] written there, |v| returned."},
    {"step_sensor", IG_FASTCALL(step_sensor), METH_FASTCALL,
     "step_sensor(s, d9, dv3, dt, stationary, valid, speed[, out]): step_frame of a sensor-frame frame\n"
     "(the state's extrinsic applied first; gravity_kernel.step_sensor)."},
    {"to_body", IG_FASTCALL(to_body), METH_FASTCALL,
     "to_body(s, d9, dv3) -> (d9, dv3): one sensor-frame frame in the body frame (the state's extrinsic;\n"
     "gravity_kernel.to_body)."},
    {"run_frames", IG_FASTCALL(run_frames), METH_FASTCALL,
     "run_frames(s, d, dv, dt, stationary, valid, speed, v_out, g_out, p_out, cum_out, f_out, a_out,\n"
     "speed_out, priors, body_out) -> None: a drive into the output buffers (gravity_kernel.run_frames)."},
    {NULL, NULL, 0, NULL}};

PyMODINIT_FUNC PyInit__gravity_native(void)
{
    static struct PyModuleDef def = {.m_base = PyModuleDef_HEAD_INIT, .m_name = "_gravity_native", .m_size = 0,
        .m_methods = methods, .m_doc = "C twin of imu_ground.filters.gravity_kernel (the gravity/velocity filter's"
                                       " per-frame kernel)."};
    return ig_module_create(&def, "BUF_LEN", BUF_LEN);
}
