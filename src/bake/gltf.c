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

bn_status bn__write_gltf(const char *path, int binary, const bn__bake_out *m, const bn_scene *scene,
                         const bn_bake_write_opts *o, bn_error *err)
{
    size_t nmat = 0, ntri = 0, nprim = 0, nviews = 0;
    const bn_material *mat = bn_scene_materials(scene, &nmat);
    double unit = bn_unit_to_metres(bn_scene_unit(scene));
    float *fpos = NULL, lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    uint32_t *idx = NULL;
    size_t *mat_tris = NULL, *mat_first = NULL;
    unsigned char *c4 = NULL;
    float *col0 = NULL;
    double scale = exp2(m->exposure_ev);
    bn__view *views = NULL;
    bn__blob blob = {0};
    bn__str js = {0};
    char *binpath = NULL;
    const char *binname = NULL;
    bn_status st = BN_OK;

    if (m->nv > UINT32_MAX)
        return bn_error_set(err, BN_EUSAGE, "%s: %zu vertices are more than glTF's 32-bit indices address", path, m->nv);
    fpos = bn__malloc_array(m->nv + 1, 3 * sizeof(float));
    mat_tris = bn__calloc(nmat + 1, sizeof(size_t));
    mat_first = bn__calloc(nmat + 1, sizeof(size_t));
    views = bn__calloc(m->nlayers + 5 + nmat, sizeof *views);
    col0 = bn__malloc_array(m->nv + 1, 3 * sizeof(float));
    if (!fpos || !mat_tris || !mat_first || !views || !col0)
        goto oom;
    /* COLOR_0, what an engine shows: L x 2^EV, clamped to [0, 1] as glTF requires (the light and
     * the brightest spots saturate); _L keeps the radiance itself */
    for (size_t i = 0; i < 3 * m->nv; i++)
        col0[i] = (float)fmin(1.0, fmax(0.0, (double)m->vals[0][i] * scale));
    /* positions in metres (glTF's unit), as float; their bounds (required for POSITION) */
    for (size_t v = 0; v < m->nv; v++)
        for (int c = 0; c < 3; c++) {
            float x = (float)(m->pos[3 * v + c] * unit);
            fpos[3 * v + c] = x;
            lo[c] = fminf(lo[c], x);
            hi[c] = fmaxf(hi[c], x);
        }
    /* triangles grouped by material: one primitive each, all sharing the vertex attributes */
    for (size_t f = 0; f < m->nf; f++) {
        if (m->face_material[f] >= nmat) {
            st = bn_error_set(err, BN_EINTERNAL, "%s: face %zu has material %u of %zu", path, f, m->face_material[f],
                              nmat);
            goto done;
        }
        mat_tris[m->face_material[f]] += m->face_n[f] - 2;
        ntri += m->face_n[f] - 2;
    }
    idx = bn__malloc_array(3 * ntri + 1, sizeof(uint32_t));
    if (!idx)
        goto oom;
    for (size_t k = 0, acc = 0; k < nmat; k++) {
        mat_first[k] = acc;
        acc += 3 * mat_tris[k];
    }
    {
        size_t *fill = bn__malloc_array(nmat + 1, sizeof(size_t));
        if (!fill)
            goto oom;
        memcpy(fill, mat_first, nmat * sizeof(size_t));
        for (size_t f = 0; f < m->nf; f++) {   /* a fan from the first corner (faces are convex) */
            const size_t *c = m->face_idx + 4 * f;
            size_t *w = &fill[m->face_material[f]];
            for (unsigned t = 0; t + 2 < m->face_n[f]; t++) {
                idx[(*w)++] = (uint32_t)c[0];
                idx[(*w)++] = (uint32_t)c[t + 1];
                idx[(*w)++] = (uint32_t)c[t + 2];
            }
        }
        free(fill);
    }

    /* buffer views: positions, one per layer, the display set, then indices per material */
    views[nviews++] = (bn__view){bn__blob_add(&blob, fpos, m->nv * 3 * sizeof(float)), m->nv * 3 * sizeof(float),
                                 34962};
    views[nviews++] = (bn__view){bn__blob_add(&blob, col0, m->nv * 3 * sizeof(float)), m->nv * 3 * sizeof(float),
                                 34962};
    for (size_t l = 0; l < m->nlayers; l++)
        views[nviews++] = (bn__view){bn__blob_add(&blob, m->vals[l], m->nv * 3 * sizeof(float)),
                                     m->nv * 3 * sizeof(float), 34962};
    if (m->c8) {   /* VEC4 of bytes (alpha 255): vertex attributes keep 4-byte strides */
        c4 = bn__malloc_array(m->nv + 1, 4);
        if (!c4)
            goto oom;
        for (size_t v = 0; v < m->nv; v++) {
            memcpy(c4 + 4 * v, m->c8 + 3 * v, 3);
            c4[4 * v + 3] = 255;
        }
        views[nviews++] = (bn__view){bn__blob_add(&blob, c4, m->nv * 4), m->nv * 4, 34962};
    }
    for (size_t k = 0; k < nmat; k++)
        if (mat_tris[k]) {
            views[nviews++] = (bn__view){bn__blob_add(&blob, idx + mat_first[k], 3 * mat_tris[k] * sizeof(uint32_t)),
                                         3 * mat_tris[k] * sizeof(uint32_t), 34963};
            nprim++;
        }
    if (blob.oom)
        goto oom;
    /* every view is whole 4-byte words (floats, 32-bit indices, 4-byte colours), so the buffer is too,
     * as the GLB chunk needs */
    if (!binary) {   /* the .bin beside the .gltf: same stem */
        size_t len = strlen(path);
        binpath = malloc(len + 8);
        if (!binpath)
            goto oom;
        snprintf(binpath, len + 8, "%.*s.bin", (int)(len - 5), path);
        binname = strrchr(binpath, '/') ? strrchr(binpath, '/') + 1 : binpath;
    }

    /* ---- the JSON ---- */
    bn__str_add(&js, "{\"asset\":{\"version\":\"2.0\",\"generator\":");
    {
        char gen[96];
        snprintf(gen, sizeof gen, "bounce %s", bn_version());
        bn__str_json(&js, gen);
    }
    bn__str_add(&js, ",\"extras\":{\"radiance_unit\":\"W m^-2 sr^-1\",\"exposure_ev\":");
    bn__str_num(&js, m->exposure_ev);
    bn__str_add(&js, ",\"colour_scale\":");
    bn__str_num(&js, scale);
    bn__str_add(&js, ",\"note\":\"per-vertex radiance baked from bounce's solution, positions in metres. COLOR_0 "
                     "is L times colour_scale (2^exposure_ev), linear, clamped to [0, 1]: what an engine shows. The "
                     "application-specific attributes hold radiance itself, unclamped: _L, and with --per-bounce "
                     "the terms of the series (_E = E, _KE = K E, _K2E = K^2 E, ..., _REST the longer paths; "
                     "their sum is _L)\",\"attributes\":{\"COLOR_0\":\"L x colour_scale, clamped to [0, 1]\"");
    for (size_t l = 0; l < m->nlayers; l++) {
        char an[64];
        bn__attr_name(m->names[l], an, sizeof an);
        bn__str_add(&js, ",");
        bn__str_json(&js, an);
        bn__str_add(&js, ":");
        bn__str_json(&js, m->names[l]);
    }
    bn__str_add(&js, "},\"power_W\":{");
    for (size_t l = 0; l < m->nlayers; l++) {   /* pi sum A L over the patches, per layer and channel */
        bn__str_add(&js, "%s", l ? "," : "");
        bn__str_json(&js, m->names[l]);
        bn__str_add(&js, ":[");
        for (int c = 0; c < 3; c++) {
            bn__str_add(&js, "%s", c ? "," : "");
            bn__str_num(&js, m->power ? m->power[3 * l + (size_t)c] : 0.0);
        }
        bn__str_add(&js, "]");
    }
    bn__str_add(&js, "}");
    if (m->c8) {
        bn__str_add(&js, ",\"display\":{\"attribute\":\"COLOR_1\",\"encoding\":\"8-bit sRGB of L\",\"exposure_ev\":");
        bn__str_num(&js, m->exposure_ev);
        bn__str_add(&js, "}");
    }
    bn__str_add(&js, ",\"provenance\":{");
    for (size_t a = 0; a < o->nattrs; a++) {
        bn__str_add(&js, "%s", a ? "," : "");
        bn__str_json(&js, o->attrs[a].key);
        bn__str_add(&js, ":");
        bn__str_json(&js, o->attrs[a].value);
    }
    bn__str_add(&js, "}}},\"extensionsUsed\":[\"KHR_materials_unlit\"],\"scene\":0,\"scenes\":[{\"nodes\":[0]}],"
                     "\"nodes\":[{\"mesh\":0,\"name\":");
    bn__str_json(&js, bn_scene_path(scene));
    bn__str_add(&js, "}],\"buffers\":[{\"byteLength\":%zu", blob.n);
    if (!binary) {
        bn__str_add(&js, ",\"uri\":");
        bn__str_json(&js, binname);
    }
    bn__str_add(&js, "}],\"bufferViews\":[");
    for (size_t k = 0; k < nviews; k++)
        bn__str_add(&js, "%s{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu,\"target\":%d}", k ? "," : "",
                    views[k].offset, views[k].length, views[k].target);
    /* accessors: 0 positions, 1.. layers, then the display set, then indices */
    bn__str_add(&js, "],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":%zu,\"type\":\"VEC3\","
                     "\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]}",
                m->nv, (double)lo[0], (double)lo[1], (double)lo[2], (double)hi[0], (double)hi[1], (double)hi[2]);
    for (size_t l = 0; l <= m->nlayers; l++)   /* COLOR_0, then the layers */
        bn__str_add(&js, ",{\"bufferView\":%zu,\"componentType\":5126,\"count\":%zu,\"type\":\"VEC3\"}", 1 + l, m->nv);
    if (m->c8)
        bn__str_add(&js, ",{\"bufferView\":%zu,\"componentType\":5121,\"normalized\":true,\"count\":%zu,"
                         "\"type\":\"VEC4\"}",
                    2 + m->nlayers, m->nv);
    {
        size_t v = 2 + m->nlayers + (m->c8 ? 1 : 0);
        for (size_t k = 0; k < nmat; k++)
            if (mat_tris[k]) {
                uint32_t imin = UINT32_MAX, imax = 0;
                for (size_t i = 0; i < 3 * mat_tris[k]; i++) {
                    imin = idx[mat_first[k] + i] < imin ? idx[mat_first[k] + i] : imin;
                    imax = idx[mat_first[k] + i] > imax ? idx[mat_first[k] + i] : imax;
                }
                bn__str_add(&js, ",{\"bufferView\":%zu,\"componentType\":5125,\"count\":%zu,\"type\":\"SCALAR\","
                                 "\"min\":[%u],\"max\":[%u]}",
                            v++, 3 * mat_tris[k], imin, imax);
            }
    }
    /* one mesh, a primitive per material */
    bn__str_add(&js, "],\"meshes\":[{\"primitives\":[");
    {
        size_t acc = 2 + m->nlayers + (m->c8 ? 1 : 0), p = 0;
        for (size_t k = 0; k < nmat; k++) {
            if (!mat_tris[k])
                continue;
            bn__str_add(&js, "%s{\"attributes\":{\"POSITION\":0,\"COLOR_0\":1", p++ ? "," : "");
            for (size_t l = 0; l < m->nlayers; l++) {
                char an[64];
                bn__attr_name(m->names[l], an, sizeof an);
                bn__str_add(&js, ",\"%s\":%zu", an, 2 + l);
            }
            if (m->c8)
                bn__str_add(&js, ",\"COLOR_1\":%zu", 2 + m->nlayers);
            bn__str_add(&js, "},\"indices\":%zu,\"material\":%zu,\"mode\":4}", acc++, k);
        }
    }
    /* materials: unlit (an engine shows COLOR_0, the radiance itself; a lit material would shade it
     * twice), the reflectance and emitted radiance as data */
    bn__str_add(&js, "]}],\"materials\":[");
    for (size_t k = 0; k < nmat; k++) {
        bn__str_add(&js, "%s{\"name\":", k ? "," : "");
        bn__str_json(&js, mat[k].name);
        bn__str_add(&js, ",\"pbrMetallicRoughness\":{\"baseColorFactor\":[1,1,1,1],\"metallicFactor\":0,"
                         "\"roughnessFactor\":1},\"doubleSided\":false,\"extensions\":{\"KHR_materials_unlit\":{}},"
                         "\"extras\":{\"reflectance\":[");
        for (int c = 0; c < 3; c++) {
            bn__str_add(&js, "%s", c ? "," : "");
            bn__str_num(&js, mat[k].rho[c]);
        }
        bn__str_add(&js, "],\"emitted_radiance\":[");
        for (int c = 0; c < 3; c++) {
            bn__str_add(&js, "%s", c ? "," : "");
            bn__str_num(&js, mat[k].Le[c]);
        }
        bn__str_add(&js, "]}}");
    }
    bn__str_add(&js, "]}");
    if (js.oom)
        goto oom;
    while (js.n % 4) {   /* the JSON chunk is padded with spaces */
        bn__str_add(&js, " ");
        if (js.oom)
            goto oom;
    }

    if (binary) {   /* header, JSON chunk, BIN chunk: little-endian words, written piece by piece */
        unsigned char head[20], binhead[8];
        size_t total = 20 + js.n + 8 + blob.n;
        if (total > UINT32_MAX) {
            st = bn_error_set(err, BN_EUSAGE, "%s: %zu bytes are more than a .glb holds (4 GiB); write .gltf", path,
                              total);
            goto done;
        }
        bn__le32_put(head, 0x46546C67u);   /* "glTF" */
        bn__le32_put(head + 4, 2u);
        bn__le32_put(head + 8, (uint32_t)total);
        bn__le32_put(head + 12, (uint32_t)js.n);
        bn__le32_put(head + 16, 0x4E4F534Au);   /* "JSON" */
        bn__le32_put(binhead, (uint32_t)blob.n);
        bn__le32_put(binhead + 4, 0x004E4942u);   /* "BIN\0" */
        {
            const void *p[4] = {head, js.s, binhead, blob.p};
            size_t len[4] = {20, js.n, 8, blob.n};
            st = bn__write_pieces(path, 4, p, len, err);
        }
    } else {
        const void *pb = blob.p, *pj = js.s;
        st = bn__write_pieces(binpath, 1, &pb, &blob.n, err);
        if (st == BN_OK)
            st = bn__write_pieces(path, 1, &pj, &js.n, err);
    }
    goto done;
oom:
    st = bn_error_set(err, BN_ENOMEM, "%s: out of memory writing the glTF of %zu vertices", path, m->nv);
done:
    free(fpos);
    free(idx);
    free(mat_tris);
    free(mat_first);
    free(c4);
    free(col0);
    free(views);
    free(blob.p);
    free(js.s);
    free(binpath);
    return st;
}
