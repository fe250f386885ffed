/* Links by a brightness-weighted error oracle, refined and gathered until they settle, then
 * frozen into the operator (include/bounce/hierarchy.h). */
#include "transport/hierarchy/hierarchy_internal.h"
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
/* Shadow rays of a leaf link (x4 when partly visible). */
#define BN__LEAF_RAYS 16
/* The link set has settled when a pass splits fewer than this fraction of its links: the next
 * pass would weigh them by a brightness that the few new links hardly change (on the bunny box,
 * pass 4 splits 2,557 of 18.9 M, pass 5 17, pass 6 none, at 6 s a pass). */
#define BN__SETTLED 1e-3
/* Partly visible links are split down to this fraction of eps. */
#define BN__PARTIAL 0.125

void bn_hierarchy_opts_default(bn_hierarchy_opts *o)
{
    memset(o, 0, sizeof *o);
    o->eps = BN_HIERARCHY_EPS_DEFAULT;
    o->clusters = 1;
    o->samples = 8;
    o->max_passes = 12;
    o->flat_clusters = 1;
    bn_formfactor_opts_default(&o->ff);
}

/* ---- what refinement reads ---- */

typedef struct bn__ref {
    const bn__tree *t;
    const bn_scene *scene;
    const bn_rt *rt;
    const bn_hierarchy_opts *o;
    const bn_patch *patch;
    const double *pverts;
    double *fan0;             /* per patch: the share of a quad's area in its first fan triangle (0, 1, 2) */
    double *Bmax;             /* 3 per node: the largest radiance estimate below (oracle) */
    double eps_abs;
    double min_area;          /* planar nodes below this area are not split */
    int force;                /* eps == 0: refine every link to the patches */
    double tol, ray_eps;
    bn__ff_pairs *pairs;
    size_t plo, phi;          /* this rank's leaves (all of them with one process): bound[rank .. rank + 1] */
    size_t *bound;            /* P + 1: every rank's first leaf, then npatch */
} bn__ref;

/* The first split, before any link is known: an equal share of the leaves, in rank order (rank k's). */
static void bn__dist_leaves_of(size_t npatch, size_t k, size_t *lo, size_t *hi)
{
    size_t P = (size_t)bn_dist_size();
    *lo = npatch * k / P;
    *hi = npatch * (k + 1) / P;
}

/* Under mpirun a rank refines only receivers whose leaves meet its own (the others' links are theirs):
 * each receiver's links are then exactly one process's. A receiver is counted (links, splits, rays) by
 * the rank that holds its first leaf, so the counts summed over ranks are one process's. */
static int bn__receiver_here(const bn__ref *R, uint32_t r)
{
    return R->t->lo[r] < R->phi && R->t->hi[r] > R->plo;
}
static int bn__receiver_counted(const bn__ref *R, uint32_t r)
{
    return R->t->lo[r] >= R->plo && R->t->lo[r] < R->phi;
}

typedef struct bn__vec {
    bn__link *a;
    size_t n, cap;
    int oom;
} bn__vec;

static void bn__vec_push(bn__vec *v, uint32_t r, uint32_t s, float F, int partial)
{
    if (v->n == v->cap) {
        size_t cap = v->cap ? 2 * v->cap : 256;
        bn__link *a = bn__realloc_array(v->a, cap, sizeof *a);
        if (!a) {
            v->oom = 1;
            return;
        }
        v->a = a;
        v->cap = cap;
    }
    v->a[v->n].r = r;
    v->a[v->n].s = s;
    v->a[v->n].partial = (uint8_t)partial;
    v->a[v->n++].F = F;
}

typedef struct bn__worker {
    bn__vec links, pending;
    bn__ff_worker *ff;
    size_t rays, splits;
} bn__worker;

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

/* The oracle: the most a link could carry to the receiver's radiance, rho_r B_s F_bound. */
static double bn__link_error(const bn__ref *R, uint32_t r, uint32_t s)
{
    const float *rho = R->t->rho_max + 3 * (size_t)r;
    const double *B = R->Bmax + 3 * (size_t)s;
    double m = 0;
    for (int c = 0; c < 3; c++)
        m = fmax(m, (double)rho[c] * B[c]);
    return m > 0 ? m * bn__F_bound(R->t, r, s) : 0;
}

