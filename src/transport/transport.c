/* The transport operator K = diag(rho) F: the generic wrapper over a storage implementation. */
#include "bounce/transport.h"
#include "transport/transport_internal.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

struct bn_transport {
    size_t n;
    double *rho;
    const bn_transport_ops *ops;
    void *impl;
};

bn_status bn_transport_create(size_t n, const double *rho, const bn_transport_ops *ops, void *impl,
                              bn_transport **out, bn_error *err)
{
    bn_transport *k;
    *out = NULL;
    for (size_t i = 0; i < 3 * n; i++)
        if (!(rho[i] >= 0 && rho[i] <= 1)) {
            ops->destroy(impl);
            return bn_error_set(err, BN_EINPUT, "patch %zu: reflectance %g is outside [0, 1]", i / 3, rho[i]);
        }
    k = calloc(1, sizeof *k);
    if (k)
        k->rho = bn__malloc_array(3 * n, sizeof(double));
    if (!k || !k->rho) {
        free(k);
        ops->destroy(impl);
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    memcpy(k->rho, rho, 3 * n * sizeof(double));
    k->n = n;
    k->ops = ops;
    k->impl = impl;
    *out = k;
    return BN_OK;
}

void bn_transport_destroy(bn_transport *k)
{
    if (!k)
        return;
    k->ops->destroy(k->impl);
    free(k->rho);
    free(k);
}

const bn_transport_ops *bn__transport_ops(const bn_transport *k) { return k->ops; }
const void *bn__transport_impl(const bn_transport *k) { return k->impl; }

size_t bn_transport_size(const bn_transport *k) { return k->n; }
const double *bn_transport_rho(const bn_transport *k) { return k->rho; }
const char *bn_transport_name(const bn_transport *k) { return k->ops->name; }
size_t bn_transport_bytes(const bn_transport *k) { return k->ops->bytes(k->impl) + 3 * k->n * sizeof(double); }
double bn_transport_F(const bn_transport *k, size_t i, size_t j) { return k->ops->entry(k->impl, i, j); }

void bn_transport_apply(const bn_transport *k, const double *x, double *y)
{
    /* y <- F x, then y <- diag(rho) y */
    k->ops->apply_F(k->impl, x, y);
    for (size_t i = 0; i < 3 * k->n; i++)
        y[i] *= k->rho[i];
}

void bn_transport_row(const bn_transport *k, size_t i, const double *x, double out[3])
{
    k->ops->row_F(k->impl, i, x, out);
    for (int c = 0; c < 3; c++)
        out[c] *= k->rho[3 * i + c];
}

double bn_transport_norm_inf(const bn_transport *k, double per_channel[3])
{
    /* ||K||_inf = max_i rho_ic sum_j |F_ij| (F >= 0): the row sums are F applied to ones. */
    double *ones = bn__malloc_array(3 * k->n, sizeof(double)), *rs = bn__malloc_array(3 * k->n, sizeof(double));
    double pc[3] = {0, 0, 0}, m = 0;
    if (!ones || !rs) {
        free(ones);
        free(rs);
        return NAN;
    }
    for (size_t i = 0; i < 3 * k->n; i++)
        ones[i] = 1.0;
    k->ops->apply_F(k->impl, ones, rs);
    for (size_t i = 0; i < k->n; i++)
        for (int c = 0; c < 3; c++)
            pc[c] = fmax(pc[c], k->rho[3 * i + c] * rs[3 * i + c]);
    m = fmax(pc[0], fmax(pc[1], pc[2]));
    if (per_channel)
        memcpy(per_channel, pc, sizeof pc);
    free(ones);
    free(rs);
    return m;
}

void bn_transport_to_dense(const bn_transport *k, double *F)
{
    for (size_t i = 0; i < k->n; i++)
        for (size_t j = 0; j < k->n; j++)
            F[i * k->n + j] = k->ops->entry(k->impl, i, j);
}
