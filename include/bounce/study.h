/* bounce: speed-accuracy studies. One parameter is varied over a list of settings; each setting's
 * answer is measured against a stated, more accurate reference (whose own error is estimated), with
 * the time of each phase, the peak memory and, for the truncated series, the a priori bound.
 *
 * Errors are measured on common ground: per patch when the setting and the reference share the
 * mesh; otherwise per patch of the reference (each reference patch looks up the setting's patch in
 * the same face that contains its centroid; a finer setting gives each reference patch the area
 * mean of its patches whose centroids fall in it), and per surface (material) as area-weighted means.
 * Radiance is W m^-2 sr^-1; norms and sums are in double. */
#ifndef BOUNCE_STUDY_H
#define BOUNCE_STUDY_H

#include <stddef.h>
#include <stdio.h>
#include "bounce/scene.h"
#include "bounce/formfactor.h"
#include "bounce/hierarchy.h"
#include "bounce/solve.h"
#include "bounce/trace.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The parameter a study varies, named as the option it varies. */
typedef enum bn_study_param {
    BN_STUDY_BOUNCES,     /* n of the truncated series S_n = sum_{k<=n} K^k E; plus the methods table */
    BN_STUDY_MAX_ITER,    /* iteration limit of each iterative method */
    BN_STUDY_TOL,         /* tolerance: time and iterations of every method to reach it */
    BN_STUDY_PATCHES,     /* target patch count (re-mesh, form factors, solve) */
    BN_STUDY_PATCH_SIZE,  /* largest patch edge, scene units */
    BN_STUDY_SAMPLES,     /* form-factor samples (shadow rays per pair, point pairs, hemisphere rays) */
    BN_STUDY_FF,          /* form-factor method: values are bn_ff_method */
    BN_STUDY_SPP,         /* path-tracer samples per patch */
    BN_STUDY_PRECISION,   /* storage precision of F: values are bn_precision */
    BN_STUDY_EPS          /* the hierarchy's link tolerance (K_H on the fixed mesh against dense K) */
} bn_study_param;
#define BN_STUDY_PARAM_COUNT 10
const char *bn_study_param_name(bn_study_param v);
const char *bn_study_param_names(void);   /* "bounces|max-iter|tol|..." */
int bn_study_param_parse(const char *s, bn_study_param *out);   /* 0, or -1 for no such name */

/* What the patches, patch-size and spp studies compare with. */
typedef enum bn_study_ref {
    BN_STUDY_REF_AUTO,       /* the tracer when the equal-error comparison runs, else radiosity */
    BN_STUDY_REF_RADIOSITY,  /* a direct solve on a finer mesh (ref_patches) */
    BN_STUDY_REF_TRACE       /* the path tracer at ref_spp with an independent seed: unbiased for the
                                per-surface means, its error = 2 standard errors (~95%) */
} bn_study_ref;
const char *bn_study_ref_name(bn_study_ref v);
const char *bn_study_ref_names(void);   /* "auto|radiosity|trace" */
int bn_study_ref_parse(const char *s, bn_study_ref *out);   /* 0, or -1 for no such name */

/* The equal-error target's metric (bn_study_opts.metric_patch is one of these). */
typedef enum bn_study_metric {
    BN_STUDY_METRIC_SURFACE,   /* per-surface relative error, err_surface_max */
    BN_STUDY_METRIC_PATCH      /* RMS relative error per patch, err_rms_rel */
} bn_study_metric;
const char *bn_study_metric_name(bn_study_metric v);
const char *bn_study_metric_names(void);   /* "surface|patch" */
int bn_study_metric_parse(const char *s, bn_study_metric *out);   /* 0, or -1 for no such name */

/* Method bits for the solver comparisons (bit = 1 << bn_solve_method). */
#define BN_STUDY_ALL_METHODS 0xF

