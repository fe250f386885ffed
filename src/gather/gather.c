/* The final gather (include/bounce/gather.h): per pixel, direct light from the emitting faces by
 * Lambert's closed form times a visibility ratio, and the higher terms gathered from the solution
 * over the hemisphere. */
#include "gather/gather_internal.h"
#include "bounce/bake.h"
#include "bounce/dist.h"
#include "base/internal.h"
#include "base/vec.h"
#include "formfactor/ff_internal.h"
#include "rt/lights.h"

#include <math.h>
#include <string.h>

/* The modes in enum order (bn_gather_mode). */
#define BN__GATHER_MODES(X) X("final") X("none")
BN__VOCABULARY(bn_gather_mode, bn_gather_mode, BN__GATHER_MODES)

void bn_gather_opts_default(bn_gather_opts *o)
{
    memset(o, 0, sizeof *o);
    o->light_samples = BN_GATHER_LIGHT_SAMPLES;
    o->hemi_samples = BN_GATHER_HEMI_SAMPLES;
    o->filter = BN_GATHER_FILTER;
    o->hit_emitters = BN_GATHER_HIT_EMITTERS;
    o->tree_emitters = BN_GATHER_TREE_EMITTERS;
    o->merge_emitters = 1;
    o->seed = 1;
}

/* Doubles per pixel between the per-pixel pass and the composition: the face seen plus one, the mean
 * reflectance at the samples' points, the gathered means of K^1 E .. K^n E and rest. */
#define BN__AUX(n) (4 + 3 * ((size_t)(n) + 1))

int bn__side(int samples)
{
    int g = (int)ceil(sqrt((double)samples) - 1e-9);
    return g < 1 ? 1 : g;
}

/* The values of the gathered layers (0 .. n - 1: K^(l+1) E; n: rest) at a hit, added to hv x wt:
 * the hit patch's own, or interpolated across patches (smooth: one set of weights for every layer);
 * with hit_direct, KE (layer 0) is the hit's own direct light instead (bn__hit_direct). */
static void bn__hit_values(const bn__gather *G, const bn_hit *h, double wt, double *hv)
{
    int nl = G->n + 1, l0 = G->hit_direct ? 1 : 0;
    hv += 3 * l0;
    if (G->vv) {
        size_t vert[4];
        double w[4];
        unsigned m = bn_bake_weights(G->smooth, h->patch, h->p, vert, w);
        for (int l = l0; l < nl; l++)
            for (unsigned k = 0; k < m; k++)
                for (int c = 0; c < 3; c++)
                    hv[3 * (l - l0) + c] += wt * w[k] * G->vv[l][3 * vert[k] + c];
        return;
    }
    for (int l = l0; l < nl; l++) {
        const double *a = l < G->n ? G->terms[l + 1] : G->rest;
        for (int c = 0; c < 3; c++)
            hv[3 * (l - l0) + c] += wt * a[3 * h->patch + c];
    }
}

/* Emitter em as seen from x0 (normal n): the shading point x (moved in front of the emitter's plane
 * where it lies on it), the shadow rays' origin xo and its height dof over that plane, F(x -> the
 * part of em in front of x) and (with sph) that part's spherical polygon; 0 when x cannot see em. */
typedef struct bn__em_view {
    double x[3], xo[3], dof, F;
    bn__sph_poly sp;
} bn__em_view;

static int bn__em_view_make(const bn__gather *G, const bn__emitter *em, const double x0[3], const double n[3],
                            int sph, bn__em_view *v)
{
    double xv[3], poly[3 * BN__FF_POLY_MAX], d;
    size_t m;
    bn_v3_sub(x0, em->v, xv);
    d = bn_v3_dot(xv, em->n);   /* x's height above the emitter's plane: it emits to its front only */
    if (!(d > -2 * G->eps))
        return 0;
    /* x on (within 2 eps of) the emitter's plane, as where a floor meets a lit wall: the value is the
     * limit from the front, so x is taken 2 eps in front of that plane (else every inner corner of
     * a lit room would show a dark seam one pixel wide) */
    memcpy(v->x, x0, sizeof v->x);
    if (d < 2 * G->eps)
        bn_v3_madd(x0, 2 * G->eps - d, em->n, v->x);
    for (int k = 0; k < 3; k++)
        v->xo[k] = v->x[k] + G->eps * n[k];
    m = bn__poly_clip(em->v, em->nv, n, v->x, 0, poly);   /* the part in front of x */
    if (m < 3)
        return 0;
    v->F = bn__ff_point_polygon(v->x, n, poly, m);
    if (!(v->F > 0) || (sph && !bn__sph_poly_init(&v->sp, v->x, n, poly, m)))
        return 0;
    bn_v3_sub(v->xo, em->v, xv);
    v->dof = bn_v3_dot(xv, em->n);   /* the shadow rays' origin's height */
    return 1;
}

/* The shadow ray along dir (a direction to em): its cosine at x, 0 when it does not count;
 * *seen whether it reaches em. */
static double bn__em_ray(const bn__gather *G, const bn__emitter *em, const bn__em_view *v, const double n[3],
                         const double dir[3], int *seen)
{
    double c = bn_v3_dot(dir, n), ce = -bn_v3_dot(dir, em->n), t = v->dof / ce;
    /* t: from the offset origin to the emitter's plane, stopping short of it by 2 eps measured
     * across the plane (eps / ce along a grazing ray) */
    *seen = 0;
    if (!(c > 0) || !(ce > 0) || !(t > 0) || !isfinite(t))
        return 0;
    *seen = !bn_rt_occluded(G->rt, v->xo, dir, 0, t - 2 * G->eps / ce);
    return c;
}

