// tinygltf behind extern "C": glTF 2.0 (.gltf, .glb) parsed and mirrored into plain C arrays for
// src/scene/gltf.c, which does every check and the walk. Nothing here interprets the scene: it copies
// what the file said, with counts, so the C side can name a wrong value by its JSON pointer.
// tinygltf (Debian's libtinygltf-dev, a shared library) reads the JSON, the .glb container, external
// buffers and data URIs; images are kept encoded (bounce decodes those it uses through OpenImageIO).
#include "adapters/adapters.h"

#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <new>
#include <string>
#include <vector>

namespace {

struct Impl {
    tinygltf::Model model;
    std::string warnings;
    std::vector<bn__gltf_buffer> buffers;
    std::vector<bn__gltf_view> views;
    std::vector<bn__gltf_accessor> accessors;
    std::vector<bn__gltf_prim> prims;
    std::vector<bn__gltf_mesh> meshes;
    std::vector<bn__gltf_material> materials;
    std::vector<bn__gltf_node> nodes;
    std::vector<bn__gltf_scene> scenes;
    std::vector<bn__gltf_image> images;
    std::vector<bn__gltf_texture> textures;
    std::vector<bn__gltf_camera> cameras;
    std::vector<bn__gltf_light> lights;
    std::vector<int> children, roots;
    std::vector<const char *> required;
    bn__gltf c;
};

// Images stay encoded (bounce decodes those a material uses, through OpenImageIO): their bytes are
// kept in image.image with width -1.
bool keep_image(tinygltf::Image *image, const int, std::string *, std::string *, int, int, const unsigned char *bytes,
                int size, void *)
{
    image->image.assign(bytes, bytes + (size > 0 ? size : 0));
    image->width = image->height = -1;
    return true;
}

// 1 for a .glb (its magic), 0 for anything else; *total: its header's length, *size: the file's.
bool is_glb(const char *path, unsigned long *total, long *size)
{
    FILE *f = std::fopen(path, "rb");
    unsigned char h[12] = {0};
    if (!f)
        return false;
    size_t got = std::fread(h, 1, 12, f);
    *size = std::fseek(f, 0, SEEK_END) == 0 ? std::ftell(f) : -1;
    std::fclose(f);
    *total = (unsigned long)h[8] | (unsigned long)h[9] << 8 | (unsigned long)h[10] << 16 | (unsigned long)h[11] << 24;
    return got >= 4 && std::memcmp(h, "glTF", 4) == 0;
}

// tinygltf fails on compressed geometry before anything else can look: name the extension, if the
// file's first megabytes mention one.
std::string compression_hint(const char *path)
{
    static const char *names[] = {"KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_meshopt_compression"};
    std::string head(4u << 20, '\0');
    FILE *f = std::fopen(path, "rb");
    if (!f)
        return "";
    head.resize(std::fread(&head[0], 1, head.size(), f));
    std::fclose(f);
    for (const char *n : names)
        if (head.find(n) != std::string::npos)
            return std::string(" (the file uses ") + n + ", compressed geometry, which bounce does not read: "
                   "decompress it first, e.g. with gltf-transform)";
    return "";
}

template <size_t N> unsigned copy_n(double (&dst)[N], const std::vector<double> &src)
{
    for (size_t i = 0; i < N && i < src.size(); i++)
        dst[i] = src[i];
    return (unsigned)std::min<size_t>(src.size(), 1000);
}

int accessor_type(int t)
{
    switch (t) {
    case TINYGLTF_TYPE_SCALAR: return 1;
    case TINYGLTF_TYPE_VEC2: return 2;
    case TINYGLTF_TYPE_VEC3: return 3;
    case TINYGLTF_TYPE_VEC4: return 4;
    default: return 0;
    }
}

void mirror_data(Impl &m)
{
    for (const auto &b : m.model.buffers)
        m.buffers.push_back({b.data.data(), b.data.size()});
    for (const auto &v : m.model.bufferViews)
        m.views.push_back({v.buffer, v.byteOffset, v.byteLength, v.byteStride});
    for (const auto &a : m.model.accessors) {
        bn__gltf_accessor x{};
        x.view = a.bufferView;
        x.ctype = a.componentType;
        x.type = accessor_type(a.type);
        x.normalized = a.normalized;
        x.offset = a.byteOffset;
        x.count = a.count;
        if (a.sparse.isSparse) {
            x.sparse_count = a.sparse.count > 0 ? (size_t)a.sparse.count : 0;
            x.sparse_iview = a.sparse.indices.bufferView;
            x.sparse_ictype = a.sparse.indices.componentType;
            x.sparse_ioffset = a.sparse.indices.byteOffset > 0 ? (size_t)a.sparse.indices.byteOffset : 0;
            x.sparse_vview = a.sparse.values.bufferView;
            x.sparse_voffset = a.sparse.values.byteOffset > 0 ? (size_t)a.sparse.values.byteOffset : 0;
        }
        m.accessors.push_back(x);
    }
}

int attribute(const tinygltf::Primitive &p, const char *name)
{
    auto it = p.attributes.find(name);
    return it == p.attributes.end() ? -1 : it->second;
}

void mirror_meshes(Impl &m)
{
    for (const auto &mesh : m.model.meshes) {
        m.meshes.push_back({mesh.name.c_str(), m.prims.size(), mesh.primitives.size()});
        for (const auto &p : mesh.primitives)
            m.prims.push_back({p.mode < 0 ? TINYGLTF_MODE_TRIANGLES : p.mode, p.material, p.indices,
                               attribute(p, "POSITION"), {attribute(p, "TEXCOORD_0"), attribute(p, "TEXCOORD_1")}});
    }
}

unsigned copy_numbers(const tinygltf::Value &v, double *out, size_t n)
{
    if (!v.IsArray())
        return v.Type() == tinygltf::NULL_TYPE ? 0 : 1000;   // present but not an array: refused above
    for (size_t i = 0; i < n && i < v.ArrayLen(); i++)
        out[i] = v.Get((int)i).IsNumber() ? v.Get((int)i).GetNumberAsDouble() : NAN;
    return (unsigned)std::min<size_t>(v.ArrayLen(), 1000);
}

// KHR_texture_transform on a texture reference: defaults offset 0, rotation 0, scale 1.
void mirror_transform(const tinygltf::ExtensionMap &ext, bn__gltf_material &x)
{
    x.tt_texcoord = -1;
    x.tt_scale[0] = x.tt_scale[1] = 1;
    auto it = ext.find("KHR_texture_transform");
    if (it == ext.end())
        return;
    const tinygltf::Value &t = it->second;
    x.tex_transform = 1;
    x.ntt_offset = copy_numbers(t.Get("offset"), x.tt_offset, 2);
    x.ntt_scale = copy_numbers(t.Get("scale"), x.tt_scale, 2);
    if (!x.ntt_scale)
        x.tt_scale[0] = x.tt_scale[1] = 1;
    const tinygltf::Value &r = t.Get("rotation"), &c = t.Get("texCoord");
    x.tt_rotation = r.IsNumber() ? r.GetNumberAsDouble() : r.Type() == tinygltf::NULL_TYPE ? 0.0 : NAN;
    x.tt_texcoord = c.IsNumber() ? (int)c.GetNumberAsDouble() : -1;
}

void mirror_material(const tinygltf::Material &mt, bn__gltf_material &x)
{
    x.name = mt.name.c_str();
    x.alpha_mode = mt.alphaMode.c_str();
    x.nbase = copy_n(x.base, mt.pbrMetallicRoughness.baseColorFactor);
    x.nemissive = copy_n(x.emissive, mt.emissiveFactor);
    x.base_tex = mt.pbrMetallicRoughness.baseColorTexture.index;
    x.base_uv = mt.pbrMetallicRoughness.baseColorTexture.texCoord;
    x.emissive_tex = mt.emissiveTexture.index;
    x.emissive_uv = mt.emissiveTexture.texCoord;
    x.emissive_transform = mt.emissiveTexture.extensions.count("KHR_texture_transform") > 0;
    mirror_transform(mt.pbrMetallicRoughness.baseColorTexture.extensions, x);
    x.double_sided = mt.doubleSided;
    x.strength = 1.0;
    auto es = mt.extensions.find("KHR_materials_emissive_strength");
    if (es != mt.extensions.end()) {
        x.has_strength = 1;
        const tinygltf::Value &v = es->second.Get("emissiveStrength");
        x.strength = v.IsNumber() ? v.GetNumberAsDouble() : -1.0;   // not a number: refused above
    }
    x.unlit = mt.extensions.count("KHR_materials_unlit") != 0;
    auto sg = mt.extensions.find("KHR_materials_pbrSpecularGlossiness");
    x.diffuse_tex = -1;
    if (sg != mt.extensions.end()) {
        const tinygltf::Value &d = sg->second.Get("diffuseFactor");
        x.specgloss = 1;
        x.ndiffuse = 4;   // the extension's default: white
        for (int c = 0; c < 4; c++)
            x.diffuse[c] = 1.0;
        if (d.IsArray()) {
            x.ndiffuse = (unsigned)std::min<size_t>(d.ArrayLen(), 1000);
            for (size_t c = 0; c < 4 && c < d.ArrayLen(); c++)
                x.diffuse[c] = d.Get((int)c).IsNumber() ? d.Get((int)c).GetNumberAsDouble() : -1.0;
        }
        const tinygltf::Value &t = sg->second.Get("diffuseTexture");
        if (t.IsObject() && t.Get("index").IsNumber())
            x.diffuse_tex = (int)t.Get("index").GetNumberAsDouble();
    }
}

void mirror_images(Impl &m)
{
    for (const auto &im : m.model.images) {
        bool have = im.width == -1 && !im.image.empty();
        m.images.push_back({have ? im.image.data() : nullptr, have ? im.image.size() : 0, im.mimeType.c_str(),
                            im.uri.c_str(), im.name.c_str()});
    }
    for (const auto &t : m.model.textures) {
        bn__gltf_texture x{t.source, 10497, 10497, -1};
        if (t.sampler >= 0 && (size_t)t.sampler < m.model.samplers.size()) {
            const auto &sm = m.model.samplers[t.sampler];
            x.wrap_s = sm.wrapS, x.wrap_t = sm.wrapT, x.mag = sm.magFilter;
        }
        m.textures.push_back(x);
    }
}

// A node's KHR_lights_punctual light index: -1 none, -2 when the extension is there but not a light index.
int node_light(const tinygltf::Node &n)
{
    auto e = n.extensions.find("KHR_lights_punctual");
    if (e == n.extensions.end())
        return -1;
    const tinygltf::Value &v = e->second.Get("light");
    return v.IsNumber() && v.GetNumberAsDouble() >= 0 && v.GetNumberAsDouble() < 2e9 ? (int)v.GetNumberAsDouble() : -2;
}

void mirror_scene(Impl &m)
{
    for (const auto &mt : m.model.materials) {
        bn__gltf_material x{};
        mirror_material(mt, x);
        m.materials.push_back(x);
    }
    for (const auto &n : m.model.nodes) {
        bn__gltf_node x{};
        x.name = n.name.c_str();
        x.mesh = n.mesh;
        x.skin = n.skin;
        x.camera = n.camera;
        x.light = node_light(n);
        x.first = m.children.size();
        x.n = n.children.size();
        m.children.insert(m.children.end(), n.children.begin(), n.children.end());
        x.nmatrix = copy_n(x.matrix, n.matrix);
        x.nt = copy_n(x.t, n.translation);
        x.nr = copy_n(x.r, n.rotation);
        x.ns = copy_n(x.s, n.scale);
        m.nodes.push_back(x);
    }
    for (const auto &s : m.model.scenes) {
        m.scenes.push_back({m.roots.size(), s.nodes.size()});
        m.roots.insert(m.roots.end(), s.nodes.begin(), s.nodes.end());
    }
    for (const auto &r : m.model.extensionsRequired)
        m.required.push_back(r.c_str());
    for (const auto &l : m.model.lights) {
        bn__gltf_light x{};
        x.name = l.name.c_str();
        x.type = l.type.c_str();
        x.ncolor = copy_n(x.color, l.color);
        x.intensity = l.intensity, x.range = l.range;
        x.inner = l.spot.innerConeAngle, x.outer = l.spot.outerConeAngle;
        m.lights.push_back(x);
    }
    for (const auto &c : m.model.cameras)
        m.cameras.push_back({c.name.c_str(), c.type == "perspective", c.perspective.yfov, c.perspective.aspectRatio,
                             c.perspective.znear, c.perspective.zfar});
}

void publish(Impl &m)
{
    bn__gltf &c = m.c;
    c = bn__gltf{};
    c.nbuffers = m.buffers.size(), c.buffers = m.buffers.data();
    c.nviews = m.views.size(), c.views = m.views.data();
    c.naccessors = m.accessors.size(), c.accessors = m.accessors.data();
    c.nprims = m.prims.size(), c.prims = m.prims.data();
    c.nmeshes = m.meshes.size(), c.meshes = m.meshes.data();
    c.nmaterials = m.materials.size(), c.materials = m.materials.data();
    c.nnodes = m.nodes.size(), c.nodes = m.nodes.data();
    c.nscenes = m.scenes.size(), c.scenes = m.scenes.data();
    c.nchildren = m.children.size(), c.children = m.children.data();
    c.nroots = m.roots.size(), c.roots = m.roots.data();
    c.nrequired = m.required.size(), c.required = m.required.data();
    c.nlights = m.lights.size(), c.lights = m.lights.data();
    c.ntextures = m.textures.size(), c.textures = m.textures.data();
    c.nimages = m.images.size(), c.images = m.images.data();
    c.ncameras = m.cameras.size(), c.cameras = m.cameras.data();
    c.default_scene = m.model.defaultScene;
    c.warnings = m.warnings.c_str();
    c.impl = &m;
}

} // namespace

