/* Numeric CSV pieces parsed straight into column arrays (imu_ground.datasets._csv_native).
 *
 * The fast path of imu_ground.datasets.csvio for plain files whose every field is a
 * decimal number: the file is cut at line ends into pieces (Python), the lines of each
 * piece are counted (count_lines), and each piece is parsed into its rows of the
 * preallocated float64 columns (parse_piece), pieces side by side on threads: both
 * functions read the file themselves (pread) and run without the GIL.
 *
 * Grammar of a field: [+-] digits [. digits] [(e|E) [+-] digits], with at least one
 * digit before the exponent; fields separated by one separator byte, lines ended by
 * "\n" or "\r\n" (the file's last line may have no end). Anything else (quotes, blank
 * fields or lines, spaces, nan/inf words, a line with another number of fields) makes
 * the call raise ValueError naming the byte offset: the caller then parses the file
 * the serial way (pandas), which owns every error message and every other case.
 *
 * Conversion is correctly rounded (as pandas' default parser and Python's float()):
 * a mantissa below 2**53 with at most 17 digits and a decimal exponent within +-22 is
 * one exact IEEE multiplication or division by an exact power of ten; every other
 * number goes to the C library's strtod (correctly rounded in glibc; used only when
 * the process's decimal point is '.', else the call raises ValueError).
 *
 * Integer fields (no '.', no exponent) are stored as doubles too; parse_piece returns
 * per column whether a non-integer field was seen (the caller gives all-integer columns
 * int64, as pandas does) and whether an integer field was too large to be sure a double
 * holds it exactly (the caller then leaves a file with such an all-integer column to
 * pandas; in a column with fractions it is a float like any other).
 */
#include "_native_util.h"

#include <errno.h>
#include <locale.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <io.h>
#else
#include <unistd.h>
#endif

/* Exact powers of ten as doubles (10**22 is the largest exactly representable). */
static const double POW10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
#define EXACT_MANTISSA ((uint64_t)1 << 53)

/* Read [start, start + n) of fd into buf (retrying short reads): 0, or -1 (errno set; -1 with errno 0: EOF). */
static int read_range(int fd, char *buf, Py_ssize_t n, long long start)
{
    Py_ssize_t got = 0;
    while (got < n) {
#ifdef _WIN32
        if (_lseeki64(fd, start + got, SEEK_SET) < 0)
            return -1;
        int r = _read(fd, buf + got, (unsigned int)(n - got > (1 << 30) ? (1 << 30) : n - got));
#else
        ssize_t r = pread(fd, buf + got, (size_t)(n - got), (off_t)(start + got));
#endif
        if (r < 0) {
            if (errno == EINTR)
                continue;
            return -1;
        }
        if (r == 0) {
            errno = 0;
            return -1;
        }
        got += r;
    }
    return 0;
}

/* The writable byte buffer `obj` (at least n + 1 bytes: the text and a sentinel) into view: 0, or -1
   with an exception set. */
