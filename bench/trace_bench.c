/* Path-tracer benchmark: rays/s of the per-patch tracer beside the raw Embree ray rate measured in
 * the same run, and the time the tracer needs to reach radiosity's per-patch accuracy on the
 * Cornell box (equal error). Prints markdown. Not a test.
 *
 * Raw rate: the tracer's own mix without the tracer around it: per sample one closest-hit ray in a
 * cosine direction from a uniform point on a patch and one occlusion ray to a uniform point on the
 * light, through the same bn_rt calls, OpenMP over all threads.
 * Equal error: a high-spp tracer run is the reference (unbiased); radiosity's per-patch error is
 * e_rad^2 = mean_i ((R_i - T_i)^2 - se_i^2) / T_i^2 over non-emitting patches (L summed over R, G, B,
 * the reference's own noise subtracted); the tracer's error at spp s is its RMS relative standard
 * error, which falls as 1/sqrt(s), so it reaches e_rad at s* = s0 (se0 / e_rad)^2, taking t0 s* / s0. */
#include "bounce/formfactor.h"
#include "bounce/solve.h"
#include "bounce/trace.h"
#include "bounce/pipeline.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <omp.h>
#include <string.h>

static void die(const char *what, const bn_error *err)
{
    fprintf(stderr, "trace_bench: %s: %s\n", what, err->msg);
    exit(1);
}

/* Raw Embree rate for the tracer's ray mix; returns rays/s. */
static double raw_rate(const bn_rt *rt, const bn_scene *s, size_t nsamples)
{
    size_t np, npv, light = (size_t)-1;
    const bn_patch *p = bn_scene_patches(s, &np);
    const double *pv = bn_scene_patch_vertices(s, &npv);
    double eps = bn_rt_epsilon(rt), t0;
    unsigned long long rays = 0, hits = 0;
    for (size_t i = 0; i < np && light == (size_t)-1; i++) {
        const bn_material *m = bn_patch_material(s, i);
        if (m->Le[0] + m->Le[1] + m->Le[2] > 0)
            light = i;
    }
    t0 = bn__now();
#pragma omp parallel for schedule(dynamic, 4096) reduction(+ : rays, hits)
    for (size_t k = 0; k < nsamples; k++) {
        bn__rng r = bn__rng_make(99, k, 0);
        size_t i = (size_t)(bn__rng_uniform(&r) * (double)np) % np;
        const double *a = pv + 3 * p[i].corner[0], *b = pv + 3 * p[i].corner[1], *c = pv + 3 * p[i].corner[2];
        double u = sqrt(bn__rng_uniform(&r)), v = bn__rng_uniform(&r), x[3], o[3], d[3], t1[3], t2[3];
        double r1 = bn__rng_uniform(&r), phi = 2 * BN_PI * bn__rng_uniform(&r), rad = sqrt(r1);
        const double *n = p[i].normal;
        bn_hit h;
        for (int q = 0; q < 3; q++)
            x[q] = (1 - u) * a[q] + u * (1 - v) * b[q] + u * v * c[q];
        bn_v3_madd(x, eps, n, o);
        /* Cosine direction (the basis path.c uses). */
        {
            double lx = rad * cos(phi), ly = rad * sin(phi), lz = sqrt(fmax(0.0, 1 - r1));
            bn_v3_basis(n, t1, t2);
            for (int q = 0; q < 3; q++)
                d[q] = lx * t1[q] + ly * t2[q] + lz * n[q];
        }
        hits += (unsigned long long)bn_rt_intersect(rt, o, d, 0, INFINITY, &h);
        rays++;
        if (light != (size_t)-1) {
            const double *la = pv + 3 * p[light].corner[0], *lb = pv + 3 * p[light].corner[1],
                         *lc = pv + 3 * p[light].corner[2];
            double y[3], len;
            u = sqrt(bn__rng_uniform(&r));
            v = bn__rng_uniform(&r);
            for (int q = 0; q < 3; q++)
                y[q] = (1 - u) * la[q] + u * (1 - v) * lb[q] + u * v * lc[q];
            bn_v3_sub(y, o, d);
            len = bn_v3_normalize(d);
            if (len > 2 * eps) {
                hits += (unsigned long long)bn_rt_occluded(rt, o, d, 0, len - eps);
                rays++;
            }
        }
    }
    (void)hits;
    return (double)rays / (bn__now() - t0);
}

static double median3(double a, double b, double c)
{
    return a > b ? (b > c ? b : (a > c ? c : a)) : (a > c ? a : (b > c ? c : b));
}

