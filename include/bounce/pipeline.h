/* bounce: the pipeline from a scene file to a solved result with every bounce term, in stages
 * that each command, the study tool and the benchmarks share:
 *
 *   scene file --load, mesh--> patches --rt, form factors--> K --solve--> L, K^k E, rest
 *   (bn_pipeline_scene)               (bn_pipeline_operator)   (bn_pipeline_solve)
 *
 * bn_pipeline_run does all three. A caller may stop after any stage (info after the scene, the
 * form-factor command after the operator) or set options between stages (a log that names the
 * form factors' diagnostics). K's storage is whatever opts.ff names; nothing here depends on it. */
#ifndef BOUNCE_PIPELINE_H
#define BOUNCE_PIPELINE_H

#include <stddef.h>
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/transport.h"
#include "bounce/formfactor.h"
#include "bounce/hierarchy.h"
#include "bounce/solve.h"
#include "bounce/layers.h"
#include "bounce/trace.h"
#include "bounce/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct bn_pipeline_opts {
    bn_load_opts load;         /* how the file is read */
    bn_mesh_opts mesh;         /* how it is cut into patches */
    const char *transport;     /* how K is made: "dense" or "sparse" (form factors of every pair, kept
                                  so: overrides ff.storage), "hierarchical" (bn_hierarchy_build), "auto"
                                  (hierarchical when dense F would not fit in memory or the scene has
                                  more than BN_AUTO_HIERARCHY_PATCHES patches; says which and why);
                                  NULL: ff.storage */
    bn_formfactor_opts ff;     /* how F is assembled and stored (and cached); the hierarchy's leaf links */
    bn_hierarchy_opts hier;    /* the hierarchy's options (its ff, threads and log are set from the above) */
    bn_solve_opts solve;       /* method, tolerance, terms kept (solve.bounces) */
    int threads;               /* every stage's threads (0: the caller's), unless ff or solve set their own */
    int mesh_auto;             /* mesh is a default: when K is the hierarchy, re-mesh aiming at the input
                                  polygons + BN_HIERARCHY_EXTRA_PATCHES patches (the target of the faces
                                  it splits) */
    int method_auto;           /* solve.method is a default: gauss-seidel where K has rows, else jacobi
                                  (said in a note) */
    int keep_rt;               /* keep the ray scene for images and the tracer (built even when F
                                  comes from the cache); else it is released after F */
    int auto_precision;        /* choose F's precision by need (default 1): double when float's rounding,
                                  2^-24 amplified by 1 / (1 - rho_max), would exceed solve.tol, else
                                  ff.precision (said in a note); 0 keeps ff.precision as given */
    int tie_threshold;         /* raise solve.singular_threshold to F's measured row-sum excess
                                  (default 1: no row of F can sum above 1, so the excess is a
                                  measured part of F's error, and 1 - ||K|| below it leaves no
                                  accuracy) */
    int row_sum_rays;          /* the row-sum check after K is built (bn_ff_row_sum_check): rays per row
                                  (default 256) on at most BN_PIPELINE_ROW_SUM_ROWS rows; 0: none */
} bn_pipeline_opts;
#define BN_PIPELINE_ROW_SUM_ROWS 4096
void bn_pipeline_opts_default(bn_pipeline_opts *o);
/* Every option in range, before any work: threads, patch size and count, eps, transport and the
 * solver's (bn_solve_opts_check). BN_EUSAGE naming the option by its field name and its value.
 * bn_pipeline_scene calls it first; the patch count's memory (terms, dense F) is checked once the
 * faces are known, before meshing or K. */
bn_status bn_pipeline_opts_check(const bn_pipeline_opts *o, bn_error *err);
#define BN_PIPELINE_MAX_PATCHES 1000000000   /* the mesher refuses more (1e9) */
#define BN_AUTO_HIERARCHY_PATCHES 6000
/* The transport names, "|"-separated, for help texts: "auto|dense|sparse|hierarchical". */
const char *bn_pipeline_transports(void);
/* 1 if name is one of them. */
int bn_pipeline_transport_exists(const char *name);
/* Would `transport` (may be NULL or "auto") be the hierarchy for a scene of n patches, given the
 * form-factor options? why (may be NULL) receives the reason. */
