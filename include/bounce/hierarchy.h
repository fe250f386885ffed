/* bounce: hierarchical radiosity with clustering, as one more transport operator.
 *
 * The scene's patches are the leaves. Above them: a binary tree over each input polygon's patches
 * (planar nodes), and volume clusters over the polygons up to one root. Links join a receiver node
 * to a source node at whatever level an error oracle accepts (Hanrahan, Salzman, Aupperle 1991;
 * clusters after Smits, Arvo, Greenberg 1994 and Sillion 1995), starting from the root's self-link.
 * The oracle is brightness-weighted: a link is split while rho_receiver x B_source x F_bound
 * exceeds eps x the largest emitted radiance. Refinement alternates with gathers until the link
 * set settles; then the set is frozen, and
 *     y = F_H x = push(gather along links(pull(x)))
 * is one linear map on the patches (pull: area-weighted means up the tree; push: every node's
 * gathered value added to all leaves below it). K_H = diag(rho) F_H serves the operator interface
 * (apply and a zero diagonal: no link joins a node to itself or to its own subtree), so Jacobi, the
 * Neumann series and every bounce term K_H^k E run on it as on dense K. Gauss-Seidel needs rows,
 * which a hierarchy does not keep.
 *
 * Under mpirun with more than one process each rank holds a share of the links, so every apply of
 * K_H is a collective (an all-reduce of y): every rank must apply it the same number of times, in
 * the same order, as the solvers do; a caller applying K_H on one rank alone waits forever.
 *
 * Polygons that share an edge and lie in one plane (within 1e-3 rad) form one planar subtree, so a
 * surface cut finer (a scan subdivided 16 times) gets the same clusters above its planes, and with
 * min_area the same smallest elements, as the coarse cut: its link count follows the light, not the
 * polygon count. */
#ifndef BOUNCE_HIERARCHY_H
#define BOUNCE_HIERARCHY_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/transport.h"
#include "bounce/formfactor.h"

