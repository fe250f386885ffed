/* The unoccluded form factor between planar polygons: Lambert's contour integral for a point
 * and a polygon, integrated over the other polygon by adaptive triangle quadrature.
 *   F_dA->P = -(1/2pi) sum_k gamma_k n . (R_k x R_k+1)/|R_k x R_k+1|   (Lambert 1760; Sparrow 1963)
 *   A_i F_ij = int_{P_i} F_dA(x)->P_j dA(x)
 * Rules: Strang-Fix degree 2 (3 points) and Radon's degree 5 (7 points) on triangles. The polygon
 * primitives (the point kernel, clipping, area) are polygon.c's. */
#include "formfactor/ff_internal.h"
#include "base/vec.h"

#include <float.h>
#include <math.h>
#include <string.h>

static double bn__seg_dist(const double x[3], const double a[3], const double b[3])
{
    double ab[3], ax[3], t, q[3];
    bn_v3_sub(b, a, ab);
    bn_v3_sub(x, a, ax);
    t = bn_v3_dot(ab, ab);
    t = t > 0 ? bn_clamp(bn_v3_dot(ax, ab) / t, 0, 1) : 0;
    bn_v3_madd(a, t, ab, q);
    return bn_v3_dist(x, q);
}

double bn__point_polygon_dist(const double x[3], const double *v, size_t nv, const double n[3])
{
    double r[3], h, best = INFINITY;
    int inside = 1;
    bn_v3_sub(x, v, r);
    h = bn_v3_dot(r, n);
    for (size_t k = 0; k < nv; k++) {
        const double *a = v + 3 * k, *b = v + 3 * (k + 1 < nv ? k + 1 : 0);
        double e[3], ax[3], c[3];
        bn_v3_sub(b, a, e);
        bn_v3_sub(x, a, ax);
        bn_v3_cross(e, ax, c);
        if (bn_v3_dot(c, n) < 0)
            inside = 0;
    }
    if (inside)
        return fabs(h);
    for (size_t k = 0; k < nv; k++)
        best = fmin(best, bn__seg_dist(x, v + 3 * k, v + 3 * (k + 1 < nv ? k + 1 : 0)));
    return best;
}

/* ---- adaptive quadrature over triangles ---- */

typedef struct bn__qctx {
    const double *pj;
    size_t nj;
    double nj_n[3];
    double ni_n[3];
    double tol_per_area;   /* tolerance per unit area of P_i */
    bn__quad_stats *st;
    const double *occ;     /* occluders (bn__ff_point_blocked), or none */
    const double *cull;    /* their planes for leaving faces seen from behind out, or NULL */
    const unsigned *occ_n;
    size_t nocc;
    double gtol;
    int split;             /* start from 4^split triangles per fan triangle */
    int shadowed;          /* the current leaf: whether its first point had an occluder in view; */
    int npoints, mixed;    /* its points so far; whether one had none in view and another some */
    int mixed_depth;       /* mixed leaves are split down to this depth */
} bn__qctx;

/* A triangle may be accepted only when its diameter is below KAPPA times the distance from its
 * centroid to P_j: features of the integrand have the size of that distance, and the two rules
 * could agree by chance on a triangle much larger than them. 5 leaves touching pairs (centroid
 * at a third of the height from the shared edge) to the error test. */
#define BN__KAPPA 5.0
#define BN__MAX_DEPTH 60

static double bn__eval(bn__qctx *q, const double a[3], const double b[3], const double c[3], double l0, double l1,
                       double l2)
{
    double x[3];
    for (int k = 0; k < 3; k++)
        x[k] = l0 * a[k] + l1 * b[k] + l2 * c[k];
    q->st->evals++;
    if (q->nocc) {
        uint32_t mask;
        int sees;
        /* the blocked part, F(x -> b) minus what x sees of b: 0 wherever no occluder is in view */
        double g = bn__ff_point_blocked(x, q->ni_n, q->pj, q->nj, q->nj_n, q->occ, q->occ_n, q->cull, q->nocc, q->gtol,
                                        &mask, &sees);
        q->st->seen += sees;
        if (q->npoints++ == 0)
            q->shadowed = mask != 0;
        else if ((mask != 0) != q->shadowed)
            q->mixed = 1;
        return g;
    }
    return bn__ff_point_polygon(x, q->ni_n, q->pj, q->nj);
}

