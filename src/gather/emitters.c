/* The final gather's emitters: the scene's emitting faces, with the coplanar pieces of one light merged.
 *
 * A light cut into many triangles (a quad as two, a panel as a grid, a window traced from a texture)
 * is one convex polygon to the closed form: Lambert's contour integral over the union is the sum over
 * the pieces (the inner edges cancel), and the union's spherical polygon samples its visibility as
 * one face's does. So the emitting faces that share corners, lie in one plane, emit the same radiance
 * and tile a convex polygon of at most BN__EM_CORNERS corners are one emitter: the gather's cost per
 * pixel is then one face's however finely the light was cut, and its answer the same (the pieces'
 * closed forms summed; visibility sampled over the whole instead of per piece). Pieces that are not
 * coplanar (a lampshade, a bulb), differ in radiance or make a concave or many-cornered outline stay
 * faces, and above tree_emitters of them the light tree picks among them. */
#include "gather/gather_internal.h"
#include "base/internal.h"
#include "base/vec.h"
#include "formfactor/ff_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* A merged light's outline has at most this many corners (its part in front of a point, clipped by
 * that point's plane, one more: within BN__FF_POLY_MAX). */
#define BN__EM_CORNERS 6
/* The pieces tile their convex hull when their areas sum to its area within this fraction. */
#define BN__EM_TILE 1e-6

_Static_assert(BN__EM_CORNERS + 1 <= BN__FF_POLY_MAX, "a merged light's clipped outline fits the closed form");
_Static_assert(BN__EM_CORNERS <= BN__EMITTER_CORNERS, "a merged light's outline fits bn__emitter");

/* e's area, vertex mean and diameter from its corners. */
static void bn__em_fill(bn__emitter *e)
{
    e->area = bn__poly_area(e->v, e->nv, NULL);
    memset(e->c, 0, sizeof e->c);
    e->diam = 0;
    for (size_t k = 0; k < e->nv; k++) {
        bn_v3_madd(e->c, 1.0 / (double)e->nv, e->v + 3 * k, e->c);
        for (size_t m = k + 1; m < e->nv; m++)
            e->diam = fmax(e->diam, bn_v3_dist(e->v + 3 * k, e->v + 3 * m));
    }
}

/* Every emitting face as one emitter. */
static bn_status bn__em_faces(bn__gather *G, bn_error *err)
{
    size_t nf, nvert, nidx;
    const bn_face *faces = bn_scene_faces(G->scene, &nf);
    const double *verts = bn_scene_vertices(G->scene, &nvert);
    const size_t *idx = bn_scene_face_indices(G->scene, &nidx);
    G->em = bn__calloc(bn_scene_emitter_count(G->scene) + 1, sizeof *G->em);
    if (!G->em)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    for (size_t f = 0; f < nf; f++) {
        double Le[3];
        bn__emitter *e = &G->em[G->nem];
        bn_scene_face_emission(G->scene, f, Le);
        if (!(Le[0] > 0 || Le[1] > 0 || Le[2] > 0))
            continue;
        e->nv = faces[f].nverts;
        for (size_t k = 0; k < e->nv; k++)
            memcpy(e->v + 3 * k, verts + 3 * idx[faces[f].first + k], 3 * sizeof(double));
        memcpy(e->n, faces[f].normal, sizeof e->n);
        memcpy(e->Le, Le, sizeof e->Le);
        e->face = f;
        bn__em_fill(e);
        G->nem++;
    }
    G->faces = G->nem;
    return BN_OK;
}

/* A corner of an emitter, for finding the emitters that share corners. */
typedef struct bn__em_corner {
    double p[3];
    size_t e;
} bn__em_corner;

static int bn__em_corner_cmp(const void *a, const void *b)
{
    const double *p = ((const bn__em_corner *)a)->p, *q = ((const bn__em_corner *)b)->p;
    for (int k = 0; k < 3; k++)
        if (p[k] != q[k])
            return p[k] < q[k] ? -1 : 1;
    return 0;
}

