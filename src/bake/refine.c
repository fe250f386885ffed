/* A bake mesh refined where light changes (bn_bake_refine). The patches become triangles (quads cut
 * along a diagonal); every point that lies inside another triangle's edge (a T-junction, where faces
 * meshed at different sizes meet, or a contact line's cut) splits that edge, so no vertex hangs; then,
 * round by round, the edges whose ends' values differ by more than a tolerance are bisected, the
 * caller evaluates the new vertices (a final gather), until no edge differs or the vertex budget is
 * spent. Bisection is Rivara's longest-edge rule: a triangle with a split edge is cut at its longest
 * edge's midpoint first, so the mesh stays conforming (crack-free) and its angles bounded.
 * Splits are keyed by positions, not by vertices: an edge on a crease (the floor meeting a wall) splits
 * on both sides at once, each side with a vertex (and value) of its own. */
#include "bake/bake_internal.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <string.h>

#define BN__REFINE_SWEEPS 4096   /* the closure's sweeps before it gives up (never reached in practice) */
#define BN__REFINE_FLAT 0.99985  /* cos 1 degree: an edge whose ends face further apart lies on a curved surface */

/* Edges (a, b), a < b, to a value: open addressing with linear probing. */
typedef struct bn__emap {
    size_t cap, n;
    size_t *key;   /* 2 per slot; SIZE_MAX: empty */
    size_t *val;
} bn__emap;

static bn_status bn__emap_init(bn__emap *m, size_t n)
{
    size_t cap = 64;
    while (cap < 2 * n + 2)
        cap *= 2;
    free(m->key);
    free(m->val);
    m->cap = cap;
    m->n = 0;
    m->key = bn__malloc_array(cap, 2 * sizeof *m->key);
    m->val = bn__malloc_array(cap, sizeof *m->val);
    if (!m->key || !m->val)
        return BN_ENOMEM;
    for (size_t i = 0; i < 2 * cap; i++)
        m->key[i] = SIZE_MAX;
    return BN_OK;
}

static size_t bn__emap_slot(const bn__emap *m, size_t a, size_t b)
{
    size_t lo = a < b ? a : b, hi = a < b ? b : a;
    size_t i = (size_t)bn__hash64((uint64_t)lo * 0x9e3779b97f4a7c15ULL ^ (uint64_t)hi) & (m->cap - 1);
    while (m->key[2 * i] != SIZE_MAX && (m->key[2 * i] != lo || m->key[2 * i + 1] != hi))
        i = (i + 1) & (m->cap - 1);
    return i;
}

static size_t bn__emap_get(const bn__emap *m, size_t a, size_t b)
{
    size_t i = bn__emap_slot(m, a, b);
    return m->key[2 * i] == SIZE_MAX ? SIZE_MAX : m->val[i];
}

static bn_status bn__emap_put(bn__emap *m, size_t a, size_t b, size_t val)
{
    size_t i;
    if (2 * (m->n + 1) > m->cap) {   /* grow: rehash into twice the slots */
        bn__emap old = *m, next = {0};
        if (bn__emap_init(&next, old.cap) != BN_OK) {
            free(next.key);
            free(next.val);
            return BN_ENOMEM;
        }
        for (size_t k = 0; k < old.cap; k++)
            if (old.key[2 * k] != SIZE_MAX) {
                size_t s = bn__emap_slot(&next, old.key[2 * k], old.key[2 * k + 1]);
                next.key[2 * s] = old.key[2 * k];
                next.key[2 * s + 1] = old.key[2 * k + 1];
                next.val[s] = old.val[k];
                next.n++;
            }
        free(old.key);
        free(old.val);
        *m = next;
    }
    i = bn__emap_slot(m, a, b);
    if (m->key[2 * i] == SIZE_MAX) {
        m->key[2 * i] = a < b ? a : b;
        m->key[2 * i + 1] = a < b ? b : a;
        m->n++;
    }
    m->val[i] = val;
    return BN_OK;
}

static void bn__emap_free(bn__emap *m)
{
    free(m->key);
    free(m->val);
}

