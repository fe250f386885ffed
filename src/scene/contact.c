/* Contact lines. Where one face touches or pierces another face's front (a block standing on the
 * floor, a model resting on a table or sunk into it), the receiving face's patches are split along
 * the contact, so no patch straddles the lit floor and the hidden floor underneath.
 *
 * A contact on face P is the zero set of another face Q on P's plane, clipped to P's interior:
 * Q's edge when Q touches P's plane along it, the line where Q crosses the plane, or every edge of
 * Q when Q lies on P facing it (a block's bottom). Lines on P's boundary (walls meeting the floor
 * at its edge) and faces coplanar with P facing the same way cut nothing. Each patch of P that a
 * contact segment passes through is split along the segment's line into convex pieces; points the
 * cuts create on an edge shared with a neighbouring patch are inserted into the neighbour too, so
 * the patch mesh of a face stays free of T-junctions. Pieces become triangles or quads (the
 * patch's corners must stay 3 or 4): a fan from a corner whose neighbours are corners, or from
 * the piece's centroid. Areas sum to the face's as before. */
#include "scene/scene_internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

#ifndef BN__SLIVER
#define BN__SLIVER 1e-2
#endif

typedef struct {
    double o[3], e1[3], e2[3], n[3];
} bn__frame;

typedef struct {
    double a[2], b[2];
} bn__seg;

typedef struct {
    size_t off, n;     /* ring in the id pool */
    size_t orig;       /* the patch it came from */
    int    changed;
} bn__piece;

typedef struct {
    bn_scene *s;
    /* growable outputs */
    bn_patch *patches;
    size_t    np, np_cap;
    double   *pv;
    size_t    nv, nv_cap;
    /* per face scratch */
    size_t   *pool;
    size_t    npool, pool_cap;
    bn__piece *pieces;
    size_t    npieces, pieces_cap;
    size_t   *fresh;    /* vertices the cuts made on the current face */
    size_t    nfresh, fresh_cap;
    bn__seg  *segs;
    size_t    nsegs, segs_cap;
    bn__frame fr;
    double    tol;      /* plane distance that counts as touching */
    double    edge;     /* 1e-6 of the scene's diameter: contacts this near a face's boundary, or
                           this short, cut nothing */
    double    snap;     /* points closer than this are one point */
    int       self;     /* also contacts between faces of one object */
    double    keep;     /* on the current face: a patch corner this close to a contact line is
                           taken as on it, so cuts never leave slivers thinner than this */
} bn__cx;


static const double *bn__fvert(const bn_scene *s, const bn_face *f, unsigned i)
{
    return s->verts + 3 * s->fidx[f->first + i];
}

static void bn__frame_of(const bn_scene *s, const bn_face *f, bn__frame *fr)
{
    memcpy(fr->o, bn__fvert(s, f, 0), sizeof fr->o);
    memcpy(fr->n, f->normal, sizeof fr->n);
    bn_v3_sub(bn__fvert(s, f, 1), fr->o, fr->e1);
    /* remove any normal component so the frame is exactly orthonormal */
    bn_v3_madd(fr->e1, -bn_v3_dot(fr->e1, fr->n), fr->n, fr->e1);
    bn_v3_normalize(fr->e1);
    bn_v3_cross(fr->n, fr->e1, fr->e2);
}

static void bn__to2(const bn__frame *fr, const double p[3], double q[2])
{
    double d[3];
    bn_v3_sub(p, fr->o, d);
    q[0] = bn_v3_dot(d, fr->e1);
    q[1] = bn_v3_dot(d, fr->e2);
}