static int text_buffer(PyObject *obj, Py_buffer *view, Py_ssize_t n)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_SIMPLE | PyBUF_WRITABLE) < 0)
        return -1;
    if (view->len < n + 1) {
        PyErr_Format(PyExc_ValueError, "buf holds %zd bytes, the piece %zd and a sentinel", view->len, n);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* The descriptor, byte range and text buffer of a piece (args[0..3]: fd, start, stop, buf) into
   fd, start, stop and bv: 0 with bv held (release it), or -1 with an exception set. */
static int piece_args(PyObject *const *args, int *fd, long long *start, long long *stop, Py_buffer *bv)
{
    *fd = (int)PyLong_AsLong(args[0]);
    *start = PyLong_AsLongLong(args[1]);
    *stop = PyLong_AsLongLong(args[2]);
    if (PyErr_Occurred())
        return -1;
    if (*stop < *start) {
        PyErr_Format(PyExc_ValueError, "stop %lld before start %lld", *stop, *start);
        return -1;
    }
    return text_buffer(args[3], bv, (Py_ssize_t)(*stop - *start));
}

/* The OSError of a failed read_range (err: its errno, 0 when the file ended first); NULL. */
static PyObject *read_error(int err, long long stop)
{
    if (err == 0)
        return PyErr_Format(PyExc_OSError, "the file ended before byte %lld", stop);
    errno = err;
    return PyErr_SetFromErrno(PyExc_OSError);
}

/* count_lines(fd, start, stop, buf) -> lines in the file's bytes [start, stop): its "\n"
   plus one when it does not end with "\n" (an unended last line); buf is scratch (n + 1 bytes). */
static PyObject *py_count_lines(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 4, 4, "count_lines", "fd, start, stop, buf"))
        return NULL;
    int fd;
    long long start, stop;
    Py_buffer bv;
    if (piece_args(args, &fd, &start, &stop, &bv) < 0)
        return NULL;
    const Py_ssize_t n = (Py_ssize_t)(stop - start);
    char *buf = (char *)bv.buf;
    long long lines = 0;
    int rc, err = 0;
    Py_BEGIN_ALLOW_THREADS
    rc = read_range(fd, buf, n, start);
    if (rc < 0) {
        err = errno;
    } else {
        const char *p = buf, *end = buf + n;
        while ((p = memchr(p, '\n', (size_t)(end - p))) != NULL) {
            lines++;
            p++;
        }
        if (n > 0 && buf[n - 1] != '\n')
            lines++;
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&bv);
    return rc < 0 ? read_error(err, stop) : PyLong_FromLongLong(lines);
}

/* Where one column's values go: dst[row * stride] (stride in doubles). */
typedef struct {
    double *dst;
    Py_ssize_t stride;
} column_out;

/* Outcome of a piece's parse without the GIL: 0, or the failure and the offset (in the piece) it names. */
typedef struct {
    const char *why;                /* NULL: the read failed (io_errno: its errno, 0 for an early end of file) */
    Py_ssize_t at;
    int io_errno;
} failure;

static inline int is_digit(char c) { return (unsigned char)(c - '0') < 10; }

/* Parse the rows of buf[0, n) into the columns: 0, or -1 with f filled. buf[n] must be '\0' (a sentinel
   no field can continue through, so the scanning loops need no bounds checks). */
static int parse_rows(const char *buf, Py_ssize_t n, char sep, const column_out *cols, Py_ssize_t ncols,
                      Py_ssize_t row0, Py_ssize_t nrows, unsigned char *fractional, unsigned char *inexact,
                      failure *f)
{
    const char *p = buf, *end = buf + n;
    char token[64];
    for (Py_ssize_t r = 0; r < nrows; r++) {
        const Py_ssize_t row = row0 + r;
        for (Py_ssize_t c = 0; c < ncols; c++) {
            const char *s = p;
            int neg = 0, digits = 0, exp10 = 0, frac = 0;
            uint64_t m = 0;
            if (*p == '-' || *p == '+') {
                neg = *p == '-';
                p++;
            }
            for (; is_digit(*p); p++, digits++)
                if (digits < 19)
                    m = m * 10 + (uint64_t)(*p - '0');
            if (*p == '.') {
                frac = 1;
                for (p++; is_digit(*p); p++, digits++, exp10--)
                    if (digits < 19)
                        m = m * 10 + (uint64_t)(*p - '0');
            }
            if (digits == 0) {
                f->why = "a field that is not a decimal number";
                f->at = s - buf;
                return -1;
            }
            if (*p == 'e' || *p == 'E') {
                int eneg = 0, edigits = 0, e = 0;
                frac = 1;
                p++;
                if (*p == '-' || *p == '+') {
                    eneg = *p == '-';
                    p++;
                }
                for (; is_digit(*p); p++, edigits++)
                    if (e < 100000)
                        e = e * 10 + (*p - '0');
                if (edigits == 0) {
                    f->why = "an exponent without digits";
                    f->at = s - buf;
                    return -1;
                }
                exp10 += eneg ? -e : e;
            }
            double v;
            if (digits <= 17 && m < EXACT_MANTISSA && exp10 >= -22 && exp10 <= 22) {
                v = exp10 >= 0 ? (double)m * POW10[exp10] : (double)m / POW10[-exp10];
                if (neg)
                    v = -v;
            } else {                        /* correctly rounded by the C library */
                const Py_ssize_t len = p - s;
                inexact[c] |= (unsigned char)!frac;   /* an integer a double may not hold exactly */
                char *e;
                if (len >= (Py_ssize_t)sizeof(token)) {
                    f->why = "a number longer than 63 characters";
                    f->at = s - buf;
                    return -1;
                }
                memcpy(token, s, (size_t)len);
                token[len] = '\0';
                v = strtod(token, &e);
                if (e != token + len) {
                    f->why = "a number strtod reads otherwise";
                    f->at = s - buf;
                    return -1;
                }
            }
            fractional[c] |= (unsigned char)frac;
            cols[c].dst[row * cols[c].stride] = v;
            if (c + 1 < ncols) {
                if (*p != sep) {
                    f->why = p >= end || *p == '\n' || *p == '\r' ? "a line with fewer fields than the header"
                                                                   : "a field that is not a decimal number";
                    f->at = p - buf;
                    return -1;
                }
                p++;
            } else if (p < end) {
                if (*p == '\n')
                    p++;
                else if (*p == '\r' && p + 1 < end && p[1] == '\n')
                    p += 2;
                else {
                    f->why = *p == sep ? "a line with more fields than the header"
                                       : "a field that is not a decimal number";
                    f->at = p - buf;
                    return -1;
                }
            } else if (r + 1 < nrows) {
                f->why = "fewer lines than counted";
                f->at = p - buf;
                return -1;
            }
        }
    }
    if (p != end) {
        f->why = "more lines than counted";
        f->at = p - buf;
        return -1;
    }
    return 0;
}

