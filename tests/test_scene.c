/* Scene loading, validation and patch meshing: against the published Cornell geometry, the
 * McGuire file as shipped, a corpus of malformed files, and meshing invariants. */
#include "bn_test.h"
#include "bounce/scene.h"

#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static bn_scene *load(const char *rel, bn_unit unit)
{
    bn_load_opts o;
    bn_error err;
    bn_scene *s = NULL;
    bn_load_opts_default(&o);
    o.unit = unit;
    o.log.quiet = 1;
    o.log.fn = NULL;
    if (bn_scene_load(bn_test_path(rel), &o, &s, &err) != BN_OK)
        BN_FAIL("loading %s: %s", rel, err.msg);
    return s;
}

/* ---- the malformed corpus: each file its own message, a non-zero exit, no crash ---- */
BN_TEST(corpus_errors)
{
    char *table = bn_test_read_file(bn_test_path("tests/corpus/EXPECTED.txt"), NULL);
    char *line, *save = NULL, *msgs[64];
    int n = 0;
    BN_ASSERT(table != NULL);
    for (line = strtok_r(table, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
        char file[256], expect[512], args[1024], *out = NULL;
        int code, rc;
        if (line[0] == '#')
            continue;
        if (sscanf(line, "%255[^\t]\t%d\t%511[^\n]", file, &code, expect) != 3)
            BN_FAIL("bad EXPECTED line: %s", line);
        snprintf(args, sizeof args, "info '%s/tests/corpus/%s'", bn_test_source_dir(), file);
        rc = bn_test_bounce(args, &out);
        if (rc != code)
            BN_FAIL("%s: exit %d, expected %d; output:\n%s", file, rc, code, out);
        if (!strstr(out, expect))
            BN_FAIL("%s: message does not contain '%s'; output:\n%s", file, expect, out);
        {
            char *err_line = strstr(out, "error: ");
            BN_ASSERT(err_line != NULL);
            for (int k = 0; k < n; k++)
                if (strncmp(msgs[k], err_line, strcspn(err_line, "\n")) == 0)
                    BN_FAIL("%s: same message as an earlier file: %s", file, err_line);
            if (n < 64)
                msgs[n++] = strdup(err_line);
        }
        free(out);
    }
    BN_ASSERT_GE(n, 20);
    for (int k = 0; k < n; k++)
        free(msgs[k]);
    free(table);
}

/* ---- the published Cornell box ---- */
static double tri_area(const double *a, const double *b, const double *c)
{
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double x = e1[1] * e2[2] - e1[2] * e2[1], y = e1[2] * e2[0] - e1[0] * e2[2], z = e1[0] * e2[1] - e1[1] * e2[0];
    return 0.5 * sqrt(x * x + y * y + z * z);
}

BN_TEST(cornell_published_areas)
{
    /* Areas computed here from the published table (shared/data/cornell-box.md), not by bounce. */
    static const double floor_[4][3] = {{552.8, 0, 0}, {0, 0, 0}, {0, 0, 559.2}, {549.6, 0, 559.2}};
    static const double back[4][3] = {{549.6, 0, 559.2}, {0, 0, 559.2}, {0, 548.8, 559.2}, {556, 548.8, 559.2}};
    static const double red[4][3] = {{552.8, 0, 0}, {549.6, 0, 559.2}, {556, 548.8, 559.2}, {556, 548.8, 0}};
    static const double short_top[4][3] = {{130, 165, 65}, {82, 165, 225}, {240, 165, 272}, {290, 165, 114}};
    static const double tall_side[4][3] = {{423, 0, 247}, {423, 330, 247}, {472, 330, 406}, {472, 0, 406}};
    bn_scene *s = load("meshes/cornell-box.obj", BN_UNIT_MM);
    size_t nf, nm;
    const bn_face *f = bn_scene_faces(s, &nf);
    const bn_material *m = bn_scene_materials(s, &nm);
    double quad = 0, ceiling = 0, red_sum = 0, white_total = 0, light = 0;
    int red_tris = 0;
    bn_scene_stats st = bn_scene_stats_get(s);
    BN_ASSERT_EQ(nf, 20);           /* 19 polygons, the red wall split in two */
    BN_ASSERT_EQ(st.nonplanar_split, 1);
    for (size_t i = 0; i < nf; i++) {
        const char *mn = m[f[i].material].name;
        if (strcmp(mn, "red") == 0) {
            red_sum += f[i].area;
            red_tris++;
            BN_ASSERT_EQ(f[i].nverts, 3);
        }
        if (strcmp(mn, "light") == 0)
            light += f[i].area;
        if (strcmp(mn, "white") == 0)
            white_total += f[i].area;
        if (strcmp(mn, "white") == 0 && f[i].normal[1] < -0.5)
            ceiling += f[i].area;
    }
    quad = tri_area(floor_[0], floor_[1], floor_[2]) + tri_area(floor_[0], floor_[2], floor_[3]);
    BN_ASSERT_REL(f[0].area, quad, 1e-9);
    BN_ASSERT_REL(f[6].area, tri_area(back[0], back[1], back[2]) + tri_area(back[0], back[2], back[3]), 1e-9);
    BN_ASSERT_REL(f[7].area, 548.8 * 559.2, 1e-9);   /* green wall: a rectangle */
    BN_ASSERT_REL(light, 130.0 * 105.0, 1e-9);
    BN_ASSERT_REL(ceiling, 556.0 * 559.2 - 130.0 * 105.0, 1e-9);
    /* Red wall: the two triangles bounce makes, split along the 1st-3rd vertex diagonal. */
    BN_ASSERT_EQ(red_tris, 2);
    BN_ASSERT_REL(red_sum, tri_area(red[0], red[1], red[2]) + tri_area(red[0], red[2], red[3]), 1e-9);
    BN_ASSERT_REL(f[10].area, tri_area(short_top[0], short_top[1], short_top[2]) +
                                  tri_area(short_top[0], short_top[2], short_top[3]), 1e-9);
    BN_ASSERT_REL(f[16].area, tri_area(tall_side[0], tall_side[1], tall_side[2]) +
                                  tri_area(tall_side[0], tall_side[2], tall_side[3]), 1e-9);
    /* Front sides face into the box: floor up, ceiling and light down, green wall +x. */
    BN_ASSERT_NEAR(f[0].normal[1], 1.0, 1e-12);
    BN_ASSERT_NEAR(f[1].normal[1], -1.0, 1e-12);
    BN_ASSERT_NEAR(f[7].normal[0], 1.0, 1e-12);
    BN_ASSERT_EQ(bn_scene_emitter_count(s), 1);
    {
        double w[3];
        bn_scene_emitted_power(s, w);   /* pi * A * Le with A in m^2 */
        BN_ASSERT_REL(w[0], M_PI * 0.13 * 0.105 * 17.0, 1e-12);
    }
    (void)white_total;
    bn_scene_destroy(s);
}

BN_TEST(mcguire_loads_as_shipped)
{
    bn_load_opts o;
    bn_error err;
    bn_scene *s = NULL;
    size_t nf, nm, emitters = 0;
    const bn_face *f;
    const bn_material *m;
    char path[4096];
    snprintf(path, sizeof path, "%s/../shared/data/external/mcguire-cornell/CornellBox-Original.obj",
             bn_test_source_dir());
    bn_load_opts_default(&o);
    o.log.quiet = 1;
    if (!bn_test_file_exists(path))   /* shared/ sits beside the clone in CI; elsewhere it may not */
        BN_SKIP("reference file not found beside the clone: %s", path);
    BN_ASSERT_STATUS(bn_scene_load(path, &o, &s, &err), BN_OK);
    f = bn_scene_faces(s, &nf);
    m = bn_scene_materials(s, &nm);
    for (size_t i = 0; i < nf; i++) {
        const bn_material *mt = &m[f[i].material];
        if (mt->Le[0] > 0 || mt->Le[1] > 0 || mt->Le[2] > 0) {
            emitters++;
            BN_ASSERT_EQ(mt->Le[0], 17);
            BN_ASSERT_EQ(mt->Le[1], 12);
            BN_ASSERT_EQ(mt->Le[2], 4);
            BN_ASSERT_EQ(mt->rho[0], 0.78);   /* an emitter that also reflects */
        }
    }
    BN_ASSERT_EQ(emitters, 1);
    BN_ASSERT_EQ(bn_scene_stats_get(s).duplicates_dropped, 2);   /* faces 8/10 and 15/16 of the file */
    BN_ASSERT_EQ(bn_scene_stats_get(s).input_polygons, 18);
    bn_scene_destroy(s);
    {
        char *out = NULL, args[4200];
        snprintf(args, sizeof args, "info '%s'", path);
        BN_ASSERT_EQ(bn_test_bounce(args, &out), 0);
        BN_ASSERT(strstr(out, "emitters    1 face") != NULL);
        BN_ASSERT(strstr(out, "duplicates the face") != NULL);
        free(out);
    }
}

/* ---- meshing invariants ---- */
typedef struct edge {
    size_t a, b;
    int count;
} edge;

static int cmp_edge(const void *x, const void *y)
{
    const edge *e = x, *f = y;
    if (e->a != f->a)
        return e->a < f->a ? -1 : 1;
    return e->b < f->b ? -1 : (e->b > f->b);
}

static double dist_point_segment(const double *p, const double *a, const double *b)
{
    double ab[3], ap[3], t, q[3], d = 0;
    for (int k = 0; k < 3; k++) {
        ab[k] = b[k] - a[k];
        ap[k] = p[k] - a[k];
    }
    t = (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / (ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]);
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    for (int k = 0; k < 3; k++) {
        q[k] = a[k] + t * ab[k] - p[k];
        d += q[k] * q[k];
    }
    return sqrt(d);
}

/* size: the longest patch edge allowed (0: no bound) */
static void check_mesh(bn_scene *s, double size)
{
    size_t nf, np, npv;
    const bn_face *f = bn_scene_faces(s, &nf);
    const bn_patch *p = bn_scene_patches(s, &np);
    const double *pv = bn_scene_patch_vertices(s, &npv);
    const double *v = bn_scene_vertices(s, NULL);
    const size_t *fi = bn_scene_face_indices(s, NULL);
    double *sum = calloc(nf, sizeof *sum);
    edge *edges = malloc(4 * np * sizeof *edges);
    size_t ne = 0;
    BN_ASSERT(np > 0);
    for (size_t i = 0; i < np; i++) {
        double cr[3], e1[3], e2[3];
        const double *a = pv + 3 * p[i].corner[0], *b = pv + 3 * p[i].corner[1], *c = pv + 3 * p[i].corner[2];
        BN_ASSERT(p[i].face < nf);
        BN_ASSERT_EQ(p[i].material, f[p[i].face].material);
        sum[p[i].face] += p[i].area;
        for (int k = 0; k < 3; k++) {
            BN_ASSERT_EQ(p[i].normal[k], f[p[i].face].normal[k]);
            e1[k] = b[k] - a[k];
            e2[k] = c[k] - a[k];
        }
        cr[0] = e1[1] * e2[2] - e1[2] * e2[1];
        cr[1] = e1[2] * e2[0] - e1[0] * e2[2];
        cr[2] = e1[0] * e2[1] - e1[1] * e2[0];
        /* corners counter-clockwise seen from the front */
        BN_ASSERT_GT(cr[0] * p[i].normal[0] + cr[1] * p[i].normal[1] + cr[2] * p[i].normal[2], 0);
        for (unsigned k = 0; k < p[i].ncorners; k++) {
            size_t u = p[i].corner[k], w = p[i].corner[(k + 1) % p[i].ncorners];
            double len = 0;
            for (int q = 0; q < 3; q++)
                len += (pv[3 * u + q] - pv[3 * w + q]) * (pv[3 * u + q] - pv[3 * w + q]);
            if (size > 0)
                BN_ASSERT_LE(sqrt(len), size * (1 + 1e-9));
            edges[ne].a = u < w ? u : w;
            edges[ne].b = u < w ? w : u;
            edges[ne].count = 1;
            ne++;
        }
    }
    for (size_t i = 0; i < nf; i++)
        BN_ASSERT_REL(sum[i], f[i].area, 1e-12);   /* patch areas sum to the face's */
    /* No T-junctions: an edge used once lies on its face's boundary; others are used twice. */
    qsort(edges, ne, sizeof *edges, cmp_edge);
    for (size_t i = 0; i < ne;) {
        size_t j = i + 1;
        while (j < ne && edges[j].a == edges[i].a && edges[j].b == edges[i].b)
            j++;
        BN_ASSERT_LE(j - i, 2);
        if (j - i == 1) {
            /* find the face of this edge's patch vertex: both endpoints on one face boundary edge */
            const double *a = pv + 3 * edges[i].a, *b = pv + 3 * edges[i].b;
            int on = 0;
            for (size_t fc = 0; fc < nf && !on; fc++)
                for (unsigned k = 0; k < f[fc].nverts && !on; k++) {
                    const double *x = v + 3 * fi[f[fc].first + k], *y = v + 3 * fi[f[fc].first + (k + 1) % f[fc].nverts];
                    double scale = sqrt((x[0] - y[0]) * (x[0] - y[0]) + (x[1] - y[1]) * (x[1] - y[1]) + (x[2] - y[2]) * (x[2] - y[2]));
                    on = dist_point_segment(a, x, y) <= 1e-9 * scale && dist_point_segment(b, x, y) <= 1e-9 * scale;
                }
            if (!on)
                BN_FAIL("edge %zu-%zu is used by one patch but is not on a face boundary (a T-junction)",
                        edges[i].a, edges[i].b);
        }
        i = j;
    }
    free(sum);
    free(edges);
}

/* The Cornell box has contacts (the blocks on the floor): with them cut, edges near the contact
 * may stretch by BN_CONTACT_STRETCH; without, the grid's edges are at most the size. */
BN_TEST(mesh_invariants_cornell)
{
    bn_scene *s = load("meshes/cornell-box.obj", BN_UNIT_MM);
    bn_mesh_opts mo;
    bn_error err;
    double sizes[] = {1000.0, 100.0, 37.0, 12.5};
    for (int nc = 0; nc < 2; nc++)
        for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
            bn_mesh_opts_default(&mo);
            mo.patch_size = sizes[k];
            mo.no_contacts = nc;
            BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
            BN_ASSERT_EQ(bn_scene_stats_get(s).contact_faces, nc ? 0 : 1);
            check_mesh(s, sizes[k] * (nc ? 1 : BN_CONTACT_STRETCH));
        }
    bn_mesh_opts_default(&mo);
    mo.no_subdivide = 1;
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    {
        size_t np, nf;
        bn_scene_patches(s, &np);
        bn_scene_faces(s, &nf);
        BN_ASSERT_EQ(np, nf);
    }
    check_mesh(s, 0);
    bn_scene_destroy(s);
}