/* The refinement's state beside the bake's own arrays (which grow with it). */
typedef struct bn__refine {
    bn_bake *b;
    const bn_patch *pa;
    size_t npt0, nv0, ptcap, vcap, vpcap, tcap;   /* nv0: the vertices before refinement */
    double *ppos;       /* each position (point), npoints x 3; those below npt0 are the patches' corners */
    size_t *pv_start;   /* the points below npt0: their output vertices (CSR) */
    size_t *pv;
    double *xev;        /* each vertex's evaluation point (1% into its face) and patch */
    size_t *vpat;
    bn__emap split;     /* position edge -> the point it splits at */
    bn__emap linear;    /* position edges whose midpoint, probed, lay on the line between their ends */
    size_t probes;      /* midpoints probed so far (their random streams' keys) */
    bn__emap vsplit;    /* vertex edge -> the vertex there on that edge's side */
} bn__refine;

static bn_status bn__grow(void *pp, size_t *cap, size_t need, size_t size)
{
    void **p = pp;
    if (need <= *cap)
        return BN_OK;
    size_t nc = *cap ? *cap : 1024;
    while (nc < need)
        nc *= 2;
    void *q = bn__realloc_array(*p, nc, size);
    if (!q)
        return BN_ENOMEM;
    *p = q;
    *cap = nc;
    return BN_OK;
}

/* Room for `need` vertices in every per-vertex array (the bake's and the refinement's). */
static bn_status bn__vertex_room(bn__refine *R, size_t need)
{
    bn_bake *b = R->b;
    if (need <= R->vcap)
        return BN_OK;
    size_t nc = 2 * R->vcap > need ? 2 * R->vcap : need;
    double *pos = bn__realloc_array(b->pos, nc, 3 * sizeof(double));
    b->pos = pos ? pos : b->pos;
    size_t *vpoint = bn__realloc_array(b->vpoint, nc, sizeof(size_t));
    b->vpoint = vpoint ? vpoint : b->vpoint;
    size_t *vstart = bn__realloc_array(b->vstart, nc + 1, sizeof(size_t));
    b->vstart = vstart ? vstart : b->vstart;
    double *xev = bn__realloc_array(R->xev, nc, 3 * sizeof(double));
    R->xev = xev ? xev : R->xev;
    size_t *vpat = bn__realloc_array(R->vpat, nc, sizeof(size_t));
    R->vpat = vpat ? vpat : R->vpat;
    if (!pos || !vpoint || !vstart || !xev || !vpat)
        return BN_ENOMEM;
    R->vcap = nc;
    return BN_OK;
}

/* A new point (position) at x; its number, or SIZE_MAX without memory. */
static size_t bn__add_point(bn__refine *R, const double x[3])
{
    bn_bake *b = R->b;
    if (bn__grow(&R->ppos, &R->ptcap, b->npoints + 1, 3 * sizeof(double)) != BN_OK)
        return SIZE_MAX;
    memcpy(R->ppos + 3 * b->npoints, x, 3 * sizeof(double));
    return b->npoints++;
}

/* Vertex v is evaluated on patch `patch`, 1% of the way from it to the patch's centroid (off an edge, a
 * contact's foot; the rule of every vertex, and of `bounce trace --points`, so the tracer can be asked
 * the same point). */
static void bn__vertex_on(bn__refine *R, size_t v, size_t patch)
{
    R->vpat[v] = patch;
    bn_scene_point_inset(R->b->scene, patch, R->b->pos + 3 * v, R->xev + 3 * v);
}

/* A new output vertex at point pt on patch `patch`; SIZE_MAX without memory. */
static size_t bn__add_vertex(bn__refine *R, size_t pt, size_t patch)
{
    bn_bake *b = R->b;
    size_t v = b->nverts;
    if (bn__vertex_room(R, v + 1) != BN_OK || bn__grow(&b->vpatch, &R->vpcap, b->vstart[v] + 1, sizeof(size_t)) != BN_OK)
        return SIZE_MAX;
    memcpy(b->pos + 3 * v, R->ppos + 3 * pt, 3 * sizeof(double));
    bn__vertex_on(R, v, patch);
    b->vpoint[v] = pt;
    b->vpatch[b->vstart[v]] = patch;
    b->vstart[v + 1] = b->vstart[v] + 1;
    b->nverts++;
    return v;
}

/* The vertex on triangle t's side at point s of its edge A-B: the one a neighbour across the edge made
 * (the same vertices A, B: the same smooth surface), a vertex of that surface already at s (a
 * T-junction), or a new one. SIZE_MAX without memory. */
