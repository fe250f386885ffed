/* Form-factor benchmark: assembly throughput (pairs/s, shadow rays/s) of each method on the
 * Cornell box beside the raw Embree ray rates (random incoherent occlusion and closest-hit rays
 * between points on the same scene's patches) measured in the same run. The shadow-ray part of
 * `analytic` is isolated as the marginal cost of rays: (t(S=64) - t(S=1)) / (rays(64) - rays(1)).
 * The raw rates are medians of runs before and after the assemblies (a shared machine).
 * Prints a markdown table. Not a test.
 * usage: ff_bench [--quick] [--scene FILE] [--unit m|cm|mm] [--patches N]                      */
#include "bounce/formfactor.h"
#include "bounce/rt.h"
#include "bounce/pipeline.h"
#include "base/internal.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* A uniform point on a random patch (patches chosen by area) and its normal. */
static void random_point(const bn_scene *s, const double *cdf, size_t n, bn__rng *r, double p[3], double nrm[3])
{
    size_t np, nv, lo = 0, hi = n - 1;
    const bn_patch *pa = bn_scene_patches(s, &np);
    const double *pv = bn_scene_patch_vertices(s, &nv);
    double u = bn__rng_uniform(r) * cdf[n - 1], a = bn__rng_uniform(r), b = bn__rng_uniform(r);
    const double *c0, *c1, *c2;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        if (cdf[mid] < u)
            lo = mid + 1;
        else
            hi = mid;
    }
    c0 = pv + 3 * pa[lo].corner[0];
    c1 = pv + 3 * pa[lo].corner[1];
    c2 = pv + 3 * pa[lo].corner[2];
    if (pa[lo].ncorners == 4 && bn__rng_uniform(r) < 0.5) {
        c1 = pv + 3 * pa[lo].corner[2];
        c2 = pv + 3 * pa[lo].corner[3];
    }
    if (a + b > 1) {
        a = 1 - a;
        b = 1 - b;
    }
    for (int k = 0; k < 3; k++) {
        p[k] = c0[k] + a * (c1[k] - c0[k]) + b * (c2[k] - c0[k]);
        nrm[k] = pa[lo].normal[k];
    }
}

/* Raw rates over `nrays` random rays: occlusion through the stream API (as the assembly casts
 * them) and closest hits one at a time (as the hemisphere method does). Rays/s. */
static void raw_rates(const bn_rt *rt, const bn_scene *s, size_t nrays, double *occl, double *closest)
{
    size_t np;
    const bn_patch *pa = bn_scene_patches(s, &np);
    double *cdf = malloc(np * sizeof *cdf), acc = 0, eps = bn_rt_epsilon(rt), t0;
    enum { CH = 4096 };
    long nch = (long)((nrays + CH - 1) / CH);
    size_t hits = 0;
    for (size_t i = 0; i < np; i++)
        cdf[i] = acc += pa[i].area;
    t0 = bn__now();
#pragma omp parallel
    {
        float *org = malloc(3 * CH * sizeof(float)), *dir = malloc(3 * CH * sizeof(float)),
              *tf = malloc(CH * sizeof(float));
        unsigned char *bl = malloc(CH);
#pragma omp for schedule(static)
        for (long c = 0; c < nch; c++) {
            bn__rng r = bn__rng_make(7, (uint64_t)c, 1);
            for (size_t k = 0; k < CH; k++) {
                double p[3], q[3], n1[3], n2[3];
                random_point(s, cdf, np, &r, p, n1);
                random_point(s, cdf, np, &r, q, n2);
                for (int d = 0; d < 3; d++) {
                    org[3 * k + d] = (float)(p[d] + eps * n1[d]);
                    dir[3 * k + d] = (float)(q[d] - p[d]);
                }
                tf[k] = 0.999f;
            }
            bn_rt_occluded_batch(rt, org, dir, tf, CH, bl);
        }
        free(org);
        free(dir);
        free(tf);
        free(bl);
    }
    *occl = (double)(nch * CH) / (bn__now() - t0);
    t0 = bn__now();
#pragma omp parallel for schedule(static) reduction(+ : hits)
    for (long c = 0; c < nch; c++) {
        bn__rng r = bn__rng_make(7, (uint64_t)c, 2);
        for (size_t k = 0; k < CH; k++) {
            double p[3], n1[3], d[3], o[3], z = sqrt(bn__rng_uniform(&r)), ph = 2 * 3.14159265358979 * bn__rng_uniform(&r);
            bn_hit h;
            random_point(s, cdf, np, &r, p, n1);
            /* a cosine-weighted direction about the normal (the hemisphere method's rays) */
            {
                double t[3] = {0, 0, 0}, b[3], st = sqrt(1 - z * z);
                t[fabs(n1[0]) < 0.6 ? 0 : 1] = 1;
                b[0] = n1[1] * t[2] - n1[2] * t[1];
                b[1] = n1[2] * t[0] - n1[0] * t[2];
                b[2] = n1[0] * t[1] - n1[1] * t[0];
                {
                    double l = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
                    for (int q = 0; q < 3; q++)
                        b[q] /= l;
                }
                t[0] = b[1] * n1[2] - b[2] * n1[1];
                t[1] = b[2] * n1[0] - b[0] * n1[2];
                t[2] = b[0] * n1[1] - b[1] * n1[0];
                for (int q = 0; q < 3; q++) {
                    d[q] = st * cos(ph) * t[q] + st * sin(ph) * b[q] + z * n1[q];
                    o[q] = p[q] + eps * n1[q];
                }
            }
            hits += (size_t)bn_rt_intersect(rt, o, d, 0, INFINITY, &h);
        }
    }
    *closest = (double)(nch * CH) / (bn__now() - t0);
    (void)hits;
    free(cdf);
}