int bn_pipeline_use_hierarchy(const bn_pipeline_opts *o, size_t n, char *why, size_t why_size);

/* What the stages made; everything is owned and released by bn_pipeline_free. */
typedef struct bn_pipeline {
    bn_scene *scene;           /* loaded and meshed */
    bn_rt *rt;                 /* NULL unless keep_rt */
    bn_transport *k;           /* K = diag(rho) F */
    bn_ff_diagnostics ff;      /* the assembly's report (or the cache's); for the hierarchy: n, row sums,
                                  k_norm_inf, nonzeros (links), rays, bytes, seconds */
    int hierarchical;          /* K is the hierarchy; hier is its report */
    bn_hierarchy_report hier;
    bn_row_sum_check rows;     /* F's row sums against the exact ones (rows.rows 0: not checked) */
    double *row_exact;         /* rows.rows values: the checked rows' exact sums (the balance's escape) */
    size_t nemit, *emit_patch; /* the emitting patches, and their exact row sums by many rays (emit_rays each) */
    double *emit_exact;
    int emit_rays;
    /* The energy balance after the solve (rows checked): pi sum_i A_i (F L)_i, the power arriving
     * at surfaces, against pi sum_j A_j e_j L_j, the power leaving them towards surfaces (e_j: row j's
     * exact sum); equal for any exact F (reciprocity). Per channel, W; balance: their difference
     * over the emitted power (+: the operator makes light, -: it loses it). balance_se: its standard
     * error from the rays that estimate the escaping light (binomial per row, and the rows between
     * the checked ones); an exact F's balance is within a few of it. */
    double power_arriving[3], power_towards[3], power_emitted[3], balance[3], balance_se[3];
    double *E;                 /* N*3 emitted radiance */
    double *D;                 /* N*3 radiance the punctual lights give directly (bounce 1): rho x D_white */
    double *D_white;           /* N*3 the same for white patches (E / pi); both NULL: no punctual lights */
    bn_solve_result res;       /* L and the terms K^0 E .. K^b E (b = solve.bounces) */
    bn_solve_method method_used;  /* the solver that ran (method_auto may have chosen it) */
    double *rest;              /* N*3: L - sum of the kept terms (NULL when none are kept) */
    double *power;             /* N*3: the power iteration's last iterate (bn_solve_opts.power_start) */
    size_t n;                  /* patches */
    double singular_threshold; /* the threshold the solve used */
    double seconds_load, seconds_mesh, seconds_operator, seconds_solve;
    double seconds_relight;    /* the last bn_pipeline_relight's (0: none) */
    double relight_gain;       /* after a relight: the largest ratio of the new L to the old (patches, channels) */
} bn_pipeline;

/* Each stage reads what the earlier ones left in *p. A caller with a meshed scene of its own may
 * start at bn_pipeline_operator with p zeroed but for p->scene and p->n (bn_pipeline_free then
 * destroys that scene too, unless the caller takes it back by setting p->scene to NULL). */

/* Loads and meshes `path`. */
bn_status bn_pipeline_scene(const char *path, const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err);
/* The punctual lights' direct light on every patch of s, as the radiance a white patch reflects (E / pi,
 * N x 3, owned by the caller; times the patch's rho it is bounce 1's share): each patch's mean irradiance
 * with visibility (src/pipeline/punctual.c). *out is NULL when the scene has no punctual light. */
bn_status bn_punctual_direct(const bn_scene *s, const bn_rt *rt, int threads, double **out, bn_error *err);
/* Builds the ray scene, the punctual lights' direct light (p->D) and K for p->scene; fills p->ff. */
bn_status bn_pipeline_operator(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err);
/* The method the solve stage will use (after bn_pipeline_operator): solve.method, or under method_auto
 * jacobi in place of gauss-seidel when K has no rows. */
