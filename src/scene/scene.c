/* Scene validation (degenerate, duplicate, non-planar polygons), faces, accessors. */
#define _POSIX_C_SOURCE 200809L
#include "scene/scene_internal.h"
#include "base/vec.h"

#include <ctype.h>
#include <math.h>
#include <string.h>
#include <strings.h>

/* Non-planarity, relative to a polygon's size, above which its split is a warning, not a note. */
#define BN_NONPLANAR_WARN 1e-2

/* The units in enum order (bn_unit). */
#define BN__UNITS(X) X("m") X("cm") X("mm")
BN__VOCABULARY(bn_unit, bn_unit, BN__UNITS)
double bn_unit_to_metres(bn_unit u) { return u == BN_UNIT_MM ? 1e-3 : u == BN_UNIT_CM ? 1e-2 : 1.0; }

void bn_load_opts_default(bn_load_opts *o)
{
    memset(o, 0, sizeof *o);
    o->unit = BN_UNIT_M;
    o->planar_tol = 1e-6;   /* relative to the face diameter: far above double rounding (1e-16),
                               far below the millimetre errors of measured models (1e-3) */
}

/* ---------------- polygon soup ---------------- */
/* ---------------- face building ---------------- */
typedef struct bn__builder {
    bn_scene *sc;
    size_t faces_cap, fidx_cap;
    signed char vn;   /* the polygon being built against its vertex normals: 1 agrees, -1 did not, 0 none */
} bn__builder;

static const double *bn__vp(const bn__soup *s, size_t i) { return s->verts + 3 * i; }