BN_TEST(mesh_target_count)
{
    bn_scene *s = load("meshes/cornell-box.obj", BN_UNIT_MM);
    size_t targets[] = {50, 400, 1200, 5000};
    for (size_t k = 0; k < 4; k++) {
        bn_mesh_opts mo;
        bn_error err;
        size_t np;
        bn_mesh_opts_default(&mo);
        mo.target_patches = targets[k];
        BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
        const bn_patch *p = bn_scene_patches(s, &np);
        size_t nf, single = 0, *per;
        bn_scene_faces(s, &nf);
        BN_ASSERT((per = calloc(nf, sizeof *per)) != NULL);
        for (size_t i = 0; i < np; i++)
            per[p[i].face]++;
        for (size_t f = 0; f < nf; f++)
            single += per[f] == 1;
        free(per);
        /* the target governs the faces it splits; a face smaller than the patch stays whole */
        BN_ASSERT_LE(np - single, targets[k]);
        BN_ASSERT_GE(np, targets[k] * 0.6);
        check_mesh(s, bn_scene_patch_size(s) * BN_CONTACT_STRETCH);
    }
    bn_scene_destroy(s);
}

/* The largest patch edge is what it says, whatever the mesher was asked: one patch per face (a
 * target below the face count, or no subdivision) gives the longest edge of an input face, found
 * here from the faces' own vertices; a fine mesh gives at most the size asked and at least half. */
