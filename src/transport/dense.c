/* Dense F storage in float or double, row-major; every sum accumulates in double.
 * Memory-bandwidth bound: one pass over F serves all three channels. */
#include "bounce/transport.h"
#include "transport/storage.h"
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

static bn_status bn__dense_row(void *ctx, size_t i, const double *x, double out[3], bn_error *err)
{
    const bn__dense *d = ctx;
    (void)err;
    if (d->prec == BN_PRECISION_FLOAT)
        bn__row_inter_float((const float *)d->data + i * d->n, d->n, x, out);
    else
        bn__row_inter_double((const double *)d->data + i * d->n, d->n, x, out);
    return BN_OK;
}

/* Below this size a parallel region costs more than the product (and oversubscribed machines
 * make it far worse). */
#define BN__DENSE_PARALLEL_MIN 256

static bn_status bn__dense_apply(void *ctx, const double *x, double *y, bn_error *err)
{
    const bn__dense *d = ctx;
    long n = (long)d->n;
    double *xp = bn__malloc_array(3 * d->n, sizeof(double));
    if (!xp) {
        /* No room for the planar copy: the interleaved kernel gives the same sums. */
#pragma omp parallel for schedule(static) if (n >= BN__DENSE_PARALLEL_MIN)
        for (long i = 0; i < n; i++)
            bn__dense_row(ctx, (size_t)i, x, y + 3 * i, err);
        return BN_OK;
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
    return BN_OK;
}

static double bn__dense_get(const bn__dense *d, size_t k)
{
    return d->prec == BN_PRECISION_FLOAT ? (double)((const float *)d->data)[k] : ((const double *)d->data)[k];
}

static bn_status bn__dense_entry(void *ctx, size_t i, size_t j, double *v, bn_error *err)
{
    const bn__dense *d = ctx;
    (void)err;
    *v = bn__dense_get(d, i * d->n + j);
    return BN_OK;
}

/* A dense row stores every column. */
static bn_status bn__dense_row_entries(void *ctx, size_t i, size_t *cols, double *vals, size_t *count, bn_error *err)
{
    const bn__dense *d = ctx;
    (void)err;
    for (size_t j = 0; j < d->n; j++) {
        cols[j] = j;
        vals[j] = bn__dense_get(d, i * d->n + j);
    }
    *count = d->n;
    return BN_OK;
}

static bn_status bn__dense_diag(void *ctx, double *out, bn_error *err)
{
    const bn__dense *d = ctx;
    (void)err;
    for (size_t i = 0; i < d->n; i++)
        out[i] = bn__dense_get(d, i * d->n + i);
    return BN_OK;
}

static size_t bn__dense_bytes_for(size_t n, size_t nnz, bn_precision prec)
{
    size_t nn, b;
    (void)nnz;
    if (!bn__mul_size(n, n, &nn) || !bn__mul_size(nn, prec == BN_PRECISION_FLOAT ? sizeof(float) : sizeof(double), &b))
        return SIZE_MAX;
    return b;
}

static size_t bn__dense_bytes(const void *ctx)
{
    const bn__dense *d = ctx;
    return bn__dense_bytes_for(d->n, 0, d->prec);
}

static void bn__dense_destroy(void *ctx)
{
    bn__dense *d = ctx;
    if (d) {
        free(d->data);
        free(d);
    }
}

#define BN__DENSE_CAPS (BN_OP_ROWS | BN_OP_ENTRIES | BN_OP_DIAG)
static const bn_transport_ops bn__dense_float_ops = {
    "dense-float", BN__DENSE_CAPS, bn__dense_apply, bn__dense_row, bn__dense_entry, bn__dense_row_entries,
    bn__dense_diag, bn__dense_bytes, bn__dense_destroy, NULL};
static const bn_transport_ops bn__dense_double_ops = {
    "dense-double", BN__DENSE_CAPS, bn__dense_apply, bn__dense_row, bn__dense_entry, bn__dense_row_entries,
    bn__dense_diag, bn__dense_bytes, bn__dense_destroy, NULL};

/* ---- the storage: zeroed N^2, filled in place ---- */

static bn_status bn__dense_begin(size_t n, bn_precision prec, const size_t *counts, void **sink, bn_error *err)
{
    size_t nn, bytes = bn__dense_bytes_for(n, 0, prec);
    bn__dense *d;
    (void)counts;
    *sink = NULL;
    if (bytes == SIZE_MAX || !bn__mul_size(n, n, &nn))
        return bn_error_set(err, BN_ENOMEM, "dense F for %zu patches overflows size_t", n);
    d = calloc(1, sizeof *d);
    if (d)
        d->data = calloc(nn ? nn : 1, prec == BN_PRECISION_FLOAT ? sizeof(float) : sizeof(double));
    if (!d || !d->data) {
        free(d);
        return bn_error_set(err, BN_ENOMEM, "cannot allocate dense F: %zu patches need %.3g GiB", n,
                            (double)bytes / (1024.0 * 1024 * 1024));
    }
    d->n = n;
    d->prec = prec;
    *sink = d;
    return BN_OK;
}

static int bn__dense_put(void *sink, size_t i, size_t j, double v)
{
    bn__dense *d = sink;
    if (d->prec == BN_PRECISION_FLOAT)
        ((float *)d->data)[i * d->n + j] = (float)v;
    else
        ((double *)d->data)[i * d->n + j] = v;
    return 1;
}

static bn_status bn__dense_finish(void *sink, double drop_below, bn_builder_report *rep, const bn_transport_ops **ops,
                                  void **ctx, bn_error *err)
{
    bn__dense *d = sink;
    (void)drop_below;   /* dense keeps every entry */
    (void)rep;
    (void)err;
    *ops = d->prec == BN_PRECISION_FLOAT ? &bn__dense_float_ops : &bn__dense_double_ops;
    *ctx = d;
    return BN_OK;
}

const bn__storage bn__storage_dense = {"dense", 0, bn__dense_bytes_for, bn__dense_begin, NULL,
                                       bn__dense_put, bn__dense_finish, bn__dense_destroy};
