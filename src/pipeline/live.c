/* The live page's data (bounce view --live): what a browser needs to relight a solved scene without
 * bounce: the patches as triangles, each patch's material and texture factors, the punctual lights'
 * direct light for a white surface, and F as links (bn_transport_links: dense, sparse or the
 * hierarchy's, one format). The page's worker applies F itself; nothing here solves. Layout: "BNLV",
 * version 1, the JSON's length, the JSON (padded to 4 bytes), then the arrays it names, each at a
 * 4-byte boundary, little-endian. */
#include "bounce/pipeline.h"
#include "bounce/bake.h"
#include "base/internal.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

void bn_live_opts_default(bn_live_opts *o)
{
    memset(o, 0, sizeof *o);
    o->bounces = 5;
}

/* Per patch and per triangle: the sizes the page holds besides F's links. */
static size_t bn__live_patch_bytes(const bn_pipeline *p)
{
    size_t ntri = 0, np;
    const bn_patch *pt = bn_scene_patches(p->scene, &np);
    for (size_t i = 0; i < np; i++)
        ntri += pt[i].ncorners - 2;
    /* triangles: 9 floats + a patch index; patches: material, area, 2 x 3 factors, D_white, the solve's L */
    return ntri * (9 * 4 + 4) + np * (4 + 4 + 24 + (p->D_white ? 12 : 0) + 12);
}

bn_status bn_pipeline_live_bytes(const bn_pipeline *p, size_t *bytes, bn_error *err)
{
    size_t links;
    bn_status st = bn_transport_links_bytes(p->k, &links, err);
    *bytes = st == BN_OK ? links + bn__live_patch_bytes(p) : 0;
    return st;
}

/* An array into the blob and its entry in the JSON's "arrays": "name":[offset,count,"type"]. */
static void bn__live_array(bn__blob *b, bn__str *j, const char *name, const void *data, size_t count,
                           const char *type, size_t esize)
{
    size_t off = bn__blob_add(b, data, count * esize);
    bn__str_add(j, "%s\"%s\":[%zu,%zu,\"%s\"]", j->s && j->s[j->n - 1] == '{' ? "" : ",", name, off, count, type);
}

/* The triangles (metres, quads as two) and their patches. */
static bn_status bn__live_triangles(const bn_pipeline *p, bn__blob *b, bn__str *j, bn_error *err)
{
    size_t np, nv, ntri = 0, t = 0;
    const bn_patch *pt = bn_scene_patches(p->scene, &np);
    const double *v = bn_scene_patch_vertices(p->scene, &nv);
    double m = bn_unit_to_metres(bn_scene_unit(p->scene));
    for (size_t i = 0; i < np; i++)
        ntri += pt[i].ncorners - 2;
    float *pos = bn__malloc_array(9 * ntri + 1, sizeof *pos);
    uint32_t *tp = bn__malloc_array(ntri + 1, sizeof *tp);
    if (!pos || !tp) {
        free(pos);
        free(tp);
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu triangles", ntri);
    }
    for (size_t i = 0; i < np; i++)
        for (unsigned k = 1; k + 1 < pt[i].ncorners; k++, t++) {   /* a fan: (0, k, k + 1) */
            size_t c[3] = {pt[i].corner[0], pt[i].corner[k], pt[i].corner[k + 1]};
            for (int q = 0; q < 3; q++)
                for (int a = 0; a < 3; a++)
                    pos[9 * t + 3 * (size_t)q + (size_t)a] = (float)(m * v[3 * c[q] + (size_t)a]);
            tp[t] = (uint32_t)i;
        }
    bn__live_array(b, j, "pos", pos, 9 * ntri, "f32", 4);
    bn__live_array(b, j, "tri_patch", tp, ntri, "u32", 4);
    free(pos);
    free(tp);
    return BN_OK;
}

/* Per patch: material, area (m^2), the texture factors of rho and Le, the punctual lights' white D. */
static bn_status bn__live_patches(const bn_pipeline *p, bn__blob *b, bn__str *j, bn_error *err)
{
    size_t np = p->n;
    double m = bn_unit_to_metres(bn_scene_unit(p->scene)), *rf = bn__malloc_array(6 * np + 1, sizeof *rf);
    uint32_t *mat = bn__malloc_array(np + 1, sizeof *mat);
    float *f = bn__malloc_array(3 * np + 1, sizeof *f);
    const bn_patch *pt = bn_scene_patches(p->scene, &np);
    if (!rf || !mat || !f) {
        free(rf), free(mat), free(f);
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu patches", np);
    }
    for (size_t i = 0; i < np; i++) {
        mat[i] = pt[i].material;
        f[i] = (float)(pt[i].area * m * m);
    }
    bn__live_array(b, j, "patch_material", mat, np, "u32", 4);
    bn__live_array(b, j, "patch_area", f, np, "f32", 4);
    bn_scene_patch_texture_factors(p->scene, rf, rf + 3 * np);
    for (int k = 0; k < 4; k++) {   /* the factors; the white patches' punctual light; the solve's L */
        static const char *names[] = {"rho_factor", "Le_factor", "D_white", "L_solved"};
        const double *src = k < 2 ? rf + 3 * np * (size_t)k : k == 2 ? p->D_white : p->res.L;
        for (size_t i = 0; src && i < 3 * np; i++)
            f[i] = (float)src[i];
        if (src)
            bn__live_array(b, j, names[k], f, 3 * np, "f32", 4);
    }
    free(rf), free(mat), free(f);
    return BN_OK;
}