int main(int argc, char **argv)
{
    int quick = argc > 1 && strcmp(argv[1], "--quick") == 0;
    size_t patches = quick ? 300 : 1200, spp0 = quick ? 64 : 128, spp_ref = quick ? 1024 : 4096;
    size_t nraw = quick ? 400000 : 2000000, n;
    bn_pipeline_opts po;
    bn_pipeline pl;
    bn_scene *s;
    bn_rt *rt;
    bn_trace_opts to;
    bn_trace_patches ref, run[3];
    bn_error err;
    double t_mesh, t_ff, t_solve, raw[3], pt[3], raw_m, pt_m, e_rad2 = 0, se2 = 0, e_rad, se0, t0s[3];
    size_t cnt = 0;
    const bn_patch *p;
    char path[1024];

    snprintf(path, sizeof path, "%s/meshes/cornell-box.obj", BN_SOURCE_DIR);
    /* Radiosity through the pipeline every command uses: load, mesh, rays + K, solve. */
    bn_pipeline_opts_default(&po);
    po.load.unit = BN_UNIT_MM;
    po.load.log = (bn_log){NULL, NULL, 1};
    po.mesh.target_patches = patches;
    po.ff.quiet = 1;
    po.solve.quiet = 1;
    po.solve.bounces = -1;
    po.solve.log_sink = (bn_log){NULL, NULL, 1};
    po.keep_rt = 1;
    if (bn_pipeline_run(path, &po, &pl, &err) != BN_OK)
        die("radiosity", &err);
    s = pl.scene;
    rt = pl.rt;
    p = bn_scene_patches(s, &n);
    t_mesh = pl.seconds_mesh;
    t_ff = pl.seconds_operator;
    t_solve = pl.seconds_solve;

    /* Ray rates: raw mix and the tracer, three alternating runs each, medians. */
    bn_trace_opts_default(&to);
    to.quiet = 1;
    to.bounces = 3;
    for (int r = 0; r < 3; r++) {
        raw[r] = raw_rate(rt, s, nraw);
        to.spp = spp0;
        to.seed = 1 + (uint64_t)r;
        if (bn_trace_patches_run(rt, &to, &run[r], &err) != BN_OK)
            die("trace", &err);
        pt[r] = (double)run[r].rays / run[r].seconds;
        t0s[r] = run[r].seconds;
    }
    raw_m = median3(raw[0], raw[1], raw[2]);
    pt_m = median3(pt[0], pt[1], pt[2]);

    /* Reference and radiosity's per-patch error. */
    to.spp = spp_ref;
    to.seed = 1000;
    if (bn_trace_patches_run(rt, &to, &ref, &err) != BN_OK)
        die("trace reference", &err);
    {
        size_t lL = (size_t)ref.nlayers - 1;
        for (size_t i = 0; i < n; i++) {
            const bn_material *m = bn_patch_material(s, i);
            double R = 0, T = 0, S2 = 0, T0 = 0, S0 = 0;
            if (m->Le[0] + m->Le[1] + m->Le[2] > 0)
                continue;
            for (int c = 0; c < 3; c++) {
                size_t q = (lL * n + i) * 3 + (size_t)c;
                R += pl.res.L[3 * i + (size_t)c];
                T += ref.mean[q];
                S2 += ref.se[q] * ref.se[q];   /* channels of one patch: summed variance (upper bound) */
                T0 += run[1].mean[q];
                S0 += run[1].se[q];
            }
            (void)T0;
            if (T <= 0)
                continue;
            e_rad2 += ((R - T) * (R - T) - S2) / (T * T);
            se2 += (S0 * S0) / (T * T);   /* run's se of the channel sum (<= sum of se) */
            cnt++;
        }
    }
    e_rad = sqrt(fmax(e_rad2 / (double)cnt, 0));
    se0 = sqrt(se2 / (double)cnt);
    {
        double t0 = median3(t0s[0], t0s[1], t0s[2]);
        double s_star = (double)spp0 * (se0 / e_rad) * (se0 / e_rad);
        double t_star = t0 * s_star / (double)spp0, t_rad = t_mesh + t_ff + t_solve;
        printf("Cornell box (meshes/cornell-box.obj, mm), %zu patches, %d threads; bounce %s.\n\n", n,
               omp_get_max_threads(), bn_version());
        printf("| figure | value | limit or alternative (same run) | ratio |\n|---|---|---|---|\n");
        printf("| path tracer, per-patch estimator (MIS, %zu spp, median of 3) | %.3g rays/s | raw Embree, same ray mix "
               "%.3g rays/s | %.2f |\n",
               spp0, pt_m, raw_m, pt_m / raw_m);
        printf("| radiosity: mesh + analytic form factors + Gauss-Seidel (tol 1e-6) | %.2f s (%.2f + %.2f + %.3f) | | |\n",
               t_rad, t_mesh, t_ff, t_solve);
        printf("| radiosity per-patch RMS relative error of L (vs tracer at %zu spp) | %.3g | | |\n", spp_ref, e_rad);
        printf("| tracer RMS relative standard error at %zu spp | %.3g in %.2f s | | |\n", spp0, se0, t0);
        printf("| tracer time to radiosity's per-patch error (spp %.0f, extrapolated as 1/sqrt(spp)) | %.3g s | "
               "radiosity %.2f s | %.2f |\n",
               s_star, t_star, t_rad, t_star / t_rad);
        printf("\nThe radiosity error here is its discretisation error at this mesh (patch-constant, contact corners of "
               "the blocks dominate); the tracer's error is pure noise. Equal-error time compares the whole radiosity "
               "pipeline with the tracer's samples alone (both on the same Embree scene).\n");
    }
    for (int r = 0; r < 3; r++)
        bn_trace_patches_free(&run[r]);
    bn_trace_patches_free(&ref);
    bn_pipeline_free(&pl);
    (void)p;
    return 0;
}
