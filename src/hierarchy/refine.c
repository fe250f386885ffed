/* Refinement: a link's error bound and form factor (the oracle), the recursive visit, one pass over
 * every link, and the brightness estimate the next pass weighs links by (refine.h). */
#include "hierarchy/refine.h"
#include "bounce/dist.h"
#include "formfactor/ff_internal.h"
#include "formfactor/ff_pair.h"
#include "base/vec.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

/* Levels a work item is refined in one go before the rest is queued for the next round (so one
 * root self-link becomes enough independent items to share among threads). */
#define BN__DEPTH_PER_ROUND 6
/* Quadrature tolerance of a leaf link's unoccluded form factor (a link's error is eps-level
 * anyway; the dense assembly's 1e-5 costs ten times the time near contact). */
#define BN__LEAF_RTOL 1e-3
/* Shadow rays of a leaf link (x4 when partly visible and its noise could matter: bn__link_ftol). */
#define BN__LEAF_RAYS 16
/* Partly visible links are split down to this fraction of eps. */
#define BN__PARTIAL 0.125
/* Receivers under something near (cover classes SHUT and BACK: the floor under an object) that are also
 * dark are held to a fraction of eps, down to BN__COVERED: eps is absolute, so the error it allows
 * everywhere is a large part of their light (the bunny box's floor under the bunny: K2E 1 to 15 times
 * the tracer's at eps). Dark: below BN__DARK of the scene's typical reflected radiance (bn__eps_at).
 * Covered but lit receivers keep eps: a radiator's fins, a bookcase's shelves and the inside of foliage
 * are 60% of the living room's furniture, and at eps/8 for every covered receiver the room's links went
 * from 77 M to 137 M (92 M now). */
#define BN__COVERED 0.125
#define BN__DARK 0.25
/* Nodes whose bounding spheres overlap are split whatever their light, unless their normals bound F
 * below this (bn__F_dihedral: nearly coplanar surfaces meeting at a crease); then the oracle decides. */
#define BN__CREASE 1e-3

/* eps in radiance for links into r: for a covered r, eps times its brightness against BN__DARK of the
 * typical reflected radiance, between BN__COVERED and 1 (1 before the first estimate of brightness). */
static double bn__eps_at(const bn__ref *R, uint32_t r)
{
    unsigned c = R->t->cover[r];
    if ((c != BN_COVER_SHUT && c != BN_COVER_BACK) || !(R->btyp > 0))
        return R->eps_abs;
    const double *B = R->Bmax + 3 * (size_t)r;
    double b = fmax(B[0], fmax(B[1], B[2]));
    return R->eps_abs * fmax(BN__COVERED, fmin(1.0, b / (BN__DARK * R->btyp)));
}

void bn__vec_push(bn__vec *v, uint32_t r, uint32_t s, float F, int partial)
{
    if (v->n == v->cap) {   /* x1.25: large blocks grow by mremap, without a copy; the slack is small */
        size_t cap = v->cap ? v->cap + v->cap / 4 : 256;
        bn__link *a = bn__realloc_array(v->a, cap, sizeof *a);
        if (!a) {
            v->oom = 1;
            return;
        }
        v->a = a;
        v->cap = cap;
    }
    v->a[v->n].r = r;
    v->a[v->n].s_bits = s | (partial ? BN__LINK_PARTIAL : 0);
    v->a[v->n++].F = F;
}

/* ---- geometry of nodes ---- */

/* 1 if the box of node v lies on or behind the plane (n, p). */
static int bn__box_behind(const bn__tree *t, uint32_t v, const double n[3], const double p[3], double tol)
{
    const double *b = t->box + 6 * (size_t)v;
    double m = 0;
    for (int k = 0; k < 3; k++)
        m += n[k] * ((n[k] > 0 ? b[3 + k] : b[k]) - p[k]);
    return m <= tol;
}

/* Can r and s exchange light at all? Same plane, or one wholly behind the other's plane (by more
 * than that plane's polygons stray from it): no. */
static int bn__culled(const bn__ref *R, uint32_t r, uint32_t s)
{
    const bn__tree *t = R->t;
    int32_t fr = t->plane[r], fs = t->plane[s];
    if (fr >= 0 && fr == fs)
        return 1;
    if (fr >= 0 && bn__box_behind(t, s, t->pn + 3 * fr, t->pp + 3 * fr, R->tol - t->pthick[fr]))
        return 1;
    if (fs >= 0 && bn__box_behind(t, r, t->pn + 3 * fs, t->pp + 3 * fs, R->tol - t->pthick[fs]))
        return 1;
    return 0;
}

/* A bound of F from r to s by their normals alone, however close: from a point of r (normal n, within
 * spread_r of r's axis) the fronts below s (normals within spread_s of s's axis a) lie where d . n > 0 and
 * d . a < sin spread_s. That set's cosine-weighted share of the hemisphere is at most (1 - cos psi) / 2,
 * psi the largest angle between n and a (the wedge between two planes), plus 4 sin spread_s (the band
 * |d . a| < sin spread_s, solid angle 4 pi sin spread_s, over pi). Two planes at 0.01 rad: 2.5e-5. */