/* Newell's normal (not normalised): twice the area vector of a planar polygon. */
static void bn__newell(const bn__soup *s, const size_t *v, unsigned n, double nrm[3])
{
    nrm[0] = nrm[1] = nrm[2] = 0;
    for (unsigned i = 0; i < n; i++) {
        const double *a = bn__vp(s, v[i]), *b = bn__vp(s, v[(i + 1) % n]);
        nrm[0] += (a[1] - b[1]) * (a[2] + b[2]);
        nrm[1] += (a[2] - b[2]) * (a[0] + b[0]);
        nrm[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
}

static double bn__diameter(const bn__soup *s, const size_t *v, unsigned n)
{
    double d = 0;
    for (unsigned i = 0; i < n; i++)
        for (unsigned j = i + 1; j < n; j++) {
            double e = bn_v3_dist(bn__vp(s, v[i]), bn__vp(s, v[j]));
            if (e > d)
                d = e;
        }
    return d;
}

static bn_status bn__emit_face(bn__builder *b, const bn__soup *s, const size_t *v, unsigned n, unsigned mat,
                               size_t source, unsigned line, const double unit_normal[3], double area)
{
    bn_scene *sc = b->sc;
    bn_face *f;
    if (!bn__grow((void **)&sc->faces, &b->faces_cap, sc->nfaces + 1, sizeof(bn_face)) ||
        !bn__grow((void **)&sc->fidx, &b->fidx_cap, sc->nfidx + n, sizeof(size_t)))
        return BN_ENOMEM;
    (void)s;
    f = &sc->faces[sc->nfaces++];
    memset(f, 0, sizeof *f);
    f->first = sc->nfidx;
    f->nverts = n;
    f->material = mat;
    memcpy(f->normal, unit_normal, sizeof f->normal);
    f->area = area;
    f->source = source;
    f->line = line;
    f->vn = b->vn;
    memcpy(sc->fidx + sc->nfidx, v, n * sizeof(size_t));
    sc->nfidx += n;
    return BN_OK;
}

/* Emits triangle (a, b, c) unless it is degenerate; counts drops. */
static bn_status bn__emit_triangle(bn__builder *b, const bn__soup *s, size_t a, size_t bb, size_t c,
                                   unsigned mat, size_t source, unsigned line, double area_eps, size_t *dropped)
{
    size_t v[3] = {a, bb, c};
    double e1[3], e2[3], n[3], area;
    bn_v3_sub(bn__vp(s, bb), bn__vp(s, a), e1);
    bn_v3_sub(bn__vp(s, c), bn__vp(s, a), e2);
    bn_v3_cross(e1, e2, n);
    area = 0.5 * bn_v3_normalize(n);
    if (!(area > area_eps) || !(area > 1e-10 * pow(bn__diameter(s, v, 3), 2))) {
        (*dropped)++;
        return BN_OK;
    }
    return bn__emit_face(b, s, v, 3, mat, source, line, n, area);
}

/* Ear clipping in the plane orthogonal to `nrm` (O(n^2)); out receives n-2 triangles. */
static int bn__ear_clip(const bn__soup *s, const size_t *v, unsigned n, const double nrm[3], size_t *out)
{
    int ax = 0, ay, az;
    double sign;
    unsigned *idx = malloc(n * sizeof *idx), m = n, ntri = 0;
    double (*p)[2] = malloc(n * sizeof *p);
    if (!idx || !p) {
        free(idx);
        free(p);
        return -1;
    }
    if (fabs(nrm[1]) > fabs(nrm[ax])) ax = 1;
    if (fabs(nrm[2]) > fabs(nrm[ax])) ax = 2;
    ay = (ax + 1) % 3;
    az = (ax + 2) % 3;
    sign = nrm[ax] > 0 ? 1.0 : -1.0;
    for (unsigned i = 0; i < n; i++) {
        idx[i] = i;
        p[i][0] = bn__vp(s, v[i])[ay];
        p[i][1] = bn__vp(s, v[i])[az];
    }
    while (m > 3) {
        int found = 0;
        for (unsigned i = 0; i < m && !found; i++) {
            unsigned ia = idx[(i + m - 1) % m], ib = idx[i], ic = idx[(i + 1) % m];
            double cr = (p[ib][0] - p[ia][0]) * (p[ic][1] - p[ia][1]) - (p[ib][1] - p[ia][1]) * (p[ic][0] - p[ia][0]);
            int inside = 0;
            if (sign * cr <= 0)
                continue;   /* reflex or collinear */
            for (unsigned j = 0; j < m && !inside; j++) {
                unsigned q = idx[j];
                double d1, d2, d3;
                if (q == ia || q == ib || q == ic)
                    continue;
                d1 = (p[ib][0] - p[ia][0]) * (p[q][1] - p[ia][1]) - (p[ib][1] - p[ia][1]) * (p[q][0] - p[ia][0]);
                d2 = (p[ic][0] - p[ib][0]) * (p[q][1] - p[ib][1]) - (p[ic][1] - p[ib][1]) * (p[q][0] - p[ib][0]);
                d3 = (p[ia][0] - p[ic][0]) * (p[q][1] - p[ic][1]) - (p[ia][1] - p[ic][1]) * (p[q][0] - p[ic][0]);
                inside = sign * d1 >= 0 && sign * d2 >= 0 && sign * d3 >= 0;
            }
            if (inside)
                continue;
            out[3 * ntri + 0] = v[ia];
            out[3 * ntri + 1] = v[ib];
            out[3 * ntri + 2] = v[ic];
            ntri++;
            memmove(idx + i, idx + i + 1, (m - i - 1) * sizeof *idx);
            m--;
            found = 1;
        }
        if (!found) {
            free(idx);
            free(p);
            return 0;
        }
    }
    out[3 * ntri + 0] = v[idx[0]];
    out[3 * ntri + 1] = v[idx[1]];
    out[3 * ntri + 2] = v[idx[2]];
    free(idx);
    free(p);
    return 1;
}

/* Face key for duplicate detection: vertex positions sorted. */
typedef struct bn__fkey {
    size_t face;
    unsigned n;
    double p[4][3];
} bn__fkey;

static int bn__cmp_pt(const void *a, const void *b)
{
    const double *x = a, *y = b;
    for (int k = 0; k < 3; k++)
        if (x[k] != y[k])
            return x[k] < y[k] ? -1 : 1;
    return 0;
}

static int bn__cmp_fkey(const void *a, const void *b)
{
    const bn__fkey *x = a, *y = b;
    if (x->n != y->n)
        return x->n < y->n ? -1 : 1;
    for (unsigned i = 0; i < x->n; i++) {
        int c = bn__cmp_pt(x->p[i], y->p[i]);
        if (c)
            return c;
    }
    return x->face < y->face ? -1 : (x->face > y->face);
}

static int bn__same_key(const bn__fkey *x, const bn__fkey *y)
{
    if (x->n != y->n)
        return 0;
    for (unsigned i = 0; i < x->n; i++)
        if (bn__cmp_pt(x->p[i], y->p[i]))
            return 0;
    return 1;
}

static bn_status bn__drop_duplicates(bn_scene *sc, const char *path, const bn_log *log)
{
    bn__fkey *keys;
    unsigned char *drop;
    size_t w = 0, nf = sc->nfaces;
    if (nf < 2)
        return BN_OK;
    keys = bn__malloc_array(nf, sizeof *keys);
    drop = bn__calloc(nf, 1);
    if (!keys || !drop) {
        free(keys);
        free(drop);
        return BN_ENOMEM;
    }
    for (size_t f = 0; f < nf; f++) {
        keys[f].face = f;
        keys[f].n = sc->faces[f].nverts;
        for (unsigned i = 0; i < keys[f].n; i++)
            memcpy(keys[f].p[i], sc->verts + 3 * sc->fidx[sc->faces[f].first + i], 3 * sizeof(double));
        qsort(keys[f].p, keys[f].n, sizeof keys[f].p[0], bn__cmp_pt);
    }
    qsort(keys, nf, sizeof *keys, bn__cmp_fkey);
    for (size_t i = 0; i < nf;) {
        size_t j = i + 1;
        while (j < nf && bn__same_key(&keys[i], &keys[j]))
            j++;
        /* keys[i..j) share their vertices; keys[i] is the earliest face. */
        for (size_t k = i + 1; k < j; k++) {
            const bn_face *a = &sc->faces[keys[i].face], *b = &sc->faces[keys[k].face];
            if (bn_v3_dot(a->normal, b->normal) > 0) {
                drop[keys[k].face] = 1;
                sc->stats.duplicates_dropped++;
                bn_warnf(log, BN_W_FACE_DROPPED, 1, "%s:%u: face duplicates the face at line %u; dropped", path, b->line,
                        a->line);
            } else if (!(a->source == b->source && (a->back || b->back))) {   /* not a two-sided face's sides */
                sc->stats.back_to_back++;
                bn_warnf(log, BN_W_BACK_TO_BACK, NAN,
                        "%s:%u: face lies back to back with the face at line %u (a two-sided panel); both kept",
                        path, b->line, a->line);
            }
        }
        i = j;
    }
    for (size_t f = 0; f < nf; f++)
        if (!drop[f])
            sc->faces[w++] = sc->faces[f];
    sc->nfaces = w;
    free(keys);
    free(drop);
    return BN_OK;
}

/* Materials in range, finite vertices, indices and materials in range; the used vertices' bounds. */
static bn_status bn__soup_check(const char *path, const bn__soup *s, double lo[3], double hi[3], bn_error *err)
{
    if (s->npolys == 0)
        return bn_error_set(err, BN_EINPUT, "%s: the scene has no faces", path);
    for (size_t m = 0; m < s->nmats; m++)
        for (int c = 0; c < 3; c++) {
            const bn_material *mt = &s->mats[m];
            if (!isfinite(mt->rho[c]) || mt->rho[c] < 0 || mt->rho[c] > 1)
                return bn_error_set(err, BN_EINPUT, "%s: material '%s': reflectance %g is outside [0, 1]", path,
                                    mt->name, mt->rho[c]);
            if (!isfinite(mt->Le[c]) || mt->Le[c] < 0)
                return bn_error_set(err, BN_EINPUT, "%s: material '%s': emitted radiance %g is negative or not finite",
                                    path, mt->name, mt->Le[c]);
        }
    for (size_t v = 0; v < s->nverts; v++)
        for (int k = 0; k < 3; k++)
            if (!isfinite(s->verts[3 * v + k]))
                return bn_error_set(err, BN_EINPUT, "%s: vertex %zu has a coordinate that is not finite (%g)", path,
                                    v, s->verts[3 * v + k]);
    for (int k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
    }
    for (size_t i = 0; i < s->nidx; i++) {
        if (s->idx[i] >= s->nverts)
            return bn_error_set(err, BN_EINPUT, "%s: vertex index %zu out of range (%zu vertices)", path, s->idx[i],
                                s->nverts);
        for (int k = 0; k < 3; k++) {
            double x = s->verts[3 * s->idx[i] + k];
            lo[k] = fmin(lo[k], x);
            hi[k] = fmax(hi[k], x);
        }
    }
    for (size_t p = 0; p < s->npolys; p++)
        if (s->mat[p] >= s->nmats)
            return bn_error_set(err, BN_EINPUT, "%s: polygon %zu has material %u of %zu", path, p, s->mat[p],
                                s->nmats);
    return BN_OK;
}

/* A scene holding the soup's materials and vertices, no faces yet. */
static bn_scene *bn__scene_new(const char *path, const bn__soup *s, const bn_load_opts *o, const double lo[3],
                               const double hi[3])
{
    bn_scene *sc = calloc(1, sizeof *sc);
    if (!sc)
        return NULL;
    sc->path = bn__strdup(path);
    sc->unit = o->unit;
    sc->nmats = s->nmats;
    sc->mats = bn__malloc_array(s->nmats, sizeof *sc->mats);
    sc->nverts = s->nverts;
    sc->verts = bn__malloc_array(3 * s->nverts, sizeof(double));
    if (!sc->path || !sc->mats || !sc->verts) {
        bn_scene_destroy(sc);
        return NULL;
    }
    memcpy(sc->mats, s->mats, s->nmats * sizeof *sc->mats);
    memcpy(sc->verts, s->verts, 3 * s->nverts * sizeof(double));
    memcpy(sc->lo, lo, 3 * sizeof(double));
    memcpy(sc->hi, hi, 3 * sizeof(double));
    sc->stats.input_polygons = s->npolys;
    return sc;
}

/* The polygon's corners without repeats (the same index or position as the previous corner, and
 * the last closing onto the first): their count. */
static unsigned bn__polygon_corners(const bn__soup *s, const size_t *idx, unsigned n0, size_t *v)
{
    unsigned n = 0;
    for (unsigned i = 0; i < n0; i++) {
        size_t vi = idx[i];
        if (n > 0 && (vi == v[n - 1] || bn__cmp_pt(bn__vp(s, vi), bn__vp(s, v[n - 1])) == 0))
            continue;
        v[n++] = vi;
    }
    while (n > 1 && (v[0] == v[n - 1] || bn__cmp_pt(bn__vp(s, v[0]), bn__vp(s, v[n - 1])) == 0))
        n--;
    return n;
}

/* A polygon's plane: unit normal, area, diameter, and the largest distance of a corner from the
 * plane through the corners' mean. */
typedef struct bn__plane {
    double nrm[3], area, diam, dev;
} bn__plane;

static void bn__polygon_plane(const bn__soup *s, const size_t *v, unsigned n, bn__plane *pl)
{
    double c[3] = {0, 0, 0};
    bn__newell(s, v, n, pl->nrm);
    pl->area = 0.5 * bn_v3_normalize(pl->nrm);
    pl->diam = bn__diameter(s, v, n);
    pl->dev = 0;
    for (unsigned i = 0; i < n; i++)
        bn_v3_add(c, bn__vp(s, v[i]), c);
    bn_v3_scale(c, 1.0 / n, c);
    for (unsigned i = 0; i < n; i++) {
        double d[3];
        bn_v3_sub(bn__vp(s, v[i]), c, d);
        pl->dev = fmax(pl->dev, fabs(bn_v3_dot(d, pl->nrm)));
    }
}

static int bn__quad_convex(const bn__soup *s, const size_t *v, const bn__plane *pl)
{
    for (unsigned i = 0; i < 4; i++) {
        double e1[3], e2[3], cr[3];
        bn_v3_sub(bn__vp(s, v[(i + 1) % 4]), bn__vp(s, v[i]), e1);
        bn_v3_sub(bn__vp(s, v[(i + 2) % 4]), bn__vp(s, v[(i + 1) % 4]), e2);
        bn_v3_cross(e1, e2, cr);
        if (bn_v3_dot(cr, pl->nrm) <= 1e-12 * pl->diam * pl->diam)
            return 0;
    }
    return 1;
}

/* What building the faces needs besides the soup and the scene. */
typedef struct bn__polys {
    const char *path;
    const bn_load_opts *o;
    double area_eps;        /* a face smaller than this is below double rounding at the scene's size */
    size_t *tri, tri_cap;   /* scratch: triangles of an ear clipping, then the corners */
    size_t degenerate;
    double worst_cos;       /* the cosine between winding and vertex normals of the worst polygon */
} bn__polys;

/* Polygon p's winding against its vertex normals (their sum, s->pn): b->vn and the counts; with
 * BN_ORIENT_NORMALS a polygon wound against them is reversed (corners v[0 .. n)). 1 if reversed. */
static int bn__orient(bn__builder *b, const bn__soup *s, bn__polys *P, size_t p, size_t *v, unsigned n,
                      const bn__plane *pl)
{
    const double *pn = s->pn ? s->pn + 3 * p : NULL;
    double len, c;
    bn_scene_stats *st = &b->sc->stats;
    b->vn = 0;
    if (!pn || !((len = sqrt(pn[0] * pn[0] + pn[1] * pn[1] + pn[2] * pn[2])) > 0))
        return 0;
    st->with_normals++;
    c = (pl->nrm[0] * pn[0] + pl->nrm[1] * pn[1] + pl->nrm[2] * pn[2]) / len;
    b->vn = c < 0 ? -1 : 1;
    if (c >= 0)
        return 0;
    if (st->winding_disagree++ == 0 || c < P->worst_cos) {
        P->worst_cos = c;
        st->winding_worst_line = s->line[p];
    }
    if (P->o->orient != BN_ORIENT_NORMALS)
        return 0;
    for (unsigned k = 0; k < n / 2; k++) {
        size_t t = v[k];
        v[k] = v[n - 1 - k];
        v[n - 1 - k] = t;
    }
    st->flipped++;
    return 1;
}

/* Polygon p (corners from idx) into faces: a triangle or a planar convex quad as it is; a
 * non-planar quad split along its 1st-3rd diagonal; anything else by ear clipping. */
static bn_status bn__build_polygon(bn__builder *b, const bn__soup *s, bn__polys *P, size_t p, const size_t *idx,
                                   bn_error *err)
{
    unsigned n0 = s->counts[p], n, line = s->line[p], mat = s->mat[p];
    size_t *v, *tri;
    bn__plane pl;
    int r;
    if (!bn__grow((void **)&P->tri, &P->tri_cap, 4 * (size_t)n0, sizeof(size_t)))
        return BN_ENOMEM;
    tri = P->tri;
    v = tri + 3 * (size_t)n0; /* tri[0 .. 3n0) holds up to n0 - 2 triangles, then n0 corners */
    n = bn__polygon_corners(s, idx, n0, v);
    if (n < 3) {
        P->degenerate++;
        return BN_OK;
    }
    bn__polygon_plane(s, v, n, &pl);
    if (!(pl.area > P->area_eps) || !(pl.area > 1e-10 * pl.diam * pl.diam)) {
        P->degenerate++;
        return BN_OK;
    }
    if (bn__orient(b, s, P, p, v, n, &pl))
        bn__polygon_plane(s, v, n, &pl);
    if (n == 3)
        return bn__emit_triangle(b, s, v[0], v[1], v[2], mat, p, line, P->area_eps, &P->degenerate);
    if (pl.dev > P->o->planar_tol * pl.diam) {
        /* A split is exact geometry, not a loss: a note, and a warning only where the bend is large
         * enough (1% of the polygon) that the choice of diagonal shows in the light. */
        char msg[512];
        b->sc->stats.nonplanar_split++;
        if (n == 4)
            snprintf(msg, sizeof msg,
                     "%s:%u: quad is non-planar (a vertex is %.3g off its mean plane, %.2g of its size); split into two "
                     "triangles along the diagonal from its 1st to its 3rd vertex",
                     P->path, line, pl.dev, pl.dev / pl.diam);
        else
            snprintf(msg, sizeof msg, "%s:%u: polygon of %u vertices is non-planar by %.3g; triangulated", P->path,
                     line, n, pl.dev);
        if (pl.dev > BN_NONPLANAR_WARN * pl.diam)
            bn_warnf(&P->o->log, BN_W_NONPLANAR, pl.dev / pl.diam, "%s", msg);
        else
            bn_logf(&P->o->log, BN_LOG_INFO, "%s", msg);
        if (n == 4) {
            bn_status st = bn__emit_triangle(b, s, v[0], v[1], v[2], mat, p, line, P->area_eps, &P->degenerate);
            return st == BN_OK ? bn__emit_triangle(b, s, v[0], v[2], v[3], mat, p, line, P->area_eps, &P->degenerate)
                               : st;
        }
    } else if (n == 4 && bn__quad_convex(s, v, &pl)) {
        return bn__emit_face(b, s, v, 4, mat, p, line, pl.nrm, pl.area);
    }
    /* Planar non-convex quads and polygons of 5+ vertices: ear clipping. */
    b->sc->stats.polygons_triangulated++;
    r = bn__ear_clip(s, v, n, pl.nrm, tri);
    if (r < 0)
        return BN_ENOMEM;
    if (r == 0)
        return bn_error_set(err, BN_EINPUT, "%s:%u: polygon of %u vertices intersects itself; cannot triangulate",
                            P->path, line, n);
    for (unsigned t = 0; t < n - 2; t++) {
        bn_status st = bn__emit_triangle(b, s, tri[3 * t], tri[3 * t + 1], tri[3 * t + 2], mat, p, line, P->area_eps,
                                         &P->degenerate);
        if (st != BN_OK)
            return st;
    }
    return BN_OK;
}

/* Faces wound against their vertex normals: turned (said as a warning: the geometry is not the
 * file's winding), or kept as wound (a warning: their lit side is the other one). */
static void bn__orient_said(const bn_scene *sc, const char *path, const bn_load_opts *o)
{
    const bn_scene_stats *st = &sc->stats;
    if (!st->winding_disagree)
        return;
    if (st->flipped)
        bn_warnf(&o->log, BN_W_ORIENTATION, (double)st->flipped,
                 "%s: %zu of the %zu polygons with vertex normals are wound against them (the most opposed at line %u); "
                 "turned to face where their normals point (`orient` winding keeps the file's winding)",
                 path, st->flipped, st->with_normals, st->winding_worst_line);
    else
        bn_warnf(&o->log, BN_W_ORIENTATION, (double)st->winding_disagree,
                 "%s: %zu of the %zu polygons with vertex normals are wound against them (the most opposed at line %u); "
                 "kept as wound (`orient` winding), so they reflect on the side their normals point away from",
                 path, st->winding_disagree, st->with_normals, st->winding_worst_line);
}

/* Duplicates dropped, counts and warnings said, and a scene with no face refused. */
static bn_status bn__scene_finish(bn_scene *sc, const char *path, const bn_load_opts *o, size_t degenerate,
                                  bn_error *err)
{
    bn_status st = bn__drop_duplicates(sc, path, &o->log);
    if (st != BN_OK)
        return bn_error_set(err, st, "out of memory building faces of %s", path);
    sc->stats.degenerate_dropped = degenerate;
    if (degenerate)
        bn_warnf(&o->log, BN_W_FACE_DROPPED, (double)degenerate, "%s: %zu degenerate (zero-area) face%s dropped", path, degenerate,
                degenerate == 1 ? "" : "s");
    if (sc->nfaces == 0)
        return bn_error_set(err, BN_EINPUT, "%s: no face with a non-zero area", path);
    bn__orient_said(sc, path, o);
    if (bn_scene_emitter_count(sc) == 0 && sc->nlights == 0)
        bn_warnf(&o->log, BN_W_NO_EMITTER, NAN, "%s: no emitter (no material emits: Ke in MTL, emissiveFactor in glTF): the result will be black", path);
    return BN_OK;
}

bn_status bn__scene_build(const char *path, bn__soup *s, const bn_load_opts *o, bn_scene **out,
                          bn_error *err)
{
    bn_load_opts defo;
    bn__builder b;
    bn__polys P;
    bn_scene *sc;
    double lo[3], hi[3], d[3];
    size_t pos = 0;
    bn_status st;

    *out = NULL;
    if (!o) {
        bn_load_opts_default(&defo);
        o = &defo;
    }
    st = bn__soup_check(path, s, lo, hi, err);
    if (st != BN_OK)
        return st;
    sc = bn__scene_new(path, s, o, lo, hi);
    if (!sc)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    sc->tree = s->tree;   /* the scene takes the tree and the lights */
    s->tree = NULL;
    sc->lights = s->lights, sc->nlights = s->nlights;
    s->lights = NULL, s->nlights = s->lights_cap = 0;
    memset(&b, 0, sizeof b);
    b.sc = sc;
    memset(&P, 0, sizeof P);
    P.path = path;
    P.o = o;
    bn_v3_sub(hi, lo, d);
    P.area_eps = 1e-24 * bn_v3_dot(d, d);
    for (size_t p = 0; p < s->npolys && st == BN_OK; p++) {
        st = bn__build_polygon(&b, s, &P, p, s->idx + pos, err);
        pos += s->counts[p];
    }
    free(P.tri);
    if (st == BN_ENOMEM)
        bn_error_set(err, st, "out of memory building faces of %s", path);
    if (st == BN_OK)
        st = bn__scene_two_sided(sc, path, s->mat_two, s->mat_two_cap, o->two_sided, err);
    if (st == BN_OK)
        st = bn__scene_finish(sc, path, o, P.degenerate, err);
    if (st == BN_OK && bn__scene_objects(sc, s) != BN_OK)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the objects of %s", path);
    sc->cam = s->cam;
    if (st == BN_OK && bn__scene_textures(sc, s) != BN_OK)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the texture coordinates of %s", path);
    if (st != BN_OK) {
        bn_scene_destroy(sc);
        return st;
    }
    *out = sc;
    return BN_OK;
}

bn_status bn_scene_from_arrays(const char *name, const double *verts, size_t nverts, const unsigned *polys,
                               size_t npolys, const unsigned *poly_material, const bn_material *materials,
                               size_t nmaterials, const bn_load_opts *o, bn_scene **out, bn_error *err)
{
    bn__soup s;
    bn_status st = BN_OK;
    size_t k = 0;
    memset(&s, 0, sizeof s);
    *out = NULL;
    for (size_t v = 0; v < nverts && st == BN_OK; v++)
        if (!bn__soup_add_vertex(&s, verts + 3 * v))
            st = BN_ENOMEM;
    for (size_t m = 0; m < nmaterials && st == BN_OK; m++)
        if (!bn__soup_add_material(&s, &materials[m]))
            st = BN_ENOMEM;
    for (size_t p = 0; p < npolys && st == BN_OK; p++) {
        unsigned n = polys[k++];
        size_t *idx = bn__malloc_array(n, sizeof *idx);
        if (!idx) {
            st = BN_ENOMEM;
            break;
        }
        for (unsigned i = 0; i < n; i++)
            idx[i] = polys[k++];
        if (!bn__soup_add_polygon(&s, idx, n, poly_material[p], 0))
            st = BN_ENOMEM;
        free(idx);
    }
    if (st == BN_OK)
        st = bn__scene_build(name, &s, o, out, err);
    else
        bn_error_set(err, st, "out of memory");
    bn__soup_free(&s);
    return st;
}

static const char *bn__ext(const char *path)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash))
        return "";
    return dot + 1;
}

