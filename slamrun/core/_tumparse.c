/* Plain numeric tables (rows of numbers separated by single spaces) parsed exactly as strtod would, fast.

The TUM trajectory files a campaign reads are of this form. A number with at most 19 significant digits and
a decimal exponent within +-22 is converted with one correctly rounded operation on two exact doubles
(Clinger's fast path), 8 digits at a time where they come in a run; any other number goes to strtod. A text
of any other form is refused (row count -1): the caller then takes its careful path. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static const double POW10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

static const uint64_t POW10_INT[9] = {1, 10, 100, 1000, 10000, 100000, 1000000, 10000000, 100000000};

/* The number that 8 digit values (0-9, one a byte, the first in the lowest byte) write. */
static inline uint64_t eight_values(uint64_t v) {
    v = (v * 10) + (v >> 8);
    return (((v & 0x000000FF000000FFULL) * 0x000F424000000064ULL) +
            (((v >> 16) & 0x000000FF000000FFULL) * 0x0000271000000001ULL)) >> 32;
}

/* The run of digits from s appended to *mant, up to 8 at a time; *n counts them (the mantissa holds them all
   while *n <= 19). Returns the position after them. The text ends in a NUL byte, never a digit. */
static inline const char *run(const char *s, const char *end, uint64_t *mant, int *n) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    while (end - s >= 8) {
        uint64_t x;
        memcpy(&x, s, 8);
        x -= 0x3030303030303030ULL; /* digits become 0-9; a borrow only reaches bytes after a non-digit */
        uint64_t not_digit = (x | (x + 0x7676767676767676ULL)) & 0x8080808080808080ULL;
        int len = not_digit ? __builtin_ctzll(not_digit) >> 3 : 8; /* leading digits, little-endian */
        if (len == 0) return s;
        if (*n + len <= 19) *mant = *mant * POW10_INT[len] + eight_values(x << (8 * (8 - len)));
        *n += len;
        s += len;
        if (len < 8) return s;
    }
#else
    (void)end;
#endif
    for (; (unsigned)(*s - '0') < 10; s++, (*n)++)
        if (*n < 19) *mant = *mant * 10 + (uint64_t)(*s - '0');
    return s;
}

/* One number from s (before end); the position after it, or NULL when there is none. */
static const char *number(const char *s, const char *end, double *out) {
    const char *start = s;
    int neg = 0;
    if (*s == '-' || *s == '+') neg = (*s++ == '-');
    const char *first = s;
    while (*s == '0') s++; /* leading zeros: not in the mantissa's count */
    uint64_t mant = 0;
    int n = 0, exp10 = 0;
    s = run(s, end, &mant, &n);
    Py_ssize_t n_digits = s - first;
    if (*s == '.') {
        const char *frac = ++s;
        s = run(s, end, &mant, &n);
        exp10 = -(int)(s - frac);
        n_digits += s - frac;
    }
    if (n_digits == 0) return NULL;
    if (*s == 'e' || *s == 'E') {
        s++;
        int eneg = 0, e = 0;
        if (*s == '-' || *s == '+') eneg = (*s++ == '-');
        const char *edigits = s;
        for (; (unsigned)(*s - '0') < 10; s++)
            if (e < 100000) e = e * 10 + (*s - '0');
        if (s == edigits) return NULL;
        exp10 += eneg ? -e : e;
    }
    if (n <= 19 && mant <= (1ULL << 53) && exp10 >= -22 && exp10 <= 22) { /* exact operands: one rounding */
        double v = (double)mant;
        v = exp10 < 0 ? v / POW10[-exp10] : v * POW10[exp10];
        *out = neg ? -v : v;
        return s;
    }
    char buf[128];
    size_t len = (size_t)(s - start);
    if (len >= sizeof buf) return NULL;
    memcpy(buf, start, len);
    buf[len] = 0;
    *out = strtod(buf, NULL); /* correctly rounded (glibc) */
    return s;
}

