/* bounce: scenes (geometry and Lambertian materials), validation and patch meshing. */
#ifndef BOUNCE_SCENE_H
#define BOUNCE_SCENE_H

#include <stddef.h>
#include "bounce/status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct bn_scene bn_scene;   /* opaque */

/* Length unit of the scene file; areas and powers are reported in SI from it. */
typedef enum bn_unit { BN_UNIT_M, BN_UNIT_CM, BN_UNIT_MM } bn_unit;
const char *bn_unit_name(bn_unit v);
const char *bn_unit_names(void);   /* "m|cm|mm" */
int bn_unit_parse(const char *s, bn_unit *out);   /* 0, or -1 for no such name */
double bn_unit_to_metres(bn_unit u);   /* 1, 0.01, 0.001 */

#define BN_NAME_MAX 64
/* A Lambertian material. rho: diffuse reflectance per channel in [0, 1] (OBJ Kd);
 * Le: emitted radiance per channel, W m^-2 sr^-1, >= 0 (OBJ Ke). */
typedef struct bn_material {
    char   name[BN_NAME_MAX];
    double rho[3];
    double Le[3];
} bn_material;

/* A surface polygon after validation: planar, non-degenerate, convex quads or triangles
 * kept as they are, everything else triangulated. Front side = right-hand rule of the
 * vertex order; surfaces are one-sided (the back neither emits nor reflects). */
typedef struct bn_face {
    size_t   first;       /* index of its first entry in bn_scene_face_indices() */
    unsigned nverts;      /* 3 or 4 */
    unsigned material;    /* index into bn_scene_materials() */
    double   normal[3];   /* unit, front side */
    double   area;        /* scene units squared */
    size_t   source;      /* index of the input polygon it came from (0-based) */
    unsigned object;      /* index of its object (bn_scene_object_name) */
    unsigned char back;   /* 1: the back side of a two-sided face, the face before it wound the other way */
    signed char vn;       /* its polygon's winding against its vertex normals (OBJ vn): 1 agreed, -1 did not
                             (turned to agree unless bn_load_opts.orient keeps the winding), 0 no normals */
    unsigned line;        /* line of that polygon in the file, 0 if not known */
} bn_face;

/* A patch: a planar triangle or quad inside one face. Corners index the patch-vertex array
 * (bn_scene_patch_vertices); neighbours inside one face share corners (no T-junctions). */
typedef struct bn_patch {
    size_t   face;        /* index into bn_scene_faces() */
    unsigned material;
    unsigned ncorners;    /* 3 or 4, counter-clockwise seen from the front */
    size_t   corner[4];
    double   area;        /* scene units squared */
    double   normal[3];   /* unit; equal to the face's */
    double   centroid[3]; /* area centroid */
} bn_patch;

/* Which side of a face is its front: the winding (right-hand rule), or, where the file gives
 * vertex normals (OBJ vn), the side they point to: a polygon wound against the sum of its corners'
 * normals is reversed (the default; real assets keep their intended orientation in their normals,
 * which every rasteriser shades with, while their winding goes unseen in two-sided viewers). */
typedef enum bn_orient { BN_ORIENT_NORMALS, BN_ORIENT_WINDING } bn_orient;
typedef struct bn_load_opts {
    bn_unit unit;            /* length unit of the file (default metres) */
    bn_orient orient;        /* default BN_ORIENT_NORMALS */
    /* Materials whose faces reflect and emit on both sides, each side a surface of its own with its
     * own radiance: "all", or material names separated by commas, besides those the file marks (glTF
     * doubleSided); NULL or "": the file's marks only; "none": every surface one-sided; "none,NAMES":
     * these materials only, the file's marks dropped. */
    const char *two_sided;
    double  planar_tol;      /* non-planarity allowed, relative to the face's diameter (default 1e-6) */
    bn_log  log;             /* warnings: dropped faces, triangulated faces, no emitter */
    const struct bn_material_edit *edits;   /* applied after reading, in order (bn_scene_edit_materials; */
    size_t  nedits;                         /* borrowed: --set-rho, --set-Le) */
} bn_load_opts;
void bn_load_opts_default(bn_load_opts *o);

/* Loads OBJ (+MTL), PLY or OFF by extension, validates, and builds faces (no patches yet:
 * call bn_scene_mesh). On failure *out is NULL and err names the file, line and value. */
bn_status bn_scene_load(const char *path, const bn_load_opts *o, bn_scene **out, bn_error *err);

/* Builds a scene from arrays (tests, generators). verts: nverts*3 doubles; polys: for each
 * polygon its vertex count followed by that many 0-based indices; poly_material: one
 * material index per polygon. Same validation as bn_scene_load; `name` is used in messages. */
