/* Patches inside a closed object (include/bounce/rt.h: bn_rt_enclosed_patches): the floor under a
 * block standing on it. From such a patch's centroid (just above it) every direction meets the
 * inside of the object, a back face. Used by the bake (the darkness under the block does not bleed
 * into the floor around it) and the hierarchy (covered and uncovered patches never share a node). */
#include "bounce/rt.h"
#include "base/vec.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

/* Rays per patch, and the share of them that must meet a back face. */
#define BN__ENCLOSED_RAYS 16
#define BN__ENCLOSED_SHARE 0.9
/* Partly covered: a quarter of the rays meet a back face (the floor under an object with an open base:
 * the Stanford bunny's), or half meet a back face or a face nearer than the patch's own size or
 * BN__SHUT_NEAR (the floor 2 mm under the bunny's closed base, or under a slab). */
#define BN__BACK_SHARE 0.25
#define BN__SHUT_SHARE 0.5
/* "Near" for shut: within the patch's size or this fraction of the scene's diameter, whichever is more
 * (a large floor patch 11 mm under the bunny's belly: with its own 13 mm most rays leave the gap sideways
 * further than that, and it shared an open node's mean light, 20 times the tracer's K2E). */
#define BN__SHUT_NEAR 0.05

/* Per patch, how many of BN__ENCLOSED_RAYS fixed rays from just above its centroid meet a back face
 * (back), and how many meet a back face or any face nearer than the patch's size or BN__SHUT_NEAR of the
 * scene's diameter (shut: NULL or filled). */
static void bn__back_counts(const bn_rt *rt, unsigned char *back, unsigned char *shut)
{
    size_t np;
    const bn_patch *patches = bn_scene_patches(bn_rt_scene(rt), &np);
    double eps = bn_rt_epsilon(rt);
    long ln = (long)np;
    double near = BN__SHUT_NEAR * bn_scene_diameter(bn_rt_scene(rt));
#pragma omp parallel for schedule(dynamic, 256)
    for (long lp = 0; lp < ln; lp++) {
        const bn_patch *p = &patches[lp];
        double s[3], t[3], o[3];
        int n = 0, m = 0;
        double size = fmax(sqrt(p->area), near);
        bn_v3_basis(p->normal, s, t);
        for (int k = 0; k < 3; k++)
            o[k] = p->centroid[k] + eps * p->normal[k];
        for (int r = 0; r < BN__ENCLOSED_RAYS; r++) {   /* a fixed spiral of directions: deterministic */
            double u = (r + 0.5) / BN__ENCLOSED_RAYS, ph = 2.399963229728653 * r, rr = sqrt(u), dir[3];
            bn_hit h;
            for (int k = 0; k < 3; k++)
                dir[k] = rr * cos(ph) * s[k] + rr * sin(ph) * t[k] + sqrt(1 - u) * p->normal[k];
            if (bn_rt_intersect(rt, o, dir, 0, INFINITY, &h)) {
                n += !h.front;
                m += !h.front || h.t < size;
            }
        }
        back[lp] = (unsigned char)n;
        if (shut)
            shut[lp] = (unsigned char)m;
    }
}

size_t bn_rt_enclosed_patches(const bn_rt *rt, unsigned char *enclosed)
{
    size_t np, count = 0;
    bn_scene_patches(bn_rt_scene(rt), &np);
    bn__back_counts(rt, enclosed, NULL);
    for (size_t i = 0; i < np; i++) {
        enclosed[i] = enclosed[i] >= BN__ENCLOSED_SHARE * BN__ENCLOSED_RAYS;
        count += enclosed[i];
    }
    return count;
}

size_t bn_rt_cover_classes(const bn_rt *rt, unsigned char *cls)
{
    size_t np, count = 0;
    bn_scene_patches(bn_rt_scene(rt), &np);
    unsigned char *shut = malloc(np ? np : 1);
    if (!shut)
        return SIZE_MAX;   /* the caller says so: classes quietly missing would change the hierarchy's links */
    bn__back_counts(rt, cls, shut);
    for (size_t i = 0; i < np; i++) {
        unsigned n = cls[i];
        cls[i] = n >= BN__ENCLOSED_SHARE * BN__ENCLOSED_RAYS ? BN_COVER_ENCLOSED
                 : n >= BN__BACK_SHARE * BN__ENCLOSED_RAYS   ? BN_COVER_BACK
                 : shut[i] >= BN__SHUT_SHARE * BN__ENCLOSED_RAYS ? BN_COVER_SHUT
                                                              : BN_COVER_OPEN;
        count += cls[i] == BN_COVER_BACK || cls[i] == BN_COVER_SHUT;
    }
    free(shut);
    return count;
}