/* sampled: the analytic method's shadow rays for partly occluded pairs (--ff-visibility rays), the
 * path whose ray rate is measured here; else the exact visible part (the default, no rays). */
static int assemble(const bn_scene *s, const bn_rt *rt, bn_ff_method m, int samples, int sampled, bn_ff_diagnostics *d)
{
    bn_formfactor_opts o;
    bn_transport *k = NULL;
    bn_error err;
    bn_formfactor_opts_default(&o);
    o.method = m;
    o.samples = samples;
    if (sampled)
        o.exact_visibility = 0;
    o.quiet = 1;
    o.log.quiet = 1;
    bn_error_clear(&err);
    if (bn_formfactor_build(s, rt, &o, &k, d, &err) != BN_OK) {
        fprintf(stderr, "ff_bench: %s\n", err.msg);
        return 1;
    }
    bn_transport_destroy(k);
    return 0;
}

/* The exact visible part against shadow rays (the default against --ff-visibility rays), timed in
 * turn n times each on a shared machine: da and dx keep the runs of median time. */
static int exact_vs_rays(const bn_scene *s, const bn_rt *rt, int n, bn_ff_diagnostics *da, bn_ff_diagnostics *dx)
{
    bn_ff_diagnostics ra[5], ex[5];
    double ta[5], tx[5], ma, mx;
    n = n > 5 ? 5 : n;
    for (int r = 0; r < n; r++) {
        if (assemble(s, rt, BN_FF_ANALYTIC, 0, 1, &ra[r]) || assemble(s, rt, BN_FF_ANALYTIC, 0, 0, &ex[r]))
            return 1;
        ta[r] = ra[r].seconds;
        tx[r] = ex[r].seconds;
    }
    ma = median(ta, n);
    mx = median(tx, n);
    *da = ra[0];
    *dx = ex[0];
    for (int r = 1; r < n; r++) {
        if (ra[r].seconds == ma)
            *da = ra[r];
        if (ex[r].seconds == mx)
            *dx = ex[r];
    }
    return 0;
}

