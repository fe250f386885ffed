/* The radiosity side's share of punctual lights: each patch's mean direct irradiance from every
 * light, with visibility, as the radiance a white patch reflects (E / pi; times rho, the part of the
 * source that belongs to bounce 1: bn_solve_opts.direct).
 *
 * A patch's mean irradiance from a point or spot light is (1/A) x the integral over the solid angle the
 * patch subtends at the light of I(w) V(w): I x Omega / A when the light is isotropic and the patch in
 * full view. Omega is exact (Van Oosterom and Strackee's formula per triangle of the patch's fan); the
 * profile and the visibility enter as a ratio over the midpoint rule's points on the patch, weighted
 * by their share of Omega (cos / d^2): exact for an unshadowed point light, and for the rest as good as
 * the midpoint rule on 16 points a triangle, 1,024 where a shadow's edge crosses the patch (some points
 * see the light and some do not: a hard edge is where the fewer points would err most, up to 1/16 of
 * the light) or a spot's falloff lies between its cones (its profile has kinks at both). A directional light gives I cos theta times the share of the points it reaches.
 * Deterministic: fixed points, any thread count. */
#include "bounce/pipeline.h"
#include "bounce/rt.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define BN__PUNCTUAL_SUB 4        /* midpoint rule: 4 x 4 sub-triangles per triangle of a patch */
#define BN__PUNCTUAL_SUB_EDGE 32  /* where a shadow's edge crosses the patch: 32 x 32 */

/* The solid angle triangle (a, b, c) subtends at o (Van Oosterom and Strackee 1983), unsigned. */
static double bn__solid_angle(const double o[3], const double *a, const double *b, const double *c)
{
    double x[3], y[3], z[3], yz[3];
    bn_v3_sub(a, o, x);
    bn_v3_sub(b, o, y);
    bn_v3_sub(c, o, z);
    double lx = bn_v3_len(x), ly = bn_v3_len(y), lz = bn_v3_len(z);
    bn_v3_cross(y, z, yz);
    double num = bn_v3_dot(x, yz);
    double den = lx * ly * lz + bn_v3_dot(x, y) * lz + bn_v3_dot(x, z) * ly + bn_v3_dot(y, z) * lx;
    return fabs(2 * atan2(num, den));
}

/* The midpoint rule's k x k points on triangle (a, b, c) of a patch with normal n (area `area` each
 * point, scene units^2), for light l: adds area x E V to sum[0..2] (E the point's irradiance, V its
 * visibility), area x cos / d^2 (d in metres) to sum[3], area to sum[4], and counts the points the light
 * reaches in sum[5], those it would reach unblocked in sum[6], those in a spot's falloff in sum[7]. */
static void bn__tri_points(const bn_rt *rt, const bn_light *l, double m, const double *a, const double *b,
                           const double *c, const double n[3], double eps, double area, int k, double sum[8])
{
    bn_subtri it = {k, 0, 0, 0};
    double s1, s2;
    while (bn_subtri_next(&it, &s1, &s2)) {
        double x[3], E[3], wi[3], d, o[3];
        for (int q = 0; q < 3; q++)
            x[q] = a[q] + s1 * (b[q] - a[q]) + s2 * (c[q] - a[q]);
        int lit = bn_light_irradiance(l, m, x, n, E, wi, &d);
        double cosr = bn_v3_dot(wi, n);
        sum[4] += area;
        if (!(cosr > 0))
            continue;
        sum[3] += isinf(d) ? area * cosr : area * cosr / (d * d * m * m);
        bn_v3_madd(x, eps, n, o);
        sum[6] += lit;
        if (l->type == BN_LIGHT_SPOT && -bn_v3_dot(wi, l->dir) > l->cos_outer && -bn_v3_dot(wi, l->dir) < l->cos_inner)
            sum[7] += 1;   /* in the spot's falloff */
        if (!lit || bn_rt_occluded(rt, o, wi, 0, isinf(d) ? INFINITY : d * (1 - 1e-9) - eps))
            continue;
        sum[5] += 1;
        for (int q = 0; q < 3; q++)
            sum[q] += area * E[q];
    }
}

/* Whether the light reaches the points just inside the patch's corners (1% of the way to its centre):
 * counted into sum[5] (reached) and sum[6] (would be, unblocked), so that a shadow's edge that passes
 * between the midpoint rule's points, near a corner (a contact's foot), still asks for the finer rule. */