static void bn__rules(bn__qctx *q, const double a[3], const double b[3], const double c[3], double area, double *q2,
                      double *q5)
{
    /* Radon's 7-point degree-5 rule: b1 = (6 + sqrt 15)/21, b2 = (6 - sqrt 15)/21,
     * weights (155 +- sqrt 15)/1200 and 9/40 at the centroid. The degree-2 rule its error is
     * measured against uses the same points (no evaluations of its own): the centroid, weight
     * sqrt 15 / 8, and the orbit of b2, each 1 / (18 (a2^2 + 2 b2^2 - 1/3)), both positive. */
    static const double b1 = 0.47014206410511508977, a1 = 0.05971587178976982045;
    static const double b2 = 0.10128650732345633880, a2 = 0.79742698535308732240;
    static const double w1 = 0.13239415278850618074, w2 = 0.12593918054482715260, w0 = 0.225;
    static const double v0 = 0.48412291827592711065, v2 = 0.17195902724135762978;
    double fc = bn__eval(q, a, b, c, 1.0 / 3, 1.0 / 3, 1.0 / 3);
    double f1 = bn__eval(q, a, b, c, a1, b1, b1) + bn__eval(q, a, b, c, b1, a1, b1) + bn__eval(q, a, b, c, b1, b1, a1);
    double f2 = bn__eval(q, a, b, c, a2, b2, b2) + bn__eval(q, a, b, c, b2, a2, b2) + bn__eval(q, a, b, c, b2, b2, a2);
    *q5 = (w0 * fc + w1 * f1 + w2 * f2) * area;
    *q2 = (v0 * fc + v2 * f2) * area;
}

static double bn__tri_area(const double a[3], const double b[3], const double c[3])
{
    double e1[3], e2[3], x[3];
    bn_v3_sub(b, a, e1);
    bn_v3_sub(c, a, e2);
    bn_v3_cross(e1, e2, x);
    return 0.5 * bn_v3_len(x);
}

static double bn__tri_diam(const double a[3], const double b[3], const double c[3])
{
    return fmax(bn_v3_dist(a, b), fmax(bn_v3_dist(b, c), bn_v3_dist(c, a)));
}

/* A leaf of the refinement: a triangle with both rules evaluated. Priority: triangles larger
 * than KAPPA times their distance to P_j first, then the largest error estimate |Q5 - Q2|. */
typedef struct bn__leaf {
    double v[3][3];
    double area, q5, err, key;
    int depth;
} bn__leaf;

typedef struct bn__heap {
    bn__leaf *a;
    size_t n, cap;
    bn__leaf inline_[48];
} bn__heap;

/* An array that starts in inline storage (inl), moved to cap elements of its own (its n kept); the
 * old block freed unless it is inl. NULL when out of memory (a untouched). */
static void *bn__grow_inline(void *a, const void *inl, size_t n, size_t cap, size_t size)
{
    void *na = bn__malloc_array(cap, size);
    if (!na)
        return NULL;
    memcpy(na, a, n * size);
    if (a != inl)
        free(a);
    return na;
}

static int bn__heap_push(bn__heap *h, const bn__leaf *l)
{
    size_t k;
    if (h->n == h->cap) {
        bn__leaf *na = bn__grow_inline(h->a, h->inline_, h->n, 4 * h->cap, sizeof *na);
        if (!na)
            return 0;
        h->a = na;
        h->cap *= 4;
    }
    k = h->n++;
    while (k > 0) {
        size_t parent = (k - 1) / 2;
        if (h->a[parent].key >= l->key)
            break;
        h->a[k] = h->a[parent];
        k = parent;
    }
    h->a[k] = *l;
    return 1;
}

static bn__leaf bn__heap_pop(bn__heap *h)
{
    bn__leaf top = h->a[0], last = h->a[--h->n];
    size_t k = 0;
    for (;;) {
        size_t c = 2 * k + 1;
        if (c >= h->n)
            break;
        if (c + 1 < h->n && h->a[c + 1].key > h->a[c].key)
            c++;
        if (h->a[c].key <= last.key)
            break;
        h->a[k] = h->a[c];
        k = c;
    }
    if (h->n)
        h->a[k] = last;
    return top;
}

static void bn__leaf_make(bn__qctx *q, bn__leaf *l, const double a[3], const double b[3], const double c[3],
                          double area, int depth)
{
    double q2, g[3];
    memcpy(l->v[0], a, 3 * sizeof(double));
    memcpy(l->v[1], b, 3 * sizeof(double));
    memcpy(l->v[2], c, 3 * sizeof(double));
    l->area = area;
    l->depth = depth;
    q->npoints = q->mixed = 0;
    bn__rules(q, a, b, c, area, &q2, &l->q5);
    l->err = fabs(l->q5 - q2);
    for (int k = 0; k < 3; k++)
        g[k] = (a[k] + b[k] + c[k]) / 3;
    l->key = l->err;
    if (depth < BN__MAX_DEPTH) {
        double diam = bn__tri_diam(a, b, c);
        if (diam > BN__KAPPA * bn__point_polygon_dist(g, q->pj, q->nj, q->nj_n)) {
            /* A triangle touching P_j (a shared edge or corner) has features at every scale down
             * to the contact, which its rules see: leave it to the error test. */
            double dv = fmin(bn__point_polygon_dist(a, q->pj, q->nj, q->nj_n),
                             fmin(bn__point_polygon_dist(b, q->pj, q->nj, q->nj_n),
                                  bn__point_polygon_dist(c, q->pj, q->nj, q->nj_n)));
            if (dv > 1e-9 * diam)
                l->key = INFINITY;
        }
    }
    if (q->mixed && depth < q->mixed_depth)
        l->key = INFINITY;   /* a shadow's edge crosses it: the rules may agree by chance */
    if (depth >= BN__MAX_DEPTH)
        l->key = -1;   /* cannot be refined further */
}