extern "C" bn_status bn__gltf_parse(const char *path, bn__gltf **out, bn_error *err)
{
    *out = nullptr;
    Impl *m = nullptr;
    try {
        m = new Impl();
        tinygltf::TinyGLTF loader;
        loader.SetImageLoader(keep_image, nullptr);
        std::string error;
        unsigned long total = 0;
        long size = 0;
        bool glb = is_glb(path, &total, &size);
        if (glb && (long)total != size) {
            delete m;
            return bn_error_set(err, BN_EINPUT, "%s: a .glb cut short or with trailing bytes: its header says %lu bytes, "
                                "the file holds %ld", path, total, size);
        }
        bool ok = glb ? loader.LoadBinaryFromFile(&m->model, &error, &m->warnings, path)
                      : loader.LoadASCIIFromFile(&m->model, &error, &m->warnings, path);
        if (!ok || !error.empty()) {   // tinygltf can go on past a part it refused (a 3-value baseColorFactor)
            while (!error.empty() && (error.back() == '\n' || error.back() == ' '))
                error.pop_back();
            std::replace(error.begin(), error.end(), '\n', ' ');
            delete m;
            return bn_error_set(err, BN_EINPUT, "%s: not a readable glTF 2.0 file: %s%s", path,
                                error.empty() ? "(tinygltf gave no reason)" : error.c_str(),
                                compression_hint(path).c_str());
        }
        std::replace(m->warnings.begin(), m->warnings.end(), '\n', ' ');
        mirror_data(*m);
        mirror_meshes(*m);
        mirror_scene(*m);
        mirror_images(*m);
        publish(*m);
        *out = &m->c;
        return BN_OK;
    } catch (const std::bad_alloc &) {
        delete m;
        return bn_error_set(err, BN_ENOMEM, "%s: out of memory reading glTF", path);
    } catch (const std::exception &e) {
        delete m;
        return bn_error_set(err, BN_EINPUT, "%s: not a readable glTF 2.0 file: %s", path, e.what());
    } catch (...) {
        delete m;
        return bn_error_set(err, BN_EINPUT, "%s: not a readable glTF 2.0 file", path);
    }
}

extern "C" void bn__gltf_free(bn__gltf *g)
{
    if (g)
        delete static_cast<Impl *>(g->impl);
}
