/* Sparse F in compressed sparse rows (float or double values, 32-bit columns); every sum
 * accumulates in double. Exact zeros (pairs that cannot see each other) are never stored. */
#include "bounce/transport.h"
#include "transport/sparse_internal.h"
#include "transport/transport_internal.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

size_t bn__csr_bytes_for(size_t n, size_t nnz, bn_precision prec)
{
    size_t elem = prec == BN_PRECISION_FLOAT ? sizeof(float) : sizeof(double), a, b;
    if (!bn__mul_size(nnz, elem + sizeof(uint32_t), &a) || !bn__mul_size(n + 1, sizeof(size_t), &b))
        return (size_t)-1;
    return a + b;
}

void bn__csr_free(bn__csr *c)
{
    if (!c)
        return;
    free(c->rowptr);
    free(c->col);
    free(c->v32);
    free(c->v64);
    free(c);
}

bn_status bn__csr_alloc(size_t n, const size_t *counts, bn_precision prec, bn__csr **out, bn_error *err)
{
    bn__csr *c = calloc(1, sizeof *c);
    size_t nnz = 0;
    *out = NULL;
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
        nnz += counts ? counts[i] : 0;
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
        return bn_error_set(err, BN_ENOMEM, "cannot allocate sparse F: %zu patches, %zu entries need %.3g GiB", n,
                            nnz, (double)bn__csr_bytes_for(n, nnz, prec) / (1024.0 * 1024 * 1024));
    }
    *out = c;
    return BN_OK;
}

size_t bn__csr_find(const bn__csr *c, size_t i, size_t j)
{
    size_t lo = c->rowptr[i], hi = c->rowptr[i + 1];
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (c->col[mid] < j)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < c->rowptr[i + 1] && c->col[lo] == j ? lo : (size_t)-1;
}

double bn__csr_value(const bn__csr *c, size_t k) { return c->v32 ? (double)c->v32[k] : c->v64[k]; }

void bn__csr_set(bn__csr *c, size_t k, double v)
{
    if (c->v32)
        c->v32[k] = (float)v;
    else
        c->v64[k] = v;
}

size_t bn__csr_compact(bn__csr *c, double threshold, double *dropped)
{
    size_t w = 0, lost = 0;
    for (size_t i = 0; i < c->n; i++) {
        size_t b = c->rowptr[i], e = c->rowptr[i + 1];
        double d = 0;
        c->rowptr[i] = w;
        for (size_t k = b; k < e; k++) {
            double v = bn__csr_value(c, k);
            if (v == 0 || (v > 0 && v < threshold)) {   /* negative and NaN are kept for the checks */
                d += v;
                lost++;
                continue;
            }
            c->col[w] = c->col[k];
            bn__csr_set(c, w, v);
            w++;
        }
        if (dropped)
            dropped[i] = d;
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
    return lost;
}

static void bn__csr_row(const void *impl, size_t i, const double *x, double out[3])
{
    const bn__csr *c = impl;
    double s0 = 0, s1 = 0, s2 = 0;
    size_t b = c->rowptr[i], e = c->rowptr[i + 1];
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
}

static void bn__csr_apply(const void *impl, const double *x, double *y)
{
    const bn__csr *c = impl;
    long n = (long)c->n;
#pragma omp parallel for schedule(static)
    for (long i = 0; i < n; i++)
        bn__csr_row(impl, (size_t)i, x, y + 3 * i);
}

static double bn__csr_entry(const void *impl, size_t i, size_t j)
{
    const bn__csr *c = impl;
    size_t k = bn__csr_find(c, i, j);
    return k == (size_t)-1 ? 0.0 : bn__csr_value(c, k);
}

static size_t bn__csr_bytes(const void *impl)
{
    const bn__csr *c = impl;
    return bn__csr_bytes_for(c->n, c->nnz, c->prec);
}

static void bn__csr_destroy(void *impl) { bn__csr_free(impl); }

static const bn_transport_ops bn__csr_float_ops = {"csr-float", bn__csr_apply, bn__csr_row, bn__csr_entry,
                                                   bn__csr_bytes, bn__csr_destroy};
static const bn_transport_ops bn__csr_double_ops = {"csr-double", bn__csr_apply, bn__csr_row, bn__csr_entry,
                                                    bn__csr_bytes, bn__csr_destroy};

const bn_transport_ops *bn__csr_ops(const bn__csr *c)
{
    return c->prec == BN_PRECISION_FLOAT ? &bn__csr_float_ops : &bn__csr_double_ops;
}

const bn__csr *bn__csr_of(const bn_transport *k)
{
    const bn_transport_ops *ops = bn__transport_ops(k);
    return ops == &bn__csr_float_ops || ops == &bn__csr_double_ops ? bn__transport_impl(k) : NULL;
}

bn_status bn_transport_sparse_from_array(size_t n, const double *F, const double *rho, bn_precision prec,
                                         double threshold, bn_transport **out, bn_error *err)
{
    size_t *counts = bn__calloc(n ? n : 1, sizeof(size_t));
    bn__csr *c;
    bn_status st;
    *out = NULL;
    if (!counts)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    if (n > UINT32_MAX) {
        free(counts);
        return bn_error_set(err, BN_ENOMEM, "sparse F: %zu patches exceed 32-bit column indices", n);
    }
    for (size_t i = 0; i < n; i++)
        for (size_t j = 0; j < n; j++)
            counts[i] += F[i * n + j] != 0;
    st = bn__csr_alloc(n, counts, prec, &c, err);
    free(counts);
    if (st != BN_OK)
        return st;
    for (size_t i = 0; i < n; i++) {
        size_t k = c->rowptr[i];
        for (size_t j = 0; j < n; j++)
            if (F[i * n + j] != 0) {
                c->col[k] = (uint32_t)j;
                bn__csr_set(c, k, F[i * n + j]);
                k++;
            }
    }
    bn__csr_compact(c, threshold, NULL);
    return bn_transport_create(n, rho, bn__csr_ops(c), c, out, err);
}