/* Emitter em's direct light at x (normal n), rho-free, added to out: Le F V, V from side x side
 * stratified directions (uniform in its solid angle) as sum cos V / sum cos. */
static void bn__direct_em(const bn__gather *G, const bn__emitter *em, const double x0[3], const double n[3],
                          bn__rng *r, int side, double out[3], double *rays)
{
    double sc = 0, scv = 0;
    bn__em_view v;
    if (!bn__em_view_make(G, em, x0, n, 1, &v))
        return;
    for (int a = 0; a < side; a++)
        for (int b = 0; b < side; b++) {
            double u = (a + bn__rng_uniform(r)) / side, w = (b + bn__rng_uniform(r)) / side, dir[3], c;
            int seen;
            bn__sph_poly_sample(&v.sp, u, w, dir);
            c = bn__em_ray(G, em, &v, n, dir, &seen);
            *rays += c > 0;
            sc += c;
            scv += seen ? c : 0;
        }
    for (int k = 0; k < 3; k++)
        out[k] += sc > 0 ? em->Le[k] * v.F * (scv / sc) : 0;
}

/* The gather's hits take one shadow ray per emitter, in a control-variate form that is exact where
 * the emitter is wholly in view: F (closed form) minus the blocked part, whose integrand is the
 * kernel times (1 - V), estimated from one point: by solid angle near the emitter, (Omega / pi) cos
 * (1 - V); by area beyond BN__HIT_FAR of its diameter from its centre, A cos cos' (1 - V) / (pi r^2),
 * as smooth there and cheaper than the spherical polygon's set-up. Unbiased either way (the
 * cosines clamped at 0); where the emitter is wholly hidden the estimate scatters about 0. */
#define BN__HIT_FAR 2.0

/* The kernel at a point y drawn by area on em (the part behind x's plane has cos <= 0: no ray),
 * times A / pi, and whether the shadow ray from v->xo reaches y. */
static double bn__far_kernel(const bn__gather *G, const bn__emitter *em, const bn__em_view *v, const double n[3],
                             bn__rng *r, int *seen, double *rays)
{
    double y[3], d[3], r2, dist, cx, ce, u = bn__rng_uniform(r), w = bn__rng_uniform(r);
    bn__poly_sample(em->v, em->nv, u, w, y);
    bn_v3_sub(y, v->xo, d);
    r2 = bn_v3_dot(d, d);
    dist = sqrt(r2);
    *seen = 1;
    if (!(dist > 4 * G->eps))
        return 0;
    bn_v3_scale(d, 1 / dist, d);
    cx = bn_v3_dot(d, n);
    ce = -bn_v3_dot(d, em->n);
    if (!(cx > 0) || !(ce > 0))
        return 0;
    *rays += 1;
    *seen = !bn_rt_occluded(G->rt, v->xo, d, 0, dist - 2 * G->eps / ce);
    return em->area * cx * ce / (BN_PI * r2);
}

/* One sample of emitter em seen from x (normal n): *F its form factor by the closed form, *est a
 * one-point unbiased estimate of it (by solid angle near em, (Omega / pi) cos; by area beyond
 * BN__HIT_FAR of its diameter from its centre), *seen whether that point's shadow ray reaches em.
 * 0 when x cannot see em. */
static int bn__em_sample(const bn__gather *G, const bn__emitter *em, const double x[3], const double n[3], bn__rng *r,
                         double *F, double *est, int *seen, double *rays)
{
    double xc[3], dir[3], c, u, w;
    int far;
    bn__em_view v;
    bn_v3_sub(x, em->c, xc);
    far = bn_v3_dot(xc, em->n) > 2 * G->eps && bn_v3_len(xc) > BN__HIT_FAR * em->diam;
    if (!bn__em_view_make(G, em, x, n, !far, &v))
        return 0;
    *F = v.F;
    if (far) {
        *est = bn__far_kernel(G, em, &v, n, r, seen, rays);
        return 1;
    }
    u = bn__rng_uniform(r);
    w = bn__rng_uniform(r);
    bn__sph_poly_sample(&v.sp, u, w, dir);
    c = bn__em_ray(G, em, &v, n, dir, seen);
    *rays += c > 0;
    *est = v.sp.total * c / BN_PI;
    return 1;
}

/* Emitter em's direct light at x (normal n) from one shadow ray, rho-free, times wt, added to out:
 * Le (F - the blocked part's one-point estimate), exact where em is wholly in view. */
static void bn__direct_em_one(const bn__gather *G, const bn__emitter *em, const double x[3], const double n[3],
                              bn__rng *r, double wt, double out[3], double *rays)
{
    double F, est;
    int seen;
    if (!bn__em_sample(G, em, x, n, r, &F, &est, &seen, rays))
        return;
    for (int k = 0; k < 3; k++)
        out[k] += wt * em->Le[k] * (F - (seen ? 0 : est));
}

/* The hits' picks choose among the lights of a node that subtends less than this sine by power
 * alone: their K^2 E loses little (on the Cornell box with its light cut into 10,000 faces, its
 * median per-pixel error 0.241% against 0.238%) and the gather's time falls 2.6x. */
#define BN__HIT_FAR_SINE 0.3

