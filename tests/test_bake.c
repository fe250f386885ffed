/* Baking: vertex splitting at creases and seams, colours equal to the area-weighted patch
 * averages (checked through an independent PLY parser), OBJ output, and PLY/OFF scene input
 * through OpenMesh with malformed files refused clearly. */
#include "bn_test.h"

#include <stdint.h>
#include "bounce/bake.h"

/* Baked colours are stored as float32: 1e-6 relative covers the rounding of the average. */
#define TOL_COLOUR 1e-6

static bn_scene *scene_arrays(const double *v, size_t nv, const unsigned *polys, size_t np, const unsigned *pm,
                              const bn_material *m, size_t nm, size_t patches)
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_scene *s;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    if (bn_scene_from_arrays("test", v, nv, polys, np, pm, m, nm, &lo, &s, &err) != BN_OK)
        BN_FAIL("scene: %s", err.msg);
    bn_mesh_opts_default(&mo);
    if (patches)
        mo.target_patches = patches;
    else
        mo.no_subdivide = 1;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("mesh: %s", err.msg);
    return s;
}

static const bn_material white = {"white", {0.5, 0.5, 0.5}, {0, 0, 0}};
static const bn_material red = {"red", {0.5, 0.1, 0.1}, {0, 0, 0}};

static size_t baked_count(bn_scene *s, double crease)
{
    bn_bake *b;
    bn_error err;
    BN_ASSERT_STATUS(bn_bake_create(s, crease, &b, &err), BN_OK);
    size_t n = bn_bake_vertex_count(b);
    bn_bake_destroy(b);
    return n;
}

BN_TEST(split_at_creases_and_seams)
{
    /* Floor (y = 0, facing +y) and a wall (z = 0, facing +z) sharing the edge x in [0,1]. */
    double v[] = {0, 0, 0, 1, 0, 0, 1, 0, 1, 0, 0, 1, 0, 1, 0, 1, 1, 0};
    unsigned polys[] = {4, 0, 3, 2, 1, 4, 0, 1, 5, 4};
    unsigned same[] = {0, 0}, diff[] = {0, 1};
    bn_material m[2] = {white, red};
    bn_scene *s = scene_arrays(v, 6, polys, 2, same, m, 2, 0);
    BN_ASSERT_EQ(baked_count(s, 30), 8);    /* 90 degrees > 30: split */
    BN_ASSERT_EQ(baked_count(s, 100), 6);   /* within the crease: shared */
    bn_scene_destroy(s);
    s = scene_arrays(v, 6, polys, 2, diff, m, 2, 0);
    BN_ASSERT_EQ(baked_count(s, 100), 8);   /* material seam: split even within the crease */
    bn_scene_destroy(s);
    /* Two coplanar quads of one material, each meshed 2x2: (3x5) grid points shared = 15. */
    double w[] = {0, 0, 0, 0, 0, 1, 1, 0, 1, 1, 0, 0, 2, 0, 1, 2, 0, 0};
    unsigned q[] = {4, 0, 1, 2, 3, 4, 3, 2, 4, 5};
    s = scene_arrays(w, 6, q, 2, same, m, 2, 8);
    BN_ASSERT_EQ(bn_scene_patches(s, NULL) ? 1 : 0, 1);
    size_t np;
    bn_scene_patches(s, &np);
    BN_ASSERT_EQ(np, 8);
    BN_ASSERT_EQ(baked_count(s, 30), 15);
    bn_scene_destroy(s);
}

/* ---- an independent binary PLY parser (little endian, float/uchar/int, one list) ---- */
typedef struct ply_data {
    size_t nv, nf;
    int nprops;
    char prop[64][32];
    float *v;          /* nv * nprops */
    unsigned *fn;      /* corners per face */
    unsigned *fi;      /* 4 per face */
    int ncomments;
} ply_data;

