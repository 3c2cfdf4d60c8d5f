/* C twin of the preintegration kernel (imu_ground/imu/preint_kernel.py) and of the streaming
 * front-end's per-sample fast path (imu_ground/imu/preint_stream.py).
 *
 * integrate() below is integrate_interval of preint_kernel.py, term for term and in the same
 * order (the extension is compiled without FMA contraction), so the two round alike (equality rule:
 * imu_ground/_native.py).
 * State layouts: deltas (11 doubles) and uncertainty (90), as documented in preint_kernel.py.
 *
 * Entry points (METH_FASTCALL):
 *   integrate_interval(s, u, dt, x, y, z, fx, fy, fz, noise) -> (s', u')
 *       the drop-in twin of the Python function (tuples in, new tuples out; u None stays None);
 *   integrate(state, dt, x, y, z, fx, fy, fz)
 *       the same on a streaming state buffer, in place;
 *   push(state, times, t, gyro, accel) -> True, False or a list of frames
 *       StreamingPreintegrator.push on the state buffer (times: the frame_times as array('d')):
 *       True when the sample was integrated inside a frame (no boundary, no gap, not an every-N
 *       sample); a list of (deltas, uncertainty, n, t_start, t_end, valid) of the frames it
 *       finished when it crossed rate or frame_times boundaries without a gap (split there,
 *       midpoint values interpolated, as the Python slow path); False (state untouched) for
 *       everything else (first sample, gaps, every-N boundaries, errors), the Python slow path's.
 * Streaming state buffer (array('d'), S_* offsets below, mirrored in preint_stream.py).
 * No global mutable state.
 */
#include "_native_util.h"

enum {
    S_DELTAS = 0,   /* 11 */
    S_UNC = 11,     /* 90 */
    S_PREV = 101,   /* 7: t, gyro (3), accel (3) of the last sample, bias removed */
    S_LIM = 108,    /* fast path while t < lim */
    S_MAXGAP = 109,
    S_CD = 110,     /* samples until the next every-N boundary */
    S_BIAS = 111,   /* 6: gyro, accel */
    S_NOISE = 117,  /* 2: q_g, q_a */
    S_MIDPOINT = 119,
    S_UNCERTAINTY = 120,
    S_K = 121,      /* index of the next boundary */
    S_NEXT = 122,   /* its time (inf: none) */
    S_ACTIVE = 123, /* inside a frame */
    S_N = 124,      /* intervals integrated by the boundary path in this frame */
    S_MARK = 125,   /* S_CD at the frame's start */
    S_TSTART = 126,
    S_VALID = 127,
    S_TOL = 128,    /* snap_tol */
    S_MODE = 129,   /* boundaries: 0 every-N (the boundary path is Python's), 1 rate, 2 frame_times */
    S_RATE = 130,
    S_ORIGIN = 131,
    S_SIZE = 132
};

#define SMALL_ANGLE2 1e-8   /* imu_ground.so3.component_major.SMALL_ANGLE2 */

/* One interval (see integrate_interval in preint_kernel.py): s (11) and, unless NULL, u (90), in place.
 * Unrolled like its Python twin: every product written out entry by entry. */
