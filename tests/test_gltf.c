/* glTF 2.0 input: files written here by hand (their answers worked out by hand: transforms, winding
 * under a mirror, component types, sparse values, materials), the Cornell box written as glTF against
 * the same box read from its OBJ (a second reader), real files from Debian's assimp-testmodels (good
 * and broken ones), and every refusal naming its JSON pointer. */
#include "bn_test.h"
#include "bounce/bake.h"
#include "bounce/image.h"
#include "bounce/scene.h"

#include <stdint.h>

/* A unit square in z = 0 facing +z: 4 float positions (48 bytes), then 6 unsigned short indices. */
typedef struct square_bin {
    float pos[12];
    uint16_t idx[6];
} square_bin;
static const square_bin square = {{0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0}, {0, 1, 2, 0, 2, 3}};

#define SQUARE_BUFFERS                                                                                            \
    "\"buffers\":[{\"byteLength\":@N@,\"uri\":\"@URI@\"}],"                                                        \
    "\"bufferViews\":[{\"buffer\":0,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":12}],"      \
    "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\"},"                     \
    "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}],"

typedef struct counted_log {
    int warnings[BN_WARNING_COUNT];
    char last[512];
} counted_log;
static void count_log(void *user, const bn_message *m)
{
    counted_log *c = user;
    if (m->level == BN_LOG_WARN) {
        c->warnings[m->code]++;
        snprintf(c->last, sizeof c->last, "%s", m->text);
    }
}

static bn_scene *load(const char *path, counted_log *c)
{
    bn_load_opts o;
    bn_scene *s = NULL;
    bn_error err;
    bn_load_opts_default(&o);
    o.log.fn = count_log;
    o.log.user = c;
    if (bn_scene_load(path, &o, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    return s;
}

/* The error message of loading `json` (which must fail with bad input). */
static const char *load_error(const char *json, const void *bin, size_t n)
{
    static bn_error err;
    bn_scene *s = NULL;
    bn_load_opts o;
    bn_load_opts_default(&o);
    o.log.quiet = 1;
    o.log.fn = count_log;
    counted_log c;
    memset(&c, 0, sizeof c);
    o.log.user = &c;
    bn_status st = bn_scene_load(bn_test_write_gltf("bad.gltf", json, bin, n), &o, &s, &err);
    if (st != BN_EINPUT)
        BN_FAIL("loaded with status %d, expected bad input: %s", (int)st, json);
    BN_ASSERT(s == NULL);
    return err.msg;
}
#define ASSERT_CONTAINS(hay, needle)                                                                              \
    do {                                                                                                          \
        if (!strstr((hay), (needle)))                                                                             \
            BN_FAIL("'%s' does not contain '%s'", (hay), (needle));                                               \
    } while (0)

/* Faces of the object named `name`: count, total area, mean normal, and the centroid of its vertices. */
static void object_faces(const bn_scene *s, const char *name, size_t *n, double *area, double nrm[3], double c[3])
{
    size_t nf, nv;
    const bn_face *f = bn_scene_faces(s, &nf);
    const size_t *fi = bn_scene_face_indices(s, &nv);
    const double *v = bn_scene_vertices(s, &nv);
    double w = 0;
    *n = 0, *area = 0;
    memset(nrm, 0, 3 * sizeof *nrm);
    memset(c, 0, 3 * sizeof *c);
    for (size_t i = 0; i < nf; i++) {
        if (strcmp(bn_scene_object_name(s, f[i].object), name) != 0)
            continue;
        (*n)++, *area += f[i].area;
        for (int k = 0; k < 3; k++)
            nrm[k] += f[i].area * f[i].normal[k];
        for (unsigned j = 0; j < f[i].nverts; j++, w++)
            for (int k = 0; k < 3; k++)
                c[k] += v[3 * fi[f[i].first + j] + k];
    }
    for (int k = 0; k < 3; k++)
        nrm[k] /= *area > 0 ? *area : 1, c[k] /= w > 0 ? w : 1;
}

static void assert_object(const bn_scene *s, const char *name, double area, const double nrm[3], const double c[3])
{
    size_t n;
    double a, m[3], cc[3];
    object_faces(s, name, &n, &a, m, cc);
    if (n != 1)
        BN_FAIL("object '%s': %zu faces, expected 1 (the square's two triangles merged)", name, n);
    BN_ASSERT_NEAR(a, area, 1e-9);
    for (int k = 0; k < 3; k++) {
        BN_ASSERT_NEAR(m[k], nrm[k], 1e-9);
        BN_ASSERT_NEAR(cc[k], c[k], 1e-6);
    }
}

/* Nodes place one square six ways (two nodes named alike: two objects); each object's area, facing and
 * vertex centroid worked out by hand. */
BN_TEST(node_transforms_place_and_mirror_the_mesh)
{
    const char *json =
        "{\"asset\":{\"version\":\"2.0\"}," SQUARE_BUFFERS
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]}],"
        "\"nodes\":[{\"name\":\"t\",\"mesh\":0,\"translation\":[0,0,5]},"
        "{\"name\":\"r\",\"mesh\":0,\"rotation\":[0.70710678118654752,0,0,0.70710678118654752]},"
        "{\"name\":\"m\",\"mesh\":0,\"scale\":[-1,1,1]},"
        "{\"name\":\"M\",\"mesh\":0,\"matrix\":[2,0,0,0, 0,2,0,0, 0,0,2,0, 10,0,0,1]},"
        "{\"name\":\"parent\",\"translation\":[0,0,1],\"scale\":[1,1,3],\"children\":[5]},"
        "{\"name\":\"child\",\"mesh\":0,\"translation\":[0,0,1]},{\"name\":\"t\",\"mesh\":0,\"translation\":[0,0,7]}],"
        "\"scenes\":[{\"nodes\":[0,1,2,3,4,6]}],\"scene\":0}";
    counted_log c;
    memset(&c, 0, sizeof c);
    bn_scene *s = load(bn_test_write_gltf("nodes.gltf", json, &square, sizeof square), &c);
    size_t nf;
    bn_scene_faces(s, &nf);
    BN_ASSERT_EQ(nf, 6);   /* each square's two triangles are one quad again */
    BN_ASSERT_EQ(bn_scene_object_count(s), 6);
    assert_object(s, "t", 1, (double[]){0, 0, 1}, (double[]){0.5, 0.5, 5});
    assert_object(s, "t#6", 1, (double[]){0, 0, 1}, (double[]){0.5, 0.5, 7});   /* a second node named t */
    /* 90 degrees about x: y goes to z, +z to -y */
    assert_object(s, "r", 1, (double[]){0, -1, 0}, (double[]){0.5, 0, 0.5});
    /* a mirror keeps the front where the geometry's front went: +z, wound the other way */
    assert_object(s, "m", 1, (double[]){0, 0, 1}, (double[]){-0.5, 0.5, 0});
    assert_object(s, "M", 4, (double[]){0, 0, 1}, (double[]){11, 1, 0});
    /* the parent's scale applies to the child's translation: z = 1 + 3 x 1 */
    assert_object(s, "child", 1, (double[]){0, 0, 1}, (double[]){0.5, 0.5, 4});
    bn_scene_destroy(s);
}

