/* bounce: a final gather. Per-pixel images of the per-bounce terms, computed at each pixel's visible
 * point x from the solved terms instead of read from the patch x lies on:
 *   E(x)    the emission of the surface seen;
 *   KE(x)   rho(x) sum over emitting faces e of Le_e F(x -> e) V_e(x): F by Lambert's contour
 *           integral over the part of e in front of x (exact), V_e the visible fraction of e seen
 *           from x, estimated with the same stratified directions (uniform in e's solid angle,
 *           weighted by the cosine at x) as sum cos V / sum cos: exact where e is wholly visible or
 *           wholly hidden, and sharp to the pixel at a shadow's edge. Emitting faces that tile one
 *           flat convex light are one e (merge_emitters). Above tree_emitters of them, the sum is
 *           estimated instead from light_samples faces picked from a light tree
 *           (in proportion to a bound on each one's contribution), each Le F (1 - blocked) / pdf with
 *           one shadow ray (the blocked part by one direction): unbiased, exact where the picked face
 *           is wholly visible, and as costly for 10,000 faces as for 20;
 *   K^k E(x), k >= 2: rho(x) times the cosine-weighted mean of the solved K^(k-1) E over the
 *           hemisphere (stratified rays; the value at each hit read from its patch, or interpolated
 *           across patches with `smooth`); for K^2 E, KE at each hit is the hit's own direct light
 *           (the faces' closed forms less one picked face's blocked part, Omega cos (1 - V) / pi /
 *           its probability) while the scene has at most
 *           hit_emitters emitting faces;
 *   rest(x) rho(x) times the mean of K^n E + rest at the hits, and L(x) the sum of the layers.
 * The gathered (indirect) means are smooth inside a face, so each pixel's is averaged with those of
 * the pixels around it (filter radius) that see the same face, never across a face's edge.
 * So every layer stays one term of the Neumann series, and L(x) = E(x) + rho(x) (gathered L - E).
 * Results do not depend on the thread count (every stream keyed by pixel and sample) nor, under
 * mpirun, on the process count (rows split among ranks, each pixel computed by one). */
#ifndef BOUNCE_GATHER_H
#define BOUNCE_GATHER_H

#include <stdint.h>
#include "bounce/image.h"

#ifdef __cplusplus
extern "C" {
#endif

#define BN_GATHER_LIGHT_SAMPLES 16   /* shadow rays per emitting face per pixel sample (with the light
                                        tree: emitting faces picked per pixel sample, one ray each) */
#define BN_GATHER_HEMI_SAMPLES 144   /* gather rays per pixel sample */
#define BN_GATHER_FILTER 3           /* pixels */
#define BN_GATHER_HIT_EMITTERS 64    /* the hits' KE from the emitters up to this many emitting faces */
#define BN_GATHER_TREE_EMITTERS 16   /* above this many emitting faces, they are picked from a light tree */
/* The defaults meet the per-pixel race on the Cornell box (bench/race_bench.c, 256x256: the median
 * per-pixel error of L against a 65,536-spp path-traced reference at most 0.5% in at most 6 s,
 * measured 0.45% in about 4 s). With K^2 E's hits lit by the emitters themselves, what is left is
 * the gather's noise (144 rays and the 3 px filter) and the coarse solution's error in K^3 E and
 * beyond (600 patches: the gather reads the solution only for those). 16 shadow rays: 4 reach the
 * median as fast, but leave the penumbrae, which the median does not weigh, visibly noisy. */
#define BN_GATHER_PATCHES 600

/* How images (and bakes) get their values: FINAL, a gather at each pixel's point (closed-form
 * direct light with visibility, a hemisphere gather of the solved terms for k >= 2); NONE, the value
 * of the patch each pixel sees. */
typedef enum bn_gather_mode { BN_GATHER_FINAL, BN_GATHER_NONE } bn_gather_mode;
const char *bn_gather_mode_name(bn_gather_mode v);
const char *bn_gather_mode_names(void);   /* "final|none" */
int bn_gather_mode_parse(const char *s, bn_gather_mode *out);   /* 0, or -1 for no such name */

