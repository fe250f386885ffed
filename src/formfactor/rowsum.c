/* F's row sums against the exact ones (include/bounce/formfactor.h: bn_ff_row_sum_check).
 *
 * sum_j F_ij is the share of patch i's cosine-weighted hemisphere, averaged over the patch, whose
 * first hit is the front of another patch: 1 in a closed scene, less where rays escape or reach a
 * back. A ray answers 0 or 1, so R stratified rays estimate it with a standard error of at most
 * sqrt(p (1 - p) / R): exactly 0 where every ray hits a front, as in a closed scene. Independent of
 * how F was made (closed form, sampling, the hierarchy's links): the ray caster and the patches only. */
#include "bounce/formfactor.h"
#include "formfactor/ff_internal.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define BN__ROWSUM_TAG 0x726f7773756dULL   /* "rowsum" */

/* Rays from patch i (points and directions stratified, rays x rays strata each) reaching a front. */
static int bn__row_hits(const bn_rt *rt, const bn_scene *s, size_t i, int rays, uint64_t seed)
{
    size_t np, npv;
    const bn_patch *pa = bn_scene_patches(s, &np) + i;
    const double *pv = bn_scene_patch_vertices(s, &npv);
    double corners[12], t[3], b[3], eps = bn_rt_epsilon(rt);
    int side = (int)ceil(sqrt((double)rays)), hits = 0;
    bn__rng r = bn__rng_make(seed ^ BN__ROWSUM_TAG, i, 0);
    for (unsigned k = 0; k < pa->ncorners; k++)
        memcpy(corners + 3 * k, pv + 3 * pa->corner[k], 3 * sizeof(double));
    bn_v3_basis(pa->normal, t, b);
    for (int k = 0; k < rays; k++) {
        /* direction strata on a side x side grid of (u2, v2); the point uniform on the patch */
        double u2 = ((double)(k % side) + bn__rng_uniform(&r)) / side;
        double v2 = ((double)((k / side) % side) + bn__rng_uniform(&r)) / side;
        double x[3], d[3];
        bn_hit h;
        double p1 = bn__rng_uniform(&r), p2 = bn__rng_uniform(&r);   /* in this order on every compiler */
        bn__poly_sample(corners, pa->ncorners, p1, p2, x);
        bn_v3_cosine_dir(pa->normal, t, b, u2, v2, d);
        bn_v3_madd(x, eps, pa->normal, x);
        hits += bn_rt_intersect(rt, x, d, 0, INFINITY, &h) && h.front && h.patch != i;
    }
    return hits;
}

double bn_ff_row_sum_exact(const bn_scene *s, const bn_rt *rt, size_t i, int min_rays, int max_rays, uint64_t seed,
                           double *se)
{
    int rays = min_rays, hits = bn__row_hits(rt, s, i, rays, seed);
    if (hits > 0 && hits < rays && max_rays > rays) {   /* mixed: more rays, afresh */
        rays = max_rays;
        hits = bn__row_hits(rt, s, i, rays, seed);
    }
    double p = (double)hits / rays;
    if (se)
        *se = sqrt(p * (1 - p) / rays);
    return p;
}

static int bn__cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* The q-quantile of sorted v[0..n-1] (nearest rank). */
static double bn__quantile(const double *v, size_t n, double q)
{
    size_t k = (size_t)floor(q * (double)(n - 1) + 0.5);
    return v[k < n ? k : n - 1];
}

/* The distribution of dev[0..m-1] into out (sorts dev). */
static void bn__rowsum_summary(double *dev, const double *se, const size_t *row, size_t m, bn_row_sum_check *out)
{
    size_t worst = 0;
    for (size_t k = 0; k < m; k++) {
        /* 2 standard errors of a difference of two such estimates (a row normalised to one: the
         * hierarchy's), sqrt(2) times this one's */
        out->within_1pct += fabs(dev[k]) <= 0.01 + 2.83 * se[k];
        out->above_5pct += dev[k] > 0.05 + 2.83 * se[k];
        if (dev[k] > dev[worst])
            worst = k;
    }
    out->within_1pct /= (double)m;
    out->worst_row = row[worst];
    qsort(dev, m, sizeof *dev, bn__cmp_double);
    out->dev_min = dev[0];
    out->dev_p01 = bn__quantile(dev, m, 0.01);
    out->dev_p50 = bn__quantile(dev, m, 0.5);
    out->dev_p99 = bn__quantile(dev, m, 0.99);
    out->dev_max = dev[m - 1];
}

bn_status bn_ff_row_sum_check(const bn_scene *s, const bn_rt *rt, const double *row_sums, size_t max_rows, int rays,
                              uint64_t seed, int threads, bn_row_sum_check *out, double *exact, bn_error *err)
{
    size_t n, m, stride;
    bn_scene_patches(s, &n);
    memset(out, 0, sizeof *out);
    if (rays < 1 || max_rows < 1)
        return bn_error_set(err, BN_EUSAGE, "row-sum check: %d rays on at most %zu rows", rays, max_rows);
    if (n == 0)
        return BN_OK;
    stride = (n + max_rows - 1) / max_rows;
    m = (n + stride - 1) / stride;
    double *dev = bn__malloc_array(m, sizeof(double)), *se = bn__malloc_array(m, sizeof(double));
    size_t *row = bn__malloc_array(m, sizeof(size_t)), closed = 0;
    if (!dev || !se || !row) {
        free(dev);
        free(se);
        free(row);
        return bn_error_set(err, BN_ENOMEM, "row-sum check: out of memory for %zu rows", m);
    }
    int prev = bn__threads_begin(threads);
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : closed)
    for (size_t k = 0; k < m; k++) {
        int hits = bn__row_hits(rt, s, k * stride, rays, seed);
        double p = (double)hits / rays;
        row[k] = k * stride;
        dev[k] = row_sums[k * stride] - p;
        se[k] = sqrt(p * (1 - p) / rays);
        if (exact)
            exact[k] = p;
        closed += hits == rays;
    }
    bn__threads_end(prev);
    out->rows = m;
    out->stride = stride;
    out->rays = rays;
    out->closed = closed;
    bn__rowsum_summary(dev, se, row, m, out);
    free(dev);
    free(se);
    free(row);
    return bn_interrupted() != BN_OK ? bn_error_set(err, bn_interrupted(), "row-sum check interrupted") : BN_OK;
}