bn_solve_method bn_pipeline_method(const bn_pipeline_opts *o, const bn_pipeline *p);
/* Solves (I - K) L = E keeping the terms, and rest. On BN_ENOTCONV the answer is kept (the caller
 * decides whether an unconverged answer is a result). */
bn_status bn_pipeline_solve(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err);
/* Relights a solved p: applies the material edits (bn_scene_edit_materials: new rho, new Le) and solves
 * again on the same F, K = diag(rho') F, for E' (and the punctual lights' bounce 1 times rho'), every kept
 * term and rest anew; no form factor is computed. Dense and sparse F give exactly the answer of a fresh
 * solve of the edited scene. The hierarchy's links were refined for the old light: relit on them, the
 * answer is exactly a fresh solve on those links, and their error bound was held for the old
 * brightness (a note says by how much the new L exceeds the old: the bound scales with it there);
 * refine 1 builds new links for the new light instead (the ray scene is made again; dense and sparse
 * ignore it). On failure the scene may hold the edits and p no answer. */
bn_status bn_pipeline_relight(const bn_pipeline_opts *o, bn_pipeline *p, const bn_material_edit *e, size_t n,
                              int refine, bn_error *err);
/* The three stages. */
bn_status bn_pipeline_run(const char *path, const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err);
void bn_pipeline_free(bn_pipeline *p);

/* The solver's settings as one provenance line: "gauss-seidel tol=1e-06 max_iter=100000:
 * converged-rtol after 10 iterations, residual 7.3e-06". */
void bn_pipeline_describe_solve(const bn_pipeline_opts *o, const bn_pipeline *p, char *buf, size_t size);

/* ---- the per-bounce images of a solution (src/pipeline/bounces.c): the image stage of
 * `bounce bounces`, above the gather, the bake and the image writers ---- */

typedef struct bn_bounces_opts {
    const char *output;        /* FILE.exr; previews FILE.<layer>.png and FILE.sheet.png beside it */
    int    half;               /* EXR in half floats */
    int    previews;           /* write the PNGs and the contact sheet (default 1) */
    int    tile;               /* contact sheet tile width, pixels (default 320) */
    int    smooth;             /* interpolate baked vertex values (default 0: flat patches) */
    double crease;             /* smooth: faces whose normals differ by more are not blended (degrees) */
    int    auto_exposure;      /* preview exposure from L's 99th percentile (default 1); else `ev` */
    double ev;
    uint64_t seed;             /* pixel jitter, and the gather's samples */
    int    threads;            /* 0 = the caller's (all cores by default) */
    int    gather;             /* 1: a final gather per pixel (bounce/gather.h; needs bounces >= 1); 0: patch values */
    int    light_samples;      /* gather: shadow rays per emitting face per pixel sample */
    int    gather_samples;     /* gather: hemisphere rays per pixel sample */
    int    gather_filter;      /* gather: same-face filter radius of the gathered terms, pixels */
    int    hit_emitters;       /* gather: K^2 E's hits take KE from the emitters up to this many (bn_gather_opts) */
    int    tree_emitters;      /* gather: above this many emitting faces, picked from a light tree (bn_gather_opts) */
    int    quiet;              /* no progress bar */
    const bn_attr *attrs;      /* provenance for every file (borrowed); the first 4 go into PNG text */
    size_t nattrs;
    bn_log log;                /* one note per file written */
} bn_bounces_opts;
void bn_bounces_opts_default(bn_bounces_opts *o);

/* Renders every layer of a solution keeping terms E .. K^bounces E (layers[l], N*3 each, as
 * bn_layers_stack orders them: the terms, rest, L) through `cam` and writes the multi-layer EXR,
 * with the shading and the preview exposure added to `attrs`, then the previews and the contact
 * sheet. *ev_used (may be NULL) receives the preview exposure. Atomic per file. */
