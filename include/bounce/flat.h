/* bounce: a C API of plain types for bindings (the Python package in python/bounce, through
 * ctypes): one call solves a scene file, accessors hand out the library's own arrays (no copies),
 * errors come back as a status and a message. */
#ifndef BOUNCE_FLAT_H
#define BOUNCE_FLAT_H

#include <stddef.h>
#include <stdint.h>
#include "bounce/status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct bn_flat bn_flat;   /* a solved scene: patches, K's report, L, the terms, rest */

/* Options by name, as on the command line. Start from bn_flat_opts_default (the library's defaults);
 * NULL names and 0 counts (patches, patch_size, threads) mean the default. Every value is checked
 * before any work: out of range is BN_EUSAGE naming the option and the value. */
typedef struct bn_flat_opts {
    const char *unit;         /* "m" (default), "cm", "mm" */
    const char *method;       /* "auto" (default), "jacobi", "gauss-seidel", "neumann", "direct" */
    const char *transport;    /* one of bn_pipeline_transports(): "auto" (default), "dense", "sparse", "hierarchical" */
    int bounces;              /* terms kept: K^0 E .. K^bounces E (default 3; at most 1000; < 0: none) */
    double tol;               /* solver tolerance, relative, > 0 (default 1e-6) */
    size_t patches;           /* target patch count (default: as `bounce solve`) */
    double patch_size;        /* largest patch edge, scene units (overrides patches) */
    double eps;               /* hierarchy eps, >= 0 (default 1e-3) */
    int threads;              /* 0: all cores */
    int quiet;                /* no progress bars (default 1 here: 0 shows them on stderr) */
    int sigint;               /* 1: while the call runs, SIGINT stops bounce's loops (the call returns
                                 BN_EINTR) and the caller's handler is restored after; for
                                 interpreters whose own handler runs only between their steps
                                 (Python's). Default 0: signals are the caller's business */
    const char *visibility;   /* partly occluded pairs' form factors: "exact" (default) or "rays" (as
                                 `--ff-visibility`; the hierarchy's links above the patches always
                                 take rays) */
    /* The command line's other solve options, by the same names (0 / NULL: their defaults). */
    size_t max_iter;          /* --max-iter (default 100000) */
    double atol;              /* --atol, absolute tolerance (default 0) */
    const char *stop;         /* --stop: one of bn_flat_names("stop") */
    uint64_t seed;            /* --seed: every sampled quantity (0: the default, 1) */
    const char *precision;    /* --precision: "auto" (default) or one of bn_flat_names("precision") */
    const char *storage;      /* --storage: one of bn_flat_names("storage") (the transport's when given) */
    const char *cache;        /* --cache FILE: dense and sparse F read from it when its key matches, else
                                 written to it (NULL: none) */
    const char *ff;           /* --ff: one of bn_flat_names("ff") (default analytic) */
    const char *more;         /* the command line's further scene, form-factor and solve options by their
                                 field names, one `name=value` per line ("no_contacts=1\ncontact_gap=0.5";
                                 flags 0 or 1, vectors x,y,z); the names: bn_flat_names("scene_options")
                                 (read where the scene is loaded) and bn_flat_names("solve_options");
                                 ranges as the command line's. NULL: none */
} bn_flat_opts;
void bn_flat_opts_default(bn_flat_opts *o);
/* sizeof(bn_flat_opts) in this library: a binding that lays the struct out itself (Python's ctypes)
 * compares it with its own before the first call, so a field added on one side fails loudly. */
size_t bn_flat_opts_size(void);
/* The names of a vocabulary, "|"-separated, by the parameter that takes them: "method", "transport",
 * "storage", "precision", "ff", "visibility", "unit", "stop", "mesh", "gather", "strategy", "model";
 * NULL for another word. Bindings offer these, not copies of their own. */
const char *bn_flat_names(const char *vocabulary);

/* Loads, meshes, builds K and solves `path`. On failure *out is NULL, the status is returned and
 * msg (msglen bytes) holds bounce's message. BN_ENOTCONV keeps the unconverged answer in *out. */
bn_status bn_flat_solve(const char *path, const bn_flat_opts *o, bn_flat **out, char *msg, size_t msglen);
void bn_flat_free(bn_flat *f);   /* NULL is a no-op */

size_t bn_flat_patches(const bn_flat *f);
int bn_flat_terms(const bn_flat *f);                        /* terms kept (bounces + 1, or 0) */
const double *bn_flat_L(const bn_flat *f);                  /* N x 3, owned by f */
const double *bn_flat_term(const bn_flat *f, int k);        /* N x 3: K^k E, or NULL past the last */
const double *bn_flat_rest(const bn_flat *f);               /* N x 3: L - the kept terms, or NULL */
const double *bn_flat_emission(const bn_flat *f);           /* N x 3 */
/* Per-patch geometry and materials, written into caller arrays: area (N), normal (N x 3),
 * centroid (N x 3), reflectance (N x 3), face (N, the input polygon's index); any may be NULL. */