/* rho-free direct light at x (normal n, on face f) from a few emitting faces (2 .. BN__PICK_MAX), added to
 * out: every face's unoccluded F by the closed form, Le F summed, less the blocked part of one face picked
 * in proportion to its Le F (one shadow ray, bn__em_sample's estimate, over the pick's probability).
 * Unbiased as a ray to each face is, exact where the picked face is wholly in view (a furnace: every
 * face), one ray instead of one per face: a gather's hits in the living room (8 emitting faces) spent 72%
 * of its bake there. */
#define BN__PICK_MAX 64
static void bn__direct_em_pick(const bn__gather *G, const double x[3], const double n[3], size_t f, bn__rng *r,
                               double out[3], double *rays)
{
    double w[BN__PICK_MAX], W = 0, F, est, u;   /* w: each face's Le F summed over channels */
    size_t e = 0;
    int seen;
    for (size_t k = 0; k < G->nem; k++) {
        const bn__emitter *em = &G->em[k];
        bn__em_view v;
        w[k] = 0;
        if (bn__em_self(G, k, f) || !bn__em_view_make(G, em, x, n, 0, &v))
            continue;
        w[k] = (em->Le[0] + em->Le[1] + em->Le[2]) * v.F;
        W += w[k];
        for (int c = 0; c < 3; c++)
            out[c] += em->Le[c] * v.F;
    }
    if (!(W > 0))
        return;
    u = bn__rng_uniform(r) * W;
    while (e + 1 < G->nem && (u >= w[e] || !(w[e] > 0))) {
        u -= w[e];
        e++;
    }
    if (!(w[e] > 0))
        return;
    const double *Le = G->em[e].Le;
    if (!bn__em_sample(G, &G->em[e], x, n, r, &F, &est, &seen, rays)) {
        est = w[e] / (Le[0] + Le[1] + Le[2]);   /* no sample of it (a degenerate view): its F, taken as hidden,
                                                   as a ray to each face takes it */
        seen = 0;
    }
    for (int c = 0; !seen && c < 3; c++)
        out[c] -= Le[c] * est * W / w[e];
}

/* rho-free direct light at x (normal n) from the punctual lights, added to out: each light's irradiance
 * over pi, where one shadow ray reaches it (a point light is a point: its shadow is sharp, no noise). */
static void bn__direct_punctual(const bn__gather *G, const double x[3], const double n[3], double out[3],
                                double *rays)
{
    for (size_t k = 0; k < G->npl; k++) {
        double E[3], wi[3], d, o[3];
        if (!bn_light_irradiance(&G->pl[k], G->unit, x, n, E, wi, &d))
            continue;
        bn_v3_madd(x, G->eps, n, o);
        *rays += 1;
        if (bn_rt_occluded(G->rt, o, wi, 0, isinf(d) ? INFINITY : d * (1 - 1e-9) - G->eps))
            continue;
        for (int c = 0; c < 3; c++)
            out[c] += E[c] / BN_PI;
    }
}

/* rho-free direct light at a gather's hit x (normal n, on face f): one shadow ray per emitter, or
 * one to an emitter picked from the light tree (unbiased: Le (F - blocked) / pdf); and the punctual
 * lights'. */
static void bn__direct_one(const bn__gather *G, const double x[3], const double n[3], size_t f, bn__rng *r,
                           double out[3], double *rays)
{
    out[0] = out[1] = out[2] = 0;
    bn__direct_punctual(G, x, n, out, rays);
    if (G->tree) {
        double pdf;
        size_t e = bn__lights_pick(G->tree, x, n, bn__rng_uniform(r), BN__HIT_FAR_SINE, &pdf);
        if (e != BN__LIGHTS_NONE && !bn__em_self(G, e, f) && pdf > 0)
            bn__direct_em_one(G, &G->em[e], x, n, r, 1 / pdf, out, rays);
        return;
    }
    if (G->nem > 1 && G->nem <= BN__PICK_MAX) {
        bn__direct_em_pick(G, x, n, f, r, out, rays);
        return;
    }
    for (size_t e = 0; e < G->nem; e++)
        if (!bn__em_self(G, e, f))
            bn__direct_em_one(G, &G->em[e], x, n, r, 1, out, rays);
}

/* rho-free direct light at x (normal n, on face f) from m emitters picked from the light tree by
 * stratified uniforms, one ray each: the unoccluded light (the mean of Le F / pdf) times the
 * visible fraction estimated across the picks, per channel sum Le est V / pdf over sum Le est / pdf,
 * as bn__direct_em's sum cos V / sum cos does for one face: exact where every pick is wholly in
 * view or wholly hidden (a shadow is black, not noise about 0), consistent in a penumbra. */
static void bn__direct_tree(const bn__gather *G, const double x[3], const double n[3], size_t f, bn__rng *r, int m,
                            double out[3], double *rays)
{
    double T[3] = {0, 0, 0}, N[3] = {0, 0, 0}, D[3] = {0, 0, 0};
    for (int i = 0; i < m; i++) {
        double pdf, F, est;
        int seen;
        size_t e = bn__lights_pick(G->tree, x, n, (i + bn__rng_uniform(r)) / m, 0, &pdf);
        if (e == BN__LIGHTS_NONE || bn__em_self(G, e, f) || !(pdf > 0) ||
            !bn__em_sample(G, &G->em[e], x, n, r, &F, &est, &seen, rays))
            continue;
        for (int k = 0; k < 3; k++) {
            double a = G->em[e].Le[k] / pdf;
            T[k] += a * F;
            D[k] += a * est;
            N[k] += seen ? a * est : 0;
        }
    }
    for (int k = 0; k < 3; k++)
        out[k] = D[k] > 0 ? T[k] / m * (N[k] / D[k]) : 0;
}