static void ply_parse(const char *path, ply_data *d)
{
    size_t size;
    char *buf = bn_test_read_file(path, &size), *p = buf, *end;
    memset(d, 0, sizeof *d);
    BN_ASSERT(buf != NULL);
    BN_ASSERT(strncmp(p, "ply\n", 4) == 0);
    end = strstr(buf, "end_header\n");
    BN_ASSERT(end != NULL);
    int in_vertex = 0;
    for (char *line = p; line < end;) {
        char *nl = strchr(line, '\n');
        char tmp[256];
        size_t n = (size_t)(nl - line) < sizeof tmp - 1 ? (size_t)(nl - line) : sizeof tmp - 1;
        memcpy(tmp, line, n);
        tmp[n] = '\0';
        if (strncmp(tmp, "format ", 7) == 0)
            BN_ASSERT(strcmp(tmp, "format binary_little_endian 1.0") == 0);
        else if (strncmp(tmp, "comment ", 8) == 0)
            d->ncomments++;
        else if (sscanf(tmp, "element vertex %zu", &d->nv) == 1)
            in_vertex = 1;
        else if (sscanf(tmp, "element face %zu", &d->nf) == 1)
            in_vertex = 0;
        else if (strncmp(tmp, "property float ", 15) == 0 && in_vertex)
            snprintf(d->prop[d->nprops++], 32, "%.31s", tmp + 15);
        else if (strncmp(tmp, "property", 8) == 0)
            BN_ASSERT(!in_vertex && strcmp(tmp, "property list uchar int vertex_indices") == 0);
        line = nl + 1;
    }
    p = end + strlen("end_header\n");
    d->v = malloc(d->nv * d->nprops * sizeof(float));
    BN_ASSERT((size_t)(buf + size - p) >= d->nv * d->nprops * 4);
    memcpy(d->v, p, d->nv * d->nprops * 4);
    p += d->nv * d->nprops * 4;
    d->fn = calloc(d->nf, sizeof(unsigned));
    d->fi = calloc(d->nf * 4, sizeof(unsigned));
    for (size_t f = 0; f < d->nf; f++) {
        unsigned char k = (unsigned char)*p++;
        BN_ASSERT(k == 3 || k == 4);
        d->fn[f] = k;
        for (unsigned c = 0; c < k; c++) {
            int32_t idx;
            memcpy(&idx, p, 4);
            p += 4;
            BN_ASSERT(idx >= 0 && (size_t)idx < d->nv);
            d->fi[4 * f + c] = (unsigned)idx;
        }
    }
    BN_ASSERT_EQ(p - buf, (long)size);
    free(buf);
}

static int ply_prop(const ply_data *d, const char *name)
{
    for (int i = 0; i < d->nprops; i++)
        if (strcmp(d->prop[i], name) == 0)
            return i;
    BN_FAIL("property %s missing", name);
    return -1;
}

/* Does `pos` lie strictly inside an edge (within 1e-3 scene units, away from its ends) of a patch of
 * `material` whose normal is within `cosc` of n, and is not that patch's corner? (a T-junction: the
 * bake gives it the edge's value instead of the area mean; no_cracks_at_t_junctions checks that) */
static int on_patch_edge(const bn_patch *p, size_t np, const double *pv, const float pos[3], unsigned material,
                         const double n[3], double cosc)
{
    for (size_t q = 0; q < np; q++) {
        if (p[q].material != material || p[q].normal[0] * n[0] + p[q].normal[1] * n[1] + p[q].normal[2] * n[2] < cosc)
            continue;
        for (unsigned c = 0; c < p[q].ncorners; c++) {
            const double *a = pv + 3 * p[q].corner[c], *b = pv + 3 * p[q].corner[(c + 1) % p[q].ncorners];
            double ab[3], ap[3], l2 = 0, t = 0, d2 = 0;
            for (int k = 0; k < 3; k++) {
                ab[k] = b[k] - a[k];
                ap[k] = pos[k] - a[k];
                l2 += ab[k] * ab[k];
                t += ap[k] * ab[k];
            }
            if (!(l2 > 0))
                continue;
            t /= l2;
            for (int k = 0; k < 3; k++)
                d2 += (ap[k] - t * ab[k]) * (ap[k] - t * ab[k]);
            if (d2 < 1e-6 && t * sqrt(l2) > 1e-3 && (1 - t) * sqrt(l2) > 1e-3)
                return 1;
        }
    }
    return 0;
}

