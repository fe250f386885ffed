/* The node tree over the patches: median splits along the longest axis, first of the planes
 * (volume clusters), then of each plane's patches (planar nodes). A plane is an input polygon or a
 * connected group of coplanar ones (hierarchy_internal.h). */
#include "hierarchy/hierarchy_internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct bn__key {
    double k;
    uint32_t id;
} bn__key;

static int bn__key_cmp(const void *a, const void *b)
{
    const bn__key *x = a, *y = b;
    if (x->k != y->k)
        return x->k < y->k ? -1 : 1;
    return x->id < y->id ? -1 : x->id > y->id;
}

typedef struct bn__tb {
    bn__tree *t;
    const bn_patch *patch;
    const bn_material *mat;
    const double *pverts;
    double *pc;               /* patch centroids */
    double *fc;               /* plane centroids (area-weighted), per plane */
    const uint32_t *plane_of; /* per input face: its plane */
    const unsigned char *cover;      /* per patch: its bn_cover class (NULL: none known) */
    uint32_t *face_first, *face_count, *byface;   /* per plane */
    size_t cursor;            /* next free slot in order */
    bn__key *keys;
} bn__tb;

static uint32_t bn__node_new(bn__tree *t, uint32_t parent)
{
    uint32_t v = (uint32_t)t->n++;
    t->parent[v] = parent;
    t->child[v] = BN__NONE;
    return v;
}

/* Area, box, reflectance and face of v from its children (or its patch). */
static void bn__node_finish(bn__tb *b, uint32_t v)
{
    bn__tree *t = b->t;
    double *box = t->box + 6 * v;
    if (t->child[v] == BN__NONE) {
        const bn_patch *p = &b->patch[t->order[t->lo[v]]];
        const double *rho = b->mat[p->material].rho;
        for (int c = 0; c < 3; c++) {
            box[c] = INFINITY;
            box[3 + c] = -INFINITY;
            t->rho_max[3 * v + c] = (float)rho[c];
        }
        for (unsigned k = 0; k < p->ncorners; k++)
            for (int c = 0; c < 3; c++) {
                double x = b->pverts[3 * p->corner[k] + c];
                box[c] = fmin(box[c], x);
                box[3 + c] = fmax(box[3 + c], x);
            }
        t->area[v] = p->area;
        t->plane[v] = (int32_t)b->plane_of[p->face];
        memcpy(t->normal + 3 * v, p->normal, 3 * sizeof(double));
        t->spread[v] = 0;
        t->cover[v] = b->cover ? b->cover[t->order[t->lo[v]]] : BN_COVER_OPEN;
        return;
    }
    uint32_t a = t->child[v], c2 = a + 1;
    t->area[v] = t->area[a] + t->area[c2];
    for (int c = 0; c < 3; c++) {
        box[c] = fmin(t->box[6 * a + c], t->box[6 * c2 + c]);
        box[3 + c] = fmax(t->box[6 * a + 3 + c], t->box[6 * c2 + 3 + c]);
        t->rho_max[3 * v + c] = fmaxf(t->rho_max[3 * a + c], t->rho_max[3 * c2 + c]);
    }
    t->plane[v] = t->plane[a] == t->plane[c2] ? t->plane[a] : -1;
    t->cover[v] = t->cover[a] == t->cover[c2] ? t->cover[a] : BN_COVER_OPEN;
    {   /* the normal cone: axis the area-weighted mean, spread bounded through the children's cones */
        double *nv = t->normal + 3 * v, len;
        for (int c = 0; c < 3; c++)
            nv[c] = t->area[a] * t->normal[3 * a + c] + t->area[c2] * t->normal[3 * c2 + c];
        len = bn_v3_len(nv);
        if (t->plane[v] >= 0 || !(len > 1e-12 * t->area[v])) {
            memcpy(nv, t->normal + 3 * a, 3 * sizeof(double));
            t->spread[v] = t->plane[v] >= 0 ? 0 : BN_PI;
        } else {
            bn_v3_scale(nv, 1 / len, nv);
            t->spread[v] = 0;
            for (uint32_t k = a; k <= c2; k++) {
                double d = fmax(-1.0, fmin(1.0, bn_v3_dot(nv, t->normal + 3 * k)));
                t->spread[v] = fmax(t->spread[v], acos(d) + t->spread[k]);
            }
            t->spread[v] = fmin(t->spread[v], BN_PI);
        }
    }
    t->lo[v] = t->lo[a];
    t->hi[v] = t->hi[c2];
}