static size_t bn__split_vertex(bn__refine *R, size_t A, size_t B, size_t s, size_t patch)
{
    bn_bake *b = R->b;
    size_t v = bn__emap_get(&R->vsplit, A, B);
    if (v != SIZE_MAX && v >= R->nv0 && bn__patch_better(b, patch, R->vpat[v])) {
        b->vpatch[b->vstart[v]] = patch;   /* gathered where bn_bake_vertex_patch would (on a contact line: */
        bn__vertex_on(R, v, patch);        /* the side seen, not the one under the block) */
    }
    if (v != SIZE_MAX)
        return v;
    for (size_t i = s < R->npt0 ? R->pv_start[s] : 0; s < R->npt0 && i < R->pv_start[s + 1] && v == SIZE_MAX; i++)
        if (bn__same_surface(b, R->pa, R->pv[i], &R->pa[patch]))
            v = R->pv[i];
    if (v == SIZE_MAX)
        v = bn__add_vertex(R, s, patch);
    if (v == SIZE_MAX || bn__emap_put(&R->vsplit, A, B, v) != BN_OK)
        return SIZE_MAX;
    return v;
}

/* Cuts triangle t at point s on its edge k (corners k, k+1): t keeps the part at corner k, the other
 * part is appended; both keep t's winding and patch. */
static bn_status bn__cut(bn__refine *R, size_t t, int k, size_t s)
{
    bn_bake *b = R->b;
    size_t A = b->tri[3 * t + k], B = b->tri[3 * t + (k + 1) % 3], C = b->tri[3 * t + (k + 2) % 3], S, n = b->ntri;
    size_t patch = b->tri_patch[t], cap = R->tcap;
    if ((S = bn__split_vertex(R, A, B, s, patch)) == SIZE_MAX ||
        bn__grow(&b->tri, &cap, n + 1, 3 * sizeof(size_t)) != BN_OK ||
        bn__grow(&b->tri_patch, &R->tcap, n + 1, sizeof(size_t)) != BN_OK)
        return BN_ENOMEM;
    b->tri[3 * t] = A;
    b->tri[3 * t + 1] = S;
    b->tri[3 * t + 2] = C;
    b->tri[3 * n] = S;
    b->tri[3 * n + 1] = B;
    b->tri[3 * n + 2] = C;
    b->tri_patch[n] = patch;
    b->ntri++;
    return BN_OK;
}

/* Where triangle t is cut next: at the split of its longest edge; else at a point already on one of
 * its edges (a T-junction); else, when one of its shorter edges has a new midpoint, at a new midpoint
 * of its longest edge first (Rivara). 1 with *k (the edge) and *s (the point), 0 when t is whole,
 * -1 without memory. */
static int bn__choose(bn__refine *R, size_t t, int *k, size_t *s)
{
    const bn_bake *b = R->b;
    size_t p[3], sp[3];
    double len2[3];
    int L = 0;
    for (int i = 0; i < 3; i++)
        p[i] = b->vpoint[b->tri[3 * t + i]];
    for (int i = 0; i < 3; i++) {
        const double *A = R->ppos + 3 * p[i], *B = R->ppos + 3 * p[(i + 1) % 3];
        len2[i] = (B[0] - A[0]) * (B[0] - A[0]) + (B[1] - A[1]) * (B[1] - A[1]) + (B[2] - A[2]) * (B[2] - A[2]);
        sp[i] = bn__emap_get(&R->split, p[i], p[(i + 1) % 3]);
        if (len2[i] > len2[L])
            L = i;
    }
    *k = L;
    if ((*s = sp[L]) != SIZE_MAX)
        return 1;
    for (int i = 0; i < 3; i++)
        if (sp[i] != SIZE_MAX && sp[i] < R->npt0) {
            *k = i;
            *s = sp[i];
            return 1;
        }
    if (sp[0] == SIZE_MAX && sp[1] == SIZE_MAX && sp[2] == SIZE_MAX)
        return 0;
    double m[3];
    const double *A = R->ppos + 3 * p[L], *B = R->ppos + 3 * p[(L + 1) % 3];
    for (int i = 0; i < 3; i++)
        m[i] = 0.5 * (A[i] + B[i]);
    if ((*s = bn__add_point(R, m)) == SIZE_MAX || bn__emap_put(&R->split, p[L], p[(L + 1) % 3], *s) != BN_OK)
        return -1;
    return 1;
}

/* Cuts triangles until none has a split edge: the mesh is conforming again. The closure of a split adds
 * a few triangles (Rivara's propagation); far more than every split's share is a cycle, stopped with an
 * error rather than left to take the machine's memory. */