static double bn__F_dihedral(const bn__tree *t, uint32_t r, uint32_t s)
{
    double c = bn_v3_dot(t->normal + 3 * (size_t)r, t->normal + 3 * (size_t)s);
    double psi = fmin(BN_PI, acos(bn_clamp(c, -1, 1)) + t->spread[r]);
    return fmin(1.0, 0.5 * (1 - cos(psi)) + 4 * sin(fmin(t->spread[s], 0.5 * BN_PI)));
}

/* A bound of the form factor between r and s: A / (pi d_min^2) between their bounding spheres,
 * never above 1, with A the larger of the two areas (A_s bounds the area-averaged F from r to s;
 * A_r how much that F varies across a large receiver, whose patches all get the mean). */
static double bn__F_bound(const bn__tree *t, uint32_t r, uint32_t s)
{
    double cr[3], cs[3], rr, rs, d;
    bn__tree_sphere(t, r, cr, &rr);
    bn__tree_sphere(t, s, cs, &rs);
    d = bn_v3_dist(cr, cs) - rr - rs;
    if (!(d > 0))
        return 1;
    return fmin(1.0, fmax(t->area[s], t->area[r]) / (BN_PI * d * d));
}

/* Sources may be clusters: a link carries their area-mean radiance, the sampled F weighing each
 * source patch by its own orientation. Receivers are polygons' nodes, or nearly flat clusters facing
 * the source, which hand each polygon its own cosine's share (operator.c). */

/* Are the bounding spheres of r and s apart? Only then is a link above the patches estimated by
 * point pairs: closer nodes are split whatever their brightness, as near the kernel's 1/r^2 a few
 * samples can make a row of F sum far above 1. */
static int bn__separated(const bn__tree *t, uint32_t r, uint32_t s)
{
    double cr[3], cs[3], rr, rs;
    bn__tree_sphere(t, r, cr, &rr);
    bn__tree_sphere(t, s, cs, &rs);
    return bn_v3_dist(cr, cs) > rr + rs;
}

/* May r receive from s as one node? A polygon's nodes may; a cluster only with flat_clusters, when
 * nearly flat and every surface below faces the direction to s (hierarchy_internal.h). */
static int bn__can_receive(const bn__ref *R, uint32_t r, uint32_t s)
{
    const bn__tree *t = R->t;
    double cr[3], cs[3], rr, rs, u[3], d;
    if (t->plane[r] >= 0)
        return 1;
    if (!R->o->flat_clusters || t->spread[r] > BN__FLAT)
        return 0;
    bn__tree_sphere(t, r, cr, &rr);
    bn__tree_sphere(t, s, cs, &rs);
    bn_v3_sub(cs, cr, u);
    if (!(bn_v3_normalize(u) > 0))
        return 0;
    d = fmax(-1.0, fmin(1.0, bn_v3_dot(u, t->normal + 3 * (size_t)r)));
    return acos(d) + t->spread[r] < 0.5 * BN_PI;
}

/* May refinement split node v? Clusters always; planar nodes down to min_area; patches never. */
static int bn__splittable(const bn__ref *R, uint32_t v)
{
    const bn__tree *t = R->t;
    return !bn__tree_is_leaf(t, v) && (t->plane[v] < 0 || R->force || t->area[v] >= R->min_area);
}

/* What a unit of F from s adds to r's radiance at most: max over channels of rho_r B_s. */
static double bn__link_weight(const bn__ref *R, uint32_t r, uint32_t s)
{
    const float *rho = R->t->rho_max + 3 * (size_t)r;
    const double *B = R->Bmax + 3 * (size_t)s;
    double m = 0;
    for (int c = 0; c < 3; c++)
        m = fmax(m, (double)rho[c] * B[c]);
    return m;
}

/* The oracle: the most a link could carry to the receiver's radiance, rho_r B_s F_bound. */
static double bn__link_error(const bn__ref *R, uint32_t r, uint32_t s)
{
    double m = bn__link_weight(R, r, s);
    return m > 0 ? m * bn__F_bound(R->t, r, s) : 0;
}

/* The oracle for any pair: overlapping nodes are split whatever their light (INFINITY; see
 * bn__separated) unless their normals alone bound F below BN__CREASE (nearly coplanar surfaces meeting
 * at a crease), then rho_r B_s times that bound. */
static double bn__link_error_near(const bn__ref *R, uint32_t r, uint32_t s)
{
    double b;
    if (bn__separated(R->t, r, s))
        return bn__link_error(R, r, s);
    b = bn__F_dihedral(R->t, r, s);
    return b <= BN__CREASE ? bn__link_weight(R, r, s) * b : INFINITY;
}

/* The F error a link may keep from its first look at visibility: BN__PARTIAL x eps in radiance (as
 * partly visible links above the patches are held to); 0 at eps 0. Before the first gather a
 * non-emitter's brightness is 0, so its partly visible leaf links get a second look in a later pass
 * when they turn out to matter (bn__second_look). */
static double bn__link_ftol(const bn__ref *R, uint32_t r, uint32_t s)
{
    double m = bn__link_weight(R, r, s);
    if (R->force)
        return 0;
    return m > 0 ? BN__PARTIAL * bn__eps_at(R, r) / m : INFINITY;
}