bn_status bn_scene_load(const char *path, const bn_load_opts *o, bn_scene **out, bn_error *err)
{
    bn__soup s;
    bn_load_opts defo;
    bn_status st;
    const char *ext = bn__ext(path);
    *out = NULL;
    if (!o) {
        bn_load_opts_default(&defo);
        o = &defo;
    }
    memset(&s, 0, sizeof s);
    if (strcasecmp(ext, "obj") == 0)
        st = bn__read_obj(path, &s, &o->log, err);
    else if (strcasecmp(ext, "ply") == 0)
        st = bn__read_ply(path, &s, &o->log, err);
    else if (strcasecmp(ext, "off") == 0)
        st = bn__read_off(path, &s, &o->log, err);
    else if (strcasecmp(ext, "gltf") == 0 || strcasecmp(ext, "glb") == 0) {
        st = bn__read_gltf(path, &s, &o->log, err);
        if (st == BN_OK && o->unit != BN_UNIT_M)
            bn_logf(&o->log, BN_LOG_INFO, "%s: glTF is in metres by its specification; read in %s as asked", path,
                    bn_unit_name(o->unit));
    }
    else
        st = bn_error_set(err, BN_EINPUT, "%s: unknown scene format '.%s' (bounce reads .obj, .ply, .off, .gltf and .glb)",
                          path, ext);
    if (st == BN_OK)
        st = bn__scene_build(path, &s, o, out, err);
    bn__soup_free(&s);
    if (st == BN_OK && o->nedits > 0 && (st = bn_scene_edit_materials(*out, o->edits, o->nedits, err)) != BN_OK) {
        bn_scene_destroy(*out);
        *out = NULL;
    }
    return st;
}

