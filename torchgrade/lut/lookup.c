/* Tetrahedral and trilinear interpolation of a 3D LUT on the CPU, one pass per pixel: the CPU kernel of the operator
 * torchgrade::lut_lookup (torchgrade/lut/operator.py), built with the package as the extension module
 * torchgrade.lut._lookup (setup.py) and called on whole frames.
 *
 * For each pixel i of the planar input (r, g, b), as the operator's torch form (torchgrade.lut.operator) computes it:
 *     x = NaN -> 0, clamped to +-65504                          (torchgrade.base.images.sanitize)
 *     u = clamp((x - low) * scale, 0, size - 1)                 (the lattice coordinate, per channel; the caller
 *                                                              gives scale = (size - 1) / span: a product, not a division)
 *     corner = min(floor(u), size - 2), f = u - corner          (the cell and the fractions)
 * then, tetrahedral (torchgrade.lut.kernels.tetrahedral):
 *     y = c000 + f_a (v1 - c000) + f_b (v2 - v1) + f_c (c111 - v2)
 * where f_a >= f_b >= f_c are the sorted fractions, v1 is a step from c000 along the axis of f_a and v2 is c111
 * less a step along the axis of f_c (red before green before blue on ties): the six tetrahedra of Kasson, Nin and
 * Plouffe (1995), as OpenColorIO picks them; or trilinear (torchgrade.lut.kernels.trilinear): lerps along red, then
 * green, then blue over the cell's 8 corners. The table is the LUT's own (S, S, S, 3) [b, g, r, channel] tensor,
 * table[3 * (r + size * g + size^2 * b) + channel], so a vertex is one 12-byte read; indices are 32-bit (the caller
 * keeps 3 size^3 below 2^31). The loops have no branches, so compilers vectorise them (gathers on AVX2); GCC 12
 * vectorises them only with each select a statement of its own.
 *
 * Built with OpenMP where the compiler has it: the extension then needs libgomp.so.1, which torch's CPU build has
 * loaded already (torch/lib/libgomp.so.1, the same soname), so the dynamic loader binds it to torch's runtime and the
 * chunks run on torch's own intra-op threads. On x86-64 each run is compiled twice, for AVX2 and for the baseline,
 * and the processor picks one when the module loads (GCC's and Clang's target_clones): one wheel for every x86-64
 * machine, never -march=native. No -ffast-math: NaN and rounding behave as in torch. */

#define PY_SSIZE_T_CLEAN
#define Py_LIMITED_API 0x030A0000
#include <Python.h>
#include <stdint.h>

#define HALF_MAX 65504.0

/* The cell and fractions of pixel i (the formula above), for the loops below. */
#define CELL(T)                                                                                                        \
    T r = in_r[i], g = in_g[i], b = in_b[i];                                                                           \
    r = r == r ? r : 0; g = g == g ? g : 0; b = b == b ? b : 0;                                                        \
    r = r > -half_max ? r : -half_max; g = g > -half_max ? g : -half_max; b = b > -half_max ? b : -half_max;           \
    r = r < half_max ? r : half_max; g = g < half_max ? g : half_max; b = b < half_max ? b : half_max;                 \
    r = (r - low_r) * scale_r; g = (g - low_g) * scale_g; b = (b - low_b) * scale_b;                                   \
    r = r > 0 ? r : 0; g = g > 0 ? g : 0; b = b > 0 ? b : 0;                                                           \
    r = r < top ? r : top; g = g < top ? g : top; b = b < top ? b : top;                                               \
    int32_t ir = (int32_t)r, ig = (int32_t)g, ib = (int32_t)b;                                                         \
    ir = ir < last ? ir : last; ig = ig < last ? ig : last; ib = ib < last ? ib : last;                                \
    const T fr = r - (T)ir, fg = g - (T)ig, fb = b - (T)ib;                                                            \
    const int32_t c000 = ir + size * ig + plane * ib;