typedef struct bn_study_opts {
    bn_study_param param;
    const double *values;        /* nvalues settings (borrowed); ff: bn_ff_method, precision: bn_precision */
    size_t nvalues;
    bn_load_opts load;           /* how the scene file is read */
    bn_mesh_opts mesh;           /* fixed meshing (the varied one overrides) */
    bn_formfactor_opts ff;       /* fixed form-factor options */
    const char *transport;       /* K of every setting: NULL or "dense"/"sparse" (ff.storage), "hierarchical"
                                    (K_H with hier; solved by jacobi to 1e-10 where the method needs what K_H
                                    lacks); references stay dense. The eps study is always hierarchical. */
    bn_hierarchy_opts hier;
    bn_solve_opts solve;         /* fixed solve options; method used for mesh, samples, ff and precision
                                    settings (default direct: no iteration error mixed in) */
    bn_trace_opts trace;         /* spp settings and the equal-error comparison */
    unsigned methods;            /* bounces, max-iter, tol: methods compared (bits; default all four) */
    const double *tols;          /* bounces: the tolerances of the methods table (default 1e-2 .. 1e-8) */
    size_t ntols;
    size_t ref_patches;          /* patches, patch-size, spp: reference mesh (0: 4x the finest setting's
                                    patch count, or 4x the fixed mesh's for spp) */
    bn_study_ref ref;            /* default auto */
    size_t ref_spp;              /* trace reference: spp (0: a 64-spp pilot, scaled so that the largest
                                    per-surface standard error is target / 8, at most 65536) */
    int    ref_samples;          /* samples, ff: shadow rays of the analytic reference (0: 8x the largest
                                    setting, at least 256) */
    const size_t *against_spp;   /* patches, patch-size, eps: path-tracer runs for the equal-error comparison
                                    (eps: the reference is then the tracer on the study's mesh) */
    size_t nagainst;
    double target;               /* equal-error target: per-surface relative error (default 0.01) */
    int    metric_patch;         /* 1: the equal-error target is on err_rms_rel (RMS relative error per
                                    patch, on the reference's patches) instead of err_surface_max; the
                                    tracer's runs are on the reference's mesh, and a tracer reference's
                                    pilot aims at a per-patch standard error of target / 4 */
    bn_log log;                  /* progress notes (one per setting) */
    int threads;                 /* every phase's threads (0: the caller's); results do not depend on it */
} bn_study_opts;
void bn_study_opts_default(bn_study_opts *o);

#define BN_STUDY_LABEL 32
/* One measured setting (or one method at one tolerance). NAN where a figure does not apply. */
typedef struct bn_study_row {
    char   method[BN_STUDY_LABEL];   /* "truncated", "jacobi", "gauss-seidel", "neumann", "direct", "trace" */
    char   value[BN_STUDY_LABEL];    /* the setting as given ("20", "1e-06", "analytic", "float") */
    double x;                        /* the setting as a number (ff, precision: 0, 1, 2 by index) */
    size_t patches;
    size_t k_entries;                /* stored entries of F (dense, sparse) or links (hierarchy); 0 n/a */
    double k_mb;                     /* K's memory, MiB (0 n/a) */
    size_t iterations;               /* sweeps, bounces or K applications (0 for direct) */
    int    ground;                   /* 0: same mesh as the reference, 1: reference patches by centroid,
                                        2: area means of a finer setting's patches over each reference patch */
    double err_inf;                  /* ||L - L_ref||_inf over patches and channels, W m^-2 sr^-1 */
    double err_inf_rel;              /* err_inf / ||L_ref||_inf */
    double err_max_rel, err_rms_rel; /* per patch and channel e = |L - L_ref| / max(|L_ref|, mean L_ref):
                                        the largest, and the area-weighted RMS (L2) */
    double err_l1_rel;               /* the area-weighted mean of e (L1) */
    double err_energy_rel;           /* reflected power pi sum A (L - E), max over channels */
    double err_surface_max;          /* max over surfaces (and channels) of the area-weighted mean's error */
    double err_surface_mean;         /* mean over surfaces */
    double *err_surface;             /* nsurfaces: per-surface relative error (owned by the result) */
    double bound;                    /* a priori ||K||^(n+1) / (1 - ||K||) ||E||_inf (bounces, max-iter) */
    double bound_ke;                 /* the same bound from the first reflection, ||K||^n / (1 - ||K||) ||KE||_inf:
                                        also rigorous, and tighter when the emitters dominate ||E|| */
    double estimate;                 /* bounces: rho(K) / (1 - rho(K)) ||K^n E||_inf; max-iter: rho(K)^(k+1) /
                                        (1 - rho(K)) ||E||_inf: spectral estimates (not bounds) */
    double t_mesh, t_ff, t_solve, t_output, t_total;   /* seconds */
    double peak_mb;                  /* peak resident memory during the setting, MiB */
    double k_norm;                   /* ||K||_inf of the setting's K (NAN for the tracer) */
    double se_surface_max;           /* trace: largest per-surface standard error, relative */
    double t_iterate;                /* the solver's sweeps (or factorisation) alone, without bn_solve's
                                        analysis of K (norm, power iteration) that t_solve includes */
} bn_study_row;

