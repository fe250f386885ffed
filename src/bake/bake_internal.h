/* The bake's writers beside OpenMesh's: what bn_bake_write hands them. Not installed. */
#ifndef BN_BAKE_INTERNAL_H
#define BN_BAKE_INTERNAL_H

#include "bounce/bake.h"

/* The bake (bake.c builds it, refine.c refines it): the output vertices, the patches' corners on them,
 * each vertex's patches, and after bn_bake_refine the triangles written instead of the patches. */
struct bn_bake {
    const bn_scene *scene;
    double  eps;        /* points closer than this are one (1e-9 of the scene's diameter) */
    double  cos_crease; /* patches of one material whose normals are closer share vertices */
    size_t  nverts;
    double *pos;        /* nverts*3 */
    size_t *vpoint;     /* nverts: the position's number (vertices split at a crease share it) */
    size_t  npoints;    /* positions numbered so far */
    size_t *corner_v;   /* npatches*4: output vertex of each corner (unused corners = SIZE_MAX) */
    size_t *vstart;     /* nverts+1: CSR of the patches of each vertex's group */
    size_t *vpatch;
    unsigned char *enclosed;   /* per patch: inside a closed object (NULL: none known) */
    size_t ntj;         /* T-junctions: vertex v lies inside the edge (a, b) of a patch on its smooth */
    struct bn__tj {     /* surface, at a + t (b - a); in decreasing order of the edge's length */
        size_t v, a, b;
        double t, len;
    } *tj;
    size_t  ntri;       /* refined (bn_bake_refine): the faces are these triangles, 3 vertices each, */
    size_t *tri;        /* tri_patch[t] the patch each lies in; 0 and NULL: the faces are the patches */
    size_t *tri_patch;
};

/* Vertex v's group has a patch of pq's smooth surface (its material, normal within the crease). */
int bn__same_surface(const bn_bake *b, const bn_patch *patches, size_t v, const bn_patch *pq);

/* Where a vertex is gathered: patch p before q when p is outside every closed object and q is not, else
 * when p is larger (bn_bake_vertex_patch's rule; the refinement's new vertices follow it too). */
int bn__patch_better(const bn_bake *b, size_t p, size_t q);

/* Positions sorted by x (i: the position's index) for range searches along x. */
typedef struct bn__xkey {
    double x;
    size_t i;
} bn__xkey;
bn__xkey *bn__xsort(const double *pos, size_t n);   /* malloc'd; NULL without memory */
size_t bn__xfirst(const bn__xkey *ox, size_t n, double xlo);   /* the first with x >= xlo */
/* P strictly inside the segment A-B: more than eps from both ends, at most dist from the line;
 * *t = where along it (0 at A, 1 at B). */
int bn__inside_segment(const double A[3], const double B[3], const double P[3], double eps, double dist, double *t);

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
    /* nv x 3 or NULL: the normal of the face each vertex's values were gathered on (bn_bake_vertex_patch's;
       at a vertex of a curved mesh several faces meet), glTF's _FACE_NORMAL */
    const float *face_normal;
} bn__bake_out;

/* glTF 2.0: binary .glb (binary = 1), or .gltf with a .bin of the same stem beside it. Atomic per
 * file. Positions are converted to metres (glTF's unit). */
bn_status bn__write_gltf(const char *path, int binary, const bn__bake_out *m, const bn_scene *scene,
                         const bn_bake_write_opts *o, bn_error *err);

/* A .glb's header and first chunk against its length (bounce view's only parse of the file):
 * BN_EINPUT naming path and what is wrong. */
bn_status bn__glb_check(const unsigned char *glb, size_t len, const char *path, bn_error *err);

#endif