/* Is an existing link between patches (no pass can split it), its F from a first look that found it
 * partly visible (its partial bit: bn__ff_pair_quick's first_only), now bright enough for the second?
 * Its unoccluded F is at most BN__LEAF_RAYS x F (one ray in BN__LEAF_RAYS unblocked). A link above the
 * patches whose first look's noise could matter is split instead (its bound exceeds eps/8), unless
 * it lies between elements below min_area: those keep their first look (8 point pairs, 32 where
 * their bounding spheres overlap). */
static int bn__second_look(const bn__ref *R, uint32_t r, uint32_t s, float F)
{
    return bn__ff_vis_noise((double)F * BN__LEAF_RAYS, BN__LEAF_RAYS) > bn__link_ftol(R, r, s);
}

/* The leaves of m nodes v[j] (m <= BN__FIND_MAX) where the area fractions u1[j] fall: the last leaf k
 * of each with cum_area[k] <= its target. The searches advance in step, so that their cache misses
 * overlap (a sampled point pair: most of refinement's time at a million leaves): a link's point pairs
 * are searched all at once. */
#define BN__FIND_MAX 32
static void bn__find_leaves(const bn__tree *t, int m, const uint32_t *v, const double *u1, size_t *leaf)
{
    size_t lo[BN__FIND_MAX], hi[BN__FIND_MAX];
    double a[BN__FIND_MAX];
    int open = 0;
    for (int j = 0; j < m; j++) {
        lo[j] = t->lo[v[j]];
        hi[j] = t->hi[v[j]];
        a[j] = t->cum_area[lo[j]] + u1[j] * (t->cum_area[hi[j]] - t->cum_area[lo[j]]);
        open += hi[j] - lo[j] > 1;
    }
    while (open) {
        open = 0;
        for (int j = 0; j < m; j++)
            if (hi[j] - lo[j] > 1) {
                size_t mid = lo[j] + (hi[j] - lo[j]) / 2;
                if (t->cum_area[mid] <= a[j])
                    lo[j] = mid;
                else
                    hi[j] = mid;
                open += hi[j] - lo[j] > 1;
            }
    }
    for (int j = 0; j < m; j++)
        leaf[j] = lo[j];
}

/* The point of leaf q (in leaf order) at (u2, u3) in [0,1)^2, uniform in area; its normal. */
void bn__leaf_point(const bn__ref *R, size_t q, double u2, double u3, double x[3], const double **n)
{
    const bn__leaf_geom *g = &R->leaf[q];
    const double *pa = g->v[0], *pb = g->v[1], *pc = g->v[2];
    double f = g->fan0, s, b0, b1, b2;
    if (g->nc == 4) {   /* the fan triangle by area, as bn__poly_sample chooses it, its share precomputed */
        if (u2 < f)
            u2 = f > 0 ? u2 / f : 0.5;
        else {
            pb = pc;
            pc = g->v[3];
            u2 = f < 1 ? (u2 - f) / (1 - f) : 0.5;
        }
        u2 = bn_clamp(u2, 0, 1);
    }
    s = sqrt(u2);   /* square to triangle (Shirley) */
    b0 = 1 - s;
    b1 = s * (1 - u3);
    b2 = s * u3;
    for (int k = 0; k < 3; k++)
        x[k] = b0 * pa[k] + b1 * pb[k] + b2 * pc[k];
    *n = g->n;
}

/* A point of node v, uniform in area, from (u1, u2, u3) in [0,1)^3; its patch's normal. */
static void bn__node_point(const bn__ref *R, uint32_t v, double u1, double u2, double u3, double x[3], const double **n)
{
    size_t q;
    bn__find_leaves(R->t, 1, &v, &u1, &q);
    bn__leaf_point(R, q, u2, u3, x, n);
}

/* Is the segment from x (on a surface of normal nx) to y (normal ny) blocked? Both ends lifted by the
 * ray offset; one shadow ray, counted in w. */
static int bn__blocked(const bn__ref *R, const double x[3], const double nx[3], const double y[3], const double ny[3],
                       bn__worker *w)
{
    double o[3], e[3], d[3], len;
    bn_v3_madd(x, R->ray_eps, nx, o);
    bn_v3_madd(y, R->ray_eps, ny, e);
    bn_v3_sub(e, o, d);
    len = bn_v3_len(d);
    w->rays++;
    return len > 4 * R->ray_eps && bn_rt_occluded(R->rt, o, d, 0, 1.0 - R->ray_eps / len);
}

/* Leaves of a source node the exact kernel takes one by one (bn__F_kernel). */
#define BN__KERNEL_LEAVES 64

/* Area-averaged F from planar node r to the leaves of planar node s by the exact point-to-polygon
 * kernel (Lambert's contour integral) at S stratified points of r, each leaf clipped to the point's
 * front half-space and seen only from its own front, with one shadow ray per (point, leaf) pair to a
 * uniform point of the clipped leaf. For nodes too close for point pairs (their bounding spheres
 * overlap) that cannot be split (below min_area: a finely cut surface's original triangles), where
 * point pairs with Wallace's disk would bias F low by about a / (pi r^2). */