/* rho-free direct light at x (normal n, on face f): the sum over the emitters of bn__direct_em
 * (side x side rays each), or, with the light tree, bn__direct_tree over side x side picks; and the
 * punctual lights'. */
static void bn__direct(const bn__gather *G, const double x0[3], const double n[3], size_t f, bn__rng *r, int side,
                       double out[3], double *rays)
{
    double pl[3] = {0, 0, 0};
    bn__direct_punctual(G, x0, n, pl, rays);
    out[0] = out[1] = out[2] = 0;
    if (G->tree)
        bn__direct_tree(G, x0, n, f, r, side * side, out, rays);
    for (size_t e = 0; !G->tree && e < G->nem; e++)
        if (!bn__em_self(G, e, f))
            bn__direct_em(G, &G->em[e], x0, n, r, side, out, rays);
    for (int c = 0; c < 3; c++)
        out[c] += pl[c];
}

/* The reflectance at x on patch p: its material's, times its texture at x (glTF baseColorTexture, MTL
 * map_Kd) when it has one: the pixels show the texture while the transport uses its patch means. */
static void bn__rho_at(const bn__gather *G, const bn_patch *p, const double x[3], double rho[3])
{
    if (G->textured)
        bn_scene_reflectance_at(G->scene, p->face, x, rho);
    else
        memcpy(rho, G->mat[p->material].rho, 3 * sizeof *rho);
}

/* KE at a gather's hit from the emitting faces themselves (one shadow ray each), rho applied, added
 * to hv[0..2] x wt: the patch's KE is constant over it, where the light it reads is not (a shadow
 * edge, the fall-off near a lamp); the K^2 E it gathers is then free of that error (on the Cornell
 * box at 300 patches, the median per-pixel error of K^2 E falls from 0.58% to ...). */
static void bn__hit_direct(const bn__gather *G, const bn_hit *q, bn__rng *r, double wt, double *hv, double *rays)
{
    const bn_patch *p = &G->patch[q->patch];
    double ke[3], rho[3];
    bn__rho_at(G, p, q->p, rho);
    if (!(rho[0] > 0 || rho[1] > 0 || rho[2] > 0))
        return;
    bn__direct_one(G, q->p, p->normal, p->face, r, ke, rays);
    for (int c = 0; c < 3; c++)
        hv[c] += wt * rho[c] * ke[c];
}

/* One camera sample: E and KE (rho applied) added to acc[0..5]; hv (n + 1 layers x 3) receives the
 * hemisphere means of K^1 E .. K^n E and rest at the hits (rho not applied), rho the reflectance at the
 * point seen (its texture's there). Returns the face seen, or -1 (a miss or a back face: black,
 * surfaces are one-sided). */
static long bn__sample(const bn__gather *G, const double o[3], const double d[3], bn__rng *r, double *acc,
                       double *hv, double rho[3], bn_gather_stats *st)
{
    bn_hit h;
    st->camera_rays += 1;
    memset(hv, 0, (size_t)(G->n + 1) * 3 * sizeof(double));
    if (!bn_rt_intersect(G->rt, o, d, 0, INFINITY, &h) || !h.front)
        return -1;
    st->front_hits += 1;
    return bn__shade(G, &h, r, acc, hv, rho, st);
}

/* A gather's hit nearer than this times the size of its patch (sqrt of its area): its patch means of
 * K^2 E and beyond are not what the hit point has (the foot of a block's side seen from the floor
 * beside it is darker than the side's mean: corner vertices of a bake came out 60-260% too bright), so
 * they come from a small gather at the hit itself, whose hits take their KE from the emitters (as the
 * first level's do) and, where near again, gather once more, down to BN__NEAR_DEPTH levels: in a corner
 * every level's hits are near, and the first level alone left K^4 E at a block's foot 3x the tracer's.
 * The first level casts BN__NEAR_SIDE^2 rays, the deeper ones one each (a path through the corner). On
 * the Cornell box's bake, L's 95th percentile per-vertex error: 6.1% with one level reading patch means
 * of KE, 4.2% with the hits' own KE, 3.4% with two levels, 3.2% with three (the bake 1.7 -> 2.9 s). */
#define BN__NEAR 0.5
#define BN__NEAR_DEPTH 3
#define BN__NEAR_SIDE 2   /* the first level's rays per side of the stratified grid: 4 (16 gave the same 95th percentiles at 1.6x the bake's time) */

/* Direction (a, b) of a side x side stratified cosine-weighted grid over the hemisphere of n (s, t: its
 * tangents). */
static void bn__cosine_dir(const double n[3], const double s[3], const double t[3], int a, int b, int side,
                           bn__rng *r, double dir[3])
{
    double u1 = (a + bn__rng_uniform(r)) / side, u2 = (b + bn__rng_uniform(r)) / side;
    bn_v3_cosine_dir(n, s, t, u1, u2, dir);
}

/* The gather at a near hit q, level `depth` (0: a first gather's hit): the sums over its rays' hits of
 * every gathered layer's value, g ((n + 1) x 3), each hit's as the first gather takes it (its own KE,
 * and its near gather below BN__NEAR_DEPTH). From eps in front of q, moved 4 eps toward its patch's
 * centroid: a hit in a corner (where a near one usually is) would otherwise send rays along the adjacent
 * face's plane, out through it. Its own random stream: the caller's samples stay as they were. */
static void bn__hit_values_near(const bn__gather *G, const bn_hit *q, const bn__rng *r0, double wt, double *hv,
                                bn_gather_stats *st, int depth);

