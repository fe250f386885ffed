/* bounce: baking per-patch radiance to vertex colours, split at creases and material seams;
 * written as PLY and OM (through OpenMesh) or OBJ with `v x y z r g b`. */
#ifndef BOUNCE_BAKE_H
#define BOUNCE_BAKE_H

#include <stddef.h>
#include "bounce/scene.h"
#include "bounce/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct bn_bake bn_bake;   /* opaque: the output vertices and their patch groups */

#define BN_BAKE_DEFAULT_CREASE 30.0
#define BN_BAKE_GATHER_RAYS 2048   /* hemisphere rays per vertex of a gathered bake (bounce bake --gather) */
#define BN_BAKE_GATHER_LIGHT 256   /* shadow rays per emitting face per vertex: a vertex has no neighbours to
                                      average a penumbra's noise with, as a pixel has */
#define BN_BAKE_FLAT (-1.0)   /* as crease_deg: no two patches share a vertex (each carries its own value) */
/* Builds the baking mesh of `scene`'s patches (borrowed: it must outlive *out and not be
 * re-meshed). Patch vertices at the same position (within a tolerance scaled to the scene) are
 * one point; at each point the patches touching it are grouped into smooth surfaces: two
 * patches join when they have the same material and their normals differ by less than
 * crease_deg (transitively within the point's fan). Each group is one output vertex, so
 * vertices are split at creases and material seams. */
bn_status bn_bake_create(const bn_scene *scene, double crease_deg, bn_bake **out, bn_error *err);
void bn_bake_destroy(bn_bake *b);   /* NULL is a no-op */

const bn_scene *bn_bake_scene(const bn_bake *b);   /* the scene it was built from (borrowed) */
size_t bn_bake_vertex_count(const bn_bake *b);
const double *bn_bake_vertex_positions(const bn_bake *b);   /* xyz per output vertex (borrowed) */
/* The output vertex of corner c of patch p. */
size_t bn_bake_corner_vertex(const bn_bake *b, size_t patch, unsigned corner);
/* The faces written on the element mesh: the patches, or after bn_bake_refine its triangles (each
 * inside one patch). Face f's corners (3 or 4, returned) as output vertices in v, its patch in *patch. */
size_t bn_bake_face_count(const bn_bake *b);
unsigned bn_bake_face(const bn_bake *b, size_t f, size_t v[4], size_t *patch);

/* Vertex value = area-weighted mean of the per-patch values (N*3) of its group's patches:
 * sum_p A_p x_p / sum_p A_p; except at a T-junction (a vertex inside an edge of a patch of its own
 * smooth surface, where faces meshed at different sizes meet), which takes that edge's value, linear
 * between its ends: the interpolated surface then has no crack there. vertex_values:
 * bn_bake_vertex_count()*3, caller-allocated. */
void bn_bake_vertex_values(const bn_bake *b, const double *patch_values, double *vertex_values);
size_t bn_bake_tjunction_count(const bn_bake *b);   /* T-junctions found (0 for a flat bake) */
/* Vertex values from elsewhere (a gather at each vertex) made crack-free: each T-junction takes its
 * edge's value, as bn_bake_vertex_values does. */
void bn_bake_vertex_tjunctions(const bn_bake *b, double *vertex_values);
/* The largest patch of vertex v's group (outside every closed object when it has one): where a gather at
 * the vertex takes its normal, face and reflectance (on a curved mesh, the facet that covers most of
 * the vertex's neighbourhood). */
size_t bn_bake_vertex_patch(const bn_bake *b, size_t v);
/* Patches inside a closed object (the floor under a block standing on it: no light reaches them and no
 * eye sees them) are left out of the vertex averages wherever a vertex also has patches outside, so
 * the darkness under the block does not bleed into the floor around it (bn_rt_enclosed_patches says
 * which; rt: the ray scene of the bake's scene). Returns how many patches were found so. */
struct bn_rt;
size_t bn_bake_exclude_enclosed(bn_bake *b, const struct bn_rt *rt);
/* The value at point p on patch `patch` interpolated from its corners' vertex values:
 * barycentric on triangles, inverse bilinear on quads. Unchecked per-sample call. */
void bn_bake_interpolate(const bn_bake *b, const double *vertex_values, size_t patch, const double p[3],
                         double out[3]);
/* The same interpolation as corner vertices and weights (for reading several value sets at one
 * point): returns the corner count n (3 or 4); value = sum_k w[k] vertex_values[vert[k]]. */
unsigned bn_bake_weights(const bn_bake *b, size_t patch, const double p[3], size_t vert[4], double w[4]);

/* A bake mesh refined where light changes (bounce bake --bake-vertices): the patches become triangles,
 * every T-junction splits its edge (no vertex inside another face's edge: crack-free), then round by
 * round the edges whose ends' luminance (of layer `key`) differ by more than tol x (the larger + a
 * floor of 2% of the display white) have their midpoints probed by `eval`; those whose midpoint is off
 * the ends' mean by as much are bisected, longest edge first (Rivara: conforming, angles bounded), the
 * others left whole for good (linear light needs no vertex), and `eval` gives the new vertices'
 * values, until no edge is left to probe, no edge is longer than min_edge, or the vertices could pass
 * max_vertices. */
