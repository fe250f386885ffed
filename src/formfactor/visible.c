/* F from a point to the part of a convex polygon it sees past occluding polygons, exactly: the
 * occluders are clipped to the pyramid from the point to the polygon, projected from the point
 * onto the polygon's plane, and Lambert's contour integral is summed over the boundary of what is
 * left (the polygon minus the union of the projections), found edge piece by edge piece without
 * building that region. The method of Nishita & Nakamae, "Half-tone representation of 3-D objects
 * illuminated by area sources or polyhedron sources" (1983), and Baum, Rushmeier & Winget,
 * "Improving radiosity solutions through the use of analytically determined form-factors"
 * (SIGGRAPH 1989). */
#include "formfactor/ff_internal.h"
#include "base/vec.h"

#include <math.h>
#include <string.h>

/* An occluder quad clipped by the pyramid's sides (at most BN__FF_POLY_MAX) and three more planes. */
#define BN__VIS_CORNERS (4 + BN__FF_POLY_MAX + 4)

typedef struct bn__poly2 {
    double p[2 * BN__VIS_CORNERS];   /* counter-clockwise in the frame of b's plane */
    size_t n;
    /* per edge k (p_k -> p_k+1): direction, length, unit left normal (inward); bounding box */
    double d[2 * BN__VIS_CORNERS], len[BN__VIS_CORNERS], nl[2 * BN__VIS_CORNERS];
    double lo[2], hi[2];
} bn__poly2;

static double bn__cross2(const double a[2], const double b[2]) { return a[0] * b[1] - a[1] * b[0]; }

static double bn__area2(const double *p, size_t n)
{
    double s = 0;
    for (size_t k = 0; k < n; k++) {
        size_t k1 = k + 1 < n ? k + 1 : 0;
        s += p[2 * k] * p[2 * k1 + 1] - p[2 * k1] * p[2 * k + 1];
    }
    return 0.5 * s;
}

static void bn__poly2_edges(bn__poly2 *q)
{
    q->lo[0] = q->lo[1] = INFINITY;
    q->hi[0] = q->hi[1] = -INFINITY;
    for (size_t k = 0; k < q->n; k++) {
        const double *c0 = q->p + 2 * k, *c1 = q->p + 2 * (k + 1 < q->n ? k + 1 : 0);
        double *d = q->d + 2 * k, len;
        d[0] = c1[0] - c0[0];
        d[1] = c1[1] - c0[1];
        len = sqrt(d[0] * d[0] + d[1] * d[1]);
        q->len[k] = len;
        q->nl[2 * k] = len > 0 ? -d[1] / len : 0;
        q->nl[2 * k + 1] = len > 0 ? d[0] / len : 0;
        for (int c = 0; c < 2; c++) {
            q->lo[c] = c0[c] < q->lo[c] ? c0[c] : q->lo[c];
            q->hi[c] = c0[c] > q->hi[c] ? c0[c] : q->hi[c];
        }
    }
}

/* Is the point m moved by an infinitesimal step along dir inside the convex polygon q? On an
 * edge's line (within tol) the step decides. */
static int bn__inside_moved(const bn__poly2 *q, const double m[2], const double dir[2], double tol)
{
    if (m[0] < q->lo[0] - tol || m[0] > q->hi[0] + tol || m[1] < q->lo[1] - tol || m[1] > q->hi[1] + tol)
        return 0;
    for (size_t k = 0; k < q->n; k++) {
        const double *c0 = q->p + 2 * k, *nl = q->nl + 2 * k;
        double d;
        if (!(q->len[k] > 0))
            continue;
        d = nl[0] * (m[0] - c0[0]) + nl[1] * (m[1] - c0[1]);   /* > 0: left of the edge, inside */
        if (d < -tol)
            return 0;
        if (d <= tol && nl[0] * dir[0] + nl[1] * dir[1] < 0)
            return 0;   /* on the edge's line, stepping out */
    }
    return 1;
}