int main(int argc, char **argv)
{
    const char *scene_path = BN_SOURCE_DIR "/meshes/cornell-box.obj";
    int quick = 0, reps;
    size_t patches = 0, np, pairs, nrays;
    bn_unit unit = BN_UNIT_MM;
    bn_pipeline_opts po;
    bn_pipeline pl;
    bn_scene *s;
    bn_rt *rt;
    bn_error err;
    double occl[5], clos[5], ro, rc;
    bn_ff_diagnostics da = {0}, d1, d64, dm, dh, dx = {0};

    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--quick") == 0)
            quick = 1;
        else if (strcmp(argv[i], "--scene") == 0 && i + 1 < argc)
            scene_path = argv[++i];
        else if (strcmp(argv[i], "--patches") == 0 && i + 1 < argc)
            patches = (size_t)atol(argv[++i]);
        else if (strcmp(argv[i], "--unit") == 0 && i + 1 < argc) {
            if (bn_unit_parse(argv[++i], &unit) != 0) {
                fprintf(stderr, "ff_bench: bad unit\n");
                return 2;
            }
        } else {
            fprintf(stderr, "usage: ff_bench [--quick] [--scene FILE] [--unit m|cm|mm] [--patches N]\n");
            return 2;
        }
    }
    if (!patches)
        patches = quick ? 300 : BN_DEFAULT_PATCHES;
    reps = quick ? 3 : 5;
    nrays = quick ? (size_t)1 << 18 : (size_t)1 << 21;
    /* The pipeline's first stage (load, mesh); the rays are kept here, as every assembly below and
     * the raw rates share them. */
    bn_pipeline_opts_default(&po);
    po.load.unit = unit;
    po.load.log.quiet = 1;
    po.mesh.target_patches = patches;
    bn_error_clear(&err);
    if (bn_pipeline_scene(scene_path, &po, &pl, &err) != BN_OK || bn_rt_create(pl.scene, 0, &rt, &err) != BN_OK) {
        fprintf(stderr, "ff_bench: %s\n", err.msg);
        return 1;
    }
    s = pl.scene;
    bn_scene_patches(s, &np);
    pairs = np * (np - 1) / 2;

    /* The machine may be shared: raw rates are measured between the assemblies (reps rounds of
     * raw, exact and rays in turn 3 times, analytic S=1, analytic S=64, montecarlo, hemisphere, then
     * raw once more) and their median is the limit. */
    {
        int nr = 0;
        for (int r = 0; r < reps; r++) {
            raw_rates(rt, s, nrays, &occl[nr], &clos[nr]);
            nr++;
            if (r == reps / 2 &&
                (exact_vs_rays(s, rt, 3, &da, &dx) || assemble(s, rt, BN_FF_ANALYTIC, 1, 1, &d1) ||
                 assemble(s, rt, BN_FF_ANALYTIC, 64, 1, &d64) || assemble(s, rt, BN_FF_MONTECARLO, 0, 1, &dm) ||
                 assemble(s, rt, BN_FF_HEMISPHERE, 0, 1, &dh)))
                return 1;
        }
        ro = median(occl, nr);
        rc = median(clos, nr);
    }

    printf("Scene %s, %zu patches (%zu unordered pairs, %zu facing), %d threads. Raw rates: medians of %d runs "
           "of %zu random rays between points on the patches.\n\n",
           scene_path, np, pairs, da.pairs_nonzero, omp_get_max_threads(), reps, nrays);
    printf("| figure | value | limit measured in this run | ratio |\n|---|---|---|---|\n");
    printf("| raw Embree occlusion rays (stream API, incoherent) | %.3g rays/s | | |\n", ro);
    printf("| raw Embree closest-hit rays (cosine-weighted, one at a time) | %.3g rays/s | | |\n", rc);
    printf("| analytic, exact visible part (default; medians of 3 runs in turn with the rays'): time; largest row sum "
           "| %.3f s; %.9f | shadow rays (below) %.3f s; "
           "%.9f | %.2f |\n",
           dx.seconds, dx.row_sum_max, da.seconds, da.row_sum_max, dx.seconds / da.seconds);
    printf("| analytic with shadow rays (--ff-visibility rays, %d rays/tested pair): time | %.3f s | | |\n",
           da.samples, da.seconds);
    printf("| analytic: pairs/s (all unordered pairs) | %.3g | | |\n", (double)pairs / da.seconds);
    printf("| analytic: shaft-culled pairs (no rays) | %zu of %zu facing | | %.2f |\n", da.pairs_culled,
           da.pairs_nonzero, da.pairs_nonzero ? (double)da.pairs_culled / (double)da.pairs_nonzero : 0);
    printf("| analytic: kernel evaluations/s | %.3g | | |\n", (double)da.quad_evals / da.seconds);
    printf("| analytic: rays / whole assembly time | %.3g rays/s | raw occlusion %.3g | %.2f |\n",
           da.rays_per_second, ro, da.rays_per_second / ro);
    {
        double dt = d64.seconds - d1.seconds, dr = (double)d64.rays - (double)d1.rays, marg = dt > 0 ? dr / dt : 0;
        printf("| analytic: marginal shadow-ray rate, (t(64) - t(1)) / (rays(64) - rays(1)) | %.3g rays/s | raw "
               "occlusion %.3g | %.2f |\n",
               marg, ro, marg / ro);
    }
    printf("| montecarlo (%d pairs/pair): time | %.3f s; %.3g pairs/s; %.3g rays/s | raw occlusion %.3g | %.2f |\n",
           dm.samples, dm.seconds, (double)pairs / dm.seconds, dm.rays_per_second, ro, dm.rays_per_second / ro);
    printf("| hemisphere (%d rays/patch): time | %.3f s; %.3g rays/s | raw closest-hit %.3g | %.2f |\n", dh.samples,
           dh.seconds, dh.rays_per_second, rc, dh.rays_per_second / rc);
    bn_rt_destroy(rt);
    bn_pipeline_free(&pl);
    return 0;
}