static double bn__cross2(const double a[2], const double b[2], const double c[2])
{
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

/* Clips segment [a, b] to the convex CCW polygon poly[0..n) shrunk by `inset`: the parameters
 * [*t0, *t1] of the part inside. 0 when nothing is left. */
static int bn__clip(const double (*poly)[2], unsigned n, const double a[2], const double b[2], double inset,
                    double *t0, double *t1)
{
    double lo = 0, hi = 1, d[2] = {b[0] - a[0], b[1] - a[1]};
    for (unsigned i = 0; i < n; i++) {
        const double *p = poly[i], *q = poly[(i + 1) % n];
        double m[2] = {-(q[1] - p[1]), q[0] - p[0]}, len = hypot(m[0], m[1]), sa, sd;
        if (!(len > 0))
            continue;
        m[0] /= len;
        m[1] /= len;
        sa = m[0] * (a[0] - p[0]) + m[1] * (a[1] - p[1]) - inset;   /* >= 0 inside */
        sd = m[0] * d[0] + m[1] * d[1];
        if (sd == 0) {
            if (sa < 0)
                return 0;
        } else {
            double t = -sa / sd;
            if (sd > 0)
                lo = fmax(lo, t);
            else
                hi = fmin(hi, t);
        }
        if (lo >= hi)
            return 0;
    }
    *t0 = lo;
    *t1 = hi;
    return 1;
}

static int bn__add_seg(bn__cx *c, const double a3[3], const double b3[3], const double (*poly)[2], unsigned n)
{
    double a[2], b[2], t0, t1;
    bn__to2(&c->fr, a3, a);
    bn__to2(&c->fr, b3, b);
    if (hypot(b[0] - a[0], b[1] - a[1]) <= 2 * c->edge)
        return 1;
    /* inset: contacts on P's boundary (or within `edge` of it) cut nothing */
    if (!bn__clip(poly, n, a, b, c->edge, &t0, &t1))
        return 1;
    {
        bn__seg sg;
        for (int k = 0; k < 2; k++) {
            sg.a[k] = a[k] + t0 * (b[k] - a[k]);
            sg.b[k] = a[k] + t1 * (b[k] - a[k]);
        }
        if (hypot(sg.b[0] - sg.a[0], sg.b[1] - sg.a[1]) <= 2 * c->edge)
            return 1;
        if (!bn__grow((void **)&c->segs, &c->segs_cap, c->nsegs + 1, sizeof *c->segs))
            return 0;
        c->segs[c->nsegs++] = sg;
    }
    return 1;
}

/* The zero set of face q on face p's plane, as segments in p's frame. 0 on OOM. */
static int bn__contacts_of(bn__cx *c, const bn_face *p, const double (*poly)[2], unsigned np, const bn_face *q)
{
    const bn_scene *s = c->s;
    double d[4], pts[8][3], dmax = -INFINITY;
    unsigned n = q->nverts, npts = 0, zero = 0, shared = 0;
    /* a neighbour sharing an edge (two vertices) meets p's plane on that edge, p's boundary: cuts
     * nothing (most candidate pairs in a fine scanned mesh) */
    for (unsigned k = 0; k < n; k++)
        for (unsigned j = 0; j < np; j++)
            shared += s->fidx[q->first + k] == s->fidx[p->first + j];
    if (shared >= 2)
        return 1;
    for (unsigned k = 0; k < n; k++) {
        double r[3];
        bn_v3_sub(bn__fvert(s, q, k), c->fr.o, r);
        d[k] = bn_v3_dot(r, c->fr.n);
        if (fabs(d[k]) <= c->tol) {
            d[k] = 0;
            zero++;
        }
        dmax = fmax(dmax, d[k]);
    }
    if (zero == n) {
        /* coplanar: a face lying on p and facing it touches p along its whole outline */
        if (bn_v3_dot(q->normal, p->normal) >= 0)
            return 1;
        for (unsigned k = 0; k < n; k++)
            if (!bn__add_seg(c, bn__fvert(s, q, k), bn__fvert(s, q, (k + 1) % n), poly, np))
                return 0;
        return 1;
    }
    if (!(dmax > 0))
        return 1;   /* q lies behind p's plane: p's back neither emits nor reflects */
    for (unsigned k = 0; k < n; k++) {
        unsigned k1 = (k + 1) % n;
        if (d[k] == 0)
            memcpy(pts[npts++], bn__fvert(s, q, k), sizeof pts[0]);
        if ((d[k] > 0 && d[k1] < 0) || (d[k] < 0 && d[k1] > 0)) {
            double t = d[k] / (d[k] - d[k1]), e[3];
            bn_v3_sub(bn__fvert(s, q, k1), bn__fvert(s, q, k), e);
            bn_v3_madd(bn__fvert(s, q, k), t, e, pts[npts++]);
        }
    }
    if (npts < 2)
        return 1;
    {
        unsigned ba = 0, bb = 1;
        double best = -1;
        for (unsigned i = 0; i < npts; i++)
            for (unsigned j = i + 1; j < npts; j++) {
                double dd = bn_v3_dist(pts[i], pts[j]);
                if (dd > best) {
                    best = dd;
                    ba = i;
                    bb = j;
                }
            }
        return bn__add_seg(c, pts[ba], pts[bb], poly, np);
    }
}

static void bn__xy(const bn__cx *c, size_t id, double q[2])
{
    bn__to2(&c->fr, c->pv + 3 * id, q);
}

/* The vertex at parameter t along a -> b (computed from the lower id, so two pieces sharing the
 * edge make the same point), reused when the face already has a fresh one within `edge` (the contacts'
 * resolution): two cuts crossing near a corner of the object standing there made points 2.7e-8 m apart
 * at a table leg's foot, and the sliver between them got F = -0.011 from the closed form. */
static int bn__cut_vertex(bn__cx *c, size_t a, size_t b, double da, double db, size_t *out)
{
    double t, p[3], e[3];
    if (a > b) {
        size_t tmp = a;
        double td = da;
        a = b;
        b = tmp;
        da = db;
        db = td;
    }
    t = da / (da - db);
    bn_v3_sub(c->pv + 3 * b, c->pv + 3 * a, e);
    bn_v3_madd(c->pv + 3 * a, t, e, p);
    for (size_t i = 0; i < c->nfresh; i++)
        if (bn_v3_dist(c->pv + 3 * c->fresh[i], p) <= c->edge) {
            *out = c->fresh[i];
            return 1;
        }
    if (!bn__grow((void **)&c->pv, &c->nv_cap, c->nv + 1, 3 * sizeof(double)) ||
        !bn__grow((void **)&c->fresh, &c->fresh_cap, c->nfresh + 1, sizeof(size_t)))
        return 0;
    memcpy(c->pv + 3 * c->nv, p, sizeof p);
    c->fresh[c->nfresh++] = c->nv;
    *out = c->nv++;
    return 1;
}

static int bn__new_piece(bn__cx *c, const size_t *ids, size_t n, size_t orig, int changed)
{
    if (!bn__grow((void **)&c->pool, &c->pool_cap, c->npool + n, sizeof(size_t)) ||
        !bn__grow((void **)&c->pieces, &c->pieces_cap, c->npieces + 1, sizeof *c->pieces))
        return 0;
    memcpy(c->pool + c->npool, ids, n * sizeof(size_t));
    c->pieces[c->npieces].off = c->npool;
    c->pieces[c->npieces].n = n;
    c->pieces[c->npieces].orig = orig;
    c->pieces[c->npieces].changed = changed;
    c->npool += n;
    c->npieces++;
    return 1;
}

/* Splits piece k along segment g where g passes through it. 0 on OOM. */
static int bn__cut(bn__cx *c, size_t k, const bn__seg *g, size_t *tmp_l, size_t *tmp_r)
{
    bn__piece pc = c->pieces[k];
    double u[2] = {g->b[0] - g->a[0], g->b[1] - g->a[1]}, len = hypot(u[0], u[1]), nrm[2];
    double dmin = INFINITY, dmax = -INFINITY;
    double xy[64][2], dist[64], t0, t1;
    size_t nl = 0, nr = 0;
    if (pc.n > 64)
        return 1;   /* a piece this complex is left as it is */
    nrm[0] = -u[1] / len;
    nrm[1] = u[0] / len;
    for (size_t i = 0; i < pc.n; i++) {
        bn__xy(c, c->pool[pc.off + i], xy[i]);
        dist[i] = nrm[0] * (xy[i][0] - g->a[0]) + nrm[1] * (xy[i][1] - g->a[1]);
        dmin = fmin(dmin, dist[i]);
        dmax = fmax(dmax, dist[i]);
    }
    /* corners within keep of the line count as on it (the cut bends through them): no slivers */
    for (size_t i = 0; i < pc.n; i++)
        if (fabs(dist[i]) <= c->keep)
            dist[i] = 0;
    if (!(dmax > c->keep && -dmin > c->keep))
        return 1;
    /* the segment itself must pass through the piece, not only its line */
    if (!bn__clip((const double(*)[2])xy, (unsigned)pc.n, g->a, g->b, 0, &t0, &t1) || (t1 - t0) * len <= c->keep)
        return 1;
    for (size_t i = 0; i < pc.n; i++) {
        size_t i1 = (i + 1) % pc.n, a = c->pool[pc.off + i], b = c->pool[pc.off + i1];
        double da = dist[i], db = dist[i1];
        if (da >= 0)
            tmp_l[nl++] = a;
        if (da <= 0)
            tmp_r[nr++] = a;
        if ((da > 0 && db < 0) || (da < 0 && db > 0)) {
            size_t v;
            if (!bn__cut_vertex(c, a, b, da, db, &v))
                return 0;
            tmp_l[nl++] = v;
            tmp_r[nr++] = v;
        }
    }
    if (nl < 3 || nr < 3)
        return 1;
    /* piece k becomes the left part (its ring rewritten at the pool's end), the right is new */
    {
        size_t orig = pc.orig;
        if (!bn__new_piece(c, tmp_r, nr, orig, 1) || !bn__new_piece(c, tmp_l, nl, orig, 1))
            return 0;
        c->pieces[k] = c->pieces[c->npieces - 1];
        c->npieces--;
    }
    return 1;
}

/* Inserts the fresh vertices that lie inside an edge of piece k (a neighbour's cut). */
static int bn__mend(bn__cx *c, size_t k, size_t *tmp, size_t tmp_cap)
{
    bn__piece pc = c->pieces[k];
    size_t n = 0;
    int any = 0;
    for (size_t i = 0; i < pc.n; i++) {
        size_t a = c->pool[pc.off + i], b = c->pool[pc.off + (i + 1) % pc.n], m = 0;
        double pa[2], pb[2], e[2], l2, ts[64];
        size_t ids[64];
        bn__xy(c, a, pa);
        bn__xy(c, b, pb);
        e[0] = pb[0] - pa[0];
        e[1] = pb[1] - pa[1];
        l2 = e[0] * e[0] + e[1] * e[1];
        if (n + 1 > tmp_cap)
            return 1;
        tmp[n++] = a;
        if (!(l2 > 0))
            continue;
        for (size_t j = 0; j < c->nfresh && m < 64; j++) {
            size_t w = c->fresh[j];
            double pw[2], t, perp;
            if (w == a || w == b)
                continue;
            bn__xy(c, w, pw);
            t = ((pw[0] - pa[0]) * e[0] + (pw[1] - pa[1]) * e[1]) / l2;
            perp = fabs((pw[0] - pa[0]) * e[1] - (pw[1] - pa[1]) * e[0]) / sqrt(l2);
            if (t > 0 && t < 1 && perp <= 16 * c->snap) {
                size_t q = m++;
                while (q > 0 && ts[q - 1] > t) {   /* insertion sort along the edge */
                    ts[q] = ts[q - 1];
                    ids[q] = ids[q - 1];
                    q--;
                }
                ts[q] = t;
                ids[q] = w;
            }
        }
        for (size_t q = 0; q < m && n < tmp_cap; q++)
            tmp[n++] = ids[q];
        any |= m > 0;
    }
    if (!any)
        return 1;
    if (!bn__new_piece(c, tmp, n, pc.orig, 1))
        return 0;
    c->pieces[k] = c->pieces[c->npieces - 1];
    c->npieces--;
    return 1;
}

static int bn__emit(bn__cx *c, size_t face, const bn_patch *orig, const size_t *ring, size_t n)
{
    bn_patch p;
    if (!bn__grow((void **)&c->patches, &c->np_cap, c->np + n, sizeof *c->patches))
        return 0;
    memset(&p, 0, sizeof p);
    p.face = face;
    p.material = orig->material;
    if (n == 3 || n == 4) {
        p.ncorners = (unsigned)n;
        memcpy(p.corner, ring, n * sizeof(size_t));
        bn__scene_patch_finish(&p, c->pv, c->fr.n);
        c->patches[c->np++] = p;
        return 1;
    }
    return 0;
}

/* The ring less repeated points (two cut points merged into one, bn__cut_vertex): how many are left. */
static size_t bn__ring_clean(const size_t *ring, size_t n, size_t *out)
{
    size_t m = 0;
    for (size_t i = 0; i < n; i++)
        if (!m || ring[i] != out[m - 1])
            out[m++] = ring[i];
    while (m > 1 && out[m - 1] == out[0])
        m--;
    return m;
}

/* A ring with no corner whose neighbours are both corners: a fan from its area centroid (a new vertex
 * inside) to each edge; none when it has no area. 0 on OOM only (a flat ring was reported as out of memory). */
static int bn__emit_fan(bn__cx *c, size_t face, const bn_patch *orig, const size_t *ring, size_t n,
                        const double (*xy)[2])
{
    double cen[3] = {0, 0, 0}, w = 0;
    size_t cv;
    for (size_t j = 1; j + 1 < n; j++) {
        const double *a = c->pv + 3 * ring[0], *b = c->pv + 3 * ring[j], *d = c->pv + 3 * ring[j + 1];
        double ar = fabs(bn__cross2(xy[0], xy[j], xy[j + 1]));
        for (int k = 0; k < 3; k++)
            cen[k] += ar * (a[k] + b[k] + d[k]) / 3.0;
        w += ar;
    }
    if (!(w > 0))
        return 1;   /* no area (its points on one line, within the contacts' resolution): no patch, not an error */
    if (!bn__grow((void **)&c->pv, &c->nv_cap, c->nv + 1, 3 * sizeof(double)))
        return 0;
    bn_v3_scale(cen, 1.0 / w, cen);
    memcpy(c->pv + 3 * c->nv, cen, sizeof cen);
    cv = c->nv++;
    for (size_t j = 0; j < n; j++) {
        size_t tri[3] = {cv, ring[j], ring[(j + 1) % n]};
        if (!bn__emit(c, face, orig, tri, 3))
            return 0;
    }
    return 1;
}

/* A convex ring of n >= 3 points (some possibly on the straight line between their neighbours)
 * as triangles and quads that keep every point as a corner; fewer than 3 distinct points (a sliver
 * whose cut points merged) make none. */
static int bn__emit_piece(bn__cx *c, size_t face, const bn_patch *orig, const size_t *ring0, size_t n0)
{
    double (*xy)[2] = bn__malloc_array(n0, sizeof *xy);
    int *corner = bn__malloc_array(n0, sizeof *corner), ok = 0;
    size_t *ring = bn__malloc_array(n0, sizeof *ring), ncorner = 0, apex = SIZE_MAX, n;
    if (!xy || !corner || !ring)
        goto done;
    if ((n = bn__ring_clean(ring0, n0, ring)) < 3) {
        ok = 1;
        goto done;
    }
    for (size_t i = 0; i < n; i++)
        bn__xy(c, ring[i], xy[i]);
    for (size_t i = 0; i < n; i++) {
        const double *a = xy[(i + n - 1) % n], *b = xy[i], *d = xy[(i + 1) % n];
        double la = hypot(b[0] - a[0], b[1] - a[1]), lb = hypot(d[0] - b[0], d[1] - b[1]);
        corner[i] = bn__cross2(a, b, d) > 1e-9 * la * lb;
        ncorner += (size_t)corner[i];
    }
    if (n == 3 || (n == 4 && ncorner == 4)) {
        ok = bn__emit(c, face, orig, ring, n);
        goto done;
    }
    for (size_t i = 0; i < n && apex == SIZE_MAX; i++)
        if (corner[(i + 1) % n] && corner[(i + n - 1) % n])
            apex = i;
    if (apex != SIZE_MAX) {
        for (size_t j = 1; j + 1 < n; j++) {
            size_t tri[3] = {ring[apex], ring[(apex + j) % n], ring[(apex + j + 1) % n]};
            if (!bn__emit(c, face, orig, tri, 3))
                goto done;
        }
        ok = 1;
    } else
        ok = bn__emit_fan(c, face, orig, ring, n, (const double(*)[2])xy);
done:
    free(xy);
    free(corner);
    free(ring);
    return ok;
}

/* Candidate faces near each face: a hashed uniform grid over the faces' boxes, cells twice the
 * median face's size (a scanned model's small triangles then share a cell with a few neighbours,
 * not hundreds); faces covering more than BN__BIG_CELLS cells (walls, floors) are kept apart and
 * tested against every face. */
typedef struct {
    double lo[3], cell;
    size_t nbucket;   /* a power of two */
    size_t *start, *items;
    size_t *big;
    size_t  nbig;
} bn__fgrid;

#define BN__BIG_CELLS 4096

static void bn__face_box(const bn_scene *s, const bn_face *f, double tol, double lo[3], double hi[3])
{
    for (int k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
    }
    for (unsigned i = 0; i < f->nverts; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], bn__fvert(s, f, i)[k] - tol);
            hi[k] = fmax(hi[k], bn__fvert(s, f, i)[k] + tol);
        }
}

