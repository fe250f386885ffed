/* Convex solids among the scene's faces, and whether one hides every segment between two convex
 * polygons (a pair that several of its faces hide together: a floor patch behind a block's edge,
 * or under the block, seen from a wall).
 *
 * A solid is a connected set of faces (by shared vertices: the same index or the same
 * coordinates) whose every vertex lies on the inner side of every face's plane, and whose edges
 * used by one face only form at most one planar loop: the missing facet (a box standing on a
 * floor without a bottom face). Its hull H is the intersection of the faces' half-spaces and the
 * missing facet's.
 *
 * The points from which a segment to a given point meets a convex set form a convex set, so every
 * segment between two convex polygons meets the interior of H (shrunk by tol) when the 16 or so
 * segments between their corners do. Such a segment crosses a face of the solid wherever it enters
 * or leaves H other than through the missing facet; it cannot pass that facet's plane from outside
 * when both polygons lie on its inner side (the segment stays there), and it enters H from outside
 * because each polygon lies outside H, on the outer side of one of H's planes. So it enters through
 * a face, or starts on the missing facet (a floor patch under the block) and leaves through one.
 * Pairs with a polygon of the solid itself are not judged by it. */
#include "formfactor/ff_internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Solids with more planes are not used: the per-pair test is 16 segments x planes. */
#define BN__SOLID_PLANES_MAX 64

struct bn__solids {
    size_t nf, ns;
    size_t *of;        /* per face: its solid, or SIZE_MAX */
    double *plane;     /* per solid: BN__SOLID_PLANES_MAX x (outward unit normal, d): inside n.x <= d */
    int *nplanes;
    int *missing;      /* per solid: the index of the missing facet's plane, or -1 */
};

typedef struct bn__vref {
    double x[3];
    size_t f;
} bn__vref;

/* Lexicographic order of points (exact coordinates). */
static int bn__pt_cmp(const double *p, const double *q)
{
    for (int c = 0; c < 3; c++)
        if (p[c] != q[c])
            return p[c] < q[c] ? -1 : 1;
    return 0;
}

static int bn__vref_cmp(const void *a, const void *b)
{
    return bn__pt_cmp(((const bn__vref *)a)->x, ((const bn__vref *)b)->x);
}

typedef struct bn__edge {
    double a[3], b[3];   /* endpoints, the smaller first */
} bn__edge;

static int bn__edge_cmp(const void *x, const void *y)
{
    const bn__edge *p = x, *q = y;
    int c = bn__pt_cmp(p->a, q->a);
    return c ? c : bn__pt_cmp(p->b, q->b);
}

/* Do the boundary edges be[0..nb) (each vertex ending exactly two of them) form one cycle? */
static int bn__one_cycle(const bn__edge *be, size_t nb)
{
    double prev[3], cur[3];
    size_t steps = 1;
    memcpy(prev, be[0].a, sizeof prev);
    memcpy(cur, be[0].b, sizeof cur);
    while (bn__pt_cmp(cur, be[0].a) != 0) {
        size_t k = 0;
        for (; k < nb; k++) {
            const double *o = bn__pt_cmp(be[k].a, cur) == 0 ? be[k].b : bn__pt_cmp(be[k].b, cur) == 0 ? be[k].a : NULL;
            if (o && bn__pt_cmp(o, prev) != 0) {
                memcpy(prev, cur, sizeof prev);
                memcpy(cur, o, sizeof cur);
                break;
            }
        }
        if (k == nb || ++steps > nb)
            return 0;
    }
    return steps == nb;
}

/* Each face's plane of the component f[0..m), oriented so that every vertex of the component is on
 * its inner side, into pl (np of them); 0 if some plane has vertices on both sides (not convex) or
 * every vertex lies in one plane (flat: no solid). */