static double bn__F_kernel(const bn__ref *R, uint32_t r, uint32_t s, bn__worker *w, int *partial)
{
    const bn__tree *t = R->t;
    int S = 4 * (R->o->samples > 0 ? R->o->samples : 8), seen = 0, blocked = 0;
    bn__rng g = bn__rng_make(R->o->ff.seed ^ 0x6b65726e656cULL, ((uint64_t)r << 32) | s, 0);
    double sum = 0;
    for (int k = 0; k < S; k++) {
        double x[3];
        const double *nx;
        double u1 = (k + bn__rng_uniform(&g)) / S, u2 = bn__rng_uniform(&g), u3 = bn__rng_uniform(&g);
        bn__node_point(R, r, u1, u2, u3, x, &nx);
        for (size_t q = t->lo[s]; q < t->hi[s]; q++) {
            const bn__leaf_geom *pj = &R->leaf[q];
            double v[12], vc[3 * BN__FF_POLY_MAX], d[3], y[3], f;
            memcpy(v, pj->v, sizeof v);
            bn_v3_sub(x, v, d);
            if (bn_v3_dot(pj->n, d) <= R->tol)
                continue;   /* x behind the leaf */
            size_t nc = bn__poly_clip(v, pj->nc, nx, x, R->tol, vc);
            if (nc < 3 || !((f = bn__ff_point_polygon(x, nx, vc, nc)) > 0))
                continue;
            double w1 = bn__rng_uniform(&g), w2 = bn__rng_uniform(&g);
            bn__poly_sample(vc, nc, w1, w2, y);
            seen++;
            if (bn__blocked(R, x, nx, y, pj->n, w)) {
                blocked++;
                continue;
            }
            sum += f;
        }
    }
    *partial = blocked > 0 && blocked < seen;
    return sum / S;
}

/* One point pair of bn__F_sampled: x on leaf qx, y on leaf qy (u: their three numbers each), its
 * kernel (separated nodes: bounded by their distance; overlapping ones, below min_area: Wallace's
 * disk, which bounds each term but biases F low by ~a / (pi r^2)) added to *sum unless its shadow
 * ray is blocked, and r's cosine to *cos_sum. */
static void bn__pair_sample(const bn__ref *R, size_t qx, size_t qy, const double *u, int sep, double a, bn__worker *w,
                            double *sum, double *cos_sum, int *seen, int *blocked)
{
    double x[3], y[3], d[3], r2, len, cr, cs;
    const double *nx, *ny;
    bn__leaf_point(R, qx, u[1], u[2], x, &nx);
    bn__leaf_point(R, qy, u[4], u[5], y, &ny);
    bn_v3_sub(y, x, d);
    r2 = bn_v3_dot(d, d);
    len = sqrt(r2);
    if (!(len > 0))
        return;
    cr = bn_v3_dot(nx, d) / len;
    cs = -bn_v3_dot(ny, d) / len;
    if (cr > 0)
        *cos_sum += cr;
    if (!(cr > 0 && cs > 0))
        return;
    (*seen)++;
    if (bn__blocked(R, x, nx, y, ny, w)) {
        (*blocked)++;
        return;
    }
    *sum += cr * cs * a / (BN_PI * r2 + (sep ? 0 : a));
}

/* Area-averaged F from r to s (per unit cosine when r is a cluster) by S stratified point pairs with
 * one shadow ray each; S x 4 when the first S find partial visibility (unless split_if_partial: the
 * caller splits such a link, and wants only to know), and for nodes whose bounding spheres overlap
 * (then Wallace's disk regulariser keeps every term bounded). */
static double bn__F_sampled(const bn__ref *R, uint32_t r, uint32_t s, int split_if_partial, bn__worker *w, int *partial)
{
    int sep = bn__separated(R->t, r, s), S = (R->o->samples > 0 ? R->o->samples : 8) * (sep ? 1 : 4);
    double F;
    if (!sep && R->t->plane[r] >= 0 && R->t->plane[s] >= 0 && R->t->hi[s] - R->t->lo[s] <= BN__KERNEL_LEAVES)
        return bn__F_kernel(R, r, s, w, partial);
    for (int round = 0; round < 2; round++) {
        bn__rng g = bn__rng_make(R->o->ff.seed ^ 0x6869657261726368ull, ((uint64_t)r << 32) | s, (uint64_t)round);
        double a = R->t->area[s] / S, sum = 0, inv = 1.0 / S, cos_sum = 0;
        int seen = 0, blocked = 0;
        for (int k0 = 0; k0 < S; k0 += BN__FIND_MAX / 2) {
            int m = S - k0 < BN__FIND_MAX / 2 ? S - k0 : BN__FIND_MAX / 2;
            double u[6 * BN__FIND_MAX / 2], u1[BN__FIND_MAX];
            uint32_t v[BN__FIND_MAX];
            size_t q[BN__FIND_MAX];
            for (int i = 0; i < 6 * m; i++)   /* per sample in order: r's three, then s's three */
                u[i] = bn__rng_uniform(&g);
            for (int j = 0; j < m; j++) {
                int k = k0 + j;
                v[2 * j] = r;
                v[2 * j + 1] = s;
                u1[2 * j] = (k + u[6 * j]) * inv;
                u1[2 * j + 1] = (((k * 7 + 3) % S) + u[6 * j + 3]) * inv;
            }
            bn__find_leaves(R->t, 2 * m, v, u1, q);
            for (int j = 0; j < 2 * m; j++) {   /* a record spans up to three cache lines */
                const char *lp = (const char *)&R->leaf[q[j]];
                __builtin_prefetch(lp);
                __builtin_prefetch(lp + 64);
                __builtin_prefetch(lp + sizeof(bn__leaf_geom) - 1);
            }
            for (int j = 0; j < m; j++)
                bn__pair_sample(R, q[2 * j], q[2 * j + 1], u + 6 * j, sep, a, w, &sum, &cos_sum, &seen, &blocked);
        }
        *partial = blocked > 0 && blocked < seen;
        if (*partial && split_if_partial)
            return -1;   /* to be split: its F is not wanted */
        /* a cluster receiver: F per unit of cosine, K = F / (the receiver's mean cosine toward s, from
         * the same points), handed to each polygon as K max(0, n . u) (operator.c) */
        F = R->t->plane[r] < 0 ? (cos_sum > 0 ? sum / (cos_sum * inv) : 0) : sum;
        if (round == 1 || !*partial || bn__ff_vis_noise(F, S) <= bn__link_ftol(R, r, s))
            return F;   /* final, or its noise within BN__PARTIAL x eps in radiance */
        S *= 4;
    }
    return 0;
}

