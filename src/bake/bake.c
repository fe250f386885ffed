/* Baking per-patch values to vertices: weld patch vertices across faces, split each point's fan
 * into smooth surfaces (same material, normals within the crease angle), and average the
 * patches of each surface by area:  x_v = sum_{p in g(v)} A_p x_p / sum_{p in g(v)} A_p. */
#include "bounce/bake.h"
#include "bake/bake_internal.h"
#include "base/internal.h"
#include "base/vec.h"
#include "bounce/rt.h"

#include <math.h>
#include <string.h>

static int bn__cmp_tj(const void *x, const void *y)
{
    const struct bn__tj *p = x, *q = y;
    if (p->len != q->len)
        return p->len > q->len ? -1 : 1;
    if (p->v != q->v)
        return p->v < q->v ? -1 : 1;
    return (p->a > q->a) - (p->a < q->a);
}

static int bn__cmp_x(const void *a, const void *b)
{
    const bn__xkey *p = a, *q = b;
    if (p->x != q->x)
        return p->x < q->x ? -1 : 1;
    return p->i < q->i ? -1 : (p->i > q->i);
}

bn__xkey *bn__xsort(const double *pos, size_t n)
{
    bn__xkey *ox = bn__malloc_array(n ? n : 1, sizeof *ox);
    if (!ox)
        return NULL;
    for (size_t v = 0; v < n; v++) {
        ox[v].x = pos[3 * v];
        ox[v].i = v;
    }
    qsort(ox, n, sizeof *ox, bn__cmp_x);
    return ox;
}

