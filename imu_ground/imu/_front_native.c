/*
 * C twin of the live front end's per-sample steady state (imu_ground.pipeline.streaming,
 * StreamingEstimator.push_imu): one call per IMU sample does the sample clock's retiming
 * (imu_ground.imu.sample_clock.SampleClock.push, after its warm-up), the sum of the sample into
 * its standstill block (imu_ground.imu.causal_standstill.StandstillBlocks.add) and the
 * preintegration step (the compiled StreamingPreintegrator.push of _preint_native, called from
 * here). The Python code is the reference (the twin rule of imu_ground._native): every case
 * this kernel does not take, it leaves untouched and says so (None), and the Python path runs.
 *
 * Front state buffer (doubles, offsets F_*): the clock's state and settings, the frames' origin
 * and rate, and the index of the open block (the block of the last sample summed; NaN: none).
 * Its Python twin: SampleClock.to_buffer / from_buffer and StreamingEstimator._front_out.
 *
 * Arithmetic is the Python formulas term for term in the same order (compiled with
 * -ffp-contract=off), so the two paths agree bit for bit.
 */
#include "_native_util.h"

enum {
    F_T, F_DT, F_RAW_MAX, F_RAW_PREV, F_PENDING, F_PMIN, F_HOLD, F_GAP_FACTOR, F_ALPHA, F_BETA, F_DROP_POLICY,
    F_RETIMED, F_DROPPED, F_DROPOUTS, F_ORIGIN, F_RATE, F_OPEN_K, F_SIZE
};

#define BLOCK_SIZE 13
/* causal_standstill._EDGE: a sample this close (in frames) to a boundary ends the frame before it. */
#define EDGE 1e-6

/* Three exact Python floats of a list or tuple into out; 0 for anything else (the Python path's case). */
static int three_floats(PyObject *o, double *out)
{
    if (!(PyList_CheckExact(o) || PyTuple_CheckExact(o)) || PySequence_Fast_GET_SIZE(o) != 3)
        return 0;
    PyObject **items = PySequence_Fast_ITEMS(o);
    for (int i = 0; i < 3; i++) {
        if (!PyFloat_CheckExact(items[i]))
            return 0;
        out[i] = PyFloat_AS_DOUBLE(items[i]);
    }
    return 1;
}

/*
 * push(front, block, pre_push, pre_state, pre_times, t, gyro, accel)
 *   front: the front state buffer (F_SIZE doubles, writable);
 *   block: the open block's sums (13 doubles, writable) or None;
 *   pre_push, pre_state, pre_times: _preint_native.push and its state and times buffers.
 * Returns None (not taken: nothing changed), an int (the sample opens this block: nothing changed, the
 * caller opens it and calls again), False (the clock dropped the sample), True (taken, no frame
 * finished), the list _preint_native.push returns (finished frames' states), or the sample's time out
 * of the clock as a float (clock and block done; the preintegrator's Python push still to run).
 */
