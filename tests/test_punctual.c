/* Punctual lights (glTF KHR_lights_punctual): read where their nodes put them, refused by JSON pointer
 * when malformed, and a spot light's direct light on a plane against its closed form, E = I cos^3 / h^2
 * times the cone profile (glTF's t^2), per pixel in the final gather and per patch in the path tracer and
 * in the radiosity source; and a point light in a closed box passes the crosscheck. */
#include "bn_test.h"
#include "bounce/gather.h"
#include "bounce/image.h"
#include "bounce/pipeline.h"
#include "bounce/rt.h"
#include "bounce/trace.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI 3.14159265358979323846

/* A 4 x 4 m floor at y = 0 facing up (reflectance 0.5), as a glTF with `lights` and `nodes` after it. */
static const float FLOOR[12] = {-2, 0, -2, -2, 0, 2, 2, 0, 2, 2, 0, -2};
static const uint16_t FLOOR_IDX[6] = {0, 1, 2, 0, 2, 3};

static const char *floor_gltf(const char *name, const char *lights, const char *nodes, const char *roots)
{
    unsigned char bin[60];
    char json[4096];
    memcpy(bin, FLOOR, 48);
    memcpy(bin + 48, FLOOR_IDX, 12);
    snprintf(json, sizeof json,
             "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_lights_punctual\"],"
             "\"buffers\":[{\"byteLength\":@N@,\"uri\":\"@URI@\"}],"
             "\"bufferViews\":[{\"buffer\":0,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":12}],"
             "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\"},"
             "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}],"
             "\"materials\":[{\"name\":\"floor\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[0.5,0.5,0.5,1]}}],"
             "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":0}]}],"
             "\"extensions\":{\"KHR_lights_punctual\":{\"lights\":[%s]}},"
             "\"nodes\":[{\"name\":\"floor\",\"mesh\":0},%s],\"scenes\":[{\"nodes\":[0,%s]}]}",
             lights, nodes, roots);
    return bn_test_write_gltf(name, json, bin, sizeof bin);
}

/* Lights under nodes: a point light two levels down, a spot turned to shine down -y, a directional
 * light along -z (the node's own -z); intensity x colour, the cones' cosines. */
BN_TEST(lights_are_placed_by_their_nodes)
{
    const char *path = floor_gltf("placed.gltf",
                                  "{\"type\":\"point\",\"color\":[1,0.5,0.25],\"intensity\":4,\"name\":\"bulb\"},"
                                  "{\"type\":\"spot\",\"intensity\":2,\"spot\":{\"innerConeAngle\":0.25,"
                                  "\"outerConeAngle\":0.5}},{\"type\":\"directional\",\"intensity\":3}",
                                  "{\"translation\":[0,0,2],\"children\":[2]},"
                                  "{\"translation\":[1,0,0],\"extensions\":{\"KHR_lights_punctual\":{\"light\":0}}},"
                                  "{\"name\":\"s\",\"translation\":[0,1,0],\"rotation\":[-0.70710678118654752,0,0,"
                                  "0.70710678118654752],\"extensions\":{\"KHR_lights_punctual\":{\"light\":1}}},"
                                  "{\"extensions\":{\"KHR_lights_punctual\":{\"light\":2}}}",
                                  "1,3,4");
    bn_load_opts lo;
    bn_scene *s = NULL;
    bn_error err;
    size_t n;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    BN_ASSERT_STATUS(bn_scene_load(path, &lo, &s, &err), BN_OK);
    const bn_light *l = bn_scene_lights(s, &n);
    BN_ASSERT_EQ(n, 3);
    BN_ASSERT(l[0].type == BN_LIGHT_POINT && strcmp(l[0].name, "bulb") == 0);
    BN_ASSERT_NEAR(l[0].pos[0], 1, 1e-12);
    BN_ASSERT_NEAR(l[0].pos[1], 0, 1e-12);
    BN_ASSERT_NEAR(l[0].pos[2], 2, 1e-12);
    BN_ASSERT_NEAR(l[0].I[0], 4, 1e-12);
    BN_ASSERT_NEAR(l[0].I[1], 2, 1e-12);
    BN_ASSERT_NEAR(l[0].I[2], 1, 1e-12);
    BN_ASSERT(l[1].type == BN_LIGHT_SPOT && strcmp(l[1].name, "s") == 0);
    BN_ASSERT_NEAR(l[1].dir[0], 0, 1e-12);
    BN_ASSERT_NEAR(l[1].dir[1], -1, 1e-12);
    BN_ASSERT_NEAR(l[1].dir[2], 0, 1e-12);
    BN_ASSERT_NEAR(l[1].cos_inner, cos(0.25), 1e-15);
    BN_ASSERT_NEAR(l[1].cos_outer, cos(0.5), 1e-15);
    BN_ASSERT(l[2].type == BN_LIGHT_DIRECTIONAL);
    BN_ASSERT_NEAR(l[2].dir[2], -1, 1e-12);
    BN_ASSERT_NEAR(l[2].I[1], 3, 1e-12);
    double w[3];
    bn_light_power(&l[0], w);   /* a point light: 4 pi I */
    BN_ASSERT_NEAR(w[0], 16 * PI, 1e-12);
    bn_light_power(&l[1], w);   /* a spot: 2 pi times the profile's integral over cos, by a finer rule here */
    double want = 0;
    for (int k = 0; k < 100000; k++) {
        double c = cos(0.5) + (1 - cos(0.5)) * (k + 0.5) / 100000, t = (c - cos(0.5)) / (cos(0.25) - cos(0.5));
        want += 2 * PI * 2 * fmin(1, t * t) * (1 - cos(0.5)) / 100000;
    }
    BN_ASSERT_NEAR(w[0], want, 1e-6 * want);
    bn_scene_destroy(s);
}