bn_status bn_scene_from_arrays(const char *name, const double *verts, size_t nverts,
                               const unsigned *polys, size_t npolys,
                               const unsigned *poly_material,
                               const bn_material *materials, size_t nmaterials,
                               const bn_load_opts *o, bn_scene **out, bn_error *err);

void bn_scene_destroy(bn_scene *s);   /* NULL is a no-op */

/* Patch meshing. patch_size > 0: largest patch edge in scene units; else target_patches > 0:
 * the patch size is chosen so the faces it splits hold close to that many patches (faces smaller
 * than the size stay whole, besides: many small faces do not coarsen the large ones);
 * no_subdivide: one patch per face.
 * Planar quads become regular grids, triangles uniform subdivisions. Replaces earlier patches. */
typedef struct bn_mesh_opts {
    double patch_size;
    size_t target_patches;
    int    no_subdivide;
    /* Patches are split along contact lines (where another face touches or pierces a face's
     * front: a block standing on the floor), so no patch straddles lit and hidden parts. 1 turns
     * that off; no_subdivide implies it. A cut piece's edge can be its grid patch's diagonal, and
     * corners near a contact move onto it (no thin strips; a patch grows by at most a third), so
     * patch edges there may reach BN_CONTACT_STRETCH times the grid's longest edge. */
    int    no_contacts;
    /* Contacts are cut where one object touches another (bn_scene_object_name: the floor under a
     * chair's legs); 1 also cuts where an object touches itself (a model's own touching or
     * interpenetrating parts: most of a furniture model's contacts, hidden inside it). A scene of
     * one object has all its contacts cut. */
    int    self_contacts;
    /* Distance from a face's plane that still counts as touching it, scene units (0: 1e-6 of the
     * scene's diameter). A scanned model that rests on a floor with its base a millimetre above
     * it (the bunny box) needs about that much. */
    double contact_gap;
} bn_mesh_opts;
void bn_mesh_opts_default(bn_mesh_opts *o);   /* target_patches = BN_DEFAULT_PATCHES */
#define BN_DEFAULT_PATCHES 1200
#define BN_CONTACT_STRETCH 2.0
bn_status bn_scene_mesh(bn_scene *s, const bn_mesh_opts *o, bn_error *err);
/* The patch count bn_scene_mesh would make before contact cuts (which only add), from the faces'
 * sizes alone, without meshing: for refusing a too-large mesh before any work. */
bn_status bn_scene_mesh_estimate(const bn_scene *s, const bn_mesh_opts *o, double *patches, bn_error *err);

/* ---- material edits: a named material's reflectance or emitted radiance replaced (`--set-rho`,
 * `--set-Le`, relighting). The geometry and the patches stay: F does not change, only K = diag(rho) F
 * and E (bn_pipeline_relight). For a textured material rho is the factor its texture multiplies (glTF
 * baseColorFactor, MTL Kd under map_Kd) and Le the factor of its emission texture. */
typedef struct bn_material_edit {
    char   material[BN_NAME_MAX];   /* the material's name, as the file gives it */
    int    has_rho, has_Le;         /* which of the two this edit sets */
    double rho[3];                  /* in [0, 1] */
    double Le[3];                   /* finite, >= 0, W m^-2 sr^-1 */
} bn_material_edit;
/* Parses "NAME=R,G,B" or "NAME=V" (grey) into a zeroed e, setting rho (what "rho") or Le (what
 * "Le"); BN_EUSAGE naming the text and the value out of range. */
bn_status bn_material_edit_parse(const char *what, const char *text, bn_material_edit *e, bn_error *err);
/* Applies n edits in order: all or none (checked first: a name that is not a material of s is
 * BN_EUSAGE naming it and the scene's materials; values out of range too). A meshed scene's
 * textured reflectance per patch follows. */
bn_status bn_scene_edit_materials(bn_scene *s, const bn_material_edit *e, size_t n, bn_error *err);

/* Accessors. Returned arrays are borrowed: valid while the scene lives and is not re-meshed. */
const char        *bn_scene_path(const bn_scene *s);
bn_unit            bn_scene_unit(const bn_scene *s);
const bn_material *bn_scene_materials(const bn_scene *s, size_t *count);
const double      *bn_scene_vertices(const bn_scene *s, size_t *count);      /* xyz per vertex */
const size_t      *bn_scene_face_indices(const bn_scene *s, size_t *count);
const bn_face     *bn_scene_faces(const bn_scene *s, size_t *count);
const bn_patch    *bn_scene_patches(const bn_scene *s, size_t *count);
/* x on patch `patch` moved BN_SCENE_POINT_INSET of the way to the patch's centroid, into out (out may be
 * x): a point off the patch's edges, where `bounce trace --points` estimates and a bake gathers its
 * vertices (so the two are asked the same point; rays from a point exactly on an edge would leave along
 * the neighbouring surface's plane). */
