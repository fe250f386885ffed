/* glTF 2.0 bakes (.glb, or .gltf with its .bin): the baked mesh with linear float per-vertex
 * radiance. A small writer of our own rather than Assimp's exporter: bounce needs float colour
 * sets beside COLOR_0 under its own names (application-specific attributes _E, _KE, ...), the
 * provenance and the attribute map in the asset's extras, unlit materials that carry the
 * reflectance as data, and atomic writes; the container is a JSON header and one binary buffer,
 * and the Khronos validator checks what this writes (tests/test_gltf.py). */
#include "bake/bake_internal.h"
#include "base/internal.h"

#include <ctype.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- a growing text buffer for the JSON ---- */

typedef struct bn__str {
    char *s;
    size_t n, cap;
    int oom;
} bn__str;

static void bn__str_add(bn__str *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void bn__str_add(bn__str *b, const char *fmt, ...)
{
    va_list ap;
    int k;
    if (b->oom)
        return;
    for (;;) {
        size_t room = b->cap - b->n;
        va_start(ap, fmt);
        k = vsnprintf(b->s ? b->s + b->n : NULL, b->s ? room : 0, fmt, ap);
        va_end(ap);
        if (k < 0) {
            b->oom = 1;
            return;
        }
        if (b->s && (size_t)k < room) {
            b->n += (size_t)k;
            return;
        }
        size_t cap = (b->cap + (size_t)k + 1) * 2;
        char *s = realloc(b->s, cap);
        if (!s) {
            b->oom = 1;
            return;
        }
        b->s = s;
        b->cap = cap;
    }
}

/* A JSON string literal: quotes, backslashes and control characters escaped; bytes >= 0x80 pass
 * (UTF-8 as given). */
static void bn__str_json(bn__str *b, const char *v)
{
    bn__str_add(b, "\"");
    for (const unsigned char *p = (const unsigned char *)v; *p; p++) {
        if (*p == '"' || *p == '\\')
            bn__str_add(b, "\\%c", *p);
        else if (*p < 0x20)
            bn__str_add(b, "\\u%04x", *p);
        else
            bn__str_add(b, "%c", *p);
    }
    bn__str_add(b, "\"");
}

/* A finite double as JSON (%.9g keeps a float's value). */
static void bn__str_num(bn__str *b, double v) { bn__str_add(b, "%.9g", isfinite(v) ? v : 0.0); }

/* ---- the binary buffer ---- */

typedef struct bn__blob {
    unsigned char *p;
    size_t n, cap;
    int oom;
} bn__blob;

/* Appends n bytes at a 4-byte boundary (the buffer view's offset is returned). */
static size_t bn__blob_add(bn__blob *b, const void *src, size_t n)
{
    size_t off = (b->n + 3) & ~(size_t)3;
    if (b->oom)
        return 0;
    if (off + n > b->cap) {
        size_t cap = (off + n) * 3 / 2 + 64;
        unsigned char *p = realloc(b->p, cap);
        if (!p) {
            b->oom = 1;
            return 0;
        }
        b->p = p;
        b->cap = cap;
    }
    memset(b->p + b->n, 0, off - b->n);
    memcpy(b->p + off, src, n);
    b->n = off + n;
    return off;
}

typedef struct bn__view {
    size_t offset, length;
    int target;   /* 34962 ARRAY_BUFFER, 34963 ELEMENT_ARRAY_BUFFER */
} bn__view;

/* The attribute of a layer: _NAME, upper case (glTF's application-specific attributes). */
static void bn__attr_name(const char *layer, char *out, size_t n)
{
    size_t k = 0;
    out[k++] = '_';
    for (const char *p = layer; *p && k + 1 < n; p++)
        out[k++] = isalnum((unsigned char)*p) ? (char)toupper((unsigned char)*p) : '_';
    out[k] = '\0';
}

/* Writes the n pieces (p[i], len[i]) one after another to path, atomically (a temporary name renamed
 * when complete; bn__outfile_commit reports a failed write). */
static bn_status bn__write_pieces(const char *path, int n, const void *const *p, const size_t *len, bn_error *err)
{
    bn__outfile f;
    bn_status st = bn__outfile_open(&f, path, "wb", err);
    if (st != BN_OK)
        return st;
    for (int i = 0; i < n; i++)
        if (len[i])
            fwrite(p[i], 1, len[i], f.fp);
    return bn__outfile_commit(&f, err);
}

static void bn__le32_put(unsigned char *b, uint32_t w)
{
    b[0] = (unsigned char)(w & 0xFFu);
    b[1] = (unsigned char)(w >> 8 & 0xFFu);
    b[2] = (unsigned char)(w >> 16 & 0xFFu);
    b[3] = (unsigned char)(w >> 24 & 0xFFu);
}

/* The writer's state: the mesh, its triangles grouped by material, the binary buffer and its views,
 * the JSON. */
typedef struct bn__gltf {
    const bn__bake_out *m;
    const bn_material *mat;
    size_t nmat;
    double unit, scale;        /* metres per scene unit; COLOR_0's 2^exposure_ev */
    float lo[3], hi[3];        /* the positions' bounds (metres) */
    uint32_t *idx;             /* 3 per triangle, group by group */
    size_t nobj, ngroups;      /* objects (a node and mesh each), and groups: object x material */
    size_t *mat_tris, *mat_first;   /* per group (object o, material k: o nmat + k) */
    bn__view *views;
    size_t nviews;
    bn__blob blob;
    bn__str js;
} bn__gltf;

/* Face f's group: its object's and material's. */
static size_t bn__group(const bn__gltf *g, size_t f)
{
    size_t o = g->nobj > 1 ? g->m->face_object[f] : 0;
    return o * g->nmat + g->m->face_material[f];
}

/* Triangles grouped by object and material, one primitive each, all sharing the vertex attributes: a fan
 * from each face's first corner (faces are convex). */
static bn_status bn__gltf_triangles(bn__gltf *g, const char *path, bn_error *err)
{
    const bn__bake_out *m = g->m;
    size_t ntri = 0, *fill;
    for (size_t f = 0; f < m->nf; f++) {
        if (m->face_material[f] >= g->nmat || (g->nobj > 1 && m->face_object[f] >= g->nobj))
            return bn_error_set(err, BN_EINTERNAL, "%s: face %zu has material %u of %zu", path, f, m->face_material[f],
                                g->nmat);
        g->mat_tris[bn__group(g, f)] += m->face_n[f] - 2;
        ntri += m->face_n[f] - 2;
    }
    g->idx = bn__malloc_array(3 * ntri + 1, sizeof(uint32_t));
    fill = bn__malloc_array(g->ngroups + 1, sizeof(size_t));
    if (!g->idx || !fill) {
        free(fill);
        return BN_ENOMEM;
    }
    for (size_t k = 0, acc = 0; k < g->ngroups; k++) {
        g->mat_first[k] = fill[k] = acc;
        acc += 3 * g->mat_tris[k];
    }
    for (size_t f = 0; f < m->nf; f++) {
        const size_t *c = m->face_idx + 4 * f;
        size_t *w = &fill[bn__group(g, f)];
        for (unsigned t = 0; t + 2 < m->face_n[f]; t++) {
            g->idx[(*w)++] = (uint32_t)c[0];
            g->idx[(*w)++] = (uint32_t)c[t + 1];
            g->idx[(*w)++] = (uint32_t)c[t + 2];
        }
    }
    free(fill);
    return BN_OK;
}

static void bn__gltf_view(bn__gltf *g, const void *src, size_t n, int target)
{
    size_t off = bn__blob_add(&g->blob, src, n);
    g->views[g->nviews++] = (bn__view){off, n, target};
}

/* The binary buffer's vertex views: positions in metres (glTF's unit) as float, with their bounds
 * (required for POSITION); COLOR_0, what an engine shows: L x 2^EV clamped to [0, 1] as glTF
 * requires (the light and the brightest spots saturate); each layer's radiance itself; the 8-bit
 * display set as VEC4 (alpha 255: vertex attributes keep 4-byte strides). */
static bn_status bn__gltf_vertices(bn__gltf *g)
{
    const bn__bake_out *m = g->m;
    size_t nv = m->nv, n3 = nv * 3 * sizeof(float);
    float *f3 = bn__malloc_array(nv + 1, 3 * sizeof(float));
    unsigned char *c4 = m->c8 ? bn__malloc_array(nv + 1, 4) : NULL;
    if (!f3 || (m->c8 && !c4)) {
        free(f3);
        return BN_ENOMEM;
    }
    for (size_t v = 0; v < nv; v++)
        for (int c = 0; c < 3; c++) {
            float x = (float)(m->pos[3 * v + c] * g->unit);
            f3[3 * v + c] = x;
            g->lo[c] = fminf(g->lo[c], x);
            g->hi[c] = fmaxf(g->hi[c], x);
        }
    bn__gltf_view(g, f3, n3, 34962);
    for (size_t i = 0; i < 3 * nv; i++)
        f3[i] = (float)fmin(1.0, fmax(0.0, (double)m->vals[0][i] * g->scale));
    bn__gltf_view(g, f3, n3, 34962);
    for (size_t l = 0; l < m->nlayers; l++)
        bn__gltf_view(g, m->vals[l], n3, 34962);
    for (size_t v = 0; c4 && v < nv; v++) {
        memcpy(c4 + 4 * v, m->c8 + 3 * v, 3);
        c4[4 * v + 3] = 255;
    }
    if (c4)
        bn__gltf_view(g, c4, nv * 4, 34962);
    free(f3);
    free(c4);
    return g->blob.oom ? BN_ENOMEM : BN_OK;
}

/* The index views, one per group with triangles. Every view is whole 4-byte words (floats,
 * 32-bit indices, 4-byte colours), so the buffer is too, as the GLB chunk needs. */
static bn_status bn__gltf_indices(bn__gltf *g)
{
    for (size_t k = 0; k < g->ngroups; k++)
        if (g->mat_tris[k])
            bn__gltf_view(g, g->idx + g->mat_first[k], 3 * g->mat_tris[k] * sizeof(uint32_t), 34963);
    return g->blob.oom ? BN_ENOMEM : BN_OK;
}

/* A JSON array of three numbers. */
static void bn__str_vec3(bn__str *js, const double *v)
{
    for (int c = 0; c < 3; c++) {
        bn__str_add(js, "%s", c ? "," : "[");
        bn__str_num(js, v ? v[c] : 0.0);
    }
    bn__str_add(js, "]");
}

/* asset.extras: whether the colours include the albedo, units, exposure, what each attribute holds, each
 * layer's power, provenance. */
static void bn__gltf_json_extras(bn__gltf *g, const bn_scene *scene, const bn_bake_write_opts *o)
{
    const bn__bake_out *m = g->m;
    bn__str *js = &g->js;
    bn__str_add(js, ",\"extras\":{\"albedo\":\"included: the colours are the radiance leaving each vertex, the "
                    "reflectance applied%s (multiply by no albedo texture again)\"",
                bn_scene_textured(scene) ? ", textured materials at each patch's mean over their texture" : "");
    bn__str_add(js, ",\"radiance_unit\":\"W m^-2 sr^-1\",\"exposure_ev\":");
    bn__str_num(js, m->exposure_ev);
    bn__str_add(js, ",\"colour_scale\":");
    bn__str_num(js, g->scale);
    bn__str_add(js, ",\"note\":\"per-vertex radiance baked from bounce's solution, positions in metres. COLOR_0 "
                    "is L times colour_scale (2^exposure_ev), linear, clamped to [0, 1]: what an engine shows. The "
                    "application-specific attributes hold radiance itself, unclamped: _L, and in a per-bounce bake "
                    "the terms of the series (_E = E, _KE = K E, _K2E = K^2 E, ..., _REST the longer paths; "
                    "their sum is _L)\",\"attributes\":{\"COLOR_0\":\"L x colour_scale, clamped to [0, 1]\"");
    for (size_t l = 0; l < m->nlayers; l++) {
        char an[64];
        bn__attr_name(m->names[l], an, sizeof an);
        bn__str_add(js, ",");
        bn__str_json(js, an);
        bn__str_add(js, ":");
        bn__str_json(js, m->names[l]);
    }
    bn__str_add(js, "},\"power_W\":{");
    for (size_t l = 0; l < m->nlayers; l++) {   /* pi sum A L over the patches, per layer and channel */
        bn__str_add(js, "%s", l ? "," : "");
        bn__str_json(js, m->names[l]);
        bn__str_add(js, ":");
        bn__str_vec3(js, m->power ? m->power + 3 * l : NULL);
    }
    bn__str_add(js, "}");
    if (m->c8) {
        bn__str_add(js, ",\"display\":{\"attribute\":\"COLOR_1\",\"encoding\":\"8-bit sRGB of L\",\"exposure_ev\":");
        bn__str_num(js, m->exposure_ev);
        bn__str_add(js, "}");
    }
    bn__str_add(js, ",\"provenance\":{");
    for (size_t a = 0; a < o->nattrs; a++) {
        bn__str_add(js, "%s", a ? "," : "");
        bn__str_json(js, o->attrs[a].key);
        bn__str_add(js, ":");
        bn__str_json(js, o->attrs[a].value);
    }
    bn__str_add(js, "}}");
}

/* The buffer, its views and the accessors: 0 positions, 1 COLOR_0, 2.. the layers, then the display
 * set, then the indices. */
static void bn__gltf_json_accessors(bn__gltf *g, const char *binname)
{
    const bn__bake_out *m = g->m;
    bn__str *js = &g->js;
    size_t v = 2 + m->nlayers + (m->c8 ? 1 : 0);
    bn__str_add(js, ",\"buffers\":[{\"byteLength\":%zu", g->blob.n);
    if (binname) {
        bn__str_add(js, ",\"uri\":");
        bn__str_json(js, binname);
    }
    bn__str_add(js, "}],\"bufferViews\":[");
    for (size_t k = 0; k < g->nviews; k++)
        bn__str_add(js, "%s{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu,\"target\":%d}", k ? "," : "",
                    g->views[k].offset, g->views[k].length, g->views[k].target);
    bn__str_add(js, "],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":%zu,\"type\":\"VEC3\","
                    "\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]}",
                m->nv, (double)g->lo[0], (double)g->lo[1], (double)g->lo[2], (double)g->hi[0], (double)g->hi[1],
                (double)g->hi[2]);
    for (size_t l = 0; l <= m->nlayers; l++)   /* COLOR_0, then the layers */
        bn__str_add(js, ",{\"bufferView\":%zu,\"componentType\":5126,\"count\":%zu,\"type\":\"VEC3\"}", 1 + l, m->nv);
    if (m->c8)
        bn__str_add(js, ",{\"bufferView\":%zu,\"componentType\":5121,\"normalized\":true,\"count\":%zu,"
                        "\"type\":\"VEC4\"}",
                    2 + m->nlayers, m->nv);
    for (size_t k = 0; k < g->ngroups; k++)
        if (g->mat_tris[k]) {
            const uint32_t *t = g->idx + g->mat_first[k];
            uint32_t imin = UINT32_MAX, imax = 0;
            for (size_t i = 0; i < 3 * g->mat_tris[k]; i++) {
                imin = t[i] < imin ? t[i] : imin;
                imax = t[i] > imax ? t[i] : imax;
            }
            bn__str_add(js, ",{\"bufferView\":%zu,\"componentType\":5125,\"count\":%zu,\"type\":\"SCALAR\","
                            "\"min\":[%u],\"max\":[%u]}",
                        v++, 3 * g->mat_tris[k], imin, imax);
        }
    bn__str_add(js, "]");
}

/* A mesh per object (node), with a primitive per material; the materials unlit (an engine shows COLOR_0,
 * the radiance itself; a lit material would shade it twice), the reflectance and emitted radiance as
 * data. */
static void bn__gltf_json_meshes(bn__gltf *g)
{
    const bn__bake_out *m = g->m;
    bn__str *js = &g->js;
    size_t acc = 2 + m->nlayers + (m->c8 ? 1 : 0), nmesh = 0;
    bn__str_add(js, ",\"meshes\":[");
    for (size_t o = 0; o < g->nobj; o++) {
        size_t p = 0;
        for (size_t k = 0; k < g->nmat; k++) {
            if (!g->mat_tris[o * g->nmat + k])
                continue;
            if (p == 0) {
                bn__str_add(js, "%s{", nmesh++ ? "," : "");
                if (g->nobj > 1) {
                    bn__str_add(js, "\"name\":");
                    bn__str_json(js, m->object_names[o]);
                    bn__str_add(js, ",");
                }
                bn__str_add(js, "\"primitives\":[");
            }
            bn__str_add(js, "%s{\"attributes\":{\"POSITION\":0,\"COLOR_0\":1", p++ ? "," : "");
            for (size_t l = 0; l < m->nlayers; l++) {
                char an[64];
                bn__attr_name(m->names[l], an, sizeof an);
                bn__str_add(js, ",\"%s\":%zu", an, 2 + l);
            }
            if (m->c8)
                bn__str_add(js, ",\"COLOR_1\":%zu", 2 + m->nlayers);
            bn__str_add(js, "},\"indices\":%zu,\"material\":%zu,\"mode\":4}", acc++, k);
        }
        if (p)
            bn__str_add(js, "]}");
    }
    bn__str_add(js, "],\"materials\":[");
    for (size_t k = 0; k < g->nmat; k++) {
        bn__str_add(js, "%s{\"name\":", k ? "," : "");
        bn__str_json(js, g->mat[k].name);
        bn__str_add(js, ",\"pbrMetallicRoughness\":{\"baseColorFactor\":[1,1,1,1],\"metallicFactor\":0,"
                        "\"roughnessFactor\":1},\"doubleSided\":false,\"extensions\":{\"KHR_materials_unlit\":{}},"
                        "\"extras\":{\"reflectance\":");
        bn__str_vec3(js, g->mat[k].rho);
        bn__str_add(js, ",\"emitted_radiance\":");
        bn__str_vec3(js, g->mat[k].Le);
        bn__str_add(js, "}}");
    }
    bn__str_add(js, "]");
}

/* The scene's nodes: one per object with triangles, named as the object (the file's node or group, or
 * the material-name prefix), each with its mesh; a single node named after the scene file when there is
 * one object. Positions are in world space: the nodes carry no transform. */
static void bn__gltf_json_nodes(bn__gltf *g, const bn_scene *scene)
{
    bn__str *js = &g->js;
    size_t n = 0;
    bn__str_add(js, ",\"nodes\":[");
    for (size_t o = 0; o < g->nobj; o++) {
        size_t tris = 0;
        for (size_t k = 0; k < g->nmat; k++)
            tris += g->mat_tris[o * g->nmat + k];
        if (!tris)
            continue;
        bn__str_add(js, "%s{\"mesh\":%zu,\"name\":", n ? "," : "", n);
        bn__str_json(js, g->nobj > 1 ? g->m->object_names[o] : bn_scene_path(scene));
        bn__str_add(js, "}");
        n++;
    }
    bn__str_add(js, "],\"scenes\":[{\"nodes\":[");
    for (size_t k = 0; k < n; k++)
        bn__str_add(js, "%s%zu", k ? "," : "", k);
    bn__str_add(js, "]}]");
}

/* The whole JSON, padded with spaces to 4-byte words. */
static bn_status bn__gltf_json(bn__gltf *g, const bn_scene *scene, const bn_bake_write_opts *o, const char *binname)
{
    char gen[96];
    snprintf(gen, sizeof gen, "bounce %s", bn_version());
    bn__str_add(&g->js, "{\"asset\":{\"version\":\"2.0\",\"generator\":");
    bn__str_json(&g->js, gen);
    bn__gltf_json_extras(g, scene, o);
    bn__str_add(&g->js, "},\"extensionsUsed\":[\"KHR_materials_unlit\"],\"scene\":0");
    bn__gltf_json_nodes(g, scene);
    bn__gltf_json_accessors(g, binname);
    bn__gltf_json_meshes(g);
    bn__str_add(&g->js, "}");
    while (!g->js.oom && g->js.n % 4)
        bn__str_add(&g->js, " ");
    return g->js.oom ? BN_ENOMEM : BN_OK;
}

/* .glb: header, JSON chunk, BIN chunk, little-endian words, written piece by piece. */
static bn_status bn__gltf_write_glb(const char *path, const bn__gltf *g, bn_error *err)
{
    unsigned char head[20], binhead[8];
    size_t total = 20 + g->js.n + 8 + g->blob.n;
    if (total > UINT32_MAX)
        return bn_error_set(err, BN_EUSAGE, "%s: %zu bytes are more than a .glb holds (4 GiB); write .gltf", path,
                            total);
    bn__le32_put(head, 0x46546C67u);   /* "glTF" */
    bn__le32_put(head + 4, 2u);
    bn__le32_put(head + 8, (uint32_t)total);
    bn__le32_put(head + 12, (uint32_t)g->js.n);
    bn__le32_put(head + 16, 0x4E4F534Au);   /* "JSON" */
    bn__le32_put(binhead, (uint32_t)g->blob.n);
    bn__le32_put(binhead + 4, 0x004E4942u);   /* "BIN\0" */
    const void *p[4] = {head, g->js.s, binhead, g->blob.p};
    size_t len[4] = {20, g->js.n, 8, g->blob.n};
    return bn__write_pieces(path, 4, p, len, err);
}

static void bn__gltf_free(bn__gltf *g)
{
    free(g->idx);
    free(g->mat_tris);
    free(g->mat_first);
    free(g->views);
    free(g->blob.p);
    free(g->js.s);
}

bn_status bn__write_gltf(const char *path, int binary, const bn__bake_out *m, const bn_scene *scene,
                         const bn_bake_write_opts *o, bn_error *err)
{
    bn__gltf g = {.m = m, .unit = bn_unit_to_metres(bn_scene_unit(scene)), .scale = exp2(m->exposure_ev),
                  .lo = {INFINITY, INFINITY, INFINITY}, .hi = {-INFINITY, -INFINITY, -INFINITY}};
    size_t len = strlen(path);
    char *binpath = binary ? NULL : malloc(len + 8);   /* .gltf: the .bin beside it, same stem */
    bn_status st = BN_OK;
    if (m->nv > UINT32_MAX)
        st = bn_error_set(err, BN_EUSAGE, "%s: %zu vertices are more than glTF's 32-bit indices address", path, m->nv);
    g.mat = bn_scene_materials(scene, &g.nmat);
    g.nobj = m->face_object && m->nobjects > 1 ? m->nobjects : 1;
    g.ngroups = g.nobj * g.nmat;
    g.mat_tris = bn__calloc(g.ngroups + 1, sizeof(size_t));
    g.mat_first = bn__calloc(g.ngroups + 1, sizeof(size_t));
    g.views = bn__calloc(m->nlayers + 5 + g.ngroups, sizeof *g.views);
    if (st == BN_OK && (!g.mat_tris || !g.mat_first || !g.views || (!binary && !binpath)))
        st = BN_ENOMEM;
    if (st == BN_OK)
        st = bn__gltf_triangles(&g, path, err);
    if (st == BN_OK)
        st = bn__gltf_vertices(&g);
    if (st == BN_OK)
        st = bn__gltf_indices(&g);
    if (st == BN_OK && binpath)
        snprintf(binpath, len + 8, "%.*s.bin", (int)(len - 5), path);
    if (st == BN_OK)
        st = bn__gltf_json(&g, scene, o, binpath ? (strrchr(binpath, '/') ? strrchr(binpath, '/') + 1 : binpath) : NULL);
    if (st == BN_ENOMEM)
        st = bn_error_set(err, BN_ENOMEM, "%s: out of memory writing the glTF of %zu vertices", path, m->nv);
    if (st == BN_OK && binary)
        st = bn__gltf_write_glb(path, &g, err);
    else if (st == BN_OK) {
        const void *pb = g.blob.p, *pj = g.js.s;
        st = bn__write_pieces(binpath, 1, &pb, &g.blob.n, err);
        if (st == BN_OK)
            st = bn__write_pieces(path, 1, &pj, &g.js.n, err);
    }
    bn__gltf_free(&g);
    free(binpath);
    return st;
}
