// bounce's OBJ/MTL reader against an independent one (tinyobjloader) on real files: the same
// polygons, vertex positions, materials, Kd and Ke.
#include "scene/scene_internal.h"

#include <tiny_obj_loader.h>
#include <cmath>
#include <cstdio>
#include <string>

static int check(const std::string &path)
{
    tinyobj::ObjReaderConfig cfg;
    cfg.triangulate = false;
    cfg.mtl_search_path = path.substr(0, path.rfind('/') + 1);
    tinyobj::ObjReader reader;
    if (!reader.ParseFromFile(path, cfg)) {
        std::fprintf(stderr, "tinyobjloader failed on %s: %s\n", path.c_str(), reader.Error().c_str());
        return 1;
    }
    bn__soup soup{};
    bn_error err;
    bn_log log{};
    log.quiet = 1;
    if (bn__read_obj(path.c_str(), &soup, &log, &err) != BN_OK) {
        std::fprintf(stderr, "bounce failed on %s: %s\n", path.c_str(), err.msg);
        return 1;
    }
    const auto &attrib = reader.GetAttrib();
    const auto &mats = reader.GetMaterials();
    size_t poly = 0, fails = 0;
    size_t nv = attrib.vertices.size() / 3;
    if (nv != soup.nverts) {
        std::fprintf(stderr, "%s: vertices %zu (tinyobj) vs %zu (bounce)\n", path.c_str(), nv, soup.nverts);
        return 1;
    }
    // tinyobjloader groups faces by shape; bounce keeps file order. Match polygons by (line-free)
    // content: walk shapes in order, which for these files follows the file order.
    size_t idx_base = 0;
    for (const auto &shape : reader.GetShapes()) {
        size_t off = 0;
        for (size_t f = 0; f < shape.mesh.num_face_vertices.size(); f++, poly++) {
            unsigned n = shape.mesh.num_face_vertices[f];
            if (poly >= soup.npolys || soup.counts[poly] != n) {
                std::fprintf(stderr, "%s: polygon %zu differs in size\n", path.c_str(), poly);
                return 1;
            }
            size_t start = 0;
            for (size_t q = 0; q < poly; q++)
                start += soup.counts[q];
            for (unsigned k = 0; k < n; k++) {
                size_t vi = (size_t)shape.mesh.indices[off + k].vertex_index;
                for (int c = 0; c < 3; c++)
                    if (attrib.vertices[3 * vi + c] != (tinyobj::real_t)soup.verts[3 * soup.idx[start + k] + c])
                        fails++;
            }
            int mid = shape.mesh.material_ids[f];
            const bn_material &bm = soup.mats[soup.mat[poly]];
            if (mid < 0 || mats[mid].name != bm.name) {
                std::fprintf(stderr, "%s: polygon %zu material %s vs %s\n", path.c_str(), poly,
                             mid < 0 ? "(none)" : mats[mid].name.c_str(), bm.name);
                return 1;
            }
            for (int c = 0; c < 3; c++) {
                if (std::fabs(mats[mid].diffuse[c] - bm.rho[c]) > 1e-6 || std::fabs(mats[mid].emission[c] - bm.Le[c]) > 1e-6)
                    fails++;
            }
            off += n;
        }
        idx_base += off;
    }
    if (poly != soup.npolys || fails) {
        std::fprintf(stderr, "%s: %zu polygons (tinyobj) vs %zu (bounce), %zu mismatches\n", path.c_str(), poly,
                     soup.npolys, fails);
        return 1;
    }
    std::printf("%s: %zu polygons, %zu vertices, %zu materials agree\n", path.c_str(), poly, nv, mats.size());
    bn__soup_free(&soup);
    return 0;
}

int main(int argc, char **argv)
{
    int rc = 0;
    for (int i = 1; i < argc; i++) {
        std::FILE *fp = std::fopen(argv[i], "rb");
        if (!fp) {   // shared/ sits beside the clone in CI; elsewhere it may not: skipped, not passed
            std::fprintf(stderr, "skipped: reference file not found: %s\n", argv[i]);
            return 77;
        }
        std::fclose(fp);
    }
    for (int i = 1; i < argc; i++)
        rc |= check(argv[i]);
    return rc;
}