#define BN_SCENE_POINT_INSET 0.01
void bn_scene_point_inset(const bn_scene *s, size_t patch, const double x[3], double out[3]);
const double      *bn_scene_patch_vertices(const bn_scene *s, size_t *count); /* xyz */
/* The size the mesher was given or chose (0 with no_subdivide): an upper bound of the patch edges
 * along each face's grid, not the patches' actual size, which is: */
double             bn_scene_patch_size(const bn_scene *s);
double             bn_scene_largest_patch_edge(const bn_scene *s);   /* longest edge of any patch */
/* Polygons read, and those dropped as degenerate or duplicate, and triangulated as non-planar. */
typedef struct bn_scene_stats {
    size_t input_polygons, degenerate_dropped, duplicates_dropped, nonplanar_split,
           polygons_triangulated, back_to_back;
    /* polygons with vertex normals, those wound against them (the worst's line: the most opposed),
     * and those reversed to agree (bn_load_opts.orient) */
    size_t with_normals, winding_disagree, flipped;
    unsigned winding_worst_line;
    /* from the last bn_scene_mesh: contact segments found, faces they cut, patches split and the
     * patches those became */
    size_t contact_segments, contact_faces, contact_patches_split, contact_patches_made;
} bn_scene_stats;
bn_scene_stats     bn_scene_stats_get(const bn_scene *s);
/* The camera the scene file holds (glTF: the first perspective camera among the default scene's nodes,
 * placed by its node's world transform): 1 and its eye, a point it looks at, its up direction, vertical
 * field of view (degrees) and aspect ratio (width / height, 0 when the file gives none), and its name;
 * 0 when the file has none. */
int bn_scene_camera(const bn_scene *s, double eye[3], double look[3], double up[3], double *fov_deg, double *aspect,
                    const char **name);
/* The node tree of the scene file (glTF: the default scene's nodes, in the file's order), kept so a bake
 * can be written back under it. Each node: its name and its mesh's ("" when the file gives none), the
 * scene object its mesh's faces became (bn_scene_object_name; NULL: no mesh, or no triangles), its local
 * transform as the file gives it (nmatrix 16 values, or nt, nr, ns of translation, rotation, scale: 0 when
 * absent), its world transform (column-major, in the file's units), its perspective camera if it has one
 * (camera 1: vertical field of view in radians, aspect 0 when none, znear, zfar 0 when infinite), and its
 * children (indices into the tree). */
typedef struct bn_scene_node {
    const char *name, *mesh_name, *object, *camera_name;
    unsigned nmatrix, nt, nr, ns;
    double matrix[16], t[3], r[4], s[3], world[16];
    int camera;
    double yfov, aspect, znear, zfar;
    int light;                                 /* its punctual light (bn_scene_lights), -1 none */
    size_t nchildren;
    const size_t *children;
} bn_scene_node;
/* The tree's nodes and roots; NULL and 0 for a file without one (OBJ, PLY, OFF). */
const bn_scene_node *bn_scene_nodes(const bn_scene *s, size_t *n, const size_t **roots, size_t *nroots);
/* Punctual lights (glTF KHR_lights_punctual): light from a point (point, spot) or from a direction
 * (directional), not from a surface. A punctual light is not seen: E holds none of it, and the light it
 * sends straight to a surface is part of bounce 1 (K E). glTF's photometric numbers are read as
 * radiometric ones, as its emissive values are: colour x intensity is the radiant intensity in W sr^-1
 * (glTF's candela) of a point or spot light, and the irradiance in W m^-2 (glTF's lux) that a
 * directional light gives a surface facing it. A spot's intensity falls off between its inner and
 * outer cones as glTF's reference implementation does: t^2, t = (cos a - cos outer) / (cos inner -
 * cos outer) clamped to [0, 1]. `range` is not applied (the light falls off as 1 / d^2 to any
 * distance). */
typedef enum bn_light_type { BN_LIGHT_POINT, BN_LIGHT_SPOT, BN_LIGHT_DIRECTIONAL } bn_light_type;
typedef struct bn_light {
    char name[BN_NAME_MAX];
    bn_light_type type;
    double pos[3];                  /* scene units (point, spot) */
    double dir[3];                  /* unit: the direction it shines (spot's axis, directional) */
    double I[3];                    /* W sr^-1 (point, spot); W m^-2 (directional) */
    double cos_inner, cos_outer;    /* spot */
} bn_light;
const bn_light *bn_scene_lights(const bn_scene *s, size_t *n);
/* The irradiance (W m^-2, per channel) that light l gives a surface at x (scene units, m metres each)
 * with unit normal n, unoccluded (0 from behind the surface or outside a spot's cone); wi: the unit
 * direction from x to the light; *dist: the distance to it in scene units (INFINITY: directional).
 * Returns 1 when some channel is > 0. */