/* The link's F in [0, 1] (split_if_partial: -1 when it finds partial visibility, see bn__F_sampled). */
static float bn__link_F(const bn__ref *R, uint32_t r, uint32_t s, int split_if_partial, bn__worker *w, int *partial)
{
    const bn__tree *t = R->t;
    double F;
    *partial = 0;
    if (bn__tree_is_leaf(t, r) && bn__tree_is_leaf(t, s)) {
        uint32_t i = bn__tree_patch(t, r), j = bn__tree_patch(t, s);
        if (R->o->exact_leaf_links || R->force) {
            F = bn__ff_pair(R->pairs, w->ff, i, j, R->o->cull_leaf_rays) / R->patch[i].area;
        } else {
            double sigma;
            F = bn__ff_pair_quick(R->pairs, w->ff, i, j, BN__LEAF_RAYS, BN__LEAF_RTOL, bn__link_ftol(R, r, s), &sigma,
                                  partial);
            F = fmin(F, bn__F_dihedral(t, r, s));   /* an estimate, never above what the normals allow */
        }
    } else {
        F = bn__F_sampled(R, r, s, split_if_partial, w, partial);
        if (F < 0)
            return -1;
        if (t->plane[r] >= 0)   /* a polygon's node: F per unit area, never above what the normals allow */
            F = fmin(F, bn__F_dihedral(t, r, s));
    }
    return (float)fmin(fmax(F, 0.0), 1.0);
}

/* ---- links from a leaf into a cluster around it, by the leaf's own hemisphere rays ---- */