BN_TEST(largest_patch_edge_is_measured)
{
    bn_scene *s = load("meshes/cornell-box.obj", BN_UNIT_MM);
    size_t nf, nfi, nv;
    const bn_face *faces = bn_scene_faces(s, &nf);
    const size_t *fi = bn_scene_face_indices(s, &nfi);
    const double *v = bn_scene_vertices(s, &nv);
    double longest = 0, lo[3], hi[3];
    bn_mesh_opts mo;
    bn_error err;
    for (size_t f = 0; f < nf; f++)
        for (unsigned k = 0; k < faces[f].nverts; k++) {
            const double *a = v + 3 * fi[faces[f].first + k], *b = v + 3 * fi[faces[f].first + (k + 1) % faces[f].nverts];
            longest = fmax(longest, sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                                         (a[2] - b[2]) * (a[2] - b[2])));
        }
    bn_scene_bounds(s, lo, hi);
    BN_ASSERT_LT(longest, sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                               (hi[2] - lo[2]) * (hi[2] - lo[2])));
    for (int q = 0; q < 2; q++) {
        bn_mesh_opts_default(&mo);
        mo.target_patches = q ? 0 : 5;
        mo.no_subdivide = q;
        BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
        BN_ASSERT_REL(bn_scene_largest_patch_edge(s), longest, 1e-12);
    }
    bn_mesh_opts_default(&mo);
    mo.patch_size = 50;
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    BN_ASSERT_LE(bn_scene_largest_patch_edge(s), 50 * BN_CONTACT_STRETCH + 1e-9);
    BN_ASSERT_GE(bn_scene_largest_patch_edge(s), 25);
    mo.no_contacts = 1;
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    BN_ASSERT_LE(bn_scene_largest_patch_edge(s), 50 + 1e-9);
    bn_scene_destroy(s);
}

