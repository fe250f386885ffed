// OpenMesh behind extern "C": PLY and OFF scene input (with a header and body scan of our own for
// validation and the per-face float properties OpenMesh reads only from ASCII PLY), and writing
// baked meshes as PLY and OM. Every entry point catches all exceptions.
// OpenMesh's property containers trigger GCC 12's -Wmaybe-uninitialized at -O2 and above inside
// their own templates (DEPENDENCIES.md gotcha 7); a middle-end warning, so a file-wide pragma.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include "adapters/adapters.h"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cctype>
#include <cstdio>
#include <iostream>
#include <strings.h>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <new>
#include <sstream>
#include <string>
#include <vector>

namespace {

struct FloatTraits : public OpenMesh::DefaultTraits {
    typedef OpenMesh::Vec3d Point;
    typedef OpenMesh::Vec4f Color;   // Vec3f does not compile in OpenMesh 9.0
};
struct ByteTraits : public OpenMesh::DefaultTraits {
    typedef OpenMesh::Vec3d Point;
    typedef OpenMesh::Vec3uc Color;
};
typedef OpenMesh::PolyMesh_ArrayKernelT<FloatTraits> FloatMesh;
typedef OpenMesh::PolyMesh_ArrayKernelT<ByteTraits> ByteMesh;

// Keeps OpenMesh's messages (omerr/omlog, std::clog) off the terminal while it works: bounce
// reports failures itself. OpenMesh's streams are switched off rather than redirected, because
// its mostream leaks a small wrapper on every connect/disconnect (seen under LeakSanitizer).
struct OmCapture {
    std::ostringstream text;
    std::streambuf *clog_buf;   // the OM writer reports "#bytes written" on std::clog
    bool err_on, log_on;
    OmCapture()
    {
        clog_buf = std::clog.rdbuf(text.rdbuf());
        err_on = ::omerr().is_enabled();
        log_on = ::omlog().is_enabled();
        ::omerr().disable();
        ::omlog().disable();
    }
    ~OmCapture()
    {
        std::clog.rdbuf(clog_buf);
        if (err_on)
            ::omerr().enable();
        if (log_on)
            ::omlog().enable();
    }
};

// ---------------------------------------------------------------- writing

template <class Mesh, class SetColour>
bn_status write_mesh(const char *path, const bn__bake_mesh *m, OpenMesh::IO::Options opt, SetColour set_colour,
                     size_t *duplicated, bn_error *err)
{
    Mesh mesh;
    std::vector<typename Mesh::VertexHandle> vh(m->nverts);
    std::vector<OpenMesh::VPropHandleT<float>> extra(m->nextra);
    std::vector<size_t> source;   // output vertex -> baked vertex (duplicates for non-manifold faces)
    if (m->colour || m->colour8)
        mesh.request_vertex_colors();
    for (size_t e = 0; e < m->nextra; e++) {
        mesh.add_property(extra[e], m->extra_name[e]);
        mesh.property(extra[e]).set_persistent(true);
    }
    auto add_vertex = [&](size_t v) {
        auto h = mesh.add_vertex(typename Mesh::Point(m->pos[3 * v], m->pos[3 * v + 1], m->pos[3 * v + 2]));
        if (m->colour || m->colour8)
            set_colour(mesh, h, v);
        for (size_t e = 0; e < m->nextra; e++)
            mesh.property(extra[e], h) = m->extra[e][v];
        source.push_back(v);
        return h;
    };
    for (size_t v = 0; v < m->nverts; v++)
        vh[v] = add_vertex(v);
    *duplicated = 0;
    for (size_t f = 0; f < m->nfaces; f++) {
        std::vector<typename Mesh::VertexHandle> fv;
        for (unsigned c = 0; c < m->face_n[f]; c++)
            fv.push_back(vh[m->face_idx[4 * f + c]]);
        if (!mesh.add_face(fv).is_valid()) {
            // A face OpenMesh's half-edge structure cannot hold (non-manifold): give it its own
            // copies of its vertices, as OpenMesh's own importer does.
            for (unsigned c = 0; c < m->face_n[f]; c++) {
                fv[c] = add_vertex(m->face_idx[4 * f + c]);
                ++*duplicated;
            }
            if (!mesh.add_face(fv).is_valid())
                return bn_error_set(err, BN_EINTERNAL, "OpenMesh: cannot add face %zu", f);
        }
    }
    OpenMesh::MPropHandleT<std::string> prov;
    if (m->provenance) {
        mesh.add_property(prov, "bounce:provenance");
        mesh.mproperty(prov).set_persistent(true);
        mesh.property(prov) = m->provenance;
    }
    OmCapture cap;
    if (!OpenMesh::IO::write_mesh(mesh, path, opt, 9))
        return bn_error_set(err, BN_EIO, "OpenMesh cannot write %s (is the folder there and writable?)", path);
    return BN_OK;
}

}   // namespace