/* The images' memory of bn_bounces_write for a width x height camera and `bounces` terms (every
 * layer in float RGB), checked before any work: BN_ENOMEM naming the size, the layers and the limit
 * (max_memory; 0: 80% of physical memory) when above it, or when the product overflows. */
bn_status bn_bounces_check_memory(int width, int height, int bounces, size_t max_memory, bn_error *err);
/* ---- the live page (src/pipeline/live.c, `bounce view --live`): the viewer page with what a browser needs
 * to relight the solved scene itself: the patches, their materials and texture factors, the punctual
 * lights' direct light and F as links (bn_transport_links); its worker sums the series for the
 * materials' rho and Le the page's sliders set. ---- */
#define BN_LIVE_DEFAULT_BUDGET_MB 64   /* bounce view --live's default --budget (bn_pipeline_live_bytes) */
typedef struct bn_live_opts {
    int bounces;              /* terms E .. K^bounces E shown, then rest (default 5; 0 to 64) */
    const char *note;         /* what the page says about how it was built (may be NULL) */
    const bn_attr *attrs;     /* provenance (borrowed) */
    size_t nattrs;
} bn_live_opts;
void bn_live_opts_default(bn_live_opts *o);
/* The payload's bytes for p (F's links counted, not exported; the page embeds them base64, 4/3 as many). */
bn_status bn_pipeline_live_bytes(const bn_pipeline *p, size_t *bytes, bn_error *err);
/* Writes the live page for a solved (or only operated) p to `out` (atomic). */
bn_status bn_pipeline_live_write(const bn_pipeline *p, const bn_live_opts *o, const char *title, const char *out,
                                 bn_error *err);

/* ---- the gathered bake (src/pipeline/bake_gather.c): `bounce bake`'s and the flat API's ---- */
#include "bounce/bake.h"
typedef struct bn_bake_gather_opts {
    int gather_rays;          /* hemisphere rays per vertex (default BN_BAKE_GATHER_RAYS) */
    size_t max_vertices;      /* the refinement's vertex budget (default BN_BAKE_DEFAULT_VERTICES; 0: the
                                 patches' vertices as they are) */
    double tol;               /* the refinement's tolerance (default BN_BAKE_REFINE_TOL) */
    uint64_t seed;            /* default 1 */
    int threads, quiet;
    const bn_log *log;        /* the refinement's note (may be NULL) */
} bn_bake_gather_opts;
void bn_bake_gather_opts_default(bn_bake_gather_opts *o);
/* Each vertex of `bake` gathered (E, KE, ..., rest, L at the vertex by the final gather), the element mesh
 * refined where L changes first (bn_bake_refine): layers[0] (L) and layers[1 .. nl-1] (E, KE, ..., rest)
 * point into *vbuf (the caller frees it). Needs p->rt and a solve keeping KE. */
bn_status bn_pipeline_bake_gather(const bn_pipeline *p, bn_bake *bake, const bn_bake_gather_opts *o,
                                  bn_bake_layer *layers, size_t nl, double **vbuf, bn_error *err);

/* The images of bn_bounces_write without the files: imgs (bn_layer_count(bounces) of them, zeroed by the
 * caller; allocated here, freed with bn_image_free) receive each layer as o says (gather, smooth, seed,
 * threads); o->output, previews and exposure are not used. */
bn_status bn_bounces_render(const bn_scene *scene, const bn_rt *rt, const bn_camera *cam, const double *const *layers,
                            int bounces, const bn_bounces_opts *o, bn_image *imgs, bn_error *err);
bn_status bn_bounces_write(const bn_scene *scene, const bn_rt *rt, const bn_camera *cam, const double *const *layers,
                           int bounces, const bn_bounces_opts *o, double *ev_used, bn_error *err);