void bn_scene_destroy(bn_scene *s)
{
    if (!s)
        return;
    free(s->path);
    free(s->mats);
    free(s->verts);
    free(s->fidx);
    free(s->faces);
    free(s->patches);
    free(s->pverts);
    free(s->objnames);
    free(s->obj_assembly);
    free(s->mat_two_sided);
    bn__texture_free(s->tex, s->ntex);
    free(s->mat_tex);
    free(s->mat_etex);
    free(s->femit);
    free(s->fuv);
    free(s->ptex);
    bn__file_tree_free(s->tree);
    free(s->lights);
    free(s);
}

const bn_scene_node *bn_scene_nodes(const bn_scene *s, size_t *n, const size_t **roots, size_t *nroots)
{
    const bn__file_tree *t = s->tree;
    *n = t ? t->nnodes : 0;
    *roots = t ? t->roots : NULL;
    *nroots = t ? t->nroots : 0;
    return t ? t->nodes : NULL;
}

const char *bn_scene_path(const bn_scene *s) { return s->path; }
bn_unit bn_scene_unit(const bn_scene *s) { return s->unit; }
#define BN__ACCESS(fn, type, arr, cnt)                  \
    const type *fn(const bn_scene *s, size_t *count)    \
    {                                                   \
        if (count)                                      \
            *count = s->cnt;                            \
        return s->arr;                                  \
    }
