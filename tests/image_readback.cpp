// Read-back through the C++ libraries users open bounce's files with: an EXR written by
// bn_exr_write through OpenImageIO (same channel names and values), and a baked PLY through
// OpenMesh (vertex and face counts, 8-bit colours of --ldr equal to bounce's own tone mapping).
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"   // OpenMesh templates (DEPENDENCIES.md gotcha 7)
#include "bounce/bake.h"
#include "bounce/image.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <set>
#include <string>
#include <vector>

#define CHECK(c)                                                                  \
    do {                                                                          \
        if (!(c)) {                                                               \
            std::fprintf(stderr, "%s:%d: FAIL: %s\n", __FILE__, __LINE__, #c);    \
            std::exit(1);                                                         \
        }                                                                         \
    } while (0)
#define CHECK_EQ(a, b)                                                            \
    do {                                                                          \
        double a_ = (double)(a), b_ = (double)(b);                                \
        if (!(a_ == b_)) {                                                        \
            std::fprintf(stderr, "%s:%d: FAIL: %s == %s (%.17g vs %.17g)\n", __FILE__, __LINE__, #a, #b, a_, b_); \
            std::exit(1);                                                         \
        }                                                                         \
    } while (0)

static std::string tmpdir()
{
    std::string d = BN_TEST_BINARY_DIR;
    std::string cmd = "mkdir -p '" + d + "'";
    CHECK(std::system(cmd.c_str()) == 0);
    return d;
}

static void exr_oiio()
{
    const int W = 21, H = 35;
    const char *lname[4] = {"E", "KE", "K2E", "L"};
    bn_image img[4];
    bn_layer layers[4];
    bn_error err;
    for (int l = 0; l < 4; l++) {
        CHECK(bn_image_alloc(&img[l], W, H, &err) == BN_OK);
        for (int i = 0; i < W * H * 3; i++)
            img[l].rgb[i] = (float)(0.37 * (l + 1) + 1e-3 * i);
        layers[l].name = lname[l];
        layers[l].img = &img[l];
    }
    std::string path = tmpdir() + "/oiio.exr";
    bn_attr attr = {"bounce:commandLine", "bounce bounces x"};
    CHECK(bn_exr_write(path.c_str(), layers, 4, &attr, 1, 0, nullptr, &err) == BN_OK);
    OIIO::ImageBuf buf(path);
    CHECK(buf.read(0, 0, true, OIIO::TypeDesc::FLOAT));
    const OIIO::ImageSpec &spec = buf.spec();
    CHECK_EQ(spec.width, W);
    CHECK_EQ(spec.height, H);
    CHECK_EQ(spec.nchannels, 12);
    std::set<std::string> want, got;
    for (int l = 0; l < 4; l++)
        for (int c = 0; c < 3; c++)
            want.insert(std::string(lname[l]) + "." + "RGB"[c]);
    for (int c = 0; c < spec.nchannels; c++)
        got.insert(spec.channelnames[c]);
    CHECK(want == got);
    CHECK(spec.get_string_attribute("bounce:commandLine") == "bounce bounces x");
    std::vector<float> px((size_t)W * H * spec.nchannels);
    CHECK(buf.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, px.data()));
    for (int c = 0; c < spec.nchannels; c++) {
        const std::string &n = spec.channelnames[c];
        int l = 0;
        while (n.substr(0, n.find('.')) != lname[l])
            l++;
        int k = n.back() == 'R' ? 0 : n.back() == 'G' ? 1 : 2;
        for (int i = 0; i < W * H; i++)
            CHECK_EQ(px[(size_t)i * spec.nchannels + c], img[l].rgb[3 * i + k]);
    }
    for (int l = 0; l < 4; l++)
        bn_image_free(&img[l]);
}

static void baked_ply_openmesh()
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_scene *s = nullptr;
    bn_bake *b = nullptr;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    bn_mesh_opts_default(&mo);
    mo.target_patches = 200;
    CHECK(bn_scene_load(BN_TEST_SOURCE_DIR "/meshes/cornell-box.obj", &lo, &s, &err) == BN_OK);
    CHECK(bn_scene_mesh(s, &mo, &err) == BN_OK);
    CHECK(bn_bake_create(s, 30, &b, &err) == BN_OK);
    size_t np;
    const bn_patch *p = bn_scene_patches(s, &np);
    std::vector<double> x(np * 3);
    for (size_t i = 0; i < np; i++)
        for (int c = 0; c < 3; c++)
            x[3 * i + c] = 0.2 + 0.6 * std::fabs(std::sin(0.01 * p[i].centroid[c] + c));
    size_t nv = bn_bake_vertex_count(b);
    std::vector<double> vv(nv * 3);
    bn_bake_vertex_values(b, x.data(), vv.data());
    bn_bake_layer layer = {"L", x.data(), nullptr};
    bn_bake_write_opts wo;
    std::memset(&wo, 0, sizeof wo);
    wo.ldr = 1;
    wo.exposure_ev = 0.5;
    std::string path = tmpdir() + "/ldr.ply";
    CHECK(bn_bake_write(b, path.c_str(), &layer, 1, &wo, &err) == BN_OK);
    struct Traits : OpenMesh::DefaultTraits {
        typedef OpenMesh::Vec3uc Color;
    };
    OpenMesh::PolyMesh_ArrayKernelT<Traits> mesh;
    mesh.request_vertex_colors();
    OpenMesh::IO::Options opt = OpenMesh::IO::Options::VertexColor;
    CHECK(OpenMesh::IO::read_mesh(mesh, path, opt));
    CHECK_EQ(mesh.n_vertices(), nv);
    CHECK_EQ(mesh.n_faces(), np);
    CHECK(opt.vertex_has_color());
    for (auto v : mesh.vertices())
        for (int c = 0; c < 3; c++)
            CHECK_EQ(mesh.color(v)[c], bn_tonemap_srgb8(vv[3 * v.idx() + c], 0.5));
    // The float PLY loads too (colours come back as 8 bits in OpenMesh: only the counts here;
    // the float values are checked by the independent parser in test_bake).
    wo.ldr = 0;
    path = tmpdir() + "/float.ply";
    CHECK(bn_bake_write(b, path.c_str(), &layer, 1, &wo, &err) == BN_OK);
    OpenMesh::PolyMesh_ArrayKernelT<Traits> m2;
    CHECK(OpenMesh::IO::read_mesh(m2, path));
    CHECK_EQ(m2.n_vertices(), nv);
    CHECK_EQ(m2.n_faces(), np);
    bn_bake_destroy(b);
    bn_scene_destroy(s);
}