/* The same square through other component types: interleaved (byteStride) float positions, unsigned byte
 * and unsigned int indices, KHR_mesh_quantization's normalized shorts; and a sparse accessor that moves
 * one corner (the area it gives worked out by hand). */
BN_TEST(component_types_strides_and_sparse_values)
{
    struct {
        float pos[16];          /* 4 x (x, y, z, pad): byteStride 16 */
        uint8_t i8[8];          /* 6 used, padded to 4 */
        uint32_t i32[6];
        int16_t q[12];          /* normalized: 32767 = 1 */
        uint16_t sidx[2];       /* sparse: vertex 2 */
        float sval[3];          /*         becomes (2, 2, 0) */
    } bin = {{0, 0, 0, 9, 1, 0, 0, 9, 1, 1, 0, 9, 0, 1, 0, 9}, {0, 1, 2, 0, 2, 3, 0, 0}, {0, 1, 2, 0, 2, 3},
             {0, 0, 0, 32767, 0, 0, 32767, 32767, 0, 0, 32767, 0}, {2, 0}, {2, 2, 0}};
    const char *json =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_mesh_quantization\"],"
        "\"extensionsRequired\":[\"KHR_mesh_quantization\"],"
        "\"buffers\":[{\"byteLength\":@N@,\"uri\":\"@URI@\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":64,\"byteStride\":16},{\"buffer\":0,\"byteOffset\":64,\"byteLength\":8},"
        "{\"buffer\":0,\"byteOffset\":72,\"byteLength\":24},{\"buffer\":0,\"byteOffset\":96,\"byteLength\":24},"
        "{\"buffer\":0,\"byteOffset\":120,\"byteLength\":4},{\"buffer\":0,\"byteOffset\":124,\"byteLength\":12}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\"},"
        "{\"bufferView\":1,\"componentType\":5121,\"count\":6,\"type\":\"SCALAR\"},"
        "{\"bufferView\":2,\"componentType\":5125,\"count\":6,\"type\":\"SCALAR\"},"
        "{\"bufferView\":3,\"componentType\":5122,\"normalized\":true,\"count\":4,\"type\":\"VEC3\"},"
        "{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"sparse\":{\"count\":1,"
        "\"indices\":{\"bufferView\":4,\"componentType\":5123},\"values\":{\"bufferView\":5}}}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]},"
        "{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":2}]},"
        "{\"primitives\":[{\"attributes\":{\"POSITION\":3},\"indices\":1}]},"
        "{\"primitives\":[{\"attributes\":{\"POSITION\":4},\"indices\":2}]}],"
        "\"nodes\":[{\"name\":\"u8\",\"mesh\":0},{\"name\":\"u32\",\"mesh\":1,\"translation\":[0,0,1]},"
        "{\"name\":\"q\",\"mesh\":2,\"translation\":[0,0,2]},{\"name\":\"sparse\",\"mesh\":3,\"translation\":[0,0,3]}],"
        "\"scenes\":[{\"nodes\":[0,1,2,3]}]}";
    counted_log c;
    memset(&c, 0, sizeof c);
    bn_scene *s = load(bn_test_write_gltf("types.gltf", json, &bin, sizeof bin), &c);
    assert_object(s, "u8", 1, (double[]){0, 0, 1}, (double[]){0.5, 0.5, 0});
    assert_object(s, "u32", 1, (double[]){0, 0, 1}, (double[]){0.5, 0.5, 1});
    assert_object(s, "q", 1, (double[]){0, 0, 1}, (double[]){0.5, 0.5, 2});
    /* corners (0,0) (1,0) (2,2) (0,1): triangles of area 1 and 1, a convex quad */
    assert_object(s, "sparse", 2, (double[]){0, 0, 1}, (double[]){0.75, 0.75, 3});
    bn_scene_destroy(s);
}

