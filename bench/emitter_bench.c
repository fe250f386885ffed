/* Many emitters (issue 33): the Cornell box whose light is cut into 1, 100 and 10,000 emitting
 * triangles (the same surface and radiance, so the same light and the same reference), each solved
 * once (not timed), then the final gather alone timed at several light sample counts, with the
 * median per-pixel error of KE and of L against the kept 64k-spp path-traced reference
 * (bench/data). By default the gather merges the cut light's coplanar pieces back into one light
 * (src/gather/emitters.c): one row each at the default light samples. Not merged (merge_emitters 0, as
 * for pieces that are not coplanar), above BN_GATHER_TREE_EMITTERS faces the gather picks its faces
 * from the light tree, one ray each, so its cost per pixel should not grow with their number: the
 * table gives each gather's time as a multiple of the one face's at the default light samples, and
 * its errors.
 *
 * With --interior ROOM.obj (the living room): each emitting material rendered alone (the other
 * emitters' Ke set to 0 in a copy of the MTL), KE only, twice with two seeds at the default light
 * samples: the 90th percentile and mean over its lit pixels of the per-pixel relative standard
 * deviation |a - b| / sqrt(2) / mean, and the time, against the ceiling panels'.
 *
 * usage: emitter_bench REF.exr [--quick] (--quick: 1 and 100 faces only)
 *        emitter_bench --interior ROOM.obj (units: metres) */
#include "ref_exr.h"
#include "bounce/gather.h"
#include "bounce/pipeline.h"
#include "base/internal.h"
#include "bounce/rt.h"

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
static double gather(const bn_pipeline *p, const exr_img *rke, const exr_img *rk2, const exr_img *rl, int light,
                     int merge, double eke[3], double ek2[3], double el[3], double *rays_per, size_t *lights)
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
    go.merge_emitters = merge;
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
    *lights = gs.lights;
    for (int l = 0; l < 7; l++)
        bn_image_free(&g[l]);
    return t;
}

/* dir/room.mtl: src's MTL with every Ke but material `keep`'s set to 0; the emitting materials'
 * names into names (at most 16), their count. */
