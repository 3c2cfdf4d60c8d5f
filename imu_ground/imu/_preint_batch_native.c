/*
 * C twin of the batch preintegration's block kernel without uncertainty (imu/preint_batch.py:
 * _integrate_frames' padded blocks and _blocks_kernel with uncertainty=False), a whole-log pass.
 *
 * Entry point (METH_FASTCALL), releasing the GIL over its loop:
 *   blocks(dt, gyro, accel, ki, yb, j0, start, stop, lanes, bias, midpoint, T, R, v, p)
 *
 * dt (K,) knot interval lengths, s. The knots are the samples, gyro and accel (N, 3) C-contiguous
 * (rad/s, m/s^2, body frame), with M frame boundaries inserted between samples: boundary i before
 * sample ki[i] (M,) int64, sorted, as numpy.insert puts it, its values yb (6, M) (gyro then
 * specific force); knot j of dt is knot j0 + j of that sequence (preint_batch._knots; the
 * values are read where they are, not copied into a (6, K + 1) array). start and stop (B,)
 * int64: block b integrates intervals [start[b], stop[b]), padded to `lanes` intervals of zero
 * length; bias 6 doubles (gyro then accelerometer); midpoint: held value the knots' mean (True)
 * or the left knot's (False).
 * Out (B blocks): T (B,) the block's length, s; R (B, 3, 3) delta_R = R_{start<-end}; v, p (B, 3)
 * delta_v (m/s) and delta_p (m) in the block's start body frame.
 *
 * Term for term the numpy twin, in its operation order, padding included (compiled without FMA
 * contraction): the fused Exp of component_major.exp_and_left_jacobian, the Hillis-Steele product
 * scan of component_major.scan_products over all `lanes` lanes (its bracketing depends on the
 * lane count, so the padding lanes take part as there: identities), running sums lane after lane.
 * So the outputs equal the twin's to the bit where libm's sin is numpy's (the twin rule holds anyway).
 */
#include "_native_util.h"

#include <stdint.h>
#include <stdlib.h>

/* component_major.SMALL_ANGLE2: theta^2 below which the series are used. */
#define SMALL_ANGLE2 1e-8

/* component_major.exp_and_left_jacobian(x, y, z, jacobian=False)'s Exp, row-major into o. */
static inline void exp_cm(double x, double y, double z, double *o)
{
    const double xx = x * x, yy = y * y, zz = z * z;
    const double t2 = xx + yy + zz;
    double a, b;
    if (t2 < SMALL_ANGLE2) {
        const double tts = t2 * t2;
        a = 1.0 - t2 / 6.0 + tts / 120.0;
        b = 0.5 - t2 / 24.0 + tts / 720.0;
    } else {
        const double th = sqrt(t2), hs = sin(0.5 * th);
        a = sin(th) / th;
        b = 2.0 * hs * hs / t2;
    }
    const double xy = x * y, xz = x * z, yz = y * z;
    const double bxy = b * xy, bxz = b * xz, byz = b * yz, ax = a * x, ay = a * y, az = a * z;
    o[0] = 1.0 - b * (yy + zz);
    o[4] = 1.0 - b * (xx + zz);
    o[8] = 1.0 - b * (xx + yy);
    o[1] = bxy - az;
    o[3] = bxy + az;
    o[2] = bxz + ay;
    o[6] = bxz - ay;
    o[5] = byz - ax;
    o[7] = byz + ax;
}

/* component_major.mm for one pair: o = a @ b, each entry ((a_i0 b_0j + a_i1 b_1j) + a_i2 b_2j). */
static inline void mm(const double *a, const double *b, double *o)
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double s = a[3 * i] * b[j];
            s += a[3 * i + 1] * b[3 + j];
            s += a[3 * i + 2] * b[6 + j];
            o[3 * i + j] = s;
        }
}

/* The knots: samples with boundaries inserted (see the header). */
typedef struct {
    const double *gyro, *accel, *yb;
    const int64_t *ki;
    Py_ssize_t n, m, j0;
    Py_ssize_t at;                         /* boundaries placed before the last knot looked up */
} knots;