BN_TEST(ply_colours_are_patch_averages)
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_scene *s;
    bn_bake *b;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    bn_mesh_opts_default(&mo);
    mo.target_patches = 250;
    BN_ASSERT_STATUS(bn_scene_load(bn_test_path("meshes/cornell-box.obj"), &lo, &s, &err), BN_OK);
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    BN_ASSERT_STATUS(bn_bake_create(s, 30, &b, &err), BN_OK);
    size_t np, npv;
    const bn_patch *p = bn_scene_patches(s, &np);
    const double *pv = bn_scene_patch_vertices(s, &npv);
    double *x = malloc(np * 3 * sizeof(double)), *x2 = malloc(np * 3 * sizeof(double));
    for (size_t i = 0; i < np; i++)
        for (int c = 0; c < 3; c++) {
            x[3 * i + c] = 0.1 + 0.01 * (double)((i * 7 + c * 3) % 101);   /* distinct per patch */
            x2[3 * i + c] = 2 * x[3 * i + c];
        }
    bn_bake_layer layers[2] = {{"L", x, NULL}, {"KE", x2, NULL}};
    bn_attr attr = {"command line", "bounce bake test"};
    bn_bake_write_opts wo;
    memset(&wo, 0, sizeof wo);
    wo.attrs = &attr;
    wo.nattrs = 1;
    const char *path = bn_test_tmp("b.ply");
    BN_ASSERT_STATUS(bn_bake_write(b, path, layers, 2, &wo, &err), BN_OK);
    ply_data d;
    ply_parse(path, &d);
    BN_ASSERT_EQ(d.nv, bn_bake_vertex_count(b));
    BN_ASSERT_EQ(d.nf, np);
    BN_ASSERT_GE(d.ncomments, 2);
    int ix = ply_prop(&d, "x"), ir = ply_prop(&d, "red"), ike = ply_prop(&d, "KE_red");
    double cos30 = cos(30 * 3.14159265358979 / 180);
    /* Expected colour of vertex v: take a face (patch) f using it; average over every patch with a
     * corner at v's position (brute force), the same material as f and a normal within 30 degrees. */
    unsigned *owner = malloc(d.nv * sizeof(unsigned));
    for (size_t f = 0; f < d.nf; f++)
        for (unsigned c = 0; c < d.fn[f]; c++)
            owner[d.fi[4 * f + c]] = (unsigned)f;
    size_t tjunctions = 0;
    for (size_t v = 0; v < d.nv; v++) {
        const float *row = d.v + v * d.nprops;
        const bn_patch *pf = &p[owner[v]];
        double sum[3] = {0, 0, 0}, area = 0;
        for (int k = 0; k < d.nprops; k++)
            BN_ASSERT(isfinite(row[k]));
        if (on_patch_edge(p, np, pv, row + ix, pf->material, pf->normal, cos30)) {
            tjunctions++;   /* the edge's value, not the mean (no_cracks_at_t_junctions) */
            continue;
        }
        for (size_t q = 0; q < np; q++) {
            int at = 0;
            for (unsigned c = 0; c < p[q].ncorners; c++) {
                const double *a = pv + 3 * p[q].corner[c];
                /* float32 positions of a 560 mm box: 1e-3 mm is far below a patch edge. */
                if (fabs(a[0] - row[ix]) < 1e-3 && fabs(a[1] - row[ix + 1]) < 1e-3 && fabs(a[2] - row[ix + 2]) < 1e-3)
                    at = 1;
            }
            if (!at || p[q].material != pf->material)
                continue;
            if (p[q].normal[0] * pf->normal[0] + p[q].normal[1] * pf->normal[1] + p[q].normal[2] * pf->normal[2] <
                cos30)
                continue;
            area += p[q].area;
            for (int c = 0; c < 3; c++)
                sum[c] += p[q].area * x[3 * q + c];
        }
        BN_ASSERT_GT(area, 0);
        for (int c = 0; c < 3; c++) {
            BN_ASSERT_REL(row[ir + c], sum[c] / area, TOL_COLOUR);
            BN_ASSERT_REL(row[ike + c], 2 * sum[c] / area, TOL_COLOUR);
        }
    }
    fprintf(stderr, "%zu T-junctions (the bake found %zu)\n", tjunctions, bn_bake_tjunction_count(b));
    BN_ASSERT_EQ(tjunctions, bn_bake_tjunction_count(b));
    free(owner);
    free(d.v);
    free(d.fn);
    free(d.fi);
    /* OBJ: v x y z r g b, one line per vertex, one f per patch. */
    BN_ASSERT_STATUS(bn_bake_write(b, bn_test_tmp("b.obj"), layers, 1, &wo, &err), BN_OK);
    char *obj = bn_test_read_file(bn_test_tmp("b.obj"), NULL);
    size_t nvl = 0, nfl = 0;
    for (char *l = obj; l && *l; l = strchr(l, '\n') ? strchr(l, '\n') + 1 : l + strlen(l)) {
        double q[6];
        if (strncmp(l, "v ", 2) == 0) {
            BN_ASSERT_EQ(sscanf(l, "v %lf %lf %lf %lf %lf %lf", &q[0], &q[1], &q[2], &q[3], &q[4], &q[5]), 6);
            nvl++;
        }
        nfl += strncmp(l, "f ", 2) == 0;
    }
    BN_ASSERT(strstr(obj, "# command line: bounce bake test") != NULL);
    free(obj);
    BN_ASSERT_EQ(nvl, bn_bake_vertex_count(b));
    BN_ASSERT_EQ(nfl, np);
    /* Per-bounce sets are refused for OBJ. */
    BN_ASSERT_STATUS(bn_bake_write(b, bn_test_tmp("c.obj"), layers, 2, &wo, &err), BN_EUSAGE);
    /* NaN: refused, nothing written. */
    x[0] = NAN;
    BN_ASSERT_STATUS(bn_bake_write(b, bn_test_tmp("nan.ply"), layers, 1, &wo, &err), BN_ENUMERIC);
    BN_ASSERT(!bn_test_file_exists(bn_test_tmp("nan.ply")));
    free(x);
    free(x2);
    bn_bake_destroy(b);
    bn_scene_destroy(s);
}

/* ---- PLY and OFF scene input ---- */
static void write_file(const char *name, const char *text, size_t n)
{
    FILE *f = fopen(bn_test_tmp(name), "wb");
    fwrite(text, 1, n ? n : strlen(text), f);
    fclose(f);
}