static void bn__cell_range(const bn__fgrid *g, const double lo[3], const double hi[3], int64_t a[3], int64_t b[3])
{
    for (int k = 0; k < 3; k++) {
        a[k] = (int64_t)bn_clamp(floor((lo[k] - g->lo[k]) / g->cell), -1e15, 1e15);
        b[k] = (int64_t)bn_clamp(floor((hi[k] - g->lo[k]) / g->cell), -1e15, 1e15);
    }
}

static double bn__cells(const int64_t a[3], const int64_t b[3])
{
    return (double)(b[0] - a[0] + 1) * (double)(b[1] - a[1] + 1) * (double)(b[2] - a[2] + 1);
}

static size_t bn__bucket(const bn__fgrid *g, int64_t x, int64_t y, int64_t z)
{
    uint64_t h = (uint64_t)x * 0x9E3779B97F4A7C15ull ^ (uint64_t)y * 0xC2B2AE3D27D4EB4Full ^
                 (uint64_t)z * 0x165667B19E3779F9ull;
    h ^= h >> 29;
    return (size_t)(h & (g->nbucket - 1));
}

static void bn__fgrid_free(bn__fgrid *g)
{
    free(g->start);
    free(g->items);
    free(g->big);
}

/* Every face's cells: pass 0 sets the big faces aside and returns the others' cell count, pass 1
 * counts per bucket, pass 2 fills. */
