/* The hierarchy's construction: the node tree (tree.c), the links and their refinement
 * (refine.c), above form factors; what it freezes is the storage of src/transport/links.c
 * (transport/links.h). Not installed. */
#ifndef BN_HIERARCHY_INTERNAL_H
#define BN_HIERARCHY_INTERNAL_H

#include "bounce/hierarchy.h"
#include "base/internal.h"
#include "transport/links.h"
#include "bounce/rt.h"

/* Nodes in flat arrays (structure of arrays), a binary tree: node 0 is the root, children are
 * allocated in pairs after their parent (so a reverse sweep sees children before parents, a
 * forward one parents before children). Leaves are the scene's patches; the leaves below a node
 * are order[lo..hi) (depth-first order). plane >= 0: every patch below lies in that plane (a planar
 * node); -1: a volume cluster. A plane is one input polygon, or (merge) a connected group of input
 * polygons within BN__COPLANAR of one plane: the same surface cut finer (a subdivided scan) then
 * has the same nodes above its polygons as the coarse one. */
typedef struct bn__tree {
    size_t n;                 /* nodes */
    size_t npatch;
    uint32_t *parent, *child; /* child: first of two, BN__NONE for a leaf */
    uint32_t *lo, *hi;
    int32_t *plane;
    double *area;             /* surface area below (scene units^2) */
    double *box;              /* 6 per node: lo xyz, hi xyz */
    float *rho_max;           /* 3 per node: largest reflectance below */
    double *normal;           /* 3 per node: the axis of the normals below (area-weighted mean, unit;
                                 the polygon's normal for planar nodes) */
    double *spread;           /* per node: the largest angle between that axis and a normal below */
    unsigned char *cover;     /* per node: the bn_cover class of every patch below (BN_COVER_OPEN when mixed
                                 or unknown) */
    uint32_t *order;          /* npatch: patches in depth-first order */
    uint32_t *leaf;           /* npatch: each patch's leaf node */
    double *cum_area;         /* npatch + 1: prefix sums of the areas in `order` */
    size_t nplanes;
    double *pn, *pp;          /* 3 per plane: its unit normal and a point on it */
    double *pthick;           /* per plane: the largest distance of its polygons' vertices from it */
} bn__tree;

/* Polygons join a plane while every normal is within this angle (radians) of the plane's and every
 * vertex within this fraction of its distance from the plane's point: a crease of 1e-3 rad passes
 * light F ~ 1e-7 across, far below any eps the hierarchy is run at. */
#define BN__COPLANAR 1e-3

/* merge: group coplanar connected polygons into one plane (off for exact leaf links). cover (may be
 * NULL): per patch, its bn_cover class (bn_rt_cover_classes); each plane's patches of different
 * classes are split apart first (no node holds two). */
bn_status bn__tree_build(const bn_scene *s, int merge, const unsigned char *cover, bn__tree *t, bn_error *err);
void bn__tree_free(bn__tree *t);
static inline int bn__tree_is_leaf(const bn__tree *t, uint32_t v) { return t->child[v] == BN__NONE; }
static inline uint32_t bn__tree_patch(const bn__tree *t, uint32_t v) { return t->order[t->lo[v]]; }
size_t bn__tree_bytes(const bn__tree *t);
/* The bounding sphere of node v: its box's centre and half diagonal. */
void bn__tree_sphere(const bn__tree *t, uint32_t v, double c[3], double *rad);
/* What the frozen operator keeps of the tree (borrowed; directions between bounding spheres' centres). */
bn__hop_shape bn__tree_shape(const bn__tree *t);

/* A cluster receives only when it is nearly flat (its normals within BN__FLAT of their axis) and
 * every surface below faces the source (see refine.c): then each polygon p gets K max(0, n_p . u) =
 * K n_p . u exactly, with K the link's F per unit cosine and u the unit direction to the source, and
 * the cluster can gather one vector per channel, sum K B u, that each polygon dots with its normal.
 * u is kept per link in 16 bits (bn__oct_encode, ~1 degree). */
#define BN__FLAT 0.5236   /* 30 degrees */
#endif