/* The tetrahedron's four vertices and its value at pixel i. */
#define TETRAHEDRON(T)                                                                                                 \
    const int32_t rg = fr >= fg, gb = fg >= fb, rb = fr >= fb;                                                         \
    const int32_t r_first = rg & rb, g_first = (1 - rg) & gb, b_first = 1 - r_first - g_first;                         \
    const int32_t r_last = (1 - rg) & (1 - rb), g_last = rg & (1 - gb), b_last = 1 - r_last - g_last;                  \
    const int32_t c111 = c000 + 1 + size + plane;                                                                      \
    const int32_t v1 = c000 + r_first + size * g_first + plane * b_first;                                              \
    const int32_t v2 = c111 - (r_last + size * g_last + plane * b_last);                                               \
    T high = fr > fg ? fr : fg, middle = fr > fg ? fg : fr;                                                            \
    const T f_a = high > fb ? high : fb, f_c = middle < fb ? middle : fb;                                              \
    T f_b = middle > fb ? middle : fb;                                                                                 \
    f_b = high < f_b ? high : f_b;                                                                                     \
    const int32_t a = 3 * c000, e = 3 * v1, f = 3 * v2, h = 3 * c111;                                                  \
    out_r[i] = table[a] + f_a * (table[e] - table[a]) + f_b * (table[f] - table[e]) + f_c * (table[h] - table[f]);     \
    out_g[i] = table[a + 1] + f_a * (table[e + 1] - table[a + 1]) + f_b * (table[f + 1] - table[e + 1])                \
               + f_c * (table[h + 1] - table[f + 1]);                                                                  \
    out_b[i] = table[a + 2] + f_a * (table[e + 2] - table[a + 2]) + f_b * (table[f + 2] - table[e + 2])                \
               + f_c * (table[h + 2] - table[f + 2]);

/* Lerps along red (table offset 3), green (3 size) and blue (3 size^2) from corner offset o, channel k. */
#define LERP_R(o, k) (table[o + k] + fr * (table[o + 3 + k] - table[o + k]))
#define LERP_G(o, k) (LERP_R(o, k) + fg * (LERP_R(o + 3 * size, k) - LERP_R(o, k)))
#define LERP_B(o, k) (LERP_G(o, k) + fb * (LERP_G(o + 3 * plane, k) - LERP_G(o, k)))
#define CUBE(T)                                                                                                        \
    const int32_t o = 3 * c000;                                                                                        \
    out_r[i] = LERP_B(o, 0); out_g[i] = LERP_B(o, 1); out_b[i] = LERP_B(o, 2);

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(__APPLE__)
#define CLONES __attribute__((target_clones("avx2", "default")))
#else
#define CLONES
#endif

/* Pixels [begin, end) of one frame through INTERPOLATE (a statement of the cell); its own function, so the loop
 * vectorises. */
#define RUN(NAME, T, INTERPOLATE)                                                                                      \
CLONES static void NAME(const T *restrict in_r, const T *restrict in_g, const T *restrict in_b, int64_t begin, int64_t end,   \
                 const T *restrict low, const T *restrict scale, const T *restrict table, int32_t size,                \
                 T *restrict out_r, T *restrict out_g, T *restrict out_b) {                                            \
    const T top = (T)(size - 1), half_max = (T)HALF_MAX;                                                               \
    const T low_r = low[0], low_g = low[1], low_b = low[2], scale_r = scale[0], scale_g = scale[1], scale_b = scale[2];\
    const int32_t plane = size * size, last = size - 2;                                                                \
    for (int64_t i = begin; i < end; ++i) {                                                                            \
        CELL(T)                                                                                                        \
        INTERPOLATE(T)                                                                                                 \
    }                                                                                                                  \
}

/* frames planar frames of n pixels (each channel's pixels contiguous; channel and frame strides in elements), in
 * chunks of `chunk` pixels taken by `threads` OpenMP threads as each comes free (torch's own OpenMP runtime, whose
 * threads a torch operation just before has ready). */
