/* Dense F storage in float or double, row-major; every sum accumulates in double.
 * Memory-bandwidth bound: one pass over F serves all three channels. */
#include "bounce/transport.h"
#include "transport/transport_internal.h"
#include "base/internal.h"

#include <string.h>

typedef struct bn__dense {
    size_t n;
    bn_precision prec;
    void *data;   /* float or double, n*n */
} bn__dense;

/* Row kernels. Each row sum runs over BN__LANES independent partial sums (lane l takes the
 * columns j = l mod BN__LANES), added in a fixed order at the end: enough independent chains
 * to stream F at memory speed without -ffast-math, and the same order for every thread count
 * and for row access and the full product alike. */
#define BN__LANES 4

/* out[c] = sum_j r[j] x_c[j], x given as three channel planes. */
/* AVX2 where the CPU has it (chosen at run time), SSE2 otherwise. ISO C mode (-std=c17) keeps
 * floating-point contraction off, so both clones compute the very same sums. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
#define BN__CLONES __attribute__((target_clones("avx2", "default")))
#else
#define BN__CLONES
#endif

#define BN__ROW_PLANAR(T)                                                                          \
    BN__CLONES static void bn__row_planar_##T(const T *r, size_t n, const double *x0, const double *x1,       \
                                   const double *x2, double out[3])                                \
    {                                                                                              \
        double a0[BN__LANES] = {0}, a1[BN__LANES] = {0}, a2[BN__LANES] = {0};                       \
        size_t j = 0, nb = n - n % BN__LANES;                                                      \
        for (; j < nb; j += BN__LANES)                                                             \
            for (int l = 0; l < BN__LANES; l++) {                                                  \
                double f = (double)r[j + l];                                                       \
                a0[l] += f * x0[j + l];                                                            \
                a1[l] += f * x1[j + l];                                                            \
                a2[l] += f * x2[j + l];                                                            \
            }                                                                                      \
        for (int l = 0; j < n; j++, l++) {                                                         \
            double f = (double)r[j];                                                               \
            a0[l] += f * x0[j];                                                                    \
            a1[l] += f * x1[j];                                                                    \
            a2[l] += f * x2[j];                                                                    \
        }                                                                                          \
        out[0] = out[1] = out[2] = 0;                                                              \
        for (int l = 0; l < BN__LANES; l++) {                                                      \
            out[0] += a0[l];                                                                       \
            out[1] += a1[l];                                                                       \
            out[2] += a2[l];                                                                       \
        }                                                                                          \
    }
BN__ROW_PLANAR(float)
BN__ROW_PLANAR(double)

/* Four rows at once: each x value loaded serves four rows, so the product streams F instead of
 * re-reading x (GEMV row blocking). Written with vector types whose element l is lane l, so per
 * row the lanes and their order are exactly those of the one-row kernels above. */
#define BN__ROWS 4
typedef double bn__v4d __attribute__((vector_size(4 * sizeof(double))));
typedef float bn__v4f __attribute__((vector_size(4 * sizeof(float))));
/* Unaligned vector loads (memcpy keeps them free of aliasing and alignment assumptions). */
#define bn__ld4d(v, p) memcpy(&(v), (p), sizeof(bn__v4d))
#define bn__ld4_double(v, p) memcpy(&(v), (p), sizeof(bn__v4d))
#define bn__ld4_float(v, p)                                                                        \
    do {                                                                                           \
        bn__v4f bn__f4;                                                                            \
        memcpy(&bn__f4, (p), sizeof bn__f4);                                                       \
        (v) = __builtin_convertvector(bn__f4, bn__v4d);                                            \
    } while (0)

