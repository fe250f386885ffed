/* Reflectance textures (MTL map_Kd, glTF baseColorTexture): K takes each patch's mean reflectance over
 * its area, the images the reflectance at each pixel's point. Independent answers: a float gradient's
 * mean over a patch is its value at the patch's centroid (the texture is linear there), and a checker
 * whose squares are the patches gives the transport of the same floor cut into patches of the two
 * colours. */
#include "bn_test.h"
#include "bounce/image.h"
#include "bounce/pipeline.h"
#include "bounce/scene.h"

#include <stdint.h>

#define GW 64
#define GH 32

/* A linear gradient in x (red) and y (green), blue constant: texel (i, j) as stored. */
static double grad(int c, double i, double j)
{
    return c == 0 ? 0.1 + 0.8 * i / (GW - 1) : c == 1 ? 0.2 + 0.6 * j / (GH - 1) : 0.5;
}

/* A 1 x 1 m floor (y = 0, facing up) mapped onto the texture's middle half (u, v in [0.25, 0.75]; OBJ's
 * vt counts v from the bottom), Kd 0.5 1 1 times map_Kd gradient.exr, a light above. */
static const char *write_gradient_floor(void)
{
    bn_image img;
    bn_error err;
    BN_ASSERT_EQ(bn_image_alloc(&img, GW, GH, &err), BN_OK);
    for (int j = 0; j < GH; j++)
        for (int i = 0; i < GW; i++)
            for (int c = 0; c < 3; c++)
                img.rgb[3 * (j * GW + i) + c] = (float)grad(c, i, j);
    bn_layer layer = {"tex", &img};
    BN_ASSERT_EQ(bn_exr_write(bn_test_tmp("gradient.exr"), &layer, 1, NULL, 0, 0, NULL, &err), BN_OK);
    bn_image_free(&img);
    FILE *m = fopen(bn_test_tmp("floor.mtl"), "w"), *o = fopen(bn_test_tmp("floor.obj"), "w");
    fprintf(m, "newmtl floor\nKd 0.5 1 1\nmap_Kd -clamp on gradient.exr\nnewmtl light\nKd 0 0 0\nKe 5 5 5\n");
    fprintf(o, "mtllib floor.mtl\nv 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\n"
               "vt 0.25 0.25\nvt 0.25 0.75\nvt 0.75 0.75\nvt 0.75 0.25\nusemtl floor\nf 1/1 2/2 3/3 4/4\n"
               "v 0.4 1 0.4\nv 0.6 1 0.4\nv 0.6 1 0.6\nv 0.4 1 0.6\nusemtl light\nf 5 6 7 8\n");
    fclose(m), fclose(o);
    return bn_test_tmp("floor.obj");
}

/* The texture at floor point (x, z): u = 0.25 + x / 2, v = 1 - (0.25 + z / 2), texel centres at half
 * integers; times Kd. */
static double expected(int c, double x, double z)
{
    double u = 0.25 + 0.5 * x, v = 1 - (0.25 + 0.5 * z), kd = c == 0 ? 0.5 : 1;
    return kd * grad(c, u * GW - 0.5, v * GH - 0.5);
}

/* `path` loaded quietly and meshed at patch size `size` without contact cuts (0: the default mesh). */
static bn_scene *load_meshed(const char *path, double size)
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_scene *s = NULL;
    bn_error err;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    if (bn_scene_load(path, &lo, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_mesh_opts_default(&mo);
    if (size > 0)
        mo.patch_size = size, mo.no_contacts = 1;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    return s;
}

BN_TEST(exr_gradient_gives_each_patch_its_mean)
{
    bn_scene *s = load_meshed(write_gradient_floor(), 0.13);   /* patches that do not line up with texels */
    BN_ASSERT(bn_scene_textured(s));
    size_t np, nfloor = 0;
    const bn_patch *p = bn_scene_patches(s, &np);
    double *rho = malloc(3 * np * sizeof *rho), worst = 0;
    bn_scene_patch_reflectance(s, rho);
    for (size_t i = 0; i < np; i++) {
        if (p[i].normal[1] < 0.5)
            continue;   /* the light faces down */
        nfloor++;
        for (int c = 0; c < 3; c++)
            worst = fmax(worst, fabs(rho[3 * i + c] - expected(c, p[i].centroid[0], p[i].centroid[2])));
    }
    BN_ASSERT_GE(nfloor, 49);
    BN_ASSERT_LE(worst, 1e-6);
    /* and at a point, as the images read it */
    double x[3] = {0.3, 0, 0.8}, r[3];
    bn_scene_reflectance_at(s, 0, x, r);
    for (int c = 0; c < 3; c++)
        BN_ASSERT_NEAR(r[c], expected(c, 0.3, 0.8), 1e-6);
    free(rho);
    bn_scene_destroy(s);
}

/* ---- a checker on the floor of a closed box, against the floor cut by colour ---- */

static double srgb(double c) { return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4); }

