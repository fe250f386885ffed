/* Refinement's shared state (src/hierarchy): what a pass reads (bn__ref), the growing link arrays,
 * the per-thread workers; refine.c refines, balance.c splits the leaves among MPI processes,
 * build.c runs the passes and freezes the links. Not installed. */
#ifndef BN_HIERARCHY_REFINE_H
#define BN_HIERARCHY_REFINE_H

#include "hierarchy/hierarchy_internal.h"
#include "formfactor/ff_pair.h"

/* A leaf's geometry where sampling reads it: in the tree's leaf order (node v's leaves are
 * leaf[lo[v] .. hi[v]), beside cum_area), one record each instead of a patch, its corner indices and
 * the corners (three cache misses per sampled point on scenes of a million patches). */
typedef struct bn__leaf_geom {
    double v[4][3];           /* corners, counter-clockwise from the front (v[3]: quads only) */
    double n[3];              /* unit normal */
    double fan0;              /* the share of a quad's area in its first fan triangle (0, 1, 2); 1 for a triangle */
    uint32_t nc;              /* 3 or 4 */
} bn__leaf_geom;

typedef struct bn__ref {
    const bn__tree *t;
    const bn_scene *scene;
    const bn_rt *rt;
    const bn_hierarchy_opts *o;
    const bn_patch *patch;
    const double *pverts;
    bn__leaf_geom *leaf;      /* npatch, in leaf order */
    double *Bmax;             /* 3 per node: the largest radiance estimate below (oracle) */
    double *Bmin;             /* 3 per node: the smallest */
    uint32_t **vol;           /* npatch, in leaf order: a leaf's hits (count, then sorted leaf positions), cast
                                 when its first volume link is made (NULL until then) */
    size_t *vol_bytes;        /* what vol holds (atomic) */
    double eps_abs;
    double btyp;              /* the scene's typical reflected radiance (0 before the first estimate) */
    double min_area;          /* planar nodes below this area are not split */
    int force;                /* eps == 0: refine every link to the patches */
    double tol, ray_eps;
    bn__ff_pairs *pairs;
    size_t plo, phi;          /* this rank's leaves (all of them with one process): bound[rank .. rank + 1] */
    size_t *bound;            /* P + 1: every rank's first leaf, then npatch */
} bn__ref;

/* Under mpirun a rank refines only receivers whose leaves meet its own (the others' links are theirs):
 * each receiver's links are then exactly one process's. A receiver is counted (links, splits, rays) by
 * the rank that holds its first leaf, so the counts summed over ranks are one process's. */
static inline int bn__receiver_here(const bn__ref *R, uint32_t r)
{
    return R->t->lo[r] < R->phi && R->t->hi[r] > R->plo;
}
static inline int bn__receiver_counted(const bn__ref *R, uint32_t r)
{
    return R->t->lo[r] >= R->plo && R->t->lo[r] < R->phi;
}

typedef struct bn__vec {
    bn__link *a;
    size_t n, cap;
    int oom;
} bn__vec;

void bn__vec_push(bn__vec *v, uint32_t r, uint32_t s, float F, int partial);

/* Hemisphere rays from a leaf receiver (volume links, refine.c): cast once for the whole build, the
 * leaf positions of the front faces they hit kept per leaf (R->vol). */
#define BN__VOL_RAYS 256

typedef struct bn__worker {
    bn__vec links, pending;
    uint32_t vol[1 + BN__VOL_RAYS];   /* scratch: a leaf's hits before they are kept */
    bn__ff_worker *ff;
    size_t rays, splits;
    size_t ff_rays;           /* ff's rays counted already (it counts from its creation) */
} bn__worker;

/* The point of leaf q (in leaf order) at (u2, u3) in [0,1)^2, uniform in area; its normal. */
void bn__leaf_point(const bn__ref *R, size_t q, double u2, double u3, double x[3], const double **n);
/* What a pass counts: existing links split (this pass), shadow rays and the most bytes of links held
 * at once (added to / raised across passes). */
typedef struct bn__pass_stats {
    size_t splits, rays, peak_bytes;
} bn__pass_stats;
/* One pass: every item of *work refined (rounds of a few levels); the accepted links replace *work,
 * sorted. */
bn_status bn__pass(const bn__ref *R, bn__worker *W, int nt, bn__vec *work, bn__pass_stats *st, const char *label,
                   bn_error *err);
/* Bmax from per-patch radiances L (N*3): the largest below each node. */
void bn__bmax(const bn__tree *t, const double *L, double *Bmax, double *Bmin);
/* The area-weighted mean over patches of the largest channel of L - E: the light a typical surface
 * reflects, what a dark covered receiver's brightness is measured against (bn__eps_at). */
double bn__typical_radiance(const bn__tree *t, const double *L, const double *E);
/* Keeps the links with F > 0, in place; returns their count. */
size_t bn__compact(bn__vec *v);
/* L ~ E + K_H L by a few Jacobi sweeps over the current links (the oracle's brightness). */
bn_status bn__estimate(const bn__tree *t, bn__vec *links, const size_t *bound, const double *E, const double *rho,
                       double eps_abs, double *L, bn_error *err);

/* rows.c: F_H 1 against every leaf's exact row sum (bn_ff_row_sum_exact) into rep, and with
 * o->normalize_rows each leaf's row scaled to it (h->rowscale). A collective under mpirun. */
bn_status bn__rows_normalize(const bn__ref *R, bn__hop *h, bn_hierarchy_report *rep, bn_error *err);

/* balance.c: the first split of the leaves among processes (rank k's equal share) */
void bn__dist_leaves_of(size_t npatch, size_t k, size_t *lo, size_t *hi);
/* A split is redone when the most loaded process holds more than this times the mean. */
#define BN__IMBALANCE 1.05
/* Under mpirun, after a pass: the leaves split again by link cost and the links moved to their new
 * ranks (*imbalance: the old split's most loaded / mean; *moved: links this rank received). */
bn_status bn__rebalance(bn__ref *R, bn__vec *work, double *imbalance, size_t *moved, bn_error *err);
/* The final counts over all processes (links, leaf links, cluster links) into rep, and the log line of
 * what each process stores. */
bn_status bn__count_links(const bn__ref *R, const bn__vec *work, bn_hierarchy_report *rep, const bn_log *log,
                          bn_error *err);

#endif
