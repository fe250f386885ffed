/* The bake's writers beside OpenMesh's: what bn_bake_write hands them. Not installed. */
#ifndef BN_BAKE_INTERNAL_H
#define BN_BAKE_INTERNAL_H

#include "bounce/bake.h"

/* The mesh to write: nv vertices (positions in scene units), nf convex faces of 3 or 4 corners
 * (face_idx: 4 per face), each face's material, and nlayers float colour sets (3 per vertex;
 * vals[0] is L), named; c8: an optional 8-bit sRGB display set (3 per vertex) at exposure_ev. */
typedef struct bn__bake_out {
    size_t nv;
    const double *pos;
    size_t nf;
    const unsigned *face_n;
    const size_t *face_idx;
    const unsigned *face_material;
    size_t nlayers;
    const float *const *vals;
    const char *const *names;
    const unsigned char *c8;
    double exposure_ev;
    int colour_sets;          /* layers 1 .. also as COLOR_1 .. */
    const double *power;      /* nlayers x 3: each layer's power pi sum_p A_p x_p over the patches (W) */
    /* each face's object and the objects' names (glTF: a node and mesh each); NULL or nobjects 1: one */
    const unsigned *face_object;
    size_t nobjects;
    const char *const *object_names;
} bn__bake_out;

/* glTF 2.0: binary .glb (binary = 1), or .gltf with a .bin of the same stem beside it. Atomic per
 * file. Positions are converted to metres (glTF's unit). */
bn_status bn__write_gltf(const char *path, int binary, const bn__bake_out *m, const bn_scene *scene,
                         const bn_bake_write_opts *o, bn_error *err);

/* A .glb's header and first chunk against its length (bounce view's only parse of the file):
 * BN_EINPUT naming path and what is wrong. */
bn_status bn__glb_check(const unsigned char *glb, size_t len, const char *path, bn_error *err);

#endif
