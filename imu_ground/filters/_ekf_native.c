/* C twin of the InvariantEKF predict/update kernels (imu_ground/filters/invariant_ekf.py).
 *
 * The filter's whole state is one flat buffer of doubles owned by the Python
 * object (an array('d'); layout: the E_* offsets below, mirrored by the _B*
 * constants of invariant_ekf.py). Every formula is the pure-Python kernel's,
 * term for term and in the same order (the extension is compiled without FMA
 * contraction), so the two round alike; the equality the tests hold them to is the
 * twin rule stated in imu_ground/_native.py.
 *
 * Entry points (METH_FASTCALL):
 *   predict(state, u, Q) -> True          u: None, (3, 3) rotation or (3,) rotation vector (rad);
 *                                          Q: None (the state's Q) or (3, 3). False when u or Q is
 *                                          not a C-contiguous float64 buffer of those shapes (the
 *                                          caller coerces and names the problem).
 *   fill_x(state)                          x as a matrix into its cache (from the quaternion when stale).
 *   update(state, z, R) -> True           z: None (skip), (3, 3) rotation or (3,) direction;
 *                                          False as above; a float (det S) when the innovation
 *                                          covariance is singular (state untouched).
 * No global mutable state; the state buffer is validated at each call.
 */
#include "_native_util.h"

/* state layout (doubles) */
enum {
    E_Q = 0,      /* 4  unit quaternion (w, x, y, z) of x, world <- body */
    E_P = 4,      /* 9  covariance, row-major */
    E_QN = 13,    /* 9  process noise */
    E_RN = 22,    /* 9  measurement noise */
    E_X = 31,     /* 9  x as a matrix (cache, valid when E_XV != 0) */
    E_XV = 40,    /* 1 */
    E_XPR = 41,   /* 4  x_prior (quaternion) */
    E_PPR = 45,   /* 9  P_prior */
    E_XPO = 54,   /* 4  x_post (quaternion) */
    E_PPO = 58,   /* 9  P_post */
    E_Y = 67,     /* 3  innovation */
    E_K = 70,     /* 9  gain */
    E_S = 79,     /* 9  innovation covariance */
    E_SI = 88,    /* 9  its inverse */
    E_DET = 97,   /* 1  det S (nan: no update yet) */
    E_NUP = 98,   /* 1  number of updates */
    E_B = 99,     /* 3  observed body axis b */
    E_HB = 102,   /* 9  -[b]x */
    E_LEFT = 111, /* 1  1: left error, 0: right */
    E_RENORM = 112, /* 1 renormalise the quaternion every this many updates */
    E_Z = 113,    /* 9  last measurement */
    E_ZN = 122,   /* 1  its size: 0 (none), 3 or 9 */
    E_SIZE = 123
};

#define SMALL 1e-4   /* so3.SMALL_ANGLE */

/* ---- scalar kernels (so3's *_flat and quat_* functions) ---------------------------------- */
static inline void sym_upper(double *m)
{
    m[3] = m[1];
    m[6] = m[2];
    m[7] = m[5];
}

/* A P A^T + Q (upper triangle of Q used; lower mirrored), as _congruence */
static inline void congruence(const double *a, const double *p, const double *q, double *o)
{
    double m[9];
    ig_mul33(a, p, m);
    double c00 = m[0] * a[0] + m[1] * a[1] + m[2] * a[2] + q[0];
    double c01 = m[0] * a[3] + m[1] * a[4] + m[2] * a[5] + q[1];
    double c02 = m[0] * a[6] + m[1] * a[7] + m[2] * a[8] + q[2];
    double c11 = m[3] * a[3] + m[4] * a[4] + m[5] * a[5] + q[4];
    double c12 = m[3] * a[6] + m[4] * a[7] + m[5] * a[8] + q[5];
    double c22 = m[6] * a[6] + m[7] * a[7] + m[8] * a[8] + q[8];
    o[0] = c00; o[1] = c01; o[2] = c02;
    o[3] = c01; o[4] = c11; o[5] = c12;
    o[6] = c02; o[7] = c12; o[8] = c22;
}

static const double ZERO9[9] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};