static bn_status load(const char *name, bn_scene **s, bn_error *err)
{
    bn_load_opts lo;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    return bn_scene_load(bn_test_tmp(name), &lo, s, err);
}

static const char ply_head[] = "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\n"
                               "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
                               "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                               "property float emission_red\nproperty float emission_green\n"
                               "property float emission_blue\nend_header\n";
static const char ply_verts[] = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n0 1 1\n1 1 1\n1 0 1\n";

BN_TEST(ply_ascii_input)
{
    char text[2048];
    bn_scene *s;
    bn_error err;
    snprintf(text, sizeof text, "%s%s4 0 1 2 3 255 51 0 0 0 0\n4 4 5 6 7 0 0 0 5 4 3\n", ply_head, ply_verts);
    write_file("a.ply", text, 0);
    BN_ASSERT_STATUS(load("a.ply", &s, &err), BN_OK);
    size_t nf, nm;
    const bn_face *f = bn_scene_faces(s, &nf);
    const bn_material *m = bn_scene_materials(s, &nm);
    BN_ASSERT_EQ(nf, 2);
    BN_ASSERT_EQ(bn_scene_emitter_count(s), 1);
    BN_ASSERT_NEAR(m[f[0].material].rho[0], 1, 1e-12);
    BN_ASSERT_NEAR(m[f[0].material].rho[1], 0.2, 1e-7);   /* 51 / 255 */
    BN_ASSERT_EQ(m[f[1].material].Le[0], 5);
    BN_ASSERT_EQ(m[f[1].material].Le[2], 3);
    BN_ASSERT_EQ(f[1].line, 25);
    bn_scene_destroy(s);
}

BN_TEST(ply_binary_input)
{
    /* Binary little endian, double positions, float reflectance and emission per face. */
    const char *head = "ply\nformat binary_little_endian 1.0\ncomment test\nelement vertex 4\nproperty double x\n"
                       "property double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_indices\n"
                       "property float reflectance_red\nproperty float reflectance_green\n"
                       "property float reflectance_blue\nproperty float emission_red\nproperty float emission_green\n"
                       "property float emission_blue\nend_header\n";
    char buf[1024];
    size_t n = strlen(head);
    double v[12] = {0, 0, 0, 2, 0, 0, 2, 3, 0, 0, 3, 0};
    unsigned char k = 4;
    uint32_t idx[4] = {0, 1, 2, 3};
    float props[6] = {0.25f, 0.5f, 0.75f, 1, 2, 3};
    memcpy(buf, head, n);
    memcpy(buf + n, v, sizeof v), n += sizeof v;
    buf[n++] = (char)k;
    memcpy(buf + n, idx, sizeof idx), n += sizeof idx;
    memcpy(buf + n, props, sizeof props), n += sizeof props;
    write_file("b.ply", buf, n);
    bn_scene *s;
    bn_error err;
    BN_ASSERT_STATUS(load("b.ply", &s, &err), BN_OK);
    size_t nf;
    const bn_face *f = bn_scene_faces(s, &nf);
    const bn_material *m = bn_scene_materials(s, NULL);
    BN_ASSERT_EQ(nf, 1);
    BN_ASSERT_NEAR(f[0].area, 6, 1e-12);
    BN_ASSERT_EQ(m[f[0].material].rho[2], 0.75);
    BN_ASSERT_EQ(m[f[0].material].Le[1], 2);
    bn_scene_destroy(s);
    /* Truncated: the same file without its last bytes. */
    write_file("bt.ply", buf, n - 5);
    BN_ASSERT_STATUS(load("bt.ply", &s, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "ends inside element 'face'") != NULL);
}

BN_TEST(off_input)
{
    bn_scene *s;
    bn_error err;
    write_file("a.off", "OFF\n# a comment\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n", 0);
    BN_ASSERT_STATUS(load("a.off", &s, &err), BN_OK);
    size_t nf;
    bn_scene_faces(s, &nf);
    BN_ASSERT_EQ(nf, 1);
    bn_scene_destroy(s);
    write_file("bad.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n3 0 1 7\n", 0);
    BN_ASSERT_STATUS(load("bad.off", &s, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "bad.off") != NULL);
}

/* Colours as reflectance, each file read by one reader: PLY vertex colours (a face takes their
 * mean), big-endian binary face colours (8 bits / 255), a face with a repeated vertex dropped; OFF
 * with COFF vertex colours and comments, and with real-valued face colours. Materials are shared
 * by faces with equal colours, numbered in order of first use. */