BN_TEST(mesh_triangles_uniform)
{
    /* One triangle with edges 3, 4, 5: n = ceil(5 / 1) = 5 divisions, 25 congruent patches. */
    double v[] = {0, 0, 0, 4, 0, 0, 0, 3, 0};
    unsigned polys[] = {3, 0, 1, 2}, pm[] = {0};
    bn_material m = {"m", {0.5, 0.5, 0.5}, {1, 1, 1}};
    bn_scene *s;
    bn_error err;
    bn_mesh_opts mo;
    size_t np;
    const bn_patch *p;
    BN_ASSERT_STATUS(bn_scene_from_arrays("tri", v, 3, polys, 1, pm, &m, 1, NULL, &s, &err), BN_OK);
    bn_mesh_opts_default(&mo);
    mo.patch_size = 1.0;
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    p = bn_scene_patches(s, &np);
    BN_ASSERT_EQ(np, 25);
    for (size_t i = 0; i < np; i++)
        BN_ASSERT_REL(p[i].area, 6.0 / 25.0, 1e-12);
    check_mesh(s, 1.0);
    bn_scene_destroy(s);
}

BN_TEST(polygons_triangulated)
{
    /* A planar L-shaped hexagon (non-convex, area 3) and a dart quad (non-convex, area 1). */
    double v[] = {0, 0, 0, 2, 0, 0, 2, 1, 0, 1, 1, 0, 1, 2, 0, 0, 2, 0,
                  10, 0, 0, 12, 0, 0, 11, 0.5, 0, 11, 2, 0};
    unsigned polys[] = {6, 0, 1, 2, 3, 4, 5, 4, 6, 7, 8, 9}, pm[] = {0, 0};
    bn_material m = {"m", {0.5, 0.5, 0.5}, {0, 0, 0}};
    bn_scene *s;
    bn_error err;
    bn_load_opts o;
    size_t nf;
    const bn_face *f;
    double a1 = 0, a2 = 0;
    bn_load_opts_default(&o);
    o.log.quiet = 1;
    o.log.fn = NULL;
    BN_ASSERT_STATUS(bn_scene_from_arrays("poly", v, 10, polys, 2, pm, &m, 1, &o, &s, &err), BN_OK);
    f = bn_scene_faces(s, &nf);
    BN_ASSERT_EQ(nf, 4 + 2);
    for (size_t i = 0; i < nf; i++) {
        BN_ASSERT_EQ(f[i].nverts, 3);
        BN_ASSERT_NEAR(f[i].normal[2], 1.0, 1e-12);
        if (f[i].source == 0)
            a1 += f[i].area;
        else
            a2 += f[i].area;
    }
    BN_ASSERT_REL(a1, 3.0, 1e-12);
    BN_ASSERT_REL(a2, 1.25, 1e-12);   /* dart: shoelace (0 + 6 + 16.5 - 20) / 2 */
    BN_ASSERT_EQ(bn_scene_stats_get(s).polygons_triangulated, 2);
    bn_scene_destroy(s);
}