static bn_status bn__conform(bn__refine *R, bn_error *err)
{
    size_t limit = 8 * R->b->ntri + 64 * R->split.n + 4096;
    for (int sweep = 0; sweep < BN__REFINE_SWEEPS; sweep++) {
        size_t cuts = 0;
        for (size_t t = 0; t < R->b->ntri; t++) {
            int k, c;
            size_t s;
            while ((c = bn__choose(R, t, &k, &s)) == 1) {
                if (R->b->ntri > limit)
                    return bn_error_set(err, BN_EINTERNAL, "bake: the refined mesh does not close: %zu triangles "
                                        "for %zu splits (a cycle of cuts; please report the scene)", R->b->ntri,
                                        R->split.n);
                if (bn__cut(R, t, k, s) != BN_OK)
                    return bn_error_set(err, BN_ENOMEM, "bake: out of memory refining %zu triangles", R->b->ntri);
                cuts++;
            }
            if (c < 0)
                return bn_error_set(err, BN_ENOMEM, "bake: out of memory refining %zu triangles", R->b->ntri);
        }
        if (!cuts)
            return BN_OK;
    }
    return bn_error_set(err, BN_EINTERNAL, "bake: the refined mesh did not close after %d sweeps (%zu triangles)",
                        BN__REFINE_SWEEPS, R->b->ntri);
}

/* The patches as triangles (a quad cut along its diagonal 0-2). */
static bn_status bn__triangulate(bn__refine *R, bn_error *err)
{
    bn_bake *b = R->b;
    size_t np, n = 0;
    const bn_patch *pa = bn_scene_patches(b->scene, &np);
    for (size_t p = 0; p < np; p++)
        n += pa[p].ncorners - 2u;
    R->tcap = n + 1;
    b->tri = bn__malloc_array(R->tcap, 3 * sizeof(size_t));
    b->tri_patch = bn__malloc_array(R->tcap, sizeof(size_t));
    if (!b->tri || !b->tri_patch)
        return bn_error_set(err, BN_ENOMEM, "bake: out of memory for %zu triangles", n);
    for (size_t p = 0; p < np; p++)
        for (unsigned c = 1; c + 1 < pa[p].ncorners; c++) {
            b->tri[3 * b->ntri] = b->corner_v[4 * p];
            b->tri[3 * b->ntri + 1] = b->corner_v[4 * p + c];
            b->tri[3 * b->ntri + 2] = b->corner_v[4 * p + c + 1];
            b->tri_patch[b->ntri++] = p;
        }
    return BN_OK;
}

typedef struct bn__hang {
    double t;
    size_t p;
} bn__hang;
static int bn__cmp_hang(const void *x, const void *y)
{
    const bn__hang *a = x, *b = y;
    return a->t < b->t ? -1 : a->t > b->t ? 1 : (a->p > b->p) - (a->p < b->p);
}

/* Edge a-b splits at the middle one of the points h[0..n) along it (in order from a), each half at the
 * middle one of its own, and so on. */
static bn_status bn__split_chain(bn__refine *R, size_t a, size_t b, const bn__hang *h, size_t n)
{
    if (n == 0)
        return BN_OK;
    size_t m = n / 2;
    if (bn__emap_put(&R->split, a, b, h[m].p) != BN_OK || bn__split_chain(R, a, h[m].p, h, m) != BN_OK)
        return BN_ENOMEM;
    return bn__split_chain(R, h[m].p, b, h + m + 1, n - m - 1);
}

/* The points (with vertices) strictly inside edge a-b, within BN__HANG eps of its line and farther than that
 * from both ends, sorted along it. A point nearer an end is that end: a contact's cut point 3e-8 m from a
 * table leg's own corner (two points, 4 eps apart) split the leg's edge at the leg's corner, and the two
 * triangles it made, each holding both points, split each other for ever (the living room's bake, 24 GB). */
#define BN__HANG 100
static size_t bn__hanging_on(const bn__refine *R, const bn__xkey *ox, size_t nx, size_t a, size_t b, bn__hang **h,
                             size_t *cap)
{
    const double *A = R->ppos + 3 * a, *B = R->ppos + 3 * b;
    double tol = BN__HANG * R->b->eps, xhi = fmax(A[0], B[0]) + tol, t;
    size_t n = 0;
    for (size_t k = bn__xfirst(ox, nx, fmin(A[0], B[0]) - tol); k < nx && ox[k].x <= xhi; k++) {
        size_t q = ox[k].i;
        if (q == a || q == b || !bn__inside_segment(A, B, R->ppos + 3 * q, tol, tol, &t))
            continue;
        if (bn__grow(h, cap, n + 1, sizeof **h) != BN_OK)
            return SIZE_MAX;
        (*h)[n++] = (bn__hang){t, q};
    }
    if (n > 1)
        qsort(*h, n, sizeof **h, bn__cmp_hang);
    return n;
}

