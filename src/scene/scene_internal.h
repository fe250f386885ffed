/* The scene's internal layout, shared by the readers, the mesher and the library's modules. */
#ifndef BOUNCE_SCENE_INTERNAL_H
#define BOUNCE_SCENE_INTERNAL_H

#include "bounce/scene.h"
#include "base/internal.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A texture: linear values, row 0 at v = 0 (glTF's convention; OBJ's vt is turned to it on reading),
 * sampled with wrap modes per axis (BN__WRAP_*) and bilinearly or at the nearest texel. */
enum { BN__WRAP_REPEAT, BN__WRAP_CLAMP, BN__WRAP_MIRROR };
typedef struct bn__texture {
    int w, h;
    float *rgb;            /* w * h * 3 linear values, owned; or, for an 8-bit image (a quarter of the memory): */
    unsigned char *rgb8;   /* w * h * 3 bytes as stored, owned, their linear values lut[byte] */
    float lut[256];
    int wrap[2], nearest;
    char name[BN_NAME_MAX];
} bn__texture;
/* Texel component k (3 per texel) of t, linear. */
static inline double bn__texel(const bn__texture *t, size_t k) { return t->rgb8 ? t->lut[t->rgb8[k]] : t->rgb[k]; }
void bn__texture_free(bn__texture *t, size_t n);   /* the texels of t[0 .. n), and t */
/* An image file (mem NULL), or encoded bytes mem[0 .. size) whose format `name`'s extension says, as a
 * reflectance texture (repeat, bilinear): 8- and 16-bit images are sRGB (decoded to linear, as glTF and
 * MTL maps are), float images linear; every value must lie in [0, 1]. Through OpenImageIO's module. */
bn_status bn__texture_decode(const char *name, const void *mem, size_t size, bn__texture *t, bn_error *err);
/* The mean of texture t's texels (linear). */
void bn__texture_mean(const bn__texture *t, double mean[3]);
/* Texture t at (u, v): rgb (linear). */
void bn__texture_sample(const bn__texture *t, double u, double v, double rgb[3]);

/* A camera the scene file holds (glTF: the first perspective camera of the default scene's nodes). */
typedef struct bn__file_camera {
    int has;
    double eye[3], look[3], up[3], yfov_deg, aspect;   /* aspect 0: not given */
    char name[BN_NAME_MAX];
} bn__file_camera;

/* The scene file's node tree (bn_scene_nodes): the nodes with their strings and children owned. */
typedef struct bn__file_tree {
    bn_scene_node *nodes;
    size_t nnodes;
    size_t *children;   /* every node's, node after node */
    size_t *roots;
    size_t nroots;
} bn__file_tree;
void bn__file_tree_free(bn__file_tree *t);   /* NULL is fine */

/* A polygon soup as a reader produces it, before validation. */
typedef struct bn__soup {
    double   *verts;      /* xyz */
    size_t    nverts, verts_cap;
    unsigned *counts;     /* vertices per polygon */
    unsigned *mat;        /* material per polygon */
    unsigned *line;       /* source line per polygon (0 if none) */
    size_t    npolys, polys_cap;
    size_t   *idx;        /* 0-based vertex indices, polygon after polygon */
    size_t    nidx, idx_cap;
    bn_material *mats;
    size_t    nmats, mats_cap;
    /* objects as the file names them (OBJ `o`/`g`): per polygon, and their names; none read: obj NULL */
    unsigned *obj;
    unsigned  cur_obj;    /* the object bn__soup_add_polygon gives a polygon */
    char    (*objnames)[BN_NAME_MAX];
    size_t    nobjs, objs_cap;
    /* vertex normals (OBJ vn) and, per polygon, the sum of its corners' normals (pn; NULL while no
     * polygon has any; a zero sum: none), the polygon's intended front */
    double   *vn;
    size_t    nvn, vn_cap;
    double   *pn;
    double    cur_pn[3];   /* what bn__soup_add_polygon gives the next polygon */
    /* per material, 1: two-sided as the file says (glTF doubleSided); NULL while none is */
    unsigned char *mat_two;
    size_t    mat_two_cap;
    /* texture coordinates per polygon corner (2 per idx entry, NaN: none; NULL while no polygon has
     * any), decoded textures, and per material its reflectance texture (-1: none; NULL: none has) */
    double   *cuv;
    size_t    cuv_cap;
    bn__texture *tex;
    size_t    ntex, tex_cap;
    int      *mat_tex;
    size_t    mat_tex_cap;
    int      *mat_etex;     /* per material its emission texture (-1: none; NULL: none has) */
    size_t    mat_etex_cap;
    bn__file_camera cam;   /* the file's camera (glTF), if any */
    bn__file_tree *tree;   /* the file's node tree (glTF), if any: the scene takes it */
    bn_light *lights;      /* punctual lights (glTF), world space */
    size_t    nlights, lights_cap;
} bn__soup;

