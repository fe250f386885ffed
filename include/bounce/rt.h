/* bounce: ray casting over a meshed scene's patches (Embree 3). Shared by the form factors,
 * the camera images and the path tracer: the only geometry they have in common. */
#ifndef BOUNCE_RT_H
#define BOUNCE_RT_H

#include <stddef.h>
#include <stdint.h>
#include "bounce/scene.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct bn_rt bn_rt;   /* opaque: an Embree device and scene over the patches */

/* Builds the ray-casting structure over `scene`'s patches (borrowed: it must outlive *out and
 * not be re-meshed). threads: 0 = all cores, else the cap for Embree's build threads. */
bn_status bn_rt_create(const bn_scene *scene, int threads, bn_rt **out, bn_error *err);
void bn_rt_destroy(bn_rt *rt);   /* NULL is a no-op */

typedef struct bn_hit {
    size_t patch;   /* patch index */
    double t;       /* distance along the (unit or not) direction, in units of |d| */
    double p[3];    /* hit point, o + t d */
    int    front;   /* 1 if the ray arrives on the patch's front side */
} bn_hit;

/* Closest hit of o + t d for t in (tnear, tfar); 1 on a hit. Per-ray calls are unchecked:
 * d must be non-zero and finite. Geometry is two-sided for visibility. */
int bn_rt_intersect(const bn_rt *rt, const double o[3], const double d[3], double tnear, double tfar, bn_hit *hit);
/* 1 if anything lies on o + t d for t in (tnear, tfar). Unchecked per-ray call. */
int bn_rt_occluded(const bn_rt *rt, const double o[3], const double d[3], double tnear, double tfar);

/* A batch of occlusion queries (Embree's stream API: faster than one at a time).
 * org/dir: n xyz triples; tfar: n values (tnear is 0); blocked[i] receives 0 or 1. */
void bn_rt_occluded_batch(const bn_rt *rt, const float *org, const float *dir, const float *tfar, size_t n,
                          unsigned char *blocked);

/* A length for offsetting ray origins off surfaces and shortening shadow rays: a small
 * multiple of float precision at the scene's largest coordinate (pbrt's ShadowEpsilon). */
double bn_rt_epsilon(const bn_rt *rt);
const bn_scene *bn_rt_scene(const bn_rt *rt);
/* Patches inside a closed object (the floor under a block standing on it): at least 90% of 16
 * fixed rays from the patch's centroid over its hemisphere meet a back face. enclosed: one flag per
 * patch of the rt's scene. Returns how many. Deterministic, for any thread count. */
size_t bn_rt_enclosed_patches(const bn_rt *rt, unsigned char *enclosed);
/* The same rays, four classes (bn_cover), so that patches whose views of the scene differ this much
 * never share a node of the hierarchy (a node hands every patch below it its mean form factor: the
 * floor under an object took the light its open neighbours see, 3 to 7 times its own). Returns how
 * many are partly covered (BACK or SHUT), or SIZE_MAX when out of memory (cls then unset). */
enum bn_cover {
    BN_COVER_OPEN = 0,
    BN_COVER_SHUT = 1,       /* half the rays meet a back face or a face nearer than the patch's size
                                or 5% of the scene's diameter */
    BN_COVER_BACK = 2,       /* a quarter of the rays meet a back face */
    BN_COVER_ENCLOSED = 3    /* bn_rt_enclosed_patches's */
};
size_t bn_rt_cover_classes(const bn_rt *rt, unsigned char *cls);

#ifdef __cplusplus
}
#endif
#endif