typedef struct quad {
    float p[12], uv[8];
    int mat;
} quad;

/* The box's 1 x 1 x 1 m walls and ceiling (white, 4 x 4 patches each at 0.25), a light below the ceiling,
 * and `floor` (nfloor quads). Inward-facing: corners counter-clockwise seen from inside. */
static size_t box_quads(quad *q, const quad *floor, size_t nfloor)
{
    static const float w[5][12] = {
        {0, 1, 0, 1, 1, 0, 1, 1, 1, 0, 1, 1},   /* ceiling, facing down */
        {0, 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1},   /* x = 0 */
        {1, 0, 0, 1, 0, 1, 1, 1, 1, 1, 1, 0},   /* x = 1 */
        {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0},   /* z = 0 */
        {0, 0, 1, 0, 1, 1, 1, 1, 1, 1, 0, 1}};  /* z = 1 */
    static const float light[12] = {0.35f, 0.99f, 0.35f, 0.65f, 0.99f, 0.35f, 0.65f, 0.99f, 0.65f, 0.35f, 0.99f, 0.65f};
    size_t n = 0;
    memset(q, 0, 6 * sizeof *q);
    for (int k = 0; k < 5; k++, n++)
        memcpy(q[n].p, w[k], sizeof q[n].p), q[n].mat = 1;
    memcpy(q[n].p, light, sizeof q[n].p), q[n++].mat = 2;
    for (size_t k = 0; k < nfloor; k++)
        q[n++] = floor[k];
    return n;
}

/* The quads as glTF: positions, texture coordinates, a primitive per material (0: the floor's, 1 white
 * 0.7, 2 the light, 3 the second floor colour); materials[] as JSON; images and samplers as given. */
static const char *quads_gltf(const char *name, const quad *q, size_t n, const char *materials, const char *extra)
{
    size_t bytes = n * (48 + 32 + 24);
    unsigned char *bin = calloc(bytes, 1);
    uint32_t *idx = (uint32_t *)(bin + n * 80), cnt[4] = {0}, start[4];
    char *json = malloc(16384);
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
        memcpy(bin + 48 * i, q[i].p, 48);
        memcpy(bin + 48 * n + 32 * i, q[i].uv, 32);
    }
    for (int m = 0; m < 4; m++) {
        start[m] = (uint32_t)k;
        for (size_t i = 0; i < n; i++)
            for (int t = 0; q[i].mat == m && t < 6; t++, cnt[m]++)
                idx[k++] = (uint32_t)(4 * i) + (uint32_t[]){0, 1, 2, 0, 2, 3}[t];
    }
    int o = snprintf(json, 16384, "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":@N@,\"uri\":\"@URI@\"}],"
                     "\"bufferViews\":[{\"buffer\":0,\"byteLength\":%zu},{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu},"
                     "{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu}],\"accessors\":[{\"bufferView\":0,"
                     "\"componentType\":5126,\"count\":%zu,\"type\":\"VEC3\"},{\"bufferView\":1,\"componentType\":5126,"
                     "\"count\":%zu,\"type\":\"VEC2\"}", 48 * n, 48 * n, 32 * n, 80 * n, 24 * n, 4 * n, 4 * n);
    for (int m = 0; m < 4; m++)
        o += snprintf(json + o, 16384 - o, ",{\"bufferView\":2,\"byteOffset\":%u,\"componentType\":5125,\"count\":%u,"
                      "\"type\":\"SCALAR\"}", 4 * start[m], cnt[m]);
    o += snprintf(json + o, 16384 - o, "],\"materials\":[%s]%s,\"meshes\":[{\"primitives\":[", materials, extra);
    for (int m = 0, first = 1; m < 4; m++)
        if (cnt[m])
            o += snprintf(json + o, 16384 - o, "%s{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1},\"indices\":%d,"
                          "\"material\":%d}", first ? "" : ",", m + 2, m), first = 0;
    snprintf(json + o, 16384 - o, "]}],\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]}");
    const char *path = bn_test_write_gltf(name, json, bin, bytes);
    free(json), free(bin);
    return path;
}