void bn__soup_free(bn__soup *s);
int bn__soup_add_vertex(bn__soup *s, const double p[3]);                 /* 0 on OOM */
int bn__soup_add_polygon(bn__soup *s, const size_t *idx, unsigned n, unsigned mat, unsigned line);
int bn__soup_add_material(bn__soup *s, const bn_material *m);
int bn__soup_add_normal(bn__soup *s, const double n[3]);                  /* a vn; 0 on OOM */
int bn__soup_set_two_sided(bn__soup *s, unsigned mat);                    /* the file says so; 0 on OOM */
/* The texture coordinates of the last polygon's corners (uv: 2 per corner; called right after
 * bn__soup_add_polygon); 0 on OOM. */
int bn__soup_set_corner_uv(bn__soup *s, const double *uv, unsigned n);
/* Texture t added (taken: its texels become the soup's): its index, or -1 on OOM. */
int bn__soup_add_texture(bn__soup *s, bn__texture *t);
/* Texture tex (an index from bn__soup_add_texture) as material mat's reflectance texture; 0 on OOM. */
int bn__soup_set_material_texture(bn__soup *s, unsigned mat, int tex);
/* A punctual light, copied; 0 on OOM. */
int bn__soup_add_light(bn__soup *s, const bn_light *l);
/* Material mat's emission texture (glTF emissiveTexture): soup texture tex. 0 on OOM. */
int bn__soup_set_material_emissive(bn__soup *s, unsigned mat, int tex);
/* Name key's index in (*names)[0 .. *n) (capacity *cap), appended when new; SIZE_MAX on OOM. */
size_t bn__name_index(char (**names)[BN_NAME_MAX], size_t *n, size_t *cap, const char *key);
/* The object the next polygons belong to, by name (a new one, or the one of that name); 0 on OOM. */
int bn__soup_use_object(bn__soup *s, const char *name);
/* One material per distinct key among keys[6 p .. 6 p + 6) (reflectance RGB, emission RGB) of
 * polygon p, named prefix0, prefix1, ... in order of first use; sets every polygon's material.
 * 0 on OOM. */
int bn__soup_materials_from_keys(bn__soup *s, const double *keys, const char *prefix);

/* Readers. `path` is used in messages. */
bn_status bn__read_obj(const char *path, bn__soup *out, const bn_log *log, bn_error *err);
/* The same from an open stream (fuzzing reads from memory); mtllib names resolve beside `path`. */
bn_status bn__read_obj_stream(FILE *fp, const char *path, bn__soup *out, const bn_log *log, bn_error *err);
/* PLY: our own reader (src/scene/ply.c), the file read once. */
bn_status bn__read_ply(const char *path, bn__soup *out, const bn_log *log, bn_error *err);
/* OFF: ASCII by our own reader (src/scene/off.c); binary OFF through OpenMesh (src/adapters,
 * bn__read_off_binary into a sink over the soup), which reads it from its path after a check of
 * the header's counts against the file's size. */
bn_status bn__read_off(const char *path, bn__soup *out, const bn_log *log, bn_error *err);
/* glTF 2.0 (.gltf, .glb; src/scene/gltf.c over tinygltf's parse in src/adapters): the default scene's
 * triangles in world space, materials from the PBR base colour and emission, doubleSided as two-sided. */