/* Leaves kept at most: bounds the work of one pair (about 7 * 4 * BN__MAX_LEAVES / 3 kernel
 * evaluations per leaf) whatever the tolerance asks. */
#define BN__MAX_LEAVES 20000

/* tri[0 .. 9 *ntri) cut `split` times into four by its edges' midpoints (the corner triangles and the
 * middle one), while the 64 triangles' room lasts. */
static void bn__split4(double *tri, size_t *ntri, size_t split)
{
    static const int kid[4][3] = {{0, 3, 5}, {3, 1, 4}, {5, 4, 2}, {3, 4, 5}};
    for (size_t lev = 0; lev < split && 4 * *ntri <= 64; lev++) {
        for (size_t k = *ntri; k-- > 0;) {
            double p[6][3];
            memcpy(p, tri + 9 * k, 9 * sizeof(double));
            for (int e = 0; e < 3; e++)
                for (int c = 0; c < 3; c++)
                    p[3 + e][c] = 0.5 * (p[e][c] + p[(e + 1) % 3][c]);
            for (int d = 0; d < 4; d++)
                for (int v = 0; v < 3; v++)
                    memcpy(tri + 9 * (4 * k + (size_t)d) + 3 * v, p[kid[d][v]], 3 * sizeof(double));
        }
        *ntri *= 4;
    }
}

/* The worst leaf bisected along its longest edge (v[e], v[e+1]): thin triangles become rounder,
 * where a four-way split would keep their shape. The running sum and error follow; 0 when out of
 * memory. */
static int bn__bisect_worst(bn__qctx *q, bn__heap *h, double *sum, double *err)
{
    bn__leaf l = bn__heap_pop(h), kids[2];
    double mid[3], l0 = bn_v3_dist(l.v[0], l.v[1]), l1 = bn_v3_dist(l.v[1], l.v[2]), l2 = bn_v3_dist(l.v[2], l.v[0]);
    int e = l0 >= l1 && l0 >= l2 ? 0 : (l1 >= l2 ? 1 : 2);
    const double *a = l.v[e], *b = l.v[(e + 1) % 3], *c = l.v[(e + 2) % 3];
    for (int k = 0; k < 3; k++)
        mid[k] = 0.5 * (a[k] + b[k]);
    bn__leaf_make(q, &kids[0], a, mid, c, l.area / 2, l.depth + 1);
    bn__leaf_make(q, &kids[1], mid, b, c, l.area / 2, l.depth + 1);
    *sum -= l.q5;
    *err -= l.err;
    for (int k = 0; k < 2; k++) {
        *sum += kids[k].q5;
        *err += kids[k].err;
        if (!bn__heap_push(h, &kids[k]))
            return 0;
    }
    return 1;
}

static double bn__integral(bn__qctx q, const double *pi, size_t ni, const double ni_n[3], const double *pj, size_t nj,
                           double rtol, double atol, bn__quad_stats *st)
{
    bn__quad_stats local;
    bn__heap h;
    double sum = 0, err = 0;
    if (ni < 3 || nj < 3)
        return 0;
    if (!st)
        st = &local;
    memset(st, 0, sizeof *st);
    q.pj = pj;
    q.nj = nj;
    bn__poly_area(pj, nj, q.nj_n);
    memcpy(q.ni_n, ni_n, sizeof q.ni_n);
    q.st = st;
    h.a = h.inline_;
    h.n = 0;
    h.cap = sizeof h.inline_ / sizeof h.inline_[0];
    for (size_t t = 0; t + 2 < ni; t++) {
        /* each fan triangle, cut into 4^split by its midpoints first */
        double tri[3 * 3 * 64];
        size_t ntri = 1;
        double area = bn__tri_area(pi, pi + 3 * (t + 1), pi + 3 * (t + 2));
        if (!(area > 0))
            continue;
        memcpy(tri, pi, 3 * sizeof(double));
        memcpy(tri + 3, pi + 3 * (t + 1), 3 * sizeof(double));
        memcpy(tri + 6, pi + 3 * (t + 2), 3 * sizeof(double));
        bn__split4(tri, &ntri, (size_t)q.split);
        for (size_t k = 0; k < ntri; k++) {
            bn__leaf l;
            bn__leaf_make(&q, &l, tri + 9 * k, tri + 9 * k + 3, tri + 9 * k + 6, area / (double)ntri, q.split);
            sum += l.q5;
            err += l.err;
            if (!bn__heap_push(&h, &l)) {
                sum = NAN;
                goto done;
            }
        }
    }
    /* Global adaptivity: split the worst triangle until the summed estimate meets the tolerance
     * (relative to the running integral, with an absolute floor) and every triangle is small
     * against its distance to P_j. */
    while (h.n > 0 && h.n < BN__MAX_LEAVES) {
        double tol = fmax(fmax(rtol * fabs(sum), atol), 64 * DBL_EPSILON * fabs(sum));
        if (h.a[0].key < 0 || (h.a[0].key != INFINITY && err <= tol))
            break;
        if (!bn__bisect_worst(&q, &h, &sum, &err)) {
            sum = NAN;
            goto done;
        }
    }
    /* The running sums drift by rounding: add the leaves afresh. */
    sum = 0;
    for (size_t k = 0; k < h.n; k++) {
        sum += h.a[k].q5;
        if (h.a[k].depth > st->max_depth)
            st->max_depth = h.a[k].depth;
    }
    st->triangles = h.n;
    st->capped = h.n >= BN__MAX_LEAVES;
done:
    if (h.a != h.inline_)
        free(h.a);
    return sum;
}