static void bn__near_gather(const bn__gather *G, const bn_hit *q, const bn__rng *r0, double *g, bn_gather_stats *st,
                            int depth)
{
    const bn_patch *p = &G->patch[q->patch];
    bn__rng r = {bn__hash64(r0->state ^ (uint64_t)q->patch)};
    double in[3], s[3], t[3], xo[3], d;
    bn_v3_sub(p->centroid, q->p, in);
    d = bn_v3_len(in);
    bn_v3_madd(q->p, G->eps, p->normal, xo);
    if (d > 8 * G->eps)
        bn_v3_madd(xo, 4 * G->eps / d, in, xo);
    bn_v3_basis(p->normal, s, t);
    int side = depth ? 1 : BN__NEAR_SIDE;
    for (int a = 0; a < side; a++)
        for (int b = 0; b < side; b++) {
            double dir[3];
            bn_hit h;
            bn__cosine_dir(p->normal, s, t, a, b, side, &r, dir);
            st->gather_rays += 1;
            if (!bn_rt_intersect(G->rt, xo, dir, 0, INFINITY, &h) || !h.front)
                continue;
            bn__hit_values_near(G, &h, &r, 1.0, g, st, depth + 1);
            if (G->hit_direct)
                bn__hit_direct(G, &h, &r, 1.0, g, &st->shadow_rays);
        }
}

/* Patch i receives nothing in the solution (KE .. K^n E and rest all 0: the inside of a closed object's
 * back sides, a cavity no light enters): a near gather there can only find 0 too. */
static int bn__dark(const bn__gather *G, size_t i)
{
    double sum = 0;
    for (int l = 1; l <= G->n + 1; l++)
        for (int c = 0; c < 3; c++)
            sum += (l <= G->n ? G->terms[l] : G->rest)[3 * i + c];
    return !(sum > 0);
}

/* A gather's hit's layers into hv as bn__hit_values, but a near hit's (above level BN__NEAR_DEPTH) K^2 E
 * and beyond from its own gather: K^(l+1) E = rho K^l E gathered there, rest = rho (K^n E + rest)
 * gathered. */
static void bn__hit_values_near(const bn__gather *G, const bn_hit *q, const bn__rng *r0, double wt, double *hv,
                                bn_gather_stats *st, int depth)
{
    const bn_patch *p = &G->patch[q->patch];
    int n = G->n;
    if (depth >= BN__NEAR_DEPTH || n < 1 || n + 1 > 72 || !(q->t < BN__NEAR * sqrt(p->area)) || bn__dark(G, q->patch)) {
        bn__hit_values(G, q, wt, hv);
        return;
    }
    double g[3 * 72] = {0}, rho[3], inv = depth ? 1.0 : 1.0 / (BN__NEAR_SIDE * BN__NEAR_SIDE);
    if (!G->hit_direct)   /* KE: the patch's, as far hits (with hit_direct: the hit's own, added after) */
        for (int c = 0; c < 3; c++)
            hv[c] += wt * G->terms[1][3 * q->patch + c];
    bn__rho_at(G, p, q->p, rho);
    bn__near_gather(G, q, r0, g, st, depth);
    for (int c = 0; c < 3; c++) {
        for (int l = 1; l < n; l++)
            hv[3 * l + c] += wt * rho[c] * g[3 * (l - 1) + c] * inv;
        hv[3 * n + c] += wt * rho[c] * (g[3 * (n - 1) + c] + g[3 * n + c]) * inv;
    }
}

long bn__shade(const bn__gather *G, const bn_hit *hit, bn__rng *r, double *acc, double *hv, double rho[3],
               bn_gather_stats *st)
{
    const bn_hit h = *hit;
    const bn_patch *p = &G->patch[h.patch];
    double ke[3], s[3], t[3], xo[3], inv = 1.0 / ((double)G->gh * G->gh);
    bn__rho_at(G, p, h.p, rho);
    bn__direct(G, h.p, p->normal, p->face, r, G->gl, ke, &st->shadow_rays);
    for (int c = 0; c < 3; c++) {
        acc[c] += G->terms[0][3 * h.patch + c];
        acc[3 + c] += rho[c] * ke[c];
    }
    if (rho[0] > 0 || rho[1] > 0 || rho[2] > 0) {
        bn_v3_basis(p->normal, s, t);
        for (int k = 0; k < 3; k++)
            xo[k] = h.p[k] + G->eps * p->normal[k];
        for (int a = 0; a < G->gh; a++)
            for (int b = 0; b < G->gh; b++) {
                double dir[3];
                bn_hit q;
                bn__cosine_dir(p->normal, s, t, a, b, G->gh, r, dir);
                st->gather_rays += 1;
                if (!bn_rt_intersect(G->rt, xo, dir, 0, INFINITY, &q) || !q.front)
                    continue;
                bn__hit_values_near(G, &q, r, inv, hv, st, 0);
                if (G->hit_direct)
                    bn__hit_direct(G, &q, r, inv, hv, &st->shadow_rays);
            }
    }
    return (long)p->face;
}

/* The gathered layers after the per-pixel pass: aux holds per pixel BN__AUX(n) doubles: the face seen
 * by all its samples plus one (0: mixed, missed, or none), the mean reflectance at its samples' points,
 * then the hemisphere means (rho not applied) for one face, or their rho-weighted sample mean (rho
 * applied) for a mixed pixel. Each
 * pixel's gathered means are averaged with those of the pixels within `radius` that see the same face
 * (a box filter that never crosses a face's edge: the indirect terms are smooth inside a face), then
 * the layers K^2 E .. K^n E, rest and L are composed. */