static int bn__u32_cmp(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

/* Is (r, s) a volume pair: a leaf receiver whose bounding sphere meets a cluster's (foliage, a leaf
 * among its neighbours)? Point pairs cannot bound F there, and splitting s to the patches makes a
 * link per neighbouring patch; the leaf's hemisphere rays give F into any such s at once. */
static int bn__vol_pair(const bn__ref *R, uint32_t r, uint32_t s)
{
    const bn__tree *t = R->t;
    return !R->force && R->o->volume_links && bn__tree_is_leaf(t, r) && t->plane[s] < 0 && !bn__separated(t, r, s);
}

/* Leaf r's hits: the leaf positions of the front faces that BN__VOL_RAYS cosine-distributed rays from
 * stratified points of r hit first (count, then sorted), cast once and kept in R->vol (the first
 * thread to finish publishes them; every thread casts the same rays, from r's own random stream, so
 * the links do not depend on which). Out of memory: w's scratch, not kept. */
static const uint32_t *bn__vol_hits(const bn__ref *R, uint32_t r, bn__worker *w)
{
    const bn__tree *t = R->t;
    const int side = 16;   /* side x side = BN__VOL_RAYS */
    size_t q = t->lo[r];
    uint32_t *h = __atomic_load_n(&R->vol[q], __ATOMIC_ACQUIRE), *c = w->vol, *expected = NULL;
    if (h)
        return h;
    bn__rng g = bn__rng_make(R->o->ff.seed ^ 0x766f6c756d65ULL, r, 0);
    double bs[3], bt[3];
    const double *n = R->leaf[q].n;
    bn_v3_basis(n, bs, bt);
    c[0] = 0;
    for (int k = 0; k < side * side; k++) {
        double x[3], o[3], d[3], u1 = bn__rng_uniform(&g), u2 = bn__rng_uniform(&g);
        double a = ((k / side) + bn__rng_uniform(&g)) / side, b = ((k % side) + bn__rng_uniform(&g)) / side;
        const double *nx;
        bn_hit hit;
        bn__leaf_point(R, q, u1, u2, x, &nx);
        bn_v3_cosine_dir(n, bs, bt, a, b, d);
        bn_v3_madd(x, R->ray_eps, n, o);
        if (bn_rt_intersect(R->rt, o, d, 0, INFINITY, &hit) && hit.front)
            c[1 + c[0]++] = t->lo[t->leaf[hit.patch]];
    }
    w->rays += (size_t)(side * side);
    qsort(c + 1, c[0], sizeof *c, bn__u32_cmp);
    if (!(h = bn__malloc_array((size_t)c[0] + 1, sizeof *h)))
        return c;
    memcpy(h, c, ((size_t)c[0] + 1) * sizeof *h);
    if (!__atomic_compare_exchange_n(&R->vol[q], &expected, h, 0, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE)) {
        free(h);
        return expected;
    }
    __atomic_add_fetch(R->vol_bytes, ((size_t)c[0] + 1) * sizeof *h, __ATOMIC_RELAXED);
    return h;
}

/* F from leaf r (its hits h) into s: its rays' share that hit a face below s; *sigma its standard error
 * (binomial, at least that of one hit). */
static uint32_t bn__first_at_or_after(const uint32_t *pos, uint32_t n, uint32_t key)
{
    uint32_t a = 0, b = n;
    while (a < b) {
        uint32_t mid = a + (b - a) / 2;
        if (pos[mid] < key)
            a = mid + 1;
        else
            b = mid;
    }
    return a;
}

static double bn__vol_F(const bn__ref *R, const uint32_t *h, uint32_t s, double *sigma)
{
    uint32_t m = bn__first_at_or_after(h + 1, h[0], R->t->hi[s]) - bn__first_at_or_after(h + 1, h[0], R->t->lo[s]);
    double F = (double)m / BN__VOL_RAYS;
    *sigma = sqrt(fmax(F * (1 - F), 1.0 / BN__VOL_RAYS) / BN__VOL_RAYS);
    return F;
}

/* What the volume link r <- s may get wrong in r's radiance: the spread of the radiance below s
 * (the link hands r their area mean) over F, and twice F's standard error times the brightest. */
static double bn__vol_error(const bn__ref *R, uint32_t r, uint32_t s, double F, double sigma)
{
    const float *rho = R->t->rho_max + 3 * (size_t)r;
    const double *hi = R->Bmax + 3 * (size_t)s, *lo = R->Bmin + 3 * (size_t)s;
    double e = 0;
    for (int c = 0; c < 3; c++)
        e = fmax(e, (double)rho[c] * (F * (hi[c] - lo[c]) + 2 * sigma * hi[c]));
    return e;
}

static void bn__visit(const bn__ref *R, uint32_t r, uint32_t s, float F, int partial, int depth, bn__worker *w);

/* A cluster's self-link: its children's four pairs (a plane does not see itself). */
static void bn__visit_self(const bn__ref *R, uint32_t r, int depth, bn__worker *w)
{
    const bn__tree *t = R->t;
    if (bn__tree_is_leaf(t, r) || t->plane[r] >= 0)
        return;
    if (depth == 0) {
        bn__vec_push(&w->pending, r, r, -1, 0);
        return;
    }
    for (uint32_t a = t->child[r]; a < t->child[r] + 2; a++)
        for (uint32_t b = t->child[r]; b < t->child[r] + 2; b++)
            bn__visit(R, a, b, -1, 0, depth - 1, w);
}

/* A volume pair (bn__vol_pair): one link when its error is within eps, else s split. */
static void bn__visit_vol(const bn__ref *R, uint32_t r, uint32_t s, int depth, bn__worker *w)
{
    const bn__tree *t = R->t;
    double sigma, F, eps = bn__eps_at(R, r);
    int ss = bn__splittable(R, s);
    /* the least error any F could have (F = 0, one hit's standard error): above eps, no rays */
    if (ss && bn__vol_error(R, r, s, 0, 1.0 / BN__VOL_RAYS) > eps)
        F = -1;
    else
        F = bn__vol_F(R, bn__vol_hits(R, r, w), s, &sigma);
    if (F >= 0 && (bn__vol_error(R, r, s, F, sigma) <= eps || !ss)) {
        bn__vec_push(&w->links, r, s, (float)F, 0);
        return;
    }
    /* the same depth for the parts: a receiver's descent into the clusters around it is one round's
     * work (no rays after its first; bounded by the tree's depth) */
    bn__visit(R, r, t->child[s], -1, 0, depth, w);
    bn__visit(R, r, t->child[s] + 1, -1, 0, depth, w);
}

/* Refines the pair (r, s) (F: its coefficient when it is an existing link, else < 0; partial: its
 * rays found partial visibility) up to `depth` more levels: accepted links go to w->links, deeper
 * work to w->pending. Partly visible links are held to BN__PARTIAL x eps: a shadow's edge crosses
 * them, and only smaller receivers resolve it. */
static void bn__visit(const bn__ref *R, uint32_t r, uint32_t s, float F, int partial, int depth, bn__worker *w)
{
    const bn__tree *t = R->t;
    int lr = bn__tree_is_leaf(t, r), sr = bn__splittable(R, r), ss = bn__splittable(R, s), split;
    if (!bn__receiver_here(R, r))
        return;   /* another rank's receiver */
    if (r == s) {
        bn__visit_self(R, r, depth, w);
        return;
    }
    if (F < 0 && bn__culled(R, r, s))
        return;
    if (bn__vol_pair(R, r, s)) {
        bn__visit_vol(R, r, s, depth, w);
        return;
    }
    split = 0;
    if (sr || ss) {
        double e = R->force || !bn__can_receive(R, r, s) ? INFINITY : bn__link_error_near(R, r, s);
        double eps = bn__eps_at(R, r);
        split = e > (F >= 0 && partial ? BN__PARTIAL : 1.0) * eps;
        if (!split && F < 0) {   /* accepted as it stands: its F, and a second look if partly visible */
            int split_if_partial = e > BN__PARTIAL * eps;
            F = bn__link_F(R, r, s, split_if_partial, w, &partial);
            split = partial && split_if_partial;
            if (split)
                F = -1;   /* partly visible (found by its first rays) and too bright for that: split */
        }
    }
    if (split) {
        double cr[3], cs[3], rr, rs;
        if (depth == 0) {
            bn__vec_push(&w->pending, r, s, -1, 0);
            return;
        }
        if (F >= 0)
            w->splits += (size_t)bn__receiver_counted(R, r);
        bn__tree_sphere(t, r, cr, &rr);
        bn__tree_sphere(t, s, cs, &rs);
        if (sr && (!ss || rr >= rs || !bn__can_receive(R, r, s))) {
            bn__visit(R, t->child[r], s, -1, 0, depth - 1, w);
            bn__visit(R, t->child[r] + 1, s, -1, 0, depth - 1, w);
        } else {
            bn__visit(R, r, t->child[s], -1, 0, depth - 1, w);
            bn__visit(R, r, t->child[s] + 1, -1, 0, depth - 1, w);
        }
        return;
    }
    if (F < 0 || (partial && lr && bn__tree_is_leaf(t, s) && bn__second_look(R, r, s, F)))
        F = bn__link_F(R, r, s, 0, w, &partial);
    if (!(F > 0) && lr && bn__tree_is_leaf(t, s))
        return;   /* two patches that do not see each other: no link (nothing below them to refine later) */
    bn__vec_push(&w->links, r, s, F, partial);
}

/* Appends src's links to dst and frees src: a million links at a time from src's end, src shrunk
 * after each, so the two never hold the same links twice over (large blocks move by mremap). The
 * order is not kept: the pass sorts its output. 0 when out of memory (src then keeps the rest). */
#define BN__MOVE_CHUNK ((size_t)1 << 20)
static int bn__vec_move(bn__vec *dst, bn__vec *src)
{
    while (src->n) {
        size_t m = src->n < BN__MOVE_CHUNK ? src->n : BN__MOVE_CHUNK;
        if (dst->n + m > dst->cap) {   /* exactly: a few dozen reallocs, each an mremap */
            size_t cap = dst->n + m;
            bn__link *a = bn__realloc_array(dst->a, cap, sizeof *a);
            if (!a)
                return 0;
            dst->a = a;
            dst->cap = cap;
        }
        memcpy(dst->a + dst->n, src->a + src->n - m, m * sizeof *src->a);
        dst->n += m;
        src->n -= m;
        if (src->n) {
            bn__link *a = bn__realloc_array(src->a, src->n, sizeof *a);
            src->a = a ? a : src->a;
            src->cap = a ? src->n : src->cap;
        }
    }
    free(src->a);
    src->a = NULL;
    src->cap = 0;
    return 1;
}

/* Link bytes held now: the pass's input, its output so far and every worker's, as allocated. */
static size_t bn__held(const bn__vec *work, const bn__vec *out, const bn__worker *W, int nt)
{
    size_t b = (work->cap + out->cap) * sizeof(bn__link);
    for (int k = 0; k < nt; k++)
        b += (W[k].links.cap + W[k].pending.cap) * sizeof(bn__link);
    return b;
}

/* After a round: the workers' accepted links appended to out, their deeper work to *work (whose items
 * are refined), their splits counted; the peak of link bytes noted first. 0 when out of memory. */
static int bn__round_collect(bn__worker *W, int nt, bn__vec *work, bn__vec *out, size_t extra, bn__pass_stats *st)
{
    size_t held = bn__held(work, out, W, nt) + extra;
    st->peak_bytes = held > st->peak_bytes ? held : st->peak_bytes;
    work->n = 0;
    for (int k = 0; k < nt; k++) {
        if (!bn__vec_move(out, &W[k].links) || !bn__vec_move(work, &W[k].pending))
            return 0;
        st->splits += W[k].splits;
        W[k].splits = 0;
    }
    if (work->n < work->cap / 2) {   /* keep only what the next round needs */
        bn__link *a = bn__realloc_array(work->a, work->n ? work->n : 1, sizeof *a);
        if (a) {
            work->a = a;
            work->cap = work->n ? work->n : 1;
        }
    }
    return 1;
}

/* One pass: every item of *work refined (rounds of BN__DEPTH_PER_ROUND levels); the accepted
 * links replace *work, sorted. *splits: existing links that were split. */
bn_status bn__pass(const bn__ref *R, bn__worker *W, int nt, bn__vec *work, bn__pass_stats *st, const char *label,
                   bn_error *err)
{
    bn__vec out = {0};
    bn__progress prog;
    size_t done = 0, round = 0;
    char lbl[64];
    st->splits = 0;
    while (work->n) {
        volatile int oom = 0;
        long ln = (long)work->n;
        done = 0;
        /* every round its own bar (or, in a log, a line now and then): a round of a few links
         * between large clusters can take minutes */
        snprintf(lbl, sizeof lbl, "%s, round %zu", label, round + 1);
        bn__progress_begin(&prog, lbl, work->n, R->o->quiet);
#pragma omp parallel num_threads(nt)
        {
            bn__worker *w = &W[omp_get_thread_num()];
            size_t mine = 0;   /* items since this thread's last progress step (one atomic per 4096) */
#pragma omp for schedule(dynamic, 64)
            for (long l = 0; l < ln; l++) {
                if (oom || bn_interrupted() != BN_OK)
                    continue;
                bn__link it = work->a[l];
                bn__visit(R, it.r, bn__link_s(&it), it.F, bn__link_partial(&it), BN__DEPTH_PER_ROUND, w);
                if (w->links.oom || w->pending.oom)
                    oom = 1;
                if (++mine == 4096) {
                    bn__progress_step(&prog, &done, mine);
                    mine = 0;
                }
            }
            bn__progress_step(&prog, &done, mine);
        }
        bn__progress_end(&prog);
        if (bn_interrupted() != BN_OK) {
            free(out.a);
            return bn_error_set(err, bn_interrupted(), "hierarchy refinement interrupted");
        }
        if (!oom)
            oom = !bn__round_collect(W, nt, work, &out, __atomic_load_n(R->vol_bytes, __ATOMIC_RELAXED), st);
        if (oom) {
            free(out.a);
            return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy's links (%zu so far): raise eps",
                                out.n);
        }
        round++;
    }
    for (int k = 0; k < nt; k++) {   /* the form-factor worker counts from its creation */
        size_t ff = bn__ff_worker_rays(W[k].ff);
        st->rays += W[k].rays + ff - W[k].ff_rays;
        W[k].rays = 0;
        W[k].ff_rays = ff;
    }
    bn__links_sort(out.a, out.n);
    free(work->a);
    *work = out;
    return BN_OK;
}