static inline void integrate(double *s, double *u, double dt, double x, double y, double z,
                             double fx, double fy, double fz, double qg, double qa)
{
    double T = s[0], qw = s[1], qx = s[2], qy = s[3], qz = s[4], v0 = s[5], v1 = s[6], v2 = s[7];
    double p0 = s[8], p1 = s[9], p2 = s[10];
    double xx = x * x, yy = y * y, zz = z * z;
    double t2 = xx + yy + zz, ch, k, th = 0.0;
    if (t2 < SMALL_ANGLE2) {
        ch = 1.0 - t2 / 8.0 + t2 * t2 / 384.0;
        k = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0;
    } else {
        th = sqrt(t2);
        ch = cos(0.5 * th);
        k = sin(0.5 * th) / th;
    }
    double tx = 2.0 * (qy * fz - qz * fy), ty = 2.0 * (qz * fx - qx * fz), tz = 2.0 * (qx * fy - qy * fx);
    double c0 = fx + qw * tx + qy * tz - qz * ty;
    double c1 = fy + qw * ty + qz * tx - qx * tz;
    double c2 = fz + qw * tz + qx * ty - qy * tx;
    if (u) {
        double h00 = u[0], h01 = u[1], h02 = u[2], h10 = u[3], h11 = u[4], h12 = u[5], h20 = u[6], h21 = u[7], h22 = u[8];
        double g00 = u[9], g01 = u[10], g02 = u[11], g10 = u[12], g11 = u[13], g12 = u[14];
        double g20 = u[15], g21 = u[16], g22 = u[17];
        double m00 = u[18], m01 = u[19], m02 = u[20], m10 = u[21], m11 = u[22], m12 = u[23];
        double m20 = u[24], m21 = u[25], m22 = u[26];
        double a00 = u[27], a01 = u[28], a02 = u[29], a10 = u[30], a11 = u[31], a12 = u[32];
        double a20 = u[33], a21 = u[34], a22 = u[35];
        double b00 = u[36], b01 = u[37], b02 = u[38], b10 = u[39], b11 = u[40], b12 = u[41];
        double b20 = u[42], b21 = u[43], b22 = u[44];
        double rr00 = u[45], rr01 = u[46], rr02 = u[47], rr11 = u[48], rr12 = u[49], rr22 = u[50];
        double rv00 = u[51], rv01 = u[52], rv02 = u[53], rv10 = u[54], rv11 = u[55], rv12 = u[56];
        double rv20 = u[57], rv21 = u[58], rv22 = u[59];
        double rq00 = u[60], rq01 = u[61], rq02 = u[62], rq10 = u[63], rq11 = u[64], rq12 = u[65];
        double rq20 = u[66], rq21 = u[67], rq22 = u[68];
        double vv00 = u[69], vv01 = u[70], vv02 = u[71], vv11 = u[72], vv12 = u[73], vv22 = u[74];
        double vq00 = u[75], vq01 = u[76], vq02 = u[77], vq10 = u[78], vq11 = u[79], vq12 = u[80];
        double vq20 = u[81], vq21 = u[82], vq22 = u[83];
        double qq00 = u[84], qq01 = u[85], qq02 = u[86], qq11 = u[87], qq12 = u[88], qq22 = u[89];
        double B, C;
        if (t2 < SMALL_ANGLE2) {
            B = 0.5 - t2 / 24.0 + t2 * t2 / 720.0;
            C = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0;
        } else {
            B = 2.0 * k * k;
            C = (th - sin(th)) / (t2 * th);
        }
        /* R_k from the quaternion */
        double x2 = qx + qx, y2 = qy + qy, z2 = qz + qz;
        double wx2 = qw * x2, wy2 = qw * y2, wz2 = qw * z2;
        double xx2 = qx * x2, yy2 = qy * y2, zz2 = qz * z2;
        double xy2 = qx * y2, xz2 = qx * z2, yz2 = qy * z2;
        double r00 = 1.0 - yy2 - zz2, r01 = xy2 - wz2, r02 = xz2 + wy2;
        double r10 = xy2 + wz2, r11 = 1.0 - xx2 - zz2, r12 = yz2 - wx2;
        double r20 = xz2 - wy2, r21 = yz2 + wx2, r22 = 1.0 - xx2 - yy2;
        double mid = T + 0.5 * dt;
        /* gyro-bias Jacobians: H = hat(c) Th; Vg -= H; Mg += mid H */
        double H0, H1, H2;
        H0 = c1 * h20 - c2 * h10; H1 = c1 * h21 - c2 * h11; H2 = c1 * h22 - c2 * h12;
        g00 = g00 - H0; g01 = g01 - H1; g02 = g02 - H2;
        m00 = m00 + mid * H0; m01 = m01 + mid * H1; m02 = m02 + mid * H2;
        H0 = c2 * h00 - c0 * h20; H1 = c2 * h01 - c0 * h21; H2 = c2 * h02 - c0 * h22;
        m10 = m10 + mid * H0; m11 = m11 + mid * H1; m12 = m12 + mid * H2;
        g10 = g10 - H0; g11 = g11 - H1; g12 = g12 - H2;
        H0 = c0 * h10 - c1 * h00; H1 = c0 * h11 - c1 * h01; H2 = c0 * h12 - c1 * h02;
        g20 = g20 - H0; g21 = g21 - H1; g22 = g22 - H2;
        m20 = m20 + mid * H0; m21 = m21 + mid * H1; m22 = m22 + mid * H2;
        /* j = Jl(phi) dt */
        double Cd = C * dt, Bd = B * dt;
        double Cxy = Cd * (x * y), Cxz = Cd * (x * z), Cyz = Cd * (y * z);
        double Bx = Bd * x, By = Bd * y, Bz = Bd * z;
        double j00 = dt - Cd * (yy + zz), j11 = dt - Cd * (xx + zz), j22 = dt - Cd * (xx + yy);
        double j01 = Cxy - Bz, j10 = Cxy + Bz, j02 = Cxz + By;
        double j20 = Cxz - By, j12 = Cyz - Bx, j21 = Cyz + Bx;
        /* Th -= delta_R_k Jl dt */
        h00 = h00 - (r00 * j00 + r01 * j10 + r02 * j20); h01 = h01 - (r00 * j01 + r01 * j11 + r02 * j21);
        h02 = h02 - (r00 * j02 + r01 * j12 + r02 * j22);
        h10 = h10 - (r10 * j00 + r11 * j10 + r12 * j20); h11 = h11 - (r10 * j01 + r11 * j11 + r12 * j21);
        h12 = h12 - (r10 * j02 + r11 * j12 + r12 * j22);
        h20 = h20 - (r20 * j00 + r21 * j10 + r22 * j20); h21 = h21 - (r20 * j01 + r21 * j11 + r22 * j21);
        h22 = h22 - (r20 * j02 + r21 * j12 + r22 * j22);
        /* accelerometer-bias Jacobians: D = delta_R_k dt; Va -= D; Ma += mid D */
        double D0, D1, D2;
        D0 = r00 * dt; D1 = r01 * dt; D2 = r02 * dt;
        a00 = a00 - D0; a01 = a01 - D1; a02 = a02 - D2;
        b00 = b00 + mid * D0; b01 = b01 + mid * D1; b02 = b02 + mid * D2;
        D0 = r10 * dt; D1 = r11 * dt; D2 = r12 * dt;
        b10 = b10 + mid * D0; b11 = b11 + mid * D1; b12 = b12 + mid * D2;
        a10 = a10 - D0; a11 = a11 - D1; a12 = a12 - D2;
        D0 = r20 * dt; D1 = r21 * dt; D2 = r22 * dt;
        a20 = a20 - D0; a21 = a21 - D1; a22 = a22 - D2;
        b20 = b20 + mid * D0; b21 = b21 + mid * D1; b22 = b22 + mid * D2;
        /* covariance, left form, q rows */
        double X00 = c1 * rr02 - c2 * rr01, X01 = c1 * rr12 - c2 * rr11, X02 = c1 * rr22 - c2 * rr12;
        double X10 = c2 * rr00 - c0 * rr02, X11 = c2 * rr01 - c0 * rr12, X12 = c2 * rr02 - c0 * rr22;
        double X20 = c0 * rr01 - c1 * rr00, X21 = c0 * rr11 - c1 * rr01, X22 = c0 * rr12 - c1 * rr02;
        double na = qa * dt;
        double N00 = c1 * X02 - c2 * X01 + na, N01 = c2 * X00 - c0 * X02, N02 = c0 * X01 - c1 * X00;
        double N11 = c2 * X10 - c0 * X12 + na, N12 = c0 * X11 - c1 * X10, N22 = c0 * X21 - c1 * X20 + na;
        double Y00 = c1 * rv20 - c2 * rv10, Y01 = c1 * rv21 - c2 * rv11, Y02 = c1 * rv22 - c2 * rv12;
        double Y10 = c2 * rv00 - c0 * rv20, Y11 = c2 * rv01 - c0 * rv21, Y12 = c2 * rv02 - c0 * rv22;
        double Y20 = c0 * rv10 - c1 * rv00, Y21 = c0 * rv11 - c1 * rv01, Y22 = c0 * rv12 - c1 * rv02;
        double Z00 = c1 * rq20 - c2 * rq10, Z01 = c1 * rq21 - c2 * rq11, Z02 = c1 * rq22 - c2 * rq12;
        double Z10 = c2 * rq00 - c0 * rq20, Z11 = c2 * rq01 - c0 * rq21, Z12 = c2 * rq02 - c0 * rq22;
        double Z20 = c0 * rq10 - c1 * rq00, Z21 = c0 * rq11 - c1 * rq01, Z22 = c0 * rq12 - c1 * rq02;
        double mid2 = mid * mid, midx2 = mid * 2.0;
        qq00 = qq00 + (midx2 * Z00 + mid2 * N00); qq01 = qq01 + (mid * (Z01 + Z10) + mid2 * N01);
        qq02 = qq02 + (mid * (Z02 + Z20) + mid2 * N02);
        qq11 = qq11 + (midx2 * Z11 + mid2 * N11); qq12 = qq12 + (mid * (Z12 + Z21) + mid2 * N12);
        qq22 = qq22 + (midx2 * Z22 + mid2 * N22);
        vq00 = vq00 + (mid * (Y00 - N00) - Z00); vq01 = vq01 + (mid * (Y10 - N01) - Z01);
        vq02 = vq02 + (mid * (Y20 - N02) - Z02);
        vq10 = vq10 + (mid * (Y01 - N01) - Z10); vq11 = vq11 + (mid * (Y11 - N11) - Z11);
        vq12 = vq12 + (mid * (Y21 - N12) - Z12);
        vq20 = vq20 + (mid * (Y02 - N02) - Z20); vq21 = vq21 + (mid * (Y12 - N12) - Z21);
        vq22 = vq22 + (mid * (Y22 - N22) - Z22);
        vv00 = vv00 + (N00 - 2.0 * Y00); vv01 = vv01 + (N01 - Y01 - Y10); vv02 = vv02 + (N02 - Y02 - Y20);
        vv11 = vv11 + (N11 - 2.0 * Y11); vv12 = vv12 + (N12 - Y12 - Y21); vv22 = vv22 + (N22 - 2.0 * Y22);
        rq00 = rq00 + mid * X00; rq01 = rq01 + mid * X10; rq02 = rq02 + mid * X20;
        rq10 = rq10 + mid * X01; rq11 = rq11 + mid * X11; rq12 = rq12 + mid * X21;
        rq20 = rq20 + mid * X02; rq21 = rq21 + mid * X12; rq22 = rq22 + mid * X22;
        rv00 = rv00 - X00; rv01 = rv01 - X10; rv02 = rv02 - X20;
        rv10 = rv10 - X01; rv11 = rv11 - X11; rv12 = rv12 - X21;
        rv20 = rv20 - X02; rv21 = rv21 - X12; rv22 = rv22 - X22;
        if (qg != 0.0) {      /* gyro noise: qg dt [(1 - kap t2) I + kap psi psi^T], psi = delta_R_k phi */
            double kap = 2.0 * C - B * B - C * C * t2;
            double qgd = qg * dt;
            double w1 = qgd * kap;
            double w0 = qgd - w1 * t2;
            double s0 = r00 * x + r01 * y + r02 * z;
            double s1 = r10 * x + r11 * y + r12 * z;
            double s2 = r20 * x + r21 * y + r22 * z;
            double ws0 = w1 * s0, ws1 = w1 * s1;
            rr00 = rr00 + (w0 + ws0 * s0); rr11 = rr11 + (w0 + ws1 * s1); rr22 = rr22 + (w0 + w1 * s2 * s2);
            rr01 = rr01 + ws0 * s1; rr02 = rr02 + ws0 * s2; rr12 = rr12 + ws1 * s2;
        }
        double o[90] = {
            h00, h01, h02, h10, h11, h12, h20, h21, h22,
            g00, g01, g02, g10, g11, g12, g20, g21, g22,
            m00, m01, m02, m10, m11, m12, m20, m21, m22,
            a00, a01, a02, a10, a11, a12, a20, a21, a22,
            b00, b01, b02, b10, b11, b12, b20, b21, b22,
            rr00, rr01, rr02, rr11, rr12, rr22,
            rv00, rv01, rv02, rv10, rv11, rv12, rv20, rv21, rv22,
            rq00, rq01, rq02, rq10, rq11, rq12, rq20, rq21, rq22,
            vv00, vv01, vv02, vv11, vv12, vv22,
            vq00, vq01, vq02, vq10, vq11, vq12, vq20, vq21, vq22,
            qq00, qq01, qq02, qq11, qq12, qq22};
        memcpy(u, o, sizeof o);
    }
    const double e[4] = {ch, k * x, k * y, k * z};
    s[0] = T + dt;
    ig_quat_mul(s + 1, e, s + 1);           /* q <- q Exp(phi) (s[1..4] still hold qw, qx, qy, qz) */
    s[5] = v0 + c0; s[6] = v1 + c1; s[7] = v2 + c2;
    s[8] = p0 + dt * (v0 + 0.5 * c0); s[9] = p1 + dt * (v1 + 0.5 * c1); s[10] = p2 + dt * (v2 + 0.5 * c2);
}