BN_TEST(ply_off_colours)
{
    bn_scene *s;
    bn_error err;
    size_t nf, nm;
    const bn_face *f;
    const bn_material *m;
    write_file("vc.ply",
               "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
               "property uchar red\nproperty uchar green\nproperty uchar blue\nelement face 3\n"
               "property list uchar int vertex_indices\nend_header\n"
               "0 0 0 255 0 0\n1 0 0 255 0 0\n1 1 0 0 0 255\n0 1 0 0 0 255\n3 0 1 2\n3 0 2 3\n3 0 0 3\n", 0);
    BN_ASSERT_STATUS(load("vc.ply", &s, &err), BN_OK);
    f = bn_scene_faces(s, &nf);
    m = bn_scene_materials(s, &nm);
    BN_ASSERT_EQ(nf, 2);   /* "3 0 0 3" repeats a vertex: dropped */
    BN_ASSERT_EQ(nm, 2);
    BN_ASSERT_REL(m[f[0].material].rho[0], 2.0 / 3.0, 1e-12);   /* (1 + 1 + 0) / 3 */
    BN_ASSERT_REL(m[f[0].material].rho[2], 1.0 / 3.0, 1e-12);
    BN_ASSERT_REL(m[f[1].material].rho[0], 1.0 / 3.0, 1e-12);   /* (1 + 0 + 0) / 3 */
    BN_ASSERT_EQ(f[0].material, 0);
    bn_scene_destroy(s);
    {
        /* big-endian binary: 3 float positions a vertex, faces "uchar n, int indices, uchar r g b" */
        const char *head = "ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                           "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
                           "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
        unsigned char buf[512];
        size_t n = strlen(head);
        const float v[12] = {0, 0, 0, 2, 0, 0, 2, 2, 0, 0, 2, 0};
        const int tri[2][3] = {{0, 1, 2}, {0, 2, 3}};
        const unsigned char rgb[2][3] = {{51, 102, 255}, {51, 102, 255}};
        memcpy(buf, head, n);
        for (int k = 0; k < 12; k++) {
            uint32_t u;
            memcpy(&u, &v[k], 4);
            for (int b = 3; b >= 0; b--)
                buf[n++] = (unsigned char)(u >> (8 * b));
        }
        for (int t = 0; t < 2; t++) {
            buf[n++] = 3;
            for (int c = 0; c < 3; c++)
                for (int b = 3; b >= 0; b--)
                    buf[n++] = (unsigned char)((uint32_t)tri[t][c] >> (8 * b));
            for (int c = 0; c < 3; c++)
                buf[n++] = rgb[t][c];
        }
        write_file("be.ply", (const char *)buf, n);
        BN_ASSERT_STATUS(load("be.ply", &s, &err), BN_OK);
        f = bn_scene_faces(s, &nf);
        m = bn_scene_materials(s, &nm);
        BN_ASSERT_EQ(nf, 2);
        BN_ASSERT_EQ(nm, 1);   /* equal colours share a material */
        BN_ASSERT_NEAR(f[0].area + f[1].area, 4, 1e-12);
        BN_ASSERT_REL(m[0].rho[0], 0.2, 1e-12);
        BN_ASSERT_REL(m[0].rho[1], 0.4, 1e-12);
        BN_ASSERT_EQ(m[0].rho[2], 1);
        bn_scene_destroy(s);
    }
    write_file("c.off", "COFF # vertex colours\n4 1 0\n0 0 0 255 0 0\n1 0 0 255 0 0\n1 1 0 0 0 255\n"
                        "0 1 0 0 0 255 # blue\n4 0 1 2 3\n", 0);
    BN_ASSERT_STATUS(load("c.off", &s, &err), BN_OK);
    f = bn_scene_faces(s, &nf);
    m = bn_scene_materials(s, NULL);
    BN_ASSERT_EQ(nf, 1);
    BN_ASSERT_EQ(m[f[0].material].rho[0], 0.5);
    BN_ASSERT_EQ(m[f[0].material].rho[1], 0);
    BN_ASSERT_EQ(m[f[0].material].rho[2], 0.5);
    BN_ASSERT_EQ(f[0].line, 7);
    bn_scene_destroy(s);
    write_file("fc.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2 0.25 0.5 0.75\n3 0 2 3 0.25 0.5 0.75 1\n", 0);
    BN_ASSERT_STATUS(load("fc.off", &s, &err), BN_OK);
    m = bn_scene_materials(s, &nm);
    BN_ASSERT_EQ(nm, 1);
    BN_ASSERT_EQ(m[0].rho[0], 0.25);
    BN_ASSERT_EQ(m[0].rho[2], 0.75);
    bn_scene_destroy(s);
    /* 4OFF and nOFF are refused by name */
    write_file("h.off", "4OFF\n4 1 0\n0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n4 0 1 2 3\n", 0);
    BN_ASSERT_STATUS(load("h.off", &s, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "h.off:1: '4OFF'") != NULL);
}