/* An s x s checker of 8-bit grey texels 230 and 40 (texel (0, 0): 230), as a binary PPM. */
static void write_checker(const char *name, int s)
{
    FILE *f = fopen(bn_test_tmp(name), "wb");
    BN_ASSERT(f);
    fprintf(f, "P6\n%d %d\n255\n", s, s);
    for (int j = 0; j < s; j++)
        for (int i = 0; i < s; i++)
            for (int c = 0; c < 3; c++)
                fputc((i + j) % 2 ? 40 : 230, f);
    BN_ASSERT(fclose(f) == 0);
}

static void solve_box(const char *path, bn_pipeline *p)
{
    bn_pipeline_opts o;
    bn_error err;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.mesh.patch_size = 0.25;
    o.mesh.no_contacts = 1;   /* the light's edges near the ceiling: cuts unrelated to textures */
    o.transport = "dense";
    o.ff.quiet = 1;
    o.solve.quiet = 1;
    o.solve.log_sink.quiet = 1;
    o.row_sum_rays = 0;
    o.solve.tol = 1e-12;   /* the two scenes order their patches differently: solve both to the end */
    if (bn_pipeline_run(path, &o, p, &err) != BN_OK)
        BN_FAIL("%s: %s", path, err.msg);
}

#define WHITE "{\"name\":\"white\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[0.7,0.7,0.7,1]}}"
#define LIGHT                                                                                                     \
    "{\"name\":\"light\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[0,0,0,1]},\"emissiveFactor\":[1,1,1],"    \
    "\"extensions\":{\"KHR_materials_emissive_strength\":{\"emissiveStrength\":10}}}"

/* The floor at 4 x 4 patches of 0.25 m: one quad mapped onto the whole texture (split 0), or 16 quads,
 * each of material 0 or 3 by the checker's colour there (split 1). */
static size_t floor_quads(quad *f, int split)
{
    size_t n = 0;
    for (int a = 0; a < (split ? 4 : 1); a++)
        for (int b = 0; b < (split ? 4 : 1); b++, n++) {
            float x0 = split ? a / 4.0f : 0, x1 = split ? (a + 1) / 4.0f : 1, z0 = split ? b / 4.0f : 0,
                  z1 = split ? (b + 1) / 4.0f : 1;
            float p[12] = {x0, 0, z0, x0, 0, z1, x1, 0, z1, x1, 0, z0}, uv[8] = {x0, z0, x0, z1, x1, z1, x1, z0};
            memcpy(f[n].p, p, sizeof p), memcpy(f[n].uv, uv, sizeof uv);
            f[n].mat = split && (a + b) % 2 ? 3 : 0;
        }
    return n;
}

static const double *patch_L(const bn_pipeline *p, const double c[3])
{
    size_t np;
    const bn_patch *q = bn_scene_patches(p->scene, &np);
    for (size_t i = 0; i < np; i++)
        if (fabs(q[i].centroid[0] - c[0]) + fabs(q[i].centroid[1] - c[1]) + fabs(q[i].centroid[2] - c[2]) < 1e-6)
            return p->res.L + 3 * i;
    BN_FAIL("no patch at (%g, %g, %g)", c[0], c[1], c[2]);
}

/* A checker whose squares are the floor's patches (nearest texel, glTF's NEAREST sampler) gives, patch by
 * patch, the transport of the floor cut into patches of the two colours (as the sRGB texels decode). */
