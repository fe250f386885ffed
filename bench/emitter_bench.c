/* Many emitters (issue 33): the Cornell box whose light is cut into 1, 100 and 10,000 emitting
 * triangles (the same surface and radiance, so the same light and the same reference), each solved
 * once (not timed), then the final gather alone timed at several light sample counts, with the
 * median per-pixel error of KE and of L against the kept 64k-spp path-traced reference
 * (bench/data). Above BN_GATHER_TREE_EMITTERS faces the gather picks its faces from the light tree,
 * one ray each, so its cost per pixel should not grow with their number: the table gives each
 * gather's time as a multiple of the one face's at the default light samples, and its errors.
 *
 * usage: emitter_bench REF.exr [--quick] (--quick: 1 and 100 faces only) */
#include "ref_exr.h"
#include "bounce/gather.h"
#include "bounce/pipeline.h"
#include "base/internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#ifndef BN_SOURCE_DIR
#define BN_SOURCE_DIR "."
#endif

#define CORNELL BN_SOURCE_DIR "/meshes/cornell-box.obj"

static char *slurp(const char *path)
{
    FILE *fp = fopen(path, "rb");
    char *s = NULL;
    long n;
    if (!fp || fseek(fp, 0, SEEK_END) != 0 || (n = ftell(fp)) < 0 || fseek(fp, 0, SEEK_SET) != 0 ||
        !(s = calloc((size_t)n + 1, 1)) || fread(s, 1, (size_t)n, fp) != (size_t)n) {
        fprintf(stderr, "emitter_bench: cannot read %s\n", path);
        exit(1);
    }
    fclose(fp);
    return s;
}

/* dir/cornell-N.obj (and its .mtl): the light an na x nb grid of quads, two triangles each. */
static void write_cut(const char *dir, int na, int nb, char *path, size_t cap)
{
    const double v0[3] = {343.0, 548.8, 227.0}, v1[3] = {343.0, 548.8, 332.0}, v3[3] = {213.0, 548.8, 227.0};
    char *src = slurp(CORNELL), *mtl = slurp(BN_SOURCE_DIR "/meshes/cornell-box.mtl"), *light, *after, m[4096];
    FILE *fp;
    snprintf(m, sizeof m, "%s/cornell-box.mtl", dir);
    if (!(light = strstr(src, "o light\n")) || !(after = strstr(light, "\n\n")) || !(fp = fopen(m, "w")))
        exit(1);
    fputs(mtl, fp);
    fclose(fp);
    snprintf(path, cap, "%s/cornell-%d.obj", dir, 2 * na * nb);
    if (!(fp = fopen(path, "w")))
        exit(1);
    fprintf(fp, "%.*so light\nusemtl light\n", (int)(light - src), src);
    for (int b = 0; b <= nb; b++)
        for (int a = 0; a <= na; a++)
            fprintf(fp, "v %.9g %.9g %.9g\n", v0[0] + (v1[0] - v0[0]) * a / na + (v3[0] - v0[0]) * b / nb, v0[1],
                    v0[2] + (v1[2] - v0[2]) * a / na + (v3[2] - v0[2]) * b / nb);
    for (int b = 0; b < nb; b++)
        for (int a = 0; a < na; a++) {
            int i = b * (na + 1) + a + 1;
            fprintf(fp, "f %d %d %d\nf %d %d %d\n", -(na + 1) * (nb + 1) - 1 + i, -(na + 1) * (nb + 1) + i,
                    -(na + 1) * (nb + 1) + i + na + 1, -(na + 1) * (nb + 1) - 1 + i,
                    -(na + 1) * (nb + 1) + i + na + 1, -(na + 1) * (nb + 1) - 1 + i + na + 1);
        }
    fputs(after, fp);
    fclose(fp);
    free(src);
    free(mtl);
}

static void solve(const char *path, bn_pipeline *p)
{
    bn_pipeline_opts o;
    bn_error err;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.load.unit = BN_UNIT_MM;
    o.ff.quiet = o.solve.quiet = 1;
    o.ff.exact_visibility = 0;   /* the solve is not what is timed */
    o.solve.bounces = 4;
    o.keep_rt = 1;
    o.mesh.target_patches = BN_GATHER_PATCHES;
    if (bn_pipeline_run(path, &o, p, &err) != BN_OK) {
        fprintf(stderr, "emitter_bench: %s: %s\n", path, err.msg);
        exit(1);
    }
}