/* Is the point m inside the convex polygon q or within tol of it? */
static int bn__inside_tol(const bn__poly2 *q, const double m[2], double tol)
{
    for (size_t k = 0; k < q->n; k++) {
        const double *c0 = q->p + 2 * k, *nl = q->nl + 2 * k;
        if (q->len[k] > 0 && nl[0] * (m[0] - c0[0]) + nl[1] * (m[1] - c0[1]) < -tol)
            return 0;
    }
    return 1;
}

/* Does the piece (pa, pb) with midpoint m lie along an edge of polygon q? The same test as
 * bn__inside_moved's "on the edge's line": m within tol of the edge's line (and within the
 * edge), so that a piece the inside tests treat as on q's boundary is q's to count, whichever
 * way rounding has tilted it; and both ends within 2 tol of the line (along it, not across). */
static int bn__collinear_edge(const bn__poly2 *q, const double pa[2], const double pb[2], const double m[2],
                              double tol)
{
    if (m[0] < q->lo[0] - tol || m[0] > q->hi[0] + tol || m[1] < q->lo[1] - tol || m[1] > q->hi[1] + tol)
        return 0;
    for (size_t k = 0; k < q->n; k++) {
        const double *c0 = q->p + 2 * k, *f = q->d + 2 * k, *nl = q->nl + 2 * k;
        double len = q->len[k], t;
        if (!(len > tol) || fabs(nl[0] * (m[0] - c0[0]) + nl[1] * (m[1] - c0[1])) > tol ||
            fabs(nl[0] * (pa[0] - c0[0]) + nl[1] * (pa[1] - c0[1])) > 2 * tol ||
            fabs(nl[0] * (pb[0] - c0[0]) + nl[1] * (pb[1] - c0[1])) > 2 * tol)
            continue;
        t = ((m[0] - c0[0]) * f[0] + (m[1] - c0[1]) * f[1]) / (len * len);
        if (t >= 0 && t <= 1)
            return 1;
    }
    return 0;
}

typedef struct bn__vis_frame {
    double o[3], e1[3], e2[3];
} bn__vis_frame;

static void bn__lift(const bn__vis_frame *fr, const double p[2], double out[3])
{
    for (int c = 0; c < 3; c++)
        out[c] = fr->o[c] + p[0] * fr->e1[c] + p[1] * fr->e2[c];
}

/* Lambert's term of the edge (a, b) seen from x with normal n (the sum over a region's boundary,
 * counter-clockwise seen from the front, times -1/2pi, is F). */
static double bn__edge_term(const double x[3], const double n[3], const double a[3], const double b[3])
{
    double ra[3], rb[3], c[3], cl;
    bn_v3_sub(a, x, ra);
    bn_v3_sub(b, x, rb);
    bn_v3_cross(ra, rb, c);
    cl = bn_v3_len(c);
    return cl > 0 ? atan2(cl, bn_v3_dot(ra, rb)) * bn_v3_dot(n, c) / cl : 0;
}

static void bn__sort(double *t, size_t n)
{
    for (size_t k = 1; k < n; k++) {
        double v = t[k];
        size_t m = k;
        for (; m > 0 && t[m - 1] > v; m--)
            t[m] = t[m - 1];
        t[m] = v;
    }
}

/* One point's visible-part computation: b and the occluders' projections in b's plane. */
typedef struct bn__vis {
    bn__poly2 poly[1 + BN__VIS_OCC_MAX];   /* poly[0]: b; then the projections kept */
    size_t np;
    bn__vis_frame fr;                      /* b's plane: origin b[0], e1, e2 (counter-clockwise b) */
    double hx;                             /* x's height over b's plane */
    double c[3];                           /* b's vertex mean */
    double pl[BN__FF_POLY_MAX + 3][4];     /* the pyramid's planes (unit normal, offset) */
    size_t npl;
    double diam;                           /* b's diameter */
} bn__vis;

/* b in its plane's frame, counter-clockwise (the frame mirrored if it is not), its vertex mean and
 * diameter; 0 when x is not in front of b. */