static void bn__corner_probes(const bn_rt *rt, const bn_light *l, double m, const bn_patch *q, const double *pv,
                              const double n[3], double eps, double sum[8])
{
    double c[3] = {0, 0, 0};
    for (unsigned k = 0; k < q->ncorners; k++)
        bn_v3_madd(c, 1.0 / q->ncorners, pv + 3 * q->corner[k], c);
    for (unsigned k = 0; k < q->ncorners; k++) {
        double x[3], o[3], E[3], wi[3], d;
        for (int a = 0; a < 3; a++)
            x[a] = pv[3 * q->corner[k] + a] + 0.01 * (c[a] - pv[3 * q->corner[k] + a]);
        if (!bn_light_irradiance(l, m, x, n, E, wi, &d))
            continue;
        bn_v3_madd(x, eps, n, o);
        sum[6] += 1;
        sum[5] += !bn_rt_occluded(rt, o, wi, 0, isinf(d) ? INFINITY : d * (1 - 1e-9) - eps);
    }
}

/* The sums of bn__tri_points over patch q's fan of triangles at k x k points each; *omega: the solid angle
 * the patch subtends at a point or spot light. */
static void bn__patch_sums(const bn_scene *s, const bn_rt *rt, const bn_patch *q, const bn_light *l, int k,
                           double sum[8], double *omega)
{
    const double *pv = bn_scene_patch_vertices(s, NULL), *n = bn_scene_faces(s, NULL)[q->face].normal;
    double m = bn_unit_to_metres(bn_scene_unit(s)), eps = bn_rt_epsilon(rt);
    for (int j = 0; j < 8; j++)
        sum[j] = 0;
    *omega = 0;
    for (unsigned t = 1; t + 1 < q->ncorners; t++) {
        const double *a = pv + 3 * q->corner[0], *b = pv + 3 * q->corner[t], *c = pv + 3 * q->corner[t + 1];
        double e1[3], e2[3], cr[3];
        bn_v3_sub(b, a, e1);
        bn_v3_sub(c, a, e2);
        bn_v3_cross(e1, e2, cr);
        bn__tri_points(rt, l, m, a, b, c, n, eps, 0.5 * bn_v3_len(cr) / (k * k), k, sum);
        if (l->type != BN_LIGHT_DIRECTIONAL)
            *omega += bn__solid_angle(l->pos, a, b, c);
    }
    if (k == BN__PUNCTUAL_SUB)
        bn__corner_probes(rt, l, m, q, pv, n, eps, sum);
}

/* Patch p's mean irradiance from light l (W m^-2). */
static void bn__patch_light(const bn_scene *s, const bn_rt *rt, size_t p, const bn_light *l, double out[3])
{
    const bn_patch *q = &bn_scene_patches(s, NULL)[p];
    double m = bn_unit_to_metres(bn_scene_unit(s)), sum[8], omega;
    out[0] = out[1] = out[2] = 0;
    bn__patch_sums(s, rt, q, l, BN__PUNCTUAL_SUB, sum, &omega);
    if ((sum[5] > 0 && sum[5] < sum[6]) || sum[7] > 0)   /* a shadow's edge, or a spot's falloff, on the patch */
        bn__patch_sums(s, rt, q, l, BN__PUNCTUAL_SUB_EDGE, sum, &omega);
    if (!(sum[3] > 0) || !(sum[4] > 0))
        return;
    for (int c = 0; c < 3; c++)   /* point, spot: I Omega / A, the profile and shadows as their share */
        out[c] = l->type == BN_LIGHT_DIRECTIONAL ? sum[c] / sum[4] : sum[c] / sum[3] * omega / (sum[4] * m * m);
}

bn_status bn_punctual_direct(const bn_scene *s, const bn_rt *rt, int threads, double **out, bn_error *err)
{
    size_t nl, np;
    const bn_light *lights = bn_scene_lights(s, &nl);
    bn_scene_patches(s, &np);
    *out = NULL;
    if (nl == 0)
        return BN_OK;
    double *D = bn__calloc(3 * np + 1, sizeof *D);
    if (!D)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the punctual lights' direct light on %zu patches", np);
#pragma omp parallel for schedule(dynamic, 64) num_threads(bn_threads_resolve(threads))
    for (size_t p = 0; p < np; p++)
        for (size_t k = 0; k < nl; k++) {
            double E[3];
            bn__patch_light(s, rt, p, &lights[k], E);
            for (int c = 0; c < 3; c++)
                D[3 * p + c] += E[c] / BN_PI;
        }
    *out = D;
    return BN_OK;
}