#define BN__ROW4_PLANAR(T)                                                                         \
    BN__CLONES static void bn__row4_planar_##T(const T *r, size_t n, const double *x0,             \
                                               const double *x1, const double *x2, double *y)     \
    {                                                                                              \
        bn__v4d a[BN__ROWS][3];                                                                    \
        double t[BN__LANES];                                                                       \
        size_t j = 0, nb = n - n % BN__LANES;                                                      \
        memset(a, 0, sizeof a);                                                                    \
        for (; j < nb; j += BN__LANES) {                                                           \
            bn__v4d X0, X1, X2;                                                                    \
            bn__ld4d(X0, x0 + j);                                                                  \
            bn__ld4d(X1, x1 + j);                                                                  \
            bn__ld4d(X2, x2 + j);                                                                  \
            for (int q = 0; q < BN__ROWS; q++) {                                                   \
                bn__v4d f;                                                                         \
                bn__ld4_##T(f, r + (size_t)q * n + j);                                             \
                a[q][0] += f * X0;                                                                 \
                a[q][1] += f * X1;                                                                 \
                a[q][2] += f * X2;                                                                 \
            }                                                                                      \
        }                                                                                          \
        for (int q = 0; q < BN__ROWS; q++)                                                         \
            for (int c = 0; c < 3; c++) {                                                          \
                const double *xc = c == 0 ? x0 : c == 1 ? x1 : x2;                                 \
                double sum = 0;                                                                    \
                memcpy(t, &a[q][c], sizeof t);                                                     \
                for (int l = 0; j + (size_t)l < n; l++)                                            \
                    t[l] += (double)r[(size_t)q * n + j + l] * xc[j + l];                          \
                for (int l = 0; l < BN__LANES; l++)                                                \
                    sum += t[l];                                                                   \
                y[3 * q + c] = sum;                                                                \
            }                                                                                      \
    }
BN__ROW4_PLANAR(float)
BN__ROW4_PLANAR(double)

/* The same sums with x interleaved (x[3j + c]): row access for Gauss-Seidel, whose x changes
 * between rows. Same lanes and order, so it matches the full product bit for bit. */
#define BN__ROW_INTERLEAVED(T)                                                                     \
    static void bn__row_inter_##T(const T *r, size_t n, const double *x, double out[3])            \
    {                                                                                              \
        double a0[BN__LANES] = {0}, a1[BN__LANES] = {0}, a2[BN__LANES] = {0};                       \
        size_t j = 0, nb = n - n % BN__LANES;                                                      \
        for (; j < nb; j += BN__LANES)                                                             \
            for (int l = 0; l < BN__LANES; l++) {                                                  \
                double f = (double)r[j + l];                                                       \
                a0[l] += f * x[3 * (j + l)];                                                       \
                a1[l] += f * x[3 * (j + l) + 1];                                                   \
                a2[l] += f * x[3 * (j + l) + 2];                                                   \
            }                                                                                      \
        for (int l = 0; j < n; j++, l++) {                                                         \
            double f = (double)r[j];                                                               \
            a0[l] += f * x[3 * j];                                                                 \
            a1[l] += f * x[3 * j + 1];                                                             \
            a2[l] += f * x[3 * j + 2];                                                             \
        }                                                                                          \
        out[0] = out[1] = out[2] = 0;                                                              \
        for (int l = 0; l < BN__LANES; l++) {                                                      \
            out[0] += a0[l];                                                                       \
            out[1] += a1[l];                                                                       \
            out[2] += a2[l];                                                                       \
        }                                                                                          \
    }
BN__ROW_INTERLEAVED(float)
BN__ROW_INTERLEAVED(double)

static void bn__dense_row(const void *impl, size_t i, const double *x, double out[3])
{
    const bn__dense *d = impl;
    if (d->prec == BN_PRECISION_FLOAT)
        bn__row_inter_float((const float *)d->data + i * d->n, d->n, x, out);
    else
        bn__row_inter_double((const double *)d->data + i * d->n, d->n, x, out);
}

/* Below this size a parallel region costs more than the product (and oversubscribed machines
 * make it far worse). */
#define BN__DENSE_PARALLEL_MIN 256