static int write_mtl_alone(const char *src, const char *keep, const char *dir, char names[16][128])
{
    char *m = slurp(src), *line, *save = NULL, cur[128] = "", path[4096];
    int n = 0;
    FILE *fp;
    snprintf(path, sizeof path, "%s/room.mtl", dir);
    if (!(fp = fopen(path, "w")))
        exit(1);
    for (line = strtok_r(m, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
        double r, g, b;
        if (sscanf(line, "newmtl %127s", cur) == 1) {
            fprintf(fp, "%s\n", line);
        } else if (sscanf(line, "Ke %lf %lf %lf", &r, &g, &b) == 3 && (r > 0 || g > 0 || b > 0)) {
            if (n < 16)
                snprintf(names[n++], 128, "%s", cur);
            fprintf(fp, "%s\n", keep && strcmp(keep, cur) ? "Ke 0 0 0" : line);
        } else {
            fprintf(fp, "%s\n", line);
        }
    }
    fclose(fp);
    free(m);
    return n;
}

/* The room in dir (room.obj, room.mtl, room.camera) at 256x256, KE only (E and zero terms), with
 * seed: the KE image's luminance into y (w*h), the gather's time. */
static double interior_ke(const char *dir, uint64_t seed, float *y)
{
    char path[4096];
    bn_load_opts lo;
    bn_scene *s = NULL;
    bn_rt *rt = NULL;
    bn_error err;
    bn_camera cam;
    bn_gather_opts go;
    bn_image g[4];
    size_t np;
    double *E, *zero, t0, t;
    const double *terms[2];
    snprintf(path, sizeof path, "%s/room.obj", dir);
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    lo.unit = BN_UNIT_M;
    if (bn_scene_load(path, &lo, &s, &err) != BN_OK || bn_scene_mesh(s, NULL, &err) != BN_OK ||
        bn_rt_create(s, 0, &rt, &err) != BN_OK) {
        fprintf(stderr, "emitter_bench: %s\n", err.msg);
        exit(1);
    }
    bn_scene_patches(s, &np);
    E = calloc(3 * np, sizeof *E);
    zero = calloc(3 * np, sizeof *zero);
    bn_scene_patch_emission(s, E);
    terms[0] = E;
    terms[1] = zero;
    bn_camera_default(s, &cam);
    if (bn_camera_load_sidecar(path, &cam, NULL, &err) != BN_OK)
        exit(1);
    cam.width = cam.height = 256;
    cam.spp = 1;
    for (int l = 0; l < 4; l++)
        bn_image_alloc(&g[l], 256, 256, &err);
    bn_gather_opts_default(&go);
    go.hemi_samples = 1;
    go.seed = seed;
    go.quiet = 1;
    t0 = bn__now();
    if (bn_gather_render(rt, &cam, terms, 1, zero, &go, g, NULL, &err) != BN_OK)
        exit(1);
    t = bn__now() - t0;
    for (size_t k = 0; k < 256 * 256; k++)
        y[k] = 0.2126f * g[1].rgb[3 * k] + 0.7152f * g[1].rgb[3 * k + 1] + 0.0722f * g[1].rgb[3 * k + 2];
    for (int l = 0; l < 4; l++)
        bn_image_free(&g[l]);
    free(E);
    free(zero);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
    return t;
}

static int cmp_f(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* The per-pixel relative standard deviation of two renders over the pixels above 1e-3 of the
 * brightest: its 90th percentile (most lit pixels are exact: their deviation is 0), *mean its mean. */
static double rel_sd(const float *a, const float *b, size_t n, double *mean_out)
{
    double top = 0, *e = malloc(n * sizeof *e), med, sum = 0;
    size_t m = 0;
    for (size_t k = 0; k < n; k++)
        top = fmax(top, 0.5 * (a[k] + b[k]));
    for (size_t k = 0; k < n; k++) {
        double mean = 0.5 * (a[k] + b[k]);
        if (mean > 1e-3 * top) {
            e[m] = fabs(a[k] - b[k]) / sqrt(2.0) / mean;
            sum += e[m++];
        }
    }
    qsort(e, m, sizeof *e, cmp_f);
    med = m ? e[m * 9 / 10] : NAN;
    *mean_out = m ? sum / (double)m : NAN;
    free(e);
    return med;
}

/* --interior: each emitting material alone, its KE's relative noise and time. */
static int interior(const char *room)
{
    char dir[] = "/tmp/emitter_room.XXXXXX", names[16][128], path[8192], src[2048], *dot;
    float *a = malloc(256 * 256 * sizeof(float)), *b = malloc(256 * 256 * sizeof(float));
    int n;
    if (!mkdtemp(dir) || !a || !b)
        return 1;
    snprintf(src, sizeof src, "%s", room);
    if ((dot = strrchr(src, '.')))
        *dot = 0;
    snprintf(path, sizeof path, "%s/room.obj", dir);
    { /* the OBJ as it is, but naming room.mtl; the camera beside it */
        char *obj = slurp(room), *ml = strstr(obj, "mtllib "), cam[8192];
        FILE *fp = fopen(path, "w");
        if (!fp || !ml)
            return 1;
        fprintf(fp, "%.*smtllib room.mtl%s", (int)(ml - obj), obj, strchr(ml, '\n'));
        fclose(fp);
        free(obj);
        snprintf(cam, sizeof cam, "cp '%s.camera' '%s/room.camera'", src, dir);
        if (system(cam) != 0)
            return 1;
    }
    snprintf(path, sizeof path, "%s.mtl", src);
    n = write_mtl_alone(path, NULL, dir, names);
    printf("| emitter alone | gather s (KE) | per-pixel relative standard deviation: 90th percentile | mean |\n"
           "|---|---|---|---|\n");
    for (int e = 0; e < n; e++) {
        double t, p90, mean;
        write_mtl_alone(path, names[e], dir, names);
        t = interior_ke(dir, 1, a);
        t += interior_ke(dir, 2, b);
        p90 = rel_sd(a, b, 256 * 256, &mean);
        printf("| %s | %.2f | %.3f%% | %.3f%% |\n", names[e], t / 2, 100 * p90, 100 * mean);
        fflush(stdout);
    }
    free(a);
    free(b);
    snprintf(path, sizeof path, "rm -rf '%s'", dir);
    return system(path) != 0;
}

int main(int argc, char **argv)
{
    static const int na[] = {1, 5, 50}, nb[] = {0, 10, 100}, light[] = {16, 64, 256};
    int quick = argc > 2 && !strcmp(argv[2], "--quick");
    double t1 = NAN;
    exr_img rke, rk2, rl;
    char dir[] = "/tmp/emitter_bench.XXXXXX", path[4096];
    if (argc == 3 && !strcmp(argv[1], "--interior"))
        return interior(argv[2]);
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
        for (int l = s ? -1 : 0; l < 3; l++) {   /* l = -1: the cut light merged (the default) */
            double eke[3], ek2[3], el[3], rays, t;
            size_t nl;
            int ls = light[l < 0 ? 0 : l];
            char how[64];
            t = gather(&p, &rke, &rk2, &rl, ls, l < 0 || !s, eke, ek2, el, &rays, &nl);
            if (s == 0 && ls == BN_GATHER_LIGHT_SAMPLES)
                t1 = t;
            snprintf(how, sizeof how, "%s (%zu light%s)",
                     !s ? "every face" : l < 0 ? "merged" : "light tree, not merged", nl, nl == 1 ? "" : "s");
            printf("| %d | %d | %s | %.2f | %.2f | %.1f | %.3f%% | %.3f%% | %.3f%% |\n", s ? 2 * na[s] * nb[s] : 1, ls,
                   how, t, t / t1, rays, 100 * eke[0], 100 * ek2[0], 100 * el[0]);
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