BN_TEST(ply_malformed)
{
    static const struct {
        const char *name, *text, *expect;
    } cases[] = {
        {"m1.ply", "plx\n", "not a PLY file"},
        {"m2.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "no end_header"},
        {"m3.ply", "ply\nformat ascii 2.0\nend_header\n", "version"},
        {"m4.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n", "unknown property type"},
        {"m5.ply", "ply\nformat ascii 1.0\nelement vertex -3\nend_header\n", "bad element line"},
        {"m6.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                   "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
         "m6.ply:13: face 0: vertex index 3 is out of range"},
        {"m7.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                   "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n",
         "non-finite"},
        {"m8.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                   "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n",
         "ends inside element 'face'"},
        {"m9.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                   "element face 1\nproperty list uchar int vertex_indices\nproperty float reflectance_red\n"
                   "property float reflectance_green\nproperty float reflectance_blue\nend_header\n"
                   "0 0 0\n1 0 0\n0 1 0\n3 0 1 2 1.5 0 0\n",
         "reflectance 1.5 is outside [0, 1]"},
        {"m10.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
         "has 2 vertices"},
        {"m11.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 zz\n3 0 1 2\n",
         "'zz' is not a valid z value"},
        {"m12.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nend_header\n0\n", "lacks x, y or z"},
        {"m13.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 1\nproperty list uchar int vertex_indices\nproperty float emission_red\n"
                    "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 1\n",
         "needs all of emission_red"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        bn_scene *s = NULL;
        bn_error err;
        write_file(cases[i].name, cases[i].text, 0);
        bn_status st = load(cases[i].name, &s, &err);
        if (st != BN_EINPUT || !strstr(err.msg, cases[i].expect))
            BN_FAIL("%s: status %d, message '%s', expected '%s'", cases[i].name, (int)st, err.msg, cases[i].expect);
        BN_ASSERT(s == NULL);
    }
    /* Random bytes after a valid binary header: an error, not a crash. */
    char junk[600];
    const char *head = "ply\nformat binary_big_endian 1.0\nelement vertex 100\nproperty float x\nproperty float y\n"
                       "property float z\nelement face 100\nproperty list uchar int vertex_indices\nend_header\n";
    size_t n = strlen(head);
    memcpy(junk, head, n);
    for (size_t i = n; i < sizeof junk; i++)
        junk[i] = (char)(i * 2654435761u >> 13);
    write_file("junk.ply", junk, sizeof junk);
    bn_scene *s = NULL;
    bn_error err;
    BN_ASSERT_STATUS(load("junk.ply", &s, &err), BN_EINPUT);
}

/* The white furnace (closed cube, rho 0.5, Le 1) baked per bounce: every vertex of every layer has
 * its analytic value, E = 1, KE = rho = 0.5, K2E = rho^2 = 0.25, rest = sum_{k>2} rho^k =
 * rho^3 / (1 - rho) = 0.25 and L = Le / (1 - rho) = 2, to the form factors' row-sum accuracy (the
 * analytic method, no occluders: ~1e-6, times 1 / (1 - rho)). On the Cornell box, E is the MTL's
 * Ke on the light's vertices and 0 on every other. */
BN_TEST(cli_bake)
{
    char cmd[2048], *out = NULL;
    const char *names[] = {"E_red", "KE_red", "K2E_red", "rest_red", "red"};
    const double want[] = {1, 0.5, 0.25, 0.25, 2};
    ply_data d;
    int rc, ie, ir;
    size_t lit = 0;
    snprintf(cmd, sizeof cmd, "bake '%s' -o '%s' --per-bounce -n 2 --patches 150 --gather none --quiet",
             bn_test_path("meshes/furnace-box.obj"), bn_test_tmp("fb.ply"));
    rc = bn_test_bounce(cmd, &out);
    if (rc != 0)
        BN_FAIL("bounce exited %d: %s", rc, out ? out : "");
    free(out);
    ply_parse(bn_test_tmp("fb.ply"), &d);
    BN_ASSERT_GT(d.nv, 0);
    for (int l = 0; l < 5; l++) {
        int ip = ply_prop(&d, names[l]);
        for (size_t v = 0; v < d.nv; v++)
            for (int c = 0; c < 3; c++)
                BN_ASSERT_REL(d.v[v * d.nprops + ip + c], want[l], 1e-4);
    }
    free(d.v);
    free(d.fn);
    free(d.fi);
    snprintf(cmd, sizeof cmd, "bake '%s' -o '%s' --per-bounce -n 2 --patches 150 --gather none --ff hemisphere --samples 256 --quiet",
             bn_test_path("meshes/cornell-box.obj"), bn_test_tmp("cb.ply"));
    rc = bn_test_bounce(cmd, &out);
    if (rc != 0)
        BN_FAIL("bounce exited %d: %s", rc, out ? out : "");
    free(out);
    ply_parse(bn_test_tmp("cb.ply"), &d);
    ie = ply_prop(&d, "E_red");
    ir = ply_prop(&d, "red");
    for (size_t v = 0; v < d.nv; v++) {
        const float *r = d.v + v * d.nprops;
        if (r[ie] == 0 && r[ie + 1] == 0 && r[ie + 2] == 0)
            continue;
        lit++;
        BN_ASSERT_EQ(r[ie], 17);   /* Ke 17 12 4: the light is a material of its own, so no blending */
        BN_ASSERT_EQ(r[ie + 1], 12);
        BN_ASSERT_EQ(r[ie + 2], 4);
        BN_ASSERT_EQ(r[ir], 17);   /* its reflectance is 0: L = E */
    }
    BN_ASSERT_GE(lit, 4);
    free(d.v);
    free(d.fn);
    free(d.fi);
    snprintf(cmd, sizeof cmd, "bake '%s' -o '%s' --per-bounce", bn_test_path("meshes/cornell-box.obj"),
             bn_test_tmp("x.obj"));
    BN_ASSERT_EQ(bn_test_bounce(cmd, NULL), 2);
}

/* --mesh input (input_mesh): the faces are the scene's polygons, every corner at an input vertex, and
 * each vertex's colour is the area-weighted mean of the patches with a corner at that point on its
 * smooth surface (brute force here: same material as the polygon, normal within 30 degrees). */
BN_TEST(ply_input_mesh)
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_scene *s;
    bn_bake *b;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    bn_mesh_opts_default(&mo);
    mo.target_patches = 250;
    BN_ASSERT_STATUS(bn_scene_load(bn_test_path("meshes/cornell-box.obj"), &lo, &s, &err), BN_OK);
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    BN_ASSERT_STATUS(bn_bake_create(s, 30, &b, &err), BN_OK);
    size_t np, npv, nf, nv, ni;
    const bn_patch *p = bn_scene_patches(s, &np);
    const double *pv = bn_scene_patch_vertices(s, &npv), *iv = bn_scene_vertices(s, &nv);
    const bn_face *f = bn_scene_faces(s, &nf);
    const size_t *idx = bn_scene_face_indices(s, &ni);
    double *x = malloc(np * 3 * sizeof(double));
    for (size_t i = 0; i < np; i++)
        for (int c = 0; c < 3; c++)
            x[3 * i + c] = 0.1 + 0.01 * (double)((i * 7 + c * 3) % 101);
    bn_bake_layer layer = {"L", x, NULL};
    bn_bake_write_opts wo;
    memset(&wo, 0, sizeof wo);
    wo.input_mesh = 1;
    const char *path = bn_test_tmp("in.ply");
    BN_ASSERT_STATUS(bn_bake_write(b, path, &layer, 1, &wo, &err), BN_OK);
    ply_data d;
    ply_parse(path, &d);
    BN_ASSERT_EQ(d.nf, nf);
    BN_ASSERT_LT(d.nv, bn_bake_vertex_count(b));
    int ix = ply_prop(&d, "x"), ir = ply_prop(&d, "red");
    double cos30 = cos(30 * 3.14159265358979 / 180);
    for (size_t k = 0; k < nf; k++) {
        BN_ASSERT_EQ(d.fn[k], f[k].nverts);
        for (unsigned c = 0; c < f[k].nverts; c++) {
            const float *row = d.v + d.fi[4 * k + c] * d.nprops;
            const double *q = iv + 3 * idx[f[k].first + c];
            double sum[3] = {0, 0, 0}, area = 0;
            for (int e = 0; e < 3; e++)   /* the corner is the polygon's own vertex */
                BN_ASSERT_LE(fabs(row[ix + e] - q[e]), 1e-3);
            if (on_patch_edge(p, np, pv, row + ix, f[k].material, f[k].normal, cos30))
                continue;   /* a T-junction: the edge's value (no_cracks_at_t_junctions) */
            for (size_t j = 0; j < np; j++) {
                int at = 0;
                for (unsigned e = 0; e < p[j].ncorners; e++) {
                    const double *a = pv + 3 * p[j].corner[e];
                    if (fabs(a[0] - q[0]) < 1e-3 && fabs(a[1] - q[1]) < 1e-3 && fabs(a[2] - q[2]) < 1e-3)
                        at = 1;
                }
                if (!at || p[j].material != f[k].material ||
                    p[j].normal[0] * f[k].normal[0] + p[j].normal[1] * f[k].normal[1] + p[j].normal[2] * f[k].normal[2] <
                        cos30)
                    continue;
                area += p[j].area;
                for (int e = 0; e < 3; e++)
                    sum[e] += p[j].area * x[3 * j + e];
            }
            BN_ASSERT_GT(area, 0);
            for (int e = 0; e < 3; e++)
                BN_ASSERT_REL(row[ir + e], sum[e] / area, TOL_COLOUR);
        }
    }
    free(d.v);
    free(d.fn);
    free(d.fi);
    /* OBJ: one f line per polygon */
    BN_ASSERT_STATUS(bn_bake_write(b, bn_test_tmp("in.obj"), &layer, 1, &wo, &err), BN_OK);
    char *obj = bn_test_read_file(bn_test_tmp("in.obj"), NULL);
    size_t nfl = 0;
    for (char *l = obj; l && *l; l = strchr(l, '\n') ? strchr(l, '\n') + 1 : l + strlen(l))
        nfl += strncmp(l, "f ", 2) == 0;
    BN_ASSERT_EQ(nfl, nf);
    free(obj);
    free(x);
    bn_bake_destroy(b);
    bn_scene_destroy(s);
}

/* Two coplanar faces side by side meshed at one patch size but of different lengths along their
 * common edge (3 patches against 2): the vertices of each lie inside the other's patch edges. Smooth
 * values interpolated on either side of the common edge must agree (no crack), and a field that is
 * linear over the plane is reproduced exactly wherever the vertex values are exact (away from the
 * T-junctions too). Across a crease nothing is constrained. */
BN_TEST(no_cracks_at_t_junctions)
{
    const double v[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0,          /* face A: [0,1] x [0,1] */
                        1, 0, 0, 1.2, 0, 0, 1.2, 0.8, 0, 1, 0.8, 0}; /* face B: [1,1.2] x [0,0.8] */
    const unsigned polys[] = {4, 0, 1, 2, 3, 4, 4, 5, 6, 7};
    const unsigned pm[] = {0, 0};
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_scene *s = NULL;
    bn_bake *b;
    size_t np, nt;
    const bn_patch *P;
    double *x, *vv, worst = 0;
    int checked = 0;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    if (bn_scene_from_arrays("tj", v, 8, polys, 2, pm, &white, 1, &lo, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.patch_size = 0.4;   /* A: 3 x 3 patches (edges of 1/3), B: 1 x 2 (edges of 0.4) */
    mo.no_contacts = 1;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    P = bn_scene_patches(s, &np);
    BN_ASSERT_STATUS(bn_bake_create(s, 30, &b, &err), BN_OK);
    nt = bn_bake_tjunction_count(b);
    fprintf(stderr, "%zu patches, %zu T-junctions\n", np, nt);
    BN_ASSERT_EQ(nt, 4);   /* A's y = 1/3, 2/3 on B's edge; B's y = 0.4 and its corner y = 0.8 on A's */
    x = calloc(3 * np, sizeof *x);
    vv = calloc(3 * bn_bake_vertex_count(b), sizeof *vv);
    BN_ASSERT(x && vv);
    for (size_t i = 0; i < np; i++)   /* a patch-constant field with steps: only continuity can hold */
        for (int c = 0; c < 3; c++)
            x[3 * i + c] = 1 + P[i].centroid[0] * (2 + c) + 3 * P[i].centroid[1] * P[i].centroid[1] + (double)(i % 3);
    bn_bake_vertex_values(b, x, vv);
    for (int k = 1; k < 80; k++) {   /* along the common edge x = 1, y in (0, 0.8): A's side against B's */
        double y = 0.8 * k / 80, pt[3] = {1, y, 0}, va[3] = {0}, vb[3] = {0};
        int fa = 0, fb = 0;
        for (size_t i = 0; i < np; i++) {
            double xmin = 1e9, xmax = -1e9, ymin = 1e9, ymax = -1e9;
            const double *pv = bn_scene_patch_vertices(s, NULL);
            for (unsigned c = 0; c < P[i].ncorners; c++) {
                const double *q = pv + 3 * P[i].corner[c];
                xmin = fmin(xmin, q[0]);
                xmax = fmax(xmax, q[0]);
                ymin = fmin(ymin, q[1]);
                ymax = fmax(ymax, q[1]);
            }
            if (y < ymin || y > ymax || 1 < xmin - 1e-12 || 1 > xmax + 1e-12)
                continue;
            if (P[i].face == 0 && !fa) {
                bn_bake_interpolate(b, vv, i, pt, va);
                fa = 1;
            } else if (P[i].face == 1 && !fb) {
                bn_bake_interpolate(b, vv, i, pt, vb);
                fb = 1;
            }
        }
        BN_ASSERT(fa && fb);
        for (int c = 0; c < 3; c++)
            worst = fmax(worst, fabs(va[c] - vb[c]));
        checked++;
    }
    fprintf(stderr, "%d points on the common edge: largest jump across it %.3g\n", checked, worst);
    BN_ASSERT_LT(worst, 1e-12);
    free(x);
    free(vv);
    bn_bake_destroy(b);
    /* a flat bake has no shared vertices and so no T-junctions */
    BN_ASSERT_STATUS(bn_bake_create(s, BN_BAKE_FLAT, &b, &err), BN_OK);
    BN_ASSERT_EQ(bn_bake_tjunction_count(b), 0);
    bn_bake_destroy(b);
    bn_scene_destroy(s);
}