/* ---- argument helpers -------------------------------------------------------------------- */
/* n floats of any sequence into out; -1 with a TypeError/ValueError naming `what` */
static int read_floats(PyObject *seq, double *out, Py_ssize_t n, const char *what)
{
    PyObject *fast = PySequence_Fast(seq, what);
    if (fast == NULL)
        return -1;
    int err = -1;
    if (PySequence_Fast_GET_SIZE(fast) != n)
        PyErr_Format(PyExc_ValueError, "%s must have %zd values, got %zd", what, n, PySequence_Fast_GET_SIZE(fast));
    else
        err = ig_read_items(PySequence_Fast_ITEMS(fast), n, out, what);
    Py_DECREF(fast);
    return err;
}

/* n float arguments into out; -1 with the exception of the first that is not a number */
static int float_args(PyObject *const *args, int n, double *out)
{
    for (int i = 0; i < n; i++)
        if (ig_read_double(args[i], out + i) < 0)
            return -1;
    return 0;
}

static int get_state(PyObject *obj, Py_buffer *view)
{
    return ig_get_buffer(obj, view, "state", S_SIZE, 1, 'd');
}

/* ---- entry points ------------------------------------------------------------------------ */
static PyObject *py_integrate_interval(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 10, 10, "integrate_interval", "s, u, dt, x, y, z, fx, fy, fz, noise"))
        return NULL;
    double s[11], u[90], f[7], noise[2];
    int have_u = args[1] != Py_None;
    if (read_floats(args[0], s, 11, "deltas s") < 0 || (have_u && read_floats(args[1], u, 90, "uncertainty u") < 0) ||
        read_floats(args[9], noise, 2, "noise") < 0 || float_args(args + 2, 7, f) < 0)
        return NULL;
    integrate(s, have_u ? u : NULL, f[0], f[1], f[2], f[3], f[4], f[5], f[6], noise[0], noise[1]);
    PyObject *so = ig_tuple_of(s, 11);
    if (so == NULL)
        return NULL;
    PyObject *uo;
    if (have_u) {
        uo = ig_tuple_of(u, 90);
        if (uo == NULL) {
            Py_DECREF(so);
            return NULL;
        }
    } else {
        uo = Py_None;
        Py_INCREF(uo);
    }
    PyObject *out = PyTuple_New(2);
    if (out == NULL) {
        Py_DECREF(so);
        Py_DECREF(uo);
        return NULL;
    }
    PyTuple_SET_ITEM(out, 0, so);
    PyTuple_SET_ITEM(out, 1, uo);
    return out;
}

