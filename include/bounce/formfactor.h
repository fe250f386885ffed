/* bounce: form factors with visibility, assembled into the transport operator K = diag(rho) F. */
#ifndef BOUNCE_FORMFACTOR_H
#define BOUNCE_FORMFACTOR_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/transport.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum bn_ff_method {
    BN_FF_ANALYTIC,    /* exact point-to-polygon kernel by quadrature; shadow rays only where needed */
    BN_FF_MONTECARLO,  /* stratified area-to-area point pairs */
    BN_FF_HEMISPHERE   /* cosine-weighted rays from each patch, counting hits */
} bn_ff_method;
const char *bn_ff_method_name(bn_ff_method m);   /* "analytic", "montecarlo", "hemisphere" */

typedef struct bn_formfactor_opts {
    bn_ff_method method;      /* default analytic */
    int          samples;     /* montecarlo: point pairs per patch pair; hemisphere: rays per patch;
                                 analytic: visibility rays per partly occluded pair (default 16) */
    bn_storage   storage;     /* default dense */
    bn_precision precision;   /* default float */
    double       sparse_threshold;  /* sparse: drop F_ij below it (default 0: exact zeros only) */
    size_t       max_memory;  /* bytes; 0 = 80% of physical memory */
    uint64_t     seed;
    int          quiet;       /* no progress bar */
    const char  *cache_path;  /* NULL: no cache */
    bn_log       log;
} bn_formfactor_opts;
void bn_formfactor_opts_default(bn_formfactor_opts *o);

/* What every assembly reports. */
typedef struct bn_ff_diagnostics {
    size_t n;                     /* patches */
    double row_sum_min, row_sum_max, row_sum_rms_dev; /* sum_j F_ij, and RMS of (sum - 1) */
    double reciprocity_residual;  /* max |A_i F_ij - A_j F_ji| / max(A_i F_ij, A_j F_ji) over pairs */
    size_t negative_entries, above_one_entries;
    double occluded_fraction;     /* share of pairs that needed shadow rays and were partly blocked */
    size_t pairs_tested;          /* pairs that needed visibility */
    size_t rays;                  /* shadow / hemisphere rays cast */
    double k_norm_inf;            /* max_i rho_i sum_j F_ij */
    size_t nonzeros;              /* stored entries */
    double dropped_mass_max;      /* sparse threshold: largest per-row sum of dropped F */
    size_t bytes;                 /* storage of F */
    double seconds;
    int    from_cache;
} bn_ff_diagnostics;

/* Bytes the assembly of `scene` with `o` will need (checked against max_memory before any work). */
size_t bn_formfactor_bytes_needed(const bn_scene *scene, const bn_formfactor_opts *o);

/* Assembles F for the meshed `scene` (borrowed) using `rt` (borrowed) for visibility, and returns
 * K = diag(rho) F. diag may be NULL. Bit-identical for any thread count. Fails with BN_ENOMEM
 * (naming the patch count, the need and the remedies) above max_memory, BN_ENUMERIC if an entry
 * is negative, above 1 or not finite, BN_EINTR/BN_ETERM when interrupted. */
bn_status bn_formfactor_build(const bn_scene *scene, const bn_rt *rt, const bn_formfactor_opts *o,
                              bn_transport **out, bn_ff_diagnostics *diag, bn_error *err);

/* Prints diagnostics as `key value` lines (for logs and `bounce formfactors`). */
void bn_ff_diagnostics_print(const bn_ff_diagnostics *d, FILE *fp);

#ifdef __cplusplus
}
#endif
#endif
