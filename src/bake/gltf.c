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

typedef struct bn__view {
    size_t offset, length;
    int target;   /* 34962 ARRAY_BUFFER, 34963 ELEMENT_ARRAY_BUFFER */
    int stride;   /* vertex views: bytes per vertex (glTF wants it when accessors share the view); 0 none */
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

/* The writer's state: the mesh, its triangles grouped by mesh and material, the vertices each mesh
 * uses, the binary buffer and its views, the JSON. Two layouts: flat (a mesh per object, every mesh on
 * one shared set of world-space vertices, the nodes untransformed) and, for a scene read from a glTF
 * file, the input's node tree (each node with a mesh gets the bake of its faces, on vertices of its own
 * in the node's local frame, so its transform, kept as the file gave it, puts them back). */
typedef struct bn__gltf {
    const bn__bake_out *m;
    const bn_material *mat;
    size_t nmat;
    double unit, scale;            /* metres per scene unit; COLOR_0's 2^exposure_ev */
    const bn_scene_node *tree;     /* the input's nodes (NULL: flat) */
    size_t ntree, nroots;
    const size_t *roots;
    size_t nmesh;                  /* objects (flat) or tree nodes: a mesh each when it has triangles */
    size_t *obj_mesh;              /* per object: its mesh */
    double (*inv)[16];             /* tree: per node, its world transform's inverse */
    unsigned char *flip;           /* tree: per node, 1 when it mirrors (the winding written reversed) */
    size_t nslice;                 /* vertex slices: 1 (flat), else one per mesh */
    size_t *slice_v, *slice_nv;    /* per slice: its first output vertex, and count */
    size_t *vsrc;                  /* per output vertex: the bake's vertex it copies */
    bn__bake_out mtree;            /* m without face normals when written in the input's node tree (whose
                                      local frames they are not in) */
    size_t nvout;
    const char *flat_why;          /* flat: why the input's tree is not kept (NULL: it is) */
    float (*lo)[3], (*hi)[3];      /* per slice: its positions' bounds */
    uint32_t *idx;                 /* 3 per triangle, group by group, in its slice's numbering */
    size_t ngroups;                /* mesh x material */
    size_t *mat_tris, *mat_first;  /* per group (mesh s, material k: s nmat + k) */
    bn__view *views;
    size_t nviews;
    bn__blob blob;
    bn__str js;
} bn__gltf;

/* Face f's group: its mesh's and material's. */
static size_t bn__group(const bn__gltf *g, size_t f)
{
    size_t o = g->m->face_object && g->m->nobjects > 1 ? g->m->face_object[f] : 0;
    return g->obj_mesh[o] * g->nmat + g->m->face_material[f];
}

static size_t bn__slice_of(const bn__gltf *g, size_t mesh) { return g->nslice == 1 ? 0 : mesh; }

static double bn__det3(const double A[16])
{
    return A[0] * (A[5] * A[10] - A[9] * A[6]) - A[4] * (A[1] * A[10] - A[9] * A[2]) + A[8] * (A[1] * A[6] - A[5] * A[2]);
}

/* The inverse of affine A (column-major) into B; 0 when A is singular. */
static int bn__affine_inverse(const double A[16], double B[16])
{
    double d = bn__det3(A);
    double s = fabs(A[0]) + fabs(A[5]) + fabs(A[10]) + fabs(A[1]) + fabs(A[2]) + fabs(A[4]) + fabs(A[6]) +
               fabs(A[8]) + fabs(A[9]);
    if (!(fabs(d) > 1e-12 * s * s * s) || !isfinite(d))
        return 0;
    B[0] = (A[5] * A[10] - A[6] * A[9]) / d, B[4] = (A[8] * A[6] - A[4] * A[10]) / d, B[8] = (A[4] * A[9] - A[8] * A[5]) / d;
    B[1] = (A[9] * A[2] - A[1] * A[10]) / d, B[5] = (A[0] * A[10] - A[8] * A[2]) / d, B[9] = (A[8] * A[1] - A[0] * A[9]) / d;
    B[2] = (A[1] * A[6] - A[5] * A[2]) / d, B[6] = (A[4] * A[2] - A[0] * A[6]) / d, B[10] = (A[0] * A[5] - A[4] * A[1]) / d;
    B[3] = B[7] = B[11] = 0, B[15] = 1;
    for (int r = 0; r < 3; r++)
        B[12 + r] = -(B[r] * A[12] + B[4 + r] * A[13] + B[8 + r] * A[14]);
    return 1;
}

/* The tree node of object o: the node whose mesh became it (by name), or the one node with a mesh when
 * the objects came from elsewhere (material prefixes); SIZE_MAX: none. */
static size_t bn__object_node(const bn__gltf *g, size_t o)
{
    size_t only = SIZE_MAX, with = 0;
    for (size_t k = 0; k < g->ntree; k++) {
        const char *ob = g->tree[k].object;
        if (ob && g->m->object_names && g->m->nobjects > 1 && strcmp(ob, g->m->object_names[o]) == 0)
            return k;
        if (ob)
            only = k, with++;
    }
    return with == 1 ? only : SIZE_MAX;
}

/* Which layout, and each object's mesh: the input's tree when every object with faces has a node of its
 * own with an invertible transform, else flat (its reason in *why). */
static bn_status bn__gltf_layout(bn__gltf *g, const bn_scene *scene, const char **why)
{
    size_t nobj = g->m->face_object && g->m->nobjects > 1 ? g->m->nobjects : 1;
    g->tree = bn_scene_nodes(scene, &g->ntree, &g->roots, &g->nroots);
    g->obj_mesh = bn__calloc(nobj, sizeof *g->obj_mesh);
    if (!g->obj_mesh)
        return BN_ENOMEM;
    *why = g->tree ? NULL : "flat: the scene file has no node tree (world-space vertices, untransformed nodes)";
    if (g->tree && (!(g->inv = bn__calloc(g->ntree, sizeof *g->inv)) || !(g->flip = bn__calloc(g->ntree, 1))))
        return BN_ENOMEM;
    for (size_t k = 0; g->tree && !*why && k < g->ntree; k++) {
        int ok = bn__affine_inverse(g->tree[k].world, g->inv[k]);
        g->flip[k] = ok && bn__det3(g->tree[k].world) < 0;
        if (g->tree[k].object && !ok)
            *why = "flat: a node with a mesh has a singular transform (world-space vertices, untransformed nodes)";
    }
    for (size_t o = 0; g->tree && !*why && o < nobj; o++)
        if ((g->obj_mesh[o] = bn__object_node(g, o)) == SIZE_MAX)
            *why = "flat: an object is no node's (world-space vertices, untransformed nodes)";
    if (*why) {
        g->tree = NULL;
        for (size_t o = 0; o < nobj; o++)
            g->obj_mesh[o] = o;
    }
    g->nmesh = g->tree ? g->ntree : nobj;
    g->nslice = g->tree ? g->nmesh : 1;
    return BN_OK;
}

/* The triangles, grouped by mesh and material, each slice's vertices numbered as its faces first use
 * them (flat: the one slice is every vertex in order). */
static bn_status bn__gltf_number(bn__gltf *g, size_t *stamp, size_t *loc, size_t *fill)
{
    const bn__bake_out *m = g->m;
    for (size_t f = 0; f < m->nf; f++) {
        size_t grp = bn__group(g, f), sl = bn__slice_of(g, grp / g->nmat);
        const size_t *c = m->face_idx + 4 * f;
        for (unsigned q = 0; q < m->face_n[f]; q++) {
            size_t v = c[q];
            if (g->nslice == 1)
                loc[v] = v;
            else if (stamp[v] != sl + 1) {
                stamp[v] = sl + 1;
                loc[v] = g->slice_nv[sl]++;
            }
        }
        int flip = g->tree && g->flip[grp / g->nmat];
        size_t *w = &fill[grp];
        for (unsigned t = 0; t + 2 < m->face_n[f]; t++) {
            g->idx[(*w)++] = (uint32_t)loc[c[0]];
            g->idx[(*w)++] = (uint32_t)loc[c[flip ? t + 2 : t + 1]];
            g->idx[(*w)++] = (uint32_t)loc[c[flip ? t + 1 : t + 2]];
        }
    }
    return BN_OK;
}

/* Each slice's vertices: where it starts, and the bake's vertex each output vertex copies. */
static bn_status bn__gltf_slices(bn__gltf *g, size_t *stamp)
{
    const bn__bake_out *m = g->m;
    if (g->nslice == 1) {
        g->slice_nv[0] = m->nv;
        for (size_t v = 0; v < m->nv; v++)
            g->vsrc[v] = v;
        g->nvout = m->nv;
        return BN_OK;
    }
    for (size_t s = 0, acc = 0; s < g->nslice; s++) {
        g->slice_v[s] = acc;
        acc += g->slice_nv[s];
        g->nvout = acc;
        g->slice_nv[s] = 0;   /* counted again as they are placed */
    }
    for (size_t v = 0; v < m->nv; v++)
        stamp[v] = 0;
    for (size_t f = 0; f < m->nf; f++) {   /* the same first-use order as bn__gltf_number */
        size_t sl = bn__group(g, f) / g->nmat, *c = (size_t *)m->face_idx + 4 * f;
        for (unsigned q = 0; q < m->face_n[f]; q++)
            if (stamp[c[q]] != sl + 1) {
                stamp[c[q]] = sl + 1;
                g->vsrc[g->slice_v[sl] + g->slice_nv[sl]++] = c[q];
            }
    }
    return BN_OK;
}

/* Triangles grouped by mesh and material, one primitive each (a fan from each face's first corner:
 * faces are convex), and the vertices each slice holds. */
static bn_status bn__gltf_triangles(bn__gltf *g, const char *path, bn_error *err)
{
    const bn__bake_out *m = g->m;
    size_t ntri = 0, *fill, *stamp, *loc, nobj = m->face_object && m->nobjects > 1 ? m->nobjects : 1;
    for (size_t f = 0; f < m->nf; f++) {
        if (m->face_material[f] >= g->nmat || (nobj > 1 && m->face_object[f] >= nobj))
            return bn_error_set(err, BN_EINTERNAL, "%s: face %zu has material %u of %zu", path, f, m->face_material[f],
                                g->nmat);
        g->mat_tris[bn__group(g, f)] += m->face_n[f] - 2;
        ntri += m->face_n[f] - 2;
    }
    g->idx = bn__malloc_array(3 * ntri + 1, sizeof(uint32_t));
    fill = bn__malloc_array(g->ngroups + 1, sizeof(size_t));
    stamp = bn__calloc(m->nv + 1, sizeof(size_t));
    loc = bn__malloc_array(m->nv + 1, sizeof(size_t));
    g->vsrc = bn__malloc_array(g->nslice == 1 ? m->nv + 1 : 4 * m->nf + 1, sizeof(size_t));
    bn_status st = g->idx && fill && stamp && loc && g->vsrc ? BN_OK : BN_ENOMEM;
    for (size_t k = 0, acc = 0; st == BN_OK && k < g->ngroups; k++) {
        g->mat_first[k] = fill[k] = acc;
        acc += 3 * g->mat_tris[k];
    }
    if (st == BN_OK)
        st = bn__gltf_number(g, stamp, loc, fill);
    if (st == BN_OK)
        st = bn__gltf_slices(g, stamp);
    free(fill);
    free(stamp);
    free(loc);
    return st;
}

static void bn__gltf_view(bn__gltf *g, const void *src, size_t n, int target, int stride)
{
    size_t off = bn__blob_add(&g->blob, src, n);
    g->views[g->nviews++] = (bn__view){off, n, target, stride};
}

/* Output vertex j's position: world-space metres (flat), or its node's local frame in the file's units
 * (tree: the node's transform, as the file gave it, puts it back; a root scales the file's unit to
 * metres). */
static void bn__gltf_position(const bn__gltf *g, size_t sl, size_t j, float out[3])
{
    const double *p = g->m->pos + 3 * g->vsrc[j];
    if (!g->tree) {
        for (int c = 0; c < 3; c++)
            out[c] = (float)(p[c] * g->unit);
        return;
    }
    const double *B = g->inv[sl];
    for (int c = 0; c < 3; c++)
        out[c] = (float)(B[c] * p[0] + B[4 + c] * p[1] + B[8 + c] * p[2] + B[12 + c]);
}

/* The colour sets beside COLOR_0: COLOR_1 .. COLOR_n for the terms of a per-bounce bake (layers 1 ..;
 * layer 0 is L, which COLOR_0 shows), none otherwise. */
static size_t bn__ncolours(const bn__bake_out *m) { return m->colour_sets && m->nlayers > 1 ? m->nlayers - 1 : 0; }

/* Vertex attributes per slice: POSITION, COLOR_0, the layers' radiance, COLOR_1 .. COLOR_n, _FACE_NORMAL. */
static size_t bn__nattr(const bn__bake_out *m) { return 2 + m->nlayers + bn__ncolours(m) + (m->face_normal != NULL); }

/* Layer l's values at the output vertices as what a display shows: x 2^EV, clamped to [0, 1], linear
 * (glTF's COLOR_n are linear: the light and the brightest spots saturate). */
static void bn__gltf_display(const bn__gltf *g, size_t l, float *f3)
{
    for (size_t j = 0; j < g->nvout; j++)
        for (int c = 0; c < 3; c++)
            f3[3 * j + c] = (float)fmin(1.0, fmax(0.0, (double)g->m->vals[l][3 * g->vsrc[j] + c] * g->scale));
}

/* The binary buffer's vertex views, slice after slice: positions as float, with each slice's bounds
 * (required for POSITION); COLOR_0, what an engine shows (L); each layer's radiance itself; and in a
 * per-bounce bake COLOR_1 .. COLOR_n, each term as COLOR_0 shows L (the same scale: they add up to it
 * where nothing saturates), for tools that import colour sets only (Blender 3.4). */
static bn_status bn__gltf_vertices(bn__gltf *g)
{
    const bn__bake_out *m = g->m;
    size_t nv = g->nvout, n3 = nv * 3 * sizeof(float);
    float *f3 = bn__malloc_array(nv + 1, 3 * sizeof(float));
    if (!f3)
        return BN_ENOMEM;
    for (size_t sl = 0; sl < g->nslice; sl++)
        for (size_t j = g->slice_v[sl]; j < g->slice_v[sl] + g->slice_nv[sl]; j++) {
            bn__gltf_position(g, sl, j, f3 + 3 * j);
            for (int c = 0; c < 3; c++) {
                g->lo[sl][c] = fminf(g->lo[sl][c], f3[3 * j + c]);
                g->hi[sl][c] = fmaxf(g->hi[sl][c], f3[3 * j + c]);
            }
        }
    bn__gltf_view(g, f3, n3, 34962, 12);
    bn__gltf_display(g, 0, f3);
    bn__gltf_view(g, f3, n3, 34962, 12);
    for (size_t l = 0; l < m->nlayers; l++) {
        for (size_t j = 0; j < nv; j++)
            memcpy(f3 + 3 * j, m->vals[l] + 3 * g->vsrc[j], 3 * sizeof(float));
        bn__gltf_view(g, f3, n3, 34962, 12);
    }
    for (size_t k = 1; k <= bn__ncolours(m); k++) {
        bn__gltf_display(g, k, f3);
        bn__gltf_view(g, f3, n3, 34962, 12);
    }
    if (m->face_normal) {
        for (size_t j = 0; j < nv; j++)
            memcpy(f3 + 3 * j, m->face_normal + 3 * g->vsrc[j], 3 * sizeof(float));
        bn__gltf_view(g, f3, n3, 34962, 12);
    }
    free(f3);
    return g->blob.oom ? BN_ENOMEM : BN_OK;
}

/* The index views, one per group with triangles. Every view is whole 4-byte words (floats,
 * 32-bit indices, 4-byte colours), so the buffer is too, as the GLB chunk needs. */
static bn_status bn__gltf_indices(bn__gltf *g)
{
    for (size_t k = 0; k < g->ngroups; k++)
        if (g->mat_tris[k])
            bn__gltf_view(g, g->idx + g->mat_first[k], 3 * g->mat_tris[k] * sizeof(uint32_t), 34963, 0);
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
    bn__str_add(js, ",\"nodes\":");
    bn__str_json(js, g->flat_why ? g->flat_why : "the input's node tree: names, transforms, cameras and children as "
                 "the file gave them, each mesh replaced by the bake of its faces in the node's frame");
    bn__str_add(js, ",\"radiance_unit\":\"W m^-2 sr^-1\",\"exposure_ev\":");
    bn__str_num(js, m->exposure_ev);
    bn__str_add(js, ",\"colour_scale\":");
    bn__str_num(js, g->scale);
    bn__str_add(js, ",\"note\":\"per-vertex radiance baked from bounce's solution, positions in metres. COLOR_0 "
                    "is L times colour_scale (2^exposure_ev), linear, clamped to [0, 1]: what an engine shows; in a "
                    "per-bounce bake COLOR_1, COLOR_2, ... are the terms at the same scale (Blender imports them as "
                    "the colour attributes Col.001, Col.002, ...). The application-specific attributes hold "
                    "radiance itself, unclamped: _L, and in a per-bounce bake the terms of the series (_E = E, "
                    "_KE = K E, _K2E = K^2 E, ..., _REST the longer paths; their sum is _L)\",\"attributes\":{"
                    "\"COLOR_0\":\"L x colour_scale, clamped to [0, 1]\"");
    for (size_t k = 1; k <= bn__ncolours(m); k++) {
        bn__str_add(js, ",\"COLOR_%zu\":", k);
        bn__str_json(js, m->names[k]);
    }
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
    bn__str_add(js, ",\"provenance\":{");
    for (size_t a = 0; a < o->nattrs; a++) {
        bn__str_add(js, "%s", a ? "," : "");
        bn__str_json(js, o->attrs[a].key);
        bn__str_add(js, ":");
        bn__str_json(js, o->attrs[a].value);
    }
    bn__str_add(js, "}}");
}

/* The buffer, its views and the accessors: per slice with vertices, its positions, COLOR_0, the layers
 * and the display set (each slice at its offset in the shared views); then the indices, group by group. */
static void bn__gltf_json_accessors(bn__gltf *g, const char *binname)
{
    const bn__bake_out *m = g->m;
    bn__str *js = &g->js;
    size_t v = bn__nattr(m), nacc = 0;
    bn__str_add(js, ",\"buffers\":[{\"byteLength\":%zu", g->blob.n);
    if (binname) {
        bn__str_add(js, ",\"uri\":");
        bn__str_json(js, binname);
    }
    bn__str_add(js, "}],\"bufferViews\":[");
    for (size_t k = 0; k < g->nviews; k++) {
        bn__str_add(js, "%s{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu,\"target\":%d", k ? "," : "",
                    g->views[k].offset, g->views[k].length, g->views[k].target);
        bn__str_add(js, g->views[k].stride && g->nslice > 1 ? ",\"byteStride\":%d}" : "}", g->views[k].stride);
    }
    bn__str_add(js, "],\"accessors\":[");
    for (size_t sl = 0; sl < g->nslice; sl++) {
        size_t n = g->slice_nv[sl], o = g->slice_v[sl];
        if (!n)
            continue;
        bn__str_add(js, "%s{\"bufferView\":0,\"byteOffset\":%zu,\"componentType\":5126,\"count\":%zu,\"type\":\"VEC3\","
                        "\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]}", nacc++ ? "," : "", 12 * o, n,
                    (double)g->lo[sl][0], (double)g->lo[sl][1], (double)g->lo[sl][2], (double)g->hi[sl][0],
                    (double)g->hi[sl][1], (double)g->hi[sl][2]);
        for (size_t l = 0; l <= m->nlayers; l++)   /* COLOR_0, then the layers */
            bn__str_add(js, ",{\"bufferView\":%zu,\"byteOffset\":%zu,\"componentType\":5126,\"count\":%zu,"
                            "\"type\":\"VEC3\"}", 1 + l, 12 * o, n);
        /* COLOR_1 .. COLOR_n, then _FACE_NORMAL */
        for (size_t k = 1; k <= bn__ncolours(m) + (m->face_normal != NULL); k++)
            bn__str_add(js, ",{\"bufferView\":%zu,\"byteOffset\":%zu,\"componentType\":5126,\"count\":%zu,"
                            "\"type\":\"VEC3\"}", 1 + m->nlayers + k, 12 * o, n);
    }
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

/* Triangles of mesh s. */
static size_t bn__mesh_tris(const bn__gltf *g, size_t s)
{
    size_t tris = 0;
    for (size_t k = 0; k < g->nmat; k++)
        tris += g->mat_tris[s * g->nmat + k];
    return tris;
}

/* Mesh s's name: its node's mesh's (else the node's) in the tree, else its object's (none for one). */
static void bn__mesh_name(bn__gltf *g, size_t s)
{
    const char *name = NULL;
    if (g->tree)
        name = g->tree[s].mesh_name[0] ? g->tree[s].mesh_name : g->tree[s].name;
    else if (g->nmesh > 1)
        name = g->m->object_names[s];
    if (name && name[0]) {
        bn__str_add(&g->js, "\"name\":");
        bn__str_json(&g->js, name);
        bn__str_add(&g->js, ",");
    }
}

/* One mesh's primitives (a primitive per material) on the attributes of its slice (from accessor a0);
 * *acc: the next index accessor. */
static void bn__gltf_json_prims(bn__gltf *g, size_t s, size_t a0, size_t *acc)
{
    const bn__bake_out *m = g->m;
    bn__str *js = &g->js;
    size_t p = 0;
    bn__str_add(js, "\"primitives\":[");
    for (size_t k = 0; k < g->nmat; k++) {
        if (!g->mat_tris[s * g->nmat + k])
            continue;
        bn__str_add(js, "%s{\"attributes\":{\"POSITION\":%zu,\"COLOR_0\":%zu", p++ ? "," : "", a0, a0 + 1);
        for (size_t l = 0; l < m->nlayers; l++) {
            char an[64];
            bn__attr_name(m->names[l], an, sizeof an);
            bn__str_add(js, ",\"%s\":%zu", an, a0 + 2 + l);
        }
        for (size_t q = 1; q <= bn__ncolours(m); q++)
            bn__str_add(js, ",\"COLOR_%zu\":%zu", q, a0 + 1 + m->nlayers + q);
        if (m->face_normal)
            bn__str_add(js, ",\"_FACE_NORMAL\":%zu", a0 + 2 + m->nlayers + bn__ncolours(m));
        bn__str_add(js, "},\"indices\":%zu,\"material\":%zu,\"mode\":4}", (*acc)++, k);
    }
    bn__str_add(js, "]");
}

/* A mesh per object or tree node with triangles; the materials unlit (an engine shows COLOR_0, the
 * radiance itself; a lit material would shade it twice), the reflectance and emitted radiance as data. */
static void bn__gltf_json_meshes(bn__gltf *g)
{
    const bn__bake_out *m = g->m;
    bn__str *js = &g->js;
    size_t nattr = bn__nattr(m), nmesh = 0, acc = 0;
    for (size_t sl = 0; sl < g->nslice; sl++)
        acc += g->slice_nv[sl] ? nattr : 0;
    bn__str_add(js, ",\"meshes\":[");
    for (size_t s = 0, a0 = 0; s < g->nmesh; s++) {
        if (!bn__mesh_tris(g, s))
            continue;
        bn__str_add(js, "%s{", nmesh++ ? "," : "");
        bn__mesh_name(g, s);
        bn__gltf_json_prims(g, s, g->nslice == 1 ? 0 : a0, &acc);
        for (size_t k = 0; k <= bn__ncolours(m) && bn__ncolours(m); k++) {   /* which term each colour set holds */
            bn__str_add(js, "%s\"COLOR_%zu\":", k ? "," : ",\"extras\":{", k);
            bn__str_json(js, m->names[k]);
        }
        bn__str_add(js, "%s}", bn__ncolours(m) ? "}" : "");
        a0 += g->nslice == 1 ? 0 : nattr;
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

/* Flat: one node per object with triangles, named as the object (the file's node or group, or the
 * material-name prefix), each with its mesh; a single node named after the scene file when there is
 * one object. Positions are in world space: the nodes carry no transform. */
static void bn__gltf_json_flat_nodes(bn__gltf *g, const bn_scene *scene)
{
    bn__str *js = &g->js;
    size_t n = 0;
    bn__str_add(js, ",\"nodes\":[");
    for (size_t o = 0; o < g->nmesh; o++) {
        if (!bn__mesh_tris(g, o))
            continue;
        bn__str_add(js, "%s{\"mesh\":%zu,\"name\":", n ? "," : "", n);
        bn__str_json(js, g->nmesh > 1 ? g->m->object_names[o] : bn_scene_path(scene));
        bn__str_add(js, "}");
        n++;
    }
    bn__str_add(js, "],\"scenes\":[{\"nodes\":[");
    for (size_t k = 0; k < n; k++)
        bn__str_add(js, "%s%zu", k ? "," : "", k);
    bn__str_add(js, "]}]");
}

/* A JSON array of n numbers. */
static void bn__str_nums(bn__str *js, const double *v, size_t n)   /* %.17g: the file's doubles kept */
{
    for (size_t c = 0; c < n; c++) {
        bn__str_add(js, "%s", c ? "," : "[");
        bn__str_add(js, "%.17g", isfinite(v[c]) ? v[c] : 0.0);
    }
    bn__str_add(js, "]");
}

/* Tree node k as the file gave it (name, transform, children, camera ordinal *cam), with mesh `mesh`
 * (SIZE_MAX: none). */
static void bn__gltf_json_node(bn__gltf *g, size_t k, size_t mesh, size_t *cam)
{
    static const char *trs[3] = {"translation", "rotation", "scale"};
    const bn_scene_node *n = &g->tree[k];
    const double *v[3] = {n->t, n->r, n->s};
    unsigned nv[3] = {n->nt, n->nr, n->ns};
    bn__str *js = &g->js;
    const char *sep = "";
    bn__str_add(js, "{");
    if (n->name[0]) {
        bn__str_add(js, "\"name\":");
        bn__str_json(js, n->name);
        sep = ",";
    }
    if (n->nmatrix == 16) {
        bn__str_add(js, "%s\"matrix\":", sep);
        bn__str_nums(js, n->matrix, 16);
        sep = ",";
    }
    for (int q = 0; q < 3 && n->nmatrix != 16; q++)
        if (nv[q]) {
            bn__str_add(js, "%s\"%s\":", sep, trs[q]);
            bn__str_nums(js, v[q], nv[q]);
            sep = ",";
        }
    if (mesh != SIZE_MAX)
        bn__str_add(js, "%s\"mesh\":%zu", sep, mesh), sep = ",";
    if (n->light >= 0)
        bn__str_add(js, "%s\"extensions\":{\"KHR_lights_punctual\":{\"light\":%d}}", sep, n->light), sep = ",";
    if (n->camera)
        bn__str_add(js, "%s\"camera\":%zu", sep, (*cam)++), sep = ",";
    for (size_t c = 0; c < n->nchildren; c++)
        bn__str_add(js, "%s%zu", c ? "," : *sep ? ",\"children\":[" : "\"children\":[", n->children[c]);
    bn__str_add(js, "%s}", n->nchildren ? "]" : "");
}

/* The scene's punctual lights (the tree's nodes refer to them by index), as the extension writes them:
 * colour x intensity split as the largest channel's intensity and a colour at most 1. */
static void bn__gltf_json_lights(bn__gltf *g, const bn_scene *scene)
{
    static const char *type[] = {"point", "spot", "directional"};
    size_t n;
    const bn_light *l = bn_scene_lights(scene, &n);
    bn__str *js = &g->js;
    if (!n)
        return;
    bn__str_add(js, ",\"extensions\":{\"KHR_lights_punctual\":{\"lights\":[");
    for (size_t k = 0; k < n; k++) {
        double I = fmax(l[k].I[0], fmax(l[k].I[1], l[k].I[2])), c[3];
        for (int q = 0; q < 3; q++)
            c[q] = I > 0 ? l[k].I[q] / I : 1;
        bn__str_add(js, "%s{\"name\":", k ? "," : "");
        bn__str_json(js, l[k].name);
        bn__str_add(js, ",\"type\":\"%s\",\"color\":", type[l[k].type]);
        bn__str_nums(js, c, 3);
        bn__str_add(js, ",\"intensity\":%.17g", I);
        if (l[k].type == BN_LIGHT_SPOT)
            bn__str_add(js, ",\"spot\":{\"innerConeAngle\":%.17g,\"outerConeAngle\":%.17g}", acos(l[k].cos_inner),
                        acos(l[k].cos_outer));
        bn__str_add(js, "}");
    }
    bn__str_add(js, "]}}");
}

/* The tree's cameras, in node order. */
static void bn__gltf_json_cameras(bn__gltf *g)
{
    bn__str *js = &g->js;
    size_t c = 0;
    for (size_t k = 0; k < g->ntree; k++) {
        const bn_scene_node *n = &g->tree[k];
        if (!n->camera)
            continue;
        bn__str_add(js, "%s{", c++ ? "," : ",\"cameras\":[");
        if (n->camera_name[0]) {
            bn__str_add(js, "\"name\":");
            bn__str_json(js, n->camera_name);
            bn__str_add(js, ",");
        }
        bn__str_add(js, "\"type\":\"perspective\",\"perspective\":{\"yfov\":%.17g,\"znear\":%.17g", n->yfov, n->znear);
        if (n->zfar > 0)
            bn__str_add(js, ",\"zfar\":%.17g", n->zfar);
        if (n->aspect > 0)
            bn__str_add(js, ",\"aspectRatio\":%.17g", n->aspect);
        bn__str_add(js, "}}");
    }
    if (c)
        bn__str_add(js, "]");
}

/* The input's tree: every node as the file gave it, those with a mesh holding their bake's; when the
 * scene's unit is not the metre, a root scaling the file's unit to metres above the file's roots. */
static void bn__gltf_json_tree(bn__gltf *g)
{
    bn__str *js = &g->js;
    size_t mesh = 0, cam = 0;
    int wrap = g->unit != 1.0;
    bn__str_add(js, ",\"nodes\":[");
    for (size_t k = 0; k < g->ntree; k++) {
        bn__str_add(js, "%s", k ? "," : "");
        bn__gltf_json_node(g, k, bn__mesh_tris(g, k) ? mesh++ : SIZE_MAX, &cam);
    }
    if (wrap) {
        bn__str_add(js, "%s{\"name\":\"bounce: the file's unit in metres\",\"scale\":[%.17g,%.17g,%.17g],\"children\":[",
                    g->ntree ? "," : "", g->unit, g->unit, g->unit);
        for (size_t r = 0; r < g->nroots; r++)
            bn__str_add(js, "%s%zu", r ? "," : "", g->roots[r]);
        bn__str_add(js, "]}");
    }
    bn__str_add(js, "],\"scenes\":[{\"nodes\":[");
    if (wrap)
        bn__str_add(js, "%zu", g->ntree);
    for (size_t r = 0; !wrap && r < g->nroots; r++)
        bn__str_add(js, "%s%zu", r ? "," : "", g->roots[r]);
    bn__str_add(js, "]}]");
    bn__gltf_json_cameras(g);
}

/* The whole JSON, padded with spaces to 4-byte words. */
static bn_status bn__gltf_json(bn__gltf *g, const bn_scene *scene, const bn_bake_write_opts *o, const char *binname)
{
    char gen[96];
    snprintf(gen, sizeof gen, "bounce %s", bn_version());
    bn__str_add(&g->js, "{\"asset\":{\"version\":\"2.0\",\"generator\":");
    bn__str_json(&g->js, gen);
    bn__gltf_json_extras(g, scene, o);
    size_t nl;
    bn_scene_lights(scene, &nl);
    nl = g->tree ? nl : 0;   /* the lights go back on their nodes: only under the input's tree */
    bn__str_add(&g->js, "},\"extensionsUsed\":[\"KHR_materials_unlit\"%s],\"scene\":0",
                nl ? ",\"KHR_lights_punctual\"" : "");
    if (g->tree)
        bn__gltf_json_tree(g);
    else
        bn__gltf_json_flat_nodes(g, scene);
    if (nl)
        bn__gltf_json_lights(g, scene);
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
    free(g->obj_mesh);
    free(g->inv);
    free(g->flip);
    free(g->slice_v);
    free(g->slice_nv);
    free(g->vsrc);
    free(g->lo);
    free(g->hi);
}

/* The layout, the per-mesh and per-slice arrays, the triangles, the buffer and the JSON. */
static bn_status bn__gltf_build(bn__gltf *g, const bn_scene *scene, const bn_bake_write_opts *o, const char *path,
                                const char *binname, bn_error *err)
{
    const char *why = NULL;
    bn_status st = bn__gltf_layout(g, scene, &why);
    if (st != BN_OK)
        return st;
    g->flat_why = why;
    if (g->tree && g->m->face_normal) {
        g->mtree = *g->m;
        g->mtree.face_normal = NULL;
        g->m = &g->mtree;
    }
    g->ngroups = g->nmesh * g->nmat;
    g->mat_tris = bn__calloc(g->ngroups + 1, sizeof(size_t));
    g->mat_first = bn__calloc(g->ngroups + 1, sizeof(size_t));
    g->views = bn__calloc(bn__nattr(g->m) + 4 + g->ngroups, sizeof *g->views);
    g->slice_v = bn__calloc(g->nslice, sizeof(size_t));
    g->slice_nv = bn__calloc(g->nslice, sizeof(size_t));
    g->lo = bn__malloc_array(g->nslice, sizeof *g->lo);
    g->hi = bn__malloc_array(g->nslice, sizeof *g->hi);
    if (!g->mat_tris || !g->mat_first || !g->views || !g->slice_v || !g->slice_nv || !g->lo || !g->hi)
        return BN_ENOMEM;
    for (size_t sl = 0; sl < g->nslice; sl++)
        for (int c = 0; c < 3; c++)
            g->lo[sl][c] = INFINITY, g->hi[sl][c] = -INFINITY;
    if ((st = bn__gltf_triangles(g, path, err)) != BN_OK)
        return st;
    if (g->nvout > UINT32_MAX)
        return bn_error_set(err, BN_EUSAGE, "%s: %zu vertices are more than glTF's 32-bit indices address", path,
                            g->nvout);
    if ((st = bn__gltf_vertices(g)) == BN_OK && (st = bn__gltf_indices(g)) == BN_OK)
        st = bn__gltf_json(g, scene, o, binname);
    return st;
}

bn_status bn__write_gltf(const char *path, int binary, const bn__bake_out *m, const bn_scene *scene,
                         const bn_bake_write_opts *o, bn_error *err)
{
    bn__gltf g = {.m = m, .unit = bn_unit_to_metres(bn_scene_unit(scene)), .scale = exp2(m->exposure_ev)};
    size_t len = strlen(path);
    char *binpath = binary ? NULL : malloc(len + 8);   /* .gltf: the .bin beside it, same stem */
    bn_status st = BN_OK;
    g.mat = bn_scene_materials(scene, &g.nmat);
    if (!binary && !binpath)
        st = BN_ENOMEM;
    if (st == BN_OK && binpath)
        snprintf(binpath, len + 8, "%.*s.bin", (int)(len - 5), path);
    if (st == BN_OK)
        st = bn__gltf_build(&g, scene, o, path,
                            binpath ? (strrchr(binpath, '/') ? strrchr(binpath, '/') + 1 : binpath) : NULL, err);
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