/* T-junctions: every point of a vertex that lies inside a triangle's edge (faces meshed at different
 * sizes side by side, whatever their surfaces) splits that edge there. */
static bn_status bn__hanging(bn__refine *R, bn_error *err)
{
    bn_bake *b = R->b;
    size_t nu = 0, cap = 0, n;
    double *upos = bn__malloc_array(R->npt0 + 1, 3 * sizeof(double));
    size_t *uid = bn__malloc_array(R->npt0 + 1, sizeof(size_t));
    bn__xkey *ox = NULL;
    bn__hang *h = NULL;
    bn__emap seen = {0};
    bn_status st = upos && uid && bn__emap_init(&seen, b->ntri) == BN_OK ? BN_OK : BN_ENOMEM;
    for (size_t p = 0; st == BN_OK && p < R->npt0; p++)
        if (R->pv_start[p + 1] > R->pv_start[p]) {   /* a point some vertex stands on */
            memcpy(upos + 3 * nu, R->ppos + 3 * p, 3 * sizeof(double));
            uid[nu++] = p;
        }
    if (st == BN_OK && !(ox = bn__xsort(upos, nu)))
        st = BN_ENOMEM;
    for (size_t k = 0; st == BN_OK && k < nu; k++)
        ox[k].i = uid[ox[k].i];
    for (size_t t = 0; st == BN_OK && t < b->ntri; t++)
        for (int i = 0; i < 3 && st == BN_OK; i++) {
            size_t pa = b->vpoint[b->tri[3 * t + i]], pb = b->vpoint[b->tri[3 * t + (i + 1) % 3]];
            if (bn__emap_get(&seen, pa, pb) != SIZE_MAX || bn__emap_get(&R->split, pa, pb) != SIZE_MAX)
                continue;
            if (bn__emap_put(&seen, pa, pb, 1) != BN_OK || (n = bn__hanging_on(R, ox, nu, pa, pb, &h, &cap)) == SIZE_MAX)
                st = BN_ENOMEM;
            else
                st = bn__split_chain(R, pa, pb, h, n);
        }
    free(upos);
    free(uid);
    free(ox);
    free(h);
    bn__emap_free(&seen);
    return st == BN_OK ? BN_OK : bn_error_set(err, st, "bake: out of memory finding T-junctions");
}

void bn_bake_refine_opts_default(bn_bake_refine_opts *o)
{
    memset(o, 0, sizeof *o);
    o->max_vertices = BN_BAKE_DEFAULT_VERTICES;
    o->tol = BN_BAKE_REFINE_TOL;
    o->nlayers = 1;
}

static double bn__lum(const double *rgb) { return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]; }

typedef struct bn__cand {
    double pri;
    size_t a, b;   /* the edge's points, a < b */
    size_t va, vb, patch;   /* its ends' vertices on one side, and that side's patch */
} bn__cand;
static int bn__cmp_cand(const void *x, const void *y)
{
    const bn__cand *p = x, *q = y;
    if (p->pri != q->pri)
        return p->pri > q->pri ? -1 : 1;
    return p->a != q->a ? (p->a > q->a) - (p->a < q->a) : (p->b > q->b) - (p->b < q->b);
}

/* The edges whose ends differ (relative difference x length, largest first; an edge may come twice,
 * once from each side). */
static size_t bn__candidates(const bn__refine *R, const double *Y, double tol, double floor, double min_edge,
                             bn__cand **c, size_t *cap)
{
    const bn_bake *b = R->b;
    size_t n = 0;
    for (size_t t = 0; t < b->ntri; t++) {
        if (b->enclosed && b->enclosed[b->tri_patch[t]])
            continue;   /* inside a closed object: never seen */
        for (int i = 0; i < 3; i++) {
            size_t A = b->tri[3 * t + i], B = b->tri[3 * t + (i + 1) % 3];
            size_t pa = b->vpoint[A], pb = b->vpoint[B];
            double len = bn_v3_dist(R->ppos + 3 * pa, R->ppos + 3 * pb);
            if (bn_v3_dot(R->pa[R->vpat[A]].normal, R->pa[R->vpat[B]].normal) < BN__REFINE_FLAT)
                continue;   /* a curved surface's facets: its vertices carry the turn; a split adds nothing */
            double d = fabs(Y[A] - Y[B]) / (fmax(Y[A], Y[B]) + floor);
            if (!(len > min_edge && d > tol) || bn__emap_get(&R->linear, pa, pb) != SIZE_MAX)
                continue;   /* ends alike, too short, or found linear by a probe of its midpoint */
            if (bn__grow(c, cap, n + 1, sizeof **c) != BN_OK)
                return SIZE_MAX;
            (*c)[n++] = (bn__cand){d * len, pa < pb ? pa : pb, pa < pb ? pb : pa, A, B, b->tri_patch[t]};
        }
    }
    if (n > 1)
        qsort(*c, n, sizeof **c, bn__cmp_cand);
    return n;
}

