/* glTF 2.0 scenes (.gltf with its buffers, .glb). tinygltf parses (src/adapters/gltf_io.cpp); this
 * file checks every index, size and value it uses and names a bad one by its JSON pointer, walks the
 * default scene's node tree with each node's world transform (matrix, or translation x rotation x
 * scale), and fills the soup: every primitive of mode TRIANGLES, TRIANGLE_STRIP or TRIANGLE_FAN in
 * world space (a transform that mirrors turns the winding, as the specification says), one material per
 * glTF material (reflectance: baseColorFactor's RGB; emitted radiance: emissiveFactor x
 * KHR_materials_emissive_strength, in W m^-2 sr^-1; doubleSided: two-sided), one object per node. */
#include "scene/gltf_tree.h"
#include "base/vec.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define BN__GLTF_NO_VIEW_MAX ((size_t)1 << 26)   /* elements of an accessor without a bufferView */

typedef struct bn__gr {
    const char *path;
    const bn__gltf *g;
    bn__soup *s;
    const bn_log *log;
    bn_error *err;
    unsigned *mat_of;        /* glTF material -> soup material */
    unsigned default_mat;    /* UINT32_MAX until a primitive without a material needs it */
    unsigned char *seen;     /* per node: reached by the walk */
    double *world;           /* per node: its world transform (16), kept for the tree */
    char **objname;          /* per node: the object its mesh became (owned; NULL: none) */
    int *light;              /* per node: its punctual light's index in the soup, -1 none */
    int *tex_of;             /* glTF texture -> soup texture (-1: not decoded yet) */
    int *mat_uv;             /* per glTF material: the TEXCOORD set of its texture, -1: untextured */
    size_t skipped, skinned, triangles, ranged;
} bn__gr;

static size_t bn__ctype_size(int ct)
{
    switch (ct) {
    case 5120: case 5121: return 1;   /* BYTE, UNSIGNED_BYTE */
    case 5122: case 5123: return 2;   /* SHORT, UNSIGNED_SHORT */
    case 5125: case 5126: return 4;   /* UNSIGNED_INT, FLOAT */
    default: return 0;                /* INT (5124) is not an accessor type in glTF 2.0 */
    }
}