/* Sorts ids[0..m) by the coordinate of cent (3 per id) along the longest axis of their extent. */
static void bn__median_sort(bn__tb *b, uint32_t *ids, size_t m, const double *cent)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    int ax = 0;
    for (size_t k = 0; k < m; k++)
        for (int c = 0; c < 3; c++) {
            lo[c] = fmin(lo[c], cent[3 * ids[k] + c]);
            hi[c] = fmax(hi[c], cent[3 * ids[k] + c]);
        }
    for (int c = 1; c < 3; c++)
        if (hi[c] - lo[c] > hi[ax] - lo[ax])
            ax = c;
    for (size_t k = 0; k < m; k++) {
        b->keys[k].k = cent[3 * ids[k] + ax];
        b->keys[k].id = ids[k];
    }
    qsort(b->keys, m, sizeof *b->keys, bn__key_cmp);
    for (size_t k = 0; k < m; k++)
        ids[k] = b->keys[k].id;
}

static void bn__build_patches(bn__tb *b, uint32_t v, size_t lo, size_t hi);
static void bn__build_classes(bn__tb *b, uint32_t v, size_t lo, size_t hi);

/* Node v over order[lo..hi), its two children over [lo, mid) and [mid, hi); the second split by cover
 * class first when by_class. */
static void bn__build_split(bn__tb *b, uint32_t v, size_t lo, size_t mid, size_t hi, int by_class)
{
    bn__tree *t = b->t;
    t->lo[v] = (uint32_t)lo;
    t->hi[v] = (uint32_t)hi;
    uint32_t a = bn__node_new(t, v);
    bn__node_new(t, v);
    t->child[v] = a;
    bn__build_patches(b, a, lo, mid);
    if (by_class)
        bn__build_classes(b, a + 1, mid, hi);
    else
        bn__build_patches(b, a + 1, mid, hi);
    bn__node_finish(b, v);
}

/* Planar nodes over order[lo..hi) (patches of one plane). */
static void bn__build_patches(bn__tb *b, uint32_t v, size_t lo, size_t hi)
{
    bn__tree *t = b->t;
    if (hi - lo > 1) {
        bn__median_sort(b, t->order + lo, hi - lo, b->pc);
        bn__build_split(b, v, lo, lo + (hi - lo) / 2, hi, 0);
        return;
    }
    t->lo[v] = (uint32_t)lo;
    t->hi[v] = (uint32_t)hi;
    bn__node_finish(b, v);
}

/* Planar nodes over order[lo..hi), sorted by cover class: each class's patches apart from the next's. */
static void bn__build_classes(bn__tb *b, uint32_t v, size_t lo, size_t hi)
{
    bn__tree *t = b->t;
    size_t mid = lo;
    while (mid < hi && b->cover[t->order[mid]] == b->cover[t->order[lo]])
        mid++;
    if (mid == hi)
        bn__build_patches(b, v, lo, hi);
    else
        bn__build_split(b, v, lo, mid, hi, 1);
}

/* A plane's planar nodes over order[lo..hi): its patches of each cover class (bn_rt_cover_classes:
 * open, shut under something near, seeing back faces, enclosed) first split apart, so that no node holds
 * two kinds: the covered ones receive little or nothing, and a node's mean F would hand them the light
 * their open neighbours see (the floor under a slab 1 mm above it: 3.6x what dense F gives it at 3,000
 * patches, 7x at 6,000; under the bunny of the bunny box, 20 to 40 times the tracer's). */
