/* Form-factor files: CSV and the BNFF binary layout, also used by the cache (not installed). */
#ifndef BOUNCE_FF_IO_H
#define BOUNCE_FF_IO_H

#include "bounce/formfactor.h"
#include "transport/sparse_internal.h"

/* Writes k as CSV (by extension .csv) or BNFF binary. key: a cache key line (may be NULL);
 * provenance: '#'-prefixed lines (may be NULL). Atomic. */
bn_status bn__ff_write_file(const bn_transport *k, const bn_scene *scene, const char *path, const char *key,
                            const char *provenance, bn_error *err);

/* Reads a BNFF cache whose key line equals `key` and whose N, precision and layout match; on a
 * miss returns non-OK with the reason in why (empty if the file does not exist). On success
 * exactly one of *f32, *f64, *csr is set, with *impl / *ops to hand to bn_transport_create. */
bn_status bn__ff_read_cache(const char *path, const char *key, size_t n, bn_precision prec, bn_storage storage,
                            float **f32, double **f64, bn__csr **csr, void **impl, const bn_transport_ops **ops,
                            char *why, size_t why_size);

#endif