static size_t bn__fgrid_walk(const bn_scene *s, double tol, bn__fgrid *g, int pass)
{
    size_t total = 0;
    for (size_t f = 0; f < s->nfaces; f++) {
        double lo[3], hi[3];
        int64_t a[3], b[3];
        bn__face_box(s, &s->faces[f], tol, lo, hi);
        bn__cell_range(g, lo, hi, a, b);
        if (bn__cells(a, b) > BN__BIG_CELLS) {
            if (pass == 0)
                g->big[g->nbig++] = f;
            continue;
        }
        total += (size_t)bn__cells(a, b);
        if (pass == 0)
            continue;
        for (int64_t z = a[2]; z <= b[2]; z++)
            for (int64_t y = a[1]; y <= b[1]; y++)
                for (int64_t x = a[0]; x <= b[0]; x++) {
                    size_t h = bn__bucket(g, x, y, z);
                    if (pass == 1)
                        g->start[h + 1]++;
                    else
                        g->items[g->start[h]++] = f;
                }
    }
    return total;
}

static int bn__fgrid_build(const bn_scene *s, double tol, bn__fgrid *g)
{
    size_t nf = s->nfaces, total = 0, nsample = nf < 4096 ? nf : 4096;
    double *sz = bn__malloc_array(nsample + 1, sizeof(double)), ext = 0;
    memset(g, 0, sizeof *g);
    if (!sz)
        return 0;
    for (size_t i = 0; i < nsample; i++) {
        double lo[3], hi[3], d[3];
        bn__face_box(s, &s->faces[i * (nf / nsample)], 0, lo, hi);
        bn_v3_sub(hi, lo, d);
        sz[i] = bn_v3_len(d);
    }
    /* the median by a partial selection would do; a sort of 4096 doubles is as cheap */
    for (size_t i = 1; i < nsample; i++)
        for (size_t j = i; j > 0 && sz[j - 1] > sz[j]; j--) {
            double t = sz[j];
            sz[j] = sz[j - 1];
            sz[j - 1] = t;
        }
    for (int k = 0; k < 3; k++) {
        g->lo[k] = s->lo[k] - tol;
        ext = fmax(ext, s->hi[k] - s->lo[k] + 2 * tol);
    }
    g->cell = fmax(2 * (nsample ? sz[nsample / 2] : 0) + 2 * tol, ext / 1024);
    free(sz);
    if (!(g->cell > 0))
        g->cell = 1;
    g->big = bn__malloc_array(nf + 1, sizeof(size_t));
    if (!g->big)
        return 0;
    total = bn__fgrid_walk(s, tol, g, 0);
    g->nbucket = 1;
    while (g->nbucket < 2 * total + 1)
        g->nbucket *= 2;
    g->start = bn__calloc(g->nbucket + 1, sizeof(size_t));
    g->items = bn__malloc_array(total + 1, sizeof(size_t));
    if (!g->start || !g->items)
        return 0;
    bn__fgrid_walk(s, tol, g, 1);
    for (size_t i = 0; i < g->nbucket; i++)
        g->start[i + 1] += g->start[i];
    bn__fgrid_walk(s, tol, g, 2);
    /* the fill advanced each start to the next bucket's: shift back */
    memmove(g->start + 1, g->start, g->nbucket * sizeof(size_t));
    g->start[0] = 0;
    return 1;
}