static PyObject *py_integrate(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 8, 8, "integrate", "state, dt, x, y, z, fx, fy, fz"))
        return NULL;
    double f[7];
    Py_buffer st;
    if (float_args(args + 1, 7, f) < 0 || get_state(args[0], &st) < 0)
        return NULL;
    double *b = (double *)st.buf;
    integrate(b + S_DELTAS, b[S_UNCERTAINTY] != 0.0 ? b + S_UNC : NULL, f[0], f[1], f[2], f[3], f[4], f[5], f[6],
              b[S_NOISE], b[S_NOISE + 1]);
    PyBuffer_Release(&st);
    Py_RETURN_NONE;
}

/* three floats of a list, tuple or float64 buffer; 0 when it is none of these (no exception set) */
static int three(PyObject *o, double *out)
{
    if (PyList_CheckExact(o) || PyTuple_CheckExact(o)) {
        if (PySequence_Fast_GET_SIZE(o) != 3)
            return 0;
        if (ig_read_items(PySequence_Fast_ITEMS(o), 3, out, "sample") < 0) {
            PyErr_Clear();
            return 0;
        }
        return 1;
    }
    if (!PyObject_CheckBuffer(o))
        return 0;
    Py_buffer v;
    if (ig_get_buffer(o, &v, "sample", 3, 0, 'd') < 0) {
        PyErr_Clear();
        return 0;
    }
    int ok = v.ndim == 1;
    if (ok)
        memcpy(out, v.buf, 3 * sizeof(double));
    PyBuffer_Release(&v);
    return ok;
}