// The sRGB transfer, written out here (IEC 61966-2-1), not bounce's: 8-bit code of linear x.
static int srgb8(double x)
{
    double v = x <= 0 || !std::isfinite(x) ? 0 : x >= 1 ? 1 : x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055;
    return (int)std::lround(255 * v);
}

static std::vector<unsigned char> read_rgb8(const std::string &path, int &w, int &h)
{
    OIIO::ImageBuf buf(path);
    CHECK(buf.read(0, 0, true, OIIO::TypeDesc::UINT8));
    w = buf.spec().width;
    h = buf.spec().height;
    CHECK(buf.spec().nchannels >= 3);
    std::vector<unsigned char> px((size_t)w * h * 3);
    CHECK(buf.get_pixels(OIIO::ROI(0, w, 0, h, 0, 1, 0, 3), OIIO::TypeDesc::UINT8, px.data()));
    return px;
}

// Previews show the radiance at the stated exposure through the sRGB transfer (to the 8-bit
// rounding), and the contact sheet's first row holds every layer's preview, pixel for pixel.
static void png_pixels()
{
    const int W = 50, H = 30;
    const double ev = -1.5;
    const char *lname[3] = {"E", "KE", "K2E"};
    bn_image img[3];
    bn_layer layers[3];
    bn_error err;
    for (int l = 0; l < 3; l++) {
        CHECK(bn_image_alloc(&img[l], W, H, &err) == BN_OK);
        for (int i = 0; i < W * H; i++)
            for (int c = 0; c < 3; c++)   // a ramp over 0 .. 3.5 (clipped above 2^1.5) per layer and channel
                img[l].rgb[3 * i + c] = (float)((double)(i % W) / W * (1.0 + l + 0.25 * c) + (i / W) * 1e-3);
        layers[l].name = lname[l];
        layers[l].img = &img[l];
    }
    std::string dir = tmpdir();
    for (int l = 0; l < 3; l++) {
        int w, h;
        std::string path = dir + "/p" + lname[l] + ".png";
        CHECK(bn_png_write(path.c_str(), &img[l], ev, nullptr, 0, &err) == BN_OK);
        std::vector<unsigned char> px = read_rgb8(path, w, h);
        CHECK_EQ(w, W);
        CHECK_EQ(h, H);
        for (int i = 0; i < W * H * 3; i++)
            CHECK(std::abs((int)px[i] - srgb8(img[l].rgb[i] * std::pow(2.0, ev))) <= 1);
    }
    std::string sheet = dir + "/sheet.png";
    CHECK(bn_contact_sheet_write(sheet.c_str(), layers, 3, ev, 0, nullptr, 0, nullptr, &err) == BN_OK);
    int sw, sh;
    std::vector<unsigned char> sp = read_rgb8(sheet, sw, sh);
    CHECK(sw >= 3 * W && sh >= 2 * H);
    for (int l = 0; l < 3; l++) {
        int pw, ph, found = 0;
        std::vector<unsigned char> pv = read_rgb8(dir + "/p" + lname[l] + ".png", pw, ph);
        for (int oy = 0; oy + H <= sh && !found; oy++)
            for (int ox = 0; ox + W <= sw && !found; ox++) {
                int same = 1;
                for (int y = 0; y < H && same; y++)
                    same = std::memcmp(&sp[((size_t)(oy + y) * sw + ox) * 3], &pv[(size_t)y * W * 3], (size_t)W * 3) == 0;
                found = same;
            }
        if (!found)
            std::fprintf(stderr, "layer %s's preview is not a tile of the contact sheet\n", lname[l]);
        CHECK(found);
    }
    for (int l = 0; l < 3; l++)
        bn_image_free(&img[l]);
}