#define FRAMES(NAME, RUN_NAME, T)                                                                                      \
static void NAME(const T *in, int64_t in_frame, int64_t in_channel, T *out, int64_t out_frame, int64_t out_channel,    \
                 int64_t frames, int64_t n, const T *low, const T *scale, const T *table, int32_t size, int64_t chunk, \
                 int32_t threads) {                                                                                    \
    const int64_t per_frame = (n + chunk - 1) / chunk, chunks = frames * per_frame;                                    \
    _Pragma("omp parallel for schedule(dynamic, 1) num_threads(threads) if(threads > 1 && chunks > 1)")                \
    for (int64_t k = 0; k < chunks; ++k) {                                                                             \
        const int64_t frame = k / per_frame, begin = (k % per_frame) * chunk;                                          \
        const int64_t end = begin + chunk < n ? begin + chunk : n;                                                     \
        const T *x = in + frame * in_frame;                                                                            \
        T *y = out + frame * out_frame;                                                                                \
        RUN_NAME(x, x + in_channel, x + 2 * in_channel, begin, end, low, scale, table, size, y, y + out_channel,       \
                 y + 2 * out_channel);                                                                                 \
    }                                                                                                                  \
}

RUN(tetrahedral_run_float, float, TETRAHEDRON)
RUN(tetrahedral_run_double, double, TETRAHEDRON)
RUN(trilinear_run_float, float, CUBE)
RUN(trilinear_run_double, double, CUBE)
FRAMES(tetrahedral_float, tetrahedral_run_float, float)
FRAMES(tetrahedral_double, tetrahedral_run_double, double)
FRAMES(trilinear_float, trilinear_run_float, float)
FRAMES(trilinear_double, trilinear_run_double, double)

/* interpolate(kind, in, in_frame, in_channel, out, out_frame, out_channel, frames, n, low, scale, table, size, chunk,
 * threads): the loop of `kind` (0: tetrahedral float32, 1: tetrahedral float64, 2: trilinear float32, 3: trilinear
 * float64) over frames at the addresses given (tensors' data_ptr(); strides in elements), without the GIL. Nothing is
 * checked here: torchgrade.lut.operator passes tensors it made and checked. */
static PyObject *interpolate(PyObject *self, PyObject *args) {
    int kind, size, threads;
    unsigned long long in, out, low, scale, table;
    long long in_frame, in_channel, out_frame, out_channel, frames, n, chunk;
    if (!PyArg_ParseTuple(args, "iKLLKLLLLKKKiLi", &kind, &in, &in_frame, &in_channel, &out, &out_frame, &out_channel,
                          &frames, &n, &low, &scale, &table, &size, &chunk, &threads))
        return NULL;
    if (kind < 0 || kind > 3 || chunk < 1) {
        PyErr_SetString(PyExc_ValueError, "interpolate: kind must be 0 to 3 and chunk positive");
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    switch (kind) {
    case 0:
        tetrahedral_float((const float *)in, in_frame, in_channel, (float *)out, out_frame, out_channel, frames, n,
                          (const float *)low, (const float *)scale, (const float *)table, size, chunk, threads);
        break;
    case 1:
        tetrahedral_double((const double *)in, in_frame, in_channel, (double *)out, out_frame, out_channel, frames, n,
                           (const double *)low, (const double *)scale, (const double *)table, size, chunk, threads);
        break;
    case 2:
        trilinear_float((const float *)in, in_frame, in_channel, (float *)out, out_frame, out_channel, frames, n,
                        (const float *)low, (const float *)scale, (const float *)table, size, chunk, threads);
        break;
    default:
        trilinear_double((const double *)in, in_frame, in_channel, (double *)out, out_frame, out_channel, frames, n,
                         (const double *)low, (const double *)scale, (const double *)table, size, chunk, threads);
    }
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"interpolate", interpolate, METH_VARARGS, "Interpolate a packed 3D LUT at planar frames (see lookup.c)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_lookup", "The CPU loops of torchgrade::lut_lookup.", -1, methods};

PyMODINIT_FUNC PyInit__lookup(void) { return PyModule_Create(&module); }