/* One gather of p at the reference's size with `light` samples: its time, KE and L errors. */
static double gather(const bn_pipeline *p, const exr_img *rke, const exr_img *rk2, const exr_img *rl, int light, double eke[3],
                     double ek2[3], double el[3], double *rays_per)
{
    bn_camera cam;
    bn_image g[7];
    bn_gather_opts go;
    bn_gather_stats gs;
    bn_error err;
    const double *terms[5];
    double t0, t;
    bn_camera_default(p->scene, &cam);
    if (bn_camera_load_sidecar(CORNELL, &cam, NULL, &err) != BN_OK)
        exit(1);
    cam.width = rke->w;
    cam.height = rke->h;
    cam.spp = 1;
    for (int k = 0; k < 5; k++)
        terms[k] = p->res.terms[k];
    for (int l = 0; l < 7; l++)
        bn_image_alloc(&g[l], cam.width, cam.height, &err);
    bn_gather_opts_default(&go);
    go.light_samples = light;
    go.quiet = 1;
    t0 = bn__now();
    if (bn_gather_render(p->rt, &cam, terms, 4, p->rest, &go, g, &gs, &err) != BN_OK) {
        fprintf(stderr, "emitter_bench: %s\n", err.msg);
        exit(1);
    }
    t = bn__now() - t0;
    exr_median_err(rke, g[1].rgb, eke);
    exr_median_err(rk2, g[2].rgb, ek2);
    exr_median_err(rl, g[6].rgb, el);
    *rays_per = gs.shadow_rays / gs.camera_rays;
    for (int l = 0; l < 7; l++)
        bn_image_free(&g[l]);
    return t;
}

int main(int argc, char **argv)
{
    static const int na[] = {1, 5, 50}, nb[] = {0, 10, 100}, light[] = {16, 64, 256};
    int quick = argc > 2 && !strcmp(argv[2], "--quick");
    double t1 = NAN;
    exr_img rke, rk2, rl;
    char dir[] = "/tmp/emitter_bench.XXXXXX", path[4096];
    if (argc < 2 || !exr_img_load(argv[1], "KE", &rke, 1) || !exr_img_load(argv[1], "K2E", &rk2, 1) ||
        !exr_img_load(argv[1], "L", &rl, 1)) {
        fprintf(stderr, "usage: emitter_bench REF.exr [--quick] (REF: a `bounce trace` EXR with KE and L)\n");
        return 2;
    }
    if (!mkdtemp(dir))
        return 1;
    printf("| emitting faces | light samples | sampling | gather s | x one face's | shadow rays per camera ray | KE median "
           "error | K2E median error | L median error |\n|---|---|---|---|---|---|---|---|---|\n");
    for (int s = 0; s < (quick ? 2 : 3); s++) {
        bn_pipeline p;
        memset(&p, 0, sizeof p);
        if (s == 0)
            snprintf(path, sizeof path, "%s", CORNELL);
        else
            write_cut(dir, na[s], nb[s], path, sizeof path);
        solve(path, &p);
        for (int l = 0; l < 3; l++) {
            double eke[3], ek2[3], el[3], rays, t = gather(&p, &rke, &rk2, &rl, light[l], eke, ek2, el, &rays);
            if (s == 0 && light[l] == BN_GATHER_LIGHT_SAMPLES)
                t1 = t;
            printf("| %d | %d | %s | %.2f | %.2f | %.1f | %.3f%% | %.3f%% | %.3f%% |\n", s ? 2 * na[s] * nb[s] : 1,
                   light[l], s ? "light tree" : "every face", t, t / t1, rays, 100 * eke[0], 100 * ek2[0], 100 * el[0]);
            fflush(stdout);
        }
        bn_pipeline_free(&p);
        if (s)
            remove(path);
    }
    snprintf(path, sizeof path, "%s/cornell-box.mtl", dir);
    remove(path);
    rmdir(dir);
    exr_img_free(&rke);
    exr_img_free(&rk2);
    exr_img_free(&rl);
    return 0;
}