static void bn__build_plane(bn__tb *b, uint32_t v, size_t lo, size_t hi)
{
    bn__tree *t = b->t;
    uint32_t *tmp = b->cover ? bn__malloc_array(hi - lo, sizeof(uint32_t)) : NULL;
    if (!tmp) {
        bn__build_patches(b, v, lo, hi);
        return;
    }
    size_t n = 0;
    for (unsigned c = BN_COVER_OPEN; c <= BN_COVER_ENCLOSED; c++)   /* stable, by class */
        for (size_t k = lo; k < hi; k++)
            if (b->cover[t->order[k]] == c)
                tmp[n++] = t->order[k];
    memcpy(t->order + lo, tmp, n * sizeof(uint32_t));
    free(tmp);
    bn__build_classes(b, v, lo, hi);
}

/* Clusters over planes[0..m). */
static void bn__build_faces(bn__tb *b, uint32_t v, uint32_t *faces, size_t m)
{
    bn__tree *t = b->t;
    if (m == 1) {
        uint32_t f = faces[0];
        size_t lo = b->cursor;
        memcpy(t->order + lo, b->byface + b->face_first[f], b->face_count[f] * sizeof(uint32_t));
        b->cursor += b->face_count[f];
        bn__build_plane(b, v, lo, b->cursor);
        return;
    }
    size_t mid = m / 2;
    bn__median_sort(b, faces, m, b->fc);
    uint32_t a = bn__node_new(t, v);
    bn__node_new(t, v);
    t->child[v] = a;
    bn__build_faces(b, a, faces, mid);
    bn__build_faces(b, a + 1, faces + mid, m - mid);
    bn__node_finish(b, v);
}

void bn__tree_free(bn__tree *t)
{
    free(t->parent);
    free(t->child);
    free(t->lo);
    free(t->hi);
    free(t->plane);
    free(t->pn);
    free(t->pp);
    free(t->pthick);
    free(t->area);
    free(t->box);
    free(t->rho_max);
    free(t->normal);
    free(t->spread);
    free(t->cover);
    free(t->order);
    free(t->leaf);
    free(t->cum_area);
    memset(t, 0, sizeof *t);
}

size_t bn__tree_bytes(const bn__tree *t)
{
    return t->n * (5 * sizeof(uint32_t) + 11 * sizeof(double) + 3 * sizeof(float) + 1) +
           t->npatch * (2 * sizeof(uint32_t) + sizeof(double)) + t->nplanes * 7 * sizeof(double);
}

typedef struct bn__edge {
    size_t a, b;              /* vertex indices, a < b */
    uint32_t f;
} bn__edge;

static int bn__edge_cmp(const void *x, const void *y)
{
    const bn__edge *p = x, *q = y;
    if (p->a != q->a)
        return p->a < q->a ? -1 : 1;
    if (p->b != q->b)
        return p->b < q->b ? -1 : 1;
    return p->f < q->f ? -1 : p->f > q->f;
}

/* Does face f lie within BN__COPLANAR of the plane (n, p)? *thick: the largest distance seen. */
static int bn__on_plane(const bn_face *f, const size_t *idx, const double *v, const double n[3], const double p[3],
                        double tol, double *thick)
{
    double d[3], h = 0;
    if (bn_v3_dot(f->normal, n) < cos(BN__COPLANAR))
        return 0;
    for (unsigned k = 0; k < f->nverts; k++) {
        const double *x = v + 3 * idx[f->first + k];
        bn_v3_sub(x, p, d);
        double off = fabs(bn_v3_dot(d, n));
        if (off > BN__COPLANAR * bn_v3_len(d) + tol)
            return 0;
        h = fmax(h, off);
    }
    *thick = fmax(*thick, h);
    return 1;
}

/* The faces sharing an edge with each face: adj[adj_start[k] .. adj_start[k + 1]) (both allocated here,
 * NULL without memory: 0). */
