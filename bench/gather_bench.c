/* The final gather against the path tracer at equal per-pixel error (issue 14): the Cornell box at
 * WxW pixels, a long path-traced reference (bounce's own tracer, cached in a file), then the median
 * per-pixel relative error of L (luminance) and the time to it for each gather setting (mesh, light
 * rays, gather rays, camera samples; time = load, mesh, K, solve and gather) and for the tracer at a
 * few sample counts, extrapolated to the target by its 1/sqrt(spp) law.
 *
 * The reference's own noise is taken out: per pixel, err^2 = max(0, (x - ref)^2 - var_ref), so the
 * median measures the distance to the converged image, not to the reference's noise.
 *
 * usage: gather_bench [--size W] [--ref-spp N] [--ref-cache FILE] [--target E] [--quick] [--smooth]
 * (--smooth: the gather's hits and the patch images read values interpolated across patches) */
#include "ref_exr.h"
#include "bounce/gather.h"
#include "bounce/pipeline.h"
#include "bounce/trace.h"
#include "bounce/bake.h"
#include "base/internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef BN_SOURCE_DIR
#define BN_SOURCE_DIR "."
#endif

typedef struct ref_img {
    int w, h;
    float *L, *var;   /* 3wh each */
    double seconds;
    size_t spp;
} ref_img;

/* bench/ref_exr.c's median per-pixel error against r; *raw without the noise correction, *ref_se
 * the reference's own median standard error. */
static double median_err(const ref_img *r, const float *L, double *raw, double *ref_se)
{
    exr_img ri = {r->w, r->h, r->L, r->var};
    double e[3];
    exr_median_err(&ri, L, e);
    if (raw)
        *raw = e[1];
    if (ref_se)
        *ref_se = e[2];
    return e[0];
}

static void camera(const bn_scene *s, const char *path, int w, bn_camera *cam)
{
    bn_error err;
    bn_camera_default(s, cam);
    if (bn_camera_load_sidecar(path, cam, NULL, &err) != BN_OK) {
        fprintf(stderr, "gather_bench: %s\n", err.msg);
        exit(1);
    }
    cam->width = cam->height = w;
    cam->spp = 1;
}

static bn_status run_pipeline(const char *path, size_t patches, bn_pipeline *p, bn_error *err)
{
    bn_pipeline_opts o;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.load.unit = BN_UNIT_MM;
    o.ff.quiet = 1;
    o.solve.quiet = 1;
    o.solve.bounces = 3;
    o.keep_rt = 1;
    o.mesh.target_patches = patches;
    return bn_pipeline_run(path, &o, p, err);
}

/* The tracer's L image at `spp`, its time. */
static int trace_L(const bn_rt *rt, const bn_camera *cam, size_t spp, uint64_t seed, float **L, float **var,
                   double *seconds)
{
    bn_trace_opts to;
    bn_trace_image img;
    bn_error err;
    size_t n = (size_t)cam->width * (size_t)cam->height * 3, off;
    double t0 = bn__now();
    bn_trace_opts_default(&to);
    to.spp = spp;
    to.seed = seed;
    to.quiet = 1;
    if (bn_trace_image_run(rt, cam, &to, &img, &err) != BN_OK) {
        fprintf(stderr, "gather_bench: trace: %s\n", err.msg);
        return 0;
    }
    *seconds = bn__now() - t0;
    off = (size_t)(img.nlayers - 1) * n;   /* L is the last layer */
    *L = malloc(n * sizeof(float));
    memcpy(*L, img.mean + off, n * sizeof(float));
    if (var) {
        *var = malloc(n * sizeof(float));
        memcpy(*var, img.var + off, n * sizeof(float));
    }
    bn_trace_image_free(&img);
    return 1;
}

static int ref_load(const char *file, unsigned long long key, ref_img *r)
{
    FILE *fp = fopen(file, "rb");
    unsigned long long k = 0;
    size_t n;
    if (!fp)
        return 0;
    if (fread(&k, sizeof k, 1, fp) != 1 || k != key || fread(&r->seconds, sizeof r->seconds, 1, fp) != 1) {
        fclose(fp);
        return 0;
    }
    n = (size_t)3 * (size_t)r->w * (size_t)r->h;
    r->L = malloc(n * sizeof(float));
    r->var = malloc(n * sizeof(float));
    if (fread(r->L, sizeof(float), n, fp) != n || fread(r->var, sizeof(float), n, fp) != n) {
        fclose(fp);
        free(r->L);
        free(r->var);
        return 0;
    }
    fclose(fp);
    return 1;
}

