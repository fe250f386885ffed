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
const char *bn_ff_method_names(void);            /* "analytic|montecarlo|hemisphere" */
int bn_ff_method_parse(const char *name, bn_ff_method *m);   /* 0, or -1 for no such method */
/* The analytic method's visibility of partly occluded pairs (bn_formfactor_opts.exact_visibility):
 * "exact" (1) or "rays" (0). */
const char *bn_ff_visibility_name(int exact);
const char *bn_ff_visibility_names(void);        /* "exact|rays" */
int bn_ff_visibility_parse(const char *name, int *exact);    /* 0, or -1 for no such name */

/* The analytic method's relative tolerance per pair by default. Every unoccluded pair goes by the
 * double contour integral, whose Gauss-Kronrod panels converge geometrically: 1e-9 costs the
 * Cornell box about what 1e-5 does, and a closed enclosure's rows then sum to 1 within 1e-9 (the
 * furnace at rho 0.999 to 1e-6 needs that). */
#define BN_FF_TOLERANCE_DEFAULT 1e-9

typedef struct bn_formfactor_opts {
    bn_ff_method method;      /* default analytic */
    int          samples;     /* montecarlo: point pairs per patch pair (default 64); hemisphere: rays
                                 per patch (default 4096); analytic without exact_visibility: shadow
                                 rays per pair that an occluder may block (default 32). 0 = the
                                 method's default */
    const char  *storage;     /* a storage name (bn_storage_names(): "dense", "sparse"); default dense */
    bn_precision precision;   /* default float */
    double       sparse_threshold;  /* storages that drop entries (sparse): drop F_ij below it (default 0:
                                       exact zeros only) */
    size_t       max_memory;  /* bytes; 0 = 80% of physical memory */
    uint64_t     seed;
    int          quiet;       /* no progress bar */
    const char  *cache_path;  /* NULL: no cache */
    bn_log       log;
    double       tolerance;   /* analytic: relative tolerance per pair (default BN_FF_TOLERANCE_DEFAULT) */
    int          quadrature_only;  /* analytic: every pair by the point kernel's quadrature (the path
                                      before the closed form; for comparisons and bench/) */
    int          threads;     /* 0 = the caller's (all cores by default); results do not depend on it */
    int          exact_visibility;  /* analytic (default 1): the exact visible part of each partly occluded
                                       pair with at most 32 faces in its shaft, integrated over one patch
                                       (rows of closed scenes within 1e-4); 0: 32 shadow rays per pair
                                       (samples), rows off by a few 1e-3 in about a third of the time */
} bn_formfactor_opts;
void bn_formfactor_opts_default(bn_formfactor_opts *o);
/* The samples a method uses when o->samples is 0. */
int bn_formfactor_default_samples(bn_ff_method m);
/* One line naming every option that changes F ("method=analytic samples=32 ..."), for
 * provenance headers and cache keys. */
void bn_formfactor_opts_describe(const bn_formfactor_opts *o, char *buf, size_t size);

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
    /* Added with the assembly (issue 3). */
    size_t pairs_nonzero;         /* unordered pairs that face each other (F_unoccluded > 0 possible) */
    size_t pairs_culled;          /* of those, pairs whose shaft holds no occluder: no rays */
    size_t pairs_blocked;         /* pairs with at least one blocked shadow ray */
    size_t quad_evals;            /* analytic: point-to-polygon kernel evaluations */
    size_t dropped_entries;       /* sparse threshold: entries dropped */
    size_t rows_above_one;        /* rows with sum_j F_ij > 1 + row_sum_tol */
    double row_sum_tol;           /* the method's allowance for row sums above 1 */
    double rays_per_second;       /* rays / seconds of the whole assembly */
    bn_ff_method method;
    int    samples;
    size_t pairs_exact;           /* analytic: pairs whose visible part was computed exactly (no rays): by
                                     the exact path, or hidden wholly by one face in their shaft */
} bn_ff_diagnostics;

/* F's row sums against the exact ones, for any transport (dense, sparse, the hierarchy's F_H).
 * The exact row sum of patch i is the share of its cosine-weighted hemisphere whose first hit is a
 * front face (1 in a closed scene), estimated by `rays` stratified rays (standard error at most
 * sqrt(p (1 - p) / rays), 0 where every ray hits a front). dev = sum_j F_ij - that share. */