static int bn__face_adjacency(const bn_scene *s, size_t **adj_start_out, uint32_t **adj_out)
{
    size_t nf, ni, ne = 0;
    const bn_face *f = bn_scene_faces(s, &nf);
    const size_t *idx = bn_scene_face_indices(s, &ni);
    bn__edge *e = bn__malloc_array(4 * nf + 1, sizeof *e);
    size_t *adj_start = bn__calloc(nf + 1, sizeof *adj_start), *pos = NULL;
    uint32_t *adj = NULL;
    if (!e || !adj_start)
        goto fail;
    for (size_t k = 0; k < nf; k++)
        for (unsigned j = 0; j < f[k].nverts; j++) {
            size_t x = idx[f[k].first + j], y = idx[f[k].first + (j + 1) % f[k].nverts];
            e[ne].a = x < y ? x : y;
            e[ne].b = x < y ? y : x;
            e[ne++].f = (uint32_t)k;
        }
    qsort(e, ne, sizeof *e, bn__edge_cmp);
    for (int fill = 0; fill < 2; fill++) {   /* count, then fill (both directions) */
        if (fill) {
            for (size_t k = 0; k < nf; k++)
                adj_start[k + 1] += adj_start[k];
            adj = bn__malloc_array(adj_start[nf] + 1, sizeof *adj);
            pos = bn__malloc_array(nf + 1, sizeof *pos);
            if (!adj || !pos)
                goto fail;
            memcpy(pos, adj_start, nf * sizeof *pos);
        }
        for (size_t i = 0, j; i < ne; i = j) {
            for (j = i + 1; j < ne && e[j].a == e[i].a && e[j].b == e[i].b; j++)
                ;
            for (size_t p = i; p < j; p++)
                for (size_t q = i; q < j; q++)
                    if (e[p].f != e[q].f) {
                        if (fill)
                            adj[pos[e[p].f]++] = e[q].f;
                        else
                            adj_start[e[p].f + 1]++;
                    }
        }
    }
    free(pos);
    free(e);
    *adj_start_out = adj_start;
    *adj_out = adj;
    return 1;
fail:
    free(pos);
    free(e);
    free(adj_start);
    free(adj);
    return 0;
}

/* Plane ng from face k: every face reached across shared edges (adjacency adj_start, adj) that lies on
 * k's plane within tol joins it (breadth first; queue: nf entries). */
static void bn__flood_plane(const bn_scene *s, bn__tree *t, uint32_t *plane_of, const size_t *adj_start,
                            const uint32_t *adj, uint32_t *queue, size_t k, size_t ng, double tol)
{
    size_t nv, ni, head = 0, tail = 0;
    const bn_face *f = bn_scene_faces(s, NULL);
    const double *v = bn_scene_vertices(s, &nv);
    const size_t *idx = bn_scene_face_indices(s, &ni);
    const double *n = t->pn + 3 * ng, *p = t->pp + 3 * ng;
    bn__on_plane(&f[k], idx, v, n, p, tol, &t->pthick[ng]);
    queue[tail++] = (uint32_t)k;
    while (head < tail) {
        uint32_t g = queue[head++];
        for (size_t a = adj_start[g]; a < adj_start[g + 1]; a++) {
            uint32_t h = adj[a];
            if (plane_of[h] == UINT32_MAX && bn__on_plane(&f[h], idx, v, n, p, tol, &t->pthick[ng])) {
                plane_of[h] = (uint32_t)ng;
                queue[tail++] = h;
            }
        }
    }
}

/* plane_of[f] for every face, and the planes' normal, point and thickness: with merge, faces that
 * share an edge join the plane of the face that started it while they lie within BN__COPLANAR of
 * it (measured against that first face, so a finely cut curved surface cannot creep into one plane). */
static bn_status bn__planes(const bn_scene *s, int merge, bn__tree *t, uint32_t *plane_of, bn_error *err)
{
    size_t nf, nv, ni, ng = 0;
    const bn_face *f = bn_scene_faces(s, &nf);
    const double *v = bn_scene_vertices(s, &nv);
    const size_t *idx = bn_scene_face_indices(s, &ni);
    double tol;
    size_t *adj_start = NULL;
    uint32_t *adj = NULL, *queue = NULL;
    bn_status st = BN_OK;
    tol = 1e-9 * fmax(bn_scene_diameter(s), 1e-300);
    t->pn = bn__malloc_array(3 * nf + 1, sizeof(double));
    t->pp = bn__malloc_array(3 * nf + 1, sizeof(double));
    t->pthick = bn__calloc(nf + 1, sizeof(double));
    if (!t->pn || !t->pp || !t->pthick ||
        (merge && (!(queue = bn__malloc_array(nf + 1, sizeof *queue)) || !bn__face_adjacency(s, &adj_start, &adj)))) {
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the planes of %zu polygons", nf);
        goto done;
    }
    for (size_t k = 0; k < nf; k++)
        plane_of[k] = UINT32_MAX;
    for (size_t k = 0; k < nf; k++) {
        if (plane_of[k] != UINT32_MAX)
            continue;
        memcpy(t->pn + 3 * ng, f[k].normal, 3 * sizeof(double));
        memcpy(t->pp + 3 * ng, v + 3 * idx[f[k].first], 3 * sizeof(double));
        plane_of[k] = (uint32_t)ng;
        if (merge)
            bn__flood_plane(s, t, plane_of, adj_start, adj, queue, k, ng, tol);
        ng++;
    }
    t->nplanes = ng;
done:
    free(adj_start);
    free(adj);
    free(queue);
    return st;
}

