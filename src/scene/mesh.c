/* Planar patch meshing: quads become regular bilinear grids, triangles uniform subdivisions.
 * Patch vertices are shared inside a face (no T-junctions); patch areas sum to the face's. */
#include "scene/scene_internal.h"
#include "base/vec.h"

#include <math.h>
#include <string.h>

void bn_mesh_opts_default(bn_mesh_opts *o)
{
    memset(o, 0, sizeof *o);
    o->target_patches = BN_DEFAULT_PATCHES;
}

static const double *bn__fv(const bn_scene *s, const bn_face *f, unsigned i)
{
    return s->verts + 3 * s->fidx[f->first + i];
}

static unsigned bn__divisions(double len, double size)
{
    double n = ceil(len / size - 1e-9);   /* an edge of exactly k*size gets k divisions */
    if (!(n >= 1))
        return 1;
    if (n > 1e6)
        return 1000000u;
    return (unsigned)n;
}

/* Grid resolution of a face for patch edge `size` (size <= 0: one patch). */
static void bn__face_grid(const bn_scene *s, const bn_face *f, double size, unsigned *nu, unsigned *nv)
{
    if (size <= 0) {
        *nu = *nv = 1;
        return;
    }
    if (f->nverts == 4) {
        double a = fmax(bn_v3_dist(bn__fv(s, f, 0), bn__fv(s, f, 1)), bn_v3_dist(bn__fv(s, f, 3), bn__fv(s, f, 2)));
        double b = fmax(bn_v3_dist(bn__fv(s, f, 0), bn__fv(s, f, 3)), bn_v3_dist(bn__fv(s, f, 1), bn__fv(s, f, 2)));
        *nu = bn__divisions(a, size);
        *nv = bn__divisions(b, size);
    } else {
        double e = fmax(bn_v3_dist(bn__fv(s, f, 0), bn__fv(s, f, 1)),
                        fmax(bn_v3_dist(bn__fv(s, f, 1), bn__fv(s, f, 2)), bn_v3_dist(bn__fv(s, f, 2), bn__fv(s, f, 0))));
        *nu = *nv = bn__divisions(e, size);
    }
}

static double bn__count(const bn_scene *s, double size)
{
    double total = 0;
    for (size_t f = 0; f < s->nfaces; f++) {
        unsigned nu, nv;
        bn__face_grid(s, &s->faces[f], size, &nu, &nv);
        total += s->faces[f].nverts == 4 ? (double)nu * nv : (double)nu * nu;
    }
    return total;
}

/* The grid's patches on the faces it splits (more than one patch): what a target count governs.
 * A face smaller than the patch is one patch whatever the target, so a scene of many small faces
 * (a scanned model, a lamp cut into 10,000 triangles) does not coarsen its large ones (the floor). */
static double bn__count_split(const bn_scene *s, double size)
{
    double total = 0;
    for (size_t f = 0; f < s->nfaces; f++) {
        unsigned nu, nv;
        double c;
        bn__face_grid(s, &s->faces[f], size, &nu, &nv);
        c = s->faces[f].nverts == 4 ? (double)nu * nv : (double)nu * nu;
        total += c > 1 ? c : 0;
    }
    return total;
}

/* A patch of face fi with the given corners, finished (area, centroid, normal). */
static void bn__grid_patch(bn_patch *p, size_t fi, const bn_face *f, unsigned nc, const size_t *corner,
                           const double *pv)
{
    memset(p, 0, sizeof *p);
    p->face = fi;
    p->material = f->material;
    p->ncorners = nc;
    for (unsigned k = 0; k < nc; k++)
        p->corner[k] = corner[k];
    bn__scene_patch_finish(p, pv, f->normal);
}

/* A quad face's nu x nv grid: its (nu + 1)(nv + 1) points from pv + 3 *iv on, then its patches. */
static void bn__grid_quad(const bn_scene *s, size_t fi, unsigned nu, unsigned nvv, bn_patch *patches, size_t *ip,
                          double *pv, size_t *iv)
{
    const bn_face *f = &s->faces[fi];
    const double *a = bn__fv(s, f, 0), *b = bn__fv(s, f, 1), *c = bn__fv(s, f, 2), *d = bn__fv(s, f, 3);
    size_t base = *iv;
    for (unsigned j = 0; j <= nvv; j++)
        for (unsigned i = 0; i <= nu; i++) {
            double u = (double)i / nu, v = (double)j / nvv;
            double *q = pv + 3 * (*iv)++;
            /* Exact corners at the ends keep neighbouring faces' vertices identical. */
            for (int k = 0; k < 3; k++)
                q[k] = (1 - u) * (1 - v) * a[k] + u * (1 - v) * b[k] + u * v * c[k] + (1 - u) * v * d[k];
        }
    for (unsigned j = 0; j < nvv; j++)
        for (unsigned i = 0; i < nu; i++) {
            size_t c0 = base + (size_t)j * (nu + 1) + i, cr[4] = {c0, c0 + 1, c0 + 1 + (nu + 1), c0 + (nu + 1)};
            bn__grid_patch(&patches[(*ip)++], fi, f, 4, cr, pv);
        }
}

