/* Punctual lights (bn_scene_lights): the irradiance one gives a surface point, in closed form, and
 * its power. Shared by the radiosity side (the source of bounce 1), the final gather (each pixel's
 * point) and the path tracer (next-event estimation): like the emitting faces, a light is part of
 * the scene, not of either method. */
#include "scene/scene_internal.h"
#include "base/vec.h"

#include <math.h>

const bn_light *bn_scene_lights(const bn_scene *s, size_t *n)
{
    *n = s->nlights;
    return s->lights;
}

/* A spot's profile towards cosine c from its axis (glTF's reference falloff). */
static double bn__spot(const bn_light *l, double c)
{
    double span = l->cos_inner - l->cos_outer;
    double t = span > 1e-12 ? (c - l->cos_outer) / span : (c >= l->cos_outer ? 1.0 : 0.0);
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return t * t;
}

int bn_light_irradiance(const bn_light *l, double m, const double x[3], const double n[3], double E[3], double wi[3],
                        double *dist)
{
    double cosr, scale;
    E[0] = E[1] = E[2] = 0;
    if (l->type == BN_LIGHT_DIRECTIONAL) {
        wi[0] = -l->dir[0], wi[1] = -l->dir[1], wi[2] = -l->dir[2];
        *dist = INFINITY;
        scale = 1;
    } else {
        bn_v3_sub(l->pos, x, wi);
        *dist = bn_v3_normalize(wi);
        if (!(*dist > 0))
            return 0;
        double d = *dist * m;
        scale = 1 / (d * d);
        if (l->type == BN_LIGHT_SPOT)
            scale *= bn__spot(l, -bn_v3_dot(wi, l->dir));
    }
    cosr = bn_v3_dot(wi, n);
    if (!(cosr > 0) || !(scale > 0))
        return 0;
    for (int c = 0; c < 3; c++)
        E[c] = l->I[c] * cosr * scale;
    return E[0] > 0 || E[1] > 0 || E[2] > 0;
}

void bn_light_power(const bn_light *l, double watts[3])
{
    double solid = 0;   /* the profile's integral over the sphere (steradians) */
    if (l->type == BN_LIGHT_POINT)
        solid = 4 * BN_PI;
    else if (l->type == BN_LIGHT_SPOT) {
        const int n = 4096;   /* midpoint rule in cos a over the cone: the profile is smooth there */
        for (int k = 0; k < n; k++) {
            double c = l->cos_outer + (1 - l->cos_outer) * (k + 0.5) / n;
            solid += 2 * BN_PI * bn__spot(l, c) * (1 - l->cos_outer) / n;
        }
    }
    for (int c = 0; c < 3; c++)
        watts[c] = l->I[c] * solid;
}