/* The tree's arrays for cap nodes over np patches; 0 when out of memory. */
static int bn__tree_alloc(bn__tree *t, size_t cap, size_t np)
{
    t->parent = bn__malloc_array(cap, sizeof(uint32_t));
    t->child = bn__malloc_array(cap, sizeof(uint32_t));
    t->lo = bn__malloc_array(cap, sizeof(uint32_t));
    t->hi = bn__malloc_array(cap, sizeof(uint32_t));
    t->plane = bn__malloc_array(cap, sizeof(int32_t));
    t->area = bn__malloc_array(cap, sizeof(double));
    t->box = bn__malloc_array(6 * cap, sizeof(double));
    t->rho_max = bn__malloc_array(3 * cap, sizeof(float));
    t->normal = bn__malloc_array(3 * cap, sizeof(double));
    t->spread = bn__malloc_array(cap, sizeof(double));
    t->cover = bn__malloc_array(cap, 1);
    t->order = bn__malloc_array(np, sizeof(uint32_t));
    t->leaf = bn__malloc_array(np, sizeof(uint32_t));
    t->cum_area = bn__malloc_array(np + 1, sizeof(double));
    return t->parent && t->child && t->lo && t->hi && t->plane && t->area && t->box && t->rho_max && t->normal &&
           t->spread && t->cover && t->order && t->leaf && t->cum_area;
}

/* The builder's scratch over np patches and nf faces; 0 when out of memory. */
static int bn__tb_alloc(bn__tb *b, size_t np, size_t nf)
{
    b->pc = bn__malloc_array(3 * np, sizeof(double));
    b->fc = bn__calloc(3 * nf, sizeof(double));
    b->face_first = bn__calloc(nf + 1, sizeof(uint32_t));
    b->face_count = bn__calloc(nf + 1, sizeof(uint32_t));
    b->byface = bn__malloc_array(np, sizeof(uint32_t));
    b->keys = bn__malloc_array(np > nf ? np : nf, sizeof(bn__key));
    return b->pc && b->fc && b->face_first && b->face_count && b->byface && b->keys;
}

static void bn__tb_free(bn__tb *b)
{
    free(b->pc);
    free(b->fc);
    free(b->face_first);
    free(b->face_count);
    free(b->byface);
    free(b->keys);
}

/* Patches by plane (a counting sort keeps the mesher's order inside a plane), each plane's
 * area-weighted centroid, and the planes that hold patches in faces[0 .. *nfaces). */
static bn_status bn__by_plane(bn__tb *b, size_t np, size_t nf, uint32_t *faces, size_t *nfaces, bn_error *err)
{
    const bn__tree *t = b->t;
    double *farea = bn__calloc(nf + 1, sizeof(double));
    uint32_t *fill = bn__calloc(nf + 1, sizeof(uint32_t));
    if (!farea || !fill) {
        free(farea);
        free(fill);
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy of %zu patches", np);
    }
    for (size_t i = 0; i < np; i++) {
        size_t f = b->plane_of[b->patch[i].face];
        b->face_count[f]++;
        memcpy(b->pc + 3 * i, b->patch[i].centroid, 3 * sizeof(double));
        for (int c = 0; c < 3; c++)
            b->fc[3 * f + c] += b->patch[i].area * b->patch[i].centroid[c];
        farea[f] += b->patch[i].area;
    }
    *nfaces = 0;
    for (size_t f = 0, acc = 0; f < t->nplanes; f++) {
        b->face_first[f] = (uint32_t)acc;
        acc += b->face_count[f];
        if (b->face_count[f]) {
            faces[(*nfaces)++] = (uint32_t)f;
            for (int c = 0; c < 3; c++)
                b->fc[3 * f + c] /= farea[f];
        }
    }
    for (size_t i = 0; i < np; i++) {
        size_t f = b->plane_of[b->patch[i].face];
        b->byface[b->face_first[f] + fill[f]++] = (uint32_t)i;
    }
    free(farea);
    free(fill);
    return BN_OK;
}