void bn_flat_patch_data(const bn_flat *f, double *area, double *normal, double *centroid, double *reflectance,
                        size_t *face);
const char *bn_flat_stop_reason(const bn_flat *f);         /* "converged-rtol", ... */
const char *bn_flat_method(const bn_flat *f);              /* the solver that ran */
size_t bn_flat_iterations(const bn_flat *f);
double bn_flat_residual(const bn_flat *f);                  /* final max residual */
const char *bn_flat_transport(const bn_flat *f);           /* "dense", "sparse" or "hierarchical" */
/* The solver's monitor, one row per iteration (row 0: the initial guess E), BN_FLAT_HISTORY values
 * each: iteration, residual_max, residual_rms, change, bound, error_bound, seconds. *rows (may be
 * NULL) gets the array, owned by f; returns the row count. */
#define BN_FLAT_HISTORY 7
size_t bn_flat_history(const bn_flat *f, const double **rows);

/* Loads and meshes `path` only (no K, no solve): the patch accessors and bn_flat_emission work,
 * L and the terms are NULL until bn_flat_operator and a solve. */
bn_status bn_flat_load(const char *path, const bn_flat_opts *o, bn_flat **out, char *msg, size_t msglen);
/* Builds K for a loaded scene (no-op when built): then bn_flat_form_factors and the diagnostics. */
bn_status bn_flat_operator(bn_flat *f, char *msg, size_t msglen);
/* Solves a loaded scene on its own K (built first when it is not): o's solver options are taken
 * (method, bounces, tol, atol, max_iter, stop, threads, quiet; checked as bn_flat_solve checks them), the
 * scene's loading, meshing and form-factor options (seed, precision, storage, cache, ff) stay as loaded. Solving again replaces the answer and reuses K. */
bn_status bn_flat_solve_loaded(bn_flat *f, const bn_flat_opts *o, char *msg, size_t msglen);
/* The form factors' diagnostics, in this order (NAN where K is not built): row_sum_min, row_sum_max,
 * row_sum_rms_dev, reciprocity_residual, k_norm_inf, occluded_fraction, rays, nonzeros, bytes,
 * seconds, rows_above_one, row_sum_tol (12 values). */
void bn_flat_ff_diagnostics(const bn_flat *f, double out[12]);

/* F of a solved scene as a row-major N x N array of doubles (caller allocates N*N): the stored
 * values (float storage gives float values). BN_ENOTSUP under the hierarchy, which keeps no pairs. */
bn_status bn_flat_form_factors(const bn_flat *f, double *F, char *msg, size_t msglen);

/* F's nonzero stored entries as compressed sparse rows, without a dense copy (the hierarchy keeps no
 * pairs: BN_ENOTSUP): indptr (N + 1) is filled, *nnz set to the entries' count; with indices and data
 * (room for *nnz on entry) they are filled too. Call once without them to learn the size. */
bn_status bn_flat_form_factors_csr(const bn_flat *f, size_t *indptr, size_t *indices, double *data, size_t *nnz,
                                   char *msg, size_t msglen);
/* y = K x (with_rho 1) or y = F x (0), N x 3 interleaved; x and y distinct. Any operator, the hierarchy's
 * too (a scipy LinearOperator, a solver of the caller's). */
bn_status bn_flat_apply(const bn_flat *f, int with_rho, const double *x, double *y, char *msg, size_t msglen);

/* Relights a solved scene in place on its own F (bn_pipeline_relight): n materials by name, each with
 * a new reflectance (rho, n x 3) and/or emitted radiance (Le, n x 3; W m^-2 sr^-1); either array may be
 * NULL, and a row of three NaN leaves that material's value as it is. Every term, rest and L are solved
 * again (the arrays handed out before are freed: take them again). refine: under the hierarchy, new
 * links for the new light (else the old ones, frozen). Unknown names, rho outside [0, 1], Le negative
 * or not finite: BN_EUSAGE naming them, nothing changed. On a solve's failure f keeps the edits and
 * no answer (BN_ENOTCONV: the unconverged one). */
bn_status bn_flat_relight(bn_flat *f, size_t n, const char *const *materials, const double *rho, const double *Le,
                          int refine, char *msg, size_t msglen);
/* The largest ratio of the relit L to the one before (patches and channels); 0 before any relight. */
double bn_flat_relight_gain(const bn_flat *f);