double bn__ff_polygon_integral(const double *pi, size_t ni, const double ni_n[3], const double *pj, size_t nj,
                               double rtol, double atol, bn__quad_stats *st)
{
    bn__qctx q;
    memset(&q, 0, sizeof q);
    return bn__integral(q, pi, ni, ni_n, pj, nj, rtol, atol, st);
}

/* The blocked part's integrand is continuous but has creases where a shadow's edge crosses the
 * patch, which the two rules can miss together when none of their points falls beyond one: the
 * caller starts each fan triangle as 4^split (formfactor.c), and a triangle whose points disagree
 * about whether an occluder is in view is split down to depth BN__VIS_MIXED_DEPTH whatever its
 * error estimate. */
#define BN__VIS_MIXED_DEPTH 4

double bn__ff_blocked_integral(const double *pi, size_t ni, const double ni_n[3], const double *pj, size_t nj,
                               const double *occ, const unsigned *occ_n, const double *cull, size_t nocc, double gtol,
                               int split, double rtol, double atol, bn__quad_stats *st)
{
    bn__qctx q;
    memset(&q, 0, sizeof q);
    q.occ = occ;
    q.occ_n = occ_n;
    q.cull = cull;
    q.nocc = nocc;
    q.gtol = gtol;
    q.split = split;
    q.mixed_depth = BN__VIS_MIXED_DEPTH;
    return bn__integral(q, pi, ni, ni_n, pj, nj, rtol, atol, st);
}

void bn__poly_sample(const double *v, size_t nv, double u, double w, double out[3])
{
    double areas[BN__FF_POLY_MAX], total = 0, acc = 0, s, b0, b1, b2;
    size_t ntri = nv - 2, t = 0;
    if (ntri > BN__FF_POLY_MAX)
        ntri = BN__FF_POLY_MAX;
    if (ntri > 1) {   /* a fan triangle chosen by area (a triangle has nothing to choose) */
        for (t = 0; t < ntri; t++) {
            areas[t] = bn__tri_area(v, v + 3 * (t + 1), v + 3 * (t + 2));
            total += areas[t];
        }
        u *= total;
        for (t = 0; t + 1 < ntri; t++) {
            if (u < acc + areas[t])
                break;
            acc += areas[t];
        }
        u = areas[t] > 0 ? bn_clamp((u - acc) / areas[t], 0, 1) : 0.5;
    }
    /* Square to triangle (Shirley): b0 = 1 - sqrt(u), b1 = sqrt(u)(1 - w), b2 = sqrt(u) w. */
    s = sqrt(u);
    b0 = 1 - s;
    b1 = s * (1 - w);
    b2 = s * w;
    for (int k = 0; k < 3; k++)
        out[k] = b0 * v[k] + b1 * v[3 * (t + 1) + k] + b2 * v[3 * (t + 2) + k];
}

/* ---- directions uniform in a polygon's solid angle (Arvo 1995) ---- */

/* Solid angle of the spherical triangle of unit vectors a, b, c (Van Oosterom & Strackee 1983):
 *   tan(Omega / 2) = |a . (b x c)| / (1 + a.b + b.c + c.a). */
static double bn__sph_tri_area(const double a[3], const double b[3], const double c[3])
{
    double bc[3];
    bn_v3_cross(b, c, bc);
    return 2 * atan2(fabs(bn_v3_dot(a, bc)), 1 + bn_v3_dot(a, b) + bn_v3_dot(b, c) + bn_v3_dot(c, a));
}