/* set[e]: the lowest emitter joined to e through shared corners (the same coordinates, exactly). */
static size_t *bn__em_sets(const bn__gather *G)
{
    size_t nc = 0, *set = bn__malloc_array(G->nem, sizeof *set);
    bn__em_corner *c = bn__malloc_array(G->nem, BN__EMITTER_CORNERS * sizeof *c);
    if (!set || !c) {
        free(set);
        free(c);
        return NULL;
    }
    for (size_t e = 0; e < G->nem; e++) {
        set[e] = e;
        for (size_t k = 0; k < G->em[e].nv; k++, nc++) {
            memcpy(c[nc].p, G->em[e].v + 3 * k, sizeof c[nc].p);
            c[nc].e = e;
        }
    }
    qsort(c, nc, sizeof *c, bn__em_corner_cmp);
    for (size_t k = 1; k < nc; k++)
        if (!bn__em_corner_cmp(&c[k - 1], &c[k]))
            bn__uf_union(set, c[k - 1].e, c[k].e);
    for (size_t e = 0; e < G->nem; e++)
        set[e] = bn__uf_find(set, e);
    free(c);
    return set;
}

/* A corner in the light's plane: its coordinates there and where it is in 3-D. */
typedef struct bn__em_pt {
    double s, t;
    const double *x;
} bn__em_pt;

static int bn__em_pt_cmp(const void *a, const void *b)
{
    const bn__em_pt *p = a, *q = b;
    if (p->s != q->s)
        return p->s < q->s ? -1 : 1;
    return (p->t > q->t) - (p->t < q->t);
}

/* Twice the signed area of (o, a, b) less tol times |ob|: <= 0 when a is not clearly left of o -> b. */
static double bn__em_turn(const bn__em_pt *o, const bn__em_pt *a, const bn__em_pt *b, double tol)
{
    double cr = (a->s - o->s) * (b->t - o->t) - (a->t - o->t) * (b->s - o->s);
    return cr - tol * hypot(b->s - o->s, b->t - o->t);
}

/* The convex hull of p[0 .. np) (sorted), counter-clockwise, corners within tol of a line through their
 * neighbours dropped (Andrew's monotone chain) into h (2 np); its corner count. */
static size_t bn__em_hull(const bn__em_pt *p, size_t np, double tol, bn__em_pt *h)
{
    size_t k = 0;
    for (size_t i = 0; i < np; i++) {
        while (k >= 2 && bn__em_turn(&h[k - 2], &h[k - 1], &p[i], tol) <= 0)
            k--;
        h[k++] = p[i];
    }
    for (size_t i = np - 1, lo = k + 1; i-- > 0;) {
        while (k >= lo && bn__em_turn(&h[k - 2], &h[k - 1], &p[i], tol) <= 0)
            k--;
        h[k++] = p[i];
    }
    return k > 1 ? k - 1 : k;
}

/* Whether em[m[0 .. nm)] are one light: the same radiance, in one plane (normals within 1e-9, corners
 * within eps of the first's plane). */
static int bn__em_alike(const bn__gather *G, const size_t *m, size_t nm)
{
    const bn__emitter *a = &G->em[m[0]];
    for (size_t i = 1; i < nm; i++) {
        const bn__emitter *b = &G->em[m[i]];
        if (memcmp(a->Le, b->Le, sizeof a->Le) || bn_v3_dot(a->n, b->n) < 1 - 1e-9)
            return 0;
        for (size_t k = 0; k < b->nv; k++) {
            double d[3];
            bn_v3_sub(b->v + 3 * k, a->v, d);
            if (!(fabs(bn_v3_dot(d, a->n)) <= G->eps))
                return 0;
        }
    }
    return 1;
}

/* em[m[0 .. nm)] as one emitter in *out when they are one light tiling a convex polygon of at most
 * BN__EM_CORNERS corners (p: room for their corners, h for twice as many); else 0. */
static int bn__em_merge(const bn__gather *G, const size_t *m, size_t nm, bn__em_pt *p, bn__em_pt *h,
                        bn__emitter *out)
{
    const bn__emitter *a = &G->em[m[0]];
    double s[3], t[3], S = 0, H = 0;
    size_t np = 0, nh;
    if (!bn__em_alike(G, m, nm))
        return 0;
    bn_v3_sub(a->v + 3, a->v, s);   /* (s, t, n): right-handed, so counter-clockwise in (s, t) is from the front */
    if (!(bn_v3_normalize(s) > 0))
        return 0;
    bn_v3_cross(a->n, s, t);
    for (size_t i = 0; i < nm; i++) {
        const bn__emitter *b = &G->em[m[i]];
        S += b->area;
        for (size_t k = 0; k < b->nv; k++, np++) {
            double d[3];
            bn_v3_sub(b->v + 3 * k, a->v, d);
            p[np] = (bn__em_pt){bn_v3_dot(d, s), bn_v3_dot(d, t), b->v + 3 * k};
        }
    }
    qsort(p, np, sizeof *p, bn__em_pt_cmp);
    nh = bn__em_hull(p, np, G->eps, h);
    if (nh < 3 || nh > BN__EM_CORNERS)
        return 0;
    for (size_t k = 0; k < nh; k++)
        H += h[k].s * h[(k + 1) % nh].t - h[(k + 1) % nh].s * h[k].t;
    if (!(fabs(H / 2 - S) <= BN__EM_TILE * S))   /* a hole, a notch, or pieces overlapping */
        return 0;
    *out = *a;
    out->nv = nh;
    for (size_t k = 0; k < nh; k++)
        memcpy(out->v + 3 * k, h[k].x, 3 * sizeof(double));
    bn__em_fill(out);
    return 1;
}