static void bn__compose(const bn__gather *G, const bn_camera *cam, const double *aux, int radius, bn_image *out)
{
    int n = G->n, w = cam->width, h = cam->height;
    size_t stride = BN__AUX(n);
#pragma omp parallel for schedule(dynamic, 4)
    for (int y = 0; y < h; y++) {
        double g[3 * 66];
        for (int x = 0; x < w; x++) {
            size_t pix = (size_t)y * (size_t)w + (size_t)x;
            const double *a = aux + pix * stride;
            double face = a[0];
            const double *rho = NULL;
            int nl = n + 1;
            memcpy(g, a + 4, (size_t)nl * 3 * sizeof(double));
            if (face > 0) {
                double cnt = 1;
                rho = a + 1;   /* the pixel's own reflectance: a texture varies inside a face */
                for (int yy = y - radius; yy <= y + radius; yy++)
                    for (int xx = x - radius; xx <= x + radius; xx++) {
                        const double *b;
                        if (yy < 0 || yy >= h || xx < 0 || xx >= w || (yy == y && xx == x))
                            continue;
                        b = aux + ((size_t)yy * (size_t)w + (size_t)xx) * stride;
                        if (b[0] != face)
                            continue;
                        for (int k = 0; k < 3 * nl; k++)
                            g[k] += b[4 + k];
                        cnt += 1;
                    }
                for (int k = 0; k < 3 * nl; k++)
                    g[k] = rho[k % 3] * g[k] / cnt;
            }
            for (int c = 0; c < 3; c++) {
                double tot = 0;
                for (int k = 2; k <= n; k++)   /* K^k E = rho x the gathered K^(k-1) E */
                    out[k].rgb[3 * pix + c] = (float)g[3 * (k - 2) + c];
                out[n + 1].rgb[3 * pix + c] = (float)(g[3 * (n - 1) + c] + g[3 * n + c]);   /* rest: K^n E + rest gathered */
                for (int l = 0; l < nl; l++)
                    tot += g[3 * l + c];
                out[n + 2].rgb[3 * pix + c] =
                    (float)((double)out[0].rgb[3 * pix + c] + (double)out[1].rgb[3 * pix + c] + tot);   /* L */
            }
        }
    }
}

/* The camera, the term count, the sample counts and the output images, checked. */
static bn_status bn__gather_check(const bn_camera *cam, int n, const bn_gather_opts *o, const bn_image *out,
                                  bn_error *err)
{
    bn_status st = bn_camera_validate(cam, err);
    if (st != BN_OK)
        return st;
    if (n < 1 || n > 20)
        return bn_error_set(err, BN_EINPUT, "gather: %d bounce terms; the gather needs E and KE at least (-n 1), and "
                            "keeps at most 20", n);
    if (o->filter < 0 || o->filter > 64)
        return bn_error_set(err, BN_EINPUT, "gather: filter radius %d pixels (0 .. 64)", o->filter);
    if (o->light_samples < 1 || o->light_samples > (1 << 16) || o->hemi_samples < 1 || o->hemi_samples > (1 << 20))
        return bn_error_set(err, BN_EINPUT, "gather: %d light and %d gather samples (1 .. 65536 and 1 .. 2^20)",
                            o->light_samples, o->hemi_samples);
    for (size_t l = 0; l < (size_t)n + 3; l++)
        if (!out[l].rgb || out[l].width != cam->width || out[l].height != cam->height)
            return bn_error_set(err, BN_EINTERNAL, "gather: output image %zu is not allocated at %dx%d", l, cam->width,
                                cam->height);
    return BN_OK;
}

/* The light tree over the emitting faces, each weighted by its area x mean radiance. */
static bn_status bn__gather_tree(bn__gather *G, bn_error *err)
{
    bn__light *l = bn__malloc_array(G->nem, sizeof *l);
    if (!l)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the light tree of %zu emitting faces", G->nem);
    for (size_t e = 0; e < G->nem; e++) {
        const bn__emitter *em = &G->em[e];
        l[e] = (bn__light){em->v, em->nv, {em->n[0], em->n[1], em->n[2]},
                           em->area * (em->Le[0] + em->Le[1] + em->Le[2]) / 3};
    }
    G->tree = bn__lights_build(l, G->nem, 4 * G->eps);
    free(l);
    return G->tree ? BN_OK : bn_error_set(err, BN_ENOMEM, "out of memory for the light tree of %zu emitting faces",
                                          G->nem);
}

/* --smooth: the vertex values of K^1 E .. K^n E and rest, read at the gather's hits. */
static bn_status bn__gather_smooth(bn__gather *G, const bn_bake *smooth, bn_error *err)
{
    size_t nv = bn_bake_vertex_count(smooth);
    if (!(G->vv = bn__calloc((size_t)G->n + 1, sizeof *G->vv)))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    for (int l = 0; l <= G->n; l++) {
        if (!(G->vv[l] = bn__malloc_array(nv, 3 * sizeof(double))))
            return bn_error_set(err, BN_ENOMEM, "out of memory for %zu vertex values", nv);
        bn_bake_vertex_values(smooth, l < G->n ? G->terms[l + 1] : G->rest, G->vv[l]);
    }
    return BN_OK;
}

/* G from the ray caster, the terms and the options: the emitters, and the vertex values with
 * --smooth. */