/* One piece of length dt between knots with (bias-free) values ka and kb (_piece of preint_stream.py). */
static inline void piece(double *b, double dt, const double *ka, const double *kb)
{
    double *u = b[S_UNCERTAINTY] != 0.0 ? b + S_UNC : NULL;
    if (b[S_MIDPOINT] != 0.0) {
        double hh = 0.5 * dt;
        integrate(b + S_DELTAS, u, dt, (ka[0] + kb[0]) * hh, (ka[1] + kb[1]) * hh, (ka[2] + kb[2]) * hh,
                  (ka[3] + kb[3]) * hh, (ka[4] + kb[4]) * hh, (ka[5] + kb[5]) * hh, b[S_NOISE], b[S_NOISE + 1]);
    } else {
        integrate(b + S_DELTAS, u, dt, ka[0] * dt, ka[1] * dt, ka[2] * dt, ka[3] * dt, ka[4] * dt, ka[5] * dt,
                  b[S_NOISE], b[S_NOISE + 1]);
    }
    b[S_N] += 1.0;
}

/* A boundary at tb (_cross of preint_stream.py, rate or frame_times): the running frame appended
 * to out as (deltas, uncertainty, n, t_start, t_end, valid), the next one started. -1 on error. */
static int cross(double *b, const double *times, Py_ssize_t ntimes, double tb, PyObject *out)
{
    if (b[S_ACTIVE] != 0.0) {
        PyObject *rec = PyTuple_New(6);
        if (rec == NULL)
            return -1;
        PyObject *items[6] = {
            ig_tuple_of(b + S_DELTAS, 11),
            b[S_UNCERTAINTY] != 0.0 ? ig_tuple_of(b + S_UNC, 90) : Py_NewRef(Py_None),
            PyLong_FromDouble(b[S_N] + b[S_MARK] - b[S_CD]),
            PyFloat_FromDouble(b[S_TSTART]),
            PyFloat_FromDouble(tb),
            PyBool_FromLong(b[S_VALID] != 0.0)};
        int bad = 0;
        for (int i = 0; i < 6; i++) {
            if (items[i] == NULL)
                bad = 1;
            else
                PyTuple_SET_ITEM(rec, i, items[i]);      /* the tuple owns it */
        }
        int err = bad ? -1 : PyList_Append(out, rec);
        Py_DECREF(rec);                                  /* NULL slots are skipped by the deallocator */
        if (err < 0)
            return -1;
    }
    double k = b[S_K] + 1.0, next;
    if (b[S_MODE] == 2.0)
        next = k < (double)ntimes ? times[(Py_ssize_t)k] : INFINITY;
    else
        next = b[S_ORIGIN] + k / b[S_RATE];
    b[S_K] = k;
    b[S_NEXT] = next;
    b[S_ACTIVE] = next != INFINITY ? 1.0 : 0.0;
    b[S_LIM] = next != INFINITY ? next - b[S_TOL] : -INFINITY;
    memset(b + S_DELTAS, 0, (S_PREV - S_DELTAS) * sizeof(double));
    b[S_DELTAS + 1] = 1.0;                              /* identity quaternion */
    b[S_N] = 0.0;
    b[S_MARK] = b[S_CD];
    b[S_TSTART] = tb;
    b[S_VALID] = 1.0;
    return 0;
}