static int bn__face_planes(const double *fv, const unsigned *fnc, const double *fn, const size_t *f, size_t m,
                           double tol, double *pl, int *np)
{
    double diam, lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    int offplane = 0;
    for (size_t q = 0; q < m; q++)
        for (unsigned k = 0; k < fnc[f[q]]; k++)
            for (int c = 0; c < 3; c++) {
                lo[c] = fmin(lo[c], fv[12 * f[q] + 3 * k + c]);
                hi[c] = fmax(hi[c], fv[12 * f[q] + 3 * k + c]);
            }
    diam = bn_v3_dist(lo, hi);
    *np = 0;
    for (size_t q = 0; q < m; q++) {
        const double *n = fn + 3 * f[q];
        double d = bn_v3_dot(n, fv + 12 * f[q]), mx = -INFINITY, mn = INFINITY, sg;
        for (size_t r = 0; r < m; r++)
            for (unsigned k = 0; k < fnc[f[r]]; k++) {
                double h = bn_v3_dot(n, fv + 12 * f[r] + 3 * k) - d;
                mx = fmax(mx, h);
                mn = fmin(mn, h);
            }
        if (mx <= tol && mn >= -tol)
            continue;   /* every vertex in this plane: flat so far */
        offplane |= mx > 1e-6 * diam || mn < -1e-6 * diam;
        if (mx > tol && mn < -tol)
            return 0;   /* vertices on both sides: not convex */
        sg = mx <= tol ? 1 : -1;
        bn_v3_scale(n, sg, pl + 4 * *np);
        pl[4 * (*np)++ + 3] = sg * d;
    }
    return offplane;
}

/* The edges of f[0..m) used by one face only into be (*nb of them); 0 if an edge has three faces
 * (not a solid's surface) or the boundary is not one cycle (each boundary vertex ends two boundary
 * edges, and a walk visits them all). e: scratch of the total corner count, v: of twice that. */
static int bn__boundary(const double *fv, const unsigned *fnc, const size_t *f, size_t m, bn__edge *e, bn__edge *be,
                        bn__vref *v, size_t *nb)
{
    size_t ne = 0, nv = 0;
    int ok = 1;
    *nb = 0;
    for (size_t q = 0; q < m; q++)
        for (unsigned k = 0; k < fnc[f[q]]; k++) {
            const double *a = fv + 12 * f[q] + 3 * k, *b = fv + 12 * f[q] + 3 * (k + 1 < fnc[f[q]] ? k + 1 : 0);
            int sw = bn__pt_cmp(a, b) > 0;
            memcpy(e[ne].a, sw ? b : a, sizeof e[ne].a);
            memcpy(e[ne].b, sw ? a : b, sizeof e[ne].b);
            ne++;
        }
    qsort(e, ne, sizeof *e, bn__edge_cmp);
    for (size_t k = 0; k < ne && ok;) {
        size_t k2 = k + 1;
        while (k2 < ne && bn__edge_cmp(&e[k], &e[k2]) == 0)
            k2++;
        if (k2 - k > 2)
            ok = 0;
        else if (k2 - k == 1) {
            be[(*nb)++] = e[k];
            memcpy(v[nv++].x, e[k].a, sizeof v[0].x);
            memcpy(v[nv++].x, e[k].b, sizeof v[0].x);
        }
        k = k2;
    }
    if (ok && *nb) {
        qsort(v, nv, sizeof *v, bn__vref_cmp);
        for (size_t k = 0; k < nv && ok; k += 2)
            ok = k + 1 < nv && bn__vref_cmp(&v[k], &v[k + 1]) == 0 && (k + 2 >= nv || bn__vref_cmp(&v[k + 1], &v[k + 2]) != 0);
        ok = ok && bn__one_cycle(be, *nb);
    }
    return ok;
}

/* The missing facet's plane: across two non-parallel boundary edges, every boundary vertex within
 * tol and every vertex on one side; appended to pl as plane *np (*missing). 0 if there is none. */