BN_TEST(checker_floor_solves_as_the_floor_cut_by_colour)
{
    quad q[32], f[16];
    char mats[1024];
    double ca = (float)srgb((float)(230 / 255.0)), cb = (float)srgb((float)(40 / 255.0));
    bn_pipeline tex, cut;
    write_checker("checker.ppm", 4);
    size_t n = box_quads(q, f, floor_quads(f, 0));
    snprintf(mats, sizeof mats, "{\"name\":\"floor\",\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":0}}},"
             WHITE "," LIGHT);
    solve_box(quads_gltf("textured.gltf", q, n, mats, ",\"textures\":[{\"source\":0,\"sampler\":0}],\"samplers\":"
                         "[{\"magFilter\":9728,\"minFilter\":9728}],\"images\":[{\"uri\":\"checker.ppm\"}]"), &tex);
    n = box_quads(q, f, floor_quads(f, 1));
    snprintf(mats, sizeof mats, "{\"name\":\"a\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[%.17g,%.17g,%.17g,1]}},"
             WHITE "," LIGHT ",{\"name\":\"b\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[%.17g,%.17g,%.17g,1]}}",
             ca, ca, ca, cb, cb, cb);
    solve_box(quads_gltf("cut.gltf", q, n, mats, ""), &cut);
    BN_ASSERT_EQ(tex.n, cut.n);
    size_t np;
    const bn_patch *pt = bn_scene_patches(tex.scene, &np);
    double worst = 0, floor_min = INFINITY, floor_max = 0;
    for (size_t i = 0; i < np; i++) {
        const double *a = tex.res.L + 3 * i, *b = patch_L(&cut, pt[i].centroid);
        for (int c = 0; c < 3; c++)
            worst = fmax(worst, fabs(a[c] - b[c]) / fmax(b[c], 1e-3));
        if (pt[i].normal[1] > 0.5)
            floor_min = fmin(floor_min, a[0]), floor_max = fmax(floor_max, a[0]);
    }
    BN_ASSERT_LE(worst, 1e-6);
    BN_ASSERT_GT(floor_max, 2 * floor_min);   /* the checker shows in the floor's light */
    bn_pipeline_free(&tex);
    bn_pipeline_free(&cut);
}

/* Squares of half a patch: each patch's reflectance is the mean of its two colours, not the texel at a
 * point (its centroid falls on a corner of four squares: one colour or the other). */
BN_TEST(checker_finer_than_the_patches_is_averaged)
{
    quad q[32], f[16];
    double mean = 0.5 * ((float)srgb((float)(230 / 255.0)) + (float)srgb((float)(40 / 255.0)));
    write_checker("checker.ppm", 8);
    size_t n = box_quads(q, f, floor_quads(f, 0));
    const char *path = quads_gltf("fine.gltf", q, n, "{\"name\":\"floor\",\"pbrMetallicRoughness\":{\"baseColorTexture\":"
                                  "{\"index\":0}}}," WHITE "," LIGHT, ",\"textures\":[{\"source\":0,\"sampler\":0}],"
                                  "\"samplers\":[{\"magFilter\":9728}],\"images\":[{\"uri\":\"checker.ppm\"}]");
    bn_scene *s = load_meshed(path, 0.25);
    size_t np, nfloor = 0;
    const bn_patch *p = bn_scene_patches(s, &np);
    double *rho = malloc(3 * np * sizeof *rho);
    bn_scene_patch_reflectance(s, rho);
    for (size_t i = 0; i < np; i++)
        if (p[i].normal[1] > 0.5) {
            nfloor++;
            BN_ASSERT_REL(rho[3 * i], mean, 0.02);
        }
    BN_ASSERT_EQ(nfloor, 16);
    free(rho);
    bn_scene_destroy(s);
}

/* A textured model as Debian's sweethome3d-furniture ships it (BlendSwap-CC-0.sh3f, a zip of OBJ, MTL and
 * JPEG): the rock, Kd 0.8 times map_Kd rock01.jpg, loads with its texture, and its patches' reflectance
 * varies as the texture does (independently: Kd times the texture's own mean bounds their area mean). */
#define SH3F "/usr/share/sweethome3d/furniture/BlendSwap-CC-0.sh3f"
BN_TEST(sweethome3d_model_loads_with_its_texture)
{
    char cmd[1024];
    if (!bn_test_file_exists(SH3F))
        BN_SKIP("Debian's sweethome3d-furniture is not installed (" SH3F ")");
    snprintf(cmd, sizeof cmd, "cd '%s' && python3 -c \"import zipfile; z = zipfile.ZipFile('%s'); "
             "[z.extract(n) for n in z.namelist() if n.startswith('blendswap-cc-0/rock1/')]\"", bn_test_tmpdir(), SH3F);
    BN_ASSERT_EQ(bn_test_run(cmd, NULL), 0);
    bn_scene *s = load_meshed(bn_test_tmp("blendswap-cc-0/rock1/rock1.obj"), 0);
    const char *name;
    int w, h;
    double mean[3];
    BN_ASSERT(bn_scene_material_texture(s, 0, &name, &w, &h, mean));
    BN_ASSERT(strcmp(name, "rock01.jpg") == 0 && w == 512 && h == 512);
    size_t np;
    const bn_patch *p = bn_scene_patches(s, &np);
    double *rho = malloc(3 * np * sizeof *rho), lo_r = 1, hi_r = 0, area = 0, sum = 0;
    bn_scene_patch_reflectance(s, rho);
    for (size_t i = 0; i < np; i++) {
        lo_r = fmin(lo_r, rho[3 * i]), hi_r = fmax(hi_r, rho[3 * i]);
        area += p[i].area, sum += p[i].area * rho[3 * i];
    }
    BN_ASSERT_GT(hi_r - lo_r, 0.05);            /* the texture shows */
    BN_ASSERT_LE(hi_r, 0.8 + 1e-12);             /* Kd 0.8 times texels <= 1 */
    BN_ASSERT_LT(fabs(sum / area - 0.8 * mean[0]), 0.8 * 0.5 * mean[0]);   /* about Kd x the mean */
    free(rho);
    bn_scene_destroy(s);
}