/* One little-endian component; normalized integers map to [0, 1] or [-1, 1] as the specification says. */
static double bn__component(const unsigned char *p, int ct, int normalized)
{
    uint32_t u32 = (uint32_t)p[0];
    switch (ct) {
    case 5120: return normalized ? fmax((int8_t)p[0] / 127.0, -1.0) : (double)(int8_t)p[0];
    case 5121: return normalized ? p[0] / 255.0 : (double)p[0];
    case 5122: {
        int16_t v = (int16_t)(uint16_t)(p[0] | p[1] << 8);
        return normalized ? fmax(v / 32767.0, -1.0) : (double)v;
    }
    case 5123: return normalized ? (p[0] | p[1] << 8) / 65535.0 : (double)(p[0] | p[1] << 8);
    default: break;
    }
    u32 |= (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
    if (ct == 5125)
        return normalized ? u32 / 4294967295.0 : (double)u32;
    float f;
    memcpy(&f, &u32, sizeof f);
    return f;
}

/* The bytes of `count` elements of `esize` bytes at `off` in bufferView v (its byteStride when `strided`,
 * else packed), checked against the view and its buffer. NULL with err set when they do not fit. */
static const unsigned char *bn__view_span(bn__gr *r, const char *ref, int v, size_t off, size_t count, size_t esize,
                                          int strided, size_t *stride)
{
    const bn__gltf *g = r->g;
    if (v < 0 || (size_t)v >= g->nviews) {
        bn_error_set(r->err, BN_EINPUT, "%s: %s: bufferView %d does not exist (the file has %zu)", r->path, ref, v,
                     g->nviews);
        return NULL;
    }
    const bn__gltf_view *w = &g->views[v];
    if (w->buffer < 0 || (size_t)w->buffer >= g->nbuffers || w->offset > g->buffers[w->buffer].size ||
        w->length > g->buffers[w->buffer].size - w->offset) {
        bn_error_set(r->err, BN_EINPUT, "%s: /bufferViews/%d: %zu bytes at offset %zu do not lie in buffer %d%s", r->path,
                     v, w->length, w->offset, w->buffer,
                     w->buffer < 0 || (size_t)w->buffer >= g->nbuffers ? " (no such buffer)" : "");
        return NULL;
    }
    *stride = strided && w->stride ? w->stride : esize;
    if (*stride < esize) {
        bn_error_set(r->err, BN_EINPUT, "%s: /bufferViews/%d/byteStride: %zu is less than the %zu bytes of an element of %s",
                     r->path, v, w->stride, esize, ref);
        return NULL;
    }
    if (count > 0 && (off > w->length || esize > w->length - off || count - 1 > (w->length - off - esize) / *stride)) {
        bn_error_set(r->err, BN_EINPUT, "%s: %s: %zu elements of %zu bytes at offset %zu overrun bufferView %d (%zu bytes)",
                     r->path, ref, count, esize, off, v, w->length);
        return NULL;
    }
    static const unsigned char none[1];   /* an empty buffer's data may be NULL: no arithmetic on it */
    return g->buffers[w->buffer].data ? g->buffers[w->buffer].data + w->offset + off : none;
}

/* A sparse accessor's substitutions over its dense values (count x ncomp). */
static bn_status bn__sparse(bn__gr *r, int a, const bn__gltf_accessor *x, size_t ncomp, double *out)
{
    char ref[64];
    size_t isz = bn__ctype_size(x->sparse_ictype), esz = bn__ctype_size(x->ctype), ist, vst;
    const unsigned char *ip, *vp;
    if (x->sparse_ictype != 5121 && x->sparse_ictype != 5123 && x->sparse_ictype != 5125)
        return bn_error_set(r->err, BN_EINPUT, "%s: /accessors/%d/sparse/indices/componentType: %d is not an unsigned "
                            "integer type", r->path, a, x->sparse_ictype);
    if (x->sparse_count > x->count)
        return bn_error_set(r->err, BN_EINPUT, "%s: /accessors/%d/sparse/count: %zu is more than the accessor's %zu elements",
                            r->path, a, x->sparse_count, x->count);
    snprintf(ref, sizeof ref, "/accessors/%d/sparse/indices", a);
    if (!(ip = bn__view_span(r, ref, x->sparse_iview, x->sparse_ioffset, x->sparse_count, isz, 0, &ist)))
        return BN_EINPUT;
    snprintf(ref, sizeof ref, "/accessors/%d/sparse/values", a);
    if (!(vp = bn__view_span(r, ref, x->sparse_vview, x->sparse_voffset, x->sparse_count, esz * ncomp, 0, &vst)))
        return BN_EINPUT;
    for (size_t k = 0; k < x->sparse_count; k++) {
        double i = bn__component(ip + k * ist, x->sparse_ictype, 0);
        if (i >= (double)x->count)
            return bn_error_set(r->err, BN_EINPUT, "%s: /accessors/%d/sparse/indices: index %zu is %.0f, past the "
                                "accessor's %zu elements", r->path, a, k, i, x->count);
        for (size_t c = 0; c < ncomp; c++)
            out[(size_t)i * ncomp + c] = bn__component(vp + k * vst + c * esz, x->ctype, x->normalized);
    }
    return BN_OK;
}

static const char *bn__type_name(int t)
{
    static const char *names[] = {"not SCALAR or VECn", "SCALAR", "VEC2", "VEC3", "VEC4"};
    return names[t >= 0 && t <= 4 ? t : 0];
}

/* Accessor a (referenced at `ref`) as count x `type` doubles, sparse substitutions applied; NULL with
 * err set when it is not of that type or does not fit its buffer. */
static double *bn__accessor(bn__gr *r, int a, int type, const char *ref, size_t *count)
{
    const bn__gltf *g = r->g;
    const bn__gltf_accessor *x;
    const unsigned char *p = NULL;
    size_t esz, stride = 0;
    double *out;
    if (a < 0 || (size_t)a >= g->naccessors) {
        bn_error_set(r->err, BN_EINPUT, "%s: %s: accessor %d does not exist (the file has %zu)", r->path, ref, a,
                     g->naccessors);
        return NULL;
    }
    x = &g->accessors[a];
    esz = bn__ctype_size(x->ctype);
    if (x->type != type || esz == 0) {
        bn_error_set(r->err, BN_EINPUT, "%s: %s: accessor %d is %s of component type %d, not %s", r->path, ref, a,
                     bn__type_name(x->type), x->ctype, bn__type_name(type));
        return NULL;
    }
    if (x->view >= 0 && !(p = bn__view_span(r, ref, x->view, x->offset, x->count, esz * (size_t)type, 1, &stride)))
        return NULL;
    if (x->view < 0 && (x->sparse_count == 0 || x->count > BN__GLTF_NO_VIEW_MAX)) {
        bn_error_set(r->err, BN_EINPUT, "%s: /accessors/%d: %zu elements without a bufferView%s", r->path, a, x->count,
                     x->sparse_count == 0 ? " or sparse values (all zero)" : ", more than bounce allocates for one");
        return NULL;
    }
    if (!(out = bn__calloc(x->count * (size_t)type + 1, sizeof *out))) {
        bn_error_set(r->err, BN_ENOMEM, "%s: out of memory for /accessors/%d (%zu elements)", r->path, a, x->count);
        return NULL;
    }
    for (size_t i = 0; p && i < x->count; i++)
        for (int c = 0; c < type; c++)
            out[i * (size_t)type + (size_t)c] = bn__component(p + i * stride + (size_t)c * esz, x->ctype, x->normalized);
    if (x->sparse_count && bn__sparse(r, a, x, (size_t)type, out) != BN_OK) {
        free(out);
        return NULL;
    }
    *count = x->count;
    return out;
}

/* glTF texture ti decoded (once) into the soup: its index there, or -1 (err set). */
static int bn__decode_texture(bn__gr *r, int ti, size_t mat)
{
    const bn__gltf *g = r->g;
    bn__texture t;
    char name[256];
    if (ti < 0 || (size_t)ti >= g->ntextures) {
        bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu: texture %d does not exist (the file has %zu)", r->path, mat,
                     ti, g->ntextures);
        return -1;
    }
    if (r->tex_of[ti] >= 0)
        return r->tex_of[ti];
    int im = g->textures[ti].source;
    if (im < 0 || (size_t)im >= g->nimages || !g->images[im].bytes) {
        bn_error_set(r->err, BN_EINPUT, "%s: /textures/%d/source: image %d %s", r->path, ti, im,
                     im < 0 || (size_t)im >= g->nimages ? "does not exist" : "could not be read (a missing file?)");
        return -1;
    }
    const bn__gltf_image *I = &g->images[im];
    const char *ext = strstr(I->mime, "jpeg") ? ".jpg" : strstr(I->mime, "png") ? ".png" : "";
    if (!ext[0] && strncmp(I->uri, "data:", 5) != 0 && strrchr(I->uri, '.'))
        ext = strrchr(I->uri, '.');
    snprintf(name, sizeof name, "%s (/images/%d%s%.100s)%s", r->path, im, I->uri[0] && strncmp(I->uri, "data:", 5) ? ": " : "",
             strncmp(I->uri, "data:", 5) ? I->uri : "", ext);
    if (bn__texture_decode(name, I->bytes, I->size, &t, r->err) != BN_OK)
        return -1;
    for (int a = 0; a < 2; a++) {
        int w = a ? g->textures[ti].wrap_t : g->textures[ti].wrap_s;
        t.wrap[a] = w == 33071 ? BN__WRAP_CLAMP : w == 33648 ? BN__WRAP_MIRROR : BN__WRAP_REPEAT;
    }
    t.nearest = g->textures[ti].mag == 9728;
    snprintf(t.name, sizeof t.name, "/images/%d%s%.40s", im, I->uri[0] && strncmp(I->uri, "data:", 5) ? " " : "",
             strncmp(I->uri, "data:", 5) ? I->uri : "");
    if ((r->tex_of[ti] = bn__soup_add_texture(r->s, &t)) < 0) {
        free(t.rgb);
        free(t.rgb8);
        bn_error_set(r->err, BN_ENOMEM, "out of memory");
    }
    return r->tex_of[ti];
}

/* Material i's reflectance texture (baseColorTexture, or the specular-glossiness diffuseTexture). */
static bn_status bn__material_texture(bn__gr *r, size_t i, const bn__gltf_material *m)
{
    int ti = m->specgloss ? m->diffuse_tex : m->base_tex, t;
    r->mat_uv[i] = -1;
    if (ti < 0)
        return BN_OK;
    if (m->base_uv < 0 || m->base_uv > 1)
        return bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu/pbrMetallicRoughness/baseColorTexture/texCoord: %d "
                            "(bounce reads TEXCOORD_0 and TEXCOORD_1)", r->path, i, m->base_uv);
    if ((t = bn__decode_texture(r, ti, i)) < 0)
        return r->err->status;
    if (!bn__soup_set_material_texture(r->s, r->mat_of[i], t))
        return bn_error_set(r->err, BN_ENOMEM, "out of memory");
    r->mat_uv[i] = m->specgloss ? 0 : m->tt_texcoord >= 0 ? m->tt_texcoord : m->base_uv;
    if (r->mat_uv[i] > 1)
        return bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu: its texture reads TEXCOORD_%d (bounce reads TEXCOORD_0 "
                            "and TEXCOORD_1)", r->path, i, r->mat_uv[i]);
    return BN_OK;
}