/* Materials: reflectance from baseColorFactor (or an older file's specular-glossiness diffuseFactor), emission = emissiveFactor x emissiveStrength, doubleSided
 * as two-sided faces (the back side added), unlit / blended / textured said, no material a grey default. */
BN_TEST(materials_as_the_format_says)
{
    const char *json =
        "{\"asset\":{\"version\":\"2.0\"}," SQUARE_BUFFERS
        "\"materials\":[{\"name\":\"lamp\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[0.8,0.2,0.1,1],"
        "\"metallicFactor\":1},\"emissiveFactor\":[1,0.5,0.25],\"doubleSided\":true,"
        "\"extensions\":{\"KHR_materials_emissive_strength\":{\"emissiveStrength\":4}}},"
        "{\"name\":\"lamp\",\"alphaMode\":\"BLEND\",\"extensions\":{\"KHR_materials_unlit\":{}}},"
        "{\"name\":\"old\",\"extensions\":{\"KHR_materials_pbrSpecularGlossiness\":{\"diffuseFactor\":[0.3,0.4,0.5,1]}}}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":0}]},"
        "{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":1}]},"
        "{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]},"
        "{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":2}]}],"
        "\"nodes\":[{\"mesh\":0},{\"mesh\":1,\"translation\":[0,0,1]},{\"mesh\":2,\"translation\":[0,0,2]},"
        "{\"mesh\":3,\"translation\":[0,0,3]}],\"scenes\":[{\"nodes\":[0,1,2,3]}]}";
    counted_log c;
    memset(&c, 0, sizeof c);
    bn_scene *s = load(bn_test_write_gltf("materials.gltf", json, &square, sizeof square), &c);
    size_t nm, nf;
    const bn_material *m = bn_scene_materials(s, &nm);
    const bn_face *f = bn_scene_faces(s, &nf);
    BN_ASSERT_EQ(nm, 4);
    BN_ASSERT(strcmp(m[0].name, "lamp") == 0 && strcmp(m[1].name, "lamp#1") == 0);
    BN_ASSERT_NEAR(m[0].rho[0], 0.8, 1e-15);
    BN_ASSERT_NEAR(m[0].rho[2], 0.1, 1e-15);
    BN_ASSERT_NEAR(m[0].Le[0], 4, 1e-15);
    BN_ASSERT_NEAR(m[0].Le[1], 2, 1e-15);
    BN_ASSERT_NEAR(m[0].Le[2], 1, 1e-15);
    BN_ASSERT_NEAR(m[1].rho[1], 1, 0);   /* the schema's default base colour */
    BN_ASSERT_NEAR(m[2].rho[1], 0.4, 0); /* KHR_materials_pbrSpecularGlossiness's diffuseFactor */
    BN_ASSERT_NEAR(m[3].rho[0], 0.5, 0); /* no material: grey, added when first needed */
    BN_ASSERT(bn_scene_material_two_sided(s, 0) && !bn_scene_material_two_sided(s, 1));
    BN_ASSERT_EQ(nf, 5);   /* a quad each, the lamp's with its back side */
    size_t backs = 0;
    for (size_t i = 0; i < nf; i++)
        backs += f[i].back;
    BN_ASSERT_EQ(backs, 1);
    /* unlit, alpha BLEND, no material: three [material] warnings */
    BN_ASSERT_EQ(c.warnings[BN_W_MATERIAL], 3);
    bn_scene_destroy(s);
}

/* Every refusal names the JSON pointer and the value. */
BN_TEST(bad_files_are_refused_by_json_pointer)
{
    static const struct {
        const char *json, *says;
    } cases[] = {
        {"\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":3}]}]",
         "/meshes/0/primitives/0/material: 3 does not exist"},
        {"\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":1},\"indices\":1}]}]",
         "/meshes/0/primitives/0/attributes/POSITION: accessor 1 is SCALAR"},
        {"\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":7}]}]",
         "primitive indices accessor out of bounds"},   /* tinygltf checks this one itself */
        {"\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"mode\":9}]}]",
         "/meshes/0/primitives/0/mode: 9"},
        {"\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorFactor\":[1.5,0,0,1]}}],"
         "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":0}]}]",
         "/materials/0/pbrMetallicRoughness/baseColorFactor/0: 1.5"},
        {"\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorFactor\":[1,0,0]}}],"
         "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":0}]}]",
         "baseColorFactor` parameter in pbrMetallicRoughness must be 4, but got 3"},   /* tinygltf's words */
        {"\"materials\":[{\"extensions\":{\"KHR_materials_emissive_strength\":{\"emissiveStrength\":-2}}}],"
         "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":0}]}]",
         "emissiveStrength: -2"},
        {"\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]}],"
         "\"extensionsRequired\":[\"KHR_draco_mesh_compression\"]",
         "/extensionsRequired/0: the file requires 'KHR_draco_mesh_compression'"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        char json[2048];
        snprintf(json, sizeof json, "{\"asset\":{\"version\":\"2.0\"}," SQUARE_BUFFERS "%s,"
                 "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]}", cases[i].json);
        const char *msg = load_error(json, &square, sizeof square);
        ASSERT_CONTAINS(msg, cases[i].says);
        ASSERT_CONTAINS(msg, "bad.gltf");
    }
}

