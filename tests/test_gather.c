/* The final gather against answers it does not compute itself: KE per pixel on a plate under a
 * rectangular emitter equals Howell's point-to-rectangle factor (catalogue B-3, by superposition of
 * corner rectangles); with a blocker's straight edge between them the visible part is a smaller
 * rectangle, so the same formula gives the half-shadow exactly; the white furnace gives rho^k Le in
 * every pixel of every term; on the Cornell box the image mean of each gathered term agrees with the
 * patch solution's over the same pixels; the images do not depend on the thread count. */
#include "bn_test.h"
#include "bounce/bake.h"
#include "bounce/gather.h"
#include "bounce/pipeline.h"
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/trace.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Howell B-3: a point under the corner of a parallel a x b rectangle at height c. */
static double corner(double a, double b, double c)
{
    double A = a / c, B = b / c, sa = sqrt(1 + A * A), sb = sqrt(1 + B * B);
    return (A / sa * atan(B / sa) + B / sb * atan(A / sb)) / (2 * 3.14159265358979323846);
}
static double signed_corner(double x, double y, double c)
{
    return (x < 0 ? -1 : 1) * (y < 0 ? -1 : 1) * corner(fabs(x), fabs(y), c);
}
/* A point at the origin, the rectangle [x1, x2] x [y1, y2] at height c, parallel, facing it. */
static double howell_rect(double x1, double x2, double y1, double y2, double c)
{
    if (x2 <= x1 || y2 <= y1)
        return 0;
    return signed_corner(x2, y2, c) - signed_corner(x1, y2, c) - signed_corner(x2, y1, c) + signed_corner(x1, y1, c);
}

/* The plate z = 0 ([-3, 3]^2, facing +z), the emitter [EX1, EX2] x [EY1, EY2] at z = EH facing
 * down, and (blocker) the quad z = BH, x in [-4, BX], facing up. */
#define EX1 -0.4
#define EX2 0.6
#define EY1 -0.7
#define EY2 0.9
#define EH 1.0
#define BH 0.5
#define BX 0.1
static const double LE[3] = {2.0, 1.0, 0.5};
static const double RHO[3] = {0.5, 0.6, 0.7};