static void ref_save(const char *file, unsigned long long key, const ref_img *r)
{
    char tmp[4096];
    size_t n = (size_t)3 * (size_t)r->w * (size_t)r->h;
    FILE *fp;
    snprintf(tmp, sizeof tmp, "%s.tmp", file);
    if (!(fp = fopen(tmp, "wb")))
        return;
    fwrite(&key, sizeof key, 1, fp);
    fwrite(&r->seconds, sizeof r->seconds, 1, fp);
    fwrite(r->L, sizeof(float), n, fp);
    fwrite(r->var, sizeof(float), n, fp);
    if (fclose(fp) == 0)
        rename(tmp, file);
}

int main(int argc, char **argv)
{
    const char *path = BN_SOURCE_DIR "/meshes/cornell-box.obj", *cache = NULL;
    int w = 256, quick = 0, smooth = 0;
    size_t ref_spp = 4096;
    double target = 0.01;
    bn_pipeline base;
    bn_error err;
    bn_camera cam;
    ref_img ref;
    unsigned long long key;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--size") && i + 1 < argc)
            w = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--ref-spp") && i + 1 < argc)
            ref_spp = (size_t)atoll(argv[++i]);
        else if (!strcmp(argv[i], "--ref-cache") && i + 1 < argc)
            cache = argv[++i];
        else if (!strcmp(argv[i], "--target") && i + 1 < argc)
            target = atof(argv[++i]);
        else if (!strcmp(argv[i], "--quick"))
            quick = 1;
        else if (!strcmp(argv[i], "--smooth"))
            smooth = 1;
        else {
            fprintf(stderr, "usage: gather_bench [--size W] [--ref-spp N] [--ref-cache FILE] [--target E] [--quick] [--smooth]\n");
            return 2;
        }
    }
    /* the reference: the tracer on the scene's default mesh (the tracer's answer does not depend on it) */
    if (run_pipeline(path, 300, &base, &err) != BN_OK) {
        fprintf(stderr, "gather_bench: %s\n", err.msg);
        return 1;
    }
    camera(base.scene, path, w, &cam);
    cam.spp = 1;
    memset(&ref, 0, sizeof ref);
    ref.w = ref.h = w;
    ref.spp = ref_spp;
    key = bn_scene_digest(base.scene) ^ ((unsigned long long)w << 40) ^ ((unsigned long long)ref_spp << 8) ^ 0x9e37;
    if (!cache || !ref_load(cache, key, &ref)) {
        bn_camera rc = cam;
        float *L = NULL, *var = NULL;
        fprintf(stderr, "gather_bench: reference: the tracer at %zu spp, %dx%d...\n", ref_spp, w, w);
        if (!trace_L(base.rt, &rc, ref_spp, 7777, &L, &var, &ref.seconds))
            return 1;
        ref.L = L;
        ref.var = var;
        if (cache)
            ref_save(cache, key, &ref);
    }
    double ref_se;
    (void)median_err(&ref, ref.L, NULL, &ref_se);
    printf("Reference: bounce's tracer, %zu samples per pixel (%.0f s), %dx%d; median per-pixel relative standard "
           "error of its L %.3f%%. Errors below are the median over pixels of |L - L_ref| / L_ref in luminance with the "
           "reference's variance taken out (err^2 = (L - L_ref)^2 - var_ref); raw: without that.\n\n",
           ref_spp, ref.seconds, w, w, 100 * ref_se);

    /* the gather: settings */
    {
        static const size_t patches_q[] = {300, 1200}, patches_f[] = {300, 1200};
        static const int light_f[] = {4, 16}, hemi_f[] = {16, 64, 256}, spp_f[] = {1, 4}, filt_f[] = {0, 2, 4};
        const size_t *P = quick ? patches_q : patches_f;
        size_t nP = 2;
        double best_t = INFINITY;
        char best[160] = "none";
        printf("| patches | light rays | gather rays | camera spp | filter px | solve s | gather s | total s | median error | raw |\n");
        printf("|---|---|---|---|---|---|---|---|---|---|\n");
        for (size_t ip = 0; ip < nP; ip++) {
            bn_pipeline p;
            double t0 = bn__now(), ts;
            memset(&p, 0, sizeof p);
            if (run_pipeline(path, P[ip], &p, &err) != BN_OK) {
                fprintf(stderr, "gather_bench: %s\n", err.msg);
                return 1;
            }
            ts = bn__now() - t0;
            bn_bake *bake = NULL;
            if (smooth && bn_bake_create(p.scene, BN_BAKE_DEFAULT_CREASE, &bake, &err) != BN_OK) {
                fprintf(stderr, "gather_bench: %s\n", err.msg);
                return 1;
            }
            if (bake)
                fprintf(stderr, "gather_bench: %zu enclosed patches\n", bn_bake_exclude_enclosed(bake, p.rt));
            {   /* --gather none: each pixel the value of the patch it sees */
                bn_image fl;
                const double *Lp = p.res.L;
                double e, raw, tr;
                bn_image_alloc(&fl, w, w, &err);
                t0 = bn__now();
                if (bn_image_render(p.rt, &cam, &Lp, 1, bake, 1, 0, &fl, &err) != BN_OK) {
                    fprintf(stderr, "gather_bench: %s\n", err.msg);
                    return 1;
                }
                tr = bn__now() - t0;
                e = median_err(&ref, fl.rgb, &raw, NULL);
                printf("| %zu | patch values (--gather none) | | 1 | | %.2f | %.2f | %.2f | %.2f%% | %.2f%% |\n", p.n, ts,
                       tr, ts + tr, 100 * e, 100 * raw);
                bn_image_free(&fl);
            }
            for (int il = 0; il < 2; il++)
                for (int ih = 0; ih < 3; ih++)
                    for (int is = 0; is < 2; is++)
                    for (int iq = 0; iq < 3; iq++) {
                        bn_camera c = cam;
                        bn_image img[6];
                        bn_gather_opts go;
                        const double *terms[4] = {p.res.terms[0], p.res.terms[1], p.res.terms[2], p.res.terms[3]};
                        double tg, e, raw;
                        if (quick && (il == 0 || is == 1))
                            continue;
                        c.spp = spp_f[is];
                        for (int l = 0; l < 6; l++)
                            bn_image_alloc(&img[l], w, w, &err);
                        bn_gather_opts_default(&go);
                        go.light_samples = light_f[il];
                        go.hemi_samples = hemi_f[ih];
                        go.filter = filt_f[iq];
                        go.smooth = bake;
                        go.quiet = 1;
                        t0 = bn__now();
                        if (bn_gather_render(p.rt, &c, terms, 3, p.rest, &go, img, NULL, &err) != BN_OK) {
                            fprintf(stderr, "gather_bench: %s\n", err.msg);
                            return 1;
                        }
                        tg = bn__now() - t0;
                        e = median_err(&ref, img[5].rgb, &raw, NULL);
                        printf("| %zu | %d | %d | %d | %d | %.2f | %.2f | %.2f | %.2f%% | %.2f%% |\n", p.n, light_f[il],
                               hemi_f[ih], spp_f[is], filt_f[iq], ts, tg, ts + tg, 100 * e, 100 * raw);
                        fflush(stdout);
                        if (e <= target && ts + tg < best_t) {
                            best_t = ts + tg;
                            snprintf(best, sizeof best, "%zu patches, %d light rays, %d gather rays, %d camera spp, "
                                     "filter %d px", p.n, light_f[il], hemi_f[ih], spp_f[is], filt_f[iq]);
                        }
                        for (int l = 0; l < 6; l++)
                            bn_image_free(&img[l]);
                    }
            bn_bake_destroy(bake);
            bn_pipeline_free(&p);
        }
        printf("\nFastest gather to a median error of %.2g%%: %s, %.2f s.\n\n", 100 * target, best, best_t);

        /* the tracer at a few sample counts, extrapolated to the target by err ~ 1/sqrt(spp) */
        {
            static const size_t spp_t[] = {16, 64, 256};
            double rate_t = NAN;
            printf("| tracer spp | seconds | median error | raw |\n|---|---|---|---|\n");
            for (int k = 0; k < (quick ? 2 : 3); k++) {
                float *L = NULL;
                double sec, e, raw;
                if (!trace_L(base.rt, &cam, spp_t[k], 4242, &L, NULL, &sec))
                    return 1;
                e = median_err(&ref, L, &raw, NULL);
                printf("| %zu | %.2f | %.2f%% | %.2f%% |\n", spp_t[k], sec, 100 * e, 100 * raw);
                rate_t = sec * (e / target) * (e / target);   /* seconds to the target at this point's constant */
                free(L);
            }
            printf("\nThe tracer to %.2g%% (its last point's error x sqrt(spp) held): %.0f s; the gather's best is %.3g "
                   "times faster.\n",
                   100 * target, rate_t, rate_t / best_t);
        }
    }
    bn_pipeline_free(&base);
    free(ref.L);
    free(ref.var);
    return 0;
}