static int bn__missing_plane(const double *fv, const unsigned *fnc, const size_t *f, size_t m, const bn__edge *be,
                             size_t nb, double tol, double *pl, int *np, int *missing)
{
    double nn[3] = {0, 0, 0}, d, mx = -INFINITY, mn = INFINITY, sg;
    int found = 0, ok;
    for (size_t k = 0; k < nb && !found; k++)
        for (size_t l = k + 1; l < nb && !found; l++) {
            double u[3], w[3], x[3];
            bn_v3_sub(be[k].b, be[k].a, u);
            bn_v3_sub(be[l].b, be[l].a, w);
            bn_v3_cross(u, w, x);
            if (bn_v3_len(x) > 1e-6 * bn_v3_len(u) * bn_v3_len(w)) {
                bn_v3_scale(x, 1 / bn_v3_len(x), nn);
                found = 1;
            }
        }
    d = bn_v3_dot(nn, be[0].a);
    ok = found && *np < BN__SOLID_PLANES_MAX;
    for (size_t k = 0; k < nb && ok; k++)
        ok = fabs(bn_v3_dot(nn, be[k].a) - d) <= tol && fabs(bn_v3_dot(nn, be[k].b) - d) <= tol;
    for (size_t q = 0; q < m && ok; q++)
        for (unsigned k = 0; k < fnc[f[q]]; k++) {
            double h = bn_v3_dot(nn, fv + 12 * f[q] + 3 * k) - d;
            mx = fmax(mx, h);
            mn = fmin(mn, h);
        }
    if (!ok || !(mx <= tol || mn >= -tol))
        return 0;
    sg = mx <= tol ? 1 : -1;
    bn_v3_scale(nn, sg, pl + 4 * *np);
    pl[4 * *np + 3] = sg * d;
    *missing = (*np)++;
    return 1;
}

/* The planes of the component whose faces are f[0..m) (outward: every vertex inside): 0 if it is
 * not a convex solid closed but for at most one planar missing facet. */
static int bn__solid_planes(const double *fv, const unsigned *fnc, const double *fn, const size_t *f, size_t m,
                            double tol, double *pl, int *np, int *missing)
{
    bn__edge *e, *be;
    bn__vref *v;
    size_t ne = 0, nb = 0;
    int ok;
    if (m < 2 || m + 1 > BN__SOLID_PLANES_MAX)
        return 0;
    *missing = -1;
    if (!bn__face_planes(fv, fnc, fn, f, m, tol, pl, np))
        return 0;
    for (size_t q = 0; q < m; q++)
        ne += fnc[f[q]];
    e = bn__malloc_array(ne, sizeof *e);
    be = bn__malloc_array(ne, sizeof *be);
    v = bn__malloc_array(2 * ne, sizeof *v);
    ok = e && be && v && bn__boundary(fv, fnc, f, m, e, be, v, &nb);
    if (ok && nb)
        ok = bn__missing_plane(fv, fnc, f, m, be, nb, tol, pl, np, missing);
    free(e);
    free(be);
    free(v);
    return ok;
}

/* root[f]: face f's connected component (faces joined by a shared vertex index or equal
 * coordinates), by union-find; 0 when out of memory. */
static int bn__components(const double *fv, const unsigned *fnc, const size_t *fidx, const size_t *ffirst, size_t nf,
                          size_t *root)
{
    size_t *parent = bn__malloc_array(nf, sizeof *parent), nref = 0, *vowner = NULL, maxidx = 0;
    bn__vref *vr;
    for (size_t f = 0; f < nf; f++)
        nref += fnc[f];
    vr = bn__malloc_array(nref, sizeof *vr);
    for (size_t f = 0; f < nf; f++)
        for (unsigned k = 0; k < fnc[f]; k++)
            maxidx = fidx[ffirst[f] + k] > maxidx ? fidx[ffirst[f] + k] : maxidx;
    vowner = bn__malloc_array(maxidx + 1, sizeof *vowner);
    if (!parent || !vr || !vowner) {
        free(parent);
        free(vr);
        free(vowner);
        return 0;
    }
    for (size_t f = 0; f < nf; f++)
        parent[f] = f;
    for (size_t k = 0; k <= maxidx; k++)
        vowner[k] = SIZE_MAX;
    nref = 0;
    for (size_t f = 0; f < nf; f++)
        for (unsigned k = 0; k < fnc[f]; k++) {
            size_t vi = fidx[ffirst[f] + k];
            if (vowner[vi] != SIZE_MAX)
                bn__uf_union(parent, vowner[vi], f);
            else
                vowner[vi] = f;
            memcpy(vr[nref].x, fv + 12 * f + 3 * k, sizeof vr[0].x);
            vr[nref++].f = f;
        }
    qsort(vr, nref, sizeof *vr, bn__vref_cmp);
    for (size_t k = 1; k < nref; k++)
        if (bn__vref_cmp(&vr[k - 1], &vr[k]) == 0)
            bn__uf_union(parent, vr[k - 1].f, vr[k].f);
    for (size_t f = 0; f < nf; f++)
        root[f] = bn__uf_find(parent, f);
    free(vr);
    free(vowner);
    free(parent);
    return 1;
}