/* glTF's KHR_texture_transform (rotation a quarter turn, scale 1/2, offset (0.25, 0.75)) maps the floor onto
 * the gradient's middle as worked out by hand: u = z / 2 + 1/4, v = 3/4 - x / 2. */
BN_TEST(texture_transform_maps_as_the_extension_says)
{
    quad q[2];
    memset(q, 0, sizeof q);
    write_gradient_floor();   /* its gradient.exr */
    float fl[12] = {0, 0, 0, 0, 0, 1, 1, 0, 1, 1, 0, 0}, fuv[8] = {0, 0, 0, 1, 1, 1, 1, 0};
    float li[12] = {0.4f, 1, 0.4f, 0.6f, 1, 0.4f, 0.6f, 1, 0.6f, 0.4f, 1, 0.6f};
    memcpy(q[0].p, fl, sizeof fl), memcpy(q[0].uv, fuv, sizeof fuv), memcpy(q[1].p, li, sizeof li), q[1].mat = 2;
    const char *path = quads_gltf("transform.gltf", q, 2, "{\"name\":\"floor\",\"pbrMetallicRoughness\":{\"baseColorTexture\":"
                                  "{\"index\":0,\"extensions\":{\"KHR_texture_transform\":{\"offset\":[0.25,0.75],"
                                  "\"rotation\":1.5707963267948966,\"scale\":[0.5,0.5]}}}}}," WHITE "," LIGHT,
                                  ",\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"gradient.exr\"}]");
    bn_scene *s = load_meshed(path, 0.13);
    size_t np, nfloor = 0;
    const bn_patch *p = bn_scene_patches(s, &np);
    double *rho = malloc(3 * np * sizeof *rho), worst = 0;
    bn_scene_patch_reflectance(s, rho);
    for (size_t i = 0; i < np; i++)
        if (p[i].normal[1] > 0.5) {
            double u = 0.5 * p[i].centroid[2] + 0.25, v = 0.75 - 0.5 * p[i].centroid[0];
            nfloor++;
            worst = fmax(worst, fabs(rho[3 * i] - grad(0, u * GW - 0.5, 0)));
            worst = fmax(worst, fabs(rho[3 * i + 1] - grad(1, 0, v * GH - 0.5)));
        }
    BN_ASSERT_GE(nfloor, 49);
    BN_ASSERT_LE(worst, 1e-6);
    free(rho);
    bn_scene_destroy(s);
}

/* An emissive texture enters per face as its mean over the face (emission is uniform over a face): an
 * atlas of two texels, 255 and 0 (sRGB 1 and 0, NEAREST), under emissiveFactor 1 and strength 10; a lamp
 * mapped on the bright texel alone emits 10, one straddling both 5, and the scene's power is their sum
 * (the whole image's mean, 5 for both, would be wrong for the first). */