BN__ACCESS(bn_scene_materials, bn_material, mats, nmats)
BN__ACCESS(bn_scene_vertices, double, verts, nverts)
BN__ACCESS(bn_scene_face_indices, size_t, fidx, nfidx)
BN__ACCESS(bn_scene_faces, bn_face, faces, nfaces)
BN__ACCESS(bn_scene_patches, bn_patch, patches, npatches)
BN__ACCESS(bn_scene_patch_vertices, double, pverts, npverts)
#undef BN__ACCESS
double bn_scene_patch_size(const bn_scene *s) { return s->patch_size; }
double bn_scene_largest_patch_edge(const bn_scene *s) { return s->largest_edge; }
bn_scene_stats bn_scene_stats_get(const bn_scene *s) { return s->stats; }

void bn_scene_bounds(const bn_scene *s, double lo[3], double hi[3])
{
    memcpy(lo, s->lo, sizeof s->lo);
    memcpy(hi, s->hi, sizeof s->hi);
}

double bn_scene_diameter(const bn_scene *s)
{
    double d[3];
    bn_v3_sub(s->hi, s->lo, d);
    return bn_v3_len(d);
}

const bn_material *bn_patch_material(const bn_scene *s, size_t patch) { return &s->mats[s->patches[patch].material]; }