/* Structure: accessors past their views, strides below an element, sparse indices past the count, bad
 * rotations, a cycle in the node tree, indices past the positions. */
BN_TEST(bad_structure_is_refused_by_json_pointer)
{
    static const struct {
        const char *views, *accessors, *nodes, *says;
    } cases[] = {
        {"{\"buffer\":0,\"byteLength\":40},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":12}", NULL, NULL,
         "/meshes/0/primitives/0/attributes/POSITION: 4 elements of 12 bytes at offset 0 overrun bufferView 0"},
        {"{\"buffer\":0,\"byteLength\":48,\"byteStride\":8},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":12}", NULL,
         NULL, "/bufferViews/0/byteStride: 8 is less than the 12 bytes"},
        {"{\"buffer\":0,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":400}", NULL, NULL,
         "/bufferViews/1: 400 bytes at offset 48 do not lie in buffer 0"},
        {NULL, "{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\",\"sparse\":{\"count\":1,"
               "\"indices\":{\"bufferView\":1,\"byteOffset\":10,\"componentType\":5123},\"values\":{\"bufferView\":0}}},"
               "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}",
         NULL, "/accessors/0/sparse/indices: index 0 is 3, past the accessor's 3 elements"},
        {NULL, NULL, "{\"mesh\":0,\"rotation\":[0,0,0,0]}", "/nodes/0/rotation: (0, 0, 0, 0) is not a rotation"},
        {NULL, NULL, "{\"mesh\":0,\"children\":[1]},{\"children\":[0]}", "/nodes/1/children/0: node 0 is reached twice"},
        {NULL, "{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
               "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}",
         NULL, "/meshes/0/primitives/0/indices: index 5 is 3, past the primitive's 3 positions"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        char json[2048];
        snprintf(json, sizeof json,
                 "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":@N@,\"uri\":\"@URI@\"}],"
                 "\"bufferViews\":[%s],\"accessors\":[%s],"
                 "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]}],"
                 "\"nodes\":[%s],\"scenes\":[{\"nodes\":[0]}]}",
                 cases[i].views ? cases[i].views
                                : "{\"buffer\":0,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":12}",
                 cases[i].accessors ? cases[i].accessors
                                    : "{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\"},"
                                      "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}",
                 cases[i].nodes ? cases[i].nodes : "{\"mesh\":0}");
        ASSERT_CONTAINS(load_error(json, &square, sizeof square), cases[i].says);
    }
}

/* Per material: faces' total area, area-weighted normal, emitted radiance. */
typedef struct mat_sum {
    double area, n[3], Le[3];
} mat_sum;
static void material_sums(const bn_scene *s, mat_sum *out, size_t nout)
{
    size_t nf, nm;
    const bn_face *f = bn_scene_faces(s, &nf);
    const bn_material *m = bn_scene_materials(s, &nm);
    BN_ASSERT_EQ(nm, nout);
    memset(out, 0, nout * sizeof *out);
    for (size_t i = 0; i < nf; i++) {
        mat_sum *o = &out[f[i].material];
        o->area += f[i].area;
        for (int k = 0; k < 3; k++)
            o->n[k] += f[i].area * f[i].normal[k], o->Le[k] = m[f[i].material].Le[k];
    }
}

/* Scene s written as glTF: a primitive per material, float positions, unsigned int indices, polygons as
 * fans of triangles, each emission as a colour in [0, 1] times a strength. */