/* Bmax and Bmin from per-patch radiances L (N*3): the largest and smallest below each node. */
void bn__bmax(const bn__tree *t, const double *L, double *Bmax, double *Bmin)
{
    for (size_t v = t->n; v-- > 0;) {
        uint32_t c = t->child[v];
        if (c == BN__NONE) {
            memcpy(Bmax + 3 * v, L + 3 * (size_t)bn__tree_patch(t, (uint32_t)v), 3 * sizeof(double));
            memcpy(Bmin + 3 * v, Bmax + 3 * v, 3 * sizeof(double));
        } else
            for (int k = 0; k < 3; k++) {
                Bmax[3 * v + k] = fmax(Bmax[3 * (size_t)c + k], Bmax[3 * ((size_t)c + 1) + k]);
                Bmin[3 * v + k] = fmin(Bmin[3 * (size_t)c + k], Bmin[3 * ((size_t)c + 1) + k]);
            }
    }
}

double bn__typical_radiance(const bn__tree *t, const double *L, const double *E)
{
    double sum = 0, area = 0;
    for (size_t i = 0; i < t->npatch; i++) {
        double m = 0;
        for (int k = 0; k < 3; k++)
            m = fmax(m, L[3 * i + k] - E[3 * i + k]);
        sum += t->area[t->leaf[i]] * m;
        area += t->area[t->leaf[i]];
    }
    return area > 0 ? sum / area : 0;
}