static int bn__emits(const bn_material *m) { return m->Le[0] > 0 || m->Le[1] > 0 || m->Le[2] > 0; }

size_t bn_scene_emitter_count(const bn_scene *s)
{
    size_t n = 0;
    for (size_t f = 0; f < s->nfaces; f++)
        n += bn__emits(&s->mats[s->faces[f].material]);
    return n;
}

void bn_scene_emitted_power(const bn_scene *s, double watts[3])
{
    double m = bn_unit_to_metres(s->unit);
    watts[0] = watts[1] = watts[2] = 0;
    for (size_t f = 0; f < s->nfaces; f++) {
        double Le[3];
        bn_scene_face_emission(s, f, Le);
        for (int c = 0; c < 3; c++)
            watts[c] += BN_PI * s->faces[f].area * m * m * Le[c];
    }
}

void bn_scene_power(const bn_scene *s, const double *radiance, double watts[3])
{
    double m = bn_unit_to_metres(s->unit);
    watts[0] = watts[1] = watts[2] = 0;
    for (size_t p = 0; p < s->npatches; p++)
        for (int c = 0; c < 3; c++)
            watts[c] += BN_PI * s->patches[p].area * m * m * radiance[3 * p + (size_t)c];
}

/* The geometry alone: unit, vertices, polygons, patches (what F depends on). */
static uint64_t bn__geometry_digest(const bn_scene *s, uint64_t h)
{
    int u = (int)s->unit;
    h = bn__fnv1a(h, &u, sizeof u);
    h = bn__fnv1a(h, s->verts, s->nverts * 3 * sizeof(double));
    h = bn__fnv1a(h, s->fidx, s->nfidx * sizeof(size_t));
    h = bn__fnv1a(h, s->pverts, s->npverts * 3 * sizeof(double));
    for (size_t p = 0; p < s->npatches; p++)
        h = bn__fnv1a(h, s->patches[p].corner, sizeof s->patches[p].corner);
    return h;
}

