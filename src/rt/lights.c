/* The light tree (src/rt/lights.h): a binary tree, each split where the two halves' power x box area
 * x normal spread is least along the three axes (pbrt-v4's surface area orientation heuristic,
 * simplified), one emitter per leaf; each node's box, normal cone and power. */
#include "rt/lights.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct bn__lnode {
    double c[3], r2;         /* the centre of the box and its half-diagonal squared */
    double m[3];             /* the power-weighted mean of its lights' centroids */
    double behind;           /* a leaf: how far behind its plane a point still receives (else -1) */
    double axis[3], cos_o, sin_o;   /* the cone of the front normals: axis and half-angle */
    double power;
    double lo[3], hi[3];
    long child[2];           /* a leaf: child[0] = -1 - light, child[1] = -1 */
    long parent;             /* -1 at the root */
    size_t first, count;     /* its lights: order[first .. first + count) */
} bn__lnode;

struct bn__lights {
    bn__lnode *node;
    size_t nn, nl;
    size_t *leaf;            /* per light, its leaf */
    size_t *order;           /* the lights, each node's contiguous */
    double *prefix;          /* n + 1: the sums of the powers of order[0 .. k) */
    const struct bn__lkey *keys0;   /* while building */
    double *cost;                   /* while building: n */
    double behind;
    int depth;
};

/* Angles within BN__SLACK (radians) of a bound count as inside it, with at least BN__FLOOR as
 * their cosine: a point a hair behind an emitter's plane (the gather moves such points 2 eps to
 * the front) keeps a non-zero probability. */
#define BN__SLACK 1e-3
#define BN__FLOOR 1e-3
/* Nodes whose bounding sphere subtends less than asin(BN__NEAR) at x and whose normals lie within
 * acos(BN__FLAT) of their axis are weighed by the cosines at their centre, not less than BN__KEEP
 * of the bound. */
#define BN__NEAR 0.5
#define BN__FLAT 0.9
#define BN__KEEP 0.05

static double bn__acos(double c)
{
    return acos(c > 1 ? 1 : c < -1 ? -1 : c);
}

/* cos(a - b) floored at the bound's rules, from the cosines and sines of a and b (in [0, pi]): 1
 * when a <= b, 0 when a - b exceeds a right angle by more than the slack, else at least
 * BN__FLOOR. Without inverse trigonometry: this runs twice per tree level per pick. */
static double bn__cos_bound(double ca, double sa, double cb, double sb)
{
    double c;
    if (ca >= cb)
        return 1;
    c = ca * cb + sa * sb;
    if (c < -BN__SLACK)
        return 0;
    return c > BN__FLOOR ? c : BN__FLOOR;
}

static double bn__sin(double c)
{
    double s = 1 - c * c;
    return s > 0 ? sqrt(s) : 0;
}

/* The mean of max(0, c + t) for t uniform in [-s, s]: a cosine c at a node's mean point, spread by
 * the node's angular radius s, clamped at the horizon as the clipped node is. */
static double bn__cos_spread(double c, double s)
{
    if (c >= s)
        return c;
    if (c <= -s)
        return 0;
    return (c + s) * (c + s) / (4 * s);
}

/* A far, flat node seen from x (normal n): its power x the cosines at its mean point (each spread
 * by the node's angular radius sb about the horizon) / distance^2, which for small, distant lights
 * is their form factors' ratio to within (size / distance)^2; never below BN__KEEP of the bound's
 * cosines (bound), so never 0 where the bounds allow light. */
static double bn__far(const bn__lnode *nd, const double x[3], const double n[3], double sb, double bound)
{
    double d[3], d2, inv, ce, cx, c2, rn = 0;
    bn_v3_sub(x, nd->m, d);
    d2 = bn_v3_dot(d, d);
    inv = 1 / sqrt(d2);
    for (int k = 0; k < 3; k++)   /* the box's half-extent along n: how far its lights reach past x's horizon */
        rn += fabs(n[k]) * 0.5 * (nd->hi[k] - nd->lo[k]);
    ce = bn__cos_spread(bn_v3_dot(nd->axis, d) * inv, sb);
    cx = bn__cos_spread(-bn_v3_dot(n, d) * inv, rn * inv);
    c2 = ce * cx;
    return nd->power * (c2 > BN__KEEP * bound ? c2 : BN__KEEP * bound) / d2;
}

/* Whether node nd may be weighed by its mean point at x: far (its bounding sphere under the sine
 * BN__NEAR) and flat (its normals within acos BN__FLAT of their axis). */