size_t bn__xfirst(const bn__xkey *ox, size_t n, double xlo)
{
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (ox[mid].x < xlo)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

int bn__inside_segment(const double A[3], const double B[3], const double P[3], double eps, double dist, double *t)
{
    double ab[3], ap[3], d[3], len2, len;
    bn_v3_sub(B, A, ab);
    bn_v3_sub(P, A, ap);
    len2 = bn_v3_dot(ab, ab);
    if (!(len2 > 4 * eps * eps))
        return 0;
    len = sqrt(len2);
    *t = bn_v3_dot(ap, ab) / len2;
    if (!(*t > 0 && *t < 1) || *t * len <= eps || (1 - *t) * len <= eps)
        return 0;
    bn_v3_madd(ap, -*t, ab, d);
    return bn_v3_len(d) <= dist;
}

/* T-junctions: an output vertex strictly inside an edge of a patch of its own smooth surface (same
 * material, normals within the crease) that does not have it as a corner, where faces meshed at
 * different sizes meet side by side. Its value is then taken from that edge (linear along it, as
 * both interpolations are), so the surface has no crack there. Candidates by x-range in `order`
 * (positions sorted by x). */
/* Appends T-junction (v on the edge va-vb at t) to b->tj. */
static bn_status bn__tj_push(bn_bake *b, size_t *cap, struct bn__tj j)
{
    if (b->ntj == *cap) {
        size_t nc = *cap ? 2 * *cap : 64;
        struct bn__tj *nt = bn__realloc_array(b->tj, nc, sizeof *nt);
        if (!nt)
            return BN_ENOMEM;
        b->tj = nt;
        *cap = nc;
    }
    b->tj[b->ntj++] = j;
    return BN_OK;
}

int bn__same_surface(const bn_bake *b, const bn_patch *patches, size_t v, const bn_patch *pq)
{
    for (size_t i = b->vstart[v]; i < b->vstart[v + 1]; i++) {
        const bn_patch *pp = &patches[b->vpatch[i]];
        if (pp->material == pq->material && bn_v3_dot(pp->normal, pq->normal) >= b->cos_crease - 1e-12)
            return 1;
    }
    return 0;
}

static bn_status bn__find_tjunctions(bn_bake *b, const bn_patch *patches, size_t np)
{
    size_t n = b->nverts, cap = 0;
    double eps = b->eps;
    bn__xkey *ox = bn__xsort(b->pos, n);
    bn_status st = ox ? BN_OK : BN_ENOMEM;
    for (size_t q = 0; q < np && st == BN_OK; q++) {
        const bn_patch *pq = &patches[q];
        for (unsigned c = 0; c < pq->ncorners && st == BN_OK; c++) {
            size_t va = b->corner_v[4 * q + c], vb = b->corner_v[4 * q + (c + 1) % pq->ncorners];
            const double *A = b->pos + 3 * va, *B = b->pos + 3 * vb;
            double xhi = fmax(A[0], B[0]) + eps, t;
            for (size_t k = bn__xfirst(ox, n, fmin(A[0], B[0]) - eps); k < n && ox[k].x <= xhi && st == BN_OK; k++) {
                size_t v = ox[k].i;
                int corner = 0;
                for (unsigned cc = 0; cc < pq->ncorners; cc++)
                    corner |= b->corner_v[4 * q + cc] == v;
                if (!corner && bn__inside_segment(A, B, b->pos + 3 * v, eps, eps, &t) &&
                    bn__same_surface(b, patches, v, pq))
                    st = bn__tj_push(b, &cap, (struct bn__tj){v, va, vb, t, bn_v3_dist(A, B)});
            }
        }
    }
    free(ox);
    if (st == BN_OK && b->ntj)
        qsort(b->tj, b->ntj, sizeof *b->tj, bn__cmp_tj);
    return st;
}

/* The create's working tables: each patch vertex's welded root, and the (patch, corner)
 * incidences per root (CSR) with each incidence's output vertex. */
typedef struct bn__bake_tmp {
    size_t *weld, *inc_start, *inc, *gid, ninc;
} bn__bake_tmp;

/* 1. Weld: sort by x, sweep a window of width eps, union points within eps; weld[i] = i's root. */
static bn_status bn__weld(const double *pv, size_t npv, double eps, size_t *weld)
{
    bn__xkey *order = bn__xsort(pv, npv);
    if (!order)
        return BN_ENOMEM;
    for (size_t i = 0; i < npv; i++)
        weld[i] = i;
    for (size_t a = 0; a < npv; a++)
        for (size_t c = a + 1; c < npv && order[c].x - order[a].x <= eps; c++)
            if (bn_v3_dist(pv + 3 * order[a].i, pv + 3 * order[c].i) <= eps)
                bn__uf_union(weld, order[a].i, order[c].i);
    for (size_t i = 0; i < npv; i++)
        weld[i] = bn__uf_find(weld, i);
    free(order);
    return BN_OK;
}

/* 2. Incidences (4 patch + corner) per welded point, CSR keyed by the point's root. */
static bn_status bn__incidences(const bn_patch *patches, size_t np, size_t npv, bn__bake_tmp *t)
{
    size_t *fill;
    for (size_t p = 0; p < np; p++)
        for (unsigned c = 0; c < patches[p].ncorners; c++) {
            t->inc_start[t->weld[patches[p].corner[c]] + 1]++;
            t->ninc++;
        }
    for (size_t i = 0; i < npv; i++)
        t->inc_start[i + 1] += t->inc_start[i];
    t->inc = bn__malloc_array(t->ninc, sizeof *t->inc);
    t->gid = bn__malloc_array(t->ninc, sizeof *t->gid);
    fill = bn__malloc_array(npv, sizeof *fill);
    if (!t->inc || !t->gid || !fill) {
        free(fill);
        return BN_ENOMEM;
    }
    memcpy(fill, t->inc_start, npv * sizeof *fill);
    for (size_t p = 0; p < np; p++)
        for (unsigned c = 0; c < patches[p].ncorners; c++)
            t->inc[fill[t->weld[patches[p].corner[c]]]++] = 4 * p + c;
    free(fill);
    return BN_OK;
}

/* 3. Groups per point: incident patches of one material with normals within the crease (none when
 * flat) share an output vertex; gid[] numbers them in point order. Returns the output vertices. */
static size_t bn__group_points(const bn_patch *patches, size_t npv, int flat, double cos_crease, bn__bake_tmp *t,
                               size_t *local)
{
    size_t nout = 0;
    for (size_t w = 0; w < npv; w++) {
        size_t s = t->inc_start[w], e = t->inc_start[w + 1];
        for (size_t i = s; i < e; i++)
            local[i] = i - s;
        for (size_t i = s; i < e; i++)
            for (size_t j = i + 1; j < e; j++) {
                const bn_patch *pi = &patches[t->inc[i] / 4], *pj = &patches[t->inc[j] / 4];
                if (!flat && pi->material == pj->material &&
                    bn_v3_dot(pi->normal, pj->normal) >= cos_crease - 1e-12)
                    bn__uf_union(local + s, i - s, j - s);
            }
        for (size_t i = s; i < e; i++) {
            size_t r = bn__uf_find(local + s, i - s);
            if (r == i - s)
                t->gid[i] = nout++;
            else
                t->gid[i] = t->gid[s + r];   /* the root comes first: already numbered */
        }
    }
    return nout;
}

/* 4. The output vertices: positions, each corner's vertex, each vertex's patches (CSR). */
static bn_status bn__vertex_lists(bn_bake *b, const double *pv, size_t np, size_t npv, const bn__bake_tmp *t)
{
    size_t nout = b->nverts, *fill;
    b->corner_v = bn__malloc_array(np * 4, sizeof(size_t));
    b->pos = bn__malloc_array(nout, 3 * sizeof(double));
    b->vstart = bn__calloc(nout + 1, sizeof(size_t));
    b->vpatch = bn__malloc_array(t->ninc, sizeof(size_t));
    b->vpoint = bn__malloc_array(nout, sizeof(size_t));
    fill = bn__malloc_array(nout, sizeof *fill);
    if (!b->corner_v || !b->pos || !b->vstart || !b->vpatch || !b->vpoint || !fill) {
        free(fill);
        return BN_ENOMEM;
    }
    for (size_t i = 0; i < np * 4; i++)
        b->corner_v[i] = SIZE_MAX;
    for (size_t w = 0; w < npv; w++)
        for (size_t i = t->inc_start[w]; i < t->inc_start[w + 1]; i++) {
            memcpy(b->pos + 3 * t->gid[i], pv + 3 * w, 3 * sizeof(double));
            b->vpoint[t->gid[i]] = w;
            b->corner_v[t->inc[i]] = t->gid[i];
            b->vstart[t->gid[i] + 1]++;
        }
    for (size_t v = 0; v < nout; v++)
        b->vstart[v + 1] += b->vstart[v];
    memcpy(fill, b->vstart, nout * sizeof *fill);
    for (size_t w = 0; w < npv; w++)
        for (size_t i = t->inc_start[w]; i < t->inc_start[w + 1]; i++)
            b->vpatch[fill[t->gid[i]]++] = t->inc[i] / 4;
    free(fill);
    return BN_OK;
}

bn_status bn_bake_create(const bn_scene *scene, double crease_deg, bn_bake **out, bn_error *err)
{
    size_t np, npv, *local = NULL;
    const bn_patch *patches = bn_scene_patches(scene, &np);
    const double *pv = bn_scene_patch_vertices(scene, &npv);
    double eps, cos_crease = cos(crease_deg * BN_PI / 180.0);
    int flat = crease_deg == BN_BAKE_FLAT;
    bn__bake_tmp t = {0};
    bn_bake *b;
    bn_status st = BN_ENOMEM;

    *out = NULL;
    if (!flat && !(crease_deg >= 0 && crease_deg <= 180))
        return bn_error_set(err, BN_EINPUT, "crease angle %g is not within [0, 180] degrees", crease_deg);
    if (np == 0)
        return bn_error_set(err, BN_EINPUT, "%s: the scene has no patches to bake", bn_scene_path(scene));
    /* Points computed from two faces' grids agree to rounding (~1e-16 relative); genuinely distinct
     * points are a patch edge apart. 1e-9 of the scene's diameter sits safely between. */
    eps = 1e-9 * bn_scene_diameter(scene);
    b = calloc(1, sizeof *b);
    t.weld = bn__malloc_array(npv, sizeof *t.weld);
    t.inc_start = bn__calloc(npv + 1, sizeof *t.inc_start);
    if (b && t.weld && t.inc_start && bn__weld(pv, npv, eps, t.weld) == BN_OK &&
        bn__incidences(patches, np, npv, &t) == BN_OK && (local = bn__malloc_array(t.ninc, sizeof *local))) {
        b->scene = scene;
        b->eps = eps;
        b->cos_crease = cos_crease;
        b->npoints = npv;
        b->nverts = bn__group_points(patches, npv, flat, cos_crease, &t, local);
        if (bn__vertex_lists(b, pv, np, npv, &t) == BN_OK &&
            (flat || bn__find_tjunctions(b, patches, np) == BN_OK))
            st = BN_OK;
    }
    if (st == BN_OK) {
        *out = b;
        b = NULL;
    } else {
        bn_error_set(err, st, "out of memory baking %zu patches", np);
    }
    bn_bake_destroy(b);
    free(t.weld);
    free(t.inc_start);
    free(t.inc);
    free(t.gid);
    free(local);
    return st;
}

void bn_bake_destroy(bn_bake *b)
{
    if (!b)
        return;
    free(b->pos);
    free(b->corner_v);
    free(b->vstart);
    free(b->vpatch);
    free(b->tj);
    free(b->enclosed);
    free(b->vpoint);
    free(b->tri);
    free(b->tri_patch);
    free(b);
}

const bn_scene *bn_bake_scene(const bn_bake *b) { return b->scene; }
size_t bn_bake_vertex_count(const bn_bake *b) { return b->nverts; }
const double *bn_bake_vertex_positions(const bn_bake *b) { return b->pos; }
size_t bn_bake_corner_vertex(const bn_bake *b, size_t patch, unsigned corner) { return b->corner_v[4 * patch + corner]; }

size_t bn_bake_face_count(const bn_bake *b)
{
    size_t np;
    if (b->tri)
        return b->ntri;
    bn_scene_patches(b->scene, &np);
    return np;
}

unsigned bn_bake_face(const bn_bake *b, size_t f, size_t v[4], size_t *patch)
{
    if (b->tri) {
        memcpy(v, b->tri + 3 * f, 3 * sizeof *v);
        v[3] = 0;
        *patch = b->tri_patch[f];
        return 3;
    }
    const bn_patch *pa = &bn_scene_patches(b->scene, NULL)[f];
    for (unsigned c = 0; c < 4; c++)
        v[c] = c < pa->ncorners ? b->corner_v[4 * f + c] : 0;
    *patch = f;
    return pa->ncorners;
}

size_t bn_bake_exclude_enclosed(bn_bake *b, const bn_rt *rt)
{
    size_t np;
    bn_scene_patches(b->scene, &np);
    free(b->enclosed);
    if (!(b->enclosed = calloc(np ? np : 1, 1)))
        return 0;
    return bn_rt_enclosed_patches(rt, b->enclosed);
}

void bn_bake_vertex_values(const bn_bake *b, const double *x, double *out)
{
    const bn_patch *patches = bn_scene_patches(b->scene, NULL);
    for (size_t v = 0; v < b->nverts; v++) {
        double s[3] = {0, 0, 0}, a = 0;
        int open = 0;   /* the vertex has a patch outside every closed object: only those count */
        if (b->enclosed)
            for (size_t i = b->vstart[v]; i < b->vstart[v + 1] && !open; i++)
                open = !b->enclosed[b->vpatch[i]];
        for (size_t i = b->vstart[v]; i < b->vstart[v + 1]; i++) {
            size_t p = b->vpatch[i];
            if (open && b->enclosed[p])
                continue;
            a += patches[p].area;
            for (int c = 0; c < 3; c++)
                s[c] += patches[p].area * x[3 * p + c];
        }
        for (int c = 0; c < 3; c++)
            out[3 * v + c] = a > 0 ? s[c] / a : 0;
    }
    bn_bake_vertex_tjunctions(b, out);
}

int bn__patch_better(const bn_bake *b, size_t p, size_t q)
{
    int op = !b->enclosed || !b->enclosed[p], oq = !b->enclosed || !b->enclosed[q];
    const bn_patch *pa = bn_scene_patches(b->scene, NULL);
    return op != oq ? op : pa[p].area > pa[q].area;
}

size_t bn_bake_vertex_patch(const bn_bake *b, size_t v)
{
    size_t best = b->vpatch[b->vstart[v]];
    for (size_t i = b->vstart[v] + 1; i < b->vstart[v + 1]; i++)
        if (bn__patch_better(b, b->vpatch[i], best))
            best = b->vpatch[i];
    return best;
}

void bn_bake_vertex_tjunctions(const bn_bake *b, double *out)
{
    /* T-junctions take their edge's value, longest edges first (their ends may be T-junctions of
     * longer edges). Two faces cut at different sizes along one line make each other's vertices
     * T-junctions in a chain: the sweeps (Gauss-Seidel, each a convex combination) converge to the one
     * consistent answer, linear along the chain between its shared ends */
    for (int sweep = 0; sweep < 500 && b->ntj; sweep++) {
        double change = 0, scale = 0;
        for (size_t k = 0; k < b->ntj; k++) {
            const struct bn__tj *j = &b->tj[k];
            for (int c = 0; c < 3; c++) {
                double nv = (1 - j->t) * out[3 * j->a + c] + j->t * out[3 * j->b + c];
                change = fmax(change, fabs(nv - out[3 * j->v + c]));
                scale = fmax(scale, fabs(nv));
                out[3 * j->v + c] = nv;
            }
        }
        if (change <= 1e-15 * scale)
            break;
    }
}

size_t bn_bake_tjunction_count(const bn_bake *b) { return b->ntj; }

unsigned bn_bake_weights(const bn_bake *b, size_t patch, const double p[3], size_t vert[4], double w[4])
{
    const bn_patch *pa = &bn_scene_patches(b->scene, NULL)[patch];
    const double *pv = bn_scene_patch_vertices(b->scene, NULL);
    const double *A = pv + 3 * pa->corner[0], *B = pv + 3 * pa->corner[1], *C = pv + 3 * pa->corner[2];
    for (unsigned c = 0; c < 4; c++)
        w[c] = 0;
    for (unsigned c = 0; c < pa->ncorners; c++)
        vert[c] = b->corner_v[4 * patch + c];
    if (pa->ncorners == 3) {
        /* Barycentric: sub-triangle areas along the normal. */
        double e1[3], e2[3], q1[3], q2[3], cr[3], tot;
        bn_v3_sub(B, A, e1);
        bn_v3_sub(C, A, e2);
        bn_v3_cross(e1, e2, cr);
        tot = bn_v3_dot(cr, pa->normal);
        bn_v3_sub(B, p, q1);
        bn_v3_sub(C, p, q2);
        bn_v3_cross(q1, q2, cr);
        w[0] = tot != 0 ? bn_v3_dot(cr, pa->normal) / tot : 1.0 / 3;
        bn_v3_sub(C, p, q1);
        bn_v3_sub(A, p, q2);
        bn_v3_cross(q1, q2, cr);
        w[1] = tot != 0 ? bn_v3_dot(cr, pa->normal) / tot : 1.0 / 3;
        w[0] = bn_clamp(w[0], 0, 1);
        w[1] = bn_clamp(w[1], 0, 1 - w[0]);
        w[2] = 1 - w[0] - w[1];
    } else {
        /* Inverse bilinear by Gauss-Newton on P(u,v) = (1-u)(1-v)A + u(1-v)B + uvC + (1-u)vD. */
        const double *D = pv + 3 * pa->corner[3];
        double u = 0.5, v = 0.5;
        for (int it = 0; it < 12; it++) {
            double P[3], Pu[3], Pv[3], r[3], a11, a12, a22, b1, b2, det;
            for (int k = 0; k < 3; k++) {
                P[k] = (1 - u) * (1 - v) * A[k] + u * (1 - v) * B[k] + u * v * C[k] + (1 - u) * v * D[k];
                Pu[k] = (1 - v) * (B[k] - A[k]) + v * (C[k] - D[k]);
                Pv[k] = (1 - u) * (D[k] - A[k]) + u * (C[k] - B[k]);
                r[k] = p[k] - P[k];
            }
            a11 = bn_v3_dot(Pu, Pu);
            a12 = bn_v3_dot(Pu, Pv);
            a22 = bn_v3_dot(Pv, Pv);
            b1 = bn_v3_dot(Pu, r);
            b2 = bn_v3_dot(Pv, r);
            det = a11 * a22 - a12 * a12;
            if (!(det > 0))
                break;
            u = bn_clamp(u + (a22 * b1 - a12 * b2) / det, 0, 1);
            v = bn_clamp(v + (a11 * b2 - a12 * b1) / det, 0, 1);
        }
        w[0] = (1 - u) * (1 - v);
        w[1] = u * (1 - v);
        w[2] = u * v;
        w[3] = (1 - u) * v;
    }
    return pa->ncorners;
}

void bn_bake_interpolate(const bn_bake *b, const double *vv, size_t patch, const double p[3], double out[3])
{
    size_t vert[4];
    double w[4];
    unsigned n = bn_bake_weights(b, patch, p, vert, w);
    for (int c = 0; c < 3; c++) {
        out[c] = 0;
        for (unsigned k = 0; k < n; k++)
            out[c] += w[k] * vv[3 * vert[k] + c];
    }
}

double bn_bake_auto_exposure(const double *L, size_t np)
{
    float *rgb = bn__malloc_array(np ? 3 * np : 1, sizeof(float));
    double ev;
    if (!rgb)
        return 0;
    for (size_t i = 0; i < 3 * np; i++)
        rgb[i] = (float)L[i];
    ev = bn__auto_exposure(rgb, np);
    free(rgb);
    return ev;
}