/* The sample (t, w, a) crossing one or more boundaries without a gap (_push_slow of preint_stream.py
 * for rate / frame_times boundaries); returns the list of finished frames, NULL on error. */
static PyObject *cross_boundaries(double *b, const double *times, Py_ssize_t ntimes, double t, const double *w,
                                  const double *a)
{
    const double *bias = b + S_BIAS;
    double *prev = b + S_PREV, tol = b[S_TOL];
    double t0 = prev[0], h = t - t0, pv[6], k1[6], k0[6], kb[6];
    for (int i = 0; i < 3; i++) {
        k1[i] = w[i] - bias[i];
        k1[3 + i] = a[i] - bias[3 + i];
    }
    memcpy(pv, prev + 1, sizeof pv);
    memcpy(k0, pv, sizeof k0);
    prev[0] = t;
    memcpy(prev + 1, k1, sizeof k1);
    PyObject *out = PyList_New(0);
    if (out == NULL)
        return NULL;
    double tk = t0;
    while (b[S_NEXT] < t - tol) {
        double tb = b[S_NEXT];
        if (b[S_MIDPOINT] != 0.0) {
            double wgt = (tb - t0) / h;
            for (int i = 0; i < 6; i++)
                kb[i] = pv[i] + (k1[i] - pv[i]) * wgt;
        } else {
            memcpy(kb, k0, sizeof kb);
        }
        if (b[S_ACTIVE] != 0.0)
            piece(b, tb - tk, k0, kb);
        if (cross(b, times, ntimes, tb, out) < 0) {
            Py_DECREF(out);
            return NULL;
        }
        tk = tb;
        memcpy(k0, kb, sizeof k0);
    }
    if (b[S_ACTIVE] != 0.0)
        piece(b, t - tk, k0, k1);
    if (fabs(b[S_NEXT] - t) <= tol && cross(b, times, ntimes, b[S_NEXT], out) < 0) {
        Py_DECREF(out);
        return NULL;
    }
    return out;
}