static int bn__far_ok(const bn__lnode *nd, const double x[3])
{
    double d[3];
    bn_v3_sub(x, nd->c, d);
    return nd->cos_o > BN__FLAT && nd->r2 < BN__NEAR * BN__NEAR * bn_v3_dot(d, d);
}

/* Node nd's weight at x (normal n); far: by its mean point where bn__far_ok, else by its bounds.
 * Siblings are weighed the same way (far only when every one of them is far and flat): the
 * mean point's weight is much below the bounds' for a light seen at a grazing angle, and a light
 * weighed by it beside one weighed by bounds would get a tiny probability for what it gives (a
 * speckled image). */
static double bn__importance(const bn__lnode *nd, const double x[3], const double n[3], int far)
{
    double d[3], d2, sb, cb, cw, ce, ci = 1, inv;
    if (nd->behind >= 0) {   /* one light: no light at all behind its plane */
        bn_v3_sub(x, nd->m, d);
        if (bn_v3_dot(d, nd->axis) < -nd->behind)
            return 0;
    }
    bn_v3_sub(x, nd->c, d);
    d2 = bn_v3_dot(d, d);
    if (d2 <= nd->r2)   /* x within the node's bounding sphere: every angle possible */
        return nd->power / (d2 > nd->r2 * 1e-6 ? d2 : nd->r2 > 0 ? nd->r2 : 1e-300);
    sb = sqrt(nd->r2 / d2);   /* the half-angle the bounding sphere subtends at x */
    cb = sqrt(1 - sb * sb);
    inv = 1 / sqrt(d2);
    cw = bn_v3_dot(nd->axis, d) * inv;   /* the cone's axis against the direction to x */
    cw = cw > 1 ? 1 : cw < -1 ? -1 : cw;
    if (cw >= nd->cos_o) {   /* x within the normals' cone */
        ce = 1;
    } else {   /* theta_w - theta_o, then less theta_b */
        double sw = bn__sin(cw);
        ce = bn__cos_bound(cw * nd->cos_o + sw * nd->sin_o, sw * nd->cos_o - cw * nd->sin_o, cb, sb);
    }
    if (n && ce > 0) {
        double cx = -bn_v3_dot(n, d) * inv;
        cx = cx > 1 ? 1 : cx < -1 ? -1 : cx;
        ci = cx >= cb ? 1 : bn__cos_bound(cx, bn__sin(cx), cb, sb);
        if (far)
            return bn__far(nd, x, n, sb, ce * ci);
    }
    return nd->power * ce * ci / d2;
}

/* The smallest cone found (pbrt-v4's DirectionCone Union) holding cones a and b. */
static void bn__cone_union(const double a[3], double ca, const double b[3], double cb, double out[3], double *co)
{
    double ta = bn__acos(ca), tb = bn__acos(cb), td = bn__acos(bn_v3_dot(a, b)), to, tr, k[3], ka[3];
    if (fmin(td + tb, BN_PI) <= ta) {
        memcpy(out, a, 3 * sizeof(double));
        *co = ca;
        return;
    }
    if (fmin(td + ta, BN_PI) <= tb) {
        memcpy(out, b, 3 * sizeof(double));
        *co = cb;
        return;
    }
    to = 0.5 * (ta + td + tb);
    bn_v3_cross(a, b, k);
    memcpy(out, a, 3 * sizeof(double));
    if (to >= BN_PI || !(bn_v3_normalize(k) > 1e-12)) {
        *co = -1;
        return;
    }
    tr = to - ta;   /* a turned towards b by tr about k (k is perpendicular to a) */
    bn_v3_cross(k, a, ka);
    for (int i = 0; i < 3; i++)
        out[i] = a[i] * cos(tr) + ka[i] * sin(tr);
    bn_v3_normalize(out);
    *co = cos(to);
}

typedef struct bn__lkey {
    double key;
    size_t i;
} bn__lkey;

static int bn__lkey_cmp(const void *pa, const void *pb)
{
    const bn__lkey *a = pa, *b = pb;
    return a->key < b->key ? -1 : a->key > b->key ? 1 : a->i < b->i ? -1 : a->i > b->i;
}

/* The node's bounding sphere (its box's centre and half-diagonal) and its cone's sine. */
static void bn__node_sphere(bn__lnode *nd)
{
    nd->r2 = 0;
    for (int k = 0; k < 3; k++) {
        double h = 0.5 * (nd->hi[k] - nd->lo[k]);
        nd->c[k] = 0.5 * (nd->hi[k] + nd->lo[k]);
        nd->r2 += h * h;
    }
    nd->sin_o = bn__sin(nd->cos_o);
}