static const char *scene_to_gltf(const bn_scene *s, const char *name, const char *node)
{
    size_t nv, nf, nm, ni, k = 0;
    const double *v = bn_scene_vertices(s, &nv);
    const bn_face *f = bn_scene_faces(s, &nf);
    const size_t *fi = bn_scene_face_indices(s, &ni);
    const bn_material *m = bn_scene_materials(s, &nm);
    size_t bytes = nv * 12 + 6 * nf * 4;
    unsigned char *bin = calloc(bytes, 1);
    float *pos = (float *)bin;
    uint32_t *idx = (uint32_t *)(bin + nv * 12), nidx[64] = {0}, start[64];
    char *json = malloc(65536);
    BN_ASSERT(nm < 64);
    for (size_t i = 0; i < 3 * nv; i++)
        pos[i] = (float)v[i];
    for (size_t mat = 0; mat < nm; mat++) {   /* the faces of each material, together */
        start[mat] = (uint32_t)k;
        for (size_t i = 0; i < nf; i++)
            for (unsigned t = 0; f[i].material == mat && t + 2 < f[i].nverts; t++, nidx[mat] += 3) {
                idx[k++] = (uint32_t)fi[f[i].first];
                idx[k++] = (uint32_t)fi[f[i].first + t + 1];
                idx[k++] = (uint32_t)fi[f[i].first + t + 2];
            }
    }
    int o = snprintf(json, 65536, "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":@N@,\"uri\":\"@URI@\"}],"
                     "\"bufferViews\":[{\"buffer\":0,\"byteLength\":%zu},{\"buffer\":0,\"byteOffset\":%zu,"
                     "\"byteLength\":%zu}],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":%zu,"
                     "\"type\":\"VEC3\"}", nv * 12, nv * 12, k * 4, nv);
    for (size_t mat = 0; mat < nm; mat++)
        o += snprintf(json + o, 65536 - o, ",{\"bufferView\":1,\"byteOffset\":%u,\"componentType\":5125,\"count\":%u,"
                      "\"type\":\"SCALAR\"}", start[mat] * 4, nidx[mat]);
    o += snprintf(json + o, 65536 - o, "],\"materials\":[");
    for (size_t mat = 0; mat < nm; mat++) {
        double mx = fmax(fmax(m[mat].Le[0], m[mat].Le[1]), fmax(m[mat].Le[2], 1e-300));
        o += snprintf(json + o, 65536 - o, "%s{\"name\":\"%s\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[%.17g,%.17g,"
                      "%.17g,1]},\"emissiveFactor\":[%.17g,%.17g,%.17g],\"extensions\":{\"KHR_materials_emissive_strength\":"
                      "{\"emissiveStrength\":%.17g}}}", mat ? "," : "", m[mat].name, m[mat].rho[0], m[mat].rho[1],
                      m[mat].rho[2], m[mat].Le[0] / mx, m[mat].Le[1] / mx, m[mat].Le[2] / mx, mx);
    }
    o += snprintf(json + o, 65536 - o, "],\"meshes\":[{\"primitives\":[");
    for (size_t mat = 0; mat < nm; mat++)
        o += snprintf(json + o, 65536 - o, "%s{\"attributes\":{\"POSITION\":0},\"indices\":%zu,\"material\":%zu}",
                      mat ? "," : "", mat + 1, mat);
    snprintf(json + o, 65536 - o, "]}],\"nodes\":[%s],\"scenes\":[{\"nodes\":[0]}],\"scene\":0}", node);
    const char *path = bn_test_write_gltf(name, json, bin, bytes);
    free(json), free(bin);
    return path;
}

/* The Cornell box written as glTF reads back as the OBJ reader reads it: per material the same area,
 * facing and emission, and the whole file through `bounce info`. */
BN_TEST(cornell_box_as_gltf_reads_as_its_obj)
{
    counted_log c;
    memset(&c, 0, sizeof c);
    bn_scene *obj = load(bn_test_path("meshes/cornell-box.obj"), &c);
    size_t nm;
    const bn_material *m = bn_scene_materials(obj, &nm);
    const char *path = scene_to_gltf(obj, "cornell-box.gltf", "{\"mesh\":0}");
    bn_scene *gl = load(path, &c);
    mat_sum a[64], b[64];
    material_sums(obj, a, nm);
    material_sums(gl, b, nm);
    for (size_t mat = 0; mat < nm; mat++) {
        BN_ASSERT_REL(b[mat].area, a[mat].area, 1e-6);
        for (int j = 0; j < 3; j++) {
            BN_ASSERT_NEAR(b[mat].n[j], a[mat].n[j], 1e-6 * a[mat].area);
            BN_ASSERT_NEAR(b[mat].Le[j], a[mat].Le[j], 1e-14 * a[mat].Le[j]);
        }
        BN_ASSERT_NEAR(bn_scene_materials(gl, &nm)[mat].rho[1], m[mat].rho[1], 0);
    }
    /* the command line reads it too */
    char args[1024], *out = NULL;
    snprintf(args, sizeof args, "info '%s'", path);
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 0);
    ASSERT_CONTAINS(out, "polygons");
    free(out);
    bn_scene_destroy(gl);
    bn_scene_destroy(obj);
}

/* Real files from Debian's assimp-testmodels: the textured box in its three containers (JSON with a
 * .bin, binary .glb, embedded data URIs) reads as one closed unit cube facing out, its PNG decoded; the Asset Generator's
 * triangle, strip and fan squares (with and without indices) all face +z; broken files are refused with
 * their pointer. */
