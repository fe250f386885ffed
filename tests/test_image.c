/* Images: camera orientation, layers summing to L, EXR read-back through the OpenEXR C API,
 * identical results for any thread count, sidecars, previews, and `bounce bounces` end to end. */
#include "bn_test.h"
#include "bounce/image.h"
#include "bounce/bake.h"
#include "bounce/rt.h"

#include <openexr.h>

/* Tolerances, each with its reason. */
/* Layers are rendered from double per-patch values and stored as float: the sum of n + 2 floats
 * differs from float(L) by a few float ulps (6e-8 each); 1e-5 relative is the bound. */
#define TOL_LAYER_SUM 1e-5

static bn_scene *load_cornell(size_t patches, bn_rt **rt)
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_scene *s = NULL;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    lo.log.fn = NULL;
    bn_mesh_opts_default(&mo);
    mo.target_patches = patches;
    if (bn_scene_load(bn_test_path("meshes/cornell-box.obj"), &lo, &s, &err) != BN_OK)
        BN_FAIL("load: %s", err.msg);
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("mesh: %s", err.msg);
    if (rt && bn_rt_create(s, 0, rt, &err) != BN_OK)
        BN_FAIL("rt: %s", err.msg);
    return s;
}

static bn_camera cornell_camera(const bn_scene *s, int size, int spp)
{
    bn_camera cam;
    bn_error err;
    int found = 0;
    bn_camera_default(s, &cam);
    BN_ASSERT_STATUS(bn_camera_load_sidecar(bn_test_path("meshes/cornell-box.obj"), &cam, &found, &err), BN_OK);
    BN_ASSERT_EQ(found, 1);
    cam.width = cam.height = size;
    cam.spp = spp;
    return cam;
}