static int bn__vis_base(bn__vis *V, const double x[3], const double *b, size_t nb, const double bn[3])
{
    double r[3];
    memcpy(V->fr.o, b, sizeof V->fr.o);
    bn_v3_sub(x, V->fr.o, r);
    V->hx = bn_v3_dot(bn, r);
    if (!(V->hx > 0))
        return 0;
    bn_v3_basis(bn, V->fr.e1, V->fr.e2);
    V->poly[0].n = nb;
    V->c[0] = V->c[1] = V->c[2] = 0;
    for (size_t k = 0; k < nb; k++) {
        bn_v3_sub(b + 3 * k, V->fr.o, r);
        V->poly[0].p[2 * k] = bn_v3_dot(V->fr.e1, r);
        V->poly[0].p[2 * k + 1] = bn_v3_dot(V->fr.e2, r);
        bn_v3_add(V->c, b + 3 * k, V->c);
    }
    if (bn__area2(V->poly[0].p, nb) < 0) {
        bn_v3_scale(V->fr.e2, -1, V->fr.e2);
        for (size_t k = 0; k < nb; k++)
            V->poly[0].p[2 * k + 1] = -V->poly[0].p[2 * k + 1];
    }
    bn_v3_scale(V->c, 1.0 / (double)nb, V->c);
    V->diam = 0;
    for (size_t k = 0; k < nb; k++)
        for (size_t m = k + 1; m < nb; m++) {
            const double *p = V->poly[0].p;
            V->diam = fmax(V->diam, sqrt((p[2 * k] - p[2 * m]) * (p[2 * k] - p[2 * m]) +
                                         (p[2 * k + 1] - p[2 * m + 1]) * (p[2 * k + 1] - p[2 * m + 1])));
        }
    bn__poly2_edges(&V->poly[0]);
    return 1;
}

/* The pyramid from x to b: a side plane through x and each edge, facing in; b's plane, shifted by
 * tol so that faces lying in it do not block; a plane just short of x; x's tangent plane. */
static void bn__vis_pyramid(bn__vis *V, const double x[3], const double n[3], const double *b, size_t nb,
                            const double bn[3], double tol)
{
    V->npl = 0;
    for (size_t k = 0; k < nb; k++) {
        double ra[3], rb[3], nn[3], rc[3], len;
        bn_v3_sub(b + 3 * k, x, ra);
        bn_v3_sub(b + 3 * (k + 1 < nb ? k + 1 : 0), x, rb);
        bn_v3_cross(ra, rb, nn);
        len = bn_v3_len(nn);
        if (!(len > 0))
            continue;
        bn_v3_sub(V->c, x, rc);
        bn_v3_scale(nn, (bn_v3_dot(nn, rc) < 0 ? -1 : 1) / len, nn);
        memcpy(V->pl[V->npl], nn, sizeof nn);
        V->pl[V->npl++][3] = bn_v3_dot(nn, x);
    }
    memcpy(V->pl[V->npl], bn, 3 * sizeof(double));
    V->pl[V->npl++][3] = bn_v3_dot(bn, V->fr.o) + tol;
    V->pl[V->npl][0] = -bn[0];
    V->pl[V->npl][1] = -bn[1];
    V->pl[V->npl][2] = -bn[2];
    V->pl[V->npl++][3] = -bn_v3_dot(bn, x) + 1e-9 * V->hx;
    /* Nothing behind x's own plane can block. Exactly at the plane, not tol in front: where b
     * touches that plane (a wall seen grazing from a block's top) the side plane through x and
     * that edge is x's plane itself, and an offset would leave every occluder's cut edge a few
     * tol from b's edge once projected, where the inside and collinear tests can disagree. */
    memcpy(V->pl[V->npl], n, 3 * sizeof(double));
    V->pl[V->npl++][3] = bn_v3_dot(n, x);
}

/* Occluder o (m corners) clipped to the pyramid and projected from x onto b's plane as
 * poly[V->np]: 1 kept, 0 nothing of it in view (or beside b), -1 it covers b wholly. */
