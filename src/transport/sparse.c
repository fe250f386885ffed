/* Sparse F in compressed sparse rows (float or double values, 32-bit columns); every sum
 * accumulates in double. Exact zeros (pairs that cannot see each other) are never stored: the
 * builder gives each row its possible columns (the pattern) before any value arrives. */
#include "bounce/transport.h"
#include "transport/storage.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

/* Row i holds columns col[rowptr[i] .. rowptr[i+1]) in increasing order, values in v32 (float)
 * or v64 (double); exactly one is set. */
typedef struct bn__csr {
    size_t n, nnz;
    bn_precision prec;
    size_t *rowptr;    /* n + 1 */
    uint32_t *col;     /* nnz */
    float *v32;
    double *v64;
} bn__csr;

static size_t bn__csr_bytes_for(size_t n, size_t nnz, bn_precision prec)
{
    size_t elem = prec == BN_PRECISION_FLOAT ? sizeof(float) : sizeof(double), a, b;
    if (!bn__mul_size(nnz, elem + sizeof(uint32_t), &a) || !bn__mul_size(n + 1, sizeof(size_t), &b))
        return SIZE_MAX;
    return a + b;
}

static void bn__csr_free(void *ctx)
{
    bn__csr *c = ctx;
    if (!c)
        return;
    free(c->rowptr);
    free(c->col);
    free(c->v32);
    free(c->v64);
    free(c);
}

/* Position of (i, j) in the value arrays, or SIZE_MAX. */
static size_t bn__csr_find(const bn__csr *c, size_t i, size_t j)
{
    size_t lo = c->rowptr[i], hi = c->rowptr[i + 1];
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (c->col[mid] < j)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < c->rowptr[i + 1] && c->col[lo] == j ? lo : SIZE_MAX;
}

static double bn__csr_value(const bn__csr *c, size_t k) { return c->v32 ? (double)c->v32[k] : c->v64[k]; }

static void bn__csr_set(bn__csr *c, size_t k, double v)
{
    if (c->v32)
        c->v32[k] = (float)v;
    else
        c->v64[k] = v;
}

/* ---- the operator ---- */

static bn_status bn__csr_row(void *ctx, size_t i, const double *x, double out[3], bn_error *err)
{
    const bn__csr *c = ctx;
    double s0 = 0, s1 = 0, s2 = 0;
    size_t b = c->rowptr[i], e = c->rowptr[i + 1];
    (void)err;
    if (c->v32) {
        for (size_t k = b; k < e; k++) {
            double f = c->v32[k];
            const double *xj = x + 3 * (size_t)c->col[k];
            s0 += f * xj[0];
            s1 += f * xj[1];
            s2 += f * xj[2];
        }
    } else {
        for (size_t k = b; k < e; k++) {
            double f = c->v64[k];
            const double *xj = x + 3 * (size_t)c->col[k];
            s0 += f * xj[0];
            s1 += f * xj[1];
            s2 += f * xj[2];
        }
    }
    out[0] = s0;
    out[1] = s1;
    out[2] = s2;
    return BN_OK;
}

static bn_status bn__csr_apply(void *ctx, const double *x, double *y, bn_error *err)
{
    const bn__csr *c = ctx;
    long n = (long)c->n;
#pragma omp parallel for schedule(static)
    for (long i = 0; i < n; i++)
        bn__csr_row(ctx, (size_t)i, x, y + 3 * i, err);
    return BN_OK;
}

static bn_status bn__csr_entry(void *ctx, size_t i, size_t j, double *v, bn_error *err)
{
    const bn__csr *c = ctx;
    size_t k = bn__csr_find(c, i, j);
    (void)err;
    *v = k == SIZE_MAX ? 0.0 : bn__csr_value(c, k);
    return BN_OK;
}

static bn_status bn__csr_row_entries(void *ctx, size_t i, size_t *cols, double *vals, size_t *count, bn_error *err)
{
    const bn__csr *c = ctx;
    size_t m = 0;
    (void)err;
    for (size_t k = c->rowptr[i]; k < c->rowptr[i + 1]; k++, m++) {
        cols[m] = c->col[k];
        vals[m] = bn__csr_value(c, k);
    }
    *count = m;
    return BN_OK;
}

static bn_status bn__csr_diag(void *ctx, double *d, bn_error *err)
{
    const bn__csr *c = ctx;
    for (size_t i = 0; i < c->n; i++)
        bn__csr_entry(ctx, i, i, &d[i], err);
    return BN_OK;
}

static size_t bn__csr_bytes(const void *ctx)
{
    const bn__csr *c = ctx;
    return bn__csr_bytes_for(c->n, c->nnz, c->prec);
}