/* inverse by cofactors (as _inv_flat); returns 0 when singular */
static inline int inv_flat(const double *m, double *o, double *det_out)
{
    double a = m[0], b = m[1], c = m[2], d = m[3], e = m[4], f = m[5], g = m[6], h = m[7], i = m[8];
    double A = e * i - f * h, B = f * g - d * i, C = d * h - e * g;
    double det = a * A + b * B + c * C;
    *det_out = det;
    if (det == 0.0 || !isfinite(det))
        return 0;
    double r = 1.0 / det;
    o[0] = A * r; o[1] = (c * h - b * i) * r; o[2] = (b * f - c * e) * r;
    o[3] = B * r; o[4] = (a * i - c * g) * r; o[5] = (c * d - a * f) * r;
    o[6] = C * r; o[7] = (b * g - a * h) * r; o[8] = (a * e - b * d) * r;
    return 1;
}

/* the state's x as a matrix: the cached one, else built from the quaternion and cached */
static inline const double *state_x(double *b)
{
    if (b[E_XV] == 0.0) {
        ig_33_from_quat(b + E_Q, b + E_X);
        b[E_XV] = 1.0;
    }
    return b + E_X;
}

/* ---- predict ----------------------------------------------------------------------------- */
/* U: body increment (NULL: none); qn: process noise (9). As InvariantEKF.predict. */
static inline void predict_core(double *b, const double *U, const double *qn)
{
    double q[4], P[9], x[9], A[9];
    int left = b[E_LEFT] != 0.0, have_x = 0;
    memcpy(P, b + E_P, sizeof P);
    memcpy(q, b + E_Q, sizeof q);
    if (U) {
        double qu[4];
        ig_quat_from33(U, qu);
        ig_quat_mul(b + E_Q, qu, q);
        if (left) {                                  /* P <- U^T P U + Q */
            double Ut[9];
            ig_transpose33(U, Ut);
            congruence(Ut, P, qn, b + E_P);
            memcpy(b + E_PPR, b + E_P, 9 * sizeof(double));
            memcpy(b + E_Q, q, sizeof q);
            memcpy(b + E_XPR, q, sizeof q);
            b[E_XV] = 0.0;
            return;
        }
    } else if (b[E_XV] != 0.0) {
        memcpy(x, b + E_X, sizeof x);
        have_x = 1;
    }
    const double *qq = qn;
    if (!left) {                                     /* P <- P + A Q A^T, A = x U */
        if (!have_x) {
            ig_33_from_quat(q, x);
            have_x = 1;
        }
        congruence(x, qn, ZERO9, A);
        qq = A;
    }
    double a = P[1] + qq[1], bb = P[2] + qq[2], c = P[5] + qq[5];
    double Pn[9] = {P[0] + qq[0], a, bb, a, P[4] + qq[4], c, bb, c, P[8] + qq[8]};
    memcpy(b + E_P, Pn, sizeof Pn);
    memcpy(b + E_PPR, Pn, sizeof Pn);
    memcpy(b + E_Q, q, sizeof q);
    memcpy(b + E_XPR, q, sizeof q);
    if (have_x) {
        memcpy(b + E_X, x, sizeof x);
        b[E_XV] = 1.0;
    } else if (U) {
        b[E_XV] = 0.0;
    }
}