static int bn__vis_occluder(bn__vis *V, const double x[3], const double bn[3], const double *o, size_t m, double tol)
{
    double buf[2][3 * BN__VIS_CORNERS], r[3], area;
    size_t cur = 0, nb = V->poly[0].n;
    bn__poly2 *P = &V->poly[V->np];
    memcpy(buf[0], o, 3 * m * sizeof(double));
    for (size_t k = 0; k < V->npl && m; k++) {
        double p[3];
        bn_v3_scale(V->pl[k], V->pl[k][3], p);   /* a point of the plane (unit normal) */
        m = m + 1 < BN__VIS_CORNERS ? bn__poly_clip(buf[cur], m, V->pl[k], p, tol, buf[1 - cur]) : 0;
        cur = 1 - cur;
    }
    if (!m)
        return 0;
    for (size_t k = 0; k < m; k++) {
        double *y = buf[cur] + 3 * k, d[3], t, pp[3];
        bn_v3_sub(y, x, d);
        t = V->hx / -bn_v3_dot(bn, d);   /* y is between the planes: -bn.d in (0, hx) */
        bn_v3_madd(x, t, d, pp);
        bn_v3_sub(pp, V->fr.o, r);
        P->p[2 * k] = bn_v3_dot(V->fr.e1, r);
        P->p[2 * k + 1] = bn_v3_dot(V->fr.e2, r);
    }
    P->n = m;
    area = bn__area2(P->p, m);
    if (!(fabs(area) > 1e-14 * V->diam * V->diam))
        return 0;
    if (area < 0)
        for (size_t k = 0; k < m / 2; k++)
            for (int cc = 0; cc < 2; cc++) {
                double t = P->p[2 * k + cc];
                P->p[2 * k + cc] = P->p[2 * (m - 1 - k) + cc];
                P->p[2 * (m - 1 - k) + cc] = t;
            }
    bn__poly2_edges(P);
    if (P->lo[0] > V->poly[0].hi[0] - tol || P->hi[0] < V->poly[0].lo[0] + tol || P->lo[1] > V->poly[0].hi[1] - tol ||
        P->hi[1] < V->poly[0].lo[1] + tol)
        return 0;   /* beside b (rounding past the pyramid's sides) */
    /* one projection (convex, clipped to b) covers b: nothing of it is seen */
    for (size_t k = 0; k < nb; k++)
        if (!bn__inside_tol(P, V->poly[0].p + 2 * k, tol))
            return 1;
    return -1;
}

/* Where edge k of poly[q] is cut by the other polygons' edges (crossings, collinear edges' ends),
 * as parameters in [0, 1] with both ends, into ts (sorted); their count. */
static size_t bn__vis_cuts(const bn__vis *V, size_t q, size_t k, double tol, double *ts)
{
    const double *p0 = V->poly[q].p + 2 * k, *d = V->poly[q].d + 2 * k;
    double dlen = V->poly[q].len[k], elo[2], ehi[2];
    size_t nt = 0;   /* at most two per edge of every polygon: ts never fills */
    for (int cc = 0; cc < 2; cc++) {   /* not fmin/fmax: a call each here (no NaN to handle) */
        double e0 = p0[cc], e1 = p0[cc] + d[cc];
        elo[cc] = (e0 < e1 ? e0 : e1) - tol;
        ehi[cc] = (e0 < e1 ? e1 : e0) + tol;
    }
    ts[nt++] = 0;
    ts[nt++] = 1;
    for (size_t s = 0; s < V->np; s++) {
        const bn__poly2 *S = &V->poly[s];
        if (s == q || S->lo[0] > ehi[0] || S->hi[0] < elo[0] || S->lo[1] > ehi[1] || S->hi[1] < elo[1])
            continue;
        for (size_t e = 0; e < S->n; e++) {
            const double *c0 = S->p + 2 * e, *f = S->d + 2 * e;
            double w[2], den;
            if ((c0[0] > ehi[0] && c0[0] + f[0] > ehi[0]) || (c0[0] < elo[0] && c0[0] + f[0] < elo[0]) ||
                (c0[1] > ehi[1] && c0[1] + f[1] > ehi[1]) || (c0[1] < elo[1] && c0[1] + f[1] < elo[1]))
                continue;   /* apart */
            w[0] = c0[0] - p0[0];
            w[1] = c0[1] - p0[1];
            den = bn__cross2(d, f);
            if (fabs(den) > 1e-12 * dlen * S->len[e]) {
                /* t = tn / den on this edge, u = un / den on the other: divide only a crossing */
                double sg = den > 0 ? 1 : -1, tn = sg * bn__cross2(w, f), un = sg * bn__cross2(w, d), ad = fabs(den);
                if (tn > 0 && tn < ad && un >= -1e-9 * ad && un <= (1 + 1e-9) * ad)
                    ts[nt++] = tn / ad;
            } else if (fabs(bn__cross2(d, w)) <= tol * dlen) {
                /* collinear: the other edge's ends */
                double t0 = (w[0] * d[0] + w[1] * d[1]) / (dlen * dlen);
                double t1 = ((w[0] + f[0]) * d[0] + (w[1] + f[1]) * d[1]) / (dlen * dlen);
                if (t0 > 0 && t0 < 1)
                    ts[nt++] = t0;
                if (t1 > 0 && t1 < 1)
                    ts[nt++] = t1;
            }
        }
    }
    bn__sort(ts, nt);
    return nt;
}