/* Material i's emissiveTexture (sRGB decoded, as glTF says): each face of the material emits the
 * texture's mean over the face (bounce's emission is uniform over a face). It reads the material's
 * texture coordinates; where it would need another set or a transform of its own than the base colour's,
 * it enters as the mean over the whole image instead, said. *scale: that mean (1 otherwise). */
static bn_status bn__emissive_texture(bn__gr *r, size_t i, const bn__gltf_material *m, double scale[3])
{
    int t, own = r->mat_uv[i] < 0 ? 1 : 0;
    scale[0] = scale[1] = scale[2] = 1;
    if (m->emissive_tex < 0 || !(m->emissive[0] > 0 || m->emissive[1] > 0 || m->emissive[2] > 0))
        return BN_OK;
    if ((t = bn__decode_texture(r, m->emissive_tex, i)) < 0)
        return r->err->status;
    if (m->emissive_uv < 0 || m->emissive_uv > 1 || m->emissive_transform ||
        (!own && (r->mat_uv[i] != m->emissive_uv || m->tex_transform))) {
        bn__texture_mean(&r->s->tex[t], scale);
        bn_warnf(r->log, BN_W_MATERIAL, NAN, "%s: /materials/%zu/emissiveTexture: applied as its mean over the whole "
                 "image (%.3g %.3g %.3g): it reads TEXCOORD_%d%s, not the coordinates bounce reads for the material",
                 r->path, i, scale[0], scale[1], scale[2], m->emissive_uv,
                 m->emissive_transform || m->tex_transform ? " or a texture transform" : "");
        return BN_OK;
    }
    if (own)
        r->mat_uv[i] = m->emissive_uv;
    if (!bn__soup_set_material_emissive(r->s, r->mat_of[i], t))
        return bn_error_set(r->err, BN_ENOMEM, "out of memory");
    return BN_OK;
}

/* Material i's values, each checked against the schema's ranges. */
static bn_status bn__material_check(bn__gr *r, size_t i, const bn__gltf_material *m)
{
    if (m->nbase != 4 || m->nemissive != 3)
        return bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu/%s: %u values, not %d", r->path, i,
                            m->nbase != 4 ? "pbrMetallicRoughness/baseColorFactor" : "emissiveFactor",
                            m->nbase != 4 ? m->nbase : m->nemissive, m->nbase != 4 ? 4 : 3);
    for (int c = 0; c < 4; c++)
        if (!(m->base[c] >= 0 && m->base[c] <= 1))
            return bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu/pbrMetallicRoughness/baseColorFactor/%d: %g is "
                                "outside [0, 1]", r->path, i, c, m->base[c]);
    for (int c = 0; c < 3; c++)
        if (!(m->emissive[c] >= 0 && m->emissive[c] <= 1))
            return bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu/emissiveFactor/%d: %g is outside [0, 1]", r->path,
                                i, c, m->emissive[c]);
    for (int c = 0; m->specgloss && c < 4; c++)
        if (m->ndiffuse != 4 || !(m->diffuse[c] >= 0 && m->diffuse[c] <= 1))
            return bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu/extensions/KHR_materials_pbrSpecularGlossiness/"
                                "diffuseFactor: %u values, the %dth %g (4 in [0, 1] expected)", r->path, i, m->ndiffuse,
                                c, m->diffuse[c]);
    if (m->tex_transform && ((m->ntt_offset != 0 && m->ntt_offset != 2) || (m->ntt_scale != 0 && m->ntt_scale != 2) ||
                             !isfinite(m->tt_offset[0] + m->tt_offset[1] + m->tt_scale[0] + m->tt_scale[1] + m->tt_rotation)))
        return bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu/pbrMetallicRoughness/baseColorTexture/extensions/"
                            "KHR_texture_transform: offset and scale need 2 numbers and rotation 1 (offset %g %g, "
                            "rotation %g, scale %g %g)", r->path, i, m->tt_offset[0], m->tt_offset[1], m->tt_rotation,
                            m->tt_scale[0], m->tt_scale[1]);
    if (!(m->strength >= 0 && isfinite(m->strength)))
        return bn_error_set(r->err, BN_EINPUT, "%s: /materials/%zu/extensions/KHR_materials_emissive_strength/"
                            "emissiveStrength: %g is not a finite number >= 0", r->path, i, m->strength);
    return BN_OK;
}

/* What bounce does not model of material i, said once for it. */
static void bn__material_notes(bn__gr *r, size_t i, const bn__gltf_material *m, const char *name)
{
    if (m->specgloss)
        bn_logf(r->log, BN_LOG_INFO, "%s: /materials/%zu ('%s'): KHR_materials_pbrSpecularGlossiness: its diffuseFactor "
                "is the reflectance", r->path, i, name);
    if (m->unlit)
        bn_warnf(r->log, BN_W_MATERIAL, NAN, "%s: /materials/%zu ('%s') is KHR_materials_unlit (shown at its base "
                 "colour whatever the light): bounce reflects light off it as a Lambertian surface of that colour",
                 r->path, i, name);
    if (m->alpha_mode && strcmp(m->alpha_mode, "OPAQUE") != 0)
        bn_warnf(r->log, BN_W_MATERIAL, NAN, "%s: /materials/%zu/alphaMode ('%s'): %s: the surface is opaque to bounce",
                 r->path, i, name, m->alpha_mode);
}

/* A name no earlier material has: the file's, else "material<i>", made unique by "#<i>". */
static void bn__material_name(const bn__soup *s, size_t i, const char *given, char name[BN_NAME_MAX])
{
    int clash = 0;
    if (given && given[0])
        snprintf(name, BN_NAME_MAX, "%s", given);
    else
        snprintf(name, BN_NAME_MAX, "material%zu", i);
    for (size_t k = 0; k < s->nmats && !clash; k++)
        clash = strcmp(s->mats[k].name, name) == 0;
    if (clash) {
        char base[40];
        snprintf(base, sizeof base, "%s", name);
        snprintf(name, BN_NAME_MAX, "%s#%zu", base, i);
    }
}