static double bn__diameter(const bn__cx *c, const bn_patch *p)
{
    double d = 0;
    for (unsigned i = 0; i < p->ncorners; i++)
        for (unsigned j = i + 1; j < p->ncorners; j++)
            d = fmax(d, bn_v3_dist(c->pv + 3 * p->corner[i], c->pv + 3 * p->corner[j]));
    return d;
}

/* Corner sines of a patch in the face's frame (ring order), 0 if any is not positive. */
static int bn__sines(const bn__cx *c, const bn_patch *p, double *sn)
{
    double xy[4][2];
    unsigned n = p->ncorners;
    for (unsigned k = 0; k < n; k++)
        bn__xy(c, p->corner[k], xy[k]);
    for (unsigned k = 0; k < n; k++) {
        const double *a = xy[(k + n - 1) % n], *b = xy[k], *d = xy[(k + 1) % n];
        double la = hypot(b[0] - a[0], b[1] - a[1]), lb = hypot(d[0] - b[0], d[1] - b[1]);
        if (!(la > 0 && lb > 0))
            return 0;
        sn[k] = bn__cross2(a, b, d) / (la * lb);
        if (!(sn[k] > 0))
            return 0;
    }
    return 1;
}

/* Where interior corner id would snap to: the nearest point of a contact segment within a third of
 * the patches' width (and farther than snap); 0 for none, or a corner on the face's boundary. */
