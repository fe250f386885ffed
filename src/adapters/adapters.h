/* C declarations of the C++ adapters (OpenImageIO, OpenMesh): every entry point catches all
 * exceptions and returns a status (std::bad_alloc -> BN_ENOMEM). Not installed. */
#ifndef BOUNCE_ADAPTERS_H
#define BOUNCE_ADAPTERS_H

#include <stddef.h>
#include "bounce/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A text label drawn onto an image: left end of the baseline at (x, y), pixel size `size`. */
typedef struct bn__label {
    int x, y, size;
    const char *text;
} bn__label;

/* Writes an 8-bit RGB image (w*h*3, row 0 on top) to `path` through OpenImageIO (format from the
 * extension; the caller manages temp names), drawing `labels` in white with the TrueType font
 * `font`. *labels_ok = 0 when text could not be drawn (font missing or OIIO without FreeType);
 * the image is written anyway. attrs become metadata (PNG text chunks).
 * bn__oiio_write_rgb8 (src/image/oiio_module.c) opens the module libbounce_oiio.so on first use
 * and calls its bn__oiio_module_write_rgb8 (src/adapters/oiio_io.cpp), which has this signature. */
typedef bn_status bn__oiio_write_rgb8_fn(const char *path, int w, int h, const unsigned char *rgb,
                                         const bn__label *labels, size_t nlabels, const char *font,
                                         const bn_attr *attrs, size_t nattrs, int *labels_ok, bn_error *err);
bn_status bn__oiio_write_rgb8(const char *path, int w, int h, const unsigned char *rgb, const bn__label *labels,
                              size_t nlabels, const char *font, const bn_attr *attrs, size_t nattrs, int *labels_ok,
                              bn_error *err);

/* Reads an image as stored (RGB, row 0 on top, no colour conversion): an 8-bit image as bytes in *rgb8
 * (3 per texel; *rgb NULL), any other as floats in *rgb (16-bit values scaled to [0, 1]; *rgb8 NULL),
 * malloc'd; from `path`, or from mem[0 .. size) when mem is not NULL (`path` then names the format by its
 * extension, and the image in messages); *is_float: float or half values (linear by convention).
 * Through the OpenImageIO module as bn__oiio_write_rgb8 (bn__oiio_module_read_rgb). */
typedef bn_status bn__oiio_read_rgb_fn(const char *path, const void *mem, size_t size, int *w, int *h, float **rgb,
                                       unsigned char **rgb8, int *is_float, bn_error *err);
bn_status bn__oiio_read_rgb(const char *path, const void *mem, size_t size, int *w, int *h, float **rgb,
                            unsigned char **rgb8, int *is_float, bn_error *err);

/* Where a reader puts the mesh it reads: vertices in order, then polygons of vertex indices; each
 * returns 0 when out of memory. (The scene module passes its soup in; the adapter calls back, so
 * that src/adapters depends on nothing above it.) */
typedef struct bn__mesh_sink {
    void *user;
    int (*vertex)(void *user, const double p[3]);
    int (*polygon)(void *user, const size_t *idx, unsigned n);
} bn__mesh_sink;
/* Binary OFF through OpenMesh, after a check of the header's counts and every face's corner
 * count against the file (src/adapters/openmesh_io.cpp). Colours are not read (said once). */
bn_status bn__read_off_binary(const char *path, const bn__mesh_sink *sink, const bn_log *log, bn_error *err);

/* A baked mesh handed to OpenMesh for writing. */
typedef struct bn__bake_mesh {
    size_t nverts;
    const double *pos;          /* nverts*3 */
    size_t nfaces;
    const unsigned *face_n;     /* corners per face (3 or 4) */
    const size_t *face_idx;     /* 4 slots per face */
    const float *colour;        /* nverts*3 float radiance, or NULL */
    const unsigned char *colour8; /* nverts*3 8-bit sRGB, or NULL */
    size_t nextra;              /* extra float vertex properties */
    const char *const *extra_name;   /* nextra names */
    const float *const *extra;  /* nextra arrays of nverts floats */
    const char *provenance;     /* OM: stored as a mesh property "bounce:provenance" */
} bn__bake_mesh;
/* Writes through OpenMesh to `path` (.ply binary or .om by extension; caller manages temp names).
 * *duplicated counts vertices OpenMesh needed duplicated for non-manifold faces. */
bn_status bn__openmesh_write(const char *path, const bn__bake_mesh *m, size_t *duplicated, bn_error *err);

/* glTF 2.0 (.gltf with its buffers, or .glb) as tinygltf parsed it (src/adapters/gltf_io.cpp: parsing
 * only), mirrored in plain C for src/scene/gltf.c, which validates every index and size and walks the
 * default scene. Index fields are -1 where the file has none; n* fields count what the file gave, so a
 * wrong length (a 3-component baseColorFactor) is caught above; values past the mirror's room are
 * not copied. Strings and bytes live as long as the bn__gltf. */