static bn_status bn__materials(bn__gr *r)
{
    const bn__gltf *g = r->g;
    if (!(r->mat_of = bn__malloc_array(g->nmaterials + 1, sizeof *r->mat_of)) ||
        !(r->mat_uv = bn__malloc_array(g->nmaterials + 1, sizeof *r->mat_uv)) ||
        !(r->tex_of = bn__malloc_array(g->ntextures + 1, sizeof *r->tex_of)))
        return bn_error_set(r->err, BN_ENOMEM, "out of memory");
    for (size_t t = 0; t < g->ntextures; t++)
        r->tex_of[t] = -1;
    for (size_t i = 0; i < g->nmaterials; i++) {
        const bn__gltf_material *m = &g->materials[i];
        bn_material mt;
        bn_status st = bn__material_check(r, i, m);
        if (st != BN_OK)
            return st;
        memset(&mt, 0, sizeof mt);
        bn__material_name(r->s, i, m->name, mt.name);
        for (int c = 0; c < 3; c++) {
            mt.rho[c] = m->specgloss ? m->diffuse[c] : m->base[c];
            mt.Le[c] = m->emissive[c] * m->strength;
        }
        bn__material_notes(r, i, m, mt.name);
        r->mat_of[i] = (unsigned)r->s->nmats;
        if (!bn__soup_add_material(r->s, &mt) || (m->double_sided && !bn__soup_set_two_sided(r->s, r->mat_of[i])))
            return bn_error_set(r->err, BN_ENOMEM, "out of memory");
        double scale[3];
        if ((st = bn__material_texture(r, i, m)) != BN_OK || (st = bn__emissive_texture(r, i, m, scale)) != BN_OK)
            return st;
        bn_material *sm = &r->s->mats[r->mat_of[i]];
        for (int c = 0; c < 3; c++)
            sm->Le[c] *= scale[c];
    }
    size_t two = 0;
    for (size_t i = 0; i < g->nmaterials; i++)
        two += g->materials[i].double_sided != 0;
    if (g->nmaterials > 1 && two == g->nmaterials)
        bn_warnf(r->log, BN_W_MATERIAL, (double)two, "%s: every material is doubleSided (as Blender writes them by "
                 "default): every face gets a back side, twice the patches; where the surfaces are one-sided (closed "
                 "objects, walls), two-sided \"none\" halves the work", r->path);
    if (g->nmaterials > 0)
        bn_logf(r->log, BN_LOG_INFO, "%s: %zu materials: baseColorFactor as the diffuse reflectance (metallic and "
                "roughness are not part of a Lambertian model: ignored), emissiveFactor x emissiveStrength as the "
                "emitted radiance (W m^-2 sr^-1); %zu doubleSided: their faces get a back side each, with its own "
                "radiance (two-sided \"none\" makes every surface one-sided)", r->path, g->nmaterials, two);
    return BN_OK;
}

/* The soup material of a primitive's material index (checked); -1 gets a grey default, said once. */
static bn_status bn__material_of(bn__gr *r, int mat, size_t m, size_t k, unsigned *out)
{
    if (mat >= 0 && (size_t)mat < r->g->nmaterials) {
        *out = r->mat_of[mat];
        return BN_OK;
    }
    if (mat >= 0)
        return bn_error_set(r->err, BN_EINPUT, "%s: /meshes/%zu/primitives/%zu/material: %d does not exist (the file has "
                            "%zu)", r->path, m, k, mat, r->g->nmaterials);
    if (r->default_mat == UINT32_MAX) {
        bn_material d;
        memset(&d, 0, sizeof d);
        bn__material_name(r->s, r->g->nmaterials, "default", d.name);
        d.rho[0] = d.rho[1] = d.rho[2] = 0.5;
        r->default_mat = (unsigned)r->s->nmats;
        if (!bn__soup_add_material(r->s, &d))
            return bn_error_set(r->err, BN_ENOMEM, "out of memory");
        bn_warnf(r->log, BN_W_MATERIAL, NAN, "%s: /meshes/%zu/primitives/%zu has no material: grey reflectance 0.5 "
                 "(glTF's default material is a white metal, which a Lambertian model cannot take)", r->path, m, k);
    }
    *out = r->default_mat;
    return BN_OK;
}

/* Polygon v[0 .. n) (soup vertices; uv per primitive vertex from base, or NULL) into the soup. */
static bn_status bn__emit(bn__gr *r, const size_t *v, unsigned n, size_t base, unsigned mat, const double *uv)
{
    double cuv[8];
    for (unsigned k = 0; uv && k < n; k++)
        cuv[2 * k] = uv[2 * (v[k] - base)], cuv[2 * k + 1] = uv[2 * (v[k] - base) + 1];
    if (!bn__soup_add_polygon(r->s, v, n, mat, 0) || (uv && !bn__soup_set_corner_uv(r->s, cuv, n)))
        return bn_error_set(r->err, BN_ENOMEM, "out of memory");
    return BN_OK;
}

/* Triangles a and b as one quad (q), when they share an edge the other way round (the same positions and
 * texture coordinates) and together make a planar convex quad: what an exporter's triangulation of a
 * quad left. The quad's diagonal is its
 * corners 0-2, the shared edge, so its texture map (affine over 0-1-2 and 0-2-3) is the triangles'. */
static int bn__same(const bn__soup *s, size_t i, size_t j, size_t base, const double *uv)
{
    return i == j || (memcmp(s->verts + 3 * i, s->verts + 3 * j, 3 * sizeof(double)) == 0 &&
                      (!uv || memcmp(uv + 2 * (i - base), uv + 2 * (j - base), 2 * sizeof(double)) == 0));
}

static int bn__quad(const bn__soup *s, const size_t a[3], const size_t b[3], size_t base, const double *uv, size_t q[4])
{
    for (int k = 0; k < 3; k++) {   /* a's edge a[k+2] -> a[k] shared: b holds a[k] -> a[k+2] (by position and uv) */
        size_t x = a[k], y = a[(k + 1) % 3], z = a[(k + 2) % 3];
        for (int j = 0; j < 3; j++)
            if (bn__same(s, b[j], x, base, uv) && bn__same(s, b[(j + 1) % 3], z, base, uv)) {
                q[0] = x, q[1] = y, q[2] = z, q[3] = b[(j + 2) % 3];
                double n[4][3], e1[3], e2[3], len = 0;
                for (int c = 0; c < 4; c++) {
                    bn_v3_sub(s->verts + 3 * q[(c + 1) % 4], s->verts + 3 * q[c], e1);
                    bn_v3_sub(s->verts + 3 * q[(c + 3) % 4], s->verts + 3 * q[c], e2);
                    bn_v3_cross(e1, e2, n[c]);
                    len = fmax(len, bn_v3_len(n[c]));
                }
                for (int c = 0; c < 4; c++)   /* every corner turns the same way, about one normal */
                    if (!(len > 0) || bn_v3_dot(n[c], n[0]) < (1 - 1e-12) * bn_v3_len(n[c]) * bn_v3_len(n[0]) ||
                        !(bn_v3_len(n[c]) > 1e-9 * len))
                        return 0;
                return 1;
            }
    }
    return 0;
}

/* The triangles of a primitive's index list (mode 4, 5 or 6), wound as the file winds them, or the
 * other way under a mirroring transform (flip); vertex indices offset by base. Two in a row that make
 * a planar convex quad become that quad (bounce meshes quads as grids). */