/* A triangle's n-fold split: row j holds the points i = 0 .. n - j, at base + row_start(j) + i;
 * then its n^2 triangles, upright and inverted. */
static void bn__grid_tri(const bn_scene *s, size_t fi, unsigned n, bn_patch *patches, size_t *ip, double *pv,
                         size_t *iv)
{
    const bn_face *f = &s->faces[fi];
    const double *a = bn__fv(s, f, 0), *b = bn__fv(s, f, 1), *c = bn__fv(s, f, 2);
    size_t base = *iv;
#define BN__TRI_ID(i, j) (base + (size_t)(j) * (n + 1) - (size_t)(j) * ((j) - 1) / 2 + (i))
    for (unsigned j = 0; j <= n; j++)
        for (unsigned i = 0; i + j <= n; i++) {
            double u = (double)i / n, v = (double)j / n;
            double *q = pv + 3 * (*iv)++;
            for (int k = 0; k < 3; k++)
                q[k] = (1 - u - v) * a[k] + u * b[k] + v * c[k];
        }
    for (unsigned j = 0; j < n; j++)
        for (unsigned i = 0; i + j < n; i++) {
            size_t up[3] = {BN__TRI_ID(i, j), BN__TRI_ID(i + 1, j), BN__TRI_ID(i, j + 1)};
            size_t down[3] = {BN__TRI_ID(i + 1, j), BN__TRI_ID(i + 1, j + 1), BN__TRI_ID(i, j + 1)};
            bn__grid_patch(&patches[(*ip)++], fi, f, 3, up, pv);
            if (i + j + 1 < n)
                bn__grid_patch(&patches[(*ip)++], fi, f, 3, down, pv);
        }
#undef BN__TRI_ID
}

/* The regular grid of every face at patch edge `size`, then the contact cuts (unless off). */
static bn_status bn__grid(bn_scene *s, double size, int contacts, const bn_mesh_opts *o, bn_patch **out_p,
                          size_t *out_np, double **out_v, size_t *out_nv, bn_error *err)
{
    size_t np = 0, nv = 0, ip = 0, iv = 0;
    bn_patch *patches;
    double *pv;
    for (size_t f = 0; f < s->nfaces; f++) {
        unsigned nu, nvv;
        bn__face_grid(s, &s->faces[f], size, &nu, &nvv);
        np += s->faces[f].nverts == 4 ? (size_t)nu * nvv : (size_t)nu * nu;
        nv += s->faces[f].nverts == 4 ? (size_t)(nu + 1) * (nvv + 1) : (size_t)(nu + 1) * (nu + 2) / 2;
    }
    patches = bn__malloc_array(np, sizeof *patches);
    pv = bn__malloc_array(nv, 3 * sizeof(double));
    if (!patches || !pv) {
        free(patches);
        free(pv);
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu patches", np);
    }
    for (size_t fi = 0; fi < s->nfaces; fi++) {
        unsigned nu, nvv;
        if (bn_interrupted() != BN_OK) {   /* a face may hold a million patches: stop between faces */
            free(patches);
            free(pv);
            return bn_error_set(err, bn_interrupted(), "meshing interrupted");
        }
        bn__face_grid(s, &s->faces[fi], size, &nu, &nvv);
        if (s->faces[fi].nverts == 4)
            bn__grid_quad(s, fi, nu, nvv, patches, &ip, pv, &iv);
        else
            bn__grid_tri(s, fi, nu, patches, &ip, pv, &iv);
    }
    BN_CHECK(ip == np && iv == nv);
    s->stats.contact_segments = s->stats.contact_faces = 0;
    s->stats.contact_patches_split = s->stats.contact_patches_made = 0;
    if (contacts) {
        bn_status st = bn__mesh_contacts(s, o->contact_gap, o->self_contacts, &patches, &np, &pv, &nv, err);
        if (st != BN_OK) {
            free(patches);
            free(pv);
            return st;
        }
    }
    *out_p = patches;
    *out_np = np;
    *out_v = pv;
    *out_nv = nv;
    return BN_OK;
}