#define ASSIMP "/usr/share/assimp/models/glTF2/"
BN_TEST(assimp_sample_files)
{
    static const char *boxes[] = {"BoxTextured-glTF/BoxTextured.gltf", "BoxTextured-glTF-Binary/BoxTextured.glb",
                                  "BoxTextured-glTF-Embedded/BoxTextured.gltf"};
    if (!bn_test_file_exists(ASSIMP "BoxTextured-glTF/BoxTextured.gltf"))
        BN_SKIP("Debian's assimp-testmodels is not installed (scripts/setup.sh installs it)");
    for (size_t b = 0; b < 3; b++) {
        counted_log c;
        memset(&c, 0, sizeof c);
        char path[256];
        snprintf(path, sizeof path, ASSIMP "%s", boxes[b]);
        bn_scene *s = load(path, &c);
        size_t nf;
        const bn_face *f = bn_scene_faces(s, &nf);
        double area = 0;
        BN_ASSERT_EQ(nf, 6);   /* its triangles merged into the cube's six quads */
        for (size_t i = 0; i < nf; i++) {   /* outward: the normal's largest component has the face's side */
            const size_t *fi = bn_scene_face_indices(s, &(size_t){0});
            const double *v = bn_scene_vertices(s, &(size_t){0}), *p = v + 3 * fi[f[i].first];
            area += f[i].area;
            BN_ASSERT_GT(f[i].normal[0] * p[0] + f[i].normal[1] * p[1] + f[i].normal[2] * p[2], 0.49);
        }
        BN_ASSERT_NEAR(area, 6, 1e-6);
        BN_ASSERT_EQ(c.warnings[BN_W_MATERIAL], 0);
        /* its PNG texture (a logo on a light ground) decoded: the mean reflectance is not the factor's 1 */
        bn_mesh_opts mo;
        bn_error err;
        bn_mesh_opts_default(&mo);
        BN_ASSERT(bn_scene_textured(s));
        BN_ASSERT_EQ(bn_scene_mesh(s, &mo, &err), BN_OK);
        size_t np;
        bn_scene_patches(s, &np);
        double *rho = malloc(3 * np * sizeof *rho), mean = 0;
        bn_scene_patch_reflectance(s, rho);
        for (size_t k = 0; k < 3 * np; k++)
            mean += rho[k] / (3.0 * np);
        BN_ASSERT(mean > 0.05 && mean < 0.95);
        free(rho);
        bn_scene_destroy(s);
    }
    for (int i = 4; i <= 15; i++) {
        if (i >= 7 && i <= 10)
            continue;   /* points and lines */
        char path[256];
        counted_log c;
        memset(&c, 0, sizeof c);
        snprintf(path, sizeof path, ASSIMP "glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_%02d.gltf", i);
        bn_scene *s = load(path, &c);
        size_t nf;
        const bn_face *f = bn_scene_faces(s, &nf);
        BN_ASSERT_EQ(nf, 1);   /* two triangles, merged */
        for (size_t k = 0; k < nf; k++)
            BN_ASSERT_NEAR(f[k].normal[2], 1, 1e-12);
        bn_scene_destroy(s);
    }
}

BN_TEST(assimp_broken_files_are_refused)
{
    static const struct {
        const char *file, *says;
    } cases[] = {
        {"IndexOutOfRange/IndexOutOfRange.gltf", "/meshes/0/primitives/0/indices: index 0 is 255"},
        {"RecursiveNodes/RecursiveNodes.gltf", "is reached twice"},
        {"BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb", "/attributes/POSITION: position 0 is (-inf"},
        {"MissingBin/BoxTextured.gltf", "BoxTextured0.bin"},
        {"draco/2CylinderEngine.gltf", "KHR_draco_mesh_compression"},
    };
    if (!bn_test_file_exists(ASSIMP "IndexOutOfRange/IndexOutOfRange.gltf"))
        BN_SKIP("Debian's assimp-testmodels is not installed (scripts/setup.sh installs it)");
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        char args[512], *out = NULL;
        snprintf(args, sizeof args, "info " ASSIMP "%s", cases[i].file);
        BN_ASSERT_EQ(bn_test_bounce(args, &out), 3);
        ASSERT_CONTAINS(out, cases[i].says);
        ASSERT_CONTAINS(out, cases[i].file);
        free(out);
    }
}