typedef struct bn_gather_opts {
    int light_samples;               /* >= 1; rounded up to a stratified grid */
    int hemi_samples;                /* >= 1; rounded up to a stratified grid */
    const struct bn_bake *smooth;    /* hit values interpolated across patches (NULL: the patch's) */
    uint64_t seed;
    int filter;                      /* the gathered (indirect) terms averaged over the pixels within this
                                        radius that see the same face (0: none; default BN_GATHER_FILTER) */
    int hit_emitters;                /* K^2 E gathers, at each hit, KE from the emitting faces (their closed
                                        forms summed, one shadow ray to one face picked in proportion to
                                        its Le F) when the scene has at most this many, else the hit
                                        patch's KE (0: always the patch's; default BN_GATHER_HIT_EMITTERS);
                                        with the light tree, one ray to one picked face, whatever the count */
    int tree_emitters;               /* more emitting faces than this: each pixel sample picks light_samples
                                        of them from a light tree (src/rt/lights.h) in proportion to their
                                        likely contribution, one ray each, so the cost per pixel does not
                                        grow with their number (default BN_GATHER_TREE_EMITTERS); counted
                                        after merging (merge_emitters) */
    int merge_emitters;              /* 1 (default): emitting faces that share corners, lie in one plane,
                                        emit the same radiance and tile a convex polygon of at most 6
                                        corners are one light (a quad cut into two triangles, a panel into
                                        a grid): their closed forms are one, and one face's visibility
                                        samples; 0: every face its own */
    int threads;                     /* 0: the caller's */
    int quiet;                       /* no progress bar */
} bn_gather_opts;
void bn_gather_opts_default(bn_gather_opts *o);

/* Counts of one render. */
typedef struct bn_gather_stats {
    double shadow_rays, gather_rays, camera_rays;
    double front_hits;               /* camera rays that met a surface's front (0: a black image) */
    size_t emitters;                 /* emitting faces */
    size_t lights;                   /* the lights they make once merged (merge_emitters) */
    int hit_direct;                  /* 1: K^2 E's hits took KE from the emitters (hit_emitters) */
    int light_tree;                  /* 1: emitting faces were picked from the light tree (tree_emitters) */
    double seconds;
} bn_gather_stats;

/* terms[0..n] = E, KE, ..., K^n E per patch (N*3 each, 1 <= n <= 20) and rest (N*3), from one solve.
 * out: n + 3 images at the camera's size (E, KE, ..., K^n E, rest, L), allocated by the caller.
 * stats may be NULL. */
bn_status bn_gather_render(const bn_rt *rt, const bn_camera *cam, const double *const *terms, int n,
                           const double *rest, const bn_gather_opts *o, bn_image *out, bn_gather_stats *stats,
                           bn_error *err);

/* The final gather at points on the surfaces (a bake's vertices): point i at x[3 i ..] on patch patch[i],
 * seen from the patch's front, gets what a pixel's sample meeting the surface there gets: E from its
 * patch, KE from the emitting faces (closed form with visibility, o->light_samples each) and the
 * punctual lights, K^k E for k >= 2 and rest as rho at the point times a hemisphere gather
 * (o->hemi_samples rays) of the solved K^(k-1) E (and rest) at the hits (no pixel filter: ask for more
 * rays than an image's pixel does). terms[0..n], 1 <= n <= 20, and rest as for bn_gather_render. out:
 * (n + 3) layers E, KE, ..., K^n E, rest, L, layer-major: out[(l * npts + i) * 3 + c], each at least 0
 * (a hit's direct light is estimated without bias, so near a shadow's edge a mean can dip below 0: held
 * at 0). Deterministic: point i's streams are keyed by i. stats (may be NULL): its rays (gather_rays counts the
 * near hits' gathers too, beyond npts x hemi_samples), lights and seconds; camera_rays and front_hits 0. */
bn_status bn_gather_points(const bn_rt *rt, const double *const *terms, int n, const double *rest, const double *x,
                           const size_t *patch, size_t npts, const bn_gather_opts *o, double *out,
                           bn_gather_stats *stats, bn_error *err);

#ifdef __cplusplus
}
#endif
#endif