/* Angle between unit vectors, accurate for small and near-pi angles (no acos). */
static double bn__angle_between(const double a[3], const double b[3])
{
    double d[3];
    if (bn_v3_dot(a, b) < 0) {
        bn_v3_add(a, b, d);
        return BN_PI - 2 * asin(fmin(1, bn_v3_len(d) / 2));
    }
    bn_v3_sub(b, a, d);
    return 2 * asin(fmin(1, bn_v3_len(d) / 2));
}

int bn__sph_poly_init(bn__sph_poly *sp, const double x[3], const double n[3], const double *v, size_t nv)
{
    double cmax = 0, sum[3] = {0, 0, 0};
    int pos = 0, neg = 0;
    if (nv < 3 || nv > BN__FF_POLY_MAX)
        return 0;
    sp->nv = nv;
    for (size_t k = 0; k < nv; k++) {
        double *d = sp->v + 3 * k;
        bn_v3_sub(v + 3 * k, x, d);
        if (!(bn_v3_normalize(d) > 0))
            return 0;
        cmax = fmax(cmax, bn_v3_dot(n, d));
        bn_v3_add(sum, d, sum);
    }
    sp->total = 0;
    for (size_t t = 0; t + 2 < nv; t++) {
        sp->omega[t] = bn__sph_tri_area(sp->v, sp->v + 3 * (t + 1), sp->v + 3 * (t + 2));
        sp->total += sp->omega[t];
    }
    if (!(sp->total > 0))
        return 0;
    /* max of n . w over the spherical polygon: 1 if n lies inside it, else on a vertex or at the
     * point of an edge's great-circle arc nearest to n */
    for (size_t k = 0; k < nv; k++) {
        const double *a = sp->v + 3 * k, *b = sp->v + 3 * (k + 1 < nv ? k + 1 : 0);
        double m[3], q[3], aq[3], qb[3], s;
        bn_v3_cross(a, b, m);
        s = bn_v3_dot(m, n);
        pos += s > 0;
        neg += s < 0;
        if (!(bn_v3_normalize(m) > 0))
            continue;
        bn_v3_madd(n, -bn_v3_dot(n, m), m, q);
        if (!(bn_v3_normalize(q) > 0))
            continue;
        bn_v3_cross(a, q, aq);
        bn_v3_cross(q, b, qb);
        if (bn_v3_dot(aq, m) >= 0 && bn_v3_dot(qb, m) >= 0)
            cmax = fmax(cmax, bn_v3_dot(n, q));
    }
    if ((pos == 0 || neg == 0) && bn_v3_dot(n, sum) > 0)
        cmax = 1;
    /* a relative margin for rounding: a bound slightly high only lowers the acceptance rate */
    sp->cmax = fmin(1, cmax * (1 + 1e-9) + 1e-12);
    return 1;
}

void bn__sph_poly_sample(const bn__sph_poly *sp, double u, double w, double dir[3])
{
    const double *a, *b, *c;
    double nab[3], nbc[3], nca[3], t[3], cp[3], alpha, beta, gamma, ap, sphi, cphi, ca, sa, k1, k2, cosb, sinb, ct,
        st;
    size_t ntri = sp->nv - 2, k = 0;
    double acc = 0;
    u *= sp->total;
    for (; k + 1 < ntri; k++) {
        if (u < acc + sp->omega[k])
            break;
        acc += sp->omega[k];
    }
    u = sp->omega[k] > 0 ? bn_clamp((u - acc) / sp->omega[k], 0, 1) : 0.5;
    a = sp->v;
    b = sp->v + 3 * (k + 1);
    c = sp->v + 3 * (k + 2);
    /* Arvo's inversion, in the form of pbrt-v4's SampleSphericalTriangle: the sub-triangle
     * (a, b, c') with area u * Omega, then a point on the arc b -> c' with the right density. */
    bn_v3_cross(a, b, nab);
    bn_v3_cross(b, c, nbc);
    bn_v3_cross(c, a, nca);
    if (!(bn_v3_normalize(nab) > 0) || !(bn_v3_normalize(nbc) > 0) || !(bn_v3_normalize(nca) > 0)) {
        memcpy(dir, a, 3 * sizeof(double));
        return;
    }
    bn_v3_scale(nca, -1, t);
    alpha = bn__angle_between(nab, t);
    bn_v3_scale(nab, -1, t);
    beta = bn__angle_between(nbc, t);
    bn_v3_scale(nbc, -1, t);
    gamma = bn__angle_between(nca, t);
    ap = BN_PI + u * (alpha + beta + gamma - BN_PI);   /* A' + pi */
    ca = cos(alpha);
    sa = sin(alpha);
    sphi = sin(ap) * ca - cos(ap) * sa;
    cphi = cos(ap) * ca + sin(ap) * sa;
    k1 = cphi + ca;
    k2 = sphi - sa * bn_v3_dot(a, b);
    cosb = (k2 + (k2 * cphi - k1 * sphi) * ca) / ((k2 * sphi + k1 * cphi) * sa);
    cosb = bn_clamp(cosb, -1, 1);
    sinb = sqrt(fmax(0, 1 - cosb * cosb));
    bn_v3_madd(c, -bn_v3_dot(c, a), a, t);   /* c - (c.a) a */
    bn_v3_normalize(t);
    for (int d = 0; d < 3; d++)
        cp[d] = cosb * a[d] + sinb * t[d];
    ct = 1 - w * (1 - bn_v3_dot(cp, b));
    st = sqrt(fmax(0, 1 - ct * ct));
    bn_v3_madd(cp, -bn_v3_dot(cp, b), b, t);   /* c' - (c'.b) b */
    bn_v3_normalize(t);
    for (int d = 0; d < 3; d++)
        dir[d] = ct * b[d] + st * t[d];
    bn_v3_normalize(dir);
}