typedef bn_status (*bn_bake_eval_fn)(void *user, const double *x, const size_t *patch, size_t n, size_t first,
                                     double *out, bn_error *err);
/* eval: the values of n points x (3 each) on patches patch[], the bake's vertices first .. first+n-1
 * (keys for random streams), into out: nlayers x n x 3, layer-major. */
#define BN_BAKE_DEFAULT_VERTICES 100000   /* bounce bake's budget: the bunny box bakes in 2 minutes */
#define BN_BAKE_REFINE_TOL 0.05
typedef struct bn_bake_refine_opts {
    size_t max_vertices;   /* the budget; 0: no refinement (the patches as faces, each vertex evaluated once) */
    double tol;            /* relative difference that splits an edge (BN_BAKE_REFINE_TOL) */
    double min_edge;       /* edges no longer than this stay whole (scene units; 0: 1/1000 of the diameter) */
    size_t nlayers, key;   /* the layers eval returns, and the one compared (L) */
    bn_bake_eval_fn eval;
    void *user;
    const bn_log *log;     /* a note per round */
} bn_bake_refine_opts;
void bn_bake_refine_opts_default(bn_bake_refine_opts *o);
/* Refines b (built by bn_bake_create; it must not be refined yet) and evaluates every vertex: *values
 * (malloc'd, the caller frees) holds nlayers x bn_bake_vertex_count(b) x 3, layer-major. */
bn_status bn_bake_refine(bn_bake *b, const bn_bake_refine_opts *o, double **values, bn_error *err);

/* A named per-patch value set to write (name used for extra PLY properties: <name>_red...). */
typedef struct bn_bake_layer {
    const char *name;
    const double *patch_values;   /* N*3 (borrowed): the layer's power, and its vertex values unless given */
    const double *vertex_values;  /* bn_bake_vertex_count()*3 or NULL: the vertices' own values (a final gather
                                     at each vertex) in place of the patches' means */
} bn_bake_layer;

/* The mesh a bake is written on (bn_bake_write_opts.input_mesh is one of these). */
typedef enum bn_bake_mesh { BN_BAKE_ELEMENTS, BN_BAKE_INPUT } bn_bake_mesh;
const char *bn_bake_mesh_name(bn_bake_mesh v);
const char *bn_bake_mesh_names(void);   /* "elements|input" */
int bn_bake_mesh_parse(const char *s, bn_bake_mesh *out);   /* 0, or -1 for no such name */

typedef struct bn_bake_write_opts {
    int    input_mesh;   /* BN_BAKE_INPUT (1): the faces are the scene's input polygons (after triangulation of
                            non-planar quads), each corner taking the value of the output vertex at
                            that point (the patches around it on its smooth surface); 0: the
                            faces are the patches (the element mesh) */
    int    ldr;          /* 1: 8-bit sRGB colours at `exposure_ev` instead of float radiance */
    double exposure_ev;  /* for ldr */
    int    colour_sets;  /* glTF: the layers after the first also as colour sets COLOR_1 .. (display colours at
                            the exposure, as COLOR_0 shows the first); 0: as float attributes only */
    const bn_attr *attrs;   /* provenance: PLY/OBJ comments, OM mesh property */
    size_t nattrs;
    const bn_log *log;
} bn_bake_write_opts;

/* Writes the baked mesh by extension: .ply (binary, through OpenMesh; comments added to its
 * header), .om (OpenMesh), .obj (`v x y z r g b`, written directly). The vertex colour is
 * layers[0] (normally L); layers[1..] are written as extra float vertex properties
 * <name>_red/_green/_blue (PLY and OM only; BN_EUSAGE for OBJ). Atomic. */
bn_status bn_bake_write(const bn_bake *b, const char *path, const bn_bake_layer *layers, size_t nlayers,
                        const bn_bake_write_opts *o, bn_error *err);

/* An exposure (EV) for 8-bit colours and glTF's COLOR_0: the 99th percentile of the patches' L
 * (N x 3) luminance at 0.9. */
double bn_bake_auto_exposure(const double *L, size_t n);

/* The viewer page: one self-contained HTML file (the .glb bake at glb_path and three.js embedded;
 * no network at view time) with an orbit camera, a control per bounce term (shown summed, or one
 * alone), exposure, a false-colour mode with its scale and the per-bounce power table. Atomic.
 * BN_EUSAGE when this build has no three.js (scripts/setup.sh installs it). */
bn_status bn_view_write(const char *glb_path, const char *title, const char *out, bn_error *err);
/* The live page: the same viewer around a live payload (bn_pipeline_live_write) instead of a bake. */
bn_status bn_view_write_live(const unsigned char *live, size_t n, const char *title, const char *out, bn_error *err);
/* 1 if the .glb at glb_path is a bake bounce wrote (its asset's generator is bounce), 0 if it is some
 * other glTF (a scene: `bounce view` bakes it first), -1 if it cannot be read as a .glb. */
int bn_view_is_bake(const char *glb_path);

#ifdef __cplusplus
}
#endif
#endif