bn_status bn__read_gltf(const char *path, bn__soup *out, const bn_log *log, bn_error *err);

/* Grows *p (capacity *cap elements of elem bytes) to hold need; 0 when out of memory (soup.c). */
int bn__grow(void **p, size_t *cap, size_t need, size_t elem);

/* Validates a soup and builds faces; copies all but the textures, which it takes. */
bn_status bn__scene_build(const char *path, bn__soup *soup, const bn_load_opts *o,
                          bn_scene **out, bn_error *err);

/* The back sides of the faces of two-sided materials (the file's own flags file_two[0 .. nfile_two), or
 * NULL, and spec: bn_load_opts.two_sided), appended (src/scene/twosided.c). */
bn_status bn__scene_two_sided(bn_scene *sc, const char *path, const unsigned char *file_two, size_t nfile_two,
                              const char *spec, bn_error *err);
/* Textures (src/scene/texture.c): the soup's textures moved into the scene with each face corner's
 * texture coordinates (looked up by vertex in the polygon it came from), after its faces are built. */
bn_status bn__scene_textures(bn_scene *sc, bn__soup *s);
/* Each textured patch's texture mean (its reflectance is the material's factor times it), after
 * meshing; NULL ptex when no material has a texture. */
bn_status bn__scene_patch_textures(bn_scene *sc, bn_error *err);
/* The scene's objects and each face's (src/scene/objects.c), after its faces are built. */
bn_status bn__scene_objects(bn_scene *sc, const bn__soup *s);
/* The mesher's patch geometry (area, centroid, normal) from its corners. */
void bn__scene_patch_finish(bn_patch *p, const double *pv, const double normal[3]);
/* Splits the patches of faces that other faces touch or pierce along the contact lines
 * (src/scene/contact.c); gap: the distance that counts as touching (0: 1e-6 of the scene's
 * diameter); self: also where a face of the same object touches (bn_mesh_opts.self_contacts).
 * Patches must be in face order; *patches and *pv are replaced (grown) and stay the caller's on
 * failure. Counts go to s->stats. */
bn_status bn__mesh_contacts(bn_scene *s, double gap, int self, bn_patch **patches, size_t *np, double **pv,
                            size_t *nv, bn_error *err);

struct bn_scene {
    char        *path;
    bn_unit      unit;
    bn_material *mats;
    size_t       nmats;
    double      *verts;
    size_t       nverts;
    size_t      *fidx;      /* face vertex indices */
    size_t       nfidx;
    bn_face     *faces;
    size_t       nfaces;
    bn_patch    *patches;
    size_t       npatches;
    double      *pverts;    /* patch vertices, xyz */
    size_t       npverts;
    double       patch_size;     /* the mesher's size parameter */
    double       largest_edge;   /* longest edge of any patch */
    bn_scene_stats stats;
    double       lo[3], hi[3];
    char       (*objnames)[BN_NAME_MAX];   /* objects (src/scene/objects.c) */
    size_t       nobjs;
    unsigned char *obj_assembly;          /* per object: one model's parts (no contact cuts inside) */
    unsigned char *mat_two_sided;         /* per material, or NULL: none two-sided */
    int          objects_from_file;       /* 1: the file's groups; 0: material-name prefixes */
    bn__texture *tex;                     /* reflectance textures (src/scene/texture.c) */
    size_t       ntex;
    int         *mat_tex;                 /* per material: its texture, -1 none; NULL: no textures */
    int         *mat_etex;                /* per material: its emission texture, -1 none; NULL: none */
    double      *femit;                   /* 3 per face: its emission texture's mean over it; NULL: none */
    double      *fuv;                     /* 2 per face index entry (NaN: none); NULL: no textures */
    double      *ptex;                    /* 3 per patch: its texture's mean over it (1 untextured); NULL: none */
    bn__file_camera cam;                  /* the file's camera, if any (bn_scene_camera) */
    bn__file_tree *tree;                  /* the file's node tree, if any (bn_scene_nodes) */
    bn_light    *lights;                  /* punctual lights (bn_scene_lights) */
    size_t       nlights;
};

#ifdef __cplusplus
}
#endif
#endif
