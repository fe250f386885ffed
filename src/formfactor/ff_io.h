/* Form-factor files: CSV and the BNFF binary layout, also used by the cache (not installed). */
#ifndef BOUNCE_FF_IO_H
#define BOUNCE_FF_IO_H

#include "bounce/formfactor.h"

/* Writes k as CSV (by extension .csv) or BNFF binary with values in `prec`. key: a cache key
 * (may be NULL); provenance: '#'-prefixed lines (may be NULL); storage: the storage name for the
 * header (NULL: the operator's name). Atomic. */
bn_status bn__ff_write_file(const bn_transport *k, const bn_scene *scene, const char *path, const char *key,
                            const char *provenance, bn_precision prec, const char *storage, bn_error *err);

/* Reads a BNFF cache whose typed header matches (N, storage name, precision, and key or, when not
 * NULL, alt) into K = diag(rho) F through the storage's builder. On a miss returns non-OK with the
 * reason in why (empty if the file does not exist) and *out NULL. */
bn_status bn__ff_read_cache(const char *path, const char *key, const char *alt, size_t n, const char *storage,
                            bn_precision prec, const double *rho, bn_transport **out, char *why, size_t why_size);

#endif