/* The midpoints of edges c[0..n) evaluated (1% into each one's patch), the key layer's luminance into ym.
 * Keys for their random streams far above any vertex's. */
static bn_status bn__probe(bn__refine *R, const bn_bake_refine_opts *o, const bn__cand *c, size_t n, double *ym,
                           bn_error *err)
{
    double *x = bn__malloc_array(n + 1, 3 * sizeof(double)), *out = bn__malloc_array(n * o->nlayers + 1, 3 * sizeof(double));
    size_t *patch = bn__malloc_array(n + 1, sizeof(size_t));
    bn_status st = x && out && patch ? BN_OK : bn_error_set(err, BN_ENOMEM, "bake: out of memory probing %zu edges", n);
    for (size_t i = 0; st == BN_OK && i < n; i++) {
        const double *A = R->ppos + 3 * c[i].a, *B = R->ppos + 3 * c[i].b;
        double m[3] = {0.5 * (A[0] + B[0]), 0.5 * (A[1] + B[1]), 0.5 * (A[2] + B[2])};
        bn_scene_point_inset(R->b->scene, c[i].patch, m, x + 3 * i);
        patch[i] = c[i].patch;
    }
    if (st == BN_OK && n)
        st = o->eval(o->user, x, patch, n, ((size_t)1 << 40) + R->probes, out, err);
    R->probes += n;
    for (size_t i = 0; st == BN_OK && i < n; i++)
        ym[i] = bn__lum(out + (o->key * n + i) * 3);
    free(x);
    free(out);
    free(patch);
    return st;
}

/* Up to `room` edges whose ends differ have their midpoints probed: where the light between the ends is
 * not linear (a shadow's edge, a contact: the midpoint off the ends' mean by more than the tolerance) the
 * edge gets a split (*marked of them); where it is (a smooth gradient, which interpolation already
 * draws), the edge is left whole for good. *probed: the edges probed. */
static bn_status bn__mark(bn__refine *R, const bn_bake_refine_opts *o, const double *val, double floor,
                          double min_edge, size_t room, size_t *marked, size_t *probed, bn_error *err)
{
    bn_bake *b = R->b;
    size_t nl = o->nlayers, cap = 0, n = 0, ns = 0;
    double *Y = bn__malloc_array(b->nverts + 1, sizeof *Y), *ym = NULL;
    bn__cand *c = NULL;
    bn_status st = Y ? BN_OK : BN_ENOMEM;
    *marked = *probed = 0;
    for (size_t v = 0; Y && v < b->nverts; v++)
        Y[v] = bn__lum(val + (v * nl + o->key) * 3);
    if (st == BN_OK && (n = bn__candidates(R, Y, o->tol, floor, min_edge, &c, &cap)) == SIZE_MAX)
        st = BN_ENOMEM;
    for (size_t i = 0; st == BN_OK && i < n && ns < room; i++)   /* the first of each edge, in priority order */
        if (bn__emap_get(&R->linear, c[i].a, c[i].b) == SIZE_MAX && (st = bn__emap_put(&R->linear, c[i].a, c[i].b, 0)) == BN_OK)
            c[ns++] = c[i];
    if (st == BN_OK && !(ym = bn__malloc_array(ns + 1, sizeof *ym)))
        st = BN_ENOMEM;
    if (st != BN_OK) {
        free(Y);
        free(c);
        return bn_error_set(err, st, "bake: out of memory refining %zu vertices", b->nverts);
    }
    st = bn__probe(R, o, c, ns, ym, err);
    for (size_t i = 0; st == BN_OK && i < ns; i++) {
        double ya = Y[c[i].va], yb = Y[c[i].vb], dev = fabs(ym[i] - 0.5 * (ya + yb)) / (fmax(ya, yb) + floor);
        const double *A = R->ppos + 3 * c[i].a, *B = R->ppos + 3 * c[i].b;
        double m[3] = {0.5 * (A[0] + B[0]), 0.5 * (A[1] + B[1]), 0.5 * (A[2] + B[2])};
        size_t s;
        if (!(dev > o->tol))
            continue;   /* linear: stays in `linear`, never probed again */
        if ((s = bn__add_point(R, m)) == SIZE_MAX || bn__emap_put(&R->split, c[i].a, c[i].b, s) != BN_OK)
            st = bn_error_set(err, BN_ENOMEM, "bake: out of memory refining %zu vertices", b->nverts);
        (*marked)++;
    }
    *probed = ns;
    free(Y);
    free(c);
    free(ym);
    return st;
}

