/* A patch's geometry from its corners: area, centroid and normal, for the mesher's grids and the
 * contact cuts alike (so neither calls the other for it). */
#include "scene/scene_internal.h"
#include "base/vec.h"

#include <math.h>
#include <string.h>

void bn__scene_patch_finish(bn_patch *p, const double *pv, const double normal[3])
{
    const double *a = pv + 3 * p->corner[0], *b = pv + 3 * p->corner[1], *c = pv + 3 * p->corner[2];
    double e1[3], e2[3], cr[3];
    memcpy(p->normal, normal, 3 * sizeof(double));
    bn_v3_sub(b, a, e1);
    bn_v3_sub(c, a, e2);
    bn_v3_cross(e1, e2, cr);
    if (p->ncorners == 3) {
        p->area = 0.5 * bn_v3_len(cr);
        for (int k = 0; k < 3; k++)
            p->centroid[k] = (a[k] + b[k] + c[k]) / 3.0;
    } else {
        const double *d = pv + 3 * p->corner[3];
        double a1 = 0.5 * fabs(bn_v3_dot(cr, normal)), a2, f1[3], f2[3], cr2[3];
        bn_v3_sub(c, a, f1);
        bn_v3_sub(d, a, f2);
        bn_v3_cross(f1, f2, cr2);
        a2 = 0.5 * fabs(bn_v3_dot(cr2, normal));
        p->area = a1 + a2;
        for (int k = 0; k < 3; k++)
            p->centroid[k] = p->area > 0 ? (a1 * (a[k] + b[k] + c[k]) + a2 * (a[k] + c[k] + d[k])) / (3.0 * p->area)
                                         : 0.25 * (a[k] + b[k] + c[k] + d[k]);
    }
}

void bn_scene_point_inset(const bn_scene *s, size_t patch, const double x[3], double out[3])
{
    const double *c = bn_scene_patches(s, NULL)[patch].centroid;
    for (int k = 0; k < 3; k++)
        out[k] = x[k] + BN_SCENE_POINT_INSET * (c[k] - x[k]);
}