typedef struct bn_row_sum_check {
    size_t rows;          /* rows checked: every row up to max_rows, else an even stride */
    size_t stride;        /* row k of the check is patch k x stride */
    int    rays;          /* per row */
    size_t closed;        /* rows whose every ray reached a front face (exact row sum 1) */
    double dev_min, dev_p01, dev_p50, dev_p99, dev_max;   /* over the rows checked */
    double within_1pct;   /* share of rows with |dev| <= 0.01 + 2 standard errors of a difference of
                             two such estimates (2.83 of this one's: a row may have been normalised
                             to another, as the hierarchy's are) */
    size_t above_5pct;    /* rows with dev > 0.05 + the same allowance */
    size_t worst_row;     /* the patch of dev_max */
} bn_row_sum_check;
/* The exact row sum of patch i by min_rays stratified rays, and max_rays afresh when some of them
 * reach a front face and some do not; *se (may be NULL): its standard error. Deterministic in seed. */
double bn_ff_row_sum_exact(const bn_scene *s, const bn_rt *rt, size_t i, int min_rays, int max_rays, uint64_t seed,
                           double *se);
/* row_sums: sum_j F_ij per patch (F applied to ones). exact (may be NULL; max_rows values): each
 * checked row's exact estimate, in the check's order. Deterministic in seed, for any thread count. */
bn_status bn_ff_row_sum_check(const bn_scene *s, const bn_rt *rt, const double *row_sums, size_t max_rows, int rays,
                              uint64_t seed, int threads, bn_row_sum_check *out, double *exact, bn_error *err);

/* Bytes the assembly of `scene` with `o` will need (checked against max_memory before any work). */
size_t bn_formfactor_bytes_needed(const bn_scene *scene, const bn_formfactor_opts *o);
/* The same check before meshing, for a storage whose size follows from the patch count alone
 * (dense): BN_ENOMEM with the numbers and remedies when `n_estimate` patches would not fit, else
 * BN_OK (also for storages whose size is known only after meshing). */
bn_status bn_formfactor_check_memory(double n_estimate, const bn_formfactor_opts *o, bn_error *err);

/* Assembles F for the meshed `scene` (borrowed) using `rt` (borrowed) for visibility, and returns
 * K = diag(rho) F. diag may be NULL. Bit-identical for any thread count. Fails with BN_ENOMEM
 * (naming the patch count, the need and the remedies) above max_memory, BN_ENUMERIC if an entry
 * is negative, above 1 or not finite, BN_EINTR/BN_ETERM when interrupted. */
bn_status bn_formfactor_build(const bn_scene *scene, const bn_rt *rt, const bn_formfactor_opts *o,
                              bn_transport **out, bn_ff_diagnostics *diag, bn_error *err);

/* F from a differential area at x with unit normal n (pointing to the front) to the planar
 * polygon v[0..nv) (xyz triples, counter-clockwise seen from its front), unoccluded, by
 * Lambert's contour integral. Parts of the polygon behind x's tangent plane are clipped away.
 * Dimensionless. */
double bn_ff_point_to_polygon(const double x[3], const double n[3], const double *v, size_t nv);
/* Unoccluded F_ij between two planar convex polygons (xyz triples, counter-clockwise seen from
 * the front; surfaces one-sided): the double contour integral, its inner integral in closed form
 * and its outer one adaptive, to relative tolerance rtol (<= 0: BN_FF_TOLERANCE_DEFAULT). 0 if
 * they do not face each other. */
double bn_ff_polygon_pair(const double *vi, size_t ni, const double *vj, size_t nj, double rtol);

/* Writes F: `.csv` (provenance lines starting with '#', then `patch,area,F0,...,F{N-1}` and one
 * row per patch, areas in m^2) or `.bin` (the layout documented in doc/readme/formfactors.md:
 * "BNFF", version 2, N, nnz, value bytes, layout full|indexed rows, storage, key, provenance text,
 * areas, F), values written in `prec`. Needs an operator with entries (BN_OP_ENTRIES).
 * provenance: '#'-prefixed lines (may be NULL). Atomic: written to a temporary and renamed. */
bn_status bn_ff_write(const bn_transport *k, const bn_scene *scene, const char *path, const char *provenance,
                      bn_precision prec, bn_error *err);

/* Prints diagnostics as `key value` lines (for logs and `bounce formfactors`). */
void bn_ff_diagnostics_print(const bn_ff_diagnostics *d, FILE *fp);

#ifdef __cplusplus
}
#endif
#endif
