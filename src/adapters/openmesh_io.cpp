// OpenMesh behind extern "C": PLY and OFF scene input (with a header and body scan of our own for
// validation and the per-face float properties OpenMesh reads only from ASCII PLY), and writing
// baked meshes as PLY and OM. Every entry point catches all exceptions.
// OpenMesh's property containers trigger GCC 12's -Wmaybe-uninitialized at -O2 and above inside
// their own templates (DEPENDENCIES.md gotcha 7); a middle-end warning, so a file-wide pragma.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include "adapters/adapters.h"
#include "scene/scene_internal.h"

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

// ---------------------------------------------------------------- reading

namespace {

// A PLY scan of our own: the header, then every record, to validate what OpenMesh would drop or
// misread silently (indices out of range, NaN, truncation) with line numbers, and to read the
// per-face float properties (reflectance_*, emission_*) from ASCII and binary files alike.
enum PlyType { T_INT8, T_UINT8, T_INT16, T_UINT16, T_INT32, T_UINT32, T_FLOAT32, T_FLOAT64, T_BAD };
struct PlyProp {
    std::string name;
    PlyType type = T_BAD, count_type = T_BAD;
    bool list = false;
};
struct PlyElem {
    std::string name;
    unsigned long long count = 0;
    std::vector<PlyProp> props;
};
enum PlyFormat { F_ASCII, F_LE, F_BE };

static const char *const face_prop_names[6] = {"reflectance_red", "reflectance_green", "reflectance_blue",
                                                "emission_red",    "emission_green",    "emission_blue"};

struct PlyScan {
    PlyFormat format = F_ASCII;
    std::vector<PlyElem> elems;
    std::vector<std::array<double, 3>> pos;
    std::vector<std::vector<long long>> faces;
    std::vector<unsigned> face_line;           // ASCII line of each face (0 for binary)
    std::vector<std::array<double, 6>> face_props;
    std::vector<std::array<double, 3>> face_rgb;   // face colours as linear reflectance (8-bit / 255)
    bool has_prop[6] = {false, false, false, false, false, false};
    bool face_colour = false, vertex_colour = false;
};

static PlyType ply_type(const std::string &t)
{
    if (t == "char" || t == "int8") return T_INT8;
    if (t == "uchar" || t == "uint8") return T_UINT8;
    if (t == "short" || t == "int16") return T_INT16;
    if (t == "ushort" || t == "uint16") return T_UINT16;
    if (t == "int" || t == "int32") return T_INT32;
    if (t == "uint" || t == "uint32") return T_UINT32;
    if (t == "float" || t == "float32") return T_FLOAT32;
    if (t == "double" || t == "float64") return T_FLOAT64;
    return T_BAD;
}
static size_t ply_size(PlyType t)
{
    static const size_t sz[] = {1, 1, 2, 2, 4, 4, 4, 8, 0};
    return sz[t];
}

struct PlyReader {
    std::ifstream in;
    PlyFormat format;
    unsigned line = 1;
    void skip_ws()
    {
        int c;
        if (format != F_ASCII)
            return;
        while ((c = in.peek()) != EOF && std::isspace(c)) {
            if (c == '\n')
                line++;
            in.get();
        }
    }
    // Next value of type t; false at end of file or on a bad token.
    bool value(PlyType t, double &out, std::string &bad)
    {
        if (format == F_ASCII) {
            std::string tok;
            int c;
            skip_ws();
            while ((c = in.peek()) != EOF && !std::isspace(c))
                tok.push_back((char)in.get());
            if (tok.empty())
                return false;
            char *end;
            out = std::strtod(tok.c_str(), &end);
            if (*end != '\0') {
                bad = tok;
                return false;
            }
            if (t != T_FLOAT32 && t != T_FLOAT64 && out != std::floor(out)) {
                bad = tok;
                return false;
            }
            return true;
        }
        unsigned char b[8];
        size_t n = ply_size(t);
        if (!in.read((char *)b, (std::streamsize)n))
            return false;
        if (format == F_BE)
            for (size_t i = 0; i < n / 2; i++)
                std::swap(b[i], b[n - 1 - i]);
        switch (t) {
        case T_INT8: out = (int8_t)b[0]; break;
        case T_UINT8: out = b[0]; break;
        case T_INT16: { int16_t v; std::memcpy(&v, b, 2); out = v; break; }
        case T_UINT16: { uint16_t v; std::memcpy(&v, b, 2); out = v; break; }
        case T_INT32: { int32_t v; std::memcpy(&v, b, 4); out = v; break; }
        case T_UINT32: { uint32_t v; std::memcpy(&v, b, 4); out = v; break; }
        case T_FLOAT32: { float v; std::memcpy(&v, b, 4); out = v; break; }
        case T_FLOAT64: { double v; std::memcpy(&v, b, 8); out = v; break; }
        default: return false;
        }
        return true;
    }
};

static bn_status ply_scan(const char *path, PlyScan &S, bn_error *err)
{
    PlyReader R;
    R.in.open(path, std::ios::binary);
    if (!R.in)
        return bn_error_set(err, BN_EIO, "%s: cannot open: %s", path, std::strerror(errno));
    std::string ln;
    unsigned lineno = 0;
    bool have_format = false, ended = false;
    while (std::getline(R.in, ln)) {
        lineno++;
        if (!ln.empty() && ln.back() == '\r')
            ln.pop_back();
        std::istringstream ls(ln);
        std::string kw;
        ls >> kw;
        if (lineno == 1) {
            if (kw != "ply" || ln.size() > 3)
                return bn_error_set(err, BN_EINPUT, "%s:1: not a PLY file (the first line must be 'ply')", path);
            continue;
        }
        if (kw.empty() || kw == "comment" || kw == "obj_info")
            continue;
        if (kw == "format") {
            std::string f, v;
            ls >> f >> v;
            if (f == "ascii") S.format = F_ASCII;
            else if (f == "binary_little_endian") S.format = F_LE;
            else if (f == "binary_big_endian") S.format = F_BE;
            else
                return bn_error_set(err, BN_EINPUT, "%s:%u: unknown PLY format '%s'", path, lineno, f.c_str());
            if (v != "1.0")
                return bn_error_set(err, BN_EINPUT, "%s:%u: PLY version '%s' (bounce reads 1.0)", path, lineno, v.c_str());
            have_format = true;
        } else if (kw == "element") {
            PlyElem e;
            std::string cnt, extra;
            ls >> e.name >> cnt;
            char *end = nullptr;
            e.count = cnt.empty() || cnt[0] == '-' ? 0 : std::strtoull(cnt.c_str(), &end, 10);
            if (e.name.empty() || cnt.empty() || cnt[0] == '-' || !end || *end || (ls >> extra))
                return bn_error_set(err, BN_EINPUT, "%s:%u: bad element line '%s' (expected 'element NAME COUNT')", path,
                                    lineno, ln.c_str());
            S.elems.push_back(e);
        } else if (kw == "property") {
            PlyProp p;
            std::string t;
            if (S.elems.empty())
                return bn_error_set(err, BN_EINPUT, "%s:%u: property before any element", path, lineno);
            ls >> t;
            if (t == "list") {
                std::string ct, it;
                ls >> ct >> it >> p.name;
                p.list = true;
                p.count_type = ply_type(ct);
                p.type = ply_type(it);
                if (p.count_type == T_BAD || p.count_type == T_FLOAT32 || p.count_type == T_FLOAT64 || p.type == T_BAD)
                    return bn_error_set(err, BN_EINPUT, "%s:%u: bad list property '%s'", path, lineno, ln.c_str());
            } else {
                p.type = ply_type(t);
                ls >> p.name;
                if (p.type == T_BAD)
                    return bn_error_set(err, BN_EINPUT, "%s:%u: unknown property type '%s'", path, lineno, t.c_str());
            }
            if (p.name.empty())
                return bn_error_set(err, BN_EINPUT, "%s:%u: property without a name", path, lineno);
            S.elems.back().props.push_back(p);
        } else if (kw == "end_header") {
            ended = true;
            break;
        } else {
            return bn_error_set(err, BN_EINPUT, "%s:%u: unknown PLY header keyword '%s'", path, lineno, kw.c_str());
        }
    }
    if (!ended)
        return bn_error_set(err, BN_EINPUT, "%s: the PLY header has no end_header line", path);
    if (!have_format)
        return bn_error_set(err, BN_EINPUT, "%s: the PLY header has no format line", path);
    R.format = S.format;
    R.line = lineno + 1;
    unsigned long long nverts = 0;
    bool seen_vertex = false, seen_face = false;
    for (const PlyElem &e : S.elems) {
        bool is_v = e.name == "vertex", is_f = e.name == "face";
        int ix = -1, iy = -1, iz = -1, iidx = -1, iprop[6] = {-1, -1, -1, -1, -1, -1}, irgb[3] = {-1, -1, -1};
        double rgb_scale[3] = {1, 1, 1};
        for (size_t k = 0; k < e.props.size(); k++) {
            const std::string &n = e.props[k].name;
            if (is_v) {
                if (n == "x") ix = (int)k;
                if (n == "y") iy = (int)k;
                if (n == "z") iz = (int)k;
                if (n == "red" || n == "green" || n == "blue") S.vertex_colour = true;
            }
            if (is_f) {
                if ((n == "vertex_indices" || n == "vertex_index") && e.props[k].list) iidx = (int)k;
                if (n == "red" || n == "green" || n == "blue") {
                    if (e.props[k].list)
                        return bn_error_set(err, BN_EINPUT, "%s: face colour '%s' is a list", path, n.c_str());
                    irgb[n == "red" ? 0 : n == "green" ? 1 : 2] = (int)k;
                    rgb_scale[n == "red" ? 0 : n == "green" ? 1 : 2] =
                        e.props[k].type == T_FLOAT32 || e.props[k].type == T_FLOAT64 ? 1.0 : 1.0 / 255.0;
                }
                for (int q = 0; q < 6; q++)
                    if (n == face_prop_names[q] && !e.props[k].list) {
                        iprop[q] = (int)k;
                        S.has_prop[q] = true;
                    }
            }
        }
        if (is_v) {
            if (ix < 0 || iy < 0 || iz < 0)
                return bn_error_set(err, BN_EINPUT, "%s: the vertex element lacks x, y or z", path);
            nverts = e.count;
            seen_vertex = true;
        }
        if (is_f) {
            if (iidx < 0)
                return bn_error_set(err, BN_EINPUT, "%s: the face element has no vertex_indices list", path);
            int nset = 0;
            for (int q = 0; q < 3; q++) nset += S.has_prop[q];
            if (nset != 0 && nset != 3)
                return bn_error_set(err, BN_EINPUT, "%s: face reflectance needs all of reflectance_red, _green, _blue",
                                    path);
            nset = 0;
            for (int q = 3; q < 6; q++) nset += S.has_prop[q];
            if (nset != 0 && nset != 3)
                return bn_error_set(err, BN_EINPUT, "%s: face emission needs all of emission_red, _green, _blue", path);
            if (irgb[0] >= 0 || irgb[1] >= 0 || irgb[2] >= 0) {
                if (irgb[0] < 0 || irgb[1] < 0 || irgb[2] < 0)
                    return bn_error_set(err, BN_EINPUT, "%s: face colours need all of red, green and blue", path);
                S.face_colour = true;
            }
            seen_face = true;
        }
        for (unsigned long long r = 0; r < e.count; r++) {
            std::array<double, 3> p = {0, 0, 0};
            std::array<double, 6> fp = {0, 0, 0, 0, 0, 0};
            std::array<double, 3> rgb = {0, 0, 0};
            std::vector<long long> idx;
            R.skip_ws();
            unsigned start_line = R.line;
            for (size_t k = 0; k < e.props.size(); k++) {
                const PlyProp &pr = e.props[k];
                double v;
                std::string bad;
                size_t n = 1;
                if (pr.list) {
                    if (!R.value(pr.count_type, v, bad) || v < 0)
                        goto truncated;
                    n = (size_t)v;
                }
                for (size_t j = 0; j < n; j++) {
                    if (!R.value(pr.type, v, bad)) {
                        if (!bad.empty())
                            return bn_error_set(err, BN_EINPUT, "%s:%u: '%s' is not a valid %s value in %s %llu", path,
                                                R.line, bad.c_str(), pr.name.c_str(), e.name.c_str(), r);
                        goto truncated;
                    }
                    if ((int)k == iidx)
                        idx.push_back((long long)v);
                    if (is_v && ((int)k == ix || (int)k == iy || (int)k == iz))
                        p[(int)k == ix ? 0 : (int)k == iy ? 1 : 2] = v;
                    for (int q = 0; q < 6; q++)
                        if (is_f && (int)k == iprop[q])
                            fp[q] = v;
                    for (int q = 0; q < 3; q++)
                        if (is_f && (int)k == irgb[q])
                            rgb[q] = v * rgb_scale[q];
                }
            }
            if (is_v) {
                for (int c = 0; c < 3; c++)
                    if (!std::isfinite(p[c]))
                        return bn_error_set(err, BN_EINPUT, "%s:%s vertex %llu has a non-finite coordinate (%g)", path,
                                            S.format == F_ASCII ? std::to_string(start_line).c_str() : "", r, p[c]);
                S.pos.push_back(p);
            }
            if (is_f) {
                std::string where = S.format == F_ASCII ? std::to_string(start_line) + ":" : std::string("");
                if (idx.size() < 3)
                    return bn_error_set(err, BN_EINPUT, "%s:%s face %llu has %zu vertices (at least 3 needed)", path,
                                        where.c_str(), r, idx.size());
                for (long long i : idx)
                    if (i < 0 || (unsigned long long)i >= nverts || !seen_vertex)
                        return bn_error_set(err, BN_EINPUT, "%s:%s face %llu: vertex index %lld is out of range (%llu vertices)",
                                            path, where.c_str(), r, i, nverts);
                for (int q = 0; q < 6; q++)
                    if (S.has_prop[q] && !std::isfinite(fp[q]))
                        return bn_error_set(err, BN_EINPUT, "%s:%s face %llu: %s is not finite", path, where.c_str(), r,
                                            face_prop_names[q]);
                S.faces.push_back(idx);
                S.face_line.push_back(S.format == F_ASCII ? start_line : 0);
                S.face_props.push_back(fp);
                S.face_rgb.push_back(rgb);
            }
        }
        continue;
    truncated:
        return bn_error_set(err, BN_EINPUT, "%s: the file ends inside element '%s' (the header promises %llu)", path,
                            e.name.c_str(), e.count);
    }
    if (!seen_vertex || !seen_face)
        return bn_error_set(err, BN_EINPUT, "%s: a PLY scene needs vertex and face elements", path);
    if (S.faces.empty())
        return bn_error_set(err, BN_EINPUT, "%s: the PLY file has no faces", path);
    return BN_OK;
}

static bool all_distinct(const std::vector<long long> &v)
{
    for (size_t i = 0; i < v.size(); i++)
        for (size_t j = i + 1; j < v.size(); j++)
            if (v[i] == v[j])
                return false;
    return true;
}

// OFF text without its '#' comments (to the end of each line).
static std::string off_strip_comments(const std::string &text)
{
    std::string clean;
    bool comment = false;
    clean.reserve(text.size());
    for (char ch : text) {
        if (ch == '#')
            comment = true;
        if (ch == '\n')
            comment = false;
        if (!comment)
            clean.push_back(ch);
    }
    return clean;
}

// OFF's counts line (the first non-blank line after the keyword, comments already removed).
static bool off_counts_text(const std::string &text, unsigned long long &nv, unsigned long long &nf)
{
    std::istringstream in(text);
    std::string ln, kw;
    if (!std::getline(in, ln))
        return false;
    std::istringstream first(ln);
    first >> kw;
    // The keyword is exactly one of OpenMesh's variants: [ST][C][N][4][n]OFF.
    {
        size_t k = 0;
        for (const char *opt = "STCN4n"; *opt && k < kw.size(); opt++) {
            if (*opt == 'T' && k > 0 && kw[k - 1] == 'S')
                continue;   /* S and T exclude each other */
            if (kw[k] == *opt)
                k++;
        }
        if (kw.compare(k, std::string::npos, "OFF") != 0)
            return false;
    }
    std::string rest;
    std::getline(first, rest);
    // OpenMesh reads the counts from the lines after the keyword's, never from the same line.
    if (rest.find_first_not_of(" \t\r") != std::string::npos)
        return false;
    while (rest.find_first_not_of(" \t\r") == std::string::npos) {
        if (!std::getline(in, rest))
            return false;
    }
    std::istringstream ls(rest);
    return (bool)(ls >> nv >> nf);
}

// Checks an ASCII OFF body (comments removed, line numbers kept) before OpenMesh reads it, whose
// reader loops on malformed records: nv vertex lines of at least 3 finite numbers, then nf face
// lines "n i_1 .. i_n [colour]" with n >= 3 and every index in [0, nv).
static bn_status off_scan(const char *path, const std::string &clean, unsigned long long nv, unsigned long long nf,
                          bool &face_colour, bn_error *err)
{
    face_colour = nf > 0;   /* every face line carries at least r g b after its indices */
    std::istringstream in(clean);
    std::string ln;
    unsigned line = 0;
    bool counts_seen = false, keyword_seen = false;
    unsigned long long v = 0, f = 0;
    while (std::getline(in, ln)) {
        line++;
        std::istringstream ls(ln);
        std::vector<std::string> tok;
        std::string t;
        while (ls >> t)
            tok.push_back(t);
        if (tok.empty())
            continue;
        if (!keyword_seen) {   /* the keyword alone (off_counts_text checked it) */
            keyword_seen = true;
            continue;
        }
        if (!counts_seen) {
            counts_seen = true;
            continue;
        }
        std::vector<double> num;
        for (const std::string &x : tok) {
            char *end = nullptr;
            double d = std::strtod(x.c_str(), &end);
            if (end == x.c_str() || *end != '\0' || !std::isfinite(d))
                return bn_error_set(err, BN_EINPUT, "%s:%u: '%s' is not a finite number", path, line, x.c_str());
            num.push_back(d);
        }
        if (v < nv) {
            if (num.size() < 3)
                return bn_error_set(err, BN_EINPUT, "%s:%u: vertex %llu needs 3 coordinates", path, line, v);
            v++;
        } else if (f < nf) {
            double n = num[0];
            if (n != std::floor(n) || n < 3 || n > 65536 || num.size() < (size_t)n + 1)
                return bn_error_set(err, BN_EINPUT, "%s:%u: face %llu: '%s' vertices, or fewer indices than that",
                                    path, line, f, tok[0].c_str());
            for (size_t k = 1; k <= (size_t)n; k++)
                if (num[k] != std::floor(num[k]) || num[k] < 0 || num[k] >= (double)nv)
                    return bn_error_set(err, BN_EINPUT, "%s:%u: face %llu: vertex index %s is out of range (%llu "
                                                        "vertices)", path, line, f, tok[k].c_str(), nv);
            if (num.size() < (size_t)n + 4)
                face_colour = false;
            f++;
        } else {
            break;   /* trailing data (edges) is not read */
        }
    }
    if (v < nv || f < nf)
        return bn_error_set(err, BN_EINPUT, "%s: the file ends after %llu of %llu vertices and %llu of %llu faces", path,
                            v, nv, f, nf);
    return BN_OK;
}

struct MatKey {
    std::array<double, 6> v;
    bool operator<(const MatKey &o) const { return v < o.v; }
};

static bn_status read_openmesh(const char *path, bn__soup *out, const bn_log *log, bn_error *err)
{
    const char *dot = std::strrchr(path, '.');
    bool is_ply = dot && strcasecmp(dot, ".ply") == 0;
    PlyScan S;
    if (is_ply) {
        // A PLY header is text, and so is an ASCII body: control bytes in them (a NUL inside a
        // number) desynchronise OpenMesh's reader, which then writes out of bounds.
        std::ifstream in(path, std::ios::binary);
        std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        size_t eh = text.find("end_header");
        bool ascii = eh != std::string::npos && text.substr(0, eh).find("format ascii") != std::string::npos;
        size_t limit = eh == std::string::npos ? text.size() : ascii ? text.size() : eh;
        unsigned line = 1;
        for (size_t i = 0; i < limit; i++) {
            unsigned char ch = (unsigned char)text[i];
            if (ch == '\n')
                line++;
            else if (ch < 0x20 && ch != '\t' && ch != '\r')
                return bn_error_set(err, BN_EINPUT, "%s:%u: control byte 0x%02x in PLY text", path, line, ch);
        }
    }
    if (is_ply) {
        bn_status st = ply_scan(path, S, err);
        if (st != BN_OK)
            return st;
    }
    bool off_face_colour = false, off_vertex_colour = false;   /* what our OFF scan found */
    FloatMesh mesh;
    mesh.request_vertex_colors();
    mesh.request_face_colors();
    OpenMesh::IO::Options opt;
    if (!is_ply || S.vertex_colour)
        opt += OpenMesh::IO::Options::VertexColor;
    // PLY face colours come from our own scan: OpenMesh sets the colour of a face it has just
    // refused (a repeated vertex) and writes out of bounds.
    if (!is_ply)
        opt += OpenMesh::IO::Options::FaceColor;
    {
        std::string read_path = path;
        char *tmp = nullptr;
        if (!is_ply) {
            std::ifstream in(path, std::ios::binary);
            std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
            bool binary = text.find("BINARY") != std::string::npos;
            std::string clean = binary ? std::string() : off_strip_comments(text);
            // OpenMesh reserves whatever the header announces: check the counts against what the
            // file can hold before it sees them (a vertex takes at least 4 bytes, a face 4 more).
            unsigned long long nv = 0, nf = 0;
            if (!binary) {
                for (unsigned char ch : clean)
                    if (ch < 0x20 && ch != '\t' && ch != '\r' && ch != '\n')
                        return bn_error_set(err, BN_EINPUT, "%s: an ASCII OFF file holds a control byte (0x%02x)", path,
                                            ch);
                if (!off_counts_text(clean, nv, nf))
                    return bn_error_set(err, BN_EINPUT, "%s: not an OFF file: no line with the 'OFF' keyword alone, "
                                                        "followed by a line 'vertices faces edges'", path);
                if (nv > text.size() / 4 || nf > text.size() / 4)
                    return bn_error_set(err, BN_EINPUT,
                                        "%s: the header announces %llu vertices and %llu faces, more than a file of "
                                        "%zu bytes can hold",
                                        path, nv, nf, text.size());
                {
                    bn_status st = off_scan(path, clean, nv, nf, off_face_colour, err);
                    if (st != BN_OK)
                        return st;
                }
                {
                    /* vertex colours: the C of [ST]COFF */
                    std::istringstream k(clean);
                    std::string kw;
                    k >> kw;
                    off_vertex_colour = kw.find('C') != std::string::npos;
                }
            } else if (text.size() < 16) {
                return bn_error_set(err, BN_EINPUT, "%s: truncated binary OFF file", path);
            } else {
                // binary OFF: the counts follow the keyword line as int32s (read either byte order
                // and accept the header if one reading fits the file)
                size_t p0 = text.find('\n');
                if (p0 == std::string::npos || p0 + 9 > text.size())
                    return bn_error_set(err, BN_EINPUT, "%s: truncated binary OFF header", path);
                const unsigned char *b = reinterpret_cast<const unsigned char *>(text.data() + p0 + 1);
                auto fits = [&](bool big) {
                    for (int k = 0; k < 2; k++) {
                        const unsigned char *q = b + 4 * k;
                        uint32_t v = big ? (uint32_t)q[0] << 24 | (uint32_t)q[1] << 16 | (uint32_t)q[2] << 8 | q[3]
                                         : (uint32_t)q[3] << 24 | (uint32_t)q[2] << 16 | (uint32_t)q[1] << 8 | q[0];
                        if (v > text.size() / 4)
                            return false;
                    }
                    return true;
                };
                if (!fits(true) && !fits(false))
                    return bn_error_set(err, BN_EINPUT, "%s: the binary OFF header announces more elements than a "
                                                        "file of %zu bytes can hold", path, text.size());
            }
            if (!binary && text.find('#') != std::string::npos) {
                // OpenMesh's OFF reader stops at '#' comments (which OFF allows): give it a copy without
                // them, under a registered temporary name removed afterwards.
                std::string alt = std::string(path) + ".nocomments.off";
                if (bn__tmpname_reserve(alt.c_str(), &tmp, err) != BN_OK)
                    return err ? err->status : BN_ENOMEM;
                std::ofstream o(tmp, std::ios::binary);
                o << clean;
                if (!o) {
                    bn__tmpname_abort(tmp);
                    return bn_error_set(err, BN_EIO, "%s: cannot write a temporary copy without comments", path);
                }
                read_path = tmp;
            }
        }
        OmCapture cap;
        bool ok = OpenMesh::IO::read_mesh(mesh, read_path, opt);
        if (tmp)
            bn__tmpname_abort(tmp);
        if (!ok)
            return bn_error_set(err, BN_EINPUT, "%s: OpenMesh cannot read it as %s", path, is_ply ? "PLY" : "OFF");
    }
    // Which faces OpenMesh kept: it drops faces with a repeated vertex (and, for OFF, faces with
    // indices out of range, which the PLY scan has already refused).
    std::vector<size_t> file_face;   // OpenMesh face -> face of the file
    size_t dropped = 0;
    if (is_ply) {
        for (size_t f = 0; f < S.faces.size(); f++) {
            if (all_distinct(S.faces[f]))
                file_face.push_back(f);
            else
                dropped++;
        }
        if (file_face.size() != mesh.n_faces())
            return bn_error_set(err, BN_EINPUT, "%s: OpenMesh read %zu faces where the file has %zu usable ones", path,
                                (size_t)mesh.n_faces(), file_face.size());
    } else {
        unsigned long long nv = 0, nf = 0;
        std::ifstream in(path, std::ios::binary);
        std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        if (off_counts_text(off_strip_comments(text), nv, nf) && nf != mesh.n_faces())
            return bn_error_set(err, BN_EINPUT,
                                "%s: OpenMesh kept %zu of the %llu faces the header announces (a face has an index out "
                                "of range, a repeated vertex or fewer than 3 vertices)",
                                path, (size_t)mesh.n_faces(), nf);
        if (mesh.n_faces() == 0)
            return bn_error_set(err, BN_EINPUT, "%s: the OFF file has no faces", path);
        for (size_t f = 0; f < mesh.n_faces(); f++)
            file_face.push_back(f);
    }
    if (dropped)
        bn_logf(log, BN_LOG_WARN, "%s: %zu faces with a repeated vertex were dropped", path, dropped);

    for (auto v : mesh.vertices()) {
        const auto &p = mesh.point(v);
        double q[3] = {p[0], p[1], p[2]};
        for (int c = 0; c < 3; c++)
            if (!std::isfinite(q[c]))
                return bn_error_set(err, BN_EINPUT, "%s: vertex %d has a non-finite coordinate", path, v.idx());
        if (!bn__soup_add_vertex(out, q))
            return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    std::map<MatKey, unsigned> mats;
    bool refl_props = is_ply && S.has_prop[0], emis_props = is_ply && S.has_prop[3];
    // OpenMesh may flag colours the file does not have (its values are then uninitialised): trust
    // our own scans for which colours exist.
    bool fcol = is_ply ? S.face_colour : mesh.has_face_colors() && off_face_colour && opt.face_has_color();
    bool vcol = mesh.has_vertex_colors() && (is_ply ? S.vertex_colour : off_vertex_colour && opt.vertex_has_color());
    size_t k = 0;
    for (auto fh : mesh.faces()) {
        size_t ff = file_face[k++];
        std::vector<size_t> idx;
        MatKey key;
        unsigned line = is_ply ? S.face_line[ff] : 0;
        double rho[3] = {0.5, 0.5, 0.5}, le[3] = {0, 0, 0}, vsum[3] = {0, 0, 0};
        for (auto v : mesh.fv_range(fh)) {
            idx.push_back((size_t)v.idx());
            if (vcol)
                for (int c = 0; c < 3; c++)
                    vsum[c] += mesh.color(v)[c];
        }
        // OpenMesh may start a face at another corner: rotate back to the file's first vertex so
        // a split of a non-planar polygon follows the file's order.
        if (is_ply) {
            const auto &first = S.pos[(size_t)S.faces[ff][0]];
            for (size_t r = 0; r < idx.size(); r++) {
                const auto &p = mesh.point(OpenMesh::VertexHandle((int)idx[r]));
                if (p[0] == first[0] && p[1] == first[1] && p[2] == first[2]) {
                    std::rotate(idx.begin(), idx.begin() + (long)r, idx.end());
                    break;
                }
            }
        }
        if (refl_props)
            for (int c = 0; c < 3; c++) rho[c] = S.face_props[ff][c];
        else if (fcol && is_ply)
            for (int c = 0; c < 3; c++) rho[c] = S.face_rgb[ff][c];   // 8-bit colour / 255
        else if (fcol)
            for (int c = 0; c < 3; c++) rho[c] = mesh.color(fh)[c];   // 8-bit colour / 255
        else if (vcol)
            for (int c = 0; c < 3; c++) rho[c] = vsum[c] / (double)idx.size();
        if (emis_props)
            for (int c = 0; c < 3; c++) le[c] = S.face_props[ff][3 + c];
        for (int c = 0; c < 3; c++) {
            std::string where = line ? ":" + std::to_string(line) : std::string("");
            if (!(rho[c] >= 0 && rho[c] <= 1))
                return bn_error_set(err, BN_EINPUT, "%s%s: face %zu: reflectance %g is outside [0, 1]", path,
                                    where.c_str(), ff, rho[c]);
            if (!(le[c] >= 0))
                return bn_error_set(err, BN_EINPUT, "%s%s: face %zu: emission %g is negative", path, where.c_str(), ff,
                                    le[c]);
        }
        key.v = {rho[0], rho[1], rho[2], le[0], le[1], le[2]};
        auto it = mats.find(key);
        unsigned m;
        if (it == mats.end()) {
            bn_material mat;
            std::memset(&mat, 0, sizeof mat);
            std::snprintf(mat.name, sizeof mat.name, "ply%zu", mats.size());
            for (int c = 0; c < 3; c++) {
                mat.rho[c] = rho[c];
                mat.Le[c] = le[c];
            }
            if (!bn__soup_add_material(out, &mat))
                return bn_error_set(err, BN_ENOMEM, "out of memory");
            m = (unsigned)mats.size();
            mats[key] = m;
        } else {
            m = it->second;
        }
        if (!bn__soup_add_polygon(out, idx.data(), (unsigned)idx.size(), m, line))
            return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    if (!refl_props && !fcol && !vcol)
        bn_logf(log, BN_LOG_WARN, "%s: no colours or reflectance properties: every face has reflectance 0.5", path);
    return BN_OK;
}

}   // namespace

extern "C" bn_status bn__read_openmesh(const char *path, bn__soup *out, const bn_log *log, bn_error *err)
{
    try {
        return read_openmesh(path, out, log, err);
    } catch (const std::bad_alloc &) {
        return bn_error_set(err, BN_ENOMEM, "%s: out of memory reading it", path);
    } catch (const std::exception &e) {
        return bn_error_set(err, BN_EINPUT, "%s: %s", path, e.what());
    } catch (...) {
        return bn_error_set(err, BN_EINTERNAL, "%s: unknown exception while reading", path);
    }
}