static bn_status bn__triangles(bn__gr *r, int mode, const double *idx, size_t n, size_t base, int flip, unsigned mat,
                               const double *uv)
{
    size_t ntri = mode == 4 ? n / 3 : (n >= 3 ? n - 2 : 0), held[3], quad[4];
    int holding = 0;
    bn_status st = BN_OK;
    for (size_t t = 0; t < ntri && st == BN_OK; t++) {
        size_t v[3];
        if (mode == 4) {
            v[0] = 3 * t, v[1] = 3 * t + 1, v[2] = 3 * t + 2;
        } else if (mode == 5) {   /* a strip alternates its winding */
            v[0] = t + (t & 1), v[1] = t + 1 - (t & 1), v[2] = t + 2;
        } else {                  /* a fan turns around its first vertex */
            v[0] = 0, v[1] = t + 1, v[2] = t + 2;
        }
        size_t tri[3] = {base + (size_t)idx[v[0]], base + (size_t)idx[v[flip ? 2 : 1]], base + (size_t)idx[v[flip ? 1 : 2]]};
        if (holding && bn__quad(r->s, held, tri, base, uv, quad)) {
            st = bn__emit(r, quad, 4, base, mat, uv);
            holding = 0;
            continue;
        }
        if (holding)
            st = bn__emit(r, held, 3, base, mat, uv);
        memcpy(held, tri, sizeof tri);
        holding = 1;
    }
    if (st == BN_OK && holding)
        st = bn__emit(r, held, 3, base, mat, uv);
    r->triangles += ntri;
    return st;
}

/* The index list of a primitive (0 .. np-1 without one), each checked against its np positions. */
static double *bn__indices(bn__gr *r, const bn__gltf_prim *p, size_t m, size_t k, size_t np, size_t *n)
{
    char ref[80];
    double *idx;
    snprintf(ref, sizeof ref, "/meshes/%zu/primitives/%zu/indices", m, k);
    if (p->indices < 0) {
        if (!(idx = bn__malloc_array(np + 1, sizeof *idx)))
            bn_error_set(r->err, BN_ENOMEM, "out of memory");
        for (size_t i = 0; idx && i < np; i++)
            idx[i] = (double)i;
        *n = np;
        return idx;
    }
    if (!(idx = bn__accessor(r, p->indices, 1, ref, n)))
        return NULL;
    int ct = r->g->accessors[p->indices].ctype;
    const char *why = ct != 5121 && ct != 5123 && ct != 5125 ? "not of an unsigned integer type"
                      : r->g->accessors[p->indices].normalized ? "normalized" : NULL;
    for (size_t i = 0; !why && i < *n; i++)
        if (idx[i] >= (double)np) {
            bn_error_set(r->err, BN_EINPUT, "%s: %s: index %zu is %.0f, past the primitive's %zu positions", r->path, ref, i,
                         idx[i], np);
            free(idx);
            return NULL;
        }
    if (why) {
        bn_error_set(r->err, BN_EINPUT, "%s: %s: accessor %d is %s (component type %d)", r->path, ref, p->indices, why, ct);
        free(idx);
        return NULL;
    }
    return idx;
}

/* Positions of a primitive in world space (M: column-major 4 x 4), appended to the soup. */
static bn_status bn__positions(bn__gr *r, const bn__gltf_prim *p, size_t m, size_t k, const double M[16], size_t *np)
{
    char ref[80];
    double *pos;
    snprintf(ref, sizeof ref, "/meshes/%zu/primitives/%zu/attributes/POSITION", m, k);
    if (p->position < 0)
        return bn_error_set(r->err, BN_EINPUT, "%s: /meshes/%zu/primitives/%zu/attributes: no POSITION", r->path, m, k);
    if (!(pos = bn__accessor(r, p->position, 3, ref, np)))
        return r->err->status;
    for (size_t i = 0; i < *np; i++) {
        const double *q = pos + 3 * i;
        double w[3];
        if (!isfinite(q[0]) || !isfinite(q[1]) || !isfinite(q[2])) {
            bn_error_set(r->err, BN_EINPUT, "%s: %s: position %zu is (%g, %g, %g)", r->path, ref, i, q[0], q[1], q[2]);
            free(pos);
            return BN_EINPUT;
        }
        for (int c = 0; c < 3; c++)
            w[c] = M[c] * q[0] + M[4 + c] * q[1] + M[8 + c] * q[2] + M[12 + c];
        if (!bn__soup_add_vertex(r->s, w)) {
            free(pos);
            return bn_error_set(r->err, BN_ENOMEM, "out of memory");
        }
    }
    free(pos);
    return BN_OK;
}

/* The texture coordinates of a primitive's np vertices when its material has a texture (*uv NULL
 * otherwise): TEXCOORD_n as the material's texture says, float or normalized integers, finite. */
static bn_status bn__texcoords(bn__gr *r, const bn__gltf_prim *p, size_t m, size_t k, size_t np, double **uv)
{
    char ref[96];
    size_t n = 0;
    int set = p->material >= 0 && (size_t)p->material < r->g->nmaterials ? r->mat_uv[p->material] : -1;
    *uv = NULL;
    if (set < 0)
        return BN_OK;
    snprintf(ref, sizeof ref, "/meshes/%zu/primitives/%zu/attributes/TEXCOORD_%d", m, k, set);
    if (p->texcoord[set] < 0) {
        bn_warnf(r->log, BN_W_MATERIAL, NAN, "%s: %s: missing, so its material's texture is not applied to it (the "
                 "factor alone)", r->path, ref);
        return BN_OK;
    }
    if (!(*uv = bn__accessor(r, p->texcoord[set], 2, ref, &n)))
        return r->err->status;
    const bn__gltf_material *mt = &r->g->materials[p->material];
    double c = cos(mt->tt_rotation), sn = sin(mt->tt_rotation);
    for (size_t i = 0; mt->tex_transform && i < n; i++) {   /* KHR_texture_transform: T x R x S */
        double u = (*uv)[2 * i] * mt->tt_scale[0], v = (*uv)[2 * i + 1] * mt->tt_scale[1];
        (*uv)[2 * i] = c * u + sn * v + mt->tt_offset[0];
        (*uv)[2 * i + 1] = -sn * u + c * v + mt->tt_offset[1];
    }
    for (size_t i = 0; i < 2 * n; i++)
        if (!isfinite((*uv)[i]) || n != np) {
            bn_error_set(r->err, BN_EINPUT, "%s: %s: %s", r->path, ref, n != np ? "not one per position" : "not finite");
            free(*uv);
            *uv = NULL;
            return BN_EINPUT;
        }
    return BN_OK;
}