static void bn__live_links(const bn_transport_links *l, bn__blob *b, bn__str *j)
{
    bn__str_add(j, "},\"nodes\":%zu,\"links\":%zu,\"arrays_F\":{", l->nnodes, l->nlinks);
    bn__live_array(b, j, "child", l->child, l->nnodes, "u32", 4);
    bn__live_array(b, j, "leaf_patch", l->leaf_patch, l->nnodes, "u32", 4);
    bn__live_array(b, j, "cluster", l->cluster, l->nnodes, "u8", 1);
    bn__live_array(b, j, "area", l->area, l->nnodes, "f32", 4);
    bn__live_array(b, j, "normal", l->normal, 3 * l->nnodes, "f32", 4);
    bn__live_array(b, j, "start", l->start, l->nnodes + 1, "u32", 4);
    bn__live_array(b, j, "src", l->src, l->nlinks, "u32", 4);
    bn__live_array(b, j, "F", l->F, l->nlinks, "f32", 4);
    if (l->dir)
        bn__live_array(b, j, "dir", l->dir, l->nlinks, "u16", 2);
    if (l->rowscale)
        bn__live_array(b, j, "rowscale", l->rowscale, l->npatch, "f32", 4);
    bn__str_add(j, "}");
}

/* The JSON's head: the scene's materials (as solved), the terms shown, the provenance. */
static void bn__live_head(const bn_pipeline *p, const bn_live_opts *o, bn__str *j)
{
    size_t nm;
    const bn_material *mats = bn_scene_materials(p->scene, &nm);
    bn__str_add(j, "{\"version\":1,\"patches\":%zu,\"bounces\":%d,\"transport\":", p->n, o->bounces);
    bn__str_json(j, bn_transport_name(p->k));
    bn__str_add(j, ",\"note\":");
    bn__str_json(j, o->note ? o->note : "");
    bn__str_add(j, ",\"materials\":[");
    for (size_t m = 0; m < nm; m++) {
        bn__str_add(j, "%s{\"name\":", m ? "," : "");
        bn__str_json(j, mats[m].name);
        bn__str_add(j, ",\"rho\":[");
        for (int c = 0; c < 3; c++)
            bn__str_num(j, mats[m].rho[c]), bn__str_add(j, c < 2 ? "," : "],\"Le\":[");
        for (int c = 0; c < 3; c++)
            bn__str_num(j, mats[m].Le[c]), bn__str_add(j, c < 2 ? "," : "]}");
    }
    bn__str_add(j, "],\"provenance\":{");
    for (size_t a = 0; a < o->nattrs; a++) {
        bn__str_add(j, "%s", a ? "," : "");
        bn__str_json(j, o->attrs[a].key);
        bn__str_add(j, ":");
        bn__str_json(j, o->attrs[a].value);
    }
    bn__str_add(j, "},\"arrays\":{");
}

/* The payload in *out (malloc'd), *n bytes. */
static bn_status bn__live_payload(const bn_pipeline *p, const bn_live_opts *o, unsigned char **out, size_t *n,
                                  bn_error *err)
{
    bn__str j = {0};
    bn__blob b = {0};
    bn_transport_links l;
    bn_status st;
    *out = NULL;
    if ((st = bn_transport_links_get(p->k, &l, err)) != BN_OK)
        return st;
    bn__live_head(p, o, &j);
    if ((st = bn__live_triangles(p, &b, &j, err)) == BN_OK && (st = bn__live_patches(p, &b, &j, err)) == BN_OK)
        bn__live_links(&l, &b, &j);
    bn__str_add(&j, "}");
    bn_transport_links_free(&l);
    while (st == BN_OK && !j.oom && j.n % 4)
        bn__str_add(&j, " ");
    if (st == BN_OK && (j.oom || b.oom))
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the live page's %zu bytes", b.n);
    if (st == BN_OK && (*out = bn__malloc_array(12 + j.n + b.n, 1))) {
        uint32_t head[3] = {0x564c4e42u, 1, (uint32_t)j.n};   /* "BNLV" little-endian */
        memcpy(*out, head, 12);
        memcpy(*out + 12, j.s, j.n);
        memcpy(*out + 12 + j.n, b.p, b.n);
        *n = 12 + j.n + b.n;
    } else if (st == BN_OK)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the live page's %zu bytes", b.n);
    free(j.s);
    free(b.p);
    return st;
}

bn_status bn_pipeline_live_write(const bn_pipeline *p, const bn_live_opts *o, const char *title, const char *out,
                                 bn_error *err)
{
    unsigned char *buf;
    size_t n = 0;
    bn_status st;
    if (!p->k || !p->scene)
        return bn_error_set(err, BN_EUSAGE, "the live page needs a scene with its operator (bn_pipeline_operator)");
    if (o->bounces < 0 || o->bounces > 64)
        return bn_error_set(err, BN_EUSAGE, "`bounces` %d: the live page shows 0 to 64 terms", o->bounces);
    if ((st = bn__live_payload(p, o, &buf, &n, err)) != BN_OK)
        return st;
    st = bn_view_write_live(buf, n, title, out, err);
    free(buf);
    return st;
}
