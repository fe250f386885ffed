/* Storage constructors used by the form-factor assembly (not installed). */
#ifndef BOUNCE_TRANSPORT_INTERNAL_H
#define BOUNCE_TRANSPORT_INTERNAL_H

#include "bounce/transport.h"

/* A writable view of a dense F being assembled: exactly one of f32/f64 is set. */
typedef struct bn__dense_view {
    size_t n;
    float *f32;
    double *f64;
} bn__dense_view;

/* Allocates zeroed dense storage; hand impl/ops to bn_transport_create when filled. */
bn_status bn__dense_alloc(size_t n, bn_precision prec, bn__dense_view *view, void **impl,
                          const bn_transport_ops **ops, bn_error *err);

/* The storage behind a transport (borrowed): its ops table and implementation. */
const bn_transport_ops *bn__transport_ops(const bn_transport *k);
const void *bn__transport_impl(const bn_transport *k);

#endif