static bn_status bn__primitive(bn__gr *r, size_t m, size_t k, const double M[16], int flip)
{
    const bn__gltf_prim *p = &r->g->prims[r->g->meshes[m].first + k];
    size_t base = r->s->nverts, np = 0, n = 0;
    unsigned mat = 0;
    double *idx;
    bn_status st;
    if (p->mode < 0 || p->mode > 6)
        return bn_error_set(r->err, BN_EINPUT, "%s: /meshes/%zu/primitives/%zu/mode: %d is not a glTF primitive mode",
                            r->path, m, k, p->mode);
    if (p->mode < 4) {   /* points and lines have no area */
        r->skipped++;
        return BN_OK;
    }
    if ((st = bn__material_of(r, p->material, m, k, &mat)) != BN_OK ||
        (st = bn__positions(r, p, m, k, M, &np)) != BN_OK)
        return st;
    if (!(idx = bn__indices(r, p, m, k, np, &n)))
        return r->err->status;
    double *uv = NULL;
    if (p->mode == 4 && n % 3 != 0)
        st = bn_error_set(r->err, BN_EINPUT, "%s: /meshes/%zu/primitives/%zu: %zu indices, not a multiple of 3 "
                          "(mode TRIANGLES)", r->path, m, k, n);
    else if ((st = bn__texcoords(r, p, m, k, np, &uv)) == BN_OK)
        st = bn__triangles(r, p->mode, idx, n, base, flip, mat, uv);
    free(idx);
    free(uv);
    return st;
}

/* Node i's local transform, column-major: its matrix, or translation x rotation x scale. */
static bn_status bn__local(bn__gr *r, size_t i, double L[16])
{
    const bn__gltf_node *n = &r->g->nodes[i];
    double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1}, qn;
    if ((n->nmatrix != 0 && n->nmatrix != 16) || (n->nt != 0 && n->nt != 3) || (n->nr != 0 && n->nr != 4) ||
        (n->ns != 0 && n->ns != 3))
        return bn_error_set(r->err, BN_EINPUT, "%s: /nodes/%zu: matrix, translation, rotation, scale have %u, %u, %u, %u "
                            "values (16, 3, 4, 3 or none)", r->path, i, n->nmatrix, n->nt, n->nr, n->ns);
    if (n->nmatrix == 16) {
        memcpy(L, n->matrix, 16 * sizeof *L);
    } else {
        memcpy(t, n->nt ? n->t : t, sizeof t);
        memcpy(q, n->nr ? n->r : q, sizeof q);
        memcpy(s, n->ns ? n->s : s, sizeof s);
        qn = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        if (!(qn > 0) || !isfinite(qn))
            return bn_error_set(r->err, BN_EINPUT, "%s: /nodes/%zu/rotation: (%g, %g, %g, %g) is not a rotation", r->path, i,
                                q[0], q[1], q[2], q[3]);
        double x = q[0] / qn, y = q[1] / qn, z = q[2] / qn, w = q[3] / qn;
        double R[9] = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w),
                       2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w),
                       2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)};   /* columns */
        for (int c = 0; c < 3; c++)
            for (int k = 0; k < 3; k++)
                L[4 * c + k] = R[3 * c + k] * s[c];
        L[3] = L[7] = L[11] = 0;
        L[12] = t[0], L[13] = t[1], L[14] = t[2], L[15] = 1;
    }
    for (int k = 0; k < 16; k++)
        if (!isfinite(L[k]))
            return bn_error_set(r->err, BN_EINPUT, "%s: /nodes/%zu: its transform holds %g", r->path, i, L[k]);
    return BN_OK;
}

static void bn__mat4_mul(const double A[16], const double B[16], double C[16])
{
    for (int c = 0; c < 4; c++)
        for (int k = 0; k < 4; k++)
            C[4 * c + k] = A[k] * B[4 * c] + A[4 + k] * B[4 * c + 1] + A[8 + k] * B[4 * c + 2] + A[12 + k] * B[4 * c + 3];
}

static double bn__det3(const double M[16])
{
    return M[0] * (M[5] * M[10] - M[9] * M[6]) - M[4] * (M[1] * M[10] - M[9] * M[2]) + M[8] * (M[1] * M[6] - M[5] * M[2]);
}

/* Node i's camera, the first perspective one met: its eye at the node's origin, looking down its -z with
 * +y up (glTF's camera convention), in world space. */
static void bn__node_camera(bn__gr *r, size_t i, const double W[16])
{
    const bn__gltf_node *n = &r->g->nodes[i];
    bn__file_camera *c = &r->s->cam;
    double f[3], u[3];
    if (c->has || n->camera < 0 || (size_t)n->camera >= r->g->ncameras || !r->g->cameras[n->camera].perspective)
        return;
    const bn__gltf_camera *k = &r->g->cameras[n->camera];
    for (int a = 0; a < 3; a++) {
        c->eye[a] = W[12 + a];
        f[a] = -W[8 + a];
        u[a] = W[4 + a];
    }
    if (!(bn_v3_normalize(f) > 0) || !(bn_v3_normalize(u) > 0) || !(k->yfov > 0 && k->yfov < 3.14))
        return;
    for (int a = 0; a < 3; a++)
        c->look[a] = c->eye[a] + f[a], c->up[a] = u[a];
    c->yfov_deg = k->yfov * 180 / 3.14159265358979323846;
    c->aspect = k->aspect > 0 && isfinite(k->aspect) ? k->aspect : 0;
    snprintf(c->name, sizeof c->name, "%s", k->name && k->name[0] ? k->name : n->name && n->name[0] ? n->name : "camera");
    c->has = 1;
}

/* Node i's mesh, if any, under world transform W: its primitives into the soup, as one object named as the
 * node (else its mesh; a name an earlier node took gets "#i": every node its own object, so two chairs
 * of one mesh are two objects, their contacts cut and their bakes two nodes). */
static bn_status bn__node_mesh(bn__gr *r, size_t i, const double W[16])
{
    const bn__gltf_node *n = &r->g->nodes[i];
    char name[BN_NAME_MAX];
    bn_status st = BN_OK;
    if (n->mesh < 0)
        return BN_OK;
    if ((size_t)n->mesh >= r->g->nmeshes)
        return bn_error_set(r->err, BN_EINPUT, "%s: /nodes/%zu/mesh: %d does not exist (the file has %zu)", r->path, i,
                            n->mesh, r->g->nmeshes);
    r->skinned += n->skin >= 0;
    if (n->name && n->name[0])
        snprintf(name, sizeof name, "%s", n->name);
    else if (r->g->meshes[n->mesh].name && r->g->meshes[n->mesh].name[0])
        snprintf(name, sizeof name, "%s", r->g->meshes[n->mesh].name);
    else
        snprintf(name, sizeof name, "node%zu", i);
    for (size_t k = 0; k < r->s->nobjs; k++)   /* a name an earlier node took: this node's own object */
        if (strcmp(r->s->objnames[k], name) == 0) {
            char base[BN_NAME_MAX];
            memcpy(base, name, sizeof base);
            snprintf(name, sizeof name, "%.40s#%zu", base, i);
            break;
        }
    if (!bn__soup_use_object(r->s, name) || !(r->objname[i] = malloc(strlen(name) + 1)))
        return bn_error_set(r->err, BN_ENOMEM, "out of memory");
    memcpy(r->objname[i], name, strlen(name) + 1);
    for (size_t k = 0; st == BN_OK && k < r->g->meshes[n->mesh].n; k++)
        st = bn__primitive(r, (size_t)n->mesh, k, W, bn__det3(W) < 0);
    return st;
}