/* A malformed light is refused, naming it. */
BN_TEST(bad_lights_are_refused_by_json_pointer)
{
    static const struct {
        const char *lights, *light, *says;
    } cases[] = {
        {"{\"type\":\"area\"}", "0", "/extensions/KHR_lights_punctual/lights/0: type is not point, spot or directional"},
        {"{\"type\":\"point\"}", "3", "/nodes/1/extensions/KHR_lights_punctual/light: no such light"},
        {"{\"type\":\"point\",\"intensity\":-1}", "0", "lights/0: intensity is not a finite number >= 0"},
        {"{\"type\":\"point\",\"color\":[1.5,1,1]}", "0", "lights/0: a color value is outside [0, 1]"},
        {"{\"type\":\"spot\",\"spot\":{\"innerConeAngle\":0.6,\"outerConeAngle\":0.5}}", "0",
         "lights/0: the cone angles are not 0 <= innerConeAngle < outerConeAngle <= pi/2"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        char node[256];
        snprintf(node, sizeof node, "{\"extensions\":{\"KHR_lights_punctual\":{\"light\":%s}}}", cases[i].light);
        bn_load_opts lo;
        bn_scene *s = NULL;
        bn_error err;
        bn_load_opts_default(&lo);
        lo.log.quiet = 1;
        BN_ASSERT_STATUS(bn_scene_load(floor_gltf("bad.gltf", cases[i].lights, node, "1"), &lo, &s, &err), BN_EINPUT);
        if (!strstr(err.msg, cases[i].says) || !strstr(err.msg, "bad.gltf"))
            BN_FAIL("'%s' does not say '%s'", err.msg, cases[i].says);
    }
}

/* The spot of the closed-form tests: at (X0, H, Z0) shining down, intensity I, cones 0.3 and 0.6. */
#define X0 0.3
#define Z0 (-0.2)
#define H 1.0
#define I0 2.0
static double spot_E(double x, double z)
{
    double r2 = (x - X0) * (x - X0) + (z - Z0) * (z - Z0), c = H / sqrt(H * H + r2);
    double t = (c - cos(0.6)) / (cos(0.3) - cos(0.6));
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return I0 * c * c * c / (H * H) * t * t;
}

static void spot_pipeline(bn_pipeline *p)
{
    bn_pipeline_opts o;
    bn_error err;
    char node[256];
    snprintf(node, sizeof node, "{\"translation\":[%g,%g,%g],\"rotation\":[-0.70710678118654752,0,0,"
             "0.70710678118654752],\"extensions\":{\"KHR_lights_punctual\":{\"light\":0}}}", X0, H, Z0);
    const char *path = floor_gltf("spot.gltf", "{\"type\":\"spot\",\"intensity\":2,\"spot\":{\"innerConeAngle\":0.3,"
                                  "\"outerConeAngle\":0.6}}", node, "1");
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.mesh.target_patches = 400;
    o.transport = "dense";
    o.ff.quiet = 1;
    o.solve.quiet = 1;
    o.solve.log_sink.quiet = 1;
    o.solve.bounces = 2;
    o.row_sum_rays = 0;
    o.keep_rt = 1;
    memset(p, 0, sizeof *p);
    if (bn_pipeline_run(path, &o, p, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
}

/* Per pixel: the floor seen from above through the final gather; the floor sees nothing else, so its
 * KE is rho / pi x E at the pixel's point, exactly. */
BN_TEST(spot_light_in_the_gather_matches_the_closed_form_per_pixel)
{
    bn_pipeline p;
    bn_error err;
    spot_pipeline(&p);
    bn_camera cam = {{X0, 3, Z0}, {X0, 0, Z0}, {0, 0, 1}, 50.0, 64, 64, 1};
    bn_image img[5];
    bn_gather_opts go;
    for (int l = 0; l < 5; l++)
        BN_ASSERT_STATUS(bn_image_alloc(&img[l], 64, 64, &err), BN_OK);
    bn_gather_opts_default(&go);
    go.quiet = 1;
    go.hemi_samples = 1;
    BN_ASSERT_STATUS(bn_gather_render(p.rt, &cam, (const double *const *)p.res.terms, 2, p.rest, &go, img, NULL, &err),
                     BN_OK);
    double worst = 0, e0 = 0;
    int lit = 0;
    for (int y = 0; y < 64; y++)
        for (int x = 0; x < 64; x++) {
            double o[3], d[3];
            size_t pix = (size_t)y * 64 + (size_t)x;
            bn_camera_ray(&cam, x + 0.5, y + 0.5, o, d);
            double t = -o[1] / d[1], want = 0.5 / PI * spot_E(o[0] + t * d[0], o[2] + t * d[2]);
            e0 = fmax(e0, img[0].rgb[3 * pix]);   /* E: a punctual light is not seen */
            if (want < 1e-3) {
                BN_ASSERT_LE(img[1].rgb[3 * pix], 1e-3);
                continue;
            }
            lit++;
            worst = fmax(worst, fabs(img[1].rgb[3 * pix] - want) / want);
        }
    printf("spot, gather: %d lit pixels, worst relative error of KE %.2e\n", lit, worst);
    BN_ASSERT(lit > 300);
    BN_ASSERT_LE(worst, 1e-5);   /* the pixel's point itself: the gather's float image */
    BN_ASSERT_EQ(e0, 0);
    for (int l = 0; l < 5; l++)
        bn_image_free(&img[l]);
    bn_pipeline_free(&p);
}

/* Patch q's mean of rho / pi x E by a fine midpoint rule of the test's own (64 x 64 per triangle). */
static double patch_exact(const bn_scene *s, const bn_patch *q)
{
    const double *pv = bn_scene_patch_vertices(s, NULL);
    double sum = 0, area = 0;
    for (unsigned k = 1; k + 1 < q->ncorners; k++) {
        const double *a = pv + 3 * q->corner[0], *b = pv + 3 * q->corner[k], *c = pv + 3 * q->corner[k + 1];
        double at = 0.5 * fabs((b[0] - a[0]) * (c[2] - a[2]) - (c[0] - a[0]) * (b[2] - a[2]));
        for (int i = 0; i < 64; i++)
            for (int j = 0; i + j < 64; j++)
                for (int up = 0; up < 2 && (up == 0 || i + j + 1 < 64); up++) {
                    double s1 = (i + (up ? 2.0 : 1.0) / 3) / 64, s2 = (j + (up ? 2.0 : 1.0) / 3) / 64;
                    sum += at / 4096 * spot_E(a[0] + s1 * (b[0] - a[0]) + s2 * (c[0] - a[0]),
                                              a[2] + s1 * (b[2] - a[2]) + s2 * (c[2] - a[2]));
                }
        area += at;
    }
    return 0.5 / PI * sum / area;
}

/* Per patch: the path tracer's KE within 5 standard errors of the closed form's patch mean, and the
 * radiosity source (its KE term) within 0.5% where the patch is lit. */
BN_TEST(spot_light_in_the_tracer_and_the_source_matches_the_closed_form_per_patch)
{
    bn_pipeline p;
    bn_error err;
    spot_pipeline(&p);
    bn_trace_opts to;
    bn_trace_patches tp;
    size_t np;
    const bn_patch *pa = bn_scene_patches(p.scene, &np);
    bn_trace_opts_default(&to);
    to.spp = 64;
    to.bounces = 1;
    BN_ASSERT_STATUS(bn_trace_patches_run(p.rt, &to, &tp, &err), BN_OK);
    double zmax = 0, worst = 0;
    int lit = 0;
    for (size_t q = 0; q < np; q++) {
        double want = patch_exact(p.scene, &pa[q]), got = tp.mean[(1 * np + q) * 3], se = tp.se[(1 * np + q) * 3];
        double src = p.res.terms[1][3 * q];
        if (se > 0)
            zmax = fmax(zmax, fabs(got - want) / se);
        else   /* every sample alike (all outside the cone, or all in its flat top): the light is that */
            BN_ASSERT_LE(fabs(got - want), 1e-3 * 0.5 / PI * I0);
        if (want > 1e-3) {
            lit++;
            worst = fmax(worst, fabs(src - want) / want);
        }
    }
    printf("spot, per patch: %zu patches (%d lit), tracer's worst |z| %.2f, the source's worst relative error %.2e\n",
           np, lit, zmax, worst);
    BN_ASSERT(lit > 20);
    BN_ASSERT_LE(zmax, 5);
    BN_ASSERT_LE(worst, 5e-3);
    bn_trace_patches_free(&tp);
    bn_pipeline_free(&p);
}
