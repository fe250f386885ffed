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

static void bn__dense_row(const void *impl, size_t i, const double *x, double out[3])
{
    const bn__dense *d = impl;
    double s0 = 0, s1 = 0, s2 = 0;
    size_t n = d->n;
    if (d->prec == BN_PRECISION_FLOAT) {
        const float *r = (const float *)d->data + i * n;
        for (size_t j = 0; j < n; j++) {
            double f = r[j];
            s0 += f * x[3 * j];
            s1 += f * x[3 * j + 1];
            s2 += f * x[3 * j + 2];
        }
    } else {
        const double *r = (const double *)d->data + i * n;
        for (size_t j = 0; j < n; j++) {
            double f = r[j];
            s0 += f * x[3 * j];
            s1 += f * x[3 * j + 1];
            s2 += f * x[3 * j + 2];
        }
    }
    out[0] = s0;
    out[1] = s1;
    out[2] = s2;
}

static void bn__dense_apply(const void *impl, const double *x, double *y)
{
    const bn__dense *d = impl;
    long n = (long)d->n;
#pragma omp parallel for schedule(static)
    for (long i = 0; i < n; i++)
        bn__dense_row(impl, (size_t)i, x, y + 3 * i);
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
