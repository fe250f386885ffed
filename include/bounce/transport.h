/* bounce: the light-transport operator K = diag(rho) F behind one interface.
 * F is stored once (not per channel); K is applied as y_c = rho_c * (F x_c).
 * Radiance vectors hold N patches x 3 channels interleaved: x[3*i + c], c = R, G, B. */
#ifndef BOUNCE_TRANSPORT_H
#define BOUNCE_TRANSPORT_H

#include <stddef.h>
#include "bounce/status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum bn_storage { BN_STORAGE_DENSE, BN_STORAGE_SPARSE } bn_storage;
typedef enum bn_precision { BN_PRECISION_FLOAT, BN_PRECISION_DOUBLE } bn_precision;

/* The operator interface that dense, sparse and (later) hierarchical or distributed storage
 * implement. Every sum accumulates in double whatever the stored precision. */
typedef struct bn_transport_ops {
    const char *name;                                                  /* "dense-float", "csr-double", ... */
    /* y[3i+c] = sum_j F_ij x[3j+c] for all i and c. y does not alias x. */
    void   (*apply_F)(const void *impl, const double *x, double *y);
    /* out[c] = sum_j F_ij x[3j+c] (row access, for Gauss-Seidel). */
    void   (*row_F)(const void *impl, size_t i, const double *x, double out[3]);
    double (*entry)(const void *impl, size_t i, size_t j);              /* F_ij */
    size_t (*bytes)(const void *impl);                                  /* storage held */
    void   (*destroy)(void *impl);
} bn_transport_ops;

typedef struct bn_transport bn_transport;   /* opaque: ops + impl + rho */

/* Wraps an implementation: takes ownership of impl (destroyed with ops->destroy) and copies
 * rho (n*3 reflectances, each in [0, 1]). */
bn_status bn_transport_create(size_t n, const double *rho, const bn_transport_ops *ops, void *impl,
                              bn_transport **out, bn_error *err);
void bn_transport_destroy(bn_transport *k);   /* NULL is a no-op */

size_t        bn_transport_size(const bn_transport *k);          /* N patches */
const double *bn_transport_rho(const bn_transport *k);           /* borrowed, N*3 */
const char   *bn_transport_name(const bn_transport *k);
size_t        bn_transport_bytes(const bn_transport *k);

/* y = K x: y[3i+c] = rho[3i+c] * sum_j F_ij x[3j+c]. x, y: N*3; y must not alias x. */
void   bn_transport_apply(const bn_transport *k, const double *x, double *y);
/* out[c] = (K x)_i for channel c (row access). */
void   bn_transport_row(const bn_transport *k, size_t i, const double *x, double out[3]);
/* F_ij. */
double bn_transport_F(const bn_transport *k, size_t i, size_t j);
/* ||K||_inf per channel and overall: max_i rho_ic sum_j F_ij (the contraction factor that
 * bounds the Neumann series). per_channel may be NULL. */
double bn_transport_norm_inf(const bn_transport *k, double per_channel[3]);

/* Dense F from a row-major N*N double array (copied, stored in `prec`): tests, generators. */
bn_status bn_transport_dense_from_array(size_t n, const double *F, const double *rho, bn_precision prec,
                                        bn_transport **out, bn_error *err);
/* Sparse (CSR) F from a row-major N*N double array: exact zeros and entries below `threshold`
 * are dropped; values stored in `prec`, columns as 32-bit indices (N < 2^32). */
bn_status bn_transport_sparse_from_array(size_t n, const double *F, const double *rho, bn_precision prec,
                                         double threshold, bn_transport **out, bn_error *err);
/* Writes F as a row-major N*N double array (caller allocates N*N). */
void bn_transport_to_dense(const bn_transport *k, double *F);

#ifdef __cplusplus
}
#endif
#endif