/* Bakes the solution to vertex colours as `bounce bake` does: out by extension (.ply, .om, .obj,
 * .glb, .gltf); per_bounce adds every term; mesh: a bn_flat_names("mesh") name, "elements" (NULL,
 * the default: the patches) or "input" (the scene's polygons);
 * ldr: 8-bit sRGB colours (glTF: the COLOR_1 set beside); exposure_ev: NAN or inf for automatic;
 * crease_deg <= 0: the default 30; gather: a bn_flat_names("gather") name, "final" (NULL, the default:
 * each vertex by the final gather, the element mesh refined where L changes up to `vertices` vertices,
 * < 0: BN_BAKE_DEFAULT_VERTICES, 0: the patches' vertices; bn_pipeline_bake_gather; the input mesh
 * gathered at its own vertices) or "none" (the patches' values). Provenance names the caller ("python" for the package). */
bn_status bn_flat_bake(const bn_flat *f, const char *out, int per_bounce, const char *mesh, int ldr, double exposure_ev,
                       double crease_deg, const char *gather, long long vertices, const char *caller, char *msg,
                       size_t msglen);

/* The images' and the bake's further options for the next calls (bn_flat_images, bn_flat_render,
 * bn_flat_bake) as bn_flat_opts.more gives the solve's: `name=value` lines, the names
 * bn_flat_names("image_options") (light_samples, gather_samples, gather_filter, hit_emitters,
 * tree_emitters, tile, exposure, crease, up) and bn_flat_names("bake_options") (gather_rays, bake_tol,
 * flat, no_colour_sets), as `bounce bounces` and `bounce bake` take them. Every call starts from the
 * defaults: the options not given are reset. BN_EUSAGE naming a bad name or value (nothing set). */
bn_status bn_flat_set(bn_flat *f, const char *more, char *msg, size_t msglen);

/* Camera images of every layer as `bounce bounces` writes them: out (FILE.exr, one layer per term,
 * rest and L) and, with previews, FILE.<layer>.png and the contact sheet. The camera is the scene's
 * NAME.camera sidecar, else the default in front of the box; eye, look (3 each) and fov_deg > 0
 * override it; width, height, spp > 0 override its size and supersampling. gather: a
 * bn_flat_names("gather") name, "final" (NULL, the default: the final gather per pixel,
 * bounce/gather.h; needs a solve keeping KE) or "none" (the value of the patch each pixel sees). */
bn_status bn_flat_images(const bn_flat *f, const char *out, int width, int height, int spp, const double *eye,
                         const double *look, double fov_deg, int previews, int smooth, int half, const char *gather,
                         const char *caller, char *msg, size_t msglen);

/* The same images in memory, no file: out has room for bn_flat_layers(f) x height x width x 3 floats
 * (layer-major, rows from the top, RGB; radiance, W m^-2 sr^-1); width and height must be given. */
bn_status bn_flat_render(const bn_flat *f, int width, int height, int spp, const double *eye, const double *look,
                         double fov_deg, int smooth, const char *gather, float *out, char *msg, size_t msglen);
/* The layers of a solution (terms, rest, L: bounces + 3; 0 without terms) and layer l's name ("E", "KE",
 * "K2E", ..., "rest", "L") into buf (NULL past the last). */
int bn_flat_layers(const bn_flat *f);
const char *bn_flat_layer_name(const bn_flat *f, int layer, char *buf, size_t size);

/* The path tracer on f's scene (loaded or solved; it shares the scene and the ray scene only, never F,
 * K or the solve: bounce's independent cross-check). Layers E .. K^bounces E, rest, L (bounces + 3), spp
 * samples each, seed keys the streams; results are the same for any thread count.
 * bn_flat_trace_patches: each patch's mean outgoing radiance and its standard error, mean and se with room
 * for (bounces + 3) x patches x 3 doubles (layer-major). bn_flat_trace_image: the camera (the scene's
 * sidecar or default; eye, look may be NULL, fov_deg <= 0 keeps it) per pixel, mean and the variance of
 * the mean, (bounces + 3) x height x width x 3 floats each, rows from the top. */
bn_status bn_flat_trace_patches(bn_flat *f, size_t spp, int bounces, uint64_t seed, int threads, double *mean,
                                double *se, char *msg, size_t msglen);
bn_status bn_flat_trace_image(bn_flat *f, int width, int height, size_t spp, int bounces, uint64_t seed,
                              const double *eye, const double *look, double fov_deg, int threads, float *mean,
                              float *var, char *msg, size_t msglen);

