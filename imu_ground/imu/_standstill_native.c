/*
 * C twin of the standstill window statistics of imu_ground/imu/standstill.py (a whole-log batch pass).
 *
 * Entry points (METH_FASTCALL), each releasing the GIL over its loop:
 *   window_sums(gyro, accel, mean, c1, c2)              WindowSums.__init__'s cumulative sums
 *   quiet_windows(t, gyro, accel, mean, window, max_gap, gyro_std_max, gyro_norm_max, accel_std_max,
 *                 quiet, norm, end)                    _standstill_mask's windows and _quiet_windows
 *   window_union(good, end, mask)                       the union of the good windows [i, end[i])
 *
 * Each is its numpy twin term for term and in the same operation order (compiled without FMA
 * contraction), so the sums, the means and norms and hence the masks equal the twin's to the bit:
 * a cumulative sum adds the centred samples one after the other as numpy.cumsum does (quiet_windows
 * carries two such running sums, at the windows' starts and ends, instead of the (6, N + 1) arrays:
 * the same values without their memory); a window's
 * end is numpy.searchsorted(t, t + window, "left") found by a forward sweep (t strictly
 * increasing, so t + window never decreases); NaN propagates as through numpy.maximum.
 * Shapes: gyro and accel (N, 3) C-contiguous float64 (rad/s, m/s^2, body frame); mean 6 doubles
 * (gyro then specific force); c1 and c2 (6, N + 1); t (N,) s; quiet and mask N flags; norm N
 * doubles (m/s^2, NaN where not computed); end N int64.
 */
#include "_native_util.h"

#include <stdint.h>

static PyObject *window_sums(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!ig_check_nargs(nargs, 5, 5, "window_sums", "gyro, accel, mean, c1, c2"))
        return NULL;
    ig_views vs = {0};
    const Py_buffer *v = ig_take(&vs, args[0], "gyro", -1, 0, 'd');
    if (!v)
        return NULL;
    const Py_ssize_t n = v->len / 24;
    const double *gyro = v->buf, *accel, *mean;
    double *c1, *c2;
    if (v->len != 24 * n || !(v = ig_take(&vs, args[1], "accel", 3 * n, 0, 'd')))
        goto fail;
    accel = v->buf;
    if (!(v = ig_take(&vs, args[2], "mean", 6, 0, 'd')))
        goto fail;
    mean = v->buf;
    if (!(v = ig_take(&vs, args[3], "c1", 6 * (n + 1), 1, 'd')))
        goto fail;
    c1 = v->buf;
    if (!(v = ig_take(&vs, args[4], "c2", 6 * (n + 1), 1, 'd')))
        goto fail;
    c2 = v->buf;
    Py_BEGIN_ALLOW_THREADS
    for (int j = 0; j < 6; j++) {          /* one component's row at a time (contiguous writes) */
        const double *x = j < 3 ? gyro + j : accel + (j - 3);
        const double m = mean[j];
        double *r1 = c1 + (n + 1) * j, *r2 = c2 + (n + 1) * j;
        double s1 = 0.0, s2 = 0.0;
        r1[0] = 0.0;
        r2[0] = 0.0;
        for (Py_ssize_t k = 0; k < n; k++) {
            const double d = x[3 * k] - m;
            s1 = s1 + d;
            s2 = s2 + d * d;
            r1[k + 1] = s1;
            r2[k + 1] = s2;
        }
    }
    Py_END_ALLOW_THREADS
    ig_release(&vs);
    Py_RETURN_NONE;
fail:
    if (!PyErr_Occurred())
        PyErr_SetString(PyExc_ValueError, "gyro must hold N x 3 doubles");
    ig_release(&vs);
    return NULL;
}

/* Running sums of the centred samples and of their squares up to (not including) sample `at`, advanced one
   sample at a time: the additions of WindowSums' cumulative sums in their order, so s1[r] equals c1[r, at]. */
typedef struct {
    Py_ssize_t at;
    double s1[6], s2[6];
} running;

static inline void advance(running *p, Py_ssize_t to, const double *gyro, const double *accel, const double *mean)
{
    for (; p->at < to; p->at++) {
        const double *g = gyro + 3 * p->at, *f = accel + 3 * p->at;
        for (int r = 0; r < 6; r++) {
            const double d = (r < 3 ? g[r] : f[r - 3]) - mean[r];
            p->s1[r] = p->s1[r] + d;
            p->s2[r] = p->s2[r] + d * d;
        }
    }
}

/* Mean (with the log's mean added back) and standard deviation of component r over the samples [a.at, e.at),
   as WindowSums.stats: count max(e - a, 1); variance max(., 0) (NaN stays NaN, as through numpy.maximum). */
static inline void stats(const running *a, const running *e, int r, const double *mean, double *m, double *std)
{
    double cnt = (double)(e->at - a->at);
    if (!(cnt >= 1.0))
        cnt = 1.0;
    const double mm = (e->s1[r] - a->s1[r]) / cnt;
    double vv = (e->s2[r] - a->s2[r]) / cnt - mm * mm;
    if (vv < 0.0)
        vv = 0.0;
    *m = mm + mean[r];
    *std = sqrt(vv);
}