bn_status bn__gather_init(bn__gather *G, const bn_rt *rt, const double *const *terms, int n, const double *rest,
                                 const bn_gather_opts *o, bn_error *err)
{
    size_t nm, np;
    bn_status st;
    G->rt = rt;
    G->scene = bn_rt_scene(rt);
    G->patch = bn_scene_patches(G->scene, &np);
    G->textured = bn_scene_textured(G->scene);
    G->mat = bn_scene_materials(G->scene, &nm);
    G->terms = terms;
    G->rest = rest;
    G->n = n;
    G->gl = bn__side(o->light_samples);
    G->gh = bn__side(o->hemi_samples);
    G->eps = bn_rt_epsilon(rt);
    G->smooth = o->smooth;
    G->pl = bn_scene_lights(G->scene, &G->npl);
    G->unit = bn_unit_to_metres(bn_scene_unit(G->scene));
    if ((st = bn__gather_emitters(G, o->merge_emitters, err)) != BN_OK || (G->nem > (size_t)o->tree_emitters &&
                                                          (st = bn__gather_tree(G, err)) != BN_OK))
        return st;
    G->hit_direct = G->nem > 0 && o->hit_emitters > 0 && (G->nem <= (size_t)o->hit_emitters || G->tree);
    return o->smooth ? bn__gather_smooth(G, o->smooth, err) : BN_OK;
}

/* Per-thread buffers of one pixel's samples. */
typedef struct bn__pixbuf {
    double *acc, *hv, *gp, *gr;   /* 6; 3 (n + 1) each */
} bn__pixbuf;

/* Pixel (x, y): its spp jittered samples (sx x sy strata), E and KE into out[0..1], the face all its
 * samples saw (plus one; 0: mixed or missed) and the gathered means into aux (stride values). */
static void bn__gather_pixel(const bn__gather *G, const bn_camera *cam, const bn_gather_opts *o, int x, int y, int sx,
                             int sy, bn__pixbuf *B, bn_image *out, double *aux, bn_gather_stats *ls)
{
    size_t pix = (size_t)y * (size_t)cam->width + (size_t)x, nl3 = 3 * ((size_t)G->n + 1);
    long face = -2;   /* -2: no sample yet; -1: mixed or missed */
    double *a = aux + pix * BN__AUX(G->n), rho[3], rsum[3] = {0, 0, 0};
    memset(B->acc, 0, 6 * sizeof(double));
    memset(B->gp, 0, nl3 * sizeof(double));
    memset(B->gr, 0, nl3 * sizeof(double));
    for (int s = 0; s < cam->spp; s++) {
        double fx = 0.5, fy = 0.5, org[3], dir[3];
        bn__rng r;
        long f;
        if (cam->spp > 1) {
            bn__rng j = bn__rng_make(o->seed, pix, (uint64_t)s);
            fx = ((s % sx) + bn__rng_uniform(&j)) / sx;
            fy = ((s / sx) + bn__rng_uniform(&j)) / sy;
        }
        r = bn__rng_make(o->seed ^ BN__GATHER_STREAM, pix, (uint64_t)s);
        bn_camera_ray(cam, x + fx, y + fy, org, dir);
        f = bn__sample(G, org, dir, &r, B->acc, B->hv, rho, ls);
        face = face == -2 ? f : face == f ? face : -1;
        if (f >= 0) {
            for (int c = 0; c < 3; c++)
                rsum[c] += rho[c];
            for (size_t k = 0; k < nl3; k++) {
                B->gp[k] += B->hv[k];
                B->gr[k] += rho[k % 3] * B->hv[k];
            }
        }
    }
    for (int l = 0; l < 2; l++)
        for (int c = 0; c < 3; c++)
            out[l].rgb[3 * pix + c] = (float)(B->acc[3 * l + c] / cam->spp);
    a[0] = face >= 0 ? (double)face + 1 : 0;
    for (int c = 0; c < 3; c++)
        a[1 + c] = rsum[c] / cam->spp;
    for (size_t k = 0; k < nl3; k++)
        a[4 + k] = (face >= 0 ? B->gp[k] : B->gr[k]) / cam->spp;
}

/* Under mpirun: every rank's status, then its rows to every rank (each pixel nonzero on one rank:
 * exact). stop: 2 out of memory, 1 interrupted. */
static bn_status bn__gather_share(int stop, bn_image *out, const bn_camera *cam, double *aux, size_t naux,
                                  bn_error *err)
{
    bn_status here = stop == 2 ? BN_ENOMEM : bn_interrupted() != BN_OK ? bn_interrupted() : stop ? BN_EINTR : BN_OK;
    bn_status all = bn_dist_agree(here), st = BN_OK;
    if (all != BN_OK)
        return all == BN_ENOMEM ? bn_error_set(err, all, "out of memory while gathering")
                                : bn_error_set(err, all, "gather interrupted");
    for (size_t l = 0; l < 2 && bn_dist_size() > 1 && st == BN_OK; l++)
        st = bn_dist_sum_float(out[l].rgb, (size_t)3 * (size_t)cam->width * (size_t)cam->height, err);
    if (st == BN_OK && bn_dist_size() > 1)
        st = bn_dist_sum(aux, naux, err);
    return st;
}

/* Every row of this rank: E and KE into out[0..1], the faces and gathered means into aux (stride
 * values per pixel); c[4] += camera, shadow and gather rays and front hits. Returns 0, 1 interrupted, 2 out of memory. */