/* The patch edge the options ask for: given, or the finest whose split faces' grid count does not
 * exceed the target (bisection on log(size): the count falls as the size grows); 0 for one patch a
 * face. */
static bn_status bn__mesh_size(const bn_scene *s, const bn_mesh_opts *o, double *size, bn_error *err)
{
    if (o->no_subdivide) {
        *size = 0;
    } else if (o->patch_size > 0) {
        if (!isfinite(o->patch_size))
            return bn_error_set(err, BN_EINPUT, "patch size %g is not a finite positive length", o->patch_size);
        *size = o->patch_size;
    } else if (o->target_patches > 0) {
        double d[3], hi_s, lo_s;
        bn_v3_sub(s->hi, s->lo, d);
        hi_s = 2 * bn_v3_len(d) + 1e-300;
        lo_s = hi_s * 1e-7;
        if (bn__count_split(s, hi_s) < (double)o->target_patches)
            for (int it = 0; it < 60; it++) {
                double mid = sqrt(lo_s * hi_s);
                if (bn__count_split(s, mid) > (double)o->target_patches)
                    lo_s = mid;
                else
                    hi_s = mid;
            }
        *size = hi_s;
    } else {
        return bn_error_set(err, BN_EUSAGE, "meshing needs a patch size, a target patch count or no-subdivide");
    }
    if (!(o->contact_gap >= 0 && isfinite(o->contact_gap)))
        return bn_error_set(err, BN_EINPUT, "contact gap %g is not a finite length >= 0", o->contact_gap);
    {
        /* a gap near the scene's size would make every face touch every other (and cost N^2) */
        double d[3];
        bn_v3_sub(s->hi, s->lo, d);
        if (o->contact_gap > 0.01 * bn_v3_len(d))
            return bn_error_set(err, BN_EINPUT, "contact gap %g is more than 1%% of the scene's diameter %g",
                                o->contact_gap, bn_v3_len(d));
    }
    return BN_OK;
}

bn_status bn_scene_mesh_estimate(const bn_scene *s, const bn_mesh_opts *o, double *patches, bn_error *err)
{
    double size;
    bn_mesh_opts defo;
    bn_status st;
    if (!o) {
        bn_mesh_opts_default(&defo);
        o = &defo;
    }
    st = bn__mesh_size(s, o, &size, err);
    *patches = st == BN_OK ? bn__count(s, size) : 0;
    return st;
}

bn_status bn_scene_mesh(bn_scene *s, const bn_mesh_opts *o, bn_error *err)
{
    bn_mesh_opts defo;
    double size;
    double count_d;
    size_t np = 0, nv = 0;
    bn_patch *patches = NULL;
    double *pv = NULL;
    bn_status st;

    if (!o) {
        bn_mesh_opts_default(&defo);
        o = &defo;
    }
    if ((st = bn__mesh_size(s, o, &size, err)) != BN_OK)
        return st;
    count_d = bn__count(s, size);
    if (count_d > 1e9)
        return bn_error_set(err, BN_ENOMEM, "patch size %g would make %.3g patches (more than 1e9)", size, count_d);
    {
        int contacts = !o->no_subdivide && !o->no_contacts,
            by_target = !o->no_subdivide && !(o->patch_size > 0) && o->target_patches > 0;
        for (int attempt = 0;; attempt++) {
            st = bn__grid(s, size, contacts, o, &patches, &np, &pv, &nv, err);
            if (st != BN_OK)
                return st;
            /* contact cuts add patches: a target count holds for the mesh with its cuts, less the
             * faces of one patch (where the grid alone can meet it) */
            double single = bn__count(s, size) - bn__count_split(s, size), split = (double)np - single;
            if (!by_target || split <= (double)o->target_patches || (double)np <= bn__count(s, size) || attempt == 8)
                break;
            free(patches);
            free(pv);
            size *= 1.02 * sqrt(split / (double)o->target_patches);
        }
    }
    s->largest_edge = 0;
    for (size_t q = 0; q < np; q++)
        for (unsigned k = 0; k < patches[q].ncorners; k++)
            s->largest_edge = fmax(s->largest_edge, bn_v3_dist(pv + 3 * patches[q].corner[k],
                                                               pv + 3 * patches[q].corner[(k + 1) % patches[q].ncorners]));
    free(s->patches);
    free(s->pverts);
    s->patches = patches;
    s->npatches = np;
    s->pverts = pv;
    s->npverts = nv;
    s->patch_size = size;
    return bn__scene_patch_textures(s, err);
}