int bn_light_irradiance(const bn_light *l, double m, const double x[3], const double n[3], double E[3], double wi[3],
                        double *dist);
/* The power light l emits (W per channel): 4 pi I for a point light, the integral of its profile over
 * the sphere for a spot; 0 for a directional light (unbounded). */
void bn_light_power(const bn_light *l, double watts[3]);

/* Axis-aligned bounding box of the faces, scene units. */
void               bn_scene_bounds(const bn_scene *s, double lo[3], double hi[3]);
/* The scene's diameter: the length of that box's diagonal, scene units (what tolerances scale with). */
double             bn_scene_diameter(const bn_scene *s);
/* A digest of geometry, materials and patches (FNV-1a 64), for cache keys. */
unsigned long long bn_scene_digest(const bn_scene *s);
/* The same over the geometry alone (unit, vertices, polygons, patches), not the materials: what
 * form factors depend on, so the form-factor cache is hit by a relit or recoloured scene. */
unsigned long long bn_scene_geometry_digest(const bn_scene *s);

/* Per-patch material helpers (borrowed scene). */
const bn_material *bn_patch_material(const bn_scene *s, size_t patch);
/* Emitted power of the scene, watts per channel: pi * sum_i A_i Le_i with A in m^2. */
void bn_scene_emitted_power(const bn_scene *s, double watts[3]);
/* Power leaving the patches with radiance `radiance` (patches x 3, W m^-2 sr^-1), watts per
 * channel: pi * sum_i A_i x_i with A in m^2 (a term K^k E gives that bounce's power). */
void bn_scene_power(const bn_scene *s, const double *radiance, double watts[3]);
size_t bn_scene_emitter_count(const bn_scene *s);   /* faces with Le > 0 in any channel */
/* Objects group faces for counts, contact cuts and partitions: the file's own groups when it names
 * two or more (OBJ `o`/`g`), else the material names' prefixes up to the first '_' (`couch_Chrome`
 * and `couch_Fabric`: "couch"). */
/* 1 if material m's faces reflect and emit on both sides (bn_load_opts.two_sided). */
int         bn_scene_material_two_sided(const bn_scene *s, size_t m);
size_t      bn_scene_object_count(const bn_scene *s);
const char *bn_scene_object_name(const bn_scene *s, size_t k);
int         bn_scene_objects_from_file(const bn_scene *s);   /* 1: the file's groups; 0: material prefixes */
/* 1: object k is one model's parts (a file's group, or a prefix before a '_'), whose own contacts
 * are not cut unless asked (bn_mesh_opts.self_contacts); 0: a material named without a prefix. */
int         bn_scene_object_is_assembly(const bn_scene *s, size_t k);

/* Per-patch emission E (= Le, W m^-2 sr^-1) and reflectance rho, written into caller-allocated
 * arrays of N*3 doubles (patch-major, channel-minor: a[3*i + c]). A textured material's patches get
 * its factor times the texture's mean over the patch. */
void bn_scene_patch_emission(const bn_scene *s, double *E);
/* Face f's emitted radiance: its material's Le, times the mean of its emission texture (glTF
 * emissiveTexture) over the face when it has one. Uniform over each face. */
void bn_scene_face_emission(const bn_scene *s, size_t f, double Le[3]);
void bn_scene_patch_reflectance(const bn_scene *s, double *rho);
/* Per patch, what its material's rho and Le are multiplied by: the mean of the material's reflectance
 * and emission textures over the patch (over its face for emission), 1 where untextured; N*3 each, either
 * may be NULL. rho_i = rho_material x rho_f[i] and E_i = Le_material x Le_f[i] (a relit page's sliders). */
void bn_scene_patch_texture_factors(const bn_scene *s, double *rho_f, double *Le_f);
/* The reflectance at point x of face `face` (on its plane): the material's, times its texture there
 * (glTF baseColorTexture, MTL map_Kd) when it has one; what the final gather's pixels use. */
void bn_scene_reflectance_at(const bn_scene *s, size_t face, const double x[3], double rho[3]);
int  bn_scene_textured(const bn_scene *s);   /* 1: some material has a reflectance texture */
/* 1 if material m has a reflectance texture: its name (the file's, borrowed), size in texels and mean
 * value (linear, before the material's factor). */
int  bn_scene_material_texture(const bn_scene *s, size_t m, const char **name, int *w, int *h, double mean[3]);

#ifdef __cplusplus
}
#endif
#endif