static PyObject *py_push(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 5, 5, "push", "state, times, t, gyro, accel"))
        return NULL;
    double t = PyFloat_AsDouble(args[2]), w[3], a[3];
    if (t == -1.0 && PyErr_Occurred()) {
        PyErr_Clear();
        Py_RETURN_FALSE;
    }
    Py_buffer st;
    if (get_state(args[0], &st) < 0)
        return NULL;
    double *b = (double *)st.buf, *prev = b + S_PREV;
    double h = t - prev[0];
    PyObject *res = Py_False;
    if (t < b[S_LIM]) {                     /* the fast path of StreamingPreintegrator.push */
        double cd = b[S_CD] - 1.0;
        if (0.0 < h && h <= b[S_MAXGAP] && cd != 0.0 && three(args[3], w) && three(args[4], a)) {
            const double *bias = b + S_BIAS;
            b[S_CD] = cd;
            double wx = w[0] - bias[0], wy = w[1] - bias[1], wz = w[2] - bias[2];
            double ax = a[0] - bias[3], ay = a[1] - bias[4], az = a[2] - bias[5];
            double gx = prev[1], gy = prev[2], gz = prev[3], fx = prev[4], fy = prev[5], fz = prev[6];
            prev[0] = t; prev[1] = wx; prev[2] = wy; prev[3] = wz; prev[4] = ax; prev[5] = ay; prev[6] = az;
            double *u = b[S_UNCERTAINTY] != 0.0 ? b + S_UNC : NULL;
            if (b[S_MIDPOINT] != 0.0) {
                double hh = 0.5 * h;
                integrate(b + S_DELTAS, u, h, (gx + wx) * hh, (gy + wy) * hh, (gz + wz) * hh,
                          (fx + ax) * hh, (fy + ay) * hh, (fz + az) * hh, b[S_NOISE], b[S_NOISE + 1]);
            } else {
                integrate(b + S_DELTAS, u, h, gx * h, gy * h, gz * h, fx * h, fy * h, fz * h,
                          b[S_NOISE], b[S_NOISE + 1]);
            }
            res = Py_True;
        }
    } else if (b[S_MODE] != 0.0 && b[S_ACTIVE] != 0.0 && 0.0 < h && h <= b[S_MAXGAP] &&
               three(args[3], w) && three(args[4], a)) {   /* boundaries inside (t0, t], no gap */
        Py_buffer tv;
        const double *times = NULL;
        Py_ssize_t ntimes = 0;
        int have_tv = 0;
        if (b[S_MODE] == 2.0) {
            if (ig_get_buffer(args[1], &tv, "times", -1, 0, 'd') < 0) {
                PyBuffer_Release(&st);
                return NULL;
            }
            have_tv = 1;
            times = (const double *)tv.buf;
            ntimes = tv.len / (Py_ssize_t)sizeof(double);
        }
        res = cross_boundaries(b, times, ntimes, t, w, a);
        if (have_tv)
            PyBuffer_Release(&tv);
        if (res == NULL) {
            PyBuffer_Release(&st);
            return NULL;
        }
        PyBuffer_Release(&st);
        return res;
    }
    PyBuffer_Release(&st);
    Py_INCREF(res);
    return res;
}

static PyMethodDef methods[] = {
    {"integrate_interval", IG_FASTCALL(py_integrate_interval), METH_FASTCALL,
     "integrate_interval(s, u, dt, x, y, z, fx, fy, fz, noise) -> (s, u): preint_kernel.integrate_interval in C."},
    {"integrate", IG_FASTCALL(py_integrate), METH_FASTCALL,
     "integrate(state, dt, x, y, z, fx, fy, fz): one interval on a streaming state buffer, in place."},
    {"push", IG_FASTCALL(py_push), METH_FASTCALL,
     "push(state, times, t, gyro, accel) -> True, frames or False: StreamingPreintegrator.push (False: the "
     "Python slow path's)."},
    {NULL, NULL, 0, NULL}};

PyMODINIT_FUNC PyInit__preint_native(void)
{
    static struct PyModuleDef def = {.m_base = PyModuleDef_HEAD_INIT, .m_name = "_preint_native", .m_size = -1,
        .m_methods = methods, .m_doc = "C twin of the preintegration kernel and of the streaming fast path (see"
                                       " imu_ground.imu.preint_kernel)."};
    return ig_module_create(&def, "STATE_SIZE", S_SIZE);
}