static bn_scene *load_with(const char *path, bn_unit unit, const char *two_sided)
{
    bn_load_opts o;
    bn_scene *s = NULL;
    bn_error err;
    bn_load_opts_default(&o);
    o.unit = unit;
    o.two_sided = two_sided;
    o.log.quiet = 1;
    o.log.fn = count_log;
    counted_log c;
    o.log.user = &c;
    if (bn_scene_load(path, &o, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    return s;
}

/* meshes/cornell-box-blender.glb, the Cornell box through Blender's importer and exporter
 * (scripts/cornell_box_to_glb.py: metres, every material doubleSided, the light's Le as a colour x a
 * strength): with --two-sided none it is the OBJ's box (areas in m^2 against the OBJ's in mm^2,
 * Blender's triangles against the OBJ's quads), and as the file says, every face has a back side and
 * the light emits twice the power. */
BN_TEST(blender_export_reads_as_the_obj)
{
    bn_scene *obj = load_with(bn_test_path("meshes/cornell-box.obj"), BN_UNIT_MM, NULL);
    bn_scene *one = load_with(bn_test_path("meshes/cornell-box-blender.glb"), BN_UNIT_M, "none");
    bn_scene *two = load_with(bn_test_path("meshes/cornell-box-blender.glb"), BN_UNIT_M, NULL);
    size_t nm, nm1, nf1, nf2;
    const bn_material *m = bn_scene_materials(obj, &nm), *m1 = bn_scene_materials(one, &nm1);
    mat_sum a[16], b[16];
    BN_ASSERT(nm == nm1 && nm <= 16);
    material_sums(obj, a, nm);
    material_sums(one, b, nm);
    for (size_t i = 0; i < nm; i++) {
        size_t j = 0;   /* Blender orders materials its own way: match by name */
        while (j < nm && strcmp(m1[j].name, m[i].name) != 0)
            j++;
        BN_ASSERT(j < nm);
        BN_ASSERT_REL(b[j].area, a[i].area * 1e-6, 1e-6);
        for (int k = 0; k < 3; k++) {
            BN_ASSERT_NEAR(b[j].n[k], a[i].n[k] * 1e-6, 1e-6 * b[j].area);
            BN_ASSERT_NEAR(m1[j].rho[k], m[i].rho[k], 1e-7);   /* Blender keeps colours in float */
            BN_ASSERT_NEAR(b[j].Le[k], a[i].Le[k], 1e-5 * a[i].Le[k]);
        }
    }
    double p1[3], p2[3];
    bn_scene_faces(one, &nf1);
    bn_scene_faces(two, &nf2);
    BN_ASSERT_EQ(nf2, 2 * nf1);
    /* none,NAMES: the file's marks dropped, only the light two-sided (its one face gets a back side) */
    bn_scene *lit = load_with(bn_test_path("meshes/cornell-box-blender.glb"), BN_UNIT_M, "none,light");
    size_t nfl;
    bn_scene_faces(lit, &nfl);
    BN_ASSERT_EQ(nfl, nf1 + 1);
    bn_scene_destroy(lit);
    bn_scene_emitted_power(one, p1);
    bn_scene_emitted_power(two, p2);
    BN_ASSERT_REL(p2[0], 2 * p1[0], 1e-12);
    bn_scene_destroy(obj), bn_scene_destroy(one), bn_scene_destroy(two);
}

/* The faces scene_to_gltf writes as triangles, as OBJ + MTL polygons (positions rounded to float, faces
 * in material order). */
static const char *scene_to_obj(const bn_scene *s, const char *name)
{
    size_t nv, nf, nm, ni;
    const double *v = bn_scene_vertices(s, &nv);
    const bn_face *f = bn_scene_faces(s, &nf);
    const size_t *fi = bn_scene_face_indices(s, &ni);
    const bn_material *m = bn_scene_materials(s, &nm);
    char mtl[64];
    snprintf(mtl, sizeof mtl, "%s.mtl", name);
    FILE *fo = fopen(bn_test_tmp(name), "w"), *fm = fopen(bn_test_tmp(mtl), "w");
    BN_ASSERT(fo && fm);
    for (size_t mat = 0; mat < nm; mat++)
        fprintf(fm, "newmtl %s\nKd %.17g %.17g %.17g\nKe %.17g %.17g %.17g\n", m[mat].name, m[mat].rho[0], m[mat].rho[1],
                m[mat].rho[2], m[mat].Le[0], m[mat].Le[1], m[mat].Le[2]);
    fprintf(fo, "mtllib %s\n", mtl);
    for (size_t i = 0; i < nv; i++)
        fprintf(fo, "v %.9g %.9g %.9g\n", (float)v[3 * i], (float)v[3 * i + 1], (float)v[3 * i + 2]);
    for (size_t mat = 0; mat < nm; mat++) {
        fprintf(fo, "usemtl %s\n", m[mat].name);
        for (size_t i = 0; i < nf; i++) {
            if (f[i].material != mat)
                continue;
            fprintf(fo, "f");
            for (unsigned k = 0; k < f[i].nverts; k++)
                fprintf(fo, " %zu", fi[f[i].first + k] + 1);
            fprintf(fo, "\n");
        }
    }
    fclose(fo), fclose(fm);
    return bn_test_tmp(name);
}

/* Area (m^2) and L per patch from `bounce solve` (its CSV: patch,face,material,area,L_R,L_G,L_B); returns
 * the count. */
static size_t solve_csv(const char *args, double *L, size_t max)
{
    char cmd[1024], *out = NULL, line[512];
    const char *csv = bn_test_tmp("solve.csv");
    size_t n = 0;
    snprintf(cmd, sizeof cmd, "solve %s --patches 200 -q -o '%s'", args, csv);
    if (bn_test_bounce(cmd, &out) != 0)
        BN_FAIL("bounce %s: %s", cmd, out ? out : "");
    free(out);
    FILE *f = fopen(csv, "r");
    BN_ASSERT(f);
    while (fgets(line, sizeof line, f))
        if (line[0] >= '0' && line[0] <= '9' && n < max) {
            const char *p = line;
            for (int comma = 0; comma < 3; p++)
                comma += *p == ',';
            BN_ASSERT_EQ(sscanf(p, "%lf,%lf,%lf,%lf", &L[4 * n], &L[4 * n + 1], &L[4 * n + 2], &L[4 * n + 3]), 4);
            n++;
        }
    fclose(f);
    return n;
}

/* The Cornell box's polygons as triangles in millimetres under a node whose matrix scales by 0.001 give
 * the solution of an OBJ of the same polygons read with --unit mm, patch by patch: the reader joins each
 * quad's two triangles again (the red wall, 3 mm off planar, stays two). */
BN_TEST(millimetres_under_a_scaling_node_solve_as_the_obj)
{
    counted_log c;
    memset(&c, 0, sizeof c);
    bn_scene *box = load(bn_test_path("meshes/cornell-box.obj"), &c);
    char a[512], b[512];
    snprintf(a, sizeof a, "'%s'", scene_to_gltf(box, "mm.gltf", "{\"mesh\":0,\"matrix\":[0.001,0,0,0, 0,0.001,0,0, "
                                                            "0,0,0.001,0, 0,0,0,1]}"));
    snprintf(b, sizeof b, "'%s' --unit mm", scene_to_obj(box, "mm.obj"));
    bn_scene_destroy(box);
    static double La[4 * 4096], Lb[4 * 4096];
    size_t na = solve_csv(a, La, 4096), nb = solve_csv(b, Lb, 4096), worst = 1;
    BN_ASSERT_EQ(na, nb);
    BN_ASSERT_GT(na, 100);
    for (size_t i = 0; i < na; i++) {
        BN_ASSERT_REL(La[4 * i], Lb[4 * i], 1e-6);   /* the patch's area in m^2: the node's scale */
        for (size_t k = 4 * i + 1; k < 4 * i + 4; k++)
            if (fabs(La[k] - Lb[k]) > fabs(La[worst] - Lb[worst]))
                worst = k;
    }
    BN_ASSERT_NEAR(La[worst], Lb[worst], 1e-6);
}

/* `bounce view` of a .glb: a bake of bounce's is embedded as it is, any other glTF is a scene to bake first
 * (both a .glb; the bake's asset says bounce wrote it). */
BN_TEST(view_tells_a_bake_from_a_scene)
{
    char args[1024], *out = NULL;
    BN_ASSERT_EQ(bn_view_is_bake(bn_test_path("meshes/cornell-box-blender.glb")), 0);
    BN_ASSERT_EQ(bn_view_is_bake(bn_test_tmp("missing.glb")), -1);
    snprintf(args, sizeof args, "bake '%s' --two-sided none --patches 60 --ff-visibility rays -q -o '%s'",
             bn_test_path("meshes/cornell-box-blender.glb"), bn_test_tmp("baked.glb"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 0);
    free(out);
    BN_ASSERT_EQ(bn_view_is_bake(bn_test_tmp("baked.glb")), 1);
}

/* A glTF camera places the images' default camera: eye at its node, looking down the node's -z with +y up,
 * its field of view and aspect ratio (512 wide); under a parent turned a quarter about y it looks down -x. */
BN_TEST(the_files_camera_is_the_default_camera)
{
    const char *json =
        "{\"asset\":{\"version\":\"2.0\"}," SQUARE_BUFFERS
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]}],"
        "\"cameras\":[{\"name\":\"shot\",\"type\":\"perspective\",\"perspective\":{\"yfov\":0.6,\"aspectRatio\":2,"
        "\"znear\":0.01}}],"
        "\"nodes\":[{\"mesh\":0},{\"rotation\":[0,0.70710678118654752,0,0.70710678118654752],\"children\":[2]},"
        "{\"camera\":0,\"translation\":[0,1,5]}],\"scenes\":[{\"nodes\":[0,1]}]}";
    counted_log c;
    memset(&c, 0, sizeof c);
    bn_scene *s = load(bn_test_write_gltf("camera.gltf", json, &square, sizeof square), &c);
    bn_camera cam;
    bn_camera_default(s, &cam);
    /* the parent turns +z to +x and -z to -x: eye (5, 1, 0), looking down -x */
    BN_ASSERT_NEAR(cam.eye[0], 5, 1e-12);
    BN_ASSERT_NEAR(cam.eye[1], 1, 1e-12);
    BN_ASSERT_NEAR(cam.eye[2], 0, 1e-12);
    BN_ASSERT_NEAR(cam.look[0] - cam.eye[0], -1, 1e-12);
    BN_ASSERT_NEAR(cam.up[1], 1, 1e-12);
    BN_ASSERT_NEAR(cam.fov_deg, 0.6 * 180 / 3.14159265358979323846, 1e-9);
    BN_ASSERT_EQ(cam.width, 512);
    BN_ASSERT_EQ(cam.height, 256);
    bn_scene_destroy(s);
}