/* A leaf for light i. */
static void bn__leaf(bn__lights *T, const bn__light *l, size_t i, size_t at)
{
    bn__lnode *nd = &T->node[at];
    for (int k = 0; k < 3; k++) {
        nd->lo[k] = INFINITY;
        nd->hi[k] = -INFINITY;
    }
    for (size_t c = 0; c < l[i].nv; c++)
        for (int k = 0; k < 3; k++) {
            nd->lo[k] = fmin(nd->lo[k], l[i].v[3 * c + k]);
            nd->hi[k] = fmax(nd->hi[k], l[i].v[3 * c + k]);
        }
    memcpy(nd->axis, l[i].n, sizeof nd->axis);
    nd->cos_o = 1;
    bn__node_sphere(nd);
    nd->power = l[i].power;
    nd->child[0] = -1 - (long)i;
    nd->child[1] = -1;
    T->leaf[i] = at;
}

/* A running bound of lights for the split cost: box, cone and power. */
typedef struct bn__acc {
    double lo[3], hi[3], axis[3], cos_o, power;
    int any;
} bn__acc;

static void bn__acc_add(bn__acc *a, const bn__light *li)
{
    for (size_t c = 0; c < li->nv; c++)
        for (int k = 0; k < 3; k++) {
            double v = li->v[3 * c + k];
            a->lo[k] = a->any && a->lo[k] < v ? a->lo[k] : v;
            a->hi[k] = a->any && a->hi[k] > v ? a->hi[k] : v;
            a->any |= k == 2;
        }
    if (a->power == 0) {
        memcpy(a->axis, li->n, sizeof a->axis);
        a->cos_o = 1;
    } else {
        bn__cone_union(a->axis, a->cos_o, li->n, 1, a->axis, &a->cos_o);
    }
    a->power += li->power;
}

/* The surface area orientation cost of a bound (pbrt-v4's, simplified): power x box area x the
 * normals' spread. */
static double bn__acc_cost(const bn__acc *a)
{
    double d[3] = {a->hi[0] - a->lo[0], a->hi[1] - a->lo[1], a->hi[2] - a->lo[2]};
    return a->power * (2 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0]) + 1e-300) * (bn__acos(a->cos_o) + BN_PI / 2);
}

/* keys[0..m) sorted along the axis, and the split position (1 .. m - 1), of least cost over the three
 * axes (cost: scratch of m). */
#define BN__SAOH_DEPTH 40

static size_t bn__best_split(const bn__light *l, const double *cen, bn__lkey *keys, size_t m, int depth, double *cost)
{
    double best = INFINITY;
    int bax = 0;
    /* any split down to depth BN__SAOH_DEPTH (a lamp and a window must part at the root, 1 of 49
     * or not), the median below it: depth at most BN__SAOH_DEPTH + log2 n, so the build's recursion
     * and bn__lights_pdf's path stay short whatever the lights (all at one point, say) */
    size_t bpos = m / 2, lo = depth < BN__SAOH_DEPTH ? 1 : m / 2, hi = depth < BN__SAOH_DEPTH ? m - 1 : m / 2;
    for (int ax = 0; ax < 3; ax++) {
        bn__acc a = {0};
        for (size_t j = 0; j < m; j++)
            keys[j].key = cen[3 * keys[j].i + ax];
        qsort(keys, m, sizeof *keys, bn__lkey_cmp);
        for (size_t j = 0; j + 1 < m; j++) {
            bn__acc_add(&a, &l[keys[j].i]);
            cost[j + 1] = bn__acc_cost(&a);
        }
        memset(&a, 0, sizeof a);
        for (size_t j = m - 1; j >= 1; j--) {
            bn__acc_add(&a, &l[keys[j].i]);
            if (j >= lo && j <= hi && cost[j] + bn__acc_cost(&a) < best) {
                best = cost[j] + bn__acc_cost(&a);
                bax = ax;
                bpos = j;
            }
        }
    }
    for (size_t j = 0; j < m; j++)
        keys[j].key = cen[3 * keys[j].i + bax];
    qsort(keys, m, sizeof *keys, bn__lkey_cmp);
    return bpos;
}