BN_TEST(camera_orientation)
{
    /* The Cornell box through its published camera: red wall (x = 556) on the left, green
     * (x = 0) on the right, the light in the top half. */
    bn_rt *rt;
    bn_scene *s = load_cornell(300, &rt);
    size_t np;
    bn_scene_patches(s, &np);
    double *rho = malloc(np * 3 * sizeof(double)), *E = malloc(np * 3 * sizeof(double));
    bn_camera cam = cornell_camera(s, 64, 1);
    bn_image img[2];
    bn_error err;
    const double *vals[2] = {rho, E};
    bn_scene_patch_reflectance(s, rho);
    bn_scene_patch_emission(s, E);
    BN_ASSERT_STATUS(bn_image_alloc(&img[0], 64, 64, &err), BN_OK);
    BN_ASSERT_STATUS(bn_image_alloc(&img[1], 64, 64, &err), BN_OK);
    BN_ASSERT_STATUS(bn_image_render(rt, &cam, vals, 2, NULL, 1, 0, img, &err), BN_OK);
    double lr = 0, lg = 0, rr = 0, rg = 0, top = 0, bottom = 0;
    for (int y = 0; y < 64; y++)
        for (int x = 0; x < 64; x++) {
            const float *p = img[0].rgb + 3 * (y * 64 + x), *e = img[1].rgb + 3 * (y * 64 + x);
            if (x < 8) {
                lr += p[0];
                lg += p[1];
            }
            if (x >= 56) {
                rr += p[0];
                rg += p[1];
            }
            if (y < 32)
                top += e[0];
            else
                bottom += e[0];
        }
    BN_ASSERT_GT(lr, 3 * lg);   /* red wall on the left */
    BN_ASSERT_GT(rg, 2 * rr);   /* green wall on the right */
    BN_ASSERT_GT(top, 0);       /* the light is seen, in the top half only */
    BN_ASSERT_EQ(bottom, 0);
    bn_image_free(&img[0]);
    bn_image_free(&img[1]);
    free(rho);
    free(E);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

BN_TEST(camera_ray_frame)
{
    /* Row 0 on top, right = forward x up: looking +z with up +y, right is -x. */
    bn_camera cam = {{0, 0, 0}, {0, 0, 1}, {0, 1, 0}, 90, 100, 100, 1};
    double o[3], d[3];
    bn_camera_ray(&cam, 50, 50, o, d);
    BN_ASSERT_NEAR(d[2], 1, 1e-12);
    bn_camera_ray(&cam, 100, 50, o, d);   /* right edge: 45 degrees towards -x */
    BN_ASSERT_NEAR(d[0], -sqrt(0.5), 1e-12);
    bn_camera_ray(&cam, 50, 0, o, d);     /* top edge: +y */
    BN_ASSERT_NEAR(d[1], sqrt(0.5), 1e-12);
}

/* Synthetic per-patch terms, a smooth function of the centroid (honest for testing images). */
static void synthetic_terms(const bn_scene *s, int n, double **terms, double *rest, double *L)
{
    size_t np;
    const bn_patch *p = bn_scene_patches(s, &np);
    for (size_t i = 0; i < np; i++)
        for (int c = 0; c < 3; c++) {
            double sum = 0;
            for (int k = 0; k <= n; k++) {
                terms[k][3 * i + c] = pow(0.5, k) * (1 + 0.5 * sin(0.01 * p[i].centroid[c] + k)) * (c + 1);
                sum += terms[k][3 * i + c];
            }
            rest[3 * i + c] = 0.25 * (1 + cos(0.02 * p[i].centroid[(c + 1) % 3]));
            L[3 * i + c] = sum + rest[3 * i + c];
        }
}

static void check_layers_sum(int smooth, int spp)
{
    enum { N = 3, NL = N + 3, W = 48 };
    bn_rt *rt;
    bn_scene *s = load_cornell(300, &rt);
    bn_bake *bake = NULL;
    size_t np;
    bn_scene_patches(s, &np);
    double *arr[NL];
    bn_image img[NL];
    bn_error err;
    bn_camera cam = cornell_camera(s, W, spp);
    for (int l = 0; l < NL; l++) {
        arr[l] = calloc(np * 3, sizeof(double));
        BN_ASSERT_STATUS(bn_image_alloc(&img[l], W, W, &err), BN_OK);
    }
    synthetic_terms(s, N, arr, arr[N + 1], arr[N + 2]);
    if (smooth)
        BN_ASSERT_STATUS(bn_bake_create(s, 30, &bake, &err), BN_OK);
    BN_ASSERT_STATUS(bn_image_render(rt, &cam, (const double *const *)arr, NL, bake, 7, 0, img, &err), BN_OK);
    size_t lit = 0;
    for (size_t i = 0; i < (size_t)W * W * 3; i++) {
        double sum = 0, L = img[NL - 1].rgb[i];
        for (int l = 0; l < NL - 1; l++)
            sum += img[l].rgb[i];
        BN_ASSERT_LE(fabs(sum - L), TOL_LAYER_SUM * fabs(L));
        BN_ASSERT(isfinite(L));
        lit += L > 0;
    }
    BN_ASSERT_GT(lit, (size_t)W * W);   /* most of the image sees the box */
    for (int l = 0; l < NL; l++) {
        free(arr[l]);
        bn_image_free(&img[l]);
    }
    bn_bake_destroy(bake);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

BN_TEST(layers_sum_to_L_flat) { check_layers_sum(0, 1); }
BN_TEST(layers_sum_to_L_smooth_supersampled) { check_layers_sum(1, 4); }

BN_TEST(threads_identical)
{
    bn_rt *rt;
    bn_scene *s = load_cornell(300, &rt);
    size_t np;
    bn_scene_patches(s, &np);
    double *rho = malloc(np * 3 * sizeof(double));
    const double *vals[1] = {rho};
    bn_image a, b;
    bn_error err;
    bn_camera cam = cornell_camera(s, 40, 9);
    bn_scene_patch_reflectance(s, rho);
    BN_ASSERT_STATUS(bn_image_alloc(&a, 40, 40, &err), BN_OK);
    BN_ASSERT_STATUS(bn_image_alloc(&b, 40, 40, &err), BN_OK);
    BN_ASSERT_STATUS(bn_image_render(rt, &cam, vals, 1, NULL, 3, 1, &a, &err), BN_OK);
    BN_ASSERT_STATUS(bn_image_render(rt, &cam, vals, 1, NULL, 3, 2, &b, &err), BN_OK);
    BN_ASSERT_EQ(memcmp(a.rgb, b.rgb, 40 * 40 * 3 * sizeof(float)), 0);
    bn_image_free(&a);
    bn_image_free(&b);
    free(rho);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* Reads every channel of an EXR through the OpenEXR C API: names[i] and data[i] (w*h floats). */
static int read_exr(const char *path, char names[][32], float **data, int max, int *w, int *h, char *cmdline, size_t n)
{
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    const exr_attr_chlist_t *chl;
    exr_attr_box2i_t dw;
    int32_t lines;
    const char *s;
    int32_t len;
    BN_ASSERT_EQ(exr_start_read(&ctx, path, &init), EXR_ERR_SUCCESS);
    BN_ASSERT_EQ(exr_get_channels(ctx, 0, &chl), EXR_ERR_SUCCESS);
    BN_ASSERT_EQ(exr_get_data_window(ctx, 0, &dw), EXR_ERR_SUCCESS);
    BN_ASSERT_EQ(exr_get_scanlines_per_chunk(ctx, 0, &lines), EXR_ERR_SUCCESS);
    *w = dw.max.x - dw.min.x + 1;
    *h = dw.max.y - dw.min.y + 1;
    BN_ASSERT_LE(chl->num_channels, max);
    if (exr_attr_get_string(ctx, 0, "bounce:commandLine", &len, &s) == EXR_ERR_SUCCESS)
        snprintf(cmdline, n, "%.*s", (int)len, s);
    else
        cmdline[0] = '\0';
    for (int c = 0; c < chl->num_channels; c++) {
        snprintf(names[c], 32, "%s", chl->entries[c].name.str);
        data[c] = calloc((size_t)*w * *h, sizeof(float));
    }
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int init_done = 0;
    for (int y = 0; y < *h; y += lines) {
        exr_chunk_info_t ci;
        BN_ASSERT_EQ(exr_read_scanline_chunk_info(ctx, 0, y, &ci), EXR_ERR_SUCCESS);
        if (!init_done)
            BN_ASSERT_EQ(exr_decoding_initialize(ctx, 0, &ci, &dec), EXR_ERR_SUCCESS);
        else
            BN_ASSERT_EQ(exr_decoding_update(ctx, 0, &ci, &dec), EXR_ERR_SUCCESS);
        for (int c = 0; c < dec.channel_count; c++) {
            int k;
            for (k = 0; k < chl->num_channels; k++)
                if (strcmp(names[k], dec.channels[c].channel_name) == 0)
                    break;
            dec.channels[c].decode_to_ptr = (uint8_t *)(data[k] + (size_t)ci.start_y * *w);
            dec.channels[c].user_pixel_stride = 4;
            dec.channels[c].user_line_stride = 4 * *w;
            dec.channels[c].user_data_type = EXR_PIXEL_FLOAT;
            dec.channels[c].user_bytes_per_element = 4;
        }
        if (!init_done)
            BN_ASSERT_EQ(exr_decoding_choose_default_routines(ctx, 0, &dec), EXR_ERR_SUCCESS);
        init_done = 1;
        BN_ASSERT_EQ(exr_decoding_run(ctx, 0, &dec), EXR_ERR_SUCCESS);
    }
    exr_decoding_destroy(ctx, &dec);
    int nch = chl->num_channels;
    exr_finish(&ctx);
    return nch;
}

static void make_test_layers(bn_image *img, int w, int h, float big)
{
    bn_error err;
    for (int l = 0; l < 3; l++) {
        BN_ASSERT_STATUS(bn_image_alloc(&img[l], w, h, &err), BN_OK);
        for (int i = 0; i < w * h * 3; i++)
            img[l].rgb[i] = (float)((l + 1) * 0.001 * i + 1e-3 * (i % 7)) + (i == 5 ? big : 0);
    }
}

BN_TEST(exr_roundtrip_c_api)
{
    enum { W = 37, H = 53 };   /* more rows than one ZIP chunk (16), odd sizes */
    bn_image img[3];
    const char *lname[3] = {"E", "KE", "K2E"};
    bn_layer layers[3];
    bn_attr attrs[2] = {{"bounce:commandLine", "bounce bounces test"}, {"bounce:units", "W m^-2 sr^-1"}};
    bn_error err;
    char names[16][32], cmd[256];
    float *data[16];
    int w, h;
    make_test_layers(img, W, H, 0);
    for (int l = 0; l < 3; l++)
        layers[l] = (bn_layer){lname[l], &img[l]};
    const char *path = bn_test_tmp("rt.exr");
    BN_ASSERT_STATUS(bn_exr_write(path, layers, 3, attrs, 2, 0, NULL, &err), BN_OK);
    int nch = read_exr(path, names, data, 16, &w, &h, cmd, sizeof cmd);
    BN_ASSERT_EQ(nch, 9);
    BN_ASSERT_EQ(w, W);
    BN_ASSERT_EQ(h, H);
    BN_ASSERT(strcmp(cmd, "bounce bounces test") == 0);
    for (int l = 0; l < 3; l++)
        for (int c = 0; c < 3; c++) {
            char want[32];
            int k;
            snprintf(want, sizeof want, "%s.%c", lname[l], "RGB"[c]);
            for (k = 0; k < nch; k++)
                if (strcmp(names[k], want) == 0)
                    break;
            if (k == nch)
                BN_FAIL("channel %s missing", want);
            for (int i = 0; i < W * H; i++)
                if (data[k][i] != img[l].rgb[3 * i + c])
                    BN_FAIL("%s pixel %d: read %.9g, wrote %.9g", want, i, data[k][i], img[l].rgb[3 * i + c]);
        }
    for (int k = 0; k < nch; k++)
        free(data[k]);
    /* No temporary left beside it. */
    {
        char cmd[9000];
        snprintf(cmd, sizeof cmd, "test $(ls -a '%s' | grep -c '[.]tmp') -eq 0", bn_test_tmpdir());
        BN_ASSERT_EQ(bn_test_run(cmd, NULL), 0);
    }
    for (int l = 0; l < 3; l++)
        bn_image_free(&img[l]);
}

BN_TEST(exr_half_clamps)
{
    bn_image img[3];
    bn_layer layers[3] = {{"E", &img[0]}, {"KE", &img[1]}, {"L", &img[2]}};
    bn_error err;
    char names[16][32], cmd[64];
    float *data[16];
    int w, h;
    make_test_layers(img, 8, 8, 1e6f);
    const char *path = bn_test_tmp("half.exr");
    bn_log quiet = {NULL, NULL, 1};
    BN_ASSERT_STATUS(bn_exr_write(path, layers, 3, NULL, 0, 1, &quiet, &err), BN_OK);
    int nch = read_exr(path, names, data, 16, &w, &h, cmd, sizeof cmd);
    BN_ASSERT_EQ(nch, 9);
    for (int k = 0; k < nch; k++) {
        for (int i = 0; i < 64; i++) {
            BN_ASSERT(isfinite(data[k][i]));
            BN_ASSERT_LE(data[k][i], 65504);
        }
        free(data[k]);
    }
    /* NaN is refused, nothing written. */
    img[1].rgb[4] = NAN;
    BN_ASSERT_STATUS(bn_exr_write(bn_test_tmp("nan.exr"), layers, 3, NULL, 0, 0, NULL, &err), BN_ENUMERIC);
    BN_ASSERT(!bn_test_file_exists(bn_test_tmp("nan.exr")));
    for (int l = 0; l < 3; l++)
        bn_image_free(&img[l]);
}

BN_TEST(sidecar)
{
    bn_camera cam = {{0, 0, 0}, {0, 0, 1}, {0, 1, 0}, 40, 10, 10, 1};
    bn_error err;
    int found = 1;
    FILE *f = fopen(bn_test_tmp("s.camera"), "w");
    fprintf(f, "# test\neye 1,2,3\nlook 1, 2, 4  # trailing comment\nfov 30\nsize 20x10\nspp 4\n");
    fclose(f);
    BN_ASSERT_STATUS(bn_camera_load_sidecar(bn_test_tmp("s.obj"), &cam, &found, &err), BN_OK);
    BN_ASSERT_EQ(found, 1);
    BN_ASSERT_EQ(cam.eye[2], 3);
    BN_ASSERT_EQ(cam.look[2], 4);
    BN_ASSERT_EQ(cam.fov_deg, 30);
    BN_ASSERT_EQ(cam.width, 20);
    BN_ASSERT_EQ(cam.height, 10);
    BN_ASSERT_EQ(cam.spp, 4);
    BN_ASSERT_STATUS(bn_camera_load_sidecar(bn_test_tmp("none.obj"), &cam, &found, &err), BN_OK);
    BN_ASSERT_EQ(found, 0);
    f = fopen(bn_test_tmp("bad.camera"), "w");
    fprintf(f, "eye 1,2,3\nlook 1,2\n");
    fclose(f);
    BN_ASSERT_STATUS(bn_camera_load_sidecar(bn_test_tmp("bad.ply"), &cam, &found, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "bad.camera:2:") != NULL);
    f = fopen(bn_test_tmp("bad2.camera"), "w");
    fprintf(f, "zoom 3\n");
    fclose(f);
    BN_ASSERT_STATUS(bn_camera_load_sidecar(bn_test_tmp("bad2.obj"), &cam, &found, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "unknown key 'zoom'") != NULL);
    cam.up[0] = 0, cam.up[1] = 0, cam.up[2] = 1;   /* parallel to the view */
    memcpy(cam.eye, (double[3]){0, 0, 0}, sizeof cam.eye);
    memcpy(cam.look, (double[3]){0, 0, 5}, sizeof cam.look);
    BN_ASSERT_STATUS(bn_camera_validate(&cam, &err), BN_EINPUT);
}

static int is_png(const char *path)
{
    size_t n;
    char *d = bn_test_read_file(path, &n);
    int ok = d && n > 8 && memcmp(d, "\x89PNG\r\n\x1a\n", 8) == 0;
    free(d);
    return ok;
}

BN_TEST(previews)
{
    bn_image img[3];
    bn_layer layers[3] = {{"E", &img[0]}, {"KE", &img[1]}, {"K2E", &img[2]}};
    bn_error err;
    make_test_layers(img, 50, 30, 0);
    /* pixels read back through OpenImageIO: test_image_readback.png_pixels */
    BN_ASSERT_STATUS(bn_png_write(bn_test_tmp("p.png"), &img[1], 0, NULL, 0, &err), BN_OK);
    BN_ASSERT(is_png(bn_test_tmp("p.png")));
    BN_ASSERT_STATUS(bn_contact_sheet_write(bn_test_tmp("sheet.png"), layers, 3, -2, 0, NULL, 0, NULL, &err), BN_OK);
    BN_ASSERT(is_png(bn_test_tmp("sheet.png")));
    BN_ASSERT_EQ(bn_tonemap_srgb8(1, 0), 255);
    BN_ASSERT_EQ(bn_tonemap_srgb8(0.5, 1), 255);
    BN_ASSERT_EQ(bn_tonemap_srgb8(-1, 0), 0);
    BN_ASSERT_EQ(bn_tonemap_srgb8(NAN, 0), 0);
    BN_ASSERT_EQ(bn_tonemap_srgb8(0.2158605, 0), 128);   /* linear 0.21586 is sRGB 128/255 */
    for (int l = 0; l < 3; l++)
        bn_image_free(&img[l]);
}

BN_TEST(cli_bounces_cornell)
{
    char *out = NULL, cmd[2048], names[32][32], line[1024];
    float *data[32];
    int w, h;
    snprintf(cmd, sizeof cmd,
             "bounces '%s' -n 2 -o '%s' --patches 150 --ff hemisphere --samples 256 --size 40x32 --spp 2 --quiet "
             "--patches-out '%s'",
             bn_test_path("meshes/cornell-box.obj"), bn_test_tmp("cb.exr"), bn_test_tmp("cb.csv"));
    int rc = bn_test_bounce(cmd, &out);
    if (rc != 0)
        BN_FAIL("bounce exited %d: %s", rc, out ? out : "");
    free(out);
    /* --patches-out: the rows `bounce solve -n 2` writes for the same scene and options */
    snprintf(cmd, sizeof cmd, "solve '%s' -n 2 -o '%s' --patches 150 --ff hemisphere --samples 256 --quiet",
             bn_test_path("meshes/cornell-box.obj"), bn_test_tmp("cs.csv"));
    rc = bn_test_bounce(cmd, &out);
    if (rc != 0)
        BN_FAIL("bounce solve exited %d: %s", rc, out ? out : "");
    free(out);
    {
        FILE *a = fopen(bn_test_tmp("cb.csv"), "r"), *b = fopen(bn_test_tmp("cs.csv"), "r");
        char la[4096], lb[4096];
        int rows = 0;
        BN_ASSERT(a && b);
        for (;;) {
            char *ra, *rb;
            while ((ra = fgets(la, sizeof la, a)) && la[0] == '#') {
            }
            while ((rb = fgets(lb, sizeof lb, b)) && lb[0] == '#') {
            }
            BN_ASSERT((ra == NULL) == (rb == NULL));
            if (!ra || !rb)
                break;
            if (strcmp(la, lb) != 0)
                BN_FAIL("row %d differs: bounces: %s solve: %s", rows, la, lb);
            rows++;
        }
        BN_ASSERT(rows > 100);   /* the header and a row per patch (--patches 150 is a target) */
        fclose(a);
        fclose(b);
    }
    int nch = read_exr(bn_test_tmp("cb.exr"), names, data, 32, &w, &h, line, sizeof line);
    BN_ASSERT_EQ(nch, 15);   /* E KE K2E rest L */
    BN_ASSERT_EQ(w, 40);
    BN_ASSERT_EQ(h, 32);
    BN_ASSERT(strstr(line, "bounces") != NULL);
    for (int k = 0; k < nch; k++) {
        BN_ASSERT(strstr(names[k], "K1E") == NULL);
        for (int i = 0; i < w * h; i++)
            BN_ASSERT(isfinite(data[k][i]));
        free(data[k]);
    }
    /* the previews' pixels against these layers: test_image_readback.cli_previews_match_exr */
    BN_ASSERT(is_png(bn_test_tmp("cb.sheet.png")));
    /* A usage error is exit code 2 and names the option. */
    rc = bn_test_bounce("bounces x.obj --size 0x3", &out);
    BN_ASSERT_EQ(rc, 2);
    BN_ASSERT(out && strstr(out, "--size"));
    free(out);
}