bn_status bn__tree_build(const bn_scene *s, int merge, const unsigned char *cover, bn__tree *t, bn_error *err)
{
    size_t np, nf, nm, npv, nfaces = 0;
    bn__tb b;
    uint32_t *faces = NULL, *plane_of = NULL;
    bn_status st = BN_OK;
    memset(t, 0, sizeof *t);
    memset(&b, 0, sizeof b);
    b.patch = bn_scene_patches(s, &np);
    bn_scene_faces(s, &nf);
    b.mat = bn_scene_materials(s, &nm);
    b.pverts = bn_scene_patch_vertices(s, &npv);
    b.cover = cover;
    if (np == 0)
        return bn_error_set(err, BN_EINPUT, "%s: no patches (mesh the scene first)", bn_scene_path(s));
    if (np >= (size_t)UINT32_MAX / 2)
        return bn_error_set(err, BN_EINPUT, "%s: %zu patches; the hierarchy holds at most %u", bn_scene_path(s), np,
                            UINT32_MAX / 2 - 1);
    t->npatch = np;
    b.t = t;
    faces = bn__malloc_array(nf + 1, sizeof(uint32_t));
    plane_of = bn__malloc_array(nf + 1, sizeof(uint32_t));
    b.plane_of = plane_of;
    if (!bn__tree_alloc(t, 2 * np, np) || !bn__tb_alloc(&b, np, nf) || !faces || !plane_of)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy of %zu patches", np);
    if (st == BN_OK)
        st = bn__planes(s, merge, t, plane_of, err);
    if (st == BN_OK)
        st = bn__by_plane(&b, np, nf, faces, &nfaces, err);
    if (st == BN_OK) {
        bn__node_new(t, BN__NONE);
        bn__build_faces(&b, 0, faces, nfaces);
        t->cum_area[0] = 0;
        for (size_t k = 0; k < np; k++)
            t->cum_area[k + 1] = t->cum_area[k] + b.patch[t->order[k]].area;
        for (uint32_t v = 0; v < t->n; v++)
            if (t->child[v] == BN__NONE)
                t->leaf[t->order[t->lo[v]]] = v;
    }
    bn__tb_free(&b);
    free(faces);
    free(plane_of);
    if (st != BN_OK)
        bn__tree_free(t);
    return st;
}

void bn__tree_sphere(const bn__tree *t, uint32_t v, double c[3], double *rad)
{
    const double *b = t->box + 6 * (size_t)v;
    double h[3];
    for (int k = 0; k < 3; k++) {
        c[k] = 0.5 * (b[k] + b[3 + k]);
        h[k] = 0.5 * (b[3 + k] - b[k]);
    }
    *rad = bn_v3_len(h);
}

/* The unit direction between the bounding spheres' centres of r and s. */
static void bn__tree_dir(const void *ctx, uint32_t r, uint32_t s, double u[3])
{
    double cr[3], cs[3], rad;
    bn__tree_sphere(ctx, r, cr, &rad);
    bn__tree_sphere(ctx, s, cs, &rad);
    bn_v3_sub(cs, cr, u);
    bn_v3_normalize(u);
}

bn__hop_shape bn__tree_shape(const bn__tree *t)
{
    return (bn__hop_shape){t->n,     t->npatch, t->child, t->parent, t->lo,        t->order,
                           t->plane, t->area,   t->normal, bn__tree_dir, (const void *)t};
}
