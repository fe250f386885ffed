/* Where a storage of F plugs in (inside src/transport only): one const table per storage, found
 * by name. A storage is filled through a sink (begin, put, finish) and then serves the
 * bn_transport_ops interface; nothing outside src/transport sees how it keeps F.
 *
 *   form factors --put(i, j, v)--> builder --> storage sink --finish--> ops + ctx --> bn_transport
 *   cache file   --put_row------->                                                    (y = K x)
 */
#ifndef BOUNCE_TRANSPORT_STORAGE_H
#define BOUNCE_TRANSPORT_STORAGE_H

#include "bounce/transport.h"

typedef struct bn__storage {
    const char *name;
    int needs_pattern;   /* begin takes per-row counts and the builder fills pattern_row */
    /* Bytes for n rows and nnz entries (SIZE_MAX on overflow). */
    size_t (*bytes)(size_t n, size_t nnz, bn_precision prec);
    /* Zeroed storage; counts[i] = entries of row i when needs_pattern (else NULL). */
    bn_status (*begin)(size_t n, bn_precision prec, const size_t *counts, void **sink, bn_error *err);
    /* needs_pattern: the column slots of row i, for the builder to fill in increasing order. */
    uint32_t *(*pattern_row)(void *sink, size_t i);
    /* F_ij = v; 0 if (i, j) has no place. Thread-safe for distinct (i, j). */
    int (*put)(void *sink, size_t i, size_t j, double v);
    /* Drops entries below drop_below where the storage can; hands over the operator. The sink
     * becomes the operator's ctx (or is freed on failure). */
    bn_status (*finish)(void *sink, double drop_below, bn_builder_report *rep, const bn_transport_ops **ops,
                        void **ctx, bn_error *err);
    void (*abort)(void *sink);
} bn__storage;

extern const bn__storage bn__storage_dense;
extern const bn__storage bn__storage_sparse;

#endif