/* ---- the cross-check: radiosity against the independent path tracer on the same patches ----
 * The pipeline at the mesh asked (the rays kept for the tracer), the tracer's per-patch estimates,
 * the allowances for what the two estimate differently, then bn_crosscheck_compare. The tracer
 * shares only the scene and the rays.
 *
 * What is compared follows trace.model. PATCH (the default): the tracer estimates the
 * patch-constant transport radiosity solves on these patches, so dense and sparse K get no
 * allowance at all and a failure is an error of F, K or the solver; the hierarchy gets one for its
 * own approximation (the mesh asked at eps x r^2). CONTINUOUS: the tracer estimates light transport
 * itself, and radiosity's discretisation error is allowed from a second mesh level (two-level
 * grid-convergence estimate, Roache 1994, order 1), plus the eps level under the hierarchy. The
 * second level underestimates the error where the solution is singular (concave corners, contacts):
 * the continuous check states no false-alarm rate there. */
typedef enum bn_disc { BN_DISC_AUTO, BN_DISC_COARSE, BN_DISC_FINE, BN_DISC_NONE } bn_disc;
const char *bn_disc_name(bn_disc v);
const char *bn_disc_names(void);   /* "auto|coarse|fine|none" */
int bn_disc_parse(const char *s, bn_disc *out);   /* 0, or -1 for no such name */

typedef struct bn_crosscheck_opts {
    bn_pipeline_opts pipeline;   /* scene, meshing, form factors; its solve's tol and bounces are set here */
    bn_trace_opts trace;         /* spp, strategy, model (default PATCH here), seed, threads (bounces set here) */
    int    bounces;              /* terms compared one by one, then rest and L (default 3) */
    double solve_tol;            /* radiosity's tolerance (default 1e-10: far below the tracer's noise) */
    bn_disc disc;                /* allowances: AUTO (default) as the model says above; COARSE, FINE: a second
                                    mesh level, patch size x ratio or / ratio (and the eps level under the
                                    hierarchy, x or / r^2); NONE: no allowance */
    double ratio;                /* patch-size ratio of the levels (default 2) */
    double tol_scale;            /* safety factor Fs of the two-level estimate (default 3) */
    double rtol, alpha;          /* a further relative allowance (0); family-wise false-failure rate (0.01) */
    int    worst;                /* worst entries listed (default 10) */
    size_t regions;              /* compare on about this many regions of whole polygons (bn_partition_regions),
                                    traced with trace.spp samples each; 0 (default): per patch, or ... */
    size_t regions_above;        /* ... with regions 0 and more patches than this, per object and material
                                    (bn_partition_objects: more than the tracer resolves at its default
                                    samples in reasonable time); 0: never (default BN_CROSSCHECK_REGIONS_ABOVE) */
} bn_crosscheck_opts;
#define BN_CROSSCHECK_REGIONS_ABOVE 20000
void bn_crosscheck_opts_default(bn_crosscheck_opts *o);

typedef struct bn_crosscheck_run {
    bn_pipeline fine, other;     /* the mesh asked, and the second level (other.scene NULL: none) */
    bn_pipeline other_eps;       /* under the hierarchy: the mesh asked at eps x (or /) r^2, whose
                                    difference adds to the mesh level's (other_eps.scene NULL: none) */
    double seconds_fine, seconds_other, seconds_other_eps;
    double *layers_fine, *layers_other;   /* bn_layers_stack of each level */
    double *tol, *power_tol;     /* the discretisation tolerances (NULL without a second level) */
    bn_trace_patches trace;
    bn_partition part;           /* with regions: the partition (of the fine level's patches) */
    int regioned;                /* 0 per patch; 1 regions asked (opts.regions); 2 per object (regions_above) */
    double *rad_regions;         /* with regions: the fine level's region means */
    bn_crosscheck_input in;      /* what was compared (borrowing the above) */
    bn_crosscheck_result result; /* result.pass: the verdict */
} bn_crosscheck_run;

bn_status bn_crosscheck_run_scene(const char *path, const bn_crosscheck_opts *o, bn_crosscheck_run *run,
                                  bn_error *err);
void bn_crosscheck_run_free(bn_crosscheck_run *run);

#ifdef __cplusplus
}
#endif
#endif