/* Light k's values against the extension's schema: NULL, or what is wrong. */
static const char *bn__light_bad(const bn__gltf_light *l)
{
    int spot = strcmp(l->type, "spot") == 0;
    if (!spot && strcmp(l->type, "point") != 0 && strcmp(l->type, "directional") != 0)
        return "type is not point, spot or directional";
    if (l->ncolor != 0 && l->ncolor != 3)
        return "color has not 3 values";
    for (unsigned c = 0; c < l->ncolor; c++)
        if (!(l->color[c] >= 0 && l->color[c] <= 1))
            return "a color value is outside [0, 1]";
    if (!(l->intensity >= 0 && isfinite(l->intensity)))
        return "intensity is not a finite number >= 0";
    if (spot && !(l->inner >= 0 && l->inner < l->outer && l->outer <= 1.5707963267948966))
        return "the cone angles are not 0 <= innerConeAngle < outerConeAngle <= pi/2";
    return NULL;
}

/* Node i's punctual light, if any, placed by its world transform W: at the node's origin, shining down
 * its -z (glTF's light convention). */
static bn_status bn__node_light(bn__gr *r, size_t i, const double W[16])
{
    const bn__gltf_node *n = &r->g->nodes[i];
    const char *bad;
    bn_light l = {0};
    if (n->light == -1)
        return BN_OK;
    if (n->light < 0 || (size_t)n->light >= r->g->nlights)
        return bn_error_set(r->err, BN_EINPUT, "%s: /nodes/%zu/extensions/KHR_lights_punctual/light: %s (the file has %zu "
                            "lights)", r->path, i, n->light < 0 ? "not a light index" : "no such light", r->g->nlights);
    const bn__gltf_light *g = &r->g->lights[n->light];
    if ((bad = bn__light_bad(g)))
        return bn_error_set(r->err, BN_EINPUT, "%s: /extensions/KHR_lights_punctual/lights/%d: %s", r->path, n->light, bad);
    l.type = g->type[0] == 'p' ? BN_LIGHT_POINT : g->type[0] == 's' ? BN_LIGHT_SPOT : BN_LIGHT_DIRECTIONAL;
    for (int a = 0; a < 3; a++) {
        l.pos[a] = W[12 + a];
        l.dir[a] = -W[8 + a];
        l.I[a] = (g->ncolor ? g->color[a] : 1.0) * g->intensity;
    }
    if (l.type != BN_LIGHT_POINT && !(bn_v3_normalize(l.dir) > 0))
        return bn_error_set(r->err, BN_EINPUT, "%s: /nodes/%zu: light %d's node has no direction (a singular transform)",
                            r->path, i, n->light);
    l.cos_inner = cos(g->inner), l.cos_outer = cos(g->outer);
    snprintf(l.name, sizeof l.name, "%s", g->name && g->name[0] ? g->name : n->name && n->name[0] ? n->name : "light");
    r->ranged += g->range > 0;
    r->light[i] = (int)r->s->nlights;
    if (!bn__soup_add_light(r->s, &l))
        return bn_error_set(r->err, BN_ENOMEM, "out of memory");
    return BN_OK;
}

typedef struct bn__gltf_frame {
    size_t node;
    double W[16];   /* the parent's world transform */
} bn__gltf_frame;

/* The tree under the roots[0 .. nroots) (JSON pointer `where`), depth first with a stack of its own (a
 * chain of nodes as deep as the file is long must not overflow ours); a node reached twice is an error
 * (glTF gives every node one parent: a cycle or a shared child). */