static int bn__snap_target(const bn__cx *c, const bn_face *f, size_t id, const double (*poly)[2], double width,
                           double to[2])
{
    double q[2], best = INFINITY;
    bn__xy(c, id, q);
    for (unsigned k = 0; k < f->nverts; k++) {
        const double *a = poly[k], *b = poly[(k + 1) % f->nverts];
        double len = hypot(b[0] - a[0], b[1] - a[1]);
        if (len > 0 && fabs(bn__cross2(a, b, q)) / len <= c->edge)
            return 0;
    }
    for (size_t g = 0; g < c->nsegs; g++) {
        const bn__seg *sg = &c->segs[g];
        double e[2] = {sg->b[0] - sg->a[0], sg->b[1] - sg->a[1]}, l2 = e[0] * e[0] + e[1] * e[1], t, p2[2], d;
        t = l2 > 0 ? bn_clamp(((q[0] - sg->a[0]) * e[0] + (q[1] - sg->a[1]) * e[1]) / l2, 0, 1) : 0;
        p2[0] = sg->a[0] + t * e[0];
        p2[1] = sg->a[1] + t * e[1];
        d = hypot(q[0] - p2[0], q[1] - p2[1]);
        if (d < best) {
            best = d;
            to[0] = p2[0];
            to[1] = p2[1];
        }
    }
    return best <= width / 3 && best > c->snap;
}

/* Corner id moved to `to` (in the face's frame) if its ninc patches (indices inc) stay convex with
 * every corner's sine at least half what it was and none wider than 4/3 of `longest`; else put back. */
static void bn__snap_try(bn__cx *c, const bn_face *f, bn_patch *pt, const size_t *inc, size_t ninc, size_t id,
                         const double to[2], double longest)
{
    double old[3], sn0[16][4];
    int good = 1;
    for (size_t i = 0; i < ninc && good; i++)
        good = bn__sines(c, &pt[inc[i]], sn0[i]);
    if (!good)
        return;
    memcpy(old, c->pv + 3 * id, sizeof old);
    for (int k = 0; k < 3; k++)
        c->pv[3 * id + k] = c->fr.o[k] + to[0] * c->fr.e1[k] + to[1] * c->fr.e2[k];
    for (size_t i = 0; i < ninc && good; i++) {
        const bn_patch *p = &pt[inc[i]];
        double sn[4];
        good = bn__sines(c, p, sn);
        for (unsigned k = 0; k < p->ncorners && good; k++)
            good = sn[k] >= 0.5 * sn0[i][k];
        good = good && bn__diameter(c, p) <= 4.0 / 3.0 * longest;
    }
    if (!good) {
        memcpy(c->pv + 3 * id, old, sizeof old);
        return;
    }
    for (size_t i = 0; i < ninc; i++)
        bn__scene_patch_finish(&pt[inc[i]], c->pv, f->normal);
}

/* Moves interior patch corners that lie within a third of a patch's width of a contact segment
 * onto it (its nearest point), where the patches around them stay convex with every corner's sine
 * at least half what it was and none grows wider than 4/3 of the face's widest patch (diameter).
 * Cuts then run along patch edges there instead of leaving thin strips beside the contact: a strip a millimetre wide against a wall is where the patch-constant
 * solution is least right (the corner's light changes fastest). Returns 0 on OOM. */
static int bn__snap_corners(bn__cx *c, const bn_face *f, bn_patch *pt, size_t n, const double (*poly)[2])
{
    size_t vmin = SIZE_MAX, vmax = 0, nloc, *start = NULL, *inc = NULL, *fill = NULL;
    double width = INFINITY, longest = 0;
    int ok = 0;
    for (size_t p = 0; p < n; p++) {
        double lp = 0;
        for (unsigned k = 0; k < pt[p].ncorners; k++) {
            size_t v = pt[p].corner[k];
            vmin = v < vmin ? v : vmin;
            vmax = v > vmax ? v : vmax;
            lp = fmax(lp, bn_v3_dist(c->pv + 3 * v, c->pv + 3 * pt[p].corner[(k + 1) % pt[p].ncorners]));
        }
        if (lp > 0)
            width = fmin(width, (pt[p].ncorners == 3 ? 2 : 1) * pt[p].area / lp);
        longest = fmax(longest, bn__diameter(c, &pt[p]));
    }
    if (n == 0 || !(width < INFINITY))
        return 1;
    nloc = vmax - vmin + 1;
    start = bn__calloc(nloc + 1, sizeof(size_t));
    fill = bn__calloc(nloc + 1, sizeof(size_t));
    inc = bn__malloc_array(4 * n + 1, sizeof(size_t));
    if (!start || !fill || !inc)
        goto done;
    for (size_t p = 0; p < n; p++)
        for (unsigned k = 0; k < pt[p].ncorners; k++)
            start[pt[p].corner[k] - vmin + 1]++;
    for (size_t v = 0; v < nloc; v++)
        start[v + 1] += start[v];
    for (size_t p = 0; p < n; p++)
        for (unsigned k = 0; k < pt[p].ncorners; k++) {
            size_t v = pt[p].corner[k] - vmin;
            inc[start[v] + fill[v]++] = p;
        }
    for (size_t v = 0; v < nloc; v++) {
        double to[2] = {0, 0};
        if (start[v] == start[v + 1] || start[v + 1] - start[v] > 16 ||
            !bn__snap_target(c, f, v + vmin, poly, width, to))
            continue;
        bn__snap_try(c, f, pt, inc + start[v], start[v + 1] - start[v], v + vmin, to, longest);
    }
    ok = 1;
done:
    free(start);
    free(fill);
    free(inc);
    return ok;
}

/* Cuts face f's patches along its contact segments (c->segs); appends the result. */
/* The patches p0 .. p1 - 1 with a changed piece, each counted once, in one pass over the pieces (the
 * search per patch this replaced was quadratic: 20 s on a floor of 200,000 patches); SIZE_MAX when
 * out of memory. */
