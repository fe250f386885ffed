/* The final gather at points on the surfaces (bn_gather_points): what a pixel's sample gets where it
 * meets a surface, at a given point of a given patch instead: a bake's vertices take their values
 * from it, so a vertex bake shows what the images show (a sharp shadow edge, direct light in closed
 * form) rather than the patches' means. */
#include "gather/gather_internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define BN__GATHER_TAG_POINT 0x706f696e74ULL   /* "point": its streams apart from the pixels' */

/* Point i's layers into out (layer-major: out[(l * npts + i) * 3 + c]): E, KE, K^2 E .. K^n E, rest, L. */
static void bn__gather_point(const bn__gather *G, const double *x, size_t patch, size_t i, size_t npts, uint64_t seed,
                             double *hv, double *out, bn_gather_stats *st)
{
    bn_hit h = {patch, 0, {x[0], x[1], x[2]}, 1};
    double acc[6] = {0, 0, 0, 0, 0, 0}, rho[3], L[3] = {0, 0, 0};
    int n = G->n;
    bn__rng r = bn__rng_make(seed ^ BN__GATHER_STREAM ^ BN__GATHER_TAG_POINT, i, 0);
    memset(hv, 0, (size_t)(n + 1) * 3 * sizeof(double));
    bn__shade(G, &h, &r, acc, hv, rho, st);
    for (int c = 0; c < 3; c++) {
        double v[66];   /* E, KE, K^2 E .. K^n E, rest (n <= 20 terms: bn__gather_check's bound) */
        v[0] = acc[c];
        v[1] = acc[3 + c];
        for (int k = 2; k <= n; k++)   /* K^k E = rho x the gathered K^(k-1) E */
            v[k] = rho[c] * hv[3 * (k - 2) + c];
        v[n + 1] = rho[c] * (hv[3 * (n - 1) + c] + hv[3 * n + c]);   /* rest: K^n E + rest gathered */
        for (int l = 0; l <= n + 1; l++) {   /* the direct light's unbiased estimator at a hit near a shadow's
                                                  edge can dip below 0: a radiance cannot (bias of that size) */
            v[l] = fmax(0.0, v[l]);
            out[((size_t)l * npts + i) * 3 + (size_t)c] = v[l];
            L[c] += v[l];
        }
        out[((size_t)(n + 2) * npts + i) * 3 + (size_t)c] = L[c];
    }
}

static bn_status bn__gather_points_body(const bn_rt *rt, const double *const *terms, int n, const double *rest,
                                        const double *x, const size_t *patch, size_t npts, const bn_gather_opts *o,
                                        double *out, bn_gather_stats *stats, bn_error *err)
{
    bn__gather G;
    bn_status st;
    int bad = 0, stop = 0;
    memset(&G, 0, sizeof G);
    if (n < 1 || n > 20)
        return bn_error_set(err, BN_EUSAGE, "gather at points: %d terms kept (1 to 20: KE at least)", n);
    if ((st = bn__gather_init(&G, rt, terms, n, rest, o, err)) != BN_OK) {
        bn__gather_free(&G);
        return st;
    }
#pragma omp parallel reduction(+ : bad)
    {
        double *hv = malloc((size_t)(n + 1) * 3 * sizeof *hv);
        bn_gather_stats ts;
        memset(&ts, 0, sizeof ts);
        bad += !hv;
#pragma omp for schedule(dynamic, 64)
        for (size_t i = 0; i < npts; i++) {
            int halt;
#pragma omp atomic read
            halt = stop;
            if (halt || !hv)
                continue;
            if (i % 64 == 0 && bn_interrupted() != BN_OK) {   /* Ctrl-C: a room's bake gathers for minutes */
#pragma omp atomic write
                stop = 1;
                continue;
            }
            bn__gather_point(&G, x + 3 * i, patch[i], i, npts, o->seed, hv, out, &ts);
        }
        free(hv);
#pragma omp critical(bn__gather_points_stats)
        {
            stats->shadow_rays += ts.shadow_rays;
            stats->gather_rays += ts.gather_rays;
        }
    }
    stats->emitters = G.faces;
    stats->lights = G.nem;
    stats->hit_direct = G.hit_direct;
    stats->light_tree = G.tree != NULL;
    bn__gather_free(&G);
    if (bad)
        return bn_error_set(err, BN_ENOMEM, "gather at points: out of memory for a thread's buffers");
    if (stop)
        return bn_error_set(err, bn_interrupted(), "gather at points: interrupted");
    for (size_t k = 0; k < (size_t)(n + 3) * npts * 3; k++)
        if (!isfinite(out[k]))
            return bn_error_set(err, BN_ENUMERIC, "gather at points: point %zu's value %g is not finite",
                                (k / 3) % npts, out[k]);
    return BN_OK;
}

bn_status bn_gather_points(const bn_rt *rt, const double *const *terms, int n, const double *rest, const double *x,
                           const size_t *patch, size_t npts, const bn_gather_opts *o, double *out,
                           bn_gather_stats *stats, bn_error *err)
{
    bn_gather_opts def;
    bn_gather_stats mine;
    double t0 = bn__now();
    if (!o) {
        bn_gather_opts_default(&def);
        o = &def;
    }
    if (!stats)
        stats = &mine;
    memset(stats, 0, sizeof *stats);
    int prev = bn__threads_begin(o->threads);
    bn_status st = bn__gather_points_body(rt, terms, n, rest, x, patch, npts, o, out, stats, err);
    bn__threads_end(prev);
    stats->seconds = bn__now() - t0;
    return st;
}
