/* CSR storage of F (not installed): the form-factor assembly fills it in place. */
#ifndef BOUNCE_SPARSE_INTERNAL_H
#define BOUNCE_SPARSE_INTERNAL_H

#include <stdint.h>
#include "bounce/transport.h"

/* Compressed sparse rows: row i holds columns col[rowptr[i] .. rowptr[i+1]) in increasing
 * order, values in v32 (float) or v64 (double); exactly one is set. */
typedef struct bn__csr {
    size_t n, nnz;
    bn_precision prec;
    size_t *rowptr;    /* n + 1 */
    uint32_t *col;     /* nnz */
    float *v32;
    double *v64;
} bn__csr;

/* Bytes of a CSR with nnz entries over n rows. */
size_t bn__csr_bytes_for(size_t n, size_t nnz, bn_precision prec);
/* Allocates a CSR whose row i has counts[i] slots (columns and values zeroed; the caller
 * writes columns in increasing order). */
bn_status bn__csr_alloc(size_t n, const size_t *counts, bn_precision prec, bn__csr **out, bn_error *err);
void bn__csr_free(bn__csr *c);
/* Position of (i, j) in the value arrays, or (size_t)-1. */
size_t bn__csr_find(const bn__csr *c, size_t i, size_t j);
double bn__csr_value(const bn__csr *c, size_t k);
void bn__csr_set(bn__csr *c, size_t k, double v);
/* Drops entries equal to 0 or below `threshold`; dropped[i] (may be NULL) receives the sum of
 * what row i lost. Returns the number of entries dropped. Shrinks the arrays. */
size_t bn__csr_compact(bn__csr *c, double threshold, double *dropped);
/* The operator table for c's precision; hand (ops, c) to bn_transport_create. */
const bn_transport_ops *bn__csr_ops(const bn__csr *c);
/* The CSR behind a transport built on it, or NULL if k has other storage. */
const bn__csr *bn__csr_of(const bn_transport *k);

#endif