BN_TEST(duplicates_and_back_to_back)
{
    /* Face 0, an exact duplicate (dropped), the same square reversed (kept: a two-sided panel). */
    double v[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    unsigned polys[] = {4, 0, 1, 2, 3, 4, 1, 2, 3, 0, 4, 3, 2, 1, 0}, pm[] = {0, 0, 0};
    bn_material m = {"m", {0.5, 0.5, 0.5}, {1, 1, 1}};
    bn_scene *s;
    bn_error err;
    bn_load_opts o;
    size_t nf;
    bn_load_opts_default(&o);
    o.log.quiet = 1;
    BN_ASSERT_STATUS(bn_scene_from_arrays("dup", v, 4, polys, 3, pm, &m, 1, &o, &s, &err), BN_OK);
    bn_scene_faces(s, &nf);
    BN_ASSERT_EQ(nf, 2);
    BN_ASSERT_EQ(bn_scene_stats_get(s).duplicates_dropped, 1);
    BN_ASSERT_EQ(bn_scene_stats_get(s).back_to_back, 1);
    bn_scene_destroy(s);
}

BN_TEST(array_validation)
{
    double v[] = {0, 0, 0, 1, 0, 0, 0, 1, 0}, vnan[] = {0, 0, 0, NAN, 0, 0, 0, 1, 0};
    unsigned polys[] = {3, 0, 1, 2}, bad[] = {3, 0, 1, 7}, pm[] = {0};
    bn_material ok = {"ok", {0.5, 0.5, 0.5}, {1, 1, 1}}, hi = {"hi", {0.5, 1.5, 0.5}, {0, 0, 0}},
                neg = {"neg", {0.5, 0.5, 0.5}, {0, -1, 0}};
    bn_scene *s;
    bn_error err;
    BN_ASSERT_STATUS(bn_scene_from_arrays("t", v, 3, polys, 1, pm, &hi, 1, NULL, &s, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "'hi'") && strstr(err.msg, "1.5"));
    BN_ASSERT_STATUS(bn_scene_from_arrays("t", v, 3, polys, 1, pm, &neg, 1, NULL, &s, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "'neg'"));
    BN_ASSERT_STATUS(bn_scene_from_arrays("t", vnan, 3, polys, 1, pm, &ok, 1, NULL, &s, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "vertex 1"));
    BN_ASSERT_STATUS(bn_scene_from_arrays("t", v, 3, bad, 1, pm, &ok, 1, NULL, &s, &err), BN_EINPUT);
    BN_ASSERT(strstr(err.msg, "index 7"));
    BN_ASSERT_STATUS(bn_scene_from_arrays("t", v, 3, polys, 0, pm, &ok, 1, NULL, &s, &err), BN_EINPUT);
}

BN_TEST(cli_exit_codes)
{
    char *out = NULL;
    BN_ASSERT_EQ(bn_test_bounce("--version", &out), 0);
    BN_ASSERT(strstr(out, "bounce ") != NULL);
    free(out);
    BN_ASSERT_EQ(bn_test_bounce("--help", &out), 0);
    BN_ASSERT(strstr(out, "Exit codes") != NULL);
    free(out);
    BN_ASSERT_EQ(bn_test_bounce("", &out), 2);
    free(out);
    BN_ASSERT_EQ(bn_test_bounce("nosuchcommand", &out), 2);
    free(out);
    BN_ASSERT_EQ(bn_test_bounce("info --help", &out), 0);
    BN_ASSERT(strstr(out, "--patch-size") && strstr(out, "--threads") && strstr(out, "--seed") &&
              strstr(out, "Exit codes"));
    free(out);
    BN_ASSERT_EQ(bn_test_bounce("solve --version", &out), 0);
    BN_ASSERT(strstr(out, "bounce ") != NULL);
    free(out);
    BN_ASSERT_EQ(bn_test_bounce("info --no-such-option x.obj", &out), 2);
    BN_ASSERT(strstr(out, "unknown option '--no-such-option'"));
    free(out);
    BN_ASSERT_EQ(bn_test_bounce("info", &out), 2);
    free(out);
    {
        char args[4200];
        snprintf(args, sizeof args, "info '%s' --patch-size -3", bn_test_path("meshes/cornell-box.obj"));
        BN_ASSERT_EQ(bn_test_bounce(args, &out), 2);
        BN_ASSERT(strstr(out, "--patch-size") != NULL);
        free(out);
        snprintf(args, sizeof args, "info '%s' --unit furlong", bn_test_path("meshes/cornell-box.obj"));
        BN_ASSERT_EQ(bn_test_bounce(args, &out), 2);
        free(out);
        snprintf(args, sizeof args, "info '%s' --unit mm --patches 300 -q", bn_test_path("meshes/cornell-box.obj"));
        BN_ASSERT_EQ(bn_test_bounce(args, &out), 0);
        BN_ASSERT(strstr(out, "emitters    1 face") && strstr(out, "dense K"));
        free(out);
    }
}

BN_TEST(units_scale_power)
{
    bn_scene *m = load("meshes/parallel-plates.obj", BN_UNIT_M), *mm = load("meshes/parallel-plates.obj", BN_UNIT_MM);
    double wm[3], wmm[3];
    bn_scene_emitted_power(m, wm);
    bn_scene_emitted_power(mm, wmm);
    BN_ASSERT_REL(wm[0], M_PI, 1e-15);         /* 1 m^2 emitting Le = 1 */
    BN_ASSERT_REL(wmm[0], M_PI * 1e-6, 1e-12);  /* the same numbers read as millimetres */
    bn_scene_destroy(m);
    bn_scene_destroy(mm);
}

/* -q leaves warnings only, and the Cornell box's 3 mm bend (0.001 of its wall) is a note, not a
 * warning: a quiet run on the default scene prints nothing. A quad bent by 4% of its size still
 * warns, quiet or not. */
BN_TEST(quiet_cornell_prints_nothing_and_large_bends_warn)
{
    char args[1024], *out = NULL;
    const char *exe = bn_test_bounce_exe();
    FILE *fp;
    /* stderr alone (stdout's summary names the split too) */
    snprintf(args, sizeof args, "'%s' info '%s' --unit mm -q 2>&1 >/dev/null | cat", exe,
             bn_test_path("meshes/cornell-box.obj"));
    BN_ASSERT_EQ(bn_test_run(args, &out), 0);
    if (out && out[0])
        BN_FAIL("quiet run printed: %s", out);
    free(out);
    snprintf(args, sizeof args, "'%s' info '%s' --unit mm 2>&1 >/dev/null | cat", exe,
             bn_test_path("meshes/cornell-box.obj"));
    BN_ASSERT_EQ(bn_test_run(args, &out), 0);
    BN_ASSERT(strstr(out, "non-planar") && !strstr(out, "warning"));   /* said as a note */
    free(out);
    fp = fopen(bn_test_tmp("bent.obj"), "w");
    fprintf(fp, "v 0 0 0\nv 1 0 0\nv 1 1 0.2\nv 0 1 0\nv 0 0 -1\nf 1 2 3 4\nf 1 4 5\n");
    fclose(fp);
    snprintf(args, sizeof args, "'%s' info '%s' -q 2>&1 >/dev/null | cat", exe, bn_test_tmp("bent.obj"));
    BN_ASSERT_EQ(bn_test_run(args, &out), 0);
    BN_ASSERT(strstr(out, "warning:") && strstr(out, "bent.obj:6: quad is non-planar"));
    BN_ASSERT(strstr(out, "[nonplanar]\n") && strstr(out, "[no-emitter]\n"));   /* each with its code */
    free(out);
}

typedef struct heard {
    int count[BN_WARNING_COUNT], notes;
    double value[BN_WARNING_COUNT];
} heard;

static void hear(void *user, const bn_message *m)
{
    heard *h = user;
    if (m->level != BN_LOG_WARN) {
        h->notes += m->code == BN_W_NONE;
        return;
    }
    BN_ASSERT((unsigned)m->code < BN_WARNING_COUNT && m->code != BN_W_NONE);
    h->count[m->code]++;
    h->value[m->code] = m->value;
}

/* A sink gets each warning's code and measure, not only its text: a unit quad with one corner
 * lifted 0.2 (each vertex 0.2 / 4 = 0.05 off the mean plane, over a size of about 1.43: 0.035), no
 * emitter, no material, a duplicate face (dropped) and a degenerate one. */
BN_TEST(warnings_carry_codes_and_measures)
{
    bn_load_opts lo;
    bn_scene *s = NULL;
    bn_error err;
    heard h;
    FILE *fp = fopen(bn_test_tmp("coded.obj"), "w");
    fprintf(fp, "v 0 0 0\nv 1 0 0\nv 1 1 0.2\nv 0 1 0\nv 0 0 -1\nv 2 0 0\n"
                "f 1 2 3 4\nf 1 4 5\nf 1 4 5\nf 1 2 6\n");
    fclose(fp);
    memset(&h, 0, sizeof h);
    bn_load_opts_default(&lo);
    lo.log = (bn_log){hear, &h, 0};
    bn_error_clear(&err);
    BN_ASSERT_EQ(bn_scene_load(bn_test_tmp("coded.obj"), &lo, &s, &err), BN_OK);
    BN_ASSERT_EQ(h.count[BN_W_NONPLANAR], 1);
    BN_ASSERT_NEAR(h.value[BN_W_NONPLANAR], 0.05 / sqrt(2.04), 2e-3);
    BN_ASSERT_EQ(h.count[BN_W_MATERIAL], 1);
    BN_ASSERT_EQ(h.count[BN_W_NO_EMITTER], 1);
    BN_ASSERT_EQ(h.count[BN_W_FACE_DROPPED], 2);   /* the duplicate, then the degenerate count */
    BN_ASSERT(strcmp(bn_warning_name(BN_W_FACE_DROPPED), "face-dropped") == 0);
    BN_ASSERT(strcmp(bn_warning_name(BN_WARNING_COUNT), "?") == 0);
    bn_scene_destroy(s);
}

/* A plain binary OFF ("OFF BINARY", int32 counts, float positions, int32 faces) reads through
 * OpenMesh after bounce has walked its layout: a 2 x 3 quad and a triangle of base 2 and height 1,
 * areas 6 and 1. */
BN_TEST(binary_off_reads)
{
    const char *path = bn_test_tmp("quad.off");
    FILE *fp = fopen(path, "wb");
    int32_t cnt[3] = {5, 2, 0}, quad[5] = {4, 0, 1, 2, 3}, tri[4] = {3, 0, 4, 1};
    float v[15] = {0, 0, 0, 2, 0, 0, 2, 3, 0, 0, 3, 0, 1, -1, 0};
    BN_ASSERT(fp);
    fputs("OFF BINARY\n", fp);
    fwrite(cnt, sizeof cnt, 1, fp);
    fwrite(v, sizeof v, 1, fp);
    fwrite(quad, sizeof quad, 1, fp);
    fwrite(tri, sizeof tri, 1, fp);
    BN_ASSERT(fclose(fp) == 0);
    bn_load_opts lo;
    bn_scene *s;
    bn_error err;
    size_t nf;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    BN_ASSERT_STATUS(bn_scene_load(path, &lo, &s, &err), BN_OK);
    const bn_face *f = bn_scene_faces(s, &nf);
    BN_ASSERT_EQ(nf, 2);
    double total = 0;
    for (size_t i = 0; i < nf; i++)
        total += f[i].area;
    BN_ASSERT_NEAR(total, 7.0, 1e-12);
    bn_scene_destroy(s);
}

/* Orientation from vertex normals: a closed unit room of 6 quads whose vn all point into the room,
 * two of them (the floor and the right wall) wound by hand the other way (facing out). By default
 * the two are turned (every face's front towards the room's centre: the room as meant), counted
 * and their worst line reported; with BN_ORIENT_WINDING they are kept facing out. */
BN_TEST(orientation_from_vertex_normals)
{
    /* every quad wound to face into the room (checked by hand with the right-hand rule), except the
     * floor (y = 0) and the wall x = 1, wound the other way; the vn point into the room */
    static const char *quads[6] = {"1 2 3 4", "5 8 7 6", "2 6 5 1", "4 3 7 8", "1 4 8 5", "3 7 6 2"};
    static const double vn[6][3] = {{0, 0, 1}, {0, 0, -1}, {0, 1, 0}, {0, -1, 0}, {1, 0, 0}, {-1, 0, 0}};
    FILE *f = fopen(bn_test_tmp("room-vn.obj"), "w");
    BN_ASSERT(f != NULL);
    fprintf(f, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n");
    for (int k = 0; k < 6; k++)
        fprintf(f, "vn %g %g %g\n", vn[k][0], vn[k][1], vn[k][2]);
    for (int k = 0; k < 6; k++) {
        int c[4];
        BN_ASSERT_EQ(sscanf(quads[k], "%d %d %d %d", &c[0], &c[1], &c[2], &c[3]), 4);
        fprintf(f, "f %d//%d %d//%d %d//%d %d//%d\n", c[0], k + 1, c[1], k + 1, c[2], k + 1, c[3], k + 1);
    }
    fclose(f);
    for (int keep = 0; keep < 2; keep++) {
        bn_load_opts o;
        bn_scene *s = NULL;
        bn_error err;
        size_t nf, inward = 0;
        const bn_face *fc;
        bn_scene_stats st;
        bn_load_opts_default(&o);
        o.orient = keep ? BN_ORIENT_WINDING : BN_ORIENT_NORMALS;
        o.log.quiet = 1;
        BN_ASSERT_STATUS(bn_scene_load(bn_test_tmp("room-vn.obj"), &o, &s, &err), BN_OK);
        fc = bn_scene_faces(s, &nf);
        st = bn_scene_stats_get(s);
        for (size_t i = 0; i < nf; i++) {
            const double *v = bn_scene_vertices(s, NULL) + 3 * bn_scene_face_indices(s, NULL)[fc[i].first];
            double to_c[3] = {0.5 - v[0], 0.5 - v[1], 0.5 - v[2]};
            inward += fc[i].normal[0] * to_c[0] + fc[i].normal[1] * to_c[1] + fc[i].normal[2] * to_c[2] > 0;
        }
        fprintf(stderr, "%s: %zu faces, %zu with normals, %zu against them, %zu turned, %zu facing the room\n",
                keep ? "winding" : "normals", nf, st.with_normals, st.winding_disagree, st.flipped, inward);
        BN_ASSERT_EQ(nf, 6);
        BN_ASSERT_EQ(st.with_normals, 6);
        BN_ASSERT_EQ(st.winding_disagree, 2);
        BN_ASSERT_EQ(st.flipped, keep ? 0 : 2);
        BN_ASSERT_EQ(inward, keep ? 4 : 6);
        bn_scene_destroy(s);
    }
}