/* The node at `at` over keys[0..m): returns the next free node. */
static size_t bn__build(bn__lights *T, const bn__light *l, const double *cen, bn__lkey *keys, size_t m, size_t at,
                        int depth)
{
    T->node[at].first = (size_t)(keys - T->keys0);
    T->node[at].count = m;
    size_t next, half;
    bn__lnode *nd, *a, *b;
    T->depth = depth > T->depth ? depth : T->depth;
    if (m == 1) {
        bn__leaf(T, l, keys[0].i, at);
        memcpy(T->node[at].m, cen + 3 * keys[0].i, sizeof T->node[at].m);
        T->node[at].behind = T->behind;
        T->order[T->node[at].first] = keys[0].i;
        return at + 1;
    }
    half = bn__best_split(l, cen, keys, m, depth, T->cost);
    T->node[at].child[0] = (long)at + 1;
    next = bn__build(T, l, cen, keys, half, at + 1, depth + 1);
    T->node[at].child[1] = (long)next;
    next = bn__build(T, l, cen, keys + half, m - half, next, depth + 1);
    nd = &T->node[at];
    a = &T->node[nd->child[0]];
    b = &T->node[nd->child[1]];
    a->parent = b->parent = (long)at;
    for (int k = 0; k < 3; k++) {
        nd->lo[k] = fmin(a->lo[k], b->lo[k]);
        nd->hi[k] = fmax(a->hi[k], b->hi[k]);
    }
    bn__cone_union(a->axis, a->cos_o, b->axis, b->cos_o, nd->axis, &nd->cos_o);
    bn__node_sphere(nd);
    nd->power = a->power + b->power;
    nd->behind = -1;
    for (int k = 0; k < 3; k++)
        nd->m[k] = nd->power > 0 ? (a->power * a->m[k] + b->power * b->m[k]) / nd->power : nd->c[k];
    return next;
}

bn__lights *bn__lights_build(const bn__light *l, size_t n, double behind)
{
    bn__lights *T = bn__calloc(1, sizeof *T);
    double *cen = bn__malloc_array(n, 3 * sizeof(double));
    bn__lkey *keys = bn__malloc_array(n, sizeof *keys);
    if (!T || !cen || !keys || n == 0 || !(T->node = bn__calloc(2 * n - 1, sizeof *T->node)) ||
        !(T->leaf = bn__malloc_array(n, sizeof *T->leaf)) || !(T->order = bn__malloc_array(n, sizeof *T->order)) ||
        !(T->prefix = bn__malloc_array(n + 1, sizeof *T->prefix))) {
        free(cen);
        free(keys);
        bn__lights_free(T);
        return NULL;
    }
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) {
            cen[3 * i + k] = 0;
            for (size_t c = 0; c < l[i].nv; c++)
                cen[3 * i + k] += l[i].v[3 * c + k] / (double)l[i].nv;
        }
        keys[i].i = i;
    }
    T->nl = n;
    T->behind = behind > 0 ? behind : 0;
    T->keys0 = keys;
    if (!(T->cost = bn__malloc_array(n + 1, sizeof(double)))) {
        free(cen);
        free(keys);
        bn__lights_free(T);
        return NULL;
    }
    T->nn = bn__build(T, l, cen, keys, n, 0, 0);
    T->keys0 = NULL;
    free(T->cost);
    T->cost = NULL;
    T->prefix[0] = 0;
    for (size_t k = 0; k < n; k++)
        T->prefix[k + 1] = T->prefix[k] + l[T->order[k]].power;
    T->node[0].parent = -1;
    free(cen);
    free(keys);
    return T;
}

void bn__lights_free(bn__lights *t)
{
    if (!t)
        return;
    free(t->node);
    free(t->leaf);
    free(t->order);
    free(t->prefix);
    free(t);
}

/* The importance of each light of a node of at most BN__LIGHTS_CLUSTER lights into w; their sum. */
static double bn__cluster_weights(const bn__lights *t, const bn__lnode *nd, const double x[3], const double n[3],
                                  double *w)
{
    double s = 0;
    int far = 1;
    for (size_t k = 0; k < nd->count; k++)
        far &= bn__far_ok(&t->node[t->leaf[t->order[nd->first + k]]], x);
    for (size_t k = 0; k < nd->count; k++) {
        double v = bn__importance(&t->node[t->leaf[t->order[nd->first + k]]], x, n, far);
        s += w[k] = v > 0 ? v : 0;
    }
    return s;
}

/* The light of a small node nd chosen by u in proportion to its own importance, p multiplied in. */
static size_t bn__cluster_pick(const bn__lights *t, const bn__lnode *nd, const double x[3], const double n[3],
                               double u, double *p)
{
    double w[BN__LIGHTS_CLUSTER], s = bn__cluster_weights(t, nd, x, n, w), acc = 0;
    size_t last = 0;
    if (!(s > 0) || !isfinite(s))
        return BN__LIGHTS_NONE;
    for (size_t k = 0; k < nd->count; k++) {
        if (!(w[k] > 0))
            continue;
        last = k;
        if (u * s < acc + w[k])
            break;
        acc += w[k];
    }
    *p *= w[last] / s;
    return t->order[nd->first + last];
}