/* ---- update ------------------------------------------------------------------------------ */
/* Left error, rotation measurement: as _update_rotation_left (H = I, quaternion state). */
static inline int update_rotation_left(const double *b, const double *z, const double *r, double *q,
                                       double *Pn, double *y, double *K, double *S, double *SI, double *det_out)
{
    double zq[4];
    const double *P = b + E_P, *qs = b + E_Q;
    double qw = qs[0], qx = qs[1], qy = qs[2], qz = qs[3];
    ig_quat_from33(z, zq);
    double zw = zq[0], zx = zq[1], zy = zq[2], zz = zq[3];
    double aw = qw * zw + qx * zx + qy * zy + qz * zz, ax = qw * zx - qx * zw - qy * zz + qz * zy;
    double ay = qw * zy + qx * zz - qy * zw - qz * zx, az = qw * zz - qx * zy + qy * zx - qz * zw;
    if (aw < 0.0) {
        aw = -aw; ax = -ax; ay = -ay; az = -az;
    }
    double vn = sqrt(ax * ax + ay * ay + az * az);
    double f = vn > 0.0 ? 2.0 * atan2(vn, aw) / vn : 2.0;
    double y0 = ax * f, y1 = ay * f, y2 = az * f;
    double p0 = P[0], p1 = P[1], p2 = P[2], p4 = P[4], p5 = P[5], p8 = P[8];
    double r0 = r[0], r1 = r[1], r2 = r[2], r4 = r[4], r5 = r[5], r8 = r[8];
    double s0 = p0 + r0, s1 = p1 + r1, s2 = p2 + r2, s4 = p4 + r4, s5 = p5 + r5, s8 = p8 + r8;
    double i00 = s4 * s8 - s5 * s5, i01 = s2 * s5 - s1 * s8, i02 = s1 * s5 - s2 * s4;
    double det = s0 * i00 + s1 * i01 + s2 * i02;
    *det_out = det;
    if (det == 0.0 || !isfinite(det))
        return 0;
    double d = 1.0 / det;
    i00 = i00 * d; i01 = i01 * d; i02 = i02 * d;
    double i11 = (s0 * s8 - s2 * s2) * d, i12 = (s1 * s2 - s0 * s5) * d, i22 = (s0 * s4 - s1 * s1) * d;
    SI[0] = i00; SI[1] = i01; SI[2] = i02; SI[3] = i01; SI[4] = i11; SI[5] = i12;
    SI[6] = i02; SI[7] = i12; SI[8] = i22;
    ig_mul33(P, SI, K);
    double k0 = K[0], k1 = K[1], k2 = K[2], k3 = K[3], k4 = K[4], k5 = K[5], k6 = K[6], k7 = K[7], k8 = K[8];
    double n01, n02, n12;
    if (r1 == 0.0 && r2 == 0.0 && r5 == 0.0) {      /* diagonal R */
        n01 = k1 * r4; n02 = k2 * r8; n12 = k5 * r8;
        Pn[0] = k0 * r0; Pn[4] = k4 * r4; Pn[8] = k8 * r8;
    } else {
        n01 = k0 * r1 + k1 * r4 + k2 * r5;
        n02 = k0 * r2 + k1 * r5 + k2 * r8;
        n12 = k3 * r2 + k4 * r5 + k5 * r8;
        Pn[0] = k0 * r0 + k1 * r1 + k2 * r2;
        Pn[4] = k3 * r1 + k4 * r4 + k5 * r5;
        Pn[8] = k6 * r2 + k7 * r5 + k8 * r8;
    }
    Pn[1] = n01; Pn[2] = n02; Pn[3] = n01; Pn[5] = n12; Pn[6] = n02; Pn[7] = n12;
    double e[4];
    ig_quat_exp(k0 * y0 + k1 * y1 + k2 * y2, k3 * y0 + k4 * y1 + k5 * y2, k6 * y0 + k7 * y1 + k8 * y2, SMALL, e);
    ig_quat_mul(qs, e, q);
    y[0] = y0; y[1] = y1; y[2] = y2;
    S[0] = s0; S[1] = s1; S[2] = s2; S[3] = s1; S[4] = s4; S[5] = s5; S[6] = s2; S[7] = s5; S[8] = s8;
    return 1;
}

/* The other three updates (rotation with the right error; direction, left or right), as the
 * general branch of InvariantEKF.update. */