/* The emitters grouped by set (bn__em_sets): the members of the group whose lowest emitter is r are
 * mem[at[r] .. at[r + 1]) in ascending order. */
static int bn__em_groups(size_t nem, const size_t *set, size_t **at, size_t **mem)
{
    *at = bn__calloc(nem + 1, sizeof **at);
    *mem = bn__malloc_array(nem, sizeof **mem);
    if (!*at || !*mem)
        return 0;
    for (size_t e = 0; e < nem; e++)
        (*at)[set[e] + 1]++;
    for (size_t e = 0; e < nem; e++)
        (*at)[e + 1] += (*at)[e];
    for (size_t e = 0, *fill = *at; e < nem; e++)
        (*mem)[fill[set[e]]++] = e;
    for (size_t e = nem; e > 0; e--)   /* the fill moved each start to the next group's: moved back */
        (*at)[e] = (*at)[e - 1];
    (*at)[0] = 0;
    return 1;
}

/* Replaces the emitters by the merged ones (each group that bn__em_merge accepts as one), in the order of
 * their lowest faces, and records each emitting face's emitter in G->owner; false when out of memory. */
static int bn__em_replace(bn__gather *G, const size_t *set, const size_t *at, const size_t *mem)
{
    size_t big = 1, nout = 0, nf;
    bn__em_pt *p, *h;
    bn__emitter *out = bn__calloc(G->nem + 1, sizeof *out);
    unsigned char *merged = bn__calloc(G->nem, 1);
    bn_scene_faces(G->scene, &nf);
    for (size_t e = 0; e < G->nem; e++)
        big = at[e + 1] - at[e] > big ? at[e + 1] - at[e] : big;
    p = bn__malloc_array(big, BN__EMITTER_CORNERS * sizeof *p);
    h = bn__malloc_array(big, 2 * BN__EMITTER_CORNERS * sizeof *h);
    G->owner = bn__malloc_array(nf, sizeof *G->owner);
    int ok = out && merged && p && h && G->owner;
    if (G->owner)
        memset(G->owner, 0xff, nf * sizeof *G->owner);   /* faces that emit nothing: no emitter's */
    for (size_t e = 0; ok && e < G->nem; e++) {
        size_t nm = at[e + 1] - at[e];
        if (set[e] == e && nm > 1 && bn__em_merge(G, mem + at[e], nm, p, h, &out[nout])) {
            merged[e] = 1;
            for (size_t i = 0; i < nm; i++)
                G->owner[G->em[mem[at[e] + i]].face] = (uint32_t)nout;
            nout++;
        } else if (!merged[set[e]]) {
            out[nout] = G->em[e];
            G->owner[G->em[e].face] = (uint32_t)nout++;
        }
    }
    free(p);
    free(h);
    free(merged);
    if (ok) {
        free(G->em);
        G->em = out;
        G->nem = nout;
    } else {
        free(out);
    }
    return ok;
}

bn_status bn__gather_emitters(bn__gather *G, int merge, bn_error *err)
{
    size_t *set, *at = NULL, *mem = NULL;
    bn_status st = bn__em_faces(G, err);
    if (st != BN_OK || !merge || G->nem < 2 || G->nem >= UINT32_MAX)
        return st;
    set = bn__em_sets(G);
    int ok = set && bn__em_groups(G->nem, set, &at, &mem) && bn__em_replace(G, set, at, mem);
    free(set);
    free(at);
    free(mem);
    return ok ? BN_OK : bn_error_set(err, BN_ENOMEM, "out of memory merging %zu emitting faces", G->faces);
}
