/* The frozen F_H's rows against their exact sums, and their normalisation.
 *
 * A leaf's row of F_H sums the links of every node above it. Each link is accepted by a
 * brightness-weighted oracle, so each carries at most eps of radiance error, but a leaf gathers
 * along hundreds of them: a coarse receiver hands every leaf below it the receiver's mean F (a
 * corner patch gets less than its own, a patch under a block standing on the floor the light its
 * uncovered siblings see), and the links' few point pairs add noise. Summed over a row these reach
 * percents (the lit furnace: 20% of the leaves outside 1%; the Cornell box: the floor under the
 * blocks +60%) and the whole operator loses or makes light. The exact row sum is geometry alone: the
 * share of the leaf's cosine-weighted hemisphere that reaches a front face (1 in a closed scene),
 * estimated by rays (bn_ff_row_sum_exact). Scaling each leaf's row to it keeps the links' split of
 * the light among sources and makes every row's total right: what the leaf receives from a uniform
 * radiance is exact, and no leaf gains or loses light by the operator's approximations. */
#include "hierarchy/refine.h"
#include "bounce/dist.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define BN__ROWS_TAG 0x6e6f726d726f7773ULL   /* "normrows" */
/* Rays of a leaf's exact row sum: when all 64 reach a front face (or none) it is taken as 1 (or 0):
 * a leaf that truly sees 5% of open sky passes so with probability 0.95^64 = 4%, one with 10% with
 * 0.1%; else 256 afresh (stratified: about 1% standard error where an opening's edge crosses the
 * hemisphere). */
#define BN__ROWS_MIN_RAYS 64
#define BN__ROWS_MAX_RAYS 256
/* Leaves measured for the report alone (no normalisation): every leaf up to this many, else an
 * even stride of the leaf order (a million leaves would cost hundreds of millions of rays). */
#define BN__ROWS_REPORT 16384

/* dev[i] = sum_j F_ij - exact and scale[i] = exact / sum for this rank's leaves (0 elsewhere); the
 * ones with no links where light arrives counted in *unscalable. */
static void bn__rows_measure(const bn__ref *R, const double *y, size_t stride, double *dev, double *scale,
                             size_t *unscalable)
{
    const bn__tree *t = R->t;
    long lo = (long)R->plo, hi = (long)R->phi;
    size_t bad = 0;
#pragma omp parallel for schedule(dynamic, 64) reduction(+ : bad)
    for (long q = lo; q < hi; q++) {
        size_t i = t->order[q];
        if ((size_t)q % stride != 0) {   /* not measured: NaN (0 on the other ranks, summed) */
            dev[i] = NAN;
            scale[i] = 1;
            continue;
        }
        double e = bn_ff_row_sum_exact(R->scene, R->rt, i, BN__ROWS_MIN_RAYS, BN__ROWS_MAX_RAYS,
                                       R->o->ff.seed ^ BN__ROWS_TAG, NULL);
        double r = y[3 * i];
        dev[i] = r - e;
        scale[i] = r > 0 ? e / r : 1;
        bad += !(r > 0) && e > 0;
    }
    *unscalable = bad;
}

/* The report's figures from every leaf's dev and scale. */
static void bn__rows_report(const double *dev, const double *scale, size_t np, bn_hierarchy_report *rep)
{
    size_t within = 0, m = 0;
    rep->row_dev_min = rep->row_scale_min = INFINITY;
    rep->row_dev_max = rep->row_scale_max = -INFINITY;
    for (size_t i = 0; i < np; i++) {
        if (isnan(dev[i]))
            continue;   /* a leaf the report did not measure */
        m++;
        within += fabs(dev[i]) <= 0.01;
        rep->rows_above_5pct += dev[i] > 0.05;
        rep->row_dev_min = fmin(rep->row_dev_min, dev[i]);
        rep->row_dev_max = fmax(rep->row_dev_max, dev[i]);
        rep->row_scale_min = fmin(rep->row_scale_min, scale[i]);
        rep->row_scale_max = fmax(rep->row_scale_max, scale[i]);
    }
    rep->rows_within_1pct = m ? (double)within / (double)m : 1;
}

bn_status bn__rows_normalize(const bn__ref *R, bn__hop *h, bn_hierarchy_report *rep, bn_error *err)
{
    size_t np = h->npatch;
    unsigned long long unscalable = 0;
    double *one = bn__malloc_array(3 * np, sizeof(double)), *y = bn__malloc_array(3 * np, sizeof(double));
    double *dev = bn__calloc(np ? np : 1, sizeof(double)), *scale = bn__calloc(np ? np : 1, sizeof(double));
    bn_status st = one && y && dev && scale ? BN_OK : bn_error_set(err, BN_ENOMEM, "out of memory for %zu rows", np);
    for (size_t k = 0; st == BN_OK && k < 3 * np; k++)
        one[k] = 1;
    if (st == BN_OK)
        st = bn__hop_apply(h, one, y, err);   /* F_H 1 (a collective under mpirun) */
    if (st == BN_OK) {
        size_t u, stride = R->o->normalize_rows || np <= BN__ROWS_REPORT ? 1 : (np + BN__ROWS_REPORT - 1) / BN__ROWS_REPORT;
        bn__rows_measure(R, y, stride, dev, scale, &u);
        unscalable = u;
        /* each leaf is one rank's: the sums are every rank's values, copied */
        if ((st = bn_dist_sum(dev, np, err)) == BN_OK && (st = bn_dist_sum(scale, np, err)) == BN_OK)
            st = bn_dist_sum_u64(&unscalable, 1, err);
    }
    if (st == BN_OK) {
        bn__rows_report(dev, scale, np, rep);
        rep->rows_unscalable = (size_t)unscalable;
        rep->normalized = R->o->normalize_rows != 0;
        if (rep->normalized) {
            h->rowscale = scale;
            scale = NULL;
        }
    }
    free(one);
    free(y);
    free(dev);
    free(scale);
    return st;
}