/* The boundary sum of one point: the visible region's (or, with `blocked`, that of what the occluders
 * hide of b), each piece's Lambert term added to sum in order with the region on its left
 * (counter-clockwise); sees set once a piece bounds the visible region. */
typedef struct bn__vis_sum {
    int blocked, sees;
    double sum;
} bn__vis_sum;

/* The pieces of edge k of poly[q] between its cuts. A piece of b's edge bounds the visible region
 * where no occluder covers its inner side, the hidden one where one does; a piece of an occluder's
 * edge bounds both where its outer side is in b and no other occluder covers it (the visible
 * region on that side, the hidden one on its own). A piece lying on an edge of an earlier polygon
 * is that polygon's to count. */
static void bn__vis_edge(const bn__vis *V, size_t q, size_t k, const double *ts, size_t nt, const double x[3],
                         const double n[3], double tol, bn__vis_sum *out)
{
    const double *p0 = V->poly[q].p + 2 * k, *d = V->poly[q].d + 2 * k, *left = V->poly[q].nl + 2 * k;
    double dlen = V->poly[q].len[k], right[2] = {-left[0], -left[1]};
    for (size_t a = 0; a + 1 < nt; a++) {
        double m[2], A[3], B[3], pa[2], pb[2];
        int dup = 0, in_l, in_r, forward;
        if (!((ts[a + 1] - ts[a]) * dlen > tol))
            continue;
        m[0] = p0[0] + 0.5 * (ts[a] + ts[a + 1]) * d[0];
        m[1] = p0[1] + 0.5 * (ts[a] + ts[a + 1]) * d[1];
        pa[0] = p0[0] + ts[a] * d[0];
        pa[1] = p0[1] + ts[a] * d[1];
        pb[0] = p0[0] + ts[a + 1] * d[0];
        pb[1] = p0[1] + ts[a + 1] * d[1];
        for (size_t s = 0; s < q && !dup; s++)
            dup = bn__collinear_edge(&V->poly[s], pa, pb, m, tol);
        if (dup)
            continue;
        /* b (q = 0) has itself on its left; an occluder has itself on its left and so never the
         * visible region there */
        in_l = q == 0;
        in_r = q != 0 && bn__inside_moved(&V->poly[0], m, right, tol);
        for (size_t s = 1; s < V->np && (in_l || in_r); s++) {
            if (s == q)
                continue;
            if (in_l && bn__inside_moved(&V->poly[s], m, left, tol))
                in_l = 0;
            if (in_r && bn__inside_moved(&V->poly[s], m, right, tol))
                in_r = 0;
        }
        out->sees |= in_l || in_r;
        if (out->blocked ? (q == 0 ? in_l : !in_r) : in_l == in_r)
            continue;
        forward = out->blocked || in_l;   /* the counted region on the piece's left */
        bn__lift(&V->fr, pa, A);
        bn__lift(&V->fr, pb, B);
        out->sum += forward ? bn__edge_term(x, n, A, B) : bn__edge_term(x, n, B, A);
    }
}