// `bounce bounces`: every preview PNG is its EXR layer at the exposure the EXR records.
static void cli_previews_match_exr()
{
    std::string dir = tmpdir(), exr = dir + "/cb.exr";
    std::string cmd = std::string("'") + BN_TEST_BOUNCE_EXE + "' bounces '" + BN_TEST_SOURCE_DIR +
                      "/meshes/cornell-box.obj' -n 2 -o '" + exr +
                      "' --patches 150 --ff hemisphere --samples 256 --size 40x32 --spp 2 --quiet";
    CHECK(std::system(cmd.c_str()) == 0);
    OIIO::ImageBuf buf(exr);
    CHECK(buf.read(0, 0, true, OIIO::TypeDesc::FLOAT));
    const OIIO::ImageSpec &spec = buf.spec();
    double ev = std::atof(spec.get_string_attribute("bounce:previewExposureEV").c_str());
    std::vector<float> px((size_t)spec.width * spec.height * spec.nchannels);
    CHECK(buf.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, px.data()));
    int lit = 0;
    for (const char *layer : {"E", "KE", "K2E", "rest", "L"}) {
        int w, h, ch[3] = {-1, -1, -1};
        std::vector<unsigned char> png = read_rgb8(dir + "/cb." + layer + ".png", w, h);
        CHECK_EQ(w, spec.width);
        CHECK_EQ(h, spec.height);
        for (int c = 0; c < spec.nchannels; c++)
            for (int k = 0; k < 3; k++)
                if (spec.channelnames[c] == std::string(layer) + "." + "RGB"[k])
                    ch[k] = c;
        CHECK(ch[0] >= 0 && ch[1] >= 0 && ch[2] >= 0);
        for (int i = 0; i < w * h; i++)
            for (int k = 0; k < 3; k++) {
                int want = srgb8(px[(size_t)i * spec.nchannels + ch[k]] * std::pow(2.0, ev));
                CHECK(std::abs((int)png[3 * (size_t)i + k] - want) <= 1);
                lit += std::strcmp(layer, "KE") == 0 && want > 0;
            }
    }
    CHECK(lit > 0);   // direct light is visible at that exposure
}

// A binary OFF written by OpenMesh reads back through bounce (OpenMesh's reader, by path): same
// vertices, faces and area.
static void off_binary_openmesh()
{
    struct T : OpenMesh::DefaultTraits {
        typedef OpenMesh::Vec3d Point;
    };
    OpenMesh::PolyMesh_ArrayKernelT<T> m;
    std::vector<OpenMesh::VertexHandle> v;
    const double p[5][3] = {{0, 0, 0}, {2, 0, 0}, {2, 3, 0}, {0, 3, 0}, {1, 5, 0}};
    for (auto &q : p)
        v.push_back(m.add_vertex(T::Point(q[0], q[1], q[2])));
    m.add_face(std::vector<OpenMesh::VertexHandle>{v[0], v[1], v[2], v[3]});
    m.add_face(std::vector<OpenMesh::VertexHandle>{v[3], v[2], v[4]});
    std::string path = tmpdir() + "/b.off";
    OpenMesh::IO::Options o = OpenMesh::IO::Options::Binary;
    CHECK(OpenMesh::IO::write_mesh(m, path, o));
    bn_load_opts lo;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    bn_scene *s = nullptr;
    bn_error err;
    CHECK(bn_scene_load(path.c_str(), &lo, &s, &err) == BN_OK);
    size_t nf, nv;
    const bn_face *f = bn_scene_faces(s, &nf);
    bn_scene_vertices(s, &nv);
    CHECK_EQ(nf, 2);
    CHECK_EQ(nv, 5);
    CHECK(std::fabs(f[0].area + f[1].area - 8) < 1e-12);   // the 2 x 3 rectangle, and a triangle of base 2, height 2
    bn_scene_destroy(s);
}

int main(int argc, char **argv)
{
    if (argc != 2)
        return 2;
    if (std::strcmp(argv[1], "exr_oiio") == 0)
        exr_oiio();
    else if (std::strcmp(argv[1], "baked_ply_openmesh") == 0)
        baked_ply_openmesh();
    else if (std::strcmp(argv[1], "off_binary_openmesh") == 0)
        off_binary_openmesh();
    else if (std::strcmp(argv[1], "png_pixels") == 0)
        png_pixels();
    else if (std::strcmp(argv[1], "cli_previews_match_exr") == 0)
        cli_previews_match_exr();
    else
        return 2;
    std::printf("ok\n");
    return 0;
}