static size_t bn__count_split(const bn__cx *c, size_t p0, size_t p1)
{
    unsigned char *hit = bn__calloc(p1 - p0 + 1, 1);
    size_t changed = 0;
    if (!hit)
        return SIZE_MAX;
    for (size_t k = 0; k < c->npieces; k++)
        if (c->pieces[k].changed && !hit[c->pieces[k].orig - p0]) {
            hit[c->pieces[k].orig - p0] = 1;
            changed++;
        }
    free(hit);
    return changed;
}

/* Index scratch of the cuts: tl and tr, each of cap entries. */
typedef struct bn__cutbuf {
    size_t *tl, *tr, cap;
} bn__cutbuf;

/* Both grown to hold at least n. 0 when out of memory. */
static int bn__cutbuf_reserve(bn__cutbuf *b, size_t n)
{
    size_t *a;
    if (n <= b->cap)
        return 1;
    if (!(a = bn__realloc_array(b->tl, n, sizeof *a)))
        return 0;
    b->tl = a;
    if (!(a = bn__realloc_array(b->tr, n, sizeof *a)))
        return 0;
    b->tr = a;
    b->cap = n;
    return 1;
}

/* Every piece cut by every contact segment, then (where cuts made fresh vertices) each piece mended
 * so that its neighbours' new vertices lie on its edges. 0 when out of memory or interrupted. */
static int bn__cut_pieces(bn__cx *c, bn__cutbuf *b)
{
    for (size_t g = 0; g < c->nsegs; g++) {
        size_t count = c->npieces;
        if (bn_interrupted() != BN_OK)   /* a big face's cuts take seconds: stop promptly */
            return 0;
        for (size_t k = 0; k < count; k++)
            if (!bn__cutbuf_reserve(b, c->pieces[k].n + 2) || !bn__cut(c, k, &c->segs[g], b->tl, b->tr))
                return 0;
    }
    if (c->nfresh > 0) {
        size_t count = c->npieces, mcap = 0;
        for (size_t k = 0; k < count; k++)
            mcap = mcap > c->pieces[k].n ? mcap : c->pieces[k].n;
        if (!bn__cutbuf_reserve(b, mcap * 65))
            return 0;
        for (size_t k = 0; k < count; k++) {
            if ((k & 1023) == 0 && bn_interrupted() != BN_OK)   /* pieces x fresh vertices: seconds on a big face */
                return 0;
            if (!bn__mend(c, k, b->tl, b->cap))
                return 0;
        }
    }
    return 1;
}

static int bn__cut_face(bn__cx *c, size_t f, bn_patch *src, size_t p0, size_t p1, const double (*poly)[2],
                        bn_scene_stats *st)
{
    bn__cutbuf b = {NULL, NULL, 0};
    size_t changed = 0, before;
    int ok = 0;
    c->npool = c->npieces = c->nfresh = 0;
    c->keep = 0;
    for (size_t p = p0; p < p1; p++)
        for (unsigned k = 0; k < src[p].ncorners; k++)
            c->keep = fmax(c->keep, bn_v3_dist(c->pv + 3 * src[p].corner[k],
                                               c->pv + 3 * src[p].corner[(k + 1) % src[p].ncorners]));
    c->keep *= BN__SLIVER;
    if (!bn__snap_corners(c, &c->s->faces[f], src + p0, p1 - p0, poly))
        return 0;
    for (size_t p = p0; p < p1; p++)
        if (!bn__new_piece(c, src[p].corner, src[p].ncorners, p, 0))
            return 0;
    if (!bn__cut_pieces(c, &b))
        goto done;
    before = c->np;
    for (size_t k = 0; k < c->npieces; k++) {
        const bn__piece *pc = &c->pieces[k];
        const bn_patch *o = &src[pc->orig];
        if (!pc->changed) {
            if (!bn__grow((void **)&c->patches, &c->np_cap, c->np + 1, sizeof *c->patches))
                goto done;
            c->patches[c->np++] = *o;
            continue;
        }
        if (!bn__emit_piece(c, f, o, c->pool + pc->off, pc->n))
            goto done;
    }
    if ((changed = bn__count_split(c, p0, p1)) == SIZE_MAX)
        goto done;
    st->contact_patches_split += changed;
    st->contact_patches_made += (c->np - before) - ((p1 - p0) - changed);
    ok = 1;
done:
    free(b.tl);
    free(b.tr);
    return ok;
}

/* Face q's contacts with face fi (polygon poly in fi's frame), once per fi (stamp); 0 when out of
 * memory. */
static int bn__visit(bn__cx *c, size_t fi, const double (*poly)[2], size_t *stamp, size_t q)
{
    const bn_face *f = &c->s->faces[fi];
    if (q == fi || stamp[q] == fi + 1 ||
        (!c->self && c->s->faces[q].object == f->object && c->s->obj_assembly[f->object]))
        return 1;
    stamp[q] = fi + 1;
    return bn__contacts_of(c, f, poly, f->nverts, &c->s->faces[q]);
}

/* The contact segments on face fi from every face near it (the grid's cells around its box, and the
 * big faces), or from every face when its box spans too many cells; 0 when out of memory. */