/* A point of node v, uniform in area, from (u1, u2, u3) in [0,1)^3; its patch's normal. */
static void bn__node_point(const bn__ref *R, uint32_t v, double u1, double u2, double u3, double x[3], const double **n)
{
    const bn__tree *t = R->t;
    size_t lo = t->lo[v], hi = t->hi[v];
    double a = t->cum_area[lo] + u1 * (t->cum_area[hi] - t->cum_area[lo]);
    while (hi - lo > 1) {   /* the last k with cum_area[k] <= a */
        size_t mid = lo + (hi - lo) / 2;
        if (t->cum_area[mid] <= a)
            lo = mid;
        else
            hi = mid;
    }
    size_t i = t->order[lo];
    const bn_patch *p = &R->patch[i];
    const double *pa = R->pverts + 3 * p->corner[0], *pb = R->pverts + 3 * p->corner[1];
    const double *pc = R->pverts + 3 * p->corner[2];
    double f = R->fan0[i], s, b0, b1, b2;
    if (p->ncorners == 4) {   /* the fan triangle by area, as bn__poly_sample chooses it, its share precomputed */
        if (u2 < f)
            u2 = f > 0 ? u2 / f : 0.5;
        else {
            pb = pc;
            pc = R->pverts + 3 * p->corner[3];
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
    *n = p->normal;
}

/* Area-averaged F from r to s (per unit cosine when r is a cluster) by S stratified point pairs with
 * one shadow ray each; S x 4 when the first S find partial visibility, and for nodes whose bounding
 * spheres overlap (then Wallace's disk regulariser keeps every term bounded). */
static double bn__F_sampled(const bn__ref *R, uint32_t r, uint32_t s, bn__worker *w, int *partial)
{
    int sep = bn__separated(R->t, r, s), S = (R->o->samples > 0 ? R->o->samples : 8) * (sep ? 1 : 4);
    for (int round = 0; round < 2; round++) {
        bn__rng g = bn__rng_make(R->o->ff.seed ^ 0x6869657261726368ull, ((uint64_t)r << 32) | s, (uint64_t)round);
        double a = R->t->area[s] / S, sum = 0, inv = 1.0 / S, cos_sum = 0;
        int seen = 0, blocked = 0;
        for (int k = 0; k < S; k++) {
            double x[3], y[3], d[3], o[3], e[3], r2, len, cr, cs;
            const double *nx, *ny;
            bn__node_point(R, r, (k + bn__rng_uniform(&g)) * inv, bn__rng_uniform(&g), bn__rng_uniform(&g), x, &nx);
            bn__node_point(R, s, (((k * 7 + 3) % S) + bn__rng_uniform(&g)) * inv, bn__rng_uniform(&g),
                           bn__rng_uniform(&g), y, &ny);
            bn_v3_sub(y, x, d);
            r2 = bn_v3_dot(d, d);
            len = sqrt(r2);
            if (!(len > 0))
                continue;
            cr = bn_v3_dot(nx, d) / len;
            cs = -bn_v3_dot(ny, d) / len;
            if (cr > 0)
                cos_sum += cr;
            if (!(cr > 0 && cs > 0))
                continue;
            bn_v3_madd(x, R->ray_eps, nx, o);
            bn_v3_madd(y, R->ray_eps, ny, e);
            bn_v3_sub(e, o, d);
            len = bn_v3_len(d);
            seen++;
            w->rays++;
            if (len > 4 * R->ray_eps && bn_rt_occluded(R->rt, o, d, 0, 1.0 - R->ray_eps / len)) {
                blocked++;
                continue;
            }
            /* separated nodes: the kernel itself (bounded by their distance); overlapping ones (below
             * min_area): Wallace's disk, which bounds each term but biases F low by ~a / (pi r^2) */
            sum += cr * cs * a / (BN_PI * r2 + (sep ? 0 : a));
        }
        *partial = blocked > 0 && blocked < seen;
        if (round == 1 || !*partial)
            /* a cluster receiver: F per unit of cosine, K = F / (the receiver's mean cosine toward s,
             * from the same points), handed to each polygon as K max(0, n . u) (operator.c) */
            return R->t->plane[r] < 0 ? (cos_sum > 0 ? sum / (cos_sum * inv) : 0) : sum;
        S *= 4;
    }
    return 0;
}

static float bn__link_F(const bn__ref *R, uint32_t r, uint32_t s, bn__worker *w, int *partial)
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
            F = bn__ff_pair_quick(R->pairs, w->ff, i, j, BN__LEAF_RAYS, BN__LEAF_RTOL, &sigma);
        }
    } else {
        F = bn__F_sampled(R, r, s, w, partial);
    }
    return (float)fmin(fmax(F, 0.0), 1.0);
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
        if (lr || t->plane[r] >= 0)
            return;   /* a plane does not see itself */
        if (depth == 0) {
            bn__vec_push(&w->pending, r, s, -1, 0);
            return;
        }
        for (uint32_t a = t->child[r]; a < t->child[r] + 2; a++)
            for (uint32_t b = t->child[r]; b < t->child[r] + 2; b++)
                bn__visit(R, a, b, -1, 0, depth - 1, w);
        return;
    }
    if (F < 0 && bn__culled(R, r, s))
        return;
    split = 0;
    if (sr || ss) {
        double e = R->force || !bn__separated(t, r, s) || !bn__can_receive(R, r, s) ? INFINITY
                                                                                    : bn__link_error(R, r, s);
        split = e > (F >= 0 && partial ? BN__PARTIAL : 1.0) * R->eps_abs;
        if (!split && F < 0) {   /* accepted as it stands: its F, and a second look if partly visible */
            F = bn__link_F(R, r, s, w, &partial);
            split = partial && e > BN__PARTIAL * R->eps_abs;
            if (split)
                F = -1;   /* computed, but split: not an existing link */
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
    if (F < 0)
        F = bn__link_F(R, r, s, w, &partial);
    bn__vec_push(&w->links, r, s, F, partial);
}

static int bn__link_cmp(const void *a, const void *b)
{
    const bn__link *x = a, *y = b;
    if (x->r != y->r)
        return x->r < y->r ? -1 : 1;
    return x->s < y->s ? -1 : x->s > y->s;
}

/* One pass: every item of *work refined (rounds of BN__DEPTH_PER_ROUND levels); the accepted
 * links replace *work, sorted. *splits: existing links that were split. */
static bn_status bn__pass(const bn__ref *R, bn__worker *W, int nt, bn__vec *work, size_t *splits, size_t *rays,
                          const char *label, bn_error *err)
{
    bn__vec out = {0};
    bn__progress prog;
    size_t done = 0, round = 0;
    *splits = 0;
    while (work->n) {
        volatile int oom = 0;
        long ln = (long)work->n;
        done = 0;
        bn__progress_begin(&prog, label, work->n, R->o->quiet || round > 0);
#pragma omp parallel num_threads(nt)
        {
            bn__worker *w = &W[omp_get_thread_num()];
            size_t mine = 0;   /* items since this thread's last progress step (one atomic per 4096) */
#pragma omp for schedule(dynamic, 64)
            for (long l = 0; l < ln; l++) {
                if (oom || bn_interrupted() != BN_OK)
                    continue;
                bn__link it = work->a[l];
                bn__visit(R, it.r, it.s, it.F, it.partial, BN__DEPTH_PER_ROUND, w);
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
        work->n = 0;
        for (int k = 0; k < nt && !oom; k++) {
            bn__vec *v[2] = {&W[k].links, &W[k].pending};
            bn__vec *dst[2] = {&out, work};
            for (int q = 0; q < 2; q++) {
                if (dst[q]->n + v[q]->n > dst[q]->cap) {
                    size_t cap = (dst[q]->n + v[q]->n) * 3 / 2 + 256;
                    bn__link *a = bn__realloc_array(dst[q]->a, cap, sizeof *a);
                    if (!a) {
                        oom = 1;
                        break;
                    }
                    dst[q]->a = a;
                    dst[q]->cap = cap;
                }
                if (v[q]->n)
                    memcpy(dst[q]->a + dst[q]->n, v[q]->a, v[q]->n * sizeof *v[q]->a);
                dst[q]->n += v[q]->n;
                v[q]->n = 0;
            }
            *splits += W[k].splits;
            W[k].splits = 0;
        }
        if (oom) {
            free(out.a);
            return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy's links (%zu so far): raise --eps",
                                out.n);
        }
        round++;
    }
    for (int k = 0; k < nt; k++) {
        *rays += W[k].rays + bn__ff_worker_rays(W[k].ff);
        W[k].rays = 0;
    }
    qsort(out.a, out.n, sizeof *out.a, bn__link_cmp);
    free(work->a);
    *work = out;
    return BN_OK;
}

/* Bmax from per-patch radiances L (N*3): the largest below each node. */
static void bn__bmax(const bn__tree *t, const double *L, double *Bmax)
{
    for (size_t v = t->n; v-- > 0;) {
        uint32_t c = t->child[v];
        if (c == BN__NONE)
            memcpy(Bmax + 3 * v, L + 3 * (size_t)bn__tree_patch(t, (uint32_t)v), 3 * sizeof(double));
        else
            for (int k = 0; k < 3; k++)
                Bmax[3 * v + k] = fmax(Bmax[3 * (size_t)c + k], Bmax[3 * ((size_t)c + 1) + k]);
    }
}

/* Links with F > 0, in place. */
static size_t bn__compact(bn__vec *v)
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
static bn_status bn__estimate(const bn__tree *t, bn__vec *links, const size_t *bound, const double *E,
                              const double *rho, double eps_abs, double *L, bn_error *err)
{
    bn__vec live = *links;
    bn__hop *h = NULL;
    size_t n3 = 3 * t->npatch;
    bn__link *copy = bn__malloc_array(links->n ? links->n : 1, sizeof *copy);
    double *y = bn__malloc_array(n3, sizeof(double));
    bn_status st = BN_OK;
    if (!copy || !y) {
        free(copy);
        free(y);
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy's gather");
    }
    if (links->n)
        memcpy(copy, links->a, links->n * sizeof *copy);
    live.a = copy;
    live.n = bn__compact(&live);
    st = bn__hop_make(t, live.a, live.n, bound, &h, err);
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
    free(copy);
    free(y);
    return st;
}

/* A rank's share is rebalanced when its most loaded rank holds more than this times the mean. */
#define BN__IMBALANCE 1.05
/* A link's cost spread over its receiver's leaves, in fixed point (integer sums: every rank gets the
 * same figures, so the same ranges). */
#define BN__COST_ONE ((unsigned long long)1 << 24)

/* Under mpirun, after a pass: the leaves are split again so that every rank's receivers hold about the
 * same number of links (each link's cost spread evenly over its receiver's leaves, counted once over
 * ranks and summed), and the links move to the ranks whose new leaves their receivers meet (one
 * all-to-all; each link is sent by the rank that counted it, so no link arrives twice). The links of a
 * receiver do not depend on which rank refines them, so the answer stays one process's. *moved: links
 * this rank received from others. */
static bn_status bn__rebalance(bn__ref *R, bn__vec *work, double *imbalance, size_t *moved, bn_error *err)
{
    const bn__tree *t = R->t;
    size_t np = t->npatch, P = (size_t)bn_dist_size(), me = (size_t)bn_dist_rank(), nrecv = 0;
    unsigned long long *c = NULL, total = 0, most = 0;
    size_t *bound = NULL, *cnt = NULL, *at = NULL;
    bn__link *send = NULL;
    void *recv = NULL;
    bn_status st = BN_OK;
    *imbalance = 1;
    *moved = 0;
    if (P == 1)
        return BN_OK;
    c = bn__calloc(np + 1, sizeof *c);
    bound = bn__calloc(P + 1, sizeof *bound);
    cnt = bn__calloc(2 * P, sizeof *cnt);
    if (!c || !bound || !cnt) {
        st = bn_error_set(err, BN_ENOMEM, "out of memory to balance %zu leaves among %zu processes", np, P);
        goto done;
    }
    at = cnt + P;
    for (size_t l = 0; l < work->n; l++) {   /* a difference array of per-leaf cost */
        uint32_t r = work->a[l].r;
        if (bn__receiver_counted(R, r)) {
            unsigned long long w = BN__COST_ONE / (t->hi[r] - t->lo[r]);
            c[t->lo[r]] += w;
            c[t->hi[r]] -= w;   /* modular arithmetic: the prefix sums come out right */
        }
    }
    if ((st = bn_dist_sum_u64(c, np + 1, err)) != BN_OK)
        goto done;
    for (size_t i = 1; i <= np; i++)
        c[i] += c[i - 1];
    for (size_t i = 0; i < np; i++)
        total += c[i];
    if (total == 0)
        goto done;
    for (size_t q = 0; q < P; q++) {   /* the present split's load */
        unsigned long long load = 0;
        for (size_t i = R->bound[q]; i < R->bound[q + 1]; i++)
            load += c[i];
        most = load > most ? load : most;
    }
    *imbalance = (double)most * (double)P / (double)total;
    if (*imbalance <= BN__IMBALANCE)
        goto done;
    {   /* rank q's leaves begin where the running cost first reaches q/P of the total */
        unsigned long long run = 0;
        size_t q = 1;
        for (size_t i = 0; i < np && q < P; i++) {
            while (q < P && (long double)run * P >= (long double)total * q)
                bound[q++] = i;
            run += c[i];
        }
        while (q < P)
            bound[q++] = np;
        bound[P] = np;
    }
    /* each link this rank counted goes to every rank whose new leaves its receiver meets */
    for (int pass = 0; pass < 2; pass++) {
        size_t off = 0;
        for (size_t q = 0; q < P; q++) {
            at[q] = off;
            off += cnt[q];
        }
        if (pass == 1 && !(send = bn__malloc_array(off ? off : 1, sizeof *send))) {
            st = bn_error_set(err, BN_ENOMEM, "out of memory for %zu links to move among processes", off);
            goto done;
        }
        for (size_t l = 0; l < work->n; l++) {
            uint32_t r = work->a[l].r;
            if (!bn__receiver_counted(R, r))
                continue;
            for (size_t q = 0; q < P; q++)
                if (t->lo[r] < bound[q + 1] && t->hi[r] > bound[q]) {
                    if (pass == 0)
                        cnt[q]++;
                    else
                        send[at[q]++] = work->a[l];
                }
        }
    }
    free(work->a);
    work->a = NULL;
    work->n = work->cap = 0;
    if ((st = bn_dist_exchange(send, cnt, sizeof *send, &recv, &nrecv, err)) != BN_OK)
        goto done;
    *moved = nrecv - cnt[me];
    work->a = recv;
    work->n = work->cap = nrecv;
    qsort(work->a, work->n, sizeof *work->a, bn__link_cmp);
    memcpy(R->bound, bound, (P + 1) * sizeof *bound);
    R->plo = bound[me];
    R->phi = bound[me + 1];
done:
    free(send);
    free(c);
    free(bound);
    free(cnt);
    return st;
}

static bn_status bn__check_opts(const bn_hierarchy_opts *o, bn_error *err)
{
    if (!(o->eps >= 0 && isfinite(o->eps)))
        return bn_error_set(err, BN_EINPUT, "hierarchy: eps %g is not a finite number >= 0", o->eps);
    if (o->samples < 0 || o->samples > (1 << 20))
        return bn_error_set(err, BN_EINPUT, "hierarchy: %d samples per link is outside [1, 2^20]", o->samples);
    if (isnan(o->min_area) || isinf(o->min_area))
        return bn_error_set(err, BN_EINPUT, "hierarchy: min area %g is not a finite number", o->min_area);
    if (o->max_passes < 1)
        return bn_error_set(err, BN_EINPUT, "hierarchy: %d passes (at least 1)", o->max_passes);
    return BN_OK;
}

static bn_status bn__hierarchy_body(const bn_scene *scene, const bn_rt *rt, const bn_hierarchy_opts *o,
                                    bn_transport **out, bn_hierarchy_report *rep, bn_error *err)
{
    bn__tree t;
    bn__ref R;
    bn__vec work = {0};
    bn__worker *W = NULL;
    bn__hop *h = NULL;
    double *E = NULL, *rho = NULL, *L = NULL, lo[3], hi[3], emax = 0, t0 = bn__now();
    size_t np, limit = o->max_memory ? o->max_memory : bn_memory_limit_default();
    int nt = omp_get_max_threads();
    bn_status st;

    *out = NULL;
    memset(rep, 0, sizeof *rep);
    memset(&R, 0, sizeof R);
    if ((st = bn__check_opts(o, err)) != BN_OK)
        return st;
    if (!rt || bn_rt_scene(rt) != scene)
        return bn_error_set(err, BN_EINTERNAL, "bn_hierarchy_build: rt was built for another scene");
    st = bn__tree_build(scene, !(o->eps == 0 || o->exact_leaf_links), &t, err);
    if (st != BN_OK)
        return st;
    rep->seconds_tree = bn__now() - t0;
    t0 = bn__now();
    bn_scene_patches(scene, &np);
    R.t = &t;
    R.scene = scene;
    R.rt = rt;
    R.o = o;
    R.patch = bn_scene_patches(scene, &np);
    {
        size_t npv;
        R.pverts = bn_scene_patch_vertices(scene, &npv);
    }
    if (!(R.fan0 = bn__malloc_array(np + 1, sizeof(double)))) {
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy of %zu patches", np);
        goto done;
    }
    for (size_t i = 0; i < np; i++) {
        const bn_patch *p = &R.patch[i];
        const double *v0 = R.pverts + 3 * p->corner[0], *v2 = R.pverts + 3 * p->corner[2];
        double a0 = 0, a1 = 0;
        if (p->ncorners == 4) {
            double e1[3], e2[3], e3[3], c[3];
            bn_v3_sub(R.pverts + 3 * p->corner[1], v0, e1);
            bn_v3_sub(v2, v0, e2);
            bn_v3_sub(R.pverts + 3 * p->corner[3], v0, e3);
            bn_v3_cross(e1, e2, c);
            a0 = 0.5 * bn_v3_len(c);
            bn_v3_cross(e2, e3, c);
            a1 = 0.5 * bn_v3_len(c);
        }
        R.fan0[i] = a0 + a1 > 0 ? a0 / (a0 + a1) : 1;
    }
    bn_scene_bounds(scene, lo, hi);
    R.tol = 1e-9 * fmax(bn_v3_dist(lo, hi), 1e-300);
    R.ray_eps = bn_rt_epsilon(rt);
    R.force = o->eps == 0;
    R.min_area = o->min_area > 0 ? o->min_area : o->min_area == 0 ? ldexp(t.area[0], -20) : 0;
    if (!(R.bound = bn__calloc((size_t)bn_dist_size() + 1, sizeof *R.bound))) {
        st = bn_error_set(err, BN_ENOMEM, "out of memory");
        goto done;
    }
    for (int q = 0; q < bn_dist_size(); q++)
        bn__dist_leaves_of(np, (size_t)q, &R.bound[q], &R.bound[q + 1]);
    R.plo = R.bound[bn_dist_rank()];
    R.phi = R.bound[bn_dist_rank() + 1];
    E = bn__malloc_array(3 * np, sizeof(double));
    rho = bn__malloc_array(3 * np, sizeof(double));
    L = bn__malloc_array(3 * np, sizeof(double));
    R.Bmax = bn__malloc_array(3 * t.n, sizeof(double));
    W = bn__calloc((size_t)nt, sizeof *W);
    if (!E || !rho || !L || !R.Bmax || !W) {
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy of %zu patches", np);
        goto done;
    }
    if ((st = bn__ff_pairs_create(scene, rt, &o->ff, &R.pairs, err)) != BN_OK)
        goto done;
    for (int k = 0; k < nt; k++)
        if (!(W[k].ff = bn__ff_worker_create(R.pairs))) {
            st = bn_error_set(err, BN_ENOMEM, "out of memory for per-thread buffers");
            goto done;
        }
    bn_scene_patch_emission(scene, E);
    bn_scene_patch_reflectance(scene, rho);
    memcpy(L, E, 3 * np * sizeof(double));
    for (size_t k = 0; k < 3 * np; k++)
        emax = fmax(emax, E[k]);
    R.eps_abs = o->eps * emax;
    rep->eps_abs = R.eps_abs;
    bn__bmax(&t, E, R.Bmax);

    /* the start: the root's self-link, or every pair of polygons */
    if (o->clusters) {
        bn__vec_push(&work, 0, 0, -1, 0);
    } else {
        uint32_t *fnode = bn__malloc_array(t.n, sizeof(uint32_t));
        size_t m = 0;
        if (!fnode) {
            st = bn_error_set(err, BN_ENOMEM, "out of memory");
            goto done;
        }
        for (uint32_t v = 0; v < t.n; v++)   /* the topmost planar nodes: the planes */
            if (t.plane[v] >= 0 && (v == 0 || t.plane[t.parent[v]] < 0))
                fnode[m++] = v;
        for (size_t a = 0; a < m && !work.oom; a++)
            for (size_t b = 0; b < m; b++)
                if (a != b)
                    bn__vec_push(&work, fnode[a], fnode[b], -1, 0);
        free(fnode);
        if (work.oom) {
            st = bn_error_set(err, BN_ENOMEM, "out of memory for %zu^2 polygon pairs (use clusters)", m);
            goto done;
        }
    }
    for (int pass = 0; pass < o->max_passes; pass++) {
        size_t splits = 0;
        char label[64];
        snprintf(label, sizeof label, "hierarchy pass %d", pass + 1);
        unsigned long long cnt[3] = {0, 0, 0};   /* links, links between patches, splits: over all ranks */
        st = bn__pass(&R, W, nt, &work, &splits, &rep->rays, label, err);
        if (st == BN_OK && work.n * sizeof(bn__link) + bn__tree_bytes(&t) > limit)
            st = bn_error_set(err, BN_ENOMEM,
                              "the hierarchy needs %zu links (%.3g GiB) at eps %g, above the memory limit: raise --eps",
                              work.n, (double)(work.n * sizeof(bn__link)) / (1 << 30), o->eps);
        {   /* every rank stops together: one that failed alone would leave the others in a sum */
            bn_status all = bn_dist_agree(st);
            if (all != BN_OK && st == BN_OK)
                st = bn_error_set(err, all, "hierarchy: another MPI process failed (%s)", bn_status_str(all));
        }
        if (st != BN_OK)
            goto done;
        rep->passes = (size_t)pass + 1;
        for (size_t l = 0; l < work.n; l++)
            if (bn__receiver_counted(&R, work.a[l].r)) {
                cnt[0]++;
                cnt[1] += bn__tree_is_leaf(&t, work.a[l].r) && bn__tree_is_leaf(&t, work.a[l].s);
            }
        cnt[2] = splits;
        if ((st = bn_dist_sum_u64(cnt, 3, err)) != BN_OK)
            goto done;
        bn_logf(&o->log, BN_LOG_INFO, "hierarchy pass %d: %llu links (%llu between patches), %llu split, %.1f s",
                pass + 1, cnt[0], cnt[1], cnt[2], bn__now() - t0);
        if (pass > 0 && (double)cnt[2] < BN__SETTLED * (double)cnt[0]) {
            rep->settled = 1;
            break;
        }
        if (R.force || pass + 1 == o->max_passes)
            break;   /* eps 0: the links are at the patches already; nothing can split */
        {
            double imb;
            unsigned long long mv = 0;
            size_t moved;
            if ((st = bn__rebalance(&R, &work, &imb, &moved, err)) != BN_OK)
                goto done;
            mv = moved;
            if (imb > BN__IMBALANCE && (st = bn_dist_sum_u64(&mv, 1, err)) != BN_OK)
                goto done;
            if (imb > BN__IMBALANCE)
                bn_logf(&o->log, BN_LOG_INFO, "hierarchy: leaves split again among %d processes (the most loaded "
                        "held %.2fx the mean); %llu links moved", bn_dist_size(), imb, mv);
        }
        if ((st = bn__estimate(&t, &work, R.bound, E, rho, R.eps_abs, L, err)) != BN_OK)
            goto done;
        bn__bmax(&t, L, R.Bmax);
    }
    if (R.force)
        rep->settled = 1;
    if (!rep->settled)
        bn_logf(&o->log, BN_LOG_WARN, "hierarchy: links still splitting after %d passes; frozen as they are",
                o->max_passes);
    work.n = bn__compact(&work);
    {   /* counted by the rank holding each receiver's first leaf, summed: one process's counts */
        unsigned long long cnt[3] = {0, 0, 0};
        for (size_t l = 0; l < work.n; l++) {
            int lr = bn__tree_is_leaf(&t, work.a[l].r), ls = bn__tree_is_leaf(&t, work.a[l].s);
            if (!bn__receiver_counted(&R, work.a[l].r))
                continue;
            cnt[0]++;
            cnt[1] += lr && ls;
            cnt[2] += t.plane[work.a[l].r] < 0 || t.plane[work.a[l].s] < 0;
        }
        if ((st = bn_dist_sum_u64(cnt, 3, err)) != BN_OK)
            goto done;
        rep->links = cnt[0];
        rep->leaf_links = cnt[1];
        rep->cluster_links = cnt[2];
        rep->links_here = work.n;
        {   /* what each process stores: its receivers' links and the shared top's (all with one process) */
            unsigned long long here = work.n, most = 0, *all = bn__calloc((size_t)bn_dist_size(), sizeof *all);
            if (!all) {
                st = bn_error_set(err, BN_ENOMEM, "out of memory");
                goto done;
            }
            all[bn_dist_rank()] = here;
            if ((st = bn_dist_sum_u64(all, (size_t)bn_dist_size(), err)) != BN_OK) {
                free(all);
                goto done;
            }
            size_t recv = 0;   /* the all-gather per application: the leaves a rank does not own, 3 doubles each */
            for (int k = 0; k < bn_dist_size(); k++) {
                most = all[k] > most ? all[k] : most;
                if (bn_dist_size() > 1 && np - (R.bound[k + 1] - R.bound[k]) > recv)
                    recv = np - (R.bound[k + 1] - R.bound[k]);
            }
            bn_logf(&o->log, BN_LOG_INFO, "hierarchy: %d process%s %llu links at most each (%.2f of the %zu "
                    "kept, F > 0; rank 0 %llu); per application of K a process receives at most %zu bytes",
                    bn_dist_size(), bn_dist_size() > 1 ? "es store" : " stores", most,
                    rep->links ? (double)most / (double)rep->links : 0.0, rep->links, all[0],
                    recv * 3 * sizeof(double));
            free(all);
        }
    }
    if ((st = bn__hop_make(&t, work.a, work.n, R.bound, &h, err)) != BN_OK)
        goto done;
    rep->patches = np;
    rep->nodes = t.n;
    bn_scene_faces(scene, &rep->polygons);
    rep->planes = t.nplanes;
    rep->min_area = R.min_area;
    for (size_t v = 0; v < t.n; v++) {
        rep->clusters += t.plane[v] < 0;
        rep->planar_nodes += t.plane[v] >= 0 && t.child[v] != BN__NONE;
    }
    rep->bytes = bn__hop_bytes(h);
    rep->bytes_per_link = h->nlinks ? (double)bn__hop_link_bytes(h) / (double)h->nlinks : 0;
    rep->seconds_refine = bn__now() - t0;
    st = bn_transport_create(np, rho, &bn__hop_ops, h, out, err);
    h = NULL;   /* owned by *out now, or destroyed */
done:
    if (W)
        for (int k = 0; k < nt; k++) {
            free(W[k].links.a);
            free(W[k].pending.a);
            bn__ff_worker_destroy(W[k].ff);
        }
    free(W);
    bn__hop_destroy(h);
    bn__ff_pairs_destroy(R.pairs);
    free(R.Bmax);
    free(R.fan0);
    free(R.bound);
    free(work.a);
    free(E);
    free(rho);
    free(L);
    bn__tree_free(&t);
    return st;
}

bn_status bn_hierarchy_build(const bn_scene *scene, const bn_rt *rt, const bn_hierarchy_opts *o, bn_transport **out,
                             bn_hierarchy_report *rep, bn_error *err)
{
    bn_hierarchy_report local;
    int prev = bn__threads_begin(o->threads);
    bn_status st = bn__hierarchy_body(scene, rt, o, out, rep ? rep : &local, err);
    bn__threads_end(prev);
    return st;
}

void bn_hierarchy_report_print(const bn_hierarchy_report *r, FILE *fp)
{
    fprintf(fp, "polygons %zu\nplanes %zu\nmin_area %.6g\n", r->polygons, r->planes, r->min_area);
    fprintf(fp, "patches %zu\nnodes %zu\nclusters %zu\nplanar_nodes %zu\nlinks %zu\nleaf_links %zu\n"
                "cluster_links %zu\nlinks_per_patch %.3g\npasses %zu\nsettled %d\nrays %zu\nbytes %zu\n"
                "bytes_per_link %.3g\neps_abs %.6g\nseconds_tree %.3f\nseconds_refine %.3f\n",
            r->patches, r->nodes, r->clusters, r->planar_nodes, r->links, r->leaf_links, r->cluster_links,
            r->patches ? (double)r->links / (double)r->patches : 0.0, r->passes, r->settled, r->rays, r->bytes,
            r->bytes_per_link, r->eps_abs, r->seconds_tree, r->seconds_refine);
}