unsigned long long bn_scene_geometry_digest(const bn_scene *s)
{
    return (unsigned long long)bn__geometry_digest(s, BN__FNV_INIT);
}

unsigned long long bn_scene_digest(const bn_scene *s)
{
    uint64_t h = BN__FNV_INIT;
    int u = (int)s->unit;
    h = bn__fnv1a(h, &u, sizeof u);
    for (size_t m = 0; m < s->nmats; m++) {
        h = bn__fnv1a(h, s->mats[m].name, strlen(s->mats[m].name));
        h = bn__fnv1a(h, s->mats[m].rho, sizeof s->mats[m].rho);
        h = bn__fnv1a(h, s->mats[m].Le, sizeof s->mats[m].Le);
    }
    h = bn__fnv1a(h, s->verts, s->nverts * 3 * sizeof(double));
    h = bn__fnv1a(h, s->fidx, s->nfidx * sizeof(size_t));
    for (size_t f = 0; f < s->nfaces; f++)
        h = bn__fnv1a(h, &s->faces[f].material, sizeof(unsigned));
    h = bn__fnv1a(h, s->pverts, s->npverts * 3 * sizeof(double));
    for (size_t p = 0; p < s->npatches; p++)
        h = bn__fnv1a(h, s->patches[p].corner, sizeof s->patches[p].corner);
    if (s->ptex)   /* textured reflectance per patch */
        h = bn__fnv1a(h, s->ptex, 3 * s->npatches * sizeof *s->ptex);
    if (s->femit)   /* textured emission per face */
        h = bn__fnv1a(h, s->femit, 3 * s->nfaces * sizeof *s->femit);
    for (size_t k = 0; k < s->nlights; k++) {   /* punctual lights: what they are, not their names */
        const bn_light *l = &s->lights[k];
        h = bn__fnv1a(h, &l->type, sizeof l->type);
        h = bn__fnv1a(h, l->pos, sizeof l->pos);
        h = bn__fnv1a(h, l->dir, sizeof l->dir);
        h = bn__fnv1a(h, l->I, sizeof l->I);
        h = bn__fnv1a(h, &l->cos_inner, sizeof l->cos_inner);
        h = bn__fnv1a(h, &l->cos_outer, sizeof l->cos_outer);
    }
    return (unsigned long long)h;
}

void bn_scene_patch_emission(const bn_scene *s, double *E)
{
    for (size_t i = 0; i < s->npatches; i++)
        bn_scene_face_emission(s, s->patches[i].face, E + 3 * i);
}

void bn_scene_patch_reflectance(const bn_scene *s, double *rho)
{
    for (size_t i = 0; i < s->npatches; i++)
        for (int c = 0; c < 3; c++)
            rho[3 * i + c] = s->mats[s->patches[i].material].rho[c] * (s->ptex ? s->ptex[3 * i + c] : 1);
}

int bn_scene_textured(const bn_scene *s) { return s->mat_tex != NULL; }

int bn_scene_camera(const bn_scene *s, double eye[3], double look[3], double up[3], double *fov_deg, double *aspect,
                    const char **name)
{
    if (!s->cam.has)
        return 0;
    memcpy(eye, s->cam.eye, sizeof s->cam.eye);
    memcpy(look, s->cam.look, sizeof s->cam.look);
    memcpy(up, s->cam.up, sizeof s->cam.up);
    *fov_deg = s->cam.yfov_deg, *aspect = s->cam.aspect, *name = s->cam.name;
    return 1;
}