/* ---- the double contour integral (Stokes on both polygons) ----
 *   A_i F_ij = (1/2pi) sum_p sum_q (u_p . v_q) int_0^Lp int_0^Lq ln |x_p(s) - y_q(t)| dt ds
 * over the edges p of P_i and q of P_j (unit directions u_p, v_q; the sign is fixed against
 * Lambert's kernel in the tests). The inner integral along a straight edge is closed-form:
 * with tau the projection of x on q's line and h = |(x - b_q) x v_q| its distance,
 *   int_0^L ln sqrt((t - tau)^2 + h^2) dt = G(L - tau) - G(-tau),
 *   G(z) = z ln sqrt(z^2 + h^2) - z + h atan(z / h)      (h = 0: z ln|z| - z).
 * ln r may be measured against any length c (ln(r / c)): the constant's terms sum to
 * ln c (sum_p L_p u_p) . (sum_q L_q v_q) = 0 over closed contours, so c = the pair's distance
 * keeps the terms near the size of the result at large separations. The outer integral is smooth
 * but where s passes near an edge of P_j (a log-type layer as thin as the gap): global adaptive
 * Gauss-Kronrod (7-15) over all of P_i's edges, splitting the panel of largest error, until the
 * summed error estimate is below rtol |result|. */



typedef struct {
    const double *pj;
    size_t nj;
    double lnc;
    double v[BN__FF_POLY_MAX][3], L[BN__FF_POLY_MAX];
    double Lc[BN__FF_POLY_MAX];   /* L_q (1 + lnc): the -z terms of G and the length constant */
} bn__cctx;

/* sum_q (u . v_q) int_q ln(r / c) dt at the point x; *mag: the sum of the terms' sizes, which
 * bounds the rounding of f (the terms cancel: for nearly coplanar pairs f is 1e-9 of them) */
static double bn__contour_inner(const bn__cctx *cc, const double x[3], const double u[3], double *mag)
{
    double f = 0, m = 0;
    for (size_t q = 0; q < cc->nj; q++) {
        double dot = bn_v3_dot(u, cc->v[q]), w[3], cr[3], tau, h, g1, g0, gc;
        if (dot == 0 || !(cc->L[q] > 0))
            continue;
        bn_v3_sub(x, cc->pj + 3 * q, w);
        tau = bn_v3_dot(w, cc->v[q]);
        bn_v3_cross(w, cc->v[q], cr);
        h = bn_v3_len(cr);
        /* G(L - tau) - G(-tau), the two atan(z / h) as one angle: atan(a) + atan(b) =
         * atan2(a + b, 1 - ab) for a, b of either sign (the sum stays inside (-pi, pi)) */
        {
            double z1 = cc->L[q] - tau, z0 = -tau, r1 = z1 * z1 + h * h, r0 = z0 * z0 + h * h;
            g1 = r1 > 0 ? z1 * 0.5 * log(r1) : 0;
            g0 = r0 > 0 ? z0 * 0.5 * log(r0) : 0;
            gc = cc->Lc[q] - (h > 0 ? h * atan2(h * cc->L[q], h * h - z1 * tau) : 0);
        }
        f += dot * (g1 - g0 - gc);
        m += fabs(dot) * (fabs(g1) + fabs(g0) + fabs(gc));
    }
    *mag = m;
    return f;
}

typedef struct {
    size_t p;
    double s0, s1, val, err, mag;   /* mag: the integral of f's term sizes, for the rounding floor */
} bn__panel;

static const double bn__gk_x[8] = {0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
                                   0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
                                   0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
                                   0.207784955007898467600689403773245, 0.0};
static const double bn__gk_wk[8] = {0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
                                    0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
                                    0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
                                    0.204432940075298892414161999234649, 0.209482141084727828012999174891714};
static const double bn__gk_wg[4] = {0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
                                    0.381830050505118944950369775488975, 0.417959183673469387755102040816327};