/* Vertices first.. evaluated by the caller, into val (vertex-major: nlayers x 3 per vertex). */
static bn_status bn__evaluate(bn__refine *R, const bn_bake_refine_opts *o, size_t first, double **val, bn_error *err)
{
    size_t n = R->b->nverts - first, nl = o->nlayers;
    double *out = bn__malloc_array(n * nl + 1, 3 * sizeof(double));
    double *nv = bn__realloc_array(*val, R->b->nverts * nl + 1, 3 * sizeof(double));
    bn_status st;
    if (nv)
        *val = nv;
    if (!out || !nv) {
        free(out);
        return bn_error_set(err, BN_ENOMEM, "bake: out of memory for the values of %zu vertices", R->b->nverts);
    }
    st = n ? o->eval(o->user, R->xev + 3 * first, R->vpat + first, n, first, out, err) : BN_OK;
    for (size_t i = 0; st == BN_OK && i < n; i++)
        for (size_t l = 0; l < nl; l++)
            memcpy(*val + ((first + i) * nl + l) * 3, out + (l * n + i) * 3, 3 * sizeof(double));
    free(out);
    return st;
}

static void bn__refine_free(bn__refine *R)
{
    free(R->ppos);
    free(R->pv_start);
    free(R->pv);
    free(R->xev);
    free(R->vpat);
    bn__emap_free(&R->split);
    bn__emap_free(&R->linear);
    bn__emap_free(&R->vsplit);
}

/* The state: the points' positions, each input point's vertices, each vertex's evaluation point (1% of
 * the way into its patch, as before any refinement). */
static bn_status bn__refine_init(bn__refine *R, bn_bake *b, bn_error *err)
{
    size_t nv = b->nverts, npv;
    const double *pv = bn_scene_patch_vertices(b->scene, &npv);
    memset(R, 0, sizeof *R);
    R->b = b;
    R->pa = bn_scene_patches(b->scene, NULL);
    R->npt0 = R->ptcap = b->npoints;
    R->vcap = R->nv0 = nv;
    R->vpcap = b->vstart[nv];
    R->ppos = bn__malloc_array(R->npt0 + 1, 3 * sizeof(double));
    R->pv_start = bn__calloc(R->npt0 + 2, sizeof(size_t));
    R->pv = bn__malloc_array(nv + 1, sizeof(size_t));
    R->xev = bn__malloc_array(nv + 1, 3 * sizeof(double));
    R->vpat = bn__malloc_array(nv + 1, sizeof(size_t));
    if (!R->ppos || !R->pv_start || !R->pv || !R->xev || !R->vpat || bn__emap_init(&R->split, 1024) != BN_OK || bn__emap_init(&R->linear, 1024) != BN_OK ||
        bn__emap_init(&R->vsplit, 1024) != BN_OK)
        return bn_error_set(err, BN_ENOMEM, "bake: out of memory refining %zu vertices", nv);
    memcpy(R->ppos, pv, npv * 3 * sizeof(double));
    for (size_t v = 0; v < nv; v++)
        R->pv_start[b->vpoint[v] + 2]++;
    for (size_t p = 0; p < R->npt0; p++)
        R->pv_start[p + 2] += R->pv_start[p + 1];
    for (size_t v = 0; v < nv; v++)   /* pv_start[p + 1] counts up to p's end: then pv_start is the CSR */
        R->pv[R->pv_start[b->vpoint[v] + 1]++] = v;
    for (size_t v = 0; v < nv; v++)
        bn__vertex_on(R, v, bn_bake_vertex_patch(b, v));
    return BN_OK;
}

/* 2% of the display white (2^-EV at the bake's automatic exposure of the key layer): differences in
 * the dark below it weigh less. */