/* F from x of polygon p (m corners in b's frame) lifted back to b's plane. */
static double bn__vis_F2(const bn__vis *V, const double x[3], const double n[3], const double *p, size_t m)
{
    double v[3 * 2 * BN__VIS_CORNERS];
    for (size_t k = 0; k < m; k++)
        bn__lift(&V->fr, p + 2 * k, v + 3 * k);
    return bn__ff_point_polygon(x, n, v, m);
}

/* What x sees of b (or, blocked, what is hidden) when the hidden part's F is h. */
static double bn__vis_result(const double x[3], const double n[3], const double *b, size_t nb, int blocked, double h)
{
    return fmax(blocked ? h : bn__ff_point_polygon(x, n, b, nb) - h, 0);
}

/* P (counter-clockwise) clipped to the inner side of every edge of the convex Q: their intersection
 * into out (at most P->n + Q->n corners for a convex P); its corner count (0: none), SIZE_MAX when a
 * clip would overflow (P far from convex: the caller takes the general path). */
static size_t bn__vis_intersect(const bn__poly2 *P, const bn__poly2 *Q, double *out)
{
    double buf[2][2 * 2 * BN__VIS_CORNERS];
    size_t m = P->n, cur = 0;
    memcpy(buf[0], P->p, 2 * m * sizeof(double));
    for (size_t e = 0; e < Q->n && m >= 3; e++) {
        const double *c0 = Q->p + 2 * e, *nl = Q->nl + 2 * e, *in = buf[cur];
        double *o = buf[1 - cur];
        size_t k2 = 0;
        if (!(Q->len[e] > 0))
            continue;
        for (size_t k = 0; k < m; k++) {
            const double *a = in + 2 * k, *b = in + 2 * (k + 1 < m ? k + 1 : 0);
            double da = nl[0] * (a[0] - c0[0]) + nl[1] * (a[1] - c0[1]);
            double db = nl[0] * (b[0] - c0[0]) + nl[1] * (b[1] - c0[1]);
            if (k2 + 2 > 2 * BN__VIS_CORNERS)
                return SIZE_MAX;   /* each corner gives at most two */
            if (da >= 0) {
                o[2 * k2] = a[0];
                o[2 * k2++ + 1] = a[1];
            }
            if ((da > 0 && db < 0) || (da < 0 && db > 0)) {
                double t = da / (da - db);
                o[2 * k2] = a[0] + t * (b[0] - a[0]);
                o[2 * k2++ + 1] = a[1] + t * (b[1] - a[1]);
            }
        }
        m = k2;
        cur = 1 - cur;
    }
    memcpy(out, buf[cur], 2 * m * sizeof(double));
    return m >= 3 ? m : 0;
}

/* Two projections kept (V->np == 3): both lie in b, so what they hide is their union, F(P1) + F(P2) -
 * F(P1 and P2) (the intersection of two convex polygons, by clipping); x sees some of b unless the
 * union's area is b's to 1e-9. -1 when the intersection cannot be had (the general path then). */
static double bn__vis_two(const bn__vis *V, const double x[3], const double n[3], const double *b, size_t nb,
                          int blocked, int *sees)
{
    const bn__poly2 *P1 = &V->poly[1], *P2 = &V->poly[2];
    double I[2 * 2 * BN__VIS_CORNERS], h;
    size_t mi = bn__vis_intersect(P1, P2, I);
    if (mi == SIZE_MAX)
        return -1;
    double ai = mi ? bn__area2(I, mi) : 0;
    double au = bn__area2(P1->p, P1->n) + bn__area2(P2->p, P2->n) - ai, ab = bn__area2(V->poly[0].p, V->poly[0].n);
    h = bn__vis_F2(V, x, n, P1->p, P1->n) + bn__vis_F2(V, x, n, P2->p, P2->n) - (mi ? bn__vis_F2(V, x, n, I, mi) : 0);
    *sees = au < ab * (1 - 1e-9);
    return bn__vis_result(x, n, b, nb, blocked, h);
}

