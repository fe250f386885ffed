/* The hierarchy's internals: the node tree (tree.c), the links and their refinement (refine.c)
 * and the frozen operator (operator.c). Not installed. */
#ifndef BN_HIERARCHY_INTERNAL_H
#define BN_HIERARCHY_INTERNAL_H

#include "bounce/hierarchy.h"
#include "base/internal.h"

#define BN__NONE UINT32_MAX

/* Nodes in flat arrays (structure of arrays), a binary tree: node 0 is the root, children are
 * allocated in pairs after their parent (so a reverse sweep sees children before parents, a
 * forward one parents before children). Leaves are the scene's patches; the leaves below a node
 * are order[lo..hi) (depth-first order). face >= 0: every patch below lies in that input polygon
 * (a planar node); -1: a volume cluster. */
typedef struct bn__tree {
    size_t n;                 /* nodes */
    size_t npatch;
    uint32_t *parent, *child; /* child: first of two, BN__NONE for a leaf */
    uint32_t *lo, *hi;
    int32_t *face;
    double *area;             /* surface area below (scene units^2) */
    double *box;              /* 6 per node: lo xyz, hi xyz */
    float *rho_max;           /* 3 per node: largest reflectance below */
    double *normal;           /* 3 per node: the polygon's unit normal (planar nodes), 0 for clusters */
    uint32_t *order;          /* npatch: patches in depth-first order */
    uint32_t *leaf;           /* npatch: each patch's leaf node */
    double *cum_area;         /* npatch + 1: prefix sums of the areas in `order` */
} bn__tree;

bn_status bn__tree_build(const bn_scene *s, bn__tree *t, bn_error *err);
void bn__tree_free(bn__tree *t);
static inline int bn__tree_is_leaf(const bn__tree *t, uint32_t v) { return t->child[v] == BN__NONE; }
static inline uint32_t bn__tree_patch(const bn__tree *t, uint32_t v) { return t->order[t->lo[v]]; }
size_t bn__tree_bytes(const bn__tree *t);

/* A link: receiver r gathers F x (the area mean of the values below s). */
typedef struct bn__link {
    uint32_t r, s;
    float F;                  /* < 0: not computed yet */
    uint8_t partial;          /* its shadow rays found partial visibility */
} bn__link;

/* Directions a cluster receiver tells apart: the 26 of {-1, 0, 1}^3 \ 0, normalised. A link into a
 * cluster carries its direction's bin; what the cluster gathers from bin b reaches each polygon p
 * below it in proportion to max(0, n_p . u_b) (the link's F divided by the cluster's area-mean of
 * that cosine, so the cluster as a whole receives F x its area: light goes to the surfaces that face
 * the source, not to every surface of the group alike). */
#define BN__BINS 26
extern const double bn__bin_dir[BN__BINS][3];
int bn__bin_of(const double u[3]);   /* the nearest bin of a unit vector */

/* The frozen operator: the tree's topology and areas, links by receiver. Owns its arrays. */
typedef struct bn__hop {
    size_t n, npatch, nlinks, nclusters;
    uint32_t *child, *parent, *leaf_patch;   /* leaf_patch: BN__NONE for inner nodes */
    uint32_t *cl;             /* per node: its index among the clusters, BN__NONE for planar nodes */
    double *area;
    float *normal;            /* 3 per node: planar nodes' unit normal */
    size_t *start;            /* n + 1 */
    uint32_t *src;
    float *F;                 /* cluster receivers: F / (the cluster's mean cosine toward the bin) */
    uint8_t *bin;             /* per link: its direction bin (cluster receivers) */
    double *Bn, *G;           /* 3n each: scratch of apply */
    double *Gb;               /* 3 x BN__BINS per cluster: what clusters gather, by direction */
} bn__hop;

/* Takes links (sorted by r then s; F > 0 only) and the tree's topology (copied). */
bn_status bn__hop_make(const bn__tree *t, const bn__link *links, size_t nlinks, bn__hop **out, bn_error *err);
bn_status bn__hop_apply(void *ctx, const double *x, double *y, bn_error *err);
void bn__hop_destroy(void *ctx);
size_t bn__hop_bytes(const void *ctx);
extern const bn_transport_ops bn__hop_ops;

#endif