extern "C" bn_status bn__openmesh_write(const char *path, const bn__bake_mesh *m, size_t *duplicated, bn_error *err)
{
    try {
        OpenMesh::IO::Options opt = OpenMesh::IO::Options::Binary;
        if (m->colour8) {
            opt += OpenMesh::IO::Options::VertexColor;
            return write_mesh<ByteMesh>(
                path, m, opt,
                [m](ByteMesh &mesh, ByteMesh::VertexHandle h, size_t v) {
                    mesh.set_color(h, ByteMesh::Color(m->colour8[3 * v], m->colour8[3 * v + 1], m->colour8[3 * v + 2]));
                },
                duplicated, err);
        }
        if (m->colour) {
            opt += OpenMesh::IO::Options::VertexColor;
            opt += OpenMesh::IO::Options::ColorFloat;
        }
        return write_mesh<FloatMesh>(
            path, m, opt,
            [m](FloatMesh &mesh, FloatMesh::VertexHandle h, size_t v) {
                mesh.set_color(h, FloatMesh::Color(m->colour[3 * v], m->colour[3 * v + 1], m->colour[3 * v + 2], 1.0f));
            },
            duplicated, err);
    } catch (const std::bad_alloc &) {
        return bn_error_set(err, BN_ENOMEM, "out of memory in OpenMesh writing %s", path);
    } catch (const std::exception &e) {
        return bn_error_set(err, BN_EINTERNAL, "OpenMesh writing %s: %s", path, e.what());
    } catch (...) {
        return bn_error_set(err, BN_EINTERNAL, "OpenMesh writing %s: unknown exception", path);
    }
}

// ---------------------------------------------------------------- reading binary OFF