/* Malformed files as they come: a .glb cut short, JSON cut short, a count far past its buffer, a count
 * with no buffer at all: bad input named, never a crash. */
BN_TEST(malformed_files_are_bad_input)
{
    static const struct {
        const char *name, *text, *says;
    } cases[] = {
        {"bad.gltf", "{\"asset\":{\"version\":\"2.0\"},", "parse error"},
        {"huge.gltf", "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":4,\"uri\":\"data:application/"
                      "octet-stream;base64,AAAAAA==\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":4}],\"accessors\":"
                      "[{\"bufferView\":0,\"componentType\":5126,\"count\":4000000000000,\"type\":\"VEC3\"}],\"meshes\":"
                      "[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],\"nodes\":[{\"mesh\":0}],\"scenes\":"
                      "[{\"nodes\":[0]}]}", "4000000000000 elements of 12 bytes at offset 0 overrun bufferView 0"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        FILE *f = fopen(bn_test_tmp(cases[i].name), "w");
        BN_ASSERT(f && fputs(cases[i].text, f) >= 0 && fclose(f) == 0);
        char args[512], *out = NULL;
        snprintf(args, sizeof args, "info '%s'", bn_test_tmp(cases[i].name));
        BN_ASSERT_EQ(bn_test_bounce(args, &out), 3);
        ASSERT_CONTAINS(out, cases[i].says);
        free(out);
    }
    /* Blender's .glb cut to 3000 bytes */
    size_t n = 0;
    char *glb = bn_test_read_file(bn_test_path("meshes/cornell-box-blender.glb"), &n), args[512], *out = NULL;
    FILE *f = fopen(bn_test_tmp("cut.glb"), "wb");
    BN_ASSERT(glb && n > 3000 && f && fwrite(glb, 1, 3000, f) == 3000 && fclose(f) == 0);
    snprintf(args, sizeof args, "info '%s'", bn_test_tmp("cut.glb"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 3);
    ASSERT_CONTAINS(out, "cut short or with trailing bytes: its header says");
    free(out), free(glb);
}