static PyObject *py_push(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 8, 8, "push", "front, block, pre_push, pre_state, pre_times, t, gyro, accel"))
        return NULL;
    double w[3], f[3];
    if (!PyFloat_CheckExact(args[5]) || !three_floats(args[6], w) || !three_floats(args[7], f))
        Py_RETURN_NONE;
    const double t = PyFloat_AS_DOUBLE(args[5]);
    if (!isfinite(t) || !isfinite(w[0] + w[1] + w[2] + f[0] + f[1] + f[2]))
        Py_RETURN_NONE;
    Py_buffer fv;
    if (ig_get_buffer(args[0], &fv, "front", F_SIZE, 1, 'd') < 0)
        return NULL;
    double *b = (double *)fv.buf;
    const double dt = b[F_DT];
    if (isnan(dt)) {                                    /* the clock's warm-up: Python */
        PyBuffer_Release(&fv);
        Py_RETURN_NONE;
    }
    /* SampleClock.push after the warm-up, into locals first */
    double out = b[F_T], prev = b[F_RAW_PREV], raw_max = b[F_RAW_MAX], pending = b[F_PENDING], pmin = b[F_PMIN];
    double new_dt = dt;
    int retimed = 0, dropouts = 0;
    if (t < prev - b[F_GAP_FACTOR] * dt) {             /* a restart: Python */
        PyBuffer_Release(&fv);
        Py_RETURN_NONE;
    }
    if (t > raw_max) {
        raw_max = t;
    } else if (b[F_DROP_POLICY] != 0.0) {
        b[F_RAW_PREV] = t;
        b[F_DROPPED] += 1.0;
        PyBuffer_Release(&fv);
        Py_RETURN_FALSE;
    }
    double e = t - (out + dt);
    if (e > 0.5 * dt) {
        if (e > b[F_HOLD]) {                            /* far ahead: a dropout at once, or a restart
                                                           (SampleClock.max_jump): Python */
            PyBuffer_Release(&fv);
            Py_RETURN_NONE;
        } else {
            if (isnan(pending)) {
                pending = out;
                pmin = e;
            } else if (e < pmin) {
                pmin = e;
            }
            if (out + dt - pending >= b[F_HOLD]) {      /* ahead for hold seconds: a dropout */
                out = out + dt + pmin;
                pending = NAN;
                dropouts = 1;
            } else {
                out = out + dt;
                retimed = 1;
            }
        }
    } else {
        pending = NAN;
        if (e < -0.5 * dt) {
            e = -0.5 * dt;
            retimed = 1;
        }
        out = out + dt + b[F_ALPHA] * e;
        new_dt = dt + b[F_BETA] * e;
    }
    /* the block of the sample (causal_standstill.block_index): only the open one is summed here */
    const double k = ceil((out - b[F_ORIGIN]) * b[F_RATE] - EDGE) - 1.0;
    Py_buffer bv;
    double *blk = NULL;
    if (!(fabs(k) < 4503599627370496.0)) {             /* |k| >= 2^52 (or NaN): not exact as a double, Python */
        PyBuffer_Release(&fv);
        Py_RETURN_NONE;
    }
    if (k >= 0.0) {
        if (!(k == b[F_OPEN_K]) || args[1] == Py_None) {   /* a new block: the caller opens it, calls again */
            PyBuffer_Release(&fv);
            return PyLong_FromDouble(k);
        }
        if (ig_get_buffer(args[1], &bv, "block", BLOCK_SIZE, 1, 'd') < 0) {
            PyBuffer_Release(&fv);
            return NULL;
        }
        blk = (double *)bv.buf;
    }
    /* commit */
    b[F_T] = out;
    b[F_DT] = new_dt;
    b[F_RAW_PREV] = t;
    b[F_RAW_MAX] = raw_max;
    b[F_PENDING] = pending;
    b[F_PMIN] = pmin;
    b[F_RETIMED] += retimed;
    b[F_DROPOUTS] += dropouts;
    PyBuffer_Release(&fv);
    if (blk != NULL) {                                  /* StandstillBlocks.add, the same order */
        blk[0] += 1.0;
        blk[1] += w[0];
        blk[2] += w[1];
        blk[3] += w[2];
        blk[4] += f[0];
        blk[5] += f[1];
        blk[6] += f[2];
        blk[7] += w[0] * w[0];
        blk[8] += w[1] * w[1];
        blk[9] += w[2] * w[2];
        blk[10] += f[0] * f[0];
        blk[11] += f[1] * f[1];
        blk[12] += f[2] * f[2];
        PyBuffer_Release(&bv);
    }
    PyObject *tout = PyFloat_FromDouble(out);
    if (tout == NULL)
        return NULL;
    PyObject *pargs[5] = {args[3], args[4], tout, args[6], args[7]};
    PyObject *res = PyObject_Vectorcall(args[2], pargs, 5, NULL);
    if (res == Py_False) {                              /* the preintegrator's Python path */
        Py_DECREF(res);
        return tout;
    }
    Py_DECREF(tout);
    return res;
}


/* causal_standstill._passes: n samples with sums s (sum x y z, sum of squares x y z) pass the gyro's
   (first 0) or the specific force's tests (t: gyro_std_max, gyro_norm_max, accel_std_max, accel_norm_tol,
   gravity). max() as Python's: the first of the largest. */