/* A solid of np planes (missing: the open facet's, or -1) into s, its arrays doubling as needed;
 * 0 when out of memory (no more solids: fewer shortcuts, the same answers). */
static int bn__solids_add(bn__solids *s, size_t *cap, const double *pl, int np, int missing)
{
    if (s->ns == *cap) {   /* doubling: scenes with many small solids */
        size_t nc = *cap ? 2 * *cap : 16;
        double *npl = bn__realloc_array(s->plane, nc * 4 * BN__SOLID_PLANES_MAX, sizeof *npl);
        int *nnp, *nmi;
        if (!npl)
            return 0;
        s->plane = npl;
        if (!(nnp = bn__realloc_array(s->nplanes, nc, sizeof *nnp)))
            return 0;
        s->nplanes = nnp;
        if (!(nmi = bn__realloc_array(s->missing, nc, sizeof *nmi)))
            return 0;
        s->missing = nmi;
        *cap = nc;
    }
    memcpy(s->plane + s->ns * 4 * BN__SOLID_PLANES_MAX, pl, (size_t)np * 4 * sizeof(double));
    s->nplanes[s->ns] = np;
    s->missing[s->ns] = missing;
    return 1;
}

bn_status bn__solids_find(const double *fv, const unsigned *fnc, const double *fn, const size_t *fidx,
                          const size_t *ffirst, size_t nf, double tol, bn__solids **out)
{
    bn__solids *s = bn__calloc(1, sizeof *s);
    size_t *root = NULL, *start = NULL, *members = NULL, cap = 0;
    *out = NULL;
    if (!s)
        return BN_ENOMEM;
    s->nf = nf;
    s->of = bn__malloc_array(nf, sizeof *s->of);
    root = bn__malloc_array(nf, sizeof *root);
    start = bn__calloc(nf + 1, sizeof *start);
    members = bn__malloc_array(nf, sizeof *members);
    if (!s->of || !root || !start || !members || !bn__components(fv, fnc, fidx, ffirst, nf, root)) {
        free(root);
        free(start);
        free(members);
        bn__solids_free(s);
        return BN_ENOMEM;
    }
    /* faces grouped by root (a counting sort over roots), each group tested */
    for (size_t f = 0; f < nf; f++) {
        s->of[f] = SIZE_MAX;
        start[root[f] + 1]++;
    }
    for (size_t r = 0; r < nf; r++)
        start[r + 1] += start[r];
    for (size_t f = 0; f < nf; f++)
        members[start[root[f]]++] = f;
    for (size_t r = nf; r > 0; r--)
        start[r] = start[r - 1];
    start[0] = 0;
    for (size_t r = 0; r < nf; r++) {
        size_t m = start[r + 1] - start[r];
        double pl[4 * BN__SOLID_PLANES_MAX];
        int np = 0, missing = -1;
        if (m < 2 || m + 1 > BN__SOLID_PLANES_MAX ||
            !bn__solid_planes(fv, fnc, fn, members + start[r], m, tol, pl, &np, &missing))
            continue;
        if (!bn__solids_add(s, &cap, pl, np, missing))
            break;
        for (size_t q = start[r]; q < start[r + 1]; q++)
            s->of[members[q]] = s->ns;
        s->ns++;
    }
    free(start);
    free(members);
    free(root);
    *out = s;
    return BN_OK;
}

void bn__solids_free(bn__solids *s)
{
    if (!s)
        return;
    free(s->of);
    free(s->plane);
    free(s->nplanes);
    free(s->missing);
    free(s);
}

size_t bn__solids_count(const bn__solids *s) { return s ? s->ns : 0; }

size_t bn__solid_of(const bn__solids *s, size_t f) { return s && f < s->nf ? s->of[f] : SIZE_MAX; }

/* Is polygon v (nv corners) outside H: on the outer side (within tol) of one of its planes? */
static int bn__outside(const double *pl, int np, const double *v, size_t nv, double tol)
{
    for (int k = 0; k < np; k++) {
        size_t c = 0;
        while (c < nv && bn_v3_dot(pl + 4 * k, v + 3 * c) - pl[4 * k + 3] >= -tol)
            c++;
        if (c == nv)
            return 1;
    }
    return 0;
}