static bn_scene *plate_scene(int blocker)
{
    const double v[] = {-3, -3, 0, 3,   -3, 0,  3,   3,  0,  -3,  3,  0,             /* plate */
                        EX1, EY1, EH, EX1, EY2, EH, EX2, EY2, EH, EX2, EY1, EH,   /* emitter, facing -z */
                        -4, -4, BH, BX,  -4, BH, BX,  4,  BH, -4,  4,  BH};          /* blocker, facing +z */
    const unsigned polys[] = {4, 0, 1, 2, 3, 4, 4, 5, 6, 7, 4, 8, 9, 10, 11};
    const unsigned pm[] = {0, 1, 0};
    bn_material m[2] = {{"plate", {RHO[0], RHO[1], RHO[2]}, {0, 0, 0}}, {"light", {0, 0, 0}, {LE[0], LE[1], LE[2]}}};
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_scene *s = NULL;
    bn_error err;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    if (bn_scene_from_arrays("plate", v, 12, polys, blocker ? 3 : 2, pm, m, 2, &lo, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.target_patches = 40;
    mo.no_contacts = 1;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    return s;
}

/* KE per pixel of the plate scene against the analytic factor of the visible part of the emitter;
 * returns the largest relative error, *mean_err the mean one (over pixels seeing the lit plate). */
static double plate_case(int blocker, int light_samples, int w, int h, double *mean_err, size_t *npix)
{
    bn_scene *s = plate_scene(blocker);
    bn_rt *rt = NULL;
    bn_error err;
    size_t np;
    bn_camera cam = {{0.1, -2.6, 0.35}, {0.1, 0.2, 0}, {0, 0, 1}, 60.0, w, h, 1};
    bn_image img[5];
    bn_gather_opts go;
    double *E, *zero, worst = 0, sum = 0;
    const double *terms[2];
    bn_scene_patches(s, &np);
    E = calloc(3 * np, sizeof *E);
    zero = calloc(3 * np, sizeof *zero);
    BN_ASSERT(E && zero);
    bn_scene_patch_emission(s, E);
    terms[0] = E;
    terms[1] = zero;
    if (bn_rt_create(s, 1, &rt, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    for (int l = 0; l < 4; l++)
        BN_ASSERT_STATUS(bn_image_alloc(&img[l], w, h, &err), BN_OK);
    bn_gather_opts_default(&go);
    go.light_samples = light_samples;
    go.hemi_samples = 1;
    go.quiet = 1;
    BN_ASSERT_STATUS(bn_gather_render(rt, &cam, terms, 1, zero, &go, img, NULL, &err), BN_OK);
    *npix = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double o[3], d[3], t, px, py, F, xlo;
            size_t pix = (size_t)y * (size_t)w + (size_t)x;
            bn_camera_ray(&cam, x + 0.5, y + 0.5, o, d);
            if (!(d[2] < 0))
                continue;
            t = -o[2] / d[2];
            px = o[0] + t * d[0];
            py = o[1] + t * d[1];
            if (fabs(px) > 2.9 || fabs(py) > 2.9)
                continue;
            if (blocker && px < BX + 0.01)
                continue;   /* under the blocker from the camera's side: not what is tested */
            /* the visible part: a ray from the plate point to the emitter crosses z = BH at the mean of
             * their x; the blocker hides x < BX there, so the emitter is seen for x > 2 BX - px */
            xlo = blocker ? fmax(EX1, 2 * BX - px) : EX1;
            F = howell_rect(xlo - px, EX2 - px, EY1 - py, EY2 - py, EH);
            if (F < 1e-4)
                continue;   /* in full shadow (KE 0, checked below) or barely lit */
            for (int c = 0; c < 3; c++) {
                double want = RHO[c] * LE[c] * F, got = img[1].rgb[3 * pix + c], e = fabs(got - want) / want;
                worst = fmax(worst, e);
                sum += e;
            }
            ++*npix;
        }
    *mean_err = *npix ? sum / (3.0 * (double)*npix) : 1;
    for (int l = 0; l < 4; l++)
        bn_image_free(&img[l]);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
    free(E);
    free(zero);
    return worst;
}

/* Unoccluded: exact (the visibility ratio is 1), so float rounding is all that is left. */
BN_TEST(ke_unoccluded_plate_equals_howell)
{
    double mean, worst;
    size_t n;
    worst = plate_case(0, 4, 40, 30, &mean, &n);
    fprintf(stderr, "%zu pixels: worst relative error %.3g, mean %.3g\n", n, worst, mean);
    BN_ASSERT_GT(n, 400);
    BN_ASSERT_LT(worst, 1e-3);
    BN_ASSERT_LT(worst, 1e-5);   /* in fact: a closed form, read back as float */
}

/* A straight shadow edge: the pixels of the half shadow against the visible rectangle's factor. */
BN_TEST(ke_half_occluded_edge)
{
    double mean, worst;
    size_t n;
    worst = plate_case(1, 4096, 24, 18, &mean, &n);
    fprintf(stderr, "%zu pixels: worst relative error %.3g, mean %.3g (4096 shadow rays)\n", n, worst, mean);
    BN_ASSERT_GT(n, 50);
    BN_ASSERT_LT(mean, 2e-3);   /* 64 x 64 strata of the emitter's solid angle: ~64 cut by the edge */
    BN_ASSERT_LT(worst, 2e-2);
}

static void furnace_run(bn_pipeline *p)
{
    bn_pipeline_opts o;
    bn_error err;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.mesh.target_patches = 96;
    o.transport = "dense";
    o.ff.quiet = 1;
    o.solve.quiet = 1;
    o.solve.bounces = 3;
    o.solve.tol = 1e-12;
    o.keep_rt = 1;
    if (bn_pipeline_run(bn_test_path("meshes/furnace-box.obj"), &o, p, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
}

/* The gathered layers; smooth: hit values interpolated across patches from a bake of the scene's
 * vertices (NULL: each patch's own). */
static void gather_images(const bn_pipeline *p, const bn_camera *cam, int threads, const bn_bake *smooth,
                          bn_image *img)
{
    bn_gather_opts go;
    bn_error err;
    const double *terms[4];
    for (int k = 0; k < 4; k++)
        terms[k] = p->res.terms[k];
    for (int l = 0; l < 6; l++)
        BN_ASSERT_STATUS(bn_image_alloc(&img[l], cam->width, cam->height, &err), BN_OK);
    bn_gather_opts_default(&go);
    go.threads = threads;
    go.quiet = 1;
    go.smooth = smooth;
    BN_ASSERT_STATUS(bn_gather_render(p->rt, cam, terms, 3, p->rest, &go, img, NULL, &err), BN_OK);
}

/* Closed box, rho 0.5, Le 1: E = 1, K^k E = 0.5^k, rest = 0.5^4 / 0.5, L = 2 in every pixel, to 1e-4
 * (the solution's terms are exact to ~1e-6; KE is closed-form, but a point within 2 eps of another
 * face's plane is taken 2 eps in front of it, which moves KE by ~5e-5 at one pixel here; the
 * gathered terms are means of equal values). */
BN_TEST(furnace_every_term_every_pixel)
{
    bn_pipeline p;
    /* looking slightly askew: no pixel centre lands exactly on an edge of the box, where KE is the
     * limit from one side (taken 2 eps off the other face's plane: 4e-4 here) */
    bn_camera cam = {{0.5, 0.5, 0.5}, {0.53, 0.46, 1.0}, {0, 1, 0}, 100.0, 24, 16, 1};
    bn_image img[6];
    const double exact[6] = {1, 0.5, 0.25, 0.125, 0.125, 2};
    bn_bake *bake = NULL;
    bn_error err;
    furnace_run(&p);
    BN_ASSERT_STATUS(bn_bake_create(p.scene, 30, &bake, &err), BN_OK);
    /* flat, then smooth: interpolating equal vertex values must keep them exactly */
    for (int pass = 0; pass < 2; pass++) {
        double worst[6] = {0};
        gather_images(&p, &cam, 2, pass ? bake : NULL, img);
        for (int l = 0; l < 6; l++) {
            for (size_t k = 0; k < (size_t)3 * 24 * 16; k++)
                worst[l] = fmax(worst[l], fabs(img[l].rgb[k] - exact[l]) / exact[l]);
            fprintf(stderr, "%s layer %d: worst relative error %.3g\n", pass ? "smooth" : "flat", l, worst[l]);
            BN_ASSERT_LT(worst[l], 1e-4);
            bn_image_free(&img[l]);
        }
        BN_ASSERT_LT(worst[0], 1e-7);   /* E: the emission itself */
    }
    bn_bake_destroy(bake);
    bn_pipeline_free(&p);
}

/* Streams keyed by pixel and sample: one thread and two give the same bits. */
BN_TEST(thread_invariance)
{
    bn_pipeline p;
    bn_camera cam = {{0.5, 0.5, 0.2}, {0.3, 0.6, 1.0}, {0, 1, 0}, 70.0, 20, 14, 2};
    bn_image a[6], b[6];
    furnace_run(&p);
    gather_images(&p, &cam, 1, NULL, a);
    gather_images(&p, &cam, 2, NULL, b);
    for (int l = 0; l < 6; l++) {
        BN_ASSERT(memcmp(a[l].rgb, b[l].rgb, (size_t)3 * 20 * 14 * sizeof(float)) == 0);
        bn_image_free(&a[l]);
        bn_image_free(&b[l]);
    }
    bn_pipeline_free(&p);
}

/* The Cornell box: each gathered layer's image mean against the patch solution's mean over the same
 * pixels (the flat render: the value of the patch each pixel sees), within 1%. */
BN_TEST(cornell_gathered_means_match_the_patch_solution)
{
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_error err;
    bn_camera cam;
    bn_image g[6], f[6];
    const double *terms[4], *layers[6];
    bn_gather_opts go;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.load.unit = BN_UNIT_MM;
    o.ff.quiet = 1;
    o.ff.exact_visibility = 0;   /* shadow rays: the gather is compared with the same K's solution
                                    (the exact visible parts are tested in test_ff_visibility) */
    o.solve.quiet = 1;
    o.solve.bounces = 3;
    o.keep_rt = 1;
    o.mesh.target_patches = 1200;
    if (bn_pipeline_run(bn_test_path("meshes/cornell-box.obj"), &o, &p, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_camera_default(p.scene, &cam);
    if (bn_camera_load_sidecar(bn_test_path("meshes/cornell-box.obj"), &cam, NULL, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    cam.width = cam.height = 96;
    cam.spp = 1;
    for (int k = 0; k < 4; k++)
        terms[k] = layers[k] = p.res.terms[k];
    layers[4] = p.rest;
    layers[5] = p.res.L;
    for (int l = 0; l < 6; l++) {
        BN_ASSERT_STATUS(bn_image_alloc(&g[l], 96, 96, &err), BN_OK);
        BN_ASSERT_STATUS(bn_image_alloc(&f[l], 96, 96, &err), BN_OK);
    }
    bn_gather_opts_default(&go);
    go.hemi_samples = 256;
    go.quiet = 1;
    BN_ASSERT_STATUS(bn_gather_render(p.rt, &cam, terms, 3, p.rest, &go, g, NULL, &err), BN_OK);
    BN_ASSERT_STATUS(bn_image_render(p.rt, &cam, layers, 6, NULL, 1, 0, f, &err), BN_OK);
    for (int l = 0; l < 6; l++) {
        for (int c = 0; c < 3; c++) {
            double mg = 0, mf = 0;
            for (size_t k = 0; k < 96 * 96; k++) {
                mg += g[l].rgb[3 * k + c];
                mf += f[l].rgb[3 * k + c];
            }
            fprintf(stderr, "layer %d channel %d: gathered mean %.6g, patch mean %.6g (%+.3f%%)\n", l, c, mg / 9216,
                    mf / 9216, 100 * (mg - mf) / mf);
            if (l == 0)
                BN_ASSERT_REL(mg, mf, 1e-6);   /* the same emitter pixels */
            else
                BN_ASSERT_REL(mg, mf, 1e-2);
        }
        bn_image_free(&g[l]);
        bn_image_free(&f[l]);
    }
    bn_pipeline_free(&p);
}

/* Issue 35: the gathered higher bounces against the path tracer (independent: the scene and Embree
 * only), as `bounce bounces` makes them on the Cornell box (its default mesh, dense K, the default
 * gather). Image means of KE .. K4E within 1% (plus 3 of the tracer's standard errors of the mean);
 * E and L are left out: the gather samples each pixel's centre, the tracer its area, and the small
 * bright light's edge pixels differ by that. 256x256 pixels, 256 paths each. */
BN_TEST(cornell_gathered_bounces_match_the_tracer) /* BN_SLOW */
{
    BN_SKIP_IF_SLOW_RUN();
    enum { W = 256, NB = 4 };
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_error err;
    bn_camera cam;
    bn_image g[NB + 3];
    const double *terms[NB + 1];
    bn_gather_opts go;
    bn_trace_opts to;
    bn_trace_image ti;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.load.unit = BN_UNIT_MM;
    o.ff.quiet = o.solve.quiet = 1;
    o.solve.bounces = NB;
    o.keep_rt = 1;
    o.mesh.target_patches = BN_GATHER_PATCHES;
    if (bn_pipeline_run(bn_test_path("meshes/cornell-box.obj"), &o, &p, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_camera_default(p.scene, &cam);
    BN_ASSERT_STATUS(bn_camera_load_sidecar(bn_test_path("meshes/cornell-box.obj"), &cam, NULL, &err), BN_OK);
    cam.width = cam.height = W;
    cam.spp = 1;
    for (int k = 0; k <= NB; k++)
        terms[k] = p.res.terms[k];
    for (int l = 0; l < NB + 3; l++)
        BN_ASSERT_STATUS(bn_image_alloc(&g[l], W, W, &err), BN_OK);
    bn_gather_opts_default(&go);
    go.quiet = 1;
    BN_ASSERT_STATUS(bn_gather_render(p.rt, &cam, terms, NB, p.rest, &go, g, NULL, &err), BN_OK);
    bn_trace_opts_default(&to);
    to.spp = 256;
    to.bounces = NB;
    to.quiet = 1;
    BN_ASSERT_STATUS(bn_trace_image_run(p.rt, &cam, &to, &ti, &err), BN_OK);
    for (int l = 1; l <= NB; l++)
        for (int c = 0; c < 3; c++) {
            double mg = 0, mt = 0, vt = 0;
            size_t off = (size_t)l * W * W * 3;
            for (size_t k = 0; k < (size_t)W * W; k++) {
                mg += g[l].rgb[3 * k + c];
                mt += ti.mean[off + 3 * k + c];
                vt += ti.var[off + 3 * k + c];
            }
            double se = sqrt(vt) / (W * W);
            mg /= W * W;
            mt /= W * W;
            printf("K%dE channel %d: gathered %.6g, traced %.6g +- %.2g (%+.3f%%)\n", l, c, mg, mt, se,
                   100 * (mg - mt) / mt);
            BN_ASSERT_LE(fabs(mg - mt), 0.01 * mt + 3 * se);
        }
    for (int l = 0; l < NB + 3; l++)
        bn_image_free(&g[l]);
    bn_trace_image_free(&ti);
    bn_pipeline_free(&p);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* One Cornell box (path) solved on a coarse mesh and gathered at 64 x 64 (merge: merge_emitters): the
 * images of E .. K2E, rest, L and the counts. */
static void cornell_gather(const char *path, int merge, bn_image *g, bn_gather_stats *gs)
{
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_error err;
    bn_camera cam;
    bn_gather_opts go;
    const double *terms[3];
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = o.ff.quiet = o.solve.quiet = 1;
    o.load.unit = BN_UNIT_MM;
    o.ff.exact_visibility = 0;
    o.solve.bounces = 2;
    o.keep_rt = 1;
    o.mesh.target_patches = 300;
    if (bn_pipeline_run(path, &o, &p, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_camera_default(p.scene, &cam);
    BN_ASSERT_STATUS(bn_camera_load_sidecar(bn_test_path("meshes/cornell-box.obj"), &cam, NULL, &err), BN_OK);
    cam.width = cam.height = 64;
    cam.spp = 4;
    for (int k = 0; k < 3; k++)
        terms[k] = p.res.terms[k];
    for (int l = 0; l < 5; l++)
        BN_ASSERT_STATUS(bn_image_alloc(&g[l], 64, 64, &err), BN_OK);
    bn_gather_opts_default(&go);
    go.hemi_samples = 16;
    go.merge_emitters = merge;
    go.quiet = 1;
    BN_ASSERT_STATUS(bn_gather_render(p.rt, &cam, terms, 2, p.rest, &go, g, gs, &err), BN_OK);
    bn_pipeline_free(&p);
}

/* The median over the pixels where a's green KE exceeds 1e-3 of |b - a| / a. */
static double ke_median_difference(const bn_image *a, const bn_image *b)
{
    static double e[64 * 64];
    size_t m = 0;
    for (size_t k = 0; k < 64 * 64; k++)
        if (a->rgb[3 * k + 1] > 1e-3)
            e[m++] = fabs(b->rgb[3 * k + 1] - a->rgb[3 * k + 1]) / a->rgb[3 * k + 1];
    qsort(e, m, sizeof *e, cmp_double);
    return m ? e[m / 2] : INFINITY;
}

/* The image means of KE and K2E of the cut light's render against the one face's, per channel: within
 * tol1 and tol2. */
static void means_agree(const bn_image *one, const bn_image *cut, double tol1, double tol2)
{
    for (int l = 1; l <= 2; l++)
        for (int c = 0; c < 3; c++) {
            double m1 = 0, mc = 0;
            for (size_t k = 0; k < 64 * 64; k++) {
                m1 += one[l].rgb[3 * k + c];
                mc += cut[l].rgb[3 * k + c];
            }
            printf("K%dE channel %d: one face %.6g, cut light %.6g (%+.3f%%)\n", l, c, m1, mc, 100 * (mc - m1) / m1);
            BN_ASSERT_REL(mc, m1, l == 1 ? tol1 : tol2);
        }
}

/* Issue 33: the light cut into 512 triangles, not merged, is picked from the light tree (one shadow
 * ray per pick), the one quad is visited whole; both are the same light, so KE and K2E (whose hits take
 * KE from the emitters: one picked face each) agree in their image means within 1.5%, KE per pixel
 * within 10% at the median, and the cut light costs no more shadow rays per camera ray. */
BN_TEST(many_emitters_from_the_light_tree_match_one)
{
    bn_image one[5], cut[5];
    bn_gather_stats s1, sc;
    cornell_gather(bn_test_path("meshes/cornell-box.obj"), 1, one, &s1);
    cornell_gather(bn_test_cornell_cut_light(16), 0, cut, &sc);
    BN_ASSERT(!s1.light_tree && sc.light_tree && s1.emitters == 1 && sc.emitters == 512 && sc.lights == 512);
    BN_ASSERT(s1.hit_direct && sc.hit_direct);
    printf("shadow rays per camera ray: one face %.2f, 512 faces %.2f\n", s1.shadow_rays / s1.camera_rays,
           sc.shadow_rays / sc.camera_rays);
    BN_ASSERT_LE(sc.shadow_rays / sc.camera_rays, 1.05 * s1.shadow_rays / s1.camera_rays);
    means_agree(one, cut, 0.015, 0.015);
    printf("KE per pixel: median relative difference %.4f%%\n", 100 * ke_median_difference(&one[1], &cut[1]));
    BN_ASSERT_LE(ke_median_difference(&one[1], &cut[1]), 0.10);
    for (int l = 0; l < 5; l++) {
        bn_image_free(&one[l]);
        bn_image_free(&cut[l]);
    }
}

/* The gather's counts for the scene at path (no solve: its emission alone, 8 x 8 pixels). */
static void light_counts(const char *path, bn_gather_stats *gs)
{
    bn_load_opts lo;
    bn_gather_opts go;
    bn_image g[4];
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    lo.unit = BN_UNIT_MM;
    bn_gather_opts_default(&go);
    go.hemi_samples = 1;
    go.quiet = 1;
    bn_test_gather_emission(path, &lo, 8, 0, &go, g, gs);
    for (int l = 0; l < 4; l++)
        bn_image_free(&g[l]);
}

/* Issue 33: the light cut into 512 triangles, merged (the default), is one light again: the one quad's
 * closed form and its visibility sampled over the whole, so the image means of KE match the one face's
 * within 0.2% (the same estimator, other sample directions: the penumbrae's noise) and K2E's within 1%
 * (the solve meshes the cut light's 512 faces as its own patches), KE per pixel within 1% at the median,
 * at the one face's shadow rays per camera ray. The same cut with a hole (a middle cell left out) or a
 * notch (a corner cell) does not tile its convex hull: 510 faces, picked from the light tree. */
BN_TEST(cut_light_merges_into_one_light)
{
    bn_image one[5], cut[5];
    bn_gather_stats s1, sc;
    cornell_gather(bn_test_path("meshes/cornell-box.obj"), 1, one, &s1);
    cornell_gather(bn_test_cornell_cut_light(16), 1, cut, &sc);
    printf("cut light: %zu faces as %zu light(s); shadow rays per camera ray %.3f (one face %.3f)\n", sc.emitters,
           sc.lights, sc.shadow_rays / sc.camera_rays, s1.shadow_rays / s1.camera_rays);
    BN_ASSERT(sc.emitters == 512 && sc.lights == 1 && !sc.light_tree && sc.hit_direct);
    BN_ASSERT_LE(sc.shadow_rays / sc.camera_rays, 1.01 * s1.shadow_rays / s1.camera_rays);
    means_agree(one, cut, 0.002, 0.01);
    printf("KE per pixel: median relative difference %.4f%%\n", 100 * ke_median_difference(&one[1], &cut[1]));
    BN_ASSERT_LE(ke_median_difference(&one[1], &cut[1]), 0.01);
    for (int l = 0; l < 5; l++) {
        bn_image_free(&one[l]);
        bn_image_free(&cut[l]);
    }
    for (int k = 0; k < 2; k++) {
        light_counts(bn_test_cornell_cut_light_without(16, k ? 0 : 8 * 16 + 8), &sc);
        printf("the cut light with a %s: %zu faces as %zu lights\n", k ? "notch" : "hole", sc.emitters, sc.lights);
        BN_ASSERT(sc.emitters == 510 && sc.lights == 510 && sc.light_tree);
    }
}

/* Issue 33: faces smaller than the patch size do not coarsen the large ones: with the light cut into
 * 512 triangles, the default target meshes the room's faces exactly as for the one-quad light (the
 * same largest patch edge), and the total grows by about the light's own faces. */
BN_TEST(many_small_faces_keep_the_large_ones_meshed)
{
    const char *paths[2] = {bn_test_path("meshes/cornell-box.obj"), bn_test_cornell_cut_light(16)};
    double edge[2];
    size_t np[2];
    for (int k = 0; k < 2; k++) {
        bn_load_opts lo;
        bn_scene *s = NULL;
        bn_error err;
        bn_load_opts_default(&lo);
        lo.log.quiet = 1;
        lo.unit = BN_UNIT_MM;
        BN_ASSERT_STATUS(bn_scene_load(paths[k], &lo, &s, &err), BN_OK);
        BN_ASSERT_STATUS(bn_scene_mesh(s, NULL, &err), BN_OK);
        bn_scene_patches(s, &np[k]);
        edge[k] = bn_scene_largest_patch_edge(s);
        bn_scene_destroy(s);
    }
    printf("one quad: %zu patches, largest edge %.4g mm; 512 triangles: %zu, %.4g mm\n", np[0], edge[0], np[1],
           edge[1]);
    BN_ASSERT_REL(edge[1], edge[0], 1e-9);
    BN_ASSERT_GE(np[1], np[0] + 512 - 30);
    BN_ASSERT_LE(np[1], np[0] + 512 + 60);
}