static inline int update_general(double *b, const double *z, int zn, const double *r, double *q,
                                 double *Pn, double *y, double *K, double *S, double *SI, double *det_out)
{
    const double *x = state_x(b), *P = b + E_P;
    int left = b[E_LEFT] != 0.0;
    double Rn[9], t9[9];
    if (zn == 9) {                                   /* right error, H = I */
        double xt[9];
        ig_transpose33(x, xt);
        ig_mul33(z, xt, t9);
        ig_log33(t9, SMALL, y);
        congruence(x, r, ZERO9, Rn);
        double a = P[1] + Rn[1], bb = P[2] + Rn[2], c = P[5] + Rn[5];
        double Sv[9] = {P[0] + Rn[0], a, bb, a, P[4] + Rn[4], c, bb, c, P[8] + Rn[8]};
        memcpy(S, Sv, sizeof Sv);
        if (!inv_flat(S, SI, det_out))
            return 0;
        ig_mul33(P, SI, K);
        ig_mul33(K, Rn, Pn);
        sym_upper(Pn);
    } else {
        double H[9], Ht[9], PHT[9], HPHT[9], KH[9], IKH[9], c1[9], c2[9];
        double z0 = z[0], z1 = z[1], z2 = z[2], b0 = b[E_B], b1 = b[E_B + 1], b2 = b[E_B + 2];
        if (left) {
            y[0] = x[0] * z0 + x[3] * z1 + x[6] * z2 - b0;
            y[1] = x[1] * z0 + x[4] * z1 + x[7] * z2 - b1;
            y[2] = x[2] * z0 + x[5] * z1 + x[8] * z2 - b2;
            memcpy(H, b + E_HB, sizeof H);
            double xt[9];
            ig_transpose33(x, xt);
            congruence(xt, r, ZERO9, Rn);
        } else {
            double xb0 = x[0] * b0 + x[1] * b1 + x[2] * b2, xb1 = x[3] * b0 + x[4] * b1 + x[5] * b2;
            double xb2 = x[6] * b0 + x[7] * b1 + x[8] * b2;
            y[0] = z0 - xb0; y[1] = z1 - xb1; y[2] = z2 - xb2;
            double hat[9] = {0.0, -xb2, xb1, xb2, 0.0, -xb0, -xb1, xb0, 0.0};
            for (int i = 0; i < 9; i++)
                H[i] = -hat[i];
            memcpy(Rn, r, sizeof Rn);
        }
        ig_transpose33(H, Ht);
        ig_mul33(P, Ht, PHT);
        ig_mul33(H, PHT, HPHT);
        sym_upper(HPHT);
        double Ru[9];
        memcpy(Ru, Rn, sizeof Ru);
        sym_upper(Ru);
        for (int i = 0; i < 9; i++)
            S[i] = HPHT[i] + Ru[i];
        if (!inv_flat(S, SI, det_out))
            return 0;
        ig_mul33(PHT, SI, K);
        ig_mul33(K, H, KH);
        for (int i = 0; i < 9; i++)
            IKH[i] = (i % 4 == 0 ? 1.0 : 0.0) - KH[i];        /* Joseph form */
        congruence(IKH, P, ZERO9, c1);
        congruence(K, Rn, ZERO9, c2);
        for (int i = 0; i < 9; i++)
            Pn[i] = c1[i] + c2[i];
    }
    double e[4];
    ig_quat_exp(K[0] * y[0] + K[1] * y[1] + K[2] * y[2], K[3] * y[0] + K[4] * y[1] + K[5] * y[2],
                K[6] * y[0] + K[7] * y[1] + K[8] * y[2], SMALL, e);
    if (left)
        ig_quat_mul(b + E_Q, e, q);
    else
        ig_quat_mul(e, b + E_Q, q);
    return 1;
}

/* z: the measurement (zn = 9 or 3 doubles; zn = 0: skip); r: noise. Returns 0 when S is singular. */
static inline int update_core(double *b, const double *z, int zn, const double *r, double *det_out)
{
    double q[4], Pn[9], y[3], K[9], S[9], SI[9], det;
    if (zn == 0) {                                    /* skipped update (filterpy's convention) */
        b[E_ZN] = 0.0;
        memcpy(b + E_XPO, b + E_Q, 4 * sizeof(double));
        memcpy(b + E_PPO, b + E_P, 9 * sizeof(double));
        b[E_Y] = b[E_Y + 1] = b[E_Y + 2] = 0.0;
        return 1;
    }
    int ok = (zn == 9 && b[E_LEFT] != 0.0)
        ? update_rotation_left(b, z, r, q, Pn, y, K, S, SI, &det)
        : update_general(b, z, zn, r, q, Pn, y, K, S, SI, &det);
    *det_out = det;
    if (!ok)
        return 0;
    double nup = b[E_NUP] + 1.0;
    b[E_NUP] = nup;
    if (fmod(nup, b[E_RENORM]) == 0.0)
        ig_quat_normalise(q);
    memcpy(b + E_Q, q, sizeof q);
    memcpy(b + E_XPO, q, sizeof q);
    b[E_XV] = 0.0;
    memcpy(b + E_P, Pn, sizeof Pn);
    memcpy(b + E_PPO, Pn, sizeof Pn);
    memcpy(b + E_Z, z, zn * sizeof(double));
    b[E_ZN] = (double)zn;
    memcpy(b + E_Y, y, sizeof y);
    memcpy(b + E_K, K, sizeof K);
    memcpy(b + E_S, S, sizeof S);
    memcpy(b + E_SI, SI, sizeof SI);
    b[E_DET] = det;
    return 1;
}

/* ---- argument handling ------------------------------------------------------------------- */
/* The state buffer (writable, C-contiguous doubles, E_SIZE of them); -1 with an exception set. */
static int get_state(PyObject *obj, Py_buffer *view)
{
    return ig_get_buffer(obj, view, "state", E_SIZE, 1, 'd');
}

/* An optional float64 C-contiguous array argument of 9 or 3 doubles (shape (3, 3) or (3,)).
 * Returns its size (0 for None), or -2 when it is not such an array (no exception set):
 * the caller coerces it in Python. */