static void bn__panel_eval(const bn__cctx *cc, const double *pi, size_t ni, bn__panel *pn, size_t *evals)
{
    const double *a = pi + 3 * pn->p, *b = pi + 3 * ((pn->p + 1) % ni);
    double u[3], half = 0.5 * (pn->s1 - pn->s0), mid = 0.5 * (pn->s0 + pn->s1), k = 0, g = 0, m = 0;
    bn_v3_sub(b, a, u);
    bn_v3_normalize(u);
    for (int i = 0; i < 15; i++) {
        int j = i < 8 ? i : 14 - i;
        double t = i < 8 ? -bn__gk_x[i] : bn__gk_x[14 - i], x[3], f, fm;
        bn_v3_madd(a, mid + half * t, u, x);
        f = bn__contour_inner(cc, x, u, &fm);
        k += bn__gk_wk[j] * f;
        m += bn__gk_wk[j] * fm;
        if (j % 2 == 1)
            g += bn__gk_wg[j / 2] * f;
    }
    *evals += 15;
    pn->val = half * k;
    pn->err = fabs(half * (k - g));
    pn->mag = half * m;
}

/* The contour integral's context: pj's unit edges and lengths, and the log of the pair's scale (the
 * larger of the centroids' distance and either polygon's radius) that keeps its terms well scaled. */
static void bn__contour_ctx(bn__cctx *cc, const double *pi, size_t ni, const double *pj, size_t nj)
{
    double ci[3] = {0, 0, 0}, cj[3] = {0, 0, 0}, di = 0, dj = 0;
    cc->pj = pj;
    cc->nj = nj;
    for (size_t q = 0; q < nj; q++) {
        bn_v3_sub(pj + 3 * ((q + 1) % nj), pj + 3 * q, cc->v[q]);
        cc->L[q] = bn_v3_normalize(cc->v[q]);
        bn_v3_madd(cj, 1.0 / nj, pj + 3 * q, cj);
    }
    for (size_t p = 0; p < ni; p++)
        bn_v3_madd(ci, 1.0 / ni, pi + 3 * p, ci);
    for (size_t p = 0; p < ni; p++)
        di = fmax(di, bn_v3_dist(pi + 3 * p, ci));
    for (size_t q = 0; q < nj; q++)
        dj = fmax(dj, bn_v3_dist(pj + 3 * q, cj));
    cc->lnc = log(fmax(bn_v3_dist(ci, cj), fmax(di, dj)));
    for (size_t q = 0; q < nj; q++)
        cc->Lc[q] = cc->L[q] * (1 + cc->lnc);
}

/* The panels of the contour integral, grown as they are halved (inline storage first). */
typedef struct bn__panels {
    bn__panel inl[64], *pan;
    size_t np, cap, evals;
    double sum, err, mag;   /* running sums of the panels' values, error estimates and magnitudes */
} bn__panels;

/* The panel with the largest error halved; 0 when out of memory for one more. */
static int bn__panel_halve(const bn__cctx *cc, const double *pi, size_t ni, bn__panels *P)
{
    size_t w = 0;
    bn__panel a, b;
    for (size_t k = 1; k < P->np; k++)
        if (P->pan[k].err > P->pan[w].err)
            w = k;
    if (P->np + 1 > P->cap) {
        bn__panel *nw = bn__grow_inline(P->pan, P->inl, P->np, 2 * P->cap, sizeof *nw);
        if (!nw)
            return 0;
        P->pan = nw;
        P->cap *= 2;
    }
    a = P->pan[w];
    b = P->pan[w];
    a.s1 = b.s0 = 0.5 * (P->pan[w].s0 + P->pan[w].s1);
    bn__panel_eval(cc, pi, ni, &a, &P->evals);
    bn__panel_eval(cc, pi, ni, &b, &P->evals);
    P->sum += a.val + b.val - P->pan[w].val;
    P->err += a.err + b.err - P->pan[w].err;
    P->mag += a.mag + b.mag - P->pan[w].mag;
    P->pan[w] = a;
    P->pan[P->np++] = b;
    return 1;
}