static void bn__dense_apply(const void *impl, const double *x, double *y)
{
    const bn__dense *d = impl;
    long n = (long)d->n;
    double *xp = bn__malloc_array(3 * d->n, sizeof(double));
    if (!xp) {
        /* No room for the planar copy: the interleaved kernel gives the same sums. */
#pragma omp parallel for schedule(static) if (n >= BN__DENSE_PARALLEL_MIN)
        for (long i = 0; i < n; i++)
            bn__dense_row(impl, (size_t)i, x, y + 3 * i);
        return;
    }
    for (long j = 0; j < n; j++) {
        xp[j] = x[3 * j];
        xp[n + j] = x[3 * j + 1];
        xp[2 * n + j] = x[3 * j + 2];
    }
    {
        long nblk = (n + BN__ROWS - 1) / BN__ROWS;
#pragma omp parallel for schedule(static) if (n >= BN__DENSE_PARALLEL_MIN)
        for (long b = 0; b < nblk; b++) {
            size_t i0 = (size_t)b * BN__ROWS, nn = d->n;
            if (i0 + BN__ROWS <= nn) {
                if (d->prec == BN_PRECISION_FLOAT)
                    bn__row4_planar_float((const float *)d->data + i0 * nn, nn, xp, xp + nn, xp + 2 * nn, y + 3 * i0);
                else
                    bn__row4_planar_double((const double *)d->data + i0 * nn, nn, xp, xp + nn, xp + 2 * nn,
                                           y + 3 * i0);
            } else {
                for (size_t i = i0; i < nn; i++) {
                    if (d->prec == BN_PRECISION_FLOAT)
                        bn__row_planar_float((const float *)d->data + i * nn, nn, xp, xp + nn, xp + 2 * nn, y + 3 * i);
                    else
                        bn__row_planar_double((const double *)d->data + i * nn, nn, xp, xp + nn, xp + 2 * nn,
                                              y + 3 * i);
                }
            }
        }
    }
    free(xp);
}

static double bn__dense_entry(const void *impl, size_t i, size_t j)
{
    const bn__dense *d = impl;
    return d->prec == BN_PRECISION_FLOAT ? (double)((const float *)d->data)[i * d->n + j]
                                         : ((const double *)d->data)[i * d->n + j];
}

static size_t bn__dense_bytes(const void *impl)
{
    const bn__dense *d = impl;
    return d->n * d->n * (d->prec == BN_PRECISION_FLOAT ? sizeof(float) : sizeof(double));
}

static void bn__dense_destroy(void *impl)
{
    bn__dense *d = impl;
    if (d) {
        free(d->data);
        free(d);
    }
}

static const bn_transport_ops bn__dense_float_ops = {"dense-float", bn__dense_apply, bn__dense_row, bn__dense_entry,
                                                     bn__dense_bytes, bn__dense_destroy};
static const bn_transport_ops bn__dense_double_ops = {"dense-double", bn__dense_apply, bn__dense_row,
                                                      bn__dense_entry, bn__dense_bytes, bn__dense_destroy};

bn_status bn__dense_alloc(size_t n, bn_precision prec, bn__dense_view *view, void **impl, const bn_transport_ops **ops,
                          bn_error *err)
{
    size_t nn, bytes;
    bn__dense *d;
    size_t elem = prec == BN_PRECISION_FLOAT ? sizeof(float) : sizeof(double);
    if (!bn__mul_size(n, n, &nn) || !bn__mul_size(nn, elem, &bytes))
        return bn_error_set(err, BN_ENOMEM, "dense F for %zu patches overflows size_t", n);
    d = calloc(1, sizeof *d);
    if (d)
        d->data = calloc(nn ? nn : 1, elem);
    if (!d || !d->data) {
        free(d);
        return bn_error_set(err, BN_ENOMEM, "cannot allocate dense F: %zu patches need %.3g GiB", n,
                            (double)bytes / (1024.0 * 1024 * 1024));
    }
    d->n = n;
    d->prec = prec;
    view->n = n;
    view->f32 = prec == BN_PRECISION_FLOAT ? d->data : NULL;
    view->f64 = prec == BN_PRECISION_DOUBLE ? d->data : NULL;
    *impl = d;
    *ops = prec == BN_PRECISION_FLOAT ? &bn__dense_float_ops : &bn__dense_double_ops;
    return BN_OK;
}

bn_status bn_transport_dense_from_array(size_t n, const double *F, const double *rho, bn_precision prec,
                                        bn_transport **out, bn_error *err)
{
    bn__dense_view v;
    void *impl;
    const bn_transport_ops *ops;
    bn_status st = bn__dense_alloc(n, prec, &v, &impl, &ops, err);
    if (st != BN_OK)
        return st;
    for (size_t i = 0; i < n * n; i++) {
        if (v.f32)
            v.f32[i] = (float)F[i];
        else
            v.f64[i] = F[i];
    }
    return bn_transport_create(n, rho, ops, impl, out, err);
}