/* `bounce crosscheck` on the scene file at path (o: the load, mesh and form-factor options; o->seed
 * also keys the tracer): radiosity solved to 1e-10 against the path tracer at spp samples per patch
 * (0: 1024), terms E .. K^bounces E, rest and L compared per patch and channel at the family-wise
 * false-failure rate alpha (0: 0.01); model "patch" (the default: the tracer estimates the
 * patch-constant transport, no allowance) or "continuous" (with a second mesh level's allowance). */
typedef struct bn_flat_check bn_flat_check;
bn_status bn_flat_crosscheck(const char *path, const bn_flat_opts *o, size_t spp, int bounces, double alpha,
                             const char *model, bn_flat_check **out, char *msg, size_t msglen);
void bn_flat_check_free(bn_flat_check *c);   /* NULL is a no-op */
int bn_flat_check_pass(const bn_flat_check *c);
int bn_flat_check_layers(const bn_flat_check *c);        /* bounces + 3 */
size_t bn_flat_check_entries(const bn_flat_check *c);    /* patches (or regions, for large scenes) */
/* family, alpha, crit, within, worst_z, worst_z_raw, power_crit, power_worst_z, few_hits, spp, seconds */
#define BN_FLAT_CHECK_FIGURES 11
void bn_flat_check_figures(const bn_flat_check *c, double out[BN_FLAT_CHECK_FIGURES]);
/* layers x entries x 3 each (any may be NULL): radiosity, the tracer's mean and standard error, and the
 * allowance for what the two estimate differently (0 where none). */
void bn_flat_check_arrays(const bn_flat_check *c, double *rad, double *trace, double *se, double *tol);

/* `bounce study` on the scene file at path: vary one of bn_study_param_names() ("bounces", "tol",
 * "patches", "eps", ...) over values (ff and precision: the index of the name in their vocabulary), every
 * other setting from o (method: the study's default, direct, unless named). Rows: one per setting (and
 * per method where the study compares methods), BN_FLAT_STUDY_COLUMNS numbers each (NAN where a figure
 * does not apply), with the method ("truncated", "jacobi", ...) and the value as given. */
typedef struct bn_flat_study bn_flat_study;
#define BN_FLAT_STUDY_COLUMNS                                                                                    \
    "x,patches,k_entries,k_mb,iterations,ground,err_inf,err_inf_rel,err_max_rel,err_rms_rel,err_l1_rel,"       \
    "err_energy_rel,err_surface_max,err_surface_mean,bound,bound_ke,estimate,t_mesh,t_ff,t_solve,t_output,"  \
    "t_total,peak_mb,k_norm,se_surface_max,t_iterate"
#define BN_FLAT_STUDY_NCOLUMNS 26
bn_status bn_flat_study_run(const char *path, const bn_flat_opts *o, const char *vary, const double *values, size_t n,
                            bn_flat_study **out, char *msg, size_t msglen);
void bn_flat_study_free(bn_flat_study *s);   /* NULL is a no-op */
const char *bn_flat_study_columns(void);     /* BN_FLAT_STUDY_COLUMNS */
size_t bn_flat_study_rows(const bn_flat_study *s);
void bn_flat_study_row(const bn_flat_study *s, size_t r, double out[BN_FLAT_STUDY_NCOLUMNS]);
const char *bn_flat_study_label(const bn_flat_study *s, size_t r, int value);   /* 0: method, 1: value */
/* What the settings were measured against, and its estimated error (relative, per surface). */
const char *bn_flat_study_reference(const bn_flat_study *s, double *ref_error);

/* A caller's own operator: apply(user, x, y) sets y = K x for N x 3 interleaved x (no aliasing)
 * and returns 0, or nonzero to stop the solve (BN_EINPUT, "the operator failed"). */
typedef int (*bn_flat_apply_fn)(void *user, const double *x, double *y);
/* Optional: out[c] = (K x)_i for one patch i (Gauss-Seidel's rows); 0, or nonzero to stop. */
typedef int (*bn_flat_row_fn)(void *user, size_t i, const double *x, double *out);
/* Solves L = E + K L with K given by apply (Jacobi, the Neumann series and the terms need only
 * y = K x) and row (may be NULL; with it Gauss-Seidel too; method "auto" is then Gauss-Seidel, else
 * Jacobi; the direct solve needs entries and is refused). n patches, E (N x 3) copied. The result
 * has no scene: bn_flat_patch_data leaves its arrays untouched. */
bn_status bn_flat_solve_operator(size_t n, const double *E, bn_flat_apply_fn apply, bn_flat_row_fn row, void *user,
                                 const bn_flat_opts *o, bn_flat **out, char *msg, size_t msglen);

#ifdef __cplusplus
}
#endif
#endif