namespace {

// The plain layout OpenMesh reads without bounds checks, walked here first: the keyword line
// "OFF BINARY", then int32 counts (vertices, faces, edges) in the host's byte order (OpenMesh reads
// them so), 3 floats per vertex, and per face an int32 corner count n in [3, 2^16] and n int32
// indices. A count the file cannot hold is refused before OpenMesh reserves or loops on it (a corner
// count read from garbage once ran it for minutes). Other binary variants (COFF, NOFF, ...) are
// refused by name.
static bn_status off_check_binary(const char *path, bn_error *err)
{
    std::ifstream in(path, std::ios::binary);
    if (!in)
        return bn_error_set(err, BN_EIO, "%s: cannot open: %s", path, std::strerror(errno));
    in.seekg(0, std::ios::end);
    unsigned long long size = (unsigned long long)in.tellg(), pos;
    in.seekg(0);
    std::string key;
    std::getline(in, key);
    while (!key.empty() && (key.back() == '\r' || key.back() == ' '))
        key.pop_back();
    for (char &ch : key)   // the message shows what was there, printable
        if ((unsigned char)ch < 0x20 || (unsigned char)ch >= 0x7f)
            ch = '?';
    if (key != "OFF BINARY")
        return bn_error_set(err, BN_EINPUT, "%s: binary OFF keyword line '%.40s': only the plain 'OFF BINARY' "
                                            "(positions and faces) is read", path, key.c_str());
    int32_t cnt[3];
    if (!in.read((char *)cnt, sizeof cnt))
        return bn_error_set(err, BN_EINPUT, "%s: truncated binary OFF header", path);
    pos = (unsigned long long)in.tellg();
    if (cnt[0] < 0 || cnt[1] < 0 || (unsigned long long)cnt[0] > (size - pos) / 12 ||
        (unsigned long long)cnt[1] > (size - pos) / 16)
        return bn_error_set(err, BN_EINPUT, "%s: the binary OFF header announces %d vertices and %d faces, more than "
                                            "a file of %llu bytes can hold", path, (int)cnt[0], (int)cnt[1], size);
    pos += 12ull * (unsigned long long)cnt[0];
    for (int32_t f = 0; f < cnt[1]; f++) {
        int32_t n = 0;
        in.seekg((std::streamoff)pos);
        if (pos + 4 > size || !in.read((char *)&n, 4) || n < 3 || n > (1 << 16) ||
            pos + 4 + 4ull * (unsigned long long)n > size)
            return bn_error_set(err, BN_EINPUT, "%s: binary OFF face %d (byte %llu): %s", path, (int)f, pos,
                                pos + 4 > size ? "past the end of the file"
                                               : "its corner count is not in [3, 65536] or runs past the end");
        pos += 4 + 4ull * (unsigned long long)n;
    }
    return BN_OK;
}

// OpenMesh's mesh into the sink: vertices and faces (binary OFF colours are not read).
static bn_status off_to_sink(const char *path, FloatMesh &mesh, const bn__mesh_sink *out, const bn_log *log,
                             bn_error *err)
{
    for (auto v : mesh.vertices()) {
        const auto &p = mesh.point(v);
        double q[3] = {p[0], p[1], p[2]};
        for (int c = 0; c < 3; c++)
            if (!std::isfinite(q[c]))
                return bn_error_set(err, BN_EINPUT, "%s: vertex %d has a non-finite coordinate", path, v.idx());
        if (!out->vertex(out->user, q))
            return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    for (auto fh : mesh.faces()) {
        std::vector<size_t> idx;
        for (auto v : mesh.fv_range(fh))
            idx.push_back((size_t)v.idx());
        if (!out->polygon(out->user, idx.data(), (unsigned)idx.size()))
            return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    bn_warnf(log, BN_W_NO_COLOURS, NAN, "%s: binary OFF: colours are not read; every face has reflectance 0.5", path);
    return BN_OK;
}

static bn_status read_off_binary(const char *path, const bn__mesh_sink *out, const bn_log *log, bn_error *err)
{
    bn_status st = off_check_binary(path, err);
    if (st != BN_OK)
        return st;
    FloatMesh mesh;
    OpenMesh::IO::Options opt = OpenMesh::IO::Options::Binary;
    {
        OmCapture cap;
        if (!OpenMesh::IO::read_mesh(mesh, path, opt))
            return bn_error_set(err, BN_EINPUT, "%s: OpenMesh cannot read it as binary OFF", path);
    }
    if (mesh.n_faces() == 0)
        return bn_error_set(err, BN_EINPUT, "%s: the OFF file has no faces", path);
    return off_to_sink(path, mesh, out, log, err);
}

}   // namespace

extern "C" bn_status bn__read_off_binary(const char *path, const bn__mesh_sink *out, const bn_log *log, bn_error *err)
{
    try {
        return read_off_binary(path, out, log, err);
    } catch (const std::bad_alloc &) {
        return bn_error_set(err, BN_ENOMEM, "%s: out of memory reading it", path);
    } catch (const std::exception &e) {
        return bn_error_set(err, BN_EINPUT, "%s: %s", path, e.what());
    } catch (...) {
        return bn_error_set(err, BN_EINTERNAL, "%s: unknown exception while reading", path);
    }
}