/* An error history against time (a line of the error-vs-time plot). */
typedef struct bn_study_curve {
    char   label[BN_STUDY_LABEL];
    size_t n;
    double *t, *err;   /* seconds, relative error (owned) */
} bn_study_curve;

typedef struct bn_study_result {
    bn_study_param param;
    size_t nrows;
    bn_study_row *rows;              /* owned */
    size_t nsurfaces;
    char (*surface)[BN_NAME_MAX];    /* material names (owned) */
    double *surface_area;            /* m^2 (owned) */
    double *ref_surface_mean;        /* the reference's area-weighted mean radiance per surface, nsurfaces*3
                                        (extrapolated in mesh studies; owned; NULL when not measured) */
    char   reference[256];           /* what the reference is */
    double ref_error;                /* its estimated error, in the err_surface_max metric (relative) */
    double ref_error_patch;          /* in the err_max_rel metric */
    char   ref_error_how[512];       /* how that estimate was made */
    double ref_order;                /* mesh studies: the convergence order fitted by Richardson extrapolation
                                        (NAN when the reference is not extrapolated) */
    double ref_error_raw;            /* mesh studies: the unextrapolated reference's error (per surface) */
    size_t ref_patches;
    double ref_seconds;
    double norm_E, norm_L;           /* ||E||_inf, ||L_ref||_inf */
    double k_norm, spectral_radius;  /* of the fixed-mesh K (bounces, max-iter, tol) */
    size_t ncurves;
    bn_study_curve *curves;          /* owned */
    /* The equal-error comparison (patches/patch-size/eps with against_spp): seconds to reach `target`
     * in err_surface_max (err_rms_rel with metric_patch), by log-log interpolation; NAN when a method
     * never reached it. */
    double target, t_radiosity, t_trace, ratio;   /* ratio = t_trace / t_radiosity */
    int    metric_patch;                          /* the target is on err_rms_rel (opts) */
    double best_radiosity, best_trace;            /* smallest error each reached */
    /* The same at the finest error the reference allows: 3x its own estimated error. */
    double fine_target, t_radiosity_fine, t_trace_fine, ratio_fine;
} bn_study_result;

/* Runs the study on the scene file `path`. Fills *res (free with bn_study_result_free). */
bn_status bn_study_run(const char *path, const bn_study_opts *o, bn_study_result *res, bn_error *err);
void bn_study_result_free(bn_study_result *res);   /* NULL or zeroed is a no-op */

/* The fixed columns of the CSV; per-surface columns `err_surf_<material>` follow. */
#define BN_STUDY_CSV_COLUMNS                                                                              \
    "param,method,value,x,patches,iterations,ground,err_inf,err_inf_rel,err_max_rel,err_rms_rel,err_l1_rel," \
    "err_energy_rel,err_surface_max,err_surface_mean,bound,bound_ke,estimate,t_mesh,t_ff,t_solve,t_output,"       \
    "t_total,peak_mb,k_norm,se_surface_max,t_iterate,k_entries,k_mb"
/* Writes the rows as CSV: `provenance` ('#'-prefixed `key=value` lines, may be NULL), then the
 * study's own `# key=value` lines (reference, its error, norms), then the header and rows. Atomic. */
bn_status bn_study_write_csv(const bn_study_result *res, const char *path, const char *provenance, bn_error *err);
/* Plots to prefix.png and prefix.svg (PLplot; atomic): left, error against time (log-log, one
 * line per method); right, error against the varied parameter, with the bound and the spectral
 * estimate for the truncated series and the reference's own error drawn as a floor. */
bn_status bn_study_plot(const bn_study_result *res, const char *prefix, const char *title, bn_error *err);
/* One self-contained HTML page (no file or network beside it): how the study was made (the
 * provenance lines, the reference and its error, the fitted order), the table of every setting, and
 * both plot panels as inline SVG. Atomic. */
bn_status bn_study_write_report(const bn_study_result *res, const char *path, const char *provenance,
                                const char *title, bn_error *err);
/* A readable summary: reference, table, bound tightness, the equal-error verdict. */
void bn_study_print(const bn_study_result *res, FILE *fp);

#ifdef __cplusplus
}
#endif
#endif