/* Rows of ncols numbers separated by single spaces, each ending in '\n' (the last may not), column by column:
   number c of row r at out[c * stride + r], for at most room rows. The row count, or -1 when the text is not
   of that form. */
static Py_ssize_t table(const char *s, Py_ssize_t size, int ncols, double *out, Py_ssize_t stride,
                        Py_ssize_t room) {
    const char *end = s + size;
    Py_ssize_t rows = 0;
    while (s < end) {
        if (rows >= room) return -1;
        for (int c = 0; c < ncols; c++) {
            s = number(s, end, out + c * stride + rows);
            if (s == NULL) return -1;
            if (c < ncols - 1) {
                if (s >= end || *s != ' ') return -1;
                s++;
            }
        }
        if (s < end) {
            if (*s != '\n') return -1;
            s++;
        }
        rows++;
    }
    return rows;
}

/* parse_many(texts, ncols) -> (bytearray: ncols columns of float64, each `room` long (its length / 8 / ncols),
   holding the rows of every text of the plain form one after the other; list: each text's row count, -1 for
   one that is not of that form and was skipped) */
static PyObject *parse_many(PyObject *Py_UNUSED(self), PyObject *args) {
    PyObject *seq;
    int ncols;
    if (!PyArg_ParseTuple(args, "Oi", &seq, &ncols)) return NULL;
    if (ncols < 1) return PyErr_Format(PyExc_ValueError, "ncols must be positive, not %d", ncols);
    PyObject *fast = PySequence_Fast(seq, "texts must be a sequence of bytes");
    if (!fast) return NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(fast), cap = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *b = PySequence_Fast_GET_ITEM(fast, i);
        if (!PyBytes_Check(b)) {
            Py_DECREF(fast);
            return PyErr_Format(PyExc_TypeError, "texts[%zd]: bytes expected, not %s", i, Py_TYPE(b)->tp_name);
        }
        const char *p = PyBytes_AS_STRING(b), *e = p + PyBytes_GET_SIZE(b);
        cap += p < e && e[-1] != '\n';
        for (; (p = memchr(p, '\n', (size_t)(e - p))) != NULL; p++) cap++;
    }
    Py_ssize_t *rows = PyMem_Malloc((size_t)(n ? n : 1) * sizeof(Py_ssize_t));
    PyObject *data = PyByteArray_FromStringAndSize(NULL, cap * ncols * (Py_ssize_t)sizeof(double));
    if (!rows || !data) {
        PyMem_Free(rows);
        Py_XDECREF(data);
        Py_DECREF(fast);
        return PyErr_NoMemory();
    }
    double *out = (double *)PyByteArray_AS_STRING(data);
    Py_ssize_t used = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *b = PySequence_Fast_GET_ITEM(fast, i);
        rows[i] = table(PyBytes_AS_STRING(b), PyBytes_GET_SIZE(b), ncols, out + used, cap, cap - used);
        if (rows[i] > 0) used += rows[i];
    }
    Py_END_ALLOW_THREADS
    Py_DECREF(fast);
    PyObject *counts = PyList_New(n);
    for (Py_ssize_t i = 0; counts && i < n; i++) {
        PyObject *r = PyLong_FromSsize_t(rows[i]);
        if (!r) Py_CLEAR(counts);
        else PyList_SET_ITEM(counts, i, r);
    }
    PyMem_Free(rows);
    if (!counts) {
        Py_DECREF(data);
        return NULL;
    }
    return Py_BuildValue("(NN)", data, counts);
}

static PyMethodDef methods[] = {
    {"parse_many", parse_many, METH_VARARGS, "parse_many(texts, ncols) -> (float64 bytes, row counts)"},
    {NULL, NULL, 0, NULL}};
static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_tumparse", "Plain numeric tables, parsed fast.", -1, methods, NULL, NULL, NULL, NULL};
PyMODINIT_FUNC PyInit__tumparse(void) { return PyModule_Create(&module); }