/* parse_piece(fd, start, stop, buf, sep, arrays, layout, row0, nrows) -> (fractional, inexact)
   The nrows lines of the file's bytes [start, stop) into rows row0 .. row0 + nrows - 1.
   arrays: tuple of C-contiguous writable float64 buffers; layout: int64 buffer of 3 values a
   column (array index, first item, stride in items): column c of row i goes to
   arrays[a][first + i * stride]. Returns two bytes objects, one byte a column: a field with a
   fraction or exponent was seen; an integer field too large to be exact in a double was seen.
   ValueError (naming the offset) for anything outside the grammar; OSError for a failed read. */
static PyObject *py_parse_piece(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!ig_check_nargs(nargs, 9, 9, "parse_piece", "fd, start, stop, buf, sep, arrays, layout, row0, nrows"))
        return NULL;
    const Py_ssize_t row0 = PyLong_AsSsize_t(args[7]), nrows = PyLong_AsSsize_t(args[8]);
    if (PyErr_Occurred())
        return NULL;
    if (!PyBytes_Check(args[4]) || PyBytes_GET_SIZE(args[4]) != 1)
        return PyErr_Format(PyExc_TypeError, "sep must be one byte");
    const char sep = PyBytes_AS_STRING(args[4])[0];
    if (sep == '\n' || sep == '\r' || sep == '.' || sep == '-' || sep == '+' || is_digit(sep) || sep == 'e' ||
        sep == 'E')
        return PyErr_Format(PyExc_ValueError, "separator %R cannot be told from a number", args[4]);
    if (!PyTuple_Check(args[5]))
        return PyErr_Format(PyExc_TypeError, "arrays must be a tuple");
    const struct lconv *lc = localeconv();
    if (lc == NULL || lc->decimal_point == NULL || strcmp(lc->decimal_point, ".") != 0)
        return PyErr_Format(PyExc_ValueError, "the C library's decimal point is not '.' (locale)");
    if (row0 < 0 || nrows < 0)
        return PyErr_Format(PyExc_ValueError, "negative rows");
    int fd;
    long long start, stop;
    Py_buffer bv, lv;
    if (piece_args(args, &fd, &start, &stop, &bv) < 0)
        return NULL;
    const Py_ssize_t n = (Py_ssize_t)(stop - start), narrays = PyTuple_GET_SIZE(args[5]);

    PyObject *result = NULL;
    Py_buffer *views = PyMem_Calloc((size_t)(narrays > 0 ? narrays : 1), sizeof(Py_buffer));
    column_out *cols = NULL;
    unsigned char *flags = NULL;
    Py_ssize_t held = 0, ncols = 0;
    int have_layout = 0;
    if (views == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    if (PyObject_GetBuffer(args[6], &lv, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        goto done;
    have_layout = 1;
    if (lv.itemsize != 8 || !(ig_is_format(lv.format, 'q') || ig_is_format(lv.format, 'l')) || lv.len % 24) {
        PyErr_SetString(PyExc_TypeError, "layout must be int64 triples");
        goto done;
    }
    ncols = lv.len / 24;
    for (; held < narrays; held++)
        if (ig_get_buffer(PyTuple_GET_ITEM(args[5], held), &views[held], "arrays[i]", -1, 1, 'd') < 0)
            goto done;
    cols = PyMem_Calloc((size_t)(ncols > 0 ? ncols : 1), sizeof(column_out));
    flags = PyMem_Calloc((size_t)(2 * ncols + 2), 1);
    if (cols == NULL || flags == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    const int64_t *lay = (const int64_t *)lv.buf;
    for (Py_ssize_t c = 0; c < ncols; c++) {
        const int64_t a = lay[3 * c], first = lay[3 * c + 1], stride = lay[3 * c + 2];
        if (a < 0 || a >= narrays || first < 0 || stride < 1) {
            PyErr_Format(PyExc_ValueError, "layout of column %zd out of range", c);
            goto done;
        }
        const Py_ssize_t items = views[a].len / 8;
        if (nrows > 0 && first + (row0 + nrows - 1) * stride >= items) {
            PyErr_Format(PyExc_ValueError, "column %zd: rows %zd..%zd do not fit its array", c, row0,
                         row0 + nrows - 1);
            goto done;
        }
        cols[c].dst = (double *)views[a].buf + first;
        cols[c].stride = (Py_ssize_t)stride;
    }
    failure f = {NULL, 0, 0};
    int rc;
    Py_BEGIN_ALLOW_THREADS
    rc = read_range(fd, (char *)bv.buf, n, start);
    if (rc < 0) {
        f.io_errno = errno;
    } else {
        ((char *)bv.buf)[n] = '\0';
        rc = parse_rows((const char *)bv.buf, n, sep, cols, ncols, row0, nrows, flags, flags + ncols, &f);
    }
    Py_END_ALLOW_THREADS
    if (rc < 0) {
        if (f.why == NULL)
            read_error(f.io_errno, stop);
        else
            PyErr_Format(PyExc_ValueError, "%s at byte %lld", f.why, start + (long long)f.at);
        goto done;
    }
    result = Py_BuildValue("(y#y#)", (const char *)flags, ncols, (const char *)flags + ncols, ncols);
done:
    while (held > 0)
        PyBuffer_Release(&views[--held]);
    PyMem_Free(views);
    PyMem_Free(cols);
    PyMem_Free(flags);
    if (have_layout)
        PyBuffer_Release(&lv);
    PyBuffer_Release(&bv);
    return result;
}

static PyMethodDef methods[] = {
    {"count_lines", IG_FASTCALL(py_count_lines), METH_FASTCALL,
     "count_lines(fd, start, stop, buf) -> int: lines in the file's bytes [start, stop) (without the GIL)."},
    {"parse_piece", IG_FASTCALL(py_parse_piece), METH_FASTCALL,
     "parse_piece(fd, start, stop, buf, sep, arrays, layout, row0, nrows) -> (fractional, inexact): numeric "
     "CSV lines into column rows (without the GIL); ValueError outside the grammar."},
    {NULL, NULL, 0, NULL}};

PyMODINIT_FUNC PyInit__csv_native(void)
{
    static struct PyModuleDef def = {.m_base = PyModuleDef_HEAD_INIT, .m_name = "_csv_native", .m_size = -1,
        .m_methods = methods, .m_doc = "Numeric CSV pieces parsed straight into column arrays (see "
                                       "imu_ground.datasets.csvio)."};
    return ig_module_create(&def, "API_VERSION", 1);
}