static int bn__gather_rows(const bn__gather *G, const bn_camera *cam, const bn_gather_opts *o, bn_image *out,
                           double *aux, size_t stride, double c[4])
{
    int sx, sy;
    volatile int stop = 0;
    double cr = 0, sr = 0, gr = 0, fh = 0;
    size_t done = 0, nl3 = stride - 4, rowv = (size_t)cam->width * stride, row3 = (size_t)3 * (size_t)cam->width;
    bn__progress prog;
    for (sx = (int)floor(sqrt((double)cam->spp)); sx > 1 && cam->spp % sx != 0;)
        sx--;
    sy = cam->spp / sx;
    bn__progress_begin(&prog, "gather", (size_t)cam->height, o->quiet);
#pragma omp parallel reduction(+ : cr, sr, gr, fh)
    {
        bn__pixbuf B = {malloc(6 * sizeof(double)), malloc(nl3 * sizeof(double)), malloc(nl3 * sizeof(double)),
                        malloc(nl3 * sizeof(double))};
#pragma omp for schedule(dynamic, 1)
        for (int y = 0; y < cam->height; y++) {
            if (stop || !bn_dist_mine((size_t)y)) {
                /* another rank's row: zero here (summed exactly afterwards) */
                for (size_t l = 0; l < 2; l++)
                    memset(out[l].rgb + (size_t)y * row3, 0, row3 * sizeof(float));
                memset(aux + (size_t)y * rowv, 0, rowv * sizeof(double));
                continue;
            }
            if (!B.acc || !B.hv || !B.gp || !B.gr || bn_interrupted() != BN_OK) {
                stop = !B.acc || !B.hv || !B.gp || !B.gr ? 2 : 1;
                continue;
            }
            for (int x = 0; x < cam->width; x++) {
                bn_gather_stats ls = {0};
                bn__gather_pixel(G, cam, o, x, y, sx, sy, &B, out, aux, &ls);
                cr += ls.camera_rays;
                sr += ls.shadow_rays;
                gr += ls.gather_rays;
                fh += ls.front_hits;
            }
            bn__progress_step(&prog, &done, 1);
        }
        free(B.acc);
        free(B.hv);
        free(B.gp);
        free(B.gr);
    }
    bn__progress_end(&prog);
    c[0] += cr;
    c[1] += sr;
    c[2] += gr;
    c[3] += fh;
    return stop;
}

/* The layers composed, checked finite, and the counts (summed over ranks) into stats. */
static bn_status bn__gather_finish(const bn__gather *G, const bn_camera *cam, const double *aux, int filter,
                                   double c[4], double t0, bn_image *out, bn_gather_stats *stats, bn_error *err)
{
    size_t npix = (size_t)cam->width * (size_t)cam->height;
    bn_status st;
    bn__compose(G, cam, aux, filter, out);
    for (size_t l = 0; l < (size_t)G->n + 3; l++)
        for (size_t k = 0; k < (size_t)3 * npix; k++)
            if (!isfinite(out[l].rgb[k]))
                return bn_error_set(err, BN_ENUMERIC, "gather: a non-finite value in layer %zu at pixel %zu", l, k / 3);
    if (!stats)
        return BN_OK;
    if (bn_dist_size() > 1 && (st = bn_dist_sum(c, 4, err)) != BN_OK)
        return st;
    stats->camera_rays = c[0];
    stats->shadow_rays = c[1];
    stats->gather_rays = c[2];
    stats->front_hits = c[3];
    stats->emitters = G->faces;
    stats->lights = G->nem;
    stats->hit_direct = G->hit_direct;
    stats->light_tree = G->tree != NULL;
    stats->seconds = bn__now() - t0;
    return BN_OK;
}

static bn_status bn__gather_body(const bn_rt *rt, const bn_camera *cam, const double *const *terms, int n,
                                 const double *rest, const bn_gather_opts *o, bn_image *out, bn_gather_stats *stats,
                                 bn_error *err)
{
    bn__gather G;
    size_t npix = (size_t)cam->width * (size_t)cam->height, stride = BN__AUX(n);
    bn_status st;
    double t0 = bn__now(), c[4] = {0, 0, 0, 0}, *aux = NULL;

    memset(&G, 0, sizeof G);
    if ((st = bn__gather_check(cam, n, o, out, err)) != BN_OK)
        return st;
    if ((st = bn__gather_init(&G, rt, terms, n, rest, o, err)) != BN_OK)
        goto done;
    if (!(aux = bn__malloc_array(npix, stride * sizeof(double)))) {
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the gather's %zu x %zu values", npix, stride);
        goto done;
    }
    if ((st = bn__gather_share(bn__gather_rows(&G, cam, o, out, aux, stride, c), out, cam, aux, npix * stride,
                               err)) != BN_OK)
        goto done;
    st = bn__gather_finish(&G, cam, aux, o->filter, c, t0, out, stats, err);
done:
    bn__gather_free(&G);
    free(aux);
    return st;
}

void bn__gather_free(bn__gather *G)
{
    if (G->vv)
        for (int l = 0; l <= G->n; l++)
            free(G->vv[l]);
    free(G->vv);
    free(G->em);
    free(G->owner);
    bn__lights_free(G->tree);
    memset(G, 0, sizeof *G);
}

bn_status bn_gather_render(const bn_rt *rt, const bn_camera *cam, const double *const *terms, int n,
                           const double *rest, const bn_gather_opts *o, bn_image *out, bn_gather_stats *stats,
                           bn_error *err)
{
    bn_gather_opts def;
    int prev;
    bn_status st;
    if (!o) {
        bn_gather_opts_default(&def);
        o = &def;
    }
    prev = bn__threads_begin(o->threads);
    st = bn__gather_body(rt, cam, terms, n, rest, o, out, stats, err);
    bn__threads_end(prev);
    return st;
}