static int bn__face_contacts(bn__cx *c, bn__fgrid *g, size_t fi, const double (*poly)[2], size_t *stamp)
{
    const bn_face *f = &c->s->faces[fi];
    double lo[3], hi[3];
    int64_t a[3], b[3];
    bn__face_box(c->s, f, c->tol, lo, hi);
    bn__cell_range(g, lo, hi, a, b);
    if (bn__cells(a, b) > BN__BIG_CELLS) {
        for (size_t q = 0; q < c->s->nfaces; q++)
            if (!bn__visit(c, fi, poly, stamp, q))
                return 0;
        return 1;
    }
    for (int64_t z = a[2]; z <= b[2]; z++)
        for (int64_t y = a[1]; y <= b[1]; y++)
            for (int64_t x = a[0]; x <= b[0]; x++) {
                size_t h = bn__bucket(g, x, y, z);
                for (size_t i = g->start[h]; i < g->start[h + 1]; i++)
                    if (!bn__visit(c, fi, poly, stamp, g->items[i]))
                        return 0;
            }
    for (size_t i = 0; i < g->nbig; i++)
        if (!bn__visit(c, fi, poly, stamp, g->big[i]))
            return 0;
    return 1;
}

/* first[f] .. first[f + 1]: face f's patches (they come in face order); 0 if they do not. */
static int bn__face_firsts(const bn_patch *patches, size_t np, size_t nf, size_t *first)
{
    for (size_t p = 0; p < np; p++)
        first[patches[p].face + 1]++;
    for (size_t f = 0; f < nf; f++)
        first[f + 1] += first[f];
    for (size_t p = 0; p + 1 < np; p++)
        if (patches[p].face > patches[p + 1].face)
            return 0;
    return 1;
}

/* Face fi's patches as they are (no contact on it), or cut along its contact segments. */
static int bn__face_cut(bn__cx *c, size_t fi, bn_patch *patches, const size_t *first, const double (*poly)[2],
                        bn_scene_stats *st)
{
    if (c->nsegs == 0) {
        size_t n = first[fi + 1] - first[fi];
        if (!bn__grow((void **)&c->patches, &c->np_cap, c->np + n, sizeof *c->patches))
            return 0;
        memcpy(c->patches + c->np, patches + first[fi], n * sizeof *c->patches);
        c->np += n;
        return 1;
    }
    st->contact_segments += c->nsegs;
    st->contact_faces++;
    return bn__cut_face(c, fi, patches, first[fi], first[fi + 1], poly, st);
}

/* The cutter's state for scene s: tolerances from its size (gap when given), the patch vertices pv
 * (nv of them) to grow. */
static void bn__cx_init(bn__cx *c, bn_scene *s, double gap, int self, double *pv, size_t nv)
{
    double d[3];
    memset(c, 0, sizeof *c);
    c->s = s;
    c->patches = NULL;
    c->pv = pv;
    c->nv = c->nv_cap = nv;
    bn_v3_sub(s->hi, s->lo, d);
    c->edge = 1e-6 * bn_v3_len(d);
    c->tol = gap > 0 ? gap : c->edge;
    c->snap = 1e-9 * bn_v3_len(d);
    c->self = self || s->nobjs < 2;
}

/* Every face's contact segments found and its patches cut along them (into c->patches). 0 when out
 * of memory or interrupted. */
static int bn__cut_all_faces(bn__cx *c, bn__fgrid *g, bn_patch *patches, const size_t *first,
                             size_t *stamp, bn_scene_stats *st)
{
    bn_scene *s = c->s;
    for (size_t fi = 0; fi < s->nfaces; fi++) {
        const bn_face *f = &s->faces[fi];
        double poly[4][2];
        c->nsegs = 0;
        if (bn_interrupted() != BN_OK)
            return 0;
        bn__frame_of(s, f, &c->fr);
        for (unsigned k = 0; k < f->nverts; k++)
            bn__to2(&c->fr, bn__fvert(s, f, k), poly[k]);
        if (!bn__face_contacts(c, g, fi, (const double(*)[2])poly, stamp) ||
            !bn__face_cut(c, fi, patches, first, (const double(*)[2])poly, st))
            return 0;
    }
    return 1;
}

bn_status bn__mesh_contacts(bn_scene *s, double gap, int self, bn_patch **patches, size_t *np, double **pv,
                            size_t *nv, bn_error *err)
{
    bn__cx c;
    bn__fgrid g;
    size_t nf = s->nfaces, *first = NULL, *stamp = NULL;
    bn_scene_stats *st = &s->stats;
    bn_status rc = BN_ENOMEM;

    st->contact_segments = st->contact_faces = st->contact_patches_split = st->contact_patches_made = 0;
    bn__cx_init(&c, s, gap, self, *pv, *nv);
    if (!(c.tol > 0))
        return BN_OK;
    if (!bn__fgrid_build(s, c.tol, &g))
        goto fail;
    first = bn__calloc(nf + 1, sizeof(size_t));
    stamp = bn__calloc(nf, sizeof(size_t));
    if (!first || !stamp)
        goto fail;
    if (!bn__face_firsts(*patches, *np, nf, first)) {
        rc = bn_error_set(err, BN_EINTERNAL, "contact cuts: patches are not in face order");
        goto fail;
    }
    if (!bn__cut_all_faces(&c, &g, *patches, first, stamp, st))
        goto fail;
    free(*patches);
    *patches = c.patches;
    *np = c.np;
    *pv = c.pv;
    *nv = c.nv;
    c.patches = NULL;
    rc = BN_OK;
fail:
    if (rc != BN_OK) {
        *pv = c.pv;   /* grown or not, the caller owns it */
        *nv = c.nv;
        if (rc == BN_ENOMEM && bn_interrupted() != BN_OK)
            rc = bn_error_set(err, bn_interrupted(), "meshing interrupted while cutting patches along contact lines");
        else if (rc == BN_ENOMEM)
            bn_error_set(err, BN_ENOMEM, "out of memory while cutting patches along contact lines");
    }
    free(c.patches);
    free(c.pool);
    free(c.pieces);
    free(c.fresh);
    free(c.segs);
    free(first);
    free(stamp);
    bn__fgrid_free(&g);
    return rc;
}