static double bn__refine_floor(const double *val, size_t nv, size_t nl, size_t key)
{
    double *rgb = bn__malloc_array(nv + 1, 3 * sizeof *rgb), floor;
    if (!rgb)
        return 0;
    for (size_t v = 0; v < nv; v++)
        memcpy(rgb + 3 * v, val + (v * nl + key) * 3, 3 * sizeof *rgb);
    floor = 0.02 * pow(2.0, -bn_bake_auto_exposure(rgb, nv));
    free(rgb);
    return floor;
}

/* Rounds of marking the edges that differ, closing the mesh and evaluating the new vertices. */
static bn_status bn__refine_rounds(bn__refine *R, const bn_bake_refine_opts *o, double **val, bn_error *err)
{
    bn_bake *b = R->b;
    double floor = bn__refine_floor(*val, b->nverts, o->nlayers, o->key), t0 = bn__now();
    double min_edge = o->min_edge > 0 ? o->min_edge : 1e-3 * b->eps / 1e-9;
    size_t nv0 = b->nverts;
    int round = 0;
    if (nv0 + 8 > o->max_vertices)
        bn_logf(o->log, BN_LOG_INFO, "bake: the element mesh has %zu vertices, the budget %zu: nothing is refined (a "
                "larger vertex budget refines where light changes; each vertex is gathered all the same)", nv0,
                o->max_vertices);
    while (b->nverts < o->max_vertices) {
        size_t room = (o->max_vertices - b->nverts) / 8, marked = 0, probed = 0, first = b->nverts;
        bn_status st = room ? bn__mark(R, o, *val, floor, min_edge, room, &marked, &probed, err) : BN_OK;
        if (st != BN_OK)
            return st;
        if (!room || !probed)
            break;
        if ((st = bn__conform(R, err)) != BN_OK || (st = bn__evaluate(R, o, first, val, err)) != BN_OK)
            return st;
        bn_logf(o->log, BN_LOG_DEBUG, "bake: refinement round %d: %zu edges split: %zu vertices (+%zu), %zu triangles",
                ++round, marked, b->nverts, b->nverts - first, b->ntri);
        if ((st = bn_interrupted()) != BN_OK)
            return bn_error_set(err, st, "bake: interrupted while refining");
    }
    bn_logf(o->log, BN_LOG_INFO, "bake: refined where L changes by more than %g%% along a flat surface (edges down to "
            "%.3g; %zu midpoints probed): %zu rounds, %zu vertices (+%zu, budget %zu%s), %zu triangles, %.1f s", 100 * o->tol,
            min_edge, R->probes, (size_t)round,
            b->nverts, b->nverts - nv0, o->max_vertices, b->nverts + 8 > o->max_vertices ? ": spent" : "", b->ntri,
            bn__now() - t0);
    return BN_OK;
}

bn_status bn_bake_refine(bn_bake *b, const bn_bake_refine_opts *o, double **values, bn_error *err)
{
    bn__refine R;
    double *val = NULL;
    size_t nl = o->nlayers;
    bn_status st;
    *values = NULL;
    if (b->tri)
        return bn_error_set(err, BN_EUSAGE, "bake: the mesh is refined already");
    if (!o->eval || nl < 1 || o->key >= nl || !(o->tol > 0) || !(o->min_edge >= 0))
        return bn_error_set(err, BN_EUSAGE, "bake: refinement needs an evaluation, layers (key %zu of %zu), tolerance "
                            "%g > 0 and min_edge %g >= 0", o->key, nl, o->tol, o->min_edge);
    st = bn__refine_init(&R, b, err);
    if (st == BN_OK && o->max_vertices && (st = bn__triangulate(&R, err)) == BN_OK &&
        (st = bn__hanging(&R, err)) == BN_OK)
        st = bn__conform(&R, err);   /* T-junctions split: crack-free before any value is known */
    if (st == BN_OK)
        st = bn__evaluate(&R, o, 0, &val, err);
    if (st == BN_OK && o->max_vertices)
        st = bn__refine_rounds(&R, o, &val, err);
    if (st == BN_OK && !(*values = bn__malloc_array(b->nverts * nl + 1, 3 * sizeof(double))))
        st = bn_error_set(err, BN_ENOMEM, "bake: out of memory for the values of %zu vertices", b->nverts);
    for (size_t v = 0; st == BN_OK && v < b->nverts; v++)   /* vertex-major to layer-major */
        for (size_t l = 0; l < nl; l++)
            memcpy(*values + (l * b->nverts + v) * 3, val + (v * nl + l) * 3, 3 * sizeof(double));
    bn__refine_free(&R);
    free(val);
    return st;
}