static int get_array(PyObject *obj, Py_buffer *view, int allow3)
{
    if (obj == Py_None)
        return 0;
    if (!PyObject_CheckBuffer(obj))
        return -2;
    if (ig_get_buffer(obj, view, "u", -1, 0, 'd') < 0) {
        PyErr_Clear();
        return -2;
    }
    int n = -2;
    if (view->ndim == 2 && view->shape[0] == 3 && view->shape[1] == 3)
        n = 9;
    else if (allow3 && view->ndim == 1 && view->shape[0] == 3)
        n = 3;
    if (n < 0)
        PyBuffer_Release(view);
    return n;
}

/* Arguments (state, v, m) of both entry points: the state buffer (left acquired in *st), v copied
 * into vout (9 or 3 doubles; None: 0) and m into mout (9 doubles; None: the state's own at `deflt`).
 * Returns the size of v, -2 when v or m must be coerced by the caller (nothing held, no exception),
 * -1 with an exception set. */
static int take_args(PyObject *const *args, Py_ssize_t nargs, const char *name, const char *params, Py_buffer *st,
                     double *vout, double *mout, int deflt)
{
    if (!ig_check_nargs(nargs, 3, 3, name, params))
        return -1;
    if (get_state(args[0], st) < 0)
        return -1;
    Py_buffer vb, mb;
    int nv = get_array(args[1], &vb, 1);
    int nm = nv == -2 ? -2 : get_array(args[2], &mb, 0);
    if (nv > 0) {
        memcpy(vout, vb.buf, nv * sizeof(double));
        PyBuffer_Release(&vb);
    }
    if (nm == -2) {
        PyBuffer_Release(st);
        return -2;
    }
    memcpy(mout, nm ? (const double *)mb.buf : (const double *)st->buf + deflt, 9 * sizeof(double));
    if (nm)
        PyBuffer_Release(&mb);
    return nv;
}

static PyObject *ekf_predict(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer st;
    double u[9], U[9], Qn[9];
    int nu = take_args(args, nargs, "predict", "state, u, Q", &st, u, Qn, E_QN);
    if (nu == -1)
        return NULL;
    if (nu == -2)
        Py_RETURN_FALSE;
    const double *up = NULL;
    if (nu == 9) {
        up = u;
    } else if (nu == 3) {                               /* a rotation vector: its matrix, as so3.exp_flat */
        ig_exp33(u[0], u[1], u[2], SMALL, U);
        up = U;
    }
    predict_core((double *)st.buf, up, Qn);
    PyBuffer_Release(&st);
    Py_RETURN_TRUE;
}

static PyObject *ekf_update(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer st;
    double z[9], r[9], det = 0.0;
    int nz = take_args(args, nargs, "update", "state, z, R", &st, z, r, E_RN);
    if (nz == -1)
        return NULL;
    if (nz == -2)
        Py_RETURN_FALSE;
    int ok = update_core((double *)st.buf, z, nz, r, &det);
    PyBuffer_Release(&st);
    if (!ok)
        return PyFloat_FromDouble(det);
    Py_RETURN_TRUE;
}

static PyObject *ekf_fill_x(PyObject *self, PyObject *state)
{
    (void)self;
    Py_buffer st;
    if (get_state(state, &st) < 0)
        return NULL;
    state_x((double *)st.buf);
    PyBuffer_Release(&st);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"fill_x", (PyCFunction)ekf_fill_x, METH_O,
     "fill_x(state): the state's rotation matrix cache, built from the quaternion if stale."},
    {"predict", IG_FASTCALL(ekf_predict), METH_FASTCALL,
     "predict(state, u, Q) -> bool: InvariantEKF.predict on the state buffer (False: coerce u or Q)."},
    {"update", IG_FASTCALL(ekf_update), METH_FASTCALL,
     "update(state, z, R) -> True, False (coerce z or R) or det S (singular, state untouched)."},
    {NULL, NULL, 0, NULL}};

PyMODINIT_FUNC PyInit__ekf_native(void)
{
    static struct PyModuleDef def = {.m_base = PyModuleDef_HEAD_INIT, .m_name = "_ekf_native", .m_size = -1,
        .m_methods = methods, .m_doc = "C twin of the InvariantEKF predict/update kernels (see"
                                       " imu_ground.filters.invariant_ekf)."};
    return ig_module_create(&def, "STATE_SIZE", E_SIZE);
}