/* Whether node nd (of more than one light) is far from x by the threshold: its bounding sphere
 * within the sine `far` of x's direction to it. */
static int bn__is_far(const bn__lnode *nd, const double x[3], double far)
{
    double d[3];
    bn_v3_sub(x, nd->c, d);
    return far > 0 && nd->count > 1 && nd->r2 < far * far * bn_v3_dot(d, d);
}

/* The light of a far node chosen by u in proportion to its power (binary search in the prefix sums
 * of the tree's order), p multiplied in. */
static size_t bn__power_pick(const bn__lights *t, const bn__lnode *nd, double u, double *p)
{
    size_t lo = nd->first, hi = nd->first + nd->count - 1;
    double base = t->prefix[nd->first], target = base + u * nd->power;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (target < t->prefix[mid + 1])
            hi = mid;
        else
            lo = mid + 1;
    }
    *p *= (t->prefix[lo + 1] - t->prefix[lo]) / nd->power;
    return t->order[lo];
}

/* The two children's importances at x into w; 0 when neither can light x. */
static int bn__split(const bn__lights *t, const bn__lnode *nd, const double x[3], const double n[3], double w[2])
{
    double s;
    const bn__lnode *a = &t->node[nd->child[0]], *b = &t->node[nd->child[1]];
    int far = bn__far_ok(a, x) && bn__far_ok(b, x);
    w[0] = bn__importance(a, x, n, far);
    w[1] = bn__importance(b, x, n, far);
    s = w[0] + w[1];
    return s > 0 && isfinite(s);
}

size_t bn__lights_pick(const bn__lights *t, const double x[3], const double n[3], double u, double far, double *pdf)
{
    const bn__lnode *nd = &t->node[0];
    double p = 1, w[2];
    size_t i;
    for (;;) {
        if (bn__is_far(nd, x, far)) {
            i = bn__power_pick(t, nd, u, &p);
            break;
        }
        if (nd->count <= BN__LIGHTS_CLUSTER) {
            i = bn__cluster_pick(t, nd, x, n, u, &p);
            break;
        }
        if (!bn__split(t, nd, x, n, w))
            return BN__LIGHTS_NONE;
        if (u < w[0] / (w[0] + w[1])) {
            u = u / (w[0] / (w[0] + w[1]));
            p *= w[0] / (w[0] + w[1]);
            nd = &t->node[nd->child[0]];
        } else {
            u = (u - w[0] / (w[0] + w[1])) / (w[1] / (w[0] + w[1]));
            p *= w[1] / (w[0] + w[1]);
            nd = &t->node[nd->child[1]];
        }
        u = u < 0 ? 0 : u < 1 ? u : 0x1.fffffffffffffp-1;
    }
    *pdf = p;
    return i;
}

/* The pick's own decisions replayed down the path from the root to light i's leaf. */
double bn__lights_pdf(const bn__lights *t, const double x[3], const double n[3], size_t i, double far)
{
    long path[128];
    int depth = 0;
    double p = 1, w[BN__LIGHTS_CLUSTER], s;
    for (long at = (long)t->leaf[i]; at >= 0 && depth < 128; at = t->node[at].parent)
        path[depth++] = at;
    for (int k = depth - 1; k >= 0; k--) {
        const bn__lnode *nd = &t->node[path[k]];
        if (bn__is_far(nd, x, far)) {
            size_t j = t->node[t->leaf[i]].first;
            return p * (t->prefix[j + 1] - t->prefix[j]) / nd->power;
        }
        if (nd->count <= BN__LIGHTS_CLUSTER) {
            double wi = 0;
            s = bn__cluster_weights(t, nd, x, n, w);
            for (size_t m = 0; m < nd->count; m++)
                wi = t->order[nd->first + m] == i ? w[m] : wi;
            return s > 0 && isfinite(s) ? p * wi / s : 0;
        }
        if (!bn__split(t, nd, x, n, w))
            return 0;
        p *= w[nd->child[0] == path[k - 1] ? 0 : 1] / (w[0] + w[1]);
    }
    return p;
}

size_t bn__lights_nodes(const bn__lights *t)
{
    return t->nn;
}

int bn__lights_depth(const bn__lights *t)
{
    return t->depth;
}