/* Does polygon v lie on the missing facet mi of H (in its plane, inside every other plane)? */
static int bn__on_missing(const double *pl, int np, int mi, const double *v, size_t nv, double tol)
{
    for (size_t c = 0; c < nv; c++)
        for (int k = 0; k < np; k++) {
            double h = bn_v3_dot(pl + 4 * k, v + 3 * c) - pl[4 * k + 3];
            if (k == mi ? fabs(h) > tol : h > tol)
                return 0;
        }
    return 1;
}

int bn__solid_blocks_all(const bn__solids *s, size_t k, const double *a, size_t na, const double *b, size_t nb,
                         double tol)
{
    const double *pl = s->plane + k * 4 * BN__SOLID_PLANES_MAX;
    int np = s->nplanes[k], mi = s->missing[k];
    if (!bn__outside(pl, np, a, na, tol) || !bn__outside(pl, np, b, nb, tol))
        return 0;
    if (mi >= 0) {   /* both on the missing facet's inner side */
        for (size_t c = 0; c < na; c++)
            if (bn_v3_dot(pl + 4 * mi, a + 3 * c) - pl[4 * mi + 3] > tol)
                return 0;
        for (size_t c = 0; c < nb; c++)
            if (bn_v3_dot(pl + 4 * mi, b + 3 * c) - pl[4 * mi + 3] > tol)
                return 0;
        /* One polygon on the missing facet (the floor under a block): a segment from its inside
         * toward the other, on the facet's inner side, enters H at once and leaves it, the other
         * being outside, through a face. Its corners may lie on the faces' edges, where the corner
         * segments below need not enter H at all. */
        if (bn__on_missing(pl, np, mi, a, na, tol) || bn__on_missing(pl, np, mi, b, nb, tol))
            return 1;
    }
    /* every corner segment through H shrunk by tol, over more than tol of its length */
    for (size_t i = 0; i < na; i++)
        for (size_t j = 0; j < nb; j++) {
            const double *p = a + 3 * i;
            double d[3], t0 = 0, t1 = 1, len;
            bn_v3_sub(b + 3 * j, p, d);
            len = bn_v3_len(d);
            for (int q = 0; q < np && t0 < t1; q++) {
                double dn = bn_v3_dot(pl + 4 * q, d), h = bn_v3_dot(pl + 4 * q, p) - (pl[4 * q + 3] - tol);
                if (dn == 0) {
                    if (h >= 0)
                        return 0;   /* parallel to the plane, outside it */
                } else if (dn < 0) {
                    t0 = fmax(t0, -h / dn);   /* entering */
                } else {
                    t1 = fmin(t1, -h / dn);   /* leaving */
                }
            }
            if (!((t1 - t0) * len > tol))
                return 0;
        }
    return 1;
}

int bn__solid_back_faces_hidden(const bn__solids *s, size_t k, const double *v, size_t nv, double tol)
{
    const double *pl = s->plane + k * 4 * BN__SOLID_PLANES_MAX;
    int np = s->nplanes[k], mi = s->missing[k];
    if (!bn__outside(pl, np, v, nv, -tol))   /* beyond tol of one plane */
        return 0;
    for (size_t c = 0; mi >= 0 && c < nv; c++)
        if (bn_v3_dot(pl + 4 * mi, v + 3 * c) - pl[4 * mi + 3] > tol)
            return 0;
    return 1;
}

int bn__solid_face_plane(const bn__solids *s, size_t k, const double fn[3], const double p[3], double tol,
                         double out[4])
{
    const double *pl = s->plane + k * 4 * BN__SOLID_PLANES_MAX;
    for (int q = 0; q < s->nplanes[k]; q++)
        if (q != s->missing[k] && fabs(bn_v3_dot(pl + 4 * q, fn)) > 1 - 1e-9 &&
            fabs(bn_v3_dot(pl + 4 * q, p) - pl[4 * q + 3]) <= tol) {
            memcpy(out, pl + 4 * q, 4 * sizeof(double));
            return 1;
        }
    return 0;
}
