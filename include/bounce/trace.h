/* bounce: a Monte Carlo path tracer over the scene's patches (Lambertian, one-sided), with every
 * contribution binned by path length, and its statistical cross-check against radiosity.
 *
 * The tracer shares only the scene (geometry, materials) and the ray caster (rt.h) with the
 * radiosity side: no form factors, no K, no solver. That independence is what makes it a check.
 *
 * Path length = the number of reflections. Bin k collects the paths with k reflections between
 * the emitter and the point seen (camera) or estimated (patch), i.e. the term K^k E: bin 0 is the
 * emission seen directly (E), bin 1 direct light (KE), bin 2 the first indirect bounce (K2E).
 * A renderer whose "max depth" counts path segments from the eye renders bins 0 .. depth-1. */
#ifndef BOUNCE_TRACE_H
#define BOUNCE_TRACE_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/image.h"
#include "bounce/layers.h"

#ifdef __cplusplus
extern "C" {
#endif

/* How each reflection gathers emitted light. MIS (the default) is next-event estimation and
 * cosine (BSDF) sampling combined by the power heuristic; the other two are single strategies,
 * kept because all three must agree in expectation (the suite checks it). */
typedef enum bn_trace_strategy { BN_TRACE_MIS, BN_TRACE_BSDF, BN_TRACE_NEE } bn_trace_strategy;
const char *bn_trace_strategy_name(bn_trace_strategy v);
const char *bn_trace_strategy_names(void);   /* "mis|bsdf|nee" */
int bn_trace_strategy_parse(const char *s, bn_trace_strategy *out);   /* 0, or -1 for no such name */

/* What transport the tracer estimates. CONTINUOUS is light transport itself on the scene's
 * surfaces: the physical answer, which radiosity approaches as its patches shrink. PATCH restarts
 * each path, after every reflection, at a point drawn uniformly on the patch it hit: the estimate
 * is then the piecewise-constant (Galerkin) transport the radiosity solves on the same patches,
 * F_ij = (1/A_i) int_i int_j cos cos V / (pi r^2), with no discretisation error between the two, so
 * a disagreement is an error of the form factors, K or the solver, never of the mesh. Both draw
 * only on the scene and the ray caster. */
typedef enum bn_trace_model { BN_TRACE_CONTINUOUS, BN_TRACE_PATCH } bn_trace_model;
const char *bn_trace_model_name(bn_trace_model v);
const char *bn_trace_model_names(void);   /* "continuous|patch" */
int bn_trace_model_parse(const char *s, bn_trace_model *out);   /* 0, or -1 for no such name */

typedef struct bn_trace_opts {
    size_t   spp;          /* independent samples per pixel or per patch (default 64) */
    int      bounces;      /* bins K^0 E .. K^bounces E kept separately (default 3, >= 0); longer paths go to `rest` */
    int      rr_depth;     /* reflections before Russian roulette starts (default 3) */
    int      max_depth;    /* safety cap on reflections (default 100000; with roulette's survival
                              probability <= 0.95 a path reaches it with probability < 1e-2000) */
    bn_trace_strategy strategy;  /* default MIS */
    bn_trace_model model;  /* default CONTINUOUS */
    uint64_t seed;         /* streams are keyed by (seed, pixel or patch, sample index) */
    int      quiet;        /* no progress bar */
    int      threads;      /* 0 = the caller's (all cores by default); results do not depend on it */
    int      tree_emitters;  /* next-event estimation picks among more emitting patches than this from a
                                light tree, in proportion to their likely contribution at the path's
                                point (src/rt/lights.h); up to it, by power (default BN_TRACE_TREE_EMITTERS) */
} bn_trace_opts;
#define BN_TRACE_TREE_EMITTERS 64
void bn_trace_opts_default(bn_trace_opts *o);


/* Per-patch estimates of the patch-averaged outgoing radiance (W m^-2 sr^-1): points uniform on
 * each patch, directions cosine-distributed, L_o = Le + rho E_irr / pi. Each patch's `spp`
 * samples are independent, so se is the standard error of its mean from the samples themselves. */
typedef struct bn_trace_patches {
    size_t n;          /* patches */
    int    bounces;
    int    nlayers;    /* bounces + 3 */
    size_t spp;
    double *mean;      /* nlayers * n * 3: mean[(layer * n + i) * 3 + c] (owned) */
    double *se;        /* same layout: standard error of the mean (owned) */
    double *skew;      /* same layout: sample skewness g1 of the spp samples themselves, m3 / m2^1.5
                          (0 when they do not vary); the cross-check corrects its t test with it (owned) */
    unsigned long long rays;   /* rays cast (intersection + shadow) */
    double seconds;
} bn_trace_patches;

/* Estimates every patch of rt's scene (borrowed). Bit-identical for any thread count. Returns
 * BN_ENOMEM, BN_ENUMERIC (a non-finite estimate, naming the patch), BN_EINTR/BN_ETERM. */
bn_status bn_trace_patches_run(const bn_rt *rt, const bn_trace_opts *o, bn_trace_patches *out, bn_error *err);
void bn_trace_patches_free(bn_trace_patches *r);   /* NULL or zeroed is a no-op */
/* Per-patch estimates as CSV: `header` ('#' provenance lines), then
 * patch,face,material,area_m2,cx,cy,cz and each layer's R, G, B and their standard errors
 * (`<layer>.R ... <layer>.B_se`), one row per patch. Atomic. */
bn_status bn_trace_patches_write_csv(const char *path, const bn_scene *s, const bn_trace_patches *r,
                                     const char *header, bn_error *err);

/* Power of one layer: watts[c] = pi * sum_i A_i mean_i (A in m^2 from the scene's unit), and its
 * standard error se[c] = pi * sqrt(sum_i (A_i se_i)^2) (patches are independent). */
void bn_trace_patches_power(const bn_scene *s, const bn_trace_patches *r, int layer, double watts[3], double se[3]);

/* A reporting partition: the patches grouped into regions, each a union of whole input polygons of
 * one material (so every meshing of one scene has the same regions). Each material gets its share
 * (by area) of the regions asked, at least one: its polygons larger than an even share become
 * regions of their own, and the rest are split at the area median along the longest axis of their
 * centroids. */
typedef struct bn_partition {
    size_t n;             /* regions */
    size_t npatch;
    uint32_t *of_patch;   /* npatch: each patch's region */
    size_t *start;        /* n + 1: region g holds patch[start[g] .. start[g + 1]) */
    uint32_t *patch;      /* npatch */
    double *cum;          /* npatch: running area inside its region over `patch`, the last of each = 1 */
    double *area;         /* n: scene units^2 */
    unsigned *material;   /* n */
    double *centroid;     /* 3n: area-weighted */
} bn_partition;
bn_status bn_partition_regions(const bn_scene *s, size_t nregions, bn_partition *out, bn_error *err);
/* The partition a reader names: one region per object and material (bn_scene_object_count: the
 * file's o/g groups or its material-name prefixes), and each polygon of at least own_share of the
 * scene's area a region of its own (each wall, the floor). Whole polygons too, so every meshing of
 * one scene has the same regions. */
bn_status bn_partition_objects(const bn_scene *s, double own_share, bn_partition *out, bn_error *err);
#define BN_PARTITION_OWN_SHARE 0.01
void bn_partition_free(bn_partition *p);
/* Area-weighted means per region of per-patch layers (nlayers * npatch * 3, bn_layers_stack layout)
 * into out (nlayers * n * 3). */
void bn_partition_mean(const bn_partition *p, const bn_scene *s, const double *layers, int nlayers, double *out);

/* The tracer's estimates per region: the area mean of the outgoing radiance over each region, points
 * uniform in area over the whole region; the same layout as bn_trace_patches with n = regions. */
bn_status bn_trace_regions_run(const bn_rt *rt, const bn_partition *part, const bn_trace_opts *o,
                               bn_trace_patches *out, bn_error *err);

/* Points the tracer estimates at (an independent reference for per-vertex values, bounce bake's): a
 * place on a patch, on the side its normal faces. */
#define BN_TRACE_POINT_INSET BN_SCENE_POINT_INSET   /* bn_scene_point_inset: the bake's rule too */
typedef struct bn_trace_point {
    double x[3];
    size_t patch;
    unsigned line;   /* the line of the points file it came from */
} bn_trace_point;
/* Reads `path`: one point a line, `x y z nx ny nz` in scene units (blank lines and `#` comments skipped),
 * the normal pointing to the side whose outgoing radiance is wanted. Each point takes the face nearest to
 * it within 1e-6 of the scene's diameter whose normal agrees with n (found by a short ray along -n), and
 * the patch of that face there, and is moved BN_TRACE_POINT_INSET of the way to that patch's centroid (a
 * point exactly on an edge, a bake's vertex, would send rays along the neighbouring surface's plane: a
 * block's foot on the floor; bounce bake's gather at vertices moves its points the same way). *pts (owned by the caller), *n; a line that is not six finite numbers, a
 * zero normal, or a point with no such face: BN_EINPUT naming the file and the line. */
bn_status bn_trace_points_read(const char *path, const bn_rt *rt, bn_trace_point **pts, size_t *n, bn_error *err);
/* The tracer's estimate at each point: the radiance leaving the surface there, per layer (its emission in
 * E, each path's reflections binned as for patches; the reflectance at the point, textures included),
 * with standard errors; the layout of bn_trace_patches with n = points. */
bn_status bn_trace_points_run(const bn_rt *rt, const bn_trace_point *pts, size_t n, const bn_trace_opts *o,
                              bn_trace_patches *out, bn_error *err);
/* Per-point estimates as CSV: `header`, then point,line,face,patch,x,y,z and each layer's R, G, B and
 * their standard errors (`<layer>.R ... <layer>.B_se`), one row per point in the file's order. Atomic. */
bn_status bn_trace_points_write_csv(const char *path, const bn_scene *s, const bn_trace_point *pts,
                                    const bn_trace_patches *r, const char *header, bn_error *err);

/* Camera images: per pixel the mean over `spp` independent jittered samples of the radiance leaving
 * the surface seen, per layer, and the variance of that mean (unbiased sample variance / spp). */
typedef struct bn_trace_image {
    int width, height;
    int bounces, nlayers;
    size_t spp;
    float *mean;   /* nlayers * width * height * 3, row 0 at the top (owned) */
    float *var;    /* same layout (owned) */
    unsigned long long rays;
    double seconds;
} bn_trace_image;
/* Bytes the image buffers will take (checked before allocating). */
size_t bn_trace_image_bytes(const bn_camera *cam, int bounces);
bn_status bn_trace_image_run(const bn_rt *rt, const bn_camera *cam, const bn_trace_opts *o, bn_trace_image *out,
                             bn_error *err);
void bn_trace_image_free(bn_trace_image *r);
/* The image as one multi-layer EXR: layers E .. L, then <layer>_var (the variance of each pixel's
 * mean); attrs are written as header attributes. Atomic. */
bn_status bn_trace_image_write(const bn_trace_image *img, const char *path, const bn_attr *attrs, size_t nattrs,
                               int half, const bn_log *log, bn_error *err);

/* ---- the cross-check: radiosity against the per-patch tracer ---- */


/* Discretisation tolerance from a second mesh level of the same scene (same faces, another patch
 * size): for patch i of `fine` in face f, tol = |R_i - R'_m(i)| per layer and channel, with m(i) the
 * patch of `other` in face f that contains i's centroid; power_tol = |P - P'| (watts) per layer and
 * channel. Layers as bn_layers_stack for both. Either level may be the finer one. */
bn_status bn_crosscheck_mesh_tolerance(const bn_scene *fine, const double *fine_layers, const bn_scene *other,
                                       const double *other_layers, int bounces, double *tol, double *power_tol,
                                       bn_error *err);

typedef struct bn_crosscheck_input {
    const bn_scene *scene;             /* borrowed, meshed like the tracer's */
    const bn_trace_patches *trace;     /* borrowed: per patch, or per region of part */
    const bn_partition *part;          /* regions (borrowed; rad, tol per region), or NULL: per patch */
    const double *rad;                 /* radiosity layers, nlayers * N * 3 (bn_layers_stack) */
    const double *tol;                 /* discretisation tolerance, same layout, or NULL for none */
    const double *power_tol;           /* nlayers * 3 watts, or NULL */
    double tol_scale;                  /* multiplies tol and power_tol (default 1) */
    double rtol;                       /* a further relative allowance, |R| * rtol (default 0) */
    double alpha;                      /* family-wise false-failure rate (default 0.01) */
    int    worst;                      /* how many worst entries to keep (default 10) */
} bn_crosscheck_input;
void bn_crosscheck_input_default(bn_crosscheck_input *in);

typedef struct bn_crosscheck_entry {
    size_t patch;
    int    layer, channel;
    double radiosity, trace, se, tol;
    double z;          /* (radiosity - trace) / se (raw) */
    double z_excess;   /* max(0, |radiosity - trace| - tol) / se: what the verdict tests (0 when untested) */
    int    untested;   /* 1: too few nonzero samples for the t tail (few_hits); shown, not judged */
} bn_crosscheck_entry;

typedef struct bn_crosscheck_result {
    size_t family;           /* tests: patches x layers x channels */
    double alpha, alpha_each;   /* family-wise and per test (Sidak: 1 - (1 - alpha)^(1/family)) */
    double crit;             /* two-sided Student-t bound at alpha_each, dof spp - 1 */
    size_t within;           /* tests with z_excess <= crit */
    size_t within_raw;       /* tests with |z| <= crit (no discretisation allowance) */
    size_t few_hits;         /* entries with under 100 effective nonzero samples: within, not judged */
    double worst_z;          /* largest z_excess */
    double worst_z_raw;      /* largest |z| */
    int    nworst;
    bn_crosscheck_entry *worst;   /* nworst entries, largest z_excess first (owned) */
    int    nlayers;
    size_t *layer_within;    /* nlayers: tests within per layer (owned) */
    double *layer_worst_z;   /* nlayers: largest z_excess per layer (owned) */
    /* Power per layer (watts, per channel), both methods, and the test on it. */
    double *power_rad, *power_pt, *power_se, *power_tol;   /* nlayers * 3 each (owned) */
    size_t power_family;     /* layers x channels */
    double power_crit;       /* two-sided normal bound, Sidak over power_family */
    double power_worst_z;    /* largest max(0, |dP| - tol) / se */
    /* Per surface (material): area-weighted L of both methods, and the tracer's standard error. */
    size_t nsurfaces;
    double *surf_area;                  /* nsurfaces, m^2 (owned) */
    double *surf_rad, *surf_pt, *surf_se;   /* nsurfaces * 3 (owned) */
    int    pass;
} bn_crosscheck_result;

/* Compares; fills *out (free with bn_crosscheck_result_free). */
bn_status bn_crosscheck_compare(const bn_crosscheck_input *in, bn_crosscheck_result *out, bn_error *err);
void bn_crosscheck_result_free(bn_crosscheck_result *r);
/* Prints the report: per-layer shares, worst entries, power and per-surface tables, and the
 * machine-readable verdict line, last:
 * `verdict: pass|fail alpha=A family=F crit=C within=W/F worst_z=Z ... power_worst_z=P`. */
void bn_crosscheck_print(const bn_crosscheck_input *in, const bn_crosscheck_result *r, FILE *fp);

/* Statistics helpers (exposed for tests): the upper-tail quantile of the standard normal and of
 * Student's t with `dof` degrees of freedom: returns x with P(X > x) = p, for p in (0, 0.5]. */
double bn_normal_quantile_upper(double p);
double bn_student_t_quantile_upper(double p, double dof);

#ifdef __cplusplus
}
#endif
#endif