#ifdef __cplusplus
extern "C" {
#endif

#define BN_HIERARCHY_EPS_DEFAULT 1e-3

typedef struct bn_hierarchy_opts {
    double eps;          /* link tolerance relative to the largest emitted radiance (default 1e-3);
                            0 refines every link down to the patches */
    int    clusters;     /* 1 (default): start from the root's self-link; 0: from every pair of input
                            polygons (k^2 links before any refinement) */
    int    samples;      /* point pairs (and rays) per link above the patches (default 8; partly
                            visible links get 4x as many where their noise could exceed eps/8 in
                            the receiver's radiance) */
    int    flat_clusters;    /* 1 (default): nearly flat clusters facing a source may receive as one
                                node, handing each polygon its cosine's share; 0: receivers are
                                polygons' nodes only (more links and time: bench/results.md) */
    int    max_passes;   /* refine-gather passes before the link set is frozen (default 12) */
    double min_area;     /* planar nodes smaller than this (scene units^2) are not split: the
                            smallest element refinement makes; 0 (default): 2^-20 (about a millionth)
                            of the scene's surface area; < 0: down to the patches (always so at eps 0) */
    int    exact_leaf_links; /* links between two patches computed exactly as the dense assembly does
                                (ff: method, samples, tolerance, seed); default 0 (1 when eps is 0): the
                                exact point-to-polygon form factor at `samples` points of the receiver,
                                each with one shadow ray */
    bn_formfactor_opts ff;   /* the form-factor options (seed always; the rest for exact leaf links) */
    int    cull_leaf_rays;   /* leaf links skip rays where no face can lie between (1, as the dense
                                assembly does: identical values, costs a pass over the faces per
                                patch); default 0: always cast */
    int    normalize_rows;   /* 1: once frozen, each leaf's row of F_H is scaled to its exact sum
                                (bn_ff_row_sum_exact: 1 in a closed scene); 0 (default): F_H as the
                                links make it. The rows are reported either way. Scaling makes every
                                row's total right but moves the dim links' errors onto the bright ones
                                (doc/hierarchy.md measures it) */
    size_t max_memory;   /* bytes for links and nodes; 0 = 80% of physical memory */
    int    threads;      /* 0 = the caller's; results do not depend on it */
    int    quiet;        /* no progress bars */
    const double *direct;   /* the punctual lights' direct radiance per patch (N x 3; NULL: none): part of the
                               source the links are refined for (bn_solve_opts.direct) */
    bn_log log;
    int    volume_links; /* 1 (default): a patch whose bounding sphere meets a cluster's (foliage, a part
                            among its neighbours) takes F into it from its own hemisphere rays, one link
                            while the radiance spread below the cluster allows (doc/hierarchy.md);
                            0: such pairs are split down to the patches */
} bn_hierarchy_opts;
void bn_hierarchy_opts_default(bn_hierarchy_opts *o);

/* The hierarchy's leaves are the patches: its default meshing cuts the large polygons finer than
 * dense radiosity can afford, into this many patches, the polygons smaller than a patch kept
 * whole besides (so about the input polygons plus this many). */
#define BN_HIERARCHY_EXTRA_PATCHES 15000

typedef struct bn_hierarchy_report {
    size_t patches, nodes, clusters, planar_nodes;  /* leaves = patches; planar: inside one plane */
    size_t polygons, planes;                        /* input polygons, and the planes they form */
    double min_area;                                /* the smallest element split (scene units^2) */
    size_t links, leaf_links, cluster_links;        /* leaf: patch to patch; cluster: a cluster at either end
                                                       (under mpirun: over all processes, as one process) */
    size_t links_here;                              /* the links this process stores (under mpirun: those of
                                                       receivers meeting its share of the patches) */
    size_t passes;                                  /* refine-gather passes */
    int    settled;                                 /* 1 if the last pass split fewer than 1e-3 of the links */
    size_t rays;                                    /* traced by this process */
    size_t bytes;                                   /* the frozen operator: nodes and links (this process's) */
    double bytes_per_link;                          /* link storage alone / links */
    size_t peak_link_bytes;                         /* the most bytes of links refinement held at once (as
                                                       allocated: the pass's input, its output and every
                                                       thread's, or the links beside the frozen operator) */
    double peak_bytes_per_link;                     /* peak_link_bytes / the links refinement ended with (with
                                                       those of F = 0 it keeps to refine them later) */
    double eps_abs;                                 /* eps x the largest emitted radiance: the bound of
                                                       a link's error the oracle used */
    /* F_H's rows against their exact sums (before normalize_rows scales them): every leaf with
       normalize_rows or up to 16,384 leaves, else an even stride of 16,384 of them */
    double rows_within_1pct;                        /* share of leaves with |sum_j F_ij - exact| <= 0.01 */
    size_t rows_above_5pct;                         /* leaves with sum_j F_ij > exact + 0.05 */
    double row_dev_min, row_dev_max;                /* sum_j F_ij - exact, over the leaves */
    size_t rows_unscalable;                         /* leaves no link reaches while their exact sum is > 0 */
    double row_scale_min, row_scale_max;            /* the factors normalize_rows applied */
    int    normalized;
    double seconds_tree, seconds_refine;
} bn_hierarchy_report;

/* Builds K_H for the meshed `scene` with `rt` (both borrowed; rt must outlive nothing: the operator
 * keeps neither). Fails with BN_EINPUT for a bad option, BN_ENOMEM above max_memory, BN_EINTR /
 * BN_ETERM when interrupted. rep may be NULL. */
bn_status bn_hierarchy_build(const bn_scene *scene, const bn_rt *rt, const bn_hierarchy_opts *o,
                             bn_transport **out, bn_hierarchy_report *rep, bn_error *err);

/* The report as `key value` lines. */
void bn_hierarchy_report_print(const bn_hierarchy_report *r, FILE *fp);

#ifdef __cplusplus
}
#endif
#endif
