/* The hierarchy's frozen links as a storage of K beside dense and sparse (links.c): the node tree's
 * shape, links by receiver, y = F_H x = push(gather(pull(x))). What builds them (src/hierarchy)
 * sits above form factors; this is all the operator needs of it. Not installed. */
#ifndef BN_TRANSPORT_LINKS_H
#define BN_TRANSPORT_LINKS_H

#include <stddef.h>
#include <stdint.h>
#include "bounce/transport.h"

#define BN__NONE UINT32_MAX

/* A link: receiver r gathers F x (the area mean of the values below s). 12 bytes, as refinement holds
 * tens of millions of them: the top bit of s_bits marks a link whose shadow rays found partial
 * visibility (refinement's business; nodes number below 2^31). */
typedef struct bn__link {
    uint32_t r;
    uint32_t s_bits;          /* the source node, | BN__LINK_PARTIAL */
    float F;                  /* < 0: not computed yet */
} bn__link;
#define BN__LINK_PARTIAL 0x80000000u
static inline uint32_t bn__link_s(const bn__link *l) { return l->s_bits & ~BN__LINK_PARTIAL; }
static inline int bn__link_partial(const bn__link *l) { return (l->s_bits & BN__LINK_PARTIAL) != 0; }

/* Links ordered by receiver, then source (the order bn__hop_make takes), in place. */
void bn__links_sort(bn__link *a, size_t n);

/* Octahedral encoding of a unit vector in 8 + 8 bits (Meyer et al. 2010): ~1 degree. */
uint16_t bn__oct_encode(const double u[3]);
void bn__oct_decode(uint16_t e, double u[3]);

/* The tree's shape as the operator needs it: n nodes in a binary tree (child: first of two, BN__NONE
 * for a leaf; children after their parent), the leaves below node v are order[lo[v]..] (a leaf's
 * patch is order[lo[v]]); plane < 0 marks a volume cluster; area and the unit normal (3 per node)
 * of each node. dir(ctx, r, s, u): the unit direction from receiver r to source s, for links into
 * clusters (F is then per unit cosine). */
typedef struct bn__hop_shape {
    size_t n, npatch;
    const uint32_t *child, *parent, *lo, *order;
    const int32_t *plane;
    const double *area, *normal;
    void (*dir)(const void *ctx, uint32_t r, uint32_t s, double u[3]);
    const void *dir_ctx;
} bn__hop_shape;

/* The frozen operator: the tree's topology and areas, links by receiver. Owns its arrays. */
typedef struct bn__hop {
    size_t n, npatch, nlinks, nclusters;
    uint32_t *child, *parent, *leaf_patch;   /* leaf_patch: BN__NONE for inner nodes */
    uint32_t *cl;             /* per node: its index among the clusters, BN__NONE for planar nodes */
    double *area;
    float *normal;            /* 3 per node: planar nodes' unit normal */
    size_t *start;            /* n + 1 */
    uint32_t *src;
    float *F;                 /* cluster receivers: F per unit cosine */
    uint16_t *dir;            /* per link: the direction to the source (cluster receivers) */
    double *rowscale;         /* npatch: each leaf's row scaled to its exact sum (NULL: none; set by
                                 src/hierarchy after freezing, owned) */
    double *Bn, *G;           /* scratch of apply: 4n (a node's B and a 0), 3n */
    double *Gv;               /* 9 per cluster: what it gathers, per channel as a vector */
    /* under mpirun (P > 1): rank q's leaves are [bound[q], bound[q + 1]) in the tree's leaf order; a rank
     * holds the links of every receiver whose leaves meet its own, so its leaves' values are exact, and
     * apply all-gathers every rank's leaves in leaf order (values copied: one process's bits) */
    int distributed;
    size_t plo, phi, *bound;
    uint32_t *order;          /* npatch: patches in leaf order (P > 1) */
    double *xchg;             /* 3 npatch: the leaves' values in leaf order (P > 1) */
} bn__hop;

/* Takes the links with F > 0 of `links` (sorted by r then s; the rest skipped) and the tree's shape
 * (copied); bound: P + 1, every rank's first leaf in leaf order, then npatch (copied). */
size_t bn__hop_link_bytes(const bn__hop *h);
bn_status bn__hop_make(const bn__hop_shape *t, const bn__link *links, size_t nlinks, const size_t *bound, bn__hop **out,
                       bn_error *err);
bn_status bn__hop_apply(void *ctx, const double *x, double *y, bn_error *err);
void bn__hop_destroy(void *ctx);
size_t bn__hop_bytes(const void *ctx);
extern const bn_transport_ops bn__hop_ops;

#endif