typedef struct bn__gltf_buffer { const unsigned char *data; size_t size; } bn__gltf_buffer;
typedef struct bn__gltf_view { int buffer; size_t offset, length, stride; } bn__gltf_view;
typedef struct bn__gltf_accessor {
    int view, ctype, type, normalized;    /* type: 1..4 (SCALAR..VEC4), 0 any other */
    size_t offset, count;
    size_t sparse_count;                  /* 0: not sparse */
    int sparse_iview, sparse_ictype, sparse_vview;
    size_t sparse_ioffset, sparse_voffset;
} bn__gltf_accessor;
typedef struct bn__gltf_prim { int mode, material, indices, position, texcoord[2]; } bn__gltf_prim;
/* An image's encoded bytes (from its bufferView or its uri, NULL when tinygltf could not load it) and
 * its MIME type or uri for the format; a texture's image and sampler (wrap: glTF's codes; mag: 9728
 * NEAREST, else linear). */
typedef struct bn__gltf_image { const unsigned char *bytes; size_t size; const char *mime, *uri, *name; } bn__gltf_image;
typedef struct bn__gltf_texture { int source, wrap_s, wrap_t, mag; } bn__gltf_texture;
typedef struct bn__gltf_mesh { const char *name; size_t first, n; } bn__gltf_mesh;   /* prims[first..] */
typedef struct bn__gltf_material {
    const char *name, *alpha_mode;
    unsigned nbase, nemissive;
    double base[4], emissive[3], strength;    /* strength: KHR_materials_emissive_strength, else 1 */
    int base_tex, base_uv, emissive_tex, emissive_uv, emissive_transform, double_sided, unlit, has_strength;
    /* KHR_materials_pbrSpecularGlossiness (older exporters): its diffuseFactor is the diffuse colour */
    int specgloss, diffuse_tex;
    /* its reflectance texture's KHR_texture_transform: offset, rotation (radians), scale; texcoord: the
     * set it overrides with (-1: none); ntt_* count what the file gave */
    int tex_transform, tt_texcoord;
    unsigned ntt_offset, ntt_scale;
    double tt_offset[2], tt_rotation, tt_scale[2];
    unsigned ndiffuse;
    double diffuse[4];
} bn__gltf_material;
typedef struct bn__gltf_node {
    const char *name;
    int mesh, skin, camera, light;   /* light: its KHR_lights_punctual light, -1 none, -2 malformed */
    size_t first, n;                      /* children[first..] */
    unsigned nmatrix, nt, nr, ns;
    double matrix[16], t[3], r[4], s[3];
} bn__gltf_node;
typedef struct bn__gltf_scene { size_t first, n; } bn__gltf_scene;       /* roots[first..] */
/* A camera: perspective (1) or not, its vertical field of view (radians), aspect ratio (0: none) and
 * near and far planes (zfar 0: infinite). */
typedef struct bn__gltf_camera {
    const char *name;
    int perspective;
    double yfov, aspect, znear, zfar;
} bn__gltf_camera;
/* A KHR_lights_punctual light: its type as given ("point", "spot", "directional"), colour (ncolor values),
 * intensity, range (0: none) and the spot's cone angles (radians). */
typedef struct bn__gltf_light {
    const char *name, *type;
    unsigned ncolor;
    double color[3], intensity, range, inner, outer;
} bn__gltf_light;
typedef struct bn__gltf {
    size_t nbuffers, nviews, naccessors, nprims, nmeshes, nmaterials, nnodes, nscenes, nlights, ntextures;
    size_t nchildren, nroots, nrequired, nimages, ncameras;
    const bn__gltf_camera *cameras;
    const bn__gltf_light *lights;
    const bn__gltf_image *images;
    const bn__gltf_texture *textures;
    const bn__gltf_buffer *buffers;
    const bn__gltf_view *views;
    const bn__gltf_accessor *accessors;
    const bn__gltf_prim *prims;
    const bn__gltf_mesh *meshes;
    const bn__gltf_material *materials;
    const bn__gltf_node *nodes;
    const bn__gltf_scene *scenes;
    const int *children, *roots;
    const char *const *required;          /* extensionsRequired */
    int default_scene;
    const char *warnings;                 /* tinygltf's, "" for none */
    void *impl;
} bn__gltf;
/* Parses `path` (.glb by its magic, else JSON) with its external buffers and data URIs; images are kept
 * encoded (bounce decodes them through OpenImageIO). On failure *out is NULL and err names the file
 * with tinygltf's message. */
bn_status bn__gltf_parse(const char *path, bn__gltf **out, bn_error *err);
void bn__gltf_free(bn__gltf *g);   /* NULL is a no-op */

#ifdef __cplusplus
}
#endif
#endif