/* bn__ff_point_visible's work: what x sees of b past the occluders, or (blocked) what they hide of
 * it; *sees whether x sees any of b. */
static double bn__point_vis(const double x[3], const double n[3], const double *b, size_t nb, const double bn[3],
                            const double *occ, const unsigned *occ_n, const double *cull, size_t nocc, double tol,
                            uint32_t *shadowed, int blocked, int *sees)
{
    bn__vis V;
    bn__vis_sum S = {blocked, 0, 0};
    *shadowed = 0;
    *sees = 0;
    if (nb < 3 || nb > BN__FF_POLY_MAX || nocc > BN__VIS_OCC_MAX || !bn__vis_base(&V, x, b, nb, bn))
        return 0;
    bn__vis_pyramid(&V, x, n, b, nb, bn, tol);
    V.np = 1;
    /* occluders: clipped to the pyramid, projected from x onto b's plane */
    for (size_t q = 0; q < nocc; q++) {
        int kept;
        if (cull && !isnan(cull[4 * q + 3]) && bn_v3_dot(cull + 4 * q, x) <= cull[4 * q + 3])
            continue;   /* a solid's face seen from behind: its front faces hide all it would */
        kept = bn__vis_occluder(&V, x, bn, occ + 12 * q, occ_n[q], tol);
        if (kept == 0)
            continue;
        *shadowed |= 1u << (q & 31);
        if (kept < 0)
            return blocked ? bn__ff_point_polygon(x, n, b, nb) : 0;
        V.np++;
    }
    if (V.np == 1) {
        *sees = 1;
        return blocked ? 0 : bn__ff_point_polygon(x, n, b, nb);
    }
    if (V.np == 2) {   /* one projection, not covering b (part of b is seen): clipped to the pyramid,
                          it lies in b, so what it hides is that convex polygon itself, no cuts */
        *sees = 1;
        return bn__vis_result(x, n, b, nb, blocked, bn__vis_F2(&V, x, n, V.poly[1].p, V.poly[1].n));
    }
    if (V.np == 3) {
        double f = bn__vis_two(&V, x, n, b, nb, blocked, sees);
        if (f >= 0)
            return f;
    }
    /* the boundary of b minus the union (or of b and the union): every piece of every edge, cut
     * where other edges cross it, that bounds the region */
    for (size_t q = 0; q < V.np; q++)
        for (size_t k = 0; k < V.poly[q].n; k++) {
            double ts[2 + 2 * (1 + BN__VIS_OCC_MAX) * BN__VIS_CORNERS];
            size_t nt;
            if (!(V.poly[q].len[k] > tol))
                continue;
            nt = bn__vis_cuts(&V, q, k, tol, ts);
            bn__vis_edge(&V, q, k, ts, nt, x, n, tol, &S);
        }
    *sees = S.sees;
    return fmax(-S.sum / (2 * BN_PI), 0);
}

double bn__ff_point_visible(const double x[3], const double n[3], const double *b, size_t nb, const double bn[3],
                            const double *occ, const unsigned *occ_n, const double *cull, size_t nocc, double tol,
                            uint32_t *shadowed)
{
    int sees;
    if (nocc == 0) {
        *shadowed = 0;
        return bn__ff_point_polygon(x, n, b, nb);
    }
    return bn__point_vis(x, n, b, nb, bn, occ, occ_n, cull, nocc, tol, shadowed, 0, &sees);
}

double bn__ff_point_blocked(const double x[3], const double n[3], const double *b, size_t nb, const double bn[3],
                            const double *occ, const unsigned *occ_n, const double *cull, size_t nocc, double tol,
                            uint32_t *shadowed, int *sees)
{
    return bn__point_vis(x, n, b, nb, bn, occ, occ_n, cull, nocc, tol, shadowed, 1, sees);
}