BN_TEST(emissive_texture_enters_as_its_mean_over_each_face)
{
    quad q[3];
    memset(q, 0, sizeof q);
    FILE *f = fopen(bn_test_tmp("glow.ppm"), "wb");
    BN_ASSERT(f);
    fprintf(f, "P6\n2 1\n255\n");
    for (int k = 0; k < 2; k++)
        for (int c = 0; c < 3; c++)
            fputc(k == 0 ? 255 : 0, f);
    BN_ASSERT(fclose(f) == 0);
    float fl[12] = {0, 0, 0, 0, 0, 1, 1, 0, 1, 1, 0, 0};
    float a[12] = {0.2f, 1, 0.4f, 0.4f, 1, 0.4f, 0.4f, 1, 0.6f, 0.2f, 1, 0.6f};
    float b[12] = {0.6f, 1, 0.4f, 0.8f, 1, 0.4f, 0.8f, 1, 0.6f, 0.6f, 1, 0.6f};
    float ua[8] = {0, 0, 0.5f, 0, 0.5f, 1, 0, 1}, ub[8] = {0.25f, 0, 0.75f, 0, 0.75f, 1, 0.25f, 1};
    memcpy(q[0].p, fl, sizeof fl), memcpy(q[1].p, a, sizeof a), memcpy(q[2].p, b, sizeof b);
    memcpy(q[1].uv, ua, sizeof ua), memcpy(q[2].uv, ub, sizeof ub);
    q[1].mat = q[2].mat = 2;
    const char *path = quads_gltf("glow.gltf", q, 3, WHITE "," WHITE ",{\"name\":\"lamp\",\"emissiveFactor\":[1,1,1],"
                                  "\"emissiveTexture\":{\"index\":0},\"extensions\":{\"KHR_materials_emissive_strength\":"
                                  "{\"emissiveStrength\":10}}}", ",\"textures\":[{\"source\":0,\"sampler\":0}],"
                                  "\"samplers\":[{\"magFilter\":9728}],\"images\":[{\"uri\":\"glow.ppm\"}]");
    bn_load_opts lo;
    bn_scene *s = NULL;
    bn_error err;
    size_t nf, np;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    BN_ASSERT_EQ(bn_scene_load(path, &lo, &s, &err), BN_OK);
    const bn_face *faces = bn_scene_faces(s, &nf);
    double want = 0, watts[3], Le[3];
    int seen = 0;
    for (size_t k = 0; k < nf; k++) {
        if (strcmp(bn_scene_materials(s, NULL)[faces[k].material].name, "lamp") != 0)
            continue;
        double x = bn_scene_vertices(s, NULL)[3 * bn_scene_face_indices(s, NULL)[faces[k].first]];
        double expect = x < 0.5 ? 10 : 5;   /* the lamp on the bright texel, or straddling both */
        bn_scene_face_emission(s, k, Le);
        for (int c = 0; c < 3; c++)
            BN_ASSERT_NEAR(Le[c], expect, 1e-9);
        want += 3.14159265358979323846 * faces[k].area * expect;
        seen++;
    }
    BN_ASSERT_EQ(seen, 2);
    bn_scene_emitted_power(s, watts);
    BN_ASSERT_NEAR(watts[0], want, 1e-9 * want);
    bn_mesh_opts mo;
    bn_mesh_opts_default(&mo);
    mo.patch_size = 0.1;
    BN_ASSERT_EQ(bn_scene_mesh(s, &mo, &err), BN_OK);
    const bn_patch *pa = bn_scene_patches(s, &np);
    double *E = malloc(3 * np * sizeof *E), pw[3];
    bn_scene_patch_emission(s, E);
    bn_scene_power(s, E, pw);
    BN_ASSERT_NEAR(pw[1], want, 1e-9 * want);   /* the patches emit what their faces do */
    for (size_t k = 0; k < np; k++)
        if (E[3 * k] > 0) {
            bn_scene_face_emission(s, pa[k].face, Le);
            BN_ASSERT_NEAR(E[3 * k], Le[0], 0);
        }
    free(E);
    bn_scene_destroy(s);
}

/* The tracer takes the same per-patch means as K (like with like): the crosscheck of the textured box
 * passes (it would not if either side read the texture differently: the checker's colours are 0.79 and
 * 0.02). */
BN_TEST(textured_box_passes_the_crosscheck)
{
    quad q[32], f[16];
    char args[1024], *out = NULL;
    write_checker("checker.ppm", 4);
    size_t n = box_quads(q, f, floor_quads(f, 0));
    const char *path = quads_gltf("textured.gltf", q, n, "{\"name\":\"floor\",\"pbrMetallicRoughness\":{\"baseColorTexture\":"
                                  "{\"index\":0}}}," WHITE "," LIGHT, ",\"textures\":[{\"source\":0,\"sampler\":0}],"
                                  "\"samplers\":[{\"magFilter\":9728}],\"images\":[{\"uri\":\"checker.ppm\"}]");
    snprintf(args, sizeof args, "crosscheck '%s' --patch-size 0.25 --no-contacts -q", path);
    int rc = bn_test_bounce(args, &out);
    if (rc != 0 || !strstr(out, "verdict: pass"))
        BN_FAIL("crosscheck exit %d: %s", rc, out ? out : "");
    free(out);
}