double bn__ff_contour(const double *pi, size_t ni, const double *pj, size_t nj, double rtol, double atol,
                      bn__quad_stats *st)
{
    bn__cctx cc;
    bn__panels P;
    double sum = 0, err = 0, mag = 0;
    if (ni < 3 || nj < 3 || ni > BN__FF_POLY_MAX || nj > BN__FF_POLY_MAX)
        return 0;
    bn__contour_ctx(&cc, pi, ni, pj, nj);
    P.pan = P.inl;
    P.np = P.evals = 0;
    P.cap = 64;
    P.sum = P.err = P.mag = 0;
    for (size_t p = 0; p < ni; p++) {   /* a panel per edge of pi */
        double L = bn_v3_dist(pi + 3 * p, pi + 3 * ((p + 1) % ni));
        bn__panel *pn = &P.pan[P.np];
        if (!(L > 0))
            continue;
        pn->p = p;
        pn->s0 = 0;
        pn->s1 = L;
        bn__panel_eval(&cc, pi, ni, pn, &P.evals);
        P.sum += pn->val;
        P.err += pn->err;
        P.mag += pn->mag;
        P.np++;
    }
    /* to the tolerance, or the absolute floor (atol, on A_i F_ij), or the rounding floor: terms of
     * total size mag cancel to the result */
    for (int it = 0; it < 4000; it++)
        if (P.err <= fmax(fmax(rtol * fabs(P.sum), 2 * BN_PI * atol), DBL_EPSILON * P.mag) ||
            !bn__panel_halve(&cc, pi, ni, &P))
            break;
    /* the running sums drift by rounding: add the panels afresh */
    for (size_t k = 0; k < P.np; k++) {
        sum += P.pan[k].val;
        err += P.pan[k].err;
        mag += P.pan[k].mag;
    }
    /* the integrand is >= 0: a result below zero by no more than its error and rounding (terms of
     * size mag cancelling to nothing, as between polygons that see each other edge-on) is 0 */
    if (sum < 0 && -sum <= err + 64 * DBL_EPSILON * mag + 2 * BN_PI * atol)
        sum = 0;
    if (st) {
        memset(st, 0, sizeof *st);
        st->evals = P.evals;
        st->triangles = P.np;
        st->capped = err > fmax(rtol * fabs(sum), 2 * BN_PI * atol);   /* the rounding floor or the panel limit */
    }
    if (P.pan != P.inl)
        free(P.pan);
    return sum / (2 * BN_PI);
}

int bn__ff_near(const double *pi, size_t ni, const double *pj, size_t nj)
{
    double ca[3] = {0, 0, 0}, cb[3] = {0, 0, 0}, da = 0, db = 0;
    for (size_t m = 0; m < ni; m++)
        bn_v3_madd(ca, 1.0 / ni, pi + 3 * m, ca);
    for (size_t m = 0; m < nj; m++)
        bn_v3_madd(cb, 1.0 / nj, pj + 3 * m, cb);
    for (size_t m = 0; m < ni; m++)
        da = fmax(da, 2 * bn_v3_dist(ca, pi + 3 * m));
    for (size_t m = 0; m < nj; m++)
        db = fmax(db, 2 * bn_v3_dist(cb, pj + 3 * m));
    return bn_v3_dist(ca, cb) < fmax(da, db);
}

/* Corners of the k-th fan piece of a convex polygon of nv corners: v0 and up to
 * BN__FF_POLY_MAX - 1 consecutive corners after it, each piece sharing an edge with the next. */
static size_t bn__fan_piece(const double *v, size_t nv, size_t k, double *out)
{
    size_t step = BN__FF_POLY_MAX - 2, s = 1 + k * step, m = 1;
    memcpy(out, v, 3 * sizeof(double));
    for (size_t c = s; c < nv && m < BN__FF_POLY_MAX; c++, m++)
        memcpy(out + 3 * m, v + 3 * c, 3 * sizeof(double));
    return m;
}

double bn__ff_unoccluded(const double *pi, size_t ni, const double ni_n[3], const double *pj, size_t nj, double rtol,
                         double atol, bn__quad_stats *st)
{
    double a[3 * BN__FF_POLY_MAX], b[3 * BN__FF_POLY_MAX], sum = 0;
    size_t pa, pb;
    (void)ni_n;
    if (ni < 3 || nj < 3)
        return 0;
    if (ni <= BN__FF_POLY_MAX && nj <= BN__FF_POLY_MAX)
        return bn__ff_contour(pi, ni, pj, nj, rtol, atol, st);
    /* larger convex polygons: the sum over fan pieces of both (the integral is additive; every
     * piece's value is >= 0, so each piece to rtol keeps the sum to rtol) */
    pa = (ni - 2 + BN__FF_POLY_MAX - 3) / (BN__FF_POLY_MAX - 2);
    pb = (nj - 2 + BN__FF_POLY_MAX - 3) / (BN__FF_POLY_MAX - 2);
    if (st)
        memset(st, 0, sizeof *st);
    for (size_t x = 0; x < pa; x++) {
        size_t na = bn__fan_piece(pi, ni, x, a);
        for (size_t y = 0; y < pb; y++) {
            size_t nb = bn__fan_piece(pj, nj, y, b);
            bn__quad_stats q;
            sum += bn__ff_contour(a, na, b, nb, rtol, atol / (double)(pa * pb), &q);
            if (st) {
                st->evals += q.evals;
                st->triangles += q.triangles;
                st->capped |= q.capped;
            }
        }
    }
    return sum;
}