#define BN__CSR_CAPS (BN_OP_ROWS | BN_OP_ENTRIES | BN_OP_DIAG)
static const bn_transport_ops bn__csr_float_ops = {"csr-float", BN__CSR_CAPS, bn__csr_apply, bn__csr_row,
                                                   bn__csr_entry, bn__csr_row_entries, bn__csr_diag,
                                                   bn__csr_bytes, bn__csr_free, NULL};
static const bn_transport_ops bn__csr_double_ops = {"csr-double", BN__CSR_CAPS, bn__csr_apply, bn__csr_row,
                                                    bn__csr_entry, bn__csr_row_entries, bn__csr_diag,
                                                    bn__csr_bytes, bn__csr_free, NULL};

/* ---- the storage: a pattern first, values into its slots, zeros dropped at the end ---- */

static bn_status bn__csr_begin(size_t n, bn_precision prec, const size_t *counts, void **sink, bn_error *err)
{
    bn__csr *c = calloc(1, sizeof *c);
    size_t nnz = 0;
    *sink = NULL;
    if (!c)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    c->n = n;
    c->prec = prec;
    c->rowptr = bn__malloc_array(n + 1, sizeof(size_t));
    if (!c->rowptr) {
        bn__csr_free(c);
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu CSR rows", n);
    }
    for (size_t i = 0; i < n; i++) {
        c->rowptr[i] = nnz;
        nnz += counts[i];
    }
    c->rowptr[n] = nnz;
    c->nnz = nnz;
    c->col = bn__calloc(nnz ? nnz : 1, sizeof(uint32_t));
    if (prec == BN_PRECISION_FLOAT)
        c->v32 = bn__calloc(nnz ? nnz : 1, sizeof(float));
    else
        c->v64 = bn__calloc(nnz ? nnz : 1, sizeof(double));
    if (!c->col || (!c->v32 && !c->v64)) {
        bn__csr_free(c);
        return bn_error_set(err, BN_ENOMEM, "cannot allocate sparse F: %zu patches, %zu entries need %.3g GiB", n, nnz,
                            (double)bn__csr_bytes_for(n, nnz, prec) / (1024.0 * 1024 * 1024));
    }
    *sink = c;
    return BN_OK;
}

static uint32_t *bn__csr_pattern_row(void *sink, size_t i)
{
    bn__csr *c = sink;
    return c->col + c->rowptr[i];
}

static int bn__csr_put(void *sink, size_t i, size_t j, double v)
{
    bn__csr *c = sink;
    size_t k = bn__csr_find(c, i, j);
    if (k == SIZE_MAX)
        return 0;
    bn__csr_set(c, k, v);
    return 1;
}

/* Drops entries equal to 0 or below `threshold` (negative and NaN are kept for the checks) and
 * shrinks the arrays. */
static void bn__csr_compact(bn__csr *c, double threshold, bn_builder_report *rep)
{
    size_t w = 0;
    for (size_t i = 0; i < c->n; i++) {
        size_t b = c->rowptr[i], e = c->rowptr[i + 1];
        double d = 0;
        c->rowptr[i] = w;
        for (size_t k = b; k < e; k++) {
            double v = bn__csr_value(c, k);
            if (v == 0 || (v > 0 && v < threshold)) {
                d += v;
                rep->dropped_entries++;
                continue;
            }
            c->col[w] = c->col[k];
            bn__csr_set(c, w, v);
            w++;
        }
        rep->dropped_mass_max = fmax(rep->dropped_mass_max, d);
    }
    c->rowptr[c->n] = w;
    c->nnz = w;
    {
        void *p = bn__realloc_array(c->col, w ? w : 1, sizeof(uint32_t));
        if (p)
            c->col = p;
        if (c->v32) {
            p = bn__realloc_array(c->v32, w ? w : 1, sizeof(float));
            if (p)
                c->v32 = p;
        } else {
            p = bn__realloc_array(c->v64, w ? w : 1, sizeof(double));
            if (p)
                c->v64 = p;
        }
    }
}

static bn_status bn__csr_finish(void *sink, double drop_below, bn_builder_report *rep, const bn_transport_ops **ops,
                                void **ctx, bn_error *err)
{
    bn__csr *c = sink;
    (void)err;
    bn__csr_compact(c, drop_below, rep);
    *ops = c->prec == BN_PRECISION_FLOAT ? &bn__csr_float_ops : &bn__csr_double_ops;
    *ctx = c;
    return BN_OK;
}

const bn__storage bn__storage_sparse = {"sparse", 1, bn__csr_bytes_for, bn__csr_begin, bn__csr_pattern_row,
                                        bn__csr_put, bn__csr_finish, bn__csr_free};
