/* The path tracer's camera estimator: a camera inside the furnace box sees rho^k Le in every
 * pixel of layer K^k E, with per-pixel variances that hold up; 1 and 2 threads bit-identical;
 * `bounce trace` writes its EXR and per-patch CSV. */
#include "bn_test.h"
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/trace.h"

#include <math.h>

#define ALPHA 0.01   /* family-wise false-failure rate of the statistical test */

static bn_scene *load_furnace(size_t patches)
{
    return bn_test_load_meshed("meshes/furnace-box.obj", BN_UNIT_M, patches);
}

static void inside_camera(bn_camera *cam, int w, int h)
{
    bn_camera c = {{0.5, 0.5, 0.5}, {0.5, 0.5, 1.0}, {0, 1, 0}, 90.0, w, h, 1};
    *cam = c;
}

/* Every pixel sees the inside of the box: E = 1 exactly (no variance); KE, K2E, K3E, rest, L
 * within a Sidak-corrected t bound of 0.5^k, 0.125 and 2. */
BN_TEST(furnace_pixels)
{
    bn_scene *s = load_furnace(54);
    bn_rt *rt = NULL;
    bn_camera cam;
    bn_trace_opts o;
    bn_trace_image img;
    bn_error err;
    const double exact[6] = {1, 0.5, 0.25, 0.125, 0.125, 2};
    size_t npx, family, within = 0;
    double crit, worst = 0;
    if (bn_rt_create(s, 1, &rt, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    inside_camera(&cam, 24, 16);
    bn_trace_opts_default(&o);
    o.spp = 128;
    o.quiet = 1;
    if (bn_trace_image_run(rt, &cam, &o, &img, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT_EQ(img.nlayers, 6);
    npx = (size_t)img.width * (size_t)img.height;
    family = npx * 5;   /* layers KE .. L, channel R (the material is grey: G, B repeat it) */
    crit = bn_student_t_quantile_upper(-expm1(log1p(-ALPHA) / (double)family) / 2, (double)o.spp - 1);
    for (size_t p = 0; p < npx; p++) {
        BN_ASSERT_EQ(img.mean[3 * p], 1.0f);
        BN_ASSERT_EQ(img.var[3 * p], 0.0f);
        for (int l = 1; l < 6; l++) {
            size_t k = ((size_t)l * npx + p) * 3;
            double z = (img.mean[k] - exact[l]) / sqrt(img.var[k]);
            worst = fmax(worst, fabs(z));
            within += fabs(z) <= crit;
            BN_ASSERT_EQ(img.mean[k], img.mean[k + 1]);
        }
    }
    fprintf(stderr, "%zu pixel tests, worst |z| %.3f, bound %.3f\n", family, worst, crit);
    BN_ASSERT_EQ(within, family);
    bn_trace_image_free(&img);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* Streams keyed by (seed, pixel, sample): the image is bit-identical for 1 and 2 threads. */
BN_TEST(image_thread_invariance)
{
    bn_scene *s = load_furnace(54);
    bn_rt *rt = NULL;
    bn_camera cam;
    bn_trace_opts o;
    bn_trace_image a, b;
    bn_error err;
    size_t m;
    if (bn_rt_create(s, 1, &rt, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    inside_camera(&cam, 20, 12);
    bn_trace_opts_default(&o);
    o.spp = 8;
    o.quiet = 1;
    o.threads = 1;
    if (bn_trace_image_run(rt, &cam, &o, &a, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    o.threads = 2;
    if (bn_trace_image_run(rt, &cam, &o, &b, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    m = (size_t)a.nlayers * (size_t)a.width * (size_t)a.height * 3;
    BN_ASSERT(memcmp(a.mean, b.mean, m * sizeof(float)) == 0);
    BN_ASSERT(memcmp(a.var, b.var, m * sizeof(float)) == 0);
    bn_trace_image_free(&a);
    bn_trace_image_free(&b);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* The command: EXR and CSV written, the CSV has a row per patch and the layer columns. */
BN_TEST(cli_trace_outputs)
{
    char cmd[2048], *out = NULL, *csv;
    const char *exr = bn_test_tmp("pt.exr"), *pcsv = bn_test_tmp("pt.csv");
    size_t rows = 0;
    int rc;
    snprintf(cmd, sizeof cmd, "trace %s --patches 24 --spp 8 -n 2 --size 16x12 -o %s --patches-out %s",
             bn_test_path("meshes/furnace-box.obj"), exr, pcsv);
    rc = bn_test_bounce(cmd, &out);
    if (rc != 0)
        BN_FAIL("bounce %s -> %d\n%s", cmd, rc, out ? out : "");
    BN_ASSERT(bn_test_file_exists(exr));
    csv = bn_test_read_file(pcsv, NULL);
    BN_ASSERT(csv != NULL);
    BN_ASSERT(strstr(csv, "# spp=8") != NULL);
    BN_ASSERT(strstr(csv, ",E.R,E.G,E.B,E.R_se,") != NULL);
    BN_ASSERT(strstr(csv, ",K2E.R,") != NULL);
    BN_ASSERT(strstr(csv, ",rest.R,") != NULL);
    BN_ASSERT(strstr(csv, ",L.B_se") != NULL);
    for (char *p = csv; *p; p++)
        if (*p == '\n' && p[1] >= '0' && p[1] <= '9')
            rows++;
    BN_ASSERT_EQ(rows, 24);
    free(csv);
    free(out);
    /* Usage errors exit 2 with a message. */
    rc = bn_test_bounce("trace meshes/none.obj", &out);
    BN_ASSERT_EQ(rc, 2);
    free(out);
}