/* The 6 values of knot j (of dt's numbering) into o; cheapest when j never decreases from call to call. */
static inline void knot(knots *k, Py_ssize_t j, double *o)
{
    const Py_ssize_t g = j + k->j0;        /* position in the sequence with the boundaries inserted */
    while (k->at > 0 && k->ki[k->at - 1] + (k->at - 1) >= g)
        k->at--;
    while (k->at < k->m && k->ki[k->at] + k->at < g)
        k->at++;
    if (k->at < k->m && k->ki[k->at] + k->at == g) {
        for (int r = 0; r < 6; r++)
            o[r] = k->yb[k->m * r + k->at];
        return;
    }
    const Py_ssize_t s = g - k->at;
    memcpy(o, k->gyro + 3 * s, 3 * sizeof(double));
    memcpy(o + 3, k->accel + 3 * s, 3 * sizeof(double));
}

static PyObject *blocks(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!ig_check_nargs(nargs, 15, 15, "blocks", "dt, gyro, accel, ki, yb, j0, start, stop, lanes, bias, midpoint, "
                        "T, R, v, p"))
        return NULL;
    /* the arguments after the knots' (ki, yb, j0) keep their order: shift by 4 */
    args += 4;
    const Py_ssize_t j0 = PyLong_AsSsize_t(args[1]);
    if (j0 == -1 && PyErr_Occurred())
        return NULL;
    const Py_ssize_t lanes = PyLong_AsSsize_t(args[4]);
    if (lanes == -1 && PyErr_Occurred())
        return NULL;
    if (lanes < 1) {
        PyErr_SetString(PyExc_ValueError, "lanes must be at least 1");
        return NULL;
    }
    const int midpoint = PyObject_IsTrue(args[6]);
    if (midpoint < 0)
        return NULL;
    double bias[6];
    if (ig_read_floats(args[5], bias, 6, "bias") < 0)
        return NULL;
    PyObject *const *in = args - 4;        /* dt, gyro, accel, ki, yb */
    ig_views vs = {0};
    Py_buffer startv, stopv, kiv;
    int held = 0;                          /* own views held: 1 ki, 2 and start, 3 and stop */
    PyObject *result = NULL;
    double *work = NULL;
    knots kn = {0};
    const Py_buffer *v = ig_take(&vs, in[0], "dt", -1, 0, 'd');
    if (!v)
        return NULL;
    const Py_ssize_t K = v->len / 8;
    const double *dt = v->buf;
    double *To, *Ro, *vo, *po;
    if (!(v = ig_take(&vs, in[1], "gyro", -1, 0, 'd')))
        goto done;
    kn.gyro = v->buf;
    kn.n = v->len / 24;
    if (!(v = ig_take(&vs, in[2], "accel", 3 * kn.n, 0, 'd')))
        goto done;
    kn.accel = v->buf;
    if (ig_get_int64(in[3], &kiv, "ki", -1, 0) < 0)
        goto done;
    held = 1;
    kn.ki = kiv.buf;
    kn.m = kiv.len / 8;
    if (!(v = ig_take(&vs, in[4], "yb", 6 * kn.m, 0, 'd')))
        goto done;
    kn.yb = v->buf;
    kn.j0 = j0;
    for (Py_ssize_t i = 0; i < kn.m; i++)
        if (kn.ki[i] < 1 || kn.ki[i] >= kn.n || (i && kn.ki[i] < kn.ki[i - 1])) {
            PyErr_Format(PyExc_ValueError, "ki must be sorted sample indices in [1, %zd)", kn.n);
            goto done;
        }
    if (j0 < 0 || j0 + K + 1 > kn.n + kn.m) {
        PyErr_Format(PyExc_ValueError, "knots [%zd, %zd] outside the %zd samples and %zd boundaries", j0, j0 + K,
                     kn.n, kn.m);
        goto done;
    }
    if (!(v = ig_take(&vs, args[7], "T", -1, 1, 'd')))
        goto done;
    To = v->buf;
    const Py_ssize_t B = v->len / 8;
    if (!(v = ig_take(&vs, args[8], "R", 9 * B, 1, 'd')))
        goto done;
    Ro = v->buf;
    if (!(v = ig_take(&vs, args[9], "v", 3 * B, 1, 'd')))
        goto done;
    vo = v->buf;
    if (!(v = ig_take(&vs, args[10], "p", 3 * B, 1, 'd')))
        goto done;
    po = v->buf;
    if (ig_get_int64(args[2], &startv, "start", B, 0) < 0)
        goto done;
    held = 2;
    if (ig_get_int64(args[3], &stopv, "stop", B, 0) < 0)
        goto done;
    held = 3;
    const int64_t *start = startv.buf, *stop = stopv.buf;
    for (Py_ssize_t b = 0; b < B; b++)
        if (start[b] < 0 || stop[b] < start[b] || stop[b] - start[b] > lanes || stop[b] > K) {
            PyErr_Format(PyExc_ValueError, "block %zd: intervals [%lld, %lld) outside [0, %zd) or over %zd lanes", b,
                         (long long)start[b], (long long)stop[b], K, lanes);
            goto done;
        }
    /* per lane: P, Q (9 each: the scan's two rounds), h (6: held values), d (1) */
    work = malloc((size_t)lanes * 25 * sizeof(double));
    if (work == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    double *P = work, *Q = work + 9 * lanes, *H = work + 18 * lanes, *D = work + 24 * lanes;
    for (Py_ssize_t b = 0; b < B; b++) {
        const Py_ssize_t m = (Py_ssize_t)(stop[b] - start[b]);
        for (Py_ssize_t k = 0; k < lanes; k++) {
            double *h = H + 6 * k;
            if (k < m) {
                const Py_ssize_t j = (Py_ssize_t)start[b] + k;
                D[k] = dt[j];
                double a[6], c[6];
                knot(&kn, j, a);
                if (midpoint)
                    knot(&kn, j + 1, c);
                for (int r = 0; r < 6; r++)
                    h[r] = (midpoint ? (a[r] + c[r]) * 0.5 : a[r]) - bias[r];
            } else {                       /* padding: zero length, values 0 - bias */
                D[k] = 0.0;
                for (int r = 0; r < 6; r++)
                    h[r] = 0.0 - bias[r];
            }
            exp_cm(h[0] * D[k], h[1] * D[k], h[2] * D[k], P + 9 * k);
        }
        for (Py_ssize_t d = 1; d < lanes; d *= 2) {      /* scan_products: Q[k] = P[k - d] @ P[k] for k >= d */
            memcpy(Q, P, (size_t)d * 9 * sizeof(double));
            for (Py_ssize_t k = d; k < lanes; k++)
                mm(P + 9 * (k - d), P + 9 * k, Q + 9 * k);
            double *x = P;
            P = Q;
            Q = x;
        }
        /* delta_v, delta_p and time after each lane; Rk = delta_R before lane k (identity, then P[k - 1]) */
        double V[3] = {0.0, 0.0, 0.0}, Pp[3] = {0.0, 0.0, 0.0}, e = 0.0;
        static const double I3[9] = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
        for (Py_ssize_t k = 0; k < lanes; k++) {
            const double *Rk = k ? P + 9 * (k - 1) : I3, *h = H + 6 * k, dk = D[k];
            const double f0 = h[3] * dk, f1 = h[4] * dk, f2 = h[5] * dk;
            for (int i = 0; i < 3; i++) {
                const double c = Rk[3 * i] * f0 + Rk[3 * i + 1] * f1 + Rk[3 * i + 2] * f2;
                const double vb = V[i];
                V[i] = k ? vb + c : c;
                const double q = dk * (vb + 0.5 * c);
                Pp[i] = k ? Pp[i] + q : q;
            }
            e = k ? e + dk : dk;
        }
        To[b] = e;
        memcpy(Ro + 9 * b, P + 9 * (lanes - 1), 9 * sizeof(double));
        memcpy(vo + 3 * b, V, 3 * sizeof(double));
        memcpy(po + 3 * b, Pp, 3 * sizeof(double));
        P = work;                          /* (the rounds swapped the halves) */
        Q = work + 9 * lanes;
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    free(work);
    if (held >= 3)
        PyBuffer_Release(&stopv);
    if (held >= 2)
        PyBuffer_Release(&startv);
    if (held >= 1)
        PyBuffer_Release(&kiv);
    ig_release(&vs);
    return result;
}

static PyMethodDef methods[] = {
    {"blocks", IG_FASTCALL(blocks), METH_FASTCALL,
     "blocks(dt, gyro, accel, ki, yb, j0, start, stop, lanes, bias, midpoint, T, R, v, p) -> None: each padded\n"
     "block's (T, delta_R, delta_v, delta_p) into T, R, v, p (preint_batch._blocks_kernel without uncertainty)."},
    {NULL, NULL, 0, NULL}};

PyMODINIT_FUNC PyInit__preint_batch_native(void)
{
    static struct PyModuleDef def = {.m_base = PyModuleDef_HEAD_INIT, .m_name = "_preint_batch_native", .m_size = -1,
        .m_methods = methods, .m_doc = "C twin of the batch preintegration without uncertainty (see "
                                       "imu_ground.imu.preint_batch)."};
    return PyModule_Create(&def);
}