static PyObject *quiet_windows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!ig_check_nargs(nargs, 12, 12, "quiet_windows", "t, gyro, accel, mean, window, max_gap, gyro_std_max, "
                        "gyro_norm_max, accel_std_max, quiet, norm, end"))
        return NULL;
    double lim[5];                         /* window, max_gap, gyro_std_max, gyro_norm_max, accel_std_max */
    for (int i = 0; i < 5; i++)
        if (ig_read_double(args[4 + i], &lim[i]) < 0)
            return NULL;
    ig_views vs = {0};
    Py_buffer endv;
    const Py_buffer *v = ig_take(&vs, args[0], "t", -1, 0, 'd');
    if (!v)
        return NULL;
    const Py_ssize_t n = v->len / 8;
    const double *t = v->buf, *gyro, *accel, *mean;
    double *norm;
    unsigned char *quiet;
    if (!(v = ig_take(&vs, args[1], "gyro", 3 * n, 0, 'd')))
        goto fail;
    gyro = v->buf;
    if (!(v = ig_take(&vs, args[2], "accel", 3 * n, 0, 'd')))
        goto fail;
    accel = v->buf;
    if (!(v = ig_take(&vs, args[3], "mean", 6, 0, 'd')))
        goto fail;
    mean = v->buf;
    if (!(v = ig_take(&vs, args[9], "quiet", n, 1, '?')))
        goto fail;
    quiet = v->buf;
    if (!(v = ig_take(&vs, args[10], "norm", n, 1, 'd')))
        goto fail;
    norm = v->buf;
    if (ig_get_int64(args[11], &endv, "end", n, 1) < 0)
        goto fail;
    int64_t *end = endv.buf;
    const double window = lim[0], max_gap = lim[1], gyro_std_max = lim[2], gyro_norm_max = lim[3],
                 accel_std_max = lim[4];
    Py_BEGIN_ALLOW_THREADS
    running lo = {0}, hi = {0};            /* the sums up to the window's start and up to its end */
    Py_ssize_t last = 0;                   /* numpy.searchsorted(t, t[i] + window, "left") */
    Py_ssize_t gap = -1;                   /* first step j >= i longer than max_gap (n - 1: none) */
    for (Py_ssize_t i = 0; i < n; i++) {
        const double until = t[i] + window;
        if (last < i)
            last = i;
        while (last < n && t[last] < until)
            last++;
        const Py_ssize_t e = last + 1 < n ? last + 1 : n;
        end[i] = (int64_t)e;
        quiet[i] = 0;
        norm[i] = NAN;
        if (gap < i) {
            gap = i;
            while (gap < n - 1 && !(t[gap + 1] - t[gap] > max_gap))
                gap++;
        }
        if (!(last < n) || gap < e - 1)    /* past the log's end, or a gap inside */
            continue;
        advance(&lo, i, gyro, accel, mean);
        advance(&hi, e, gyro, accel, mean);
        double m[3], sd[3];
        int ok = 1;
        for (int r = 0; r < 3; r++) {
            stats(&lo, &hi, r, mean, &m[r], &sd[r]);
            ok = ok && sd[r] <= gyro_std_max;
        }
        if (!(sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]) <= gyro_norm_max) || !ok)
            continue;
        int q = 1;
        for (int r = 0; r < 3; r++) {
            stats(&lo, &hi, 3 + r, mean, &m[r], &sd[r]);
            q = q && sd[r] <= accel_std_max;
        }
        quiet[i] = (unsigned char)q;
        norm[i] = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&endv);
    ig_release(&vs);
    Py_RETURN_NONE;
fail:
    ig_release(&vs);
    return NULL;
}

static PyObject *window_union(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!ig_check_nargs(nargs, 3, 3, "window_union", "good, end, mask"))
        return NULL;
    ig_views vs = {0};
    Py_buffer endv;
    const Py_buffer *v = ig_take(&vs, args[0], "good", -1, 0, '?');
    if (!v)
        return NULL;
    const Py_ssize_t n = v->len;
    const unsigned char *good = v->buf;
    if (!(v = ig_take(&vs, args[2], "mask", n, 1, '?'))) {
        ig_release(&vs);
        return NULL;
    }
    unsigned char *mask = v->buf;
    if (ig_get_int64(args[1], &endv, "end", n, 0) < 0) {
        ig_release(&vs);
        return NULL;
    }
    const int64_t *end = endv.buf;
    Py_BEGIN_ALLOW_THREADS
    int64_t cover = 0;                     /* samples before this one are covered by a good window */
    for (Py_ssize_t i = 0; i < n; i++) {
        if (good[i] && end[i] > cover)
            cover = end[i];
        mask[i] = cover > i;
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&endv);
    ig_release(&vs);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"window_sums", IG_FASTCALL(window_sums), METH_FASTCALL,
     "window_sums(gyro, accel, mean, c1, c2) -> None: WindowSums' cumulative sums of the centred samples and of\n"
     "their squares into c1 and c2 (6, N + 1)."},
    {"quiet_windows", IG_FASTCALL(quiet_windows), METH_FASTCALL,
     "quiet_windows(t, gyro, accel, mean, window, max_gap, gyro_std_max, gyro_norm_max, accel_std_max, quiet, norm,\n"
     "end) -> None: every sample's window end, whether it passes the rate and variance tests, and the norm of\n"
     "its mean specific force where the rate passes (standstill._quiet_windows)."},
    {"window_union", IG_FASTCALL(window_union), METH_FASTCALL,
     "window_union(good, end, mask) -> None: mask = union of the windows [i, end[i]) of the good samples."},
    {NULL, NULL, 0, NULL}};

PyMODINIT_FUNC PyInit__standstill_native(void)
{
    static struct PyModuleDef def = {.m_base = PyModuleDef_HEAD_INIT, .m_name = "_standstill_native", .m_size = -1,
        .m_methods = methods, .m_doc = "C twin of the standstill window statistics (see imu_ground.imu.standstill)."};
    return PyModule_Create(&def);
}