static int passes(const double *t, double n, const double *s, int first)
{
    double m0 = s[0] / n, m1 = s[1] / n, m2 = s[2] / n, v[3], sd;
    v[0] = s[3] / n - m0 * m0;
    v[1] = s[4] / n - m1 * m1;
    v[2] = s[5] / n - m2 * m2;
    for (int i = 0; i < 3; i++)
        v[i] = sqrt(0.0 > v[i] ? 0.0 : v[i]);
    sd = v[0];
    if (v[1] > sd)
        sd = v[1];
    if (v[2] > sd)
        sd = v[2];
    double norm = sqrt(m0 * m0 + m1 * m1 + m2 * m2);
    if (first == 0)
        return norm <= t[1] && sd <= t[0];
    return sd <= t[2] && fabs(norm - t[4]) <= t[3];
}

/*
 * windows(blocks, k, W, Wb, tests) -> (bool, bool): StandstillBlocks.windows (its Python twin, the
 * reference): whether the trailing windows of W and of Wb blocks ending at block k pass, summed newest
 * block first. blocks: dict block index -> 13 doubles (n, 6 sums, 6 sums of squares); tests: the five
 * thresholds of passes(). A window of 0 blocks is not asked (False).
 */
static PyObject *py_windows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 5, 5, "windows", "blocks, k, W, Wb, tests"))
        return NULL;
    if (!PyDict_Check(args[0])) {
        PyErr_SetString(PyExc_TypeError, "windows: blocks must be a dict");
        return NULL;
    }
    long long k = PyLong_AsLongLong(args[1]);
    long W = PyLong_AsLong(args[2]), Wb = PyLong_AsLong(args[3]);
    double tests[5];
    if (PyErr_Occurred() || ig_read_floats(args[4], tests, 5, "tests") < 0)
        return NULL;
    long top = W > Wb ? W : Wb;
    int rw = 0, rwb = 0;
    double n = 0.0, g[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0}, a[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    for (long i = 0; i < top; i++) {
        long long kk = k - i;
        if (kk < 0)
            break;
        PyObject *key = PyLong_FromLongLong(kk);
        if (key == NULL)
            return NULL;
        PyObject *blk = PyDict_GetItemWithError(args[0], key);      /* borrowed */
        Py_DECREF(key);
        if (blk == NULL) {
            if (PyErr_Occurred())
                return NULL;
            break;
        }
        Py_buffer bv;
        if (ig_get_buffer(blk, &bv, "block", BLOCK_SIZE, 0, 'd') < 0)
            return NULL;
        const double *b = (const double *)bv.buf;
        if (b[0] == 0.0) {
            PyBuffer_Release(&bv);
            break;
        }
        n += b[0];
        for (int c = 0; c < 3; c++) {
            g[c] = g[c] + b[1 + c];
            g[3 + c] = g[3 + c] + b[7 + c];
            a[c] = a[c] + b[4 + c];
            a[3 + c] = a[3 + c] + b[10 + c];
        }
        PyBuffer_Release(&bv);
        long m = i + 1;
        if (m == W || m == Wb) {
            int ok = passes(tests, n, g, 0) && passes(tests, n, a, 3);
            if (m == W)
                rw = ok;
            if (m == Wb)
                rwb = ok;
        }
    }
    return Py_BuildValue("(OO)", rw ? Py_True : Py_False, rwb ? Py_True : Py_False);
}

static PyMethodDef methods[] = {
    {"push", IG_FASTCALL(py_push), METH_FASTCALL,
     "push(front, block, pre_push, pre_state, pre_times, t, gyro, accel) -> None, False, True, frames or t_out: "
     "one sample of StreamingEstimator.push_imu's steady state (None: the Python path's)."},
    {"windows", IG_FASTCALL(py_windows), METH_FASTCALL,
     "windows(blocks, k, W, Wb, tests) -> (bool, bool): StandstillBlocks.windows (the Python twin)."},
    {NULL, NULL, 0, NULL}};

PyMODINIT_FUNC PyInit__front_native(void)
{
    static struct PyModuleDef def = {.m_base = PyModuleDef_HEAD_INIT, .m_name = "_front_native", .m_size = -1,
        .m_methods = methods, .m_doc = "C twin of the live front end's per-sample steady state (see"
                                       " imu_ground.pipeline.streaming)."};
    return ig_module_create(&def, "STATE_SIZE", F_SIZE);
}