static bn_status bn__walk(bn__gr *r, const int *roots, size_t nroots, const char *where)
{
    const bn__gltf *g = r->g;
    bn__gltf_frame *stack = bn__malloc_array(g->nnodes + 1, sizeof *stack);
    size_t top = 0;
    bn_status st = BN_OK;
    static const double I[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    if (!stack)
        return bn_error_set(r->err, BN_ENOMEM, "out of memory");
    for (size_t k = nroots; st == BN_OK && k-- > 0;) {
        size_t i = (size_t)roots[k];
        if (roots[k] < 0 || i >= g->nnodes)
            st = bn_error_set(r->err, BN_EINPUT, "%s: %s/%zu: node %d does not exist (the file has %zu)", r->path, where, k,
                              roots[k], g->nnodes);
        else if (r->seen[i] || top == g->nnodes)
            st = bn_error_set(r->err, BN_EINPUT, "%s: %s/%zu: node %zu is reached twice", r->path, where, k, i);
        else {
            r->seen[i] = 1;
            stack[top].node = i;
            memcpy(stack[top++].W, I, sizeof I);
        }
    }
    while (st == BN_OK && top > 0) {
        bn__gltf_frame f = stack[--top];
        const bn__gltf_node *n = &g->nodes[f.node];
        double L[16], W[16];
        if ((st = bn__local(r, f.node, L)) != BN_OK)
            break;
        bn__mat4_mul(f.W, L, W);
        memcpy(r->world + 16 * f.node, W, sizeof W);
        bn__node_camera(r, f.node, W);
        if ((st = bn__node_mesh(r, f.node, W)) != BN_OK || (st = bn__node_light(r, f.node, W)) != BN_OK)
            break;
        for (size_t c = n->n; st == BN_OK && c-- > 0;) {
            int ch = n->first + c < g->nchildren ? g->children[n->first + c] : -1;
            if (ch < 0 || (size_t)ch >= g->nnodes)
                st = bn_error_set(r->err, BN_EINPUT, "%s: /nodes/%zu/children/%zu: node %d does not exist (the file has "
                                  "%zu)", r->path, f.node, c, ch, g->nnodes);
            else if (r->seen[ch])
                st = bn_error_set(r->err, BN_EINPUT, "%s: /nodes/%zu/children/%zu: node %d is reached twice (a cycle, or "
                                  "a node with two parents)", r->path, f.node, c, ch);
            else {
                r->seen[ch] = 1;
                stack[top].node = (size_t)ch;
                memcpy(stack[top++].W, W, sizeof W);
            }
        }
    }
    free(stack);
    return st;
}

/* Required extensions bounce does not read, punctual lights, and the scene to load: refused or chosen. */
static bn_status bn__check_file(bn__gr *r, const int **roots, size_t *nroots, char *where, size_t wsize)
{
    static const char *known[] = {"KHR_materials_emissive_strength", "KHR_materials_unlit", "KHR_mesh_quantization",
                                  "KHR_texture_transform", "KHR_materials_pbrSpecularGlossiness", "KHR_lights_punctual"};
    const bn__gltf *g = r->g;
    for (size_t i = 0; i < g->nrequired; i++) {
        int ok = 0;
        for (size_t k = 0; k < sizeof known / sizeof *known; k++)
            ok |= strcmp(g->required[i], known[k]) == 0;
        if (!ok)
            return bn_error_set(r->err, BN_EINPUT, "%s: /extensionsRequired/%zu: the file requires '%s', which bounce "
                                "does not read (it reads KHR_materials_emissive_strength, KHR_materials_unlit, "
                                "KHR_mesh_quantization, KHR_texture_transform, KHR_materials_pbrSpecularGlossiness and KHR_lights_punctual)",
                                r->path, i, g->required[i]);
    }
    if (g->default_scene >= 0 && (size_t)g->default_scene >= g->nscenes)
        return bn_error_set(r->err, BN_EINPUT, "%s: /scene: %d does not exist (the file has %zu scenes)", r->path,
                            g->default_scene, g->nscenes);
    if (g->nscenes > 0) {
        size_t s = g->default_scene >= 0 ? (size_t)g->default_scene : 0;
        if (g->scenes[s].first > g->nroots || g->scenes[s].n > g->nroots - g->scenes[s].first)
            return bn_error_set(r->err, BN_EINPUT, "%s: /scenes/%zu/nodes: malformed", r->path, s);
        *roots = g->scenes[s].n ? g->roots + g->scenes[s].first : NULL;   /* no arithmetic on an empty array */
        *nroots = g->scenes[s].n;
        snprintf(where, wsize, "/scenes/%zu/nodes", s);
    }
    return BN_OK;
}

/* Without scenes: every node that is no node's child is a root (said in a note). */
static int *bn__orphans(bn__gr *r, size_t *n)
{
    const bn__gltf *g = r->g;
    int *roots = bn__malloc_array(g->nnodes + 1, sizeof *roots);
    unsigned char *child = bn__calloc(g->nnodes + 1, 1);
    *n = 0;
    if (roots && child) {
        for (size_t k = 0; k < g->nchildren; k++)
            if (g->children[k] >= 0 && (size_t)g->children[k] < g->nnodes)
                child[g->children[k]] = 1;
        for (size_t i = 0; i < g->nnodes; i++)
            if (!child[i])
                roots[(*n)++] = (int)i;
        bn_logf(r->log, BN_LOG_INFO, "%s: no scenes: the %zu nodes that are no node's child are the scene", r->path, *n);
    }
    free(child);
    if (!child) {
        free(roots);
        return NULL;
    }
    return roots;
}

static bn_status bn__read(bn__gr *r)
{
    const int *roots = NULL;
    int *orphans = NULL;
    size_t nroots = 0;
    char where[48] = "the root nodes";
    bn_status st = bn__check_file(r, &roots, &nroots, where, sizeof where);
    if (st == BN_OK && r->g->warnings[0])
        bn_logf(r->log, BN_LOG_INFO, "%s: tinygltf: %s", r->path, r->g->warnings);
    if (st == BN_OK && (!(r->seen = bn__calloc(r->g->nnodes + 1, 1)) ||
                        !(r->world = bn__malloc_array(r->g->nnodes + 1, 16 * sizeof(double))) ||
                        !(r->objname = bn__calloc(r->g->nnodes + 1, sizeof(char *))) ||
                        !(r->light = bn__malloc_array(r->g->nnodes + 1, sizeof(int)))))
        st = bn_error_set(r->err, BN_ENOMEM, "out of memory");
    for (size_t i = 0; st == BN_OK && i < r->g->nnodes; i++)
        r->light[i] = -1;
    if (st == BN_OK)
        st = bn__materials(r);
    if (st == BN_OK && r->g->nscenes == 0 && !(roots = orphans = bn__orphans(r, &nroots)))
        st = bn_error_set(r->err, BN_ENOMEM, "out of memory");
    if (st == BN_OK)
        st = bn__walk(r, roots, nroots, where);
    if (st == BN_OK) {   /* the tree, for a bake written back under the same nodes */
        bn__tree_capture c = {r->seen, r->world, r->objname, r->light, roots, nroots};
        if (bn__gltf_tree(r->g, &c, &r->s->tree) != BN_OK)
            st = bn_error_set(r->err, BN_ENOMEM, "out of memory");
    }
    free(orphans);
    if (st == BN_OK && r->triangles == 0)
        return bn_error_set(r->err, BN_EINPUT, "%s: %s: no triangles under these nodes (%zu primitives of points or "
                            "lines, which have no area)", r->path, where, r->skipped);
    if (st == BN_OK && r->skipped)
        bn_logf(r->log, BN_LOG_INFO, "%s: %zu primitives of points or lines skipped (no area)", r->path, r->skipped);
    if (st == BN_OK && r->s->nlights)
        bn_logf(r->log, BN_LOG_INFO, "%s: %zu punctual lights (KHR_lights_punctual): colour x intensity read as W sr^-1 "
                "(point, spot; glTF's candela) or W m^-2 (directional; lux); not seen, their direct light counted in "
                "bounce 1%s", r->path, r->s->nlights, r->ranged ? "; range not applied (light falls off as 1/d^2)" : "");
    if (st == BN_OK && r->skinned)
        bn_logf(r->log, BN_LOG_INFO, "%s: %zu skinned meshes read in their bind pose (skins and morph targets are not "
                "applied)", r->path, r->skinned);
    return st;
}

bn_status bn__read_gltf(const char *path, bn__soup *out, const bn_log *log, bn_error *err)
{
    bn__gltf *g = NULL;
    bn_error local;
    bn__gr r;
    bn_status st = bn__gltf_parse(path, &g, err);
    if (st != BN_OK)
        return st;
    memset(&r, 0, sizeof r);
    r.path = path;
    r.g = g;
    r.s = out;
    r.log = log;
    r.err = err ? err : &local;
    r.default_mat = UINT32_MAX;
    st = bn__read(&r);
    free(r.mat_of);
    free(r.mat_uv);
    free(r.tex_of);
    free(r.seen);
    free(r.world);
    for (size_t i = 0; r.objname && i < g->nnodes; i++)
        free(r.objname[i]);
    free(r.objname);
    free(r.light);
    bn__gltf_free(g);
    return st;
}
