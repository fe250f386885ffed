/* The path tracer's shared core: sampling tables over the patches and one path, binned by length. */
#ifndef BOUNCE_TRACE_INTERNAL_H
#define BOUNCE_TRACE_INTERNAL_H

#include <stdio.h>
#include "bounce/trace.h"
#include "base/internal.h"
#include "rt/lights.h"

/* What a path needs of the scene, in double, built once per run. */
typedef struct bn__tracer {
    const bn_rt    *rt;
    const bn_scene *scene;
    const bn_patch *patches;
    size_t          np;
    const double   *pv;          /* patch vertices, xyz */
    double         *rho, *Le;    /* N*3 each */
    double         *tri0;        /* per patch: share of its area in the first triangle (1 for triangles) */
    /* Emitter sampling: patch j chosen with probability A_j sum_c Le_jc / W, then a uniform point. */
    size_t          nem;
    size_t         *em_patch;    /* nem */
    double         *em_cdf;      /* nem, last = 1 */
    double         *pdf_area;    /* N: P(choose j) / A_j, 0 for non-emitters (area density of NEE points) */
    /* Above tree_emitters emitting patches: chosen from this light tree over em_patch instead (the
     * probability then depends on the path's point); em_index: per patch its index in em_patch. */
    bn__lights     *tree;
    size_t         *em_index;
    double          eps;         /* ray offset, scene units */
    const bn_light *pl;          /* punctual lights (bn_scene_lights): reached by next-event estimation alone */
    size_t          npl;
    double          unit;        /* metres per scene unit */
    bn_trace_opts   o;
    int             nbins;       /* bounces + 2: K^0 E .. K^bounces E, rest */
} bn__tracer;

bn_status bn__tracer_init(bn__tracer *t, const bn_rt *rt, const bn_trace_opts *o, bn_error *err);
void bn__tracer_free(bn__tracer *t);
/* Under mpirun, after each rank traced its own items into zeroed arrays: every rank's status first
 * (all stop together), then mean and spread (doubles or floats: dbl) and the ray count summed over
 * ranks (bn_dist_sum: each element from one rank, exact). BN_OK, or the status to stop with. */
bn_status bn__trace_combine(int no_buffers, void *mean, void *spread, double *third, int dbl, size_t n,
                            unsigned long long *rays, bn_error *err);

/* One item's samples (a pixel row, a patch, a region) with the thread's buffers: sample and mean
 * of m doubles, m2 of moments x m. */
typedef void (*bn__trace_item_fn)(void *ctx, size_t i, double *sample, double *mean, double *m2,
                                  unsigned long long *rays);
/* Runs item(ctx, i) for i < n over the threads (dynamic, one at a time; each thread with its own
 * buffers), under mpirun only this rank's items (bn_dist_mine), none after an interrupt; adds the
 * rays cast to *rays and steps prog once per item. Returns 1 when a thread had no buffers. */
int bn__trace_parallel(size_t n, size_t m, size_t moments, bn__trace_item_fn item, void *ctx, bn__progress *prog,
                       unsigned long long *rays);
/* After a run (and bn__trace_combine): BN_OK, or the interrupt's status, or BN_ENOMEM for a
 * thread without buffers, in err. */
bn_status bn__trace_stopped(int no_buffers, bn_error *err);

/* A uniform point on patch p from two uniforms. */
void bn__tracer_patch_point(const bn__tracer *t, size_t p, double u1, double u2, double u3, double x[3]);

/* The patch model's restart: x a uniform point on patch p, from three draws of rng. */
void bn__tracer_restart(const bn__tracer *t, size_t p, bn__rng *rng, double x[3]);

/* Radiance reflected at x (on the front of patch p) towards any direction, for a Lambertian
 * surface: one path starting with the reflection at x (reflection 1), with NEE/BSDF/MIS at each
 * vertex and Russian roulette after rr_depth. Adds each contribution (already weighted) to
 * bins[3 * min(k, bounces + 1) + c], k = reflections. *rays counts rays cast. rho0: the reflectance at
 * x (a texture's there, for camera paths), NULL for the patch's (its mean, as K has it); every later
 * vertex takes its patch's. */
void bn__tracer_path(const bn__tracer *t, const double x[3], size_t p, const double *rho0, bn__rng *rng, double *bins,
                     unsigned long long *rays);

/* Running mean, M2 and M3 (central moment sums; Welford, Terriberry's third-moment update) of one
 * sample vector of `m` doubles. */
static inline void bn__moments_add(double *mean, double *m2, double *m3, const double *x, size_t m, size_t count_after)
{
    double nn = (double)count_after;
    for (size_t j = 0; j < m; j++) {
        double d = x[j] - mean[j], dn = d / nn, t1 = d * dn * (nn - 1);
        mean[j] += dn;
        m3[j] += t1 * dn * (nn - 2) - 3 * dn * m2[j];
        m2[j] += t1;
    }
}

/* Running mean and M2 (Welford) of one sample vector of `m` doubles. */
static inline void bn__welford_add(double *mean, double *m2, const double *x, size_t m, size_t count_after)
{
    for (size_t j = 0; j < m; j++) {
        double d = x[j] - mean[j];
        mean[j] += d / (double)count_after;
        m2[j] += d * (x[j] - mean[j]);
    }
}

/* Stream tags, so the patch and camera estimators never share a stream. */
#define BN__TRACE_TAG_PATCH 0x7061746368ULL   /* "patch" */
#define BN__TRACE_TAG_PIXEL 0x706978656cULL   /* "pixel" */

/* The estimates' CSV columns shared by the per-patch and per-point files: each layer's R, G, B and
 * their standard errors, the header's (ending the line) and item i's (ending its row). */
void bn__trace_csv_layer_head(FILE *fp, const bn_trace_patches *r);
void bn__trace_csv_layer_row(FILE *fp, const bn_trace_patches *r, size_t i);

#endif