/* Links with F > 0, in place. */
size_t bn__compact(bn__vec *v)
{
    size_t m = 0;
    for (size_t l = 0; l < v->n; l++)
        if (v->a[l].F > 0)
            v->a[m++] = v->a[l];
    return m;
}

/* L ~ E + K_H L by a few Jacobi sweeps over the current links: the brightness the next pass's
 * oracle weighs links by. L comes in as the previous pass's estimate (E before the first): the links
 * change little after the second pass, so a few sweeps settle it again. */
bn_status bn__estimate(const bn__tree *t, bn__vec *links, const size_t *bound, const double *E,
                              const double *rho, double eps_abs, double *L, bn_error *err)
{
    bn__hop *h = NULL;
    size_t n3 = 3 * t->npatch;
    double *y = bn__malloc_array(n3, sizeof(double));
    bn_status st = BN_OK;
    if (!y)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy's gather");
    bn__hop_shape shape = bn__tree_shape(t);
    st = bn__hop_make(&shape, links->a, links->n, bound, &h, err);   /* those with F > 0 */
    for (int it = 0; st == BN_OK && it < 200; it++) {
        double change = 0;
        st = bn__hop_apply(h, L, y, err);
        for (size_t k = 0; st == BN_OK && k < n3; k++) {
            double v = E[k] + rho[k] * y[k];
            change = fmax(change, fabs(v - L[k]));
            L[k] = v;
        }
        if (change < 0.1 * eps_abs)
            break;
    }
    bn__hop_destroy(h);
    free(y);
    return st;
}
