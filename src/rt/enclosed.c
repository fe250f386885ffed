/* Patches inside a closed object (include/bounce/rt.h: bn_rt_enclosed_patches): the floor under a
 * block standing on it. From such a patch's centroid (just above it) every direction meets the
 * inside of the object, a back face. Used by the bake (the darkness under the block does not bleed
 * into the floor around it) and the hierarchy (covered and uncovered patches never share a node). */
#include "bounce/rt.h"
#include "base/vec.h"

#include <math.h>

/* Rays per patch, and the share of them that must meet a back face. */
#define BN__ENCLOSED_RAYS 16
#define BN__ENCLOSED_SHARE 0.9

size_t bn_rt_enclosed_patches(const bn_rt *rt, unsigned char *enclosed)
{
    size_t np, count = 0;
    const bn_patch *patches = bn_scene_patches(bn_rt_scene(rt), &np);
    double eps = bn_rt_epsilon(rt);
    long ln = (long)np;
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : count)
    for (long lp = 0; lp < ln; lp++) {
        const bn_patch *p = &patches[lp];
        double s[3], t[3], o[3];
        int back = 0;
        bn_v3_basis(p->normal, s, t);
        for (int k = 0; k < 3; k++)
            o[k] = p->centroid[k] + eps * p->normal[k];
        for (int r = 0; r < BN__ENCLOSED_RAYS; r++) {   /* a fixed spiral of directions: deterministic */
            double u = (r + 0.5) / BN__ENCLOSED_RAYS, ph = 2.399963229728653 * r, rr = sqrt(u), d[3];
            bn_hit h;
            for (int k = 0; k < 3; k++)
                d[k] = rr * cos(ph) * s[k] + rr * sin(ph) * t[k] + sqrt(1 - u) * p->normal[k];
            back += bn_rt_intersect(rt, o, d, 0, INFINITY, &h) && !h.front;
        }
        enclosed[lp] = back >= BN__ENCLOSED_SHARE * BN__ENCLOSED_RAYS;
        count += enclosed[lp];
    }
    return count;
}
