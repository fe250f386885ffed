/* The bake mesh refined where light changes (bn_bake_refine): against geometry (no vertex inside
 * another triangle's edge, each patch's area kept, every triangle facing as its patch), against a
 * field given in closed form (every edge across its step ends up short; the budget holds; each vertex
 * holds the value of its own point), and on the Cornell box against the gather itself at 0.25 mm steps
 * across a block's shadow edge (the "50% crossing within 2 mm"). */
#include "bn_test.h"

#include "bounce/bake.h"
#include "bounce/gather.h"
#include "bounce/pipeline.h"

#define STEP_X 300.0   /* the closed-form field steps here (mm) */

/* A field in closed form: L = 1 + x/1000 + 9 [x < STEP_X] (one layer, the key). */
static double field(const double *x) { return 1 + x[0] / 1000 + 9 * (x[0] < STEP_X); }

static bn_status eval_field(void *user, const double *x, const size_t *patch, size_t n, size_t first, double *out,
                            bn_error *err)
{
    size_t *calls = user;
    (*calls)++;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++)
            out[3 * i + c] = field(x + 3 * i);
    return BN_OK;
}

static double tri_area(const double *A, const double *B, const double *C, double n[3])
{
    double e1[3], e2[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = B[k] - A[k];
        e2[k] = C[k] - A[k];
    }
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    return 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

/* Vertices strictly inside some triangle's edge (more than tol from both ends, within tol of the line). */
static size_t hanging_vertices(const bn_bake *b, double tol)
{
    size_t nf = bn_bake_face_count(b), nv = bn_bake_vertex_count(b), bad = 0;
    const double *pos = bn_bake_vertex_positions(b);
    for (size_t f = 0; f < nf; f++) {
        size_t v[4], patch;
        unsigned n = bn_bake_face(b, f, v, &patch);
        for (unsigned e = 0; e < n; e++) {
            const double *A = pos + 3 * v[e], *B = pos + 3 * v[(e + 1) % n];
            double ab[3] = {B[0] - A[0], B[1] - A[1], B[2] - A[2]}, len2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
            for (size_t q = 0; q < nv; q++) {
                const double *P = pos + 3 * q;
                double ap[3] = {P[0] - A[0], P[1] - A[1], P[2] - A[2]}, t, d2 = 0;
                t = (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / len2;
                if (!(t * sqrt(len2) > tol && (1 - t) * sqrt(len2) > tol))
                    continue;
                for (int k = 0; k < 3; k++)
                    d2 += (ap[k] - t * ab[k]) * (ap[k] - t * ab[k]);
                bad += d2 <= tol * tol;
            }
        }
    }
    return bad;
}

BN_TEST(refined_mesh_is_conforming_and_follows_a_step)
{
    bn_scene *s = bn_test_load_meshed("meshes/cornell-box.obj", BN_UNIT_M, 400);   /* the file's numbers (mm) */
    bn_bake *b;
    bn_error err;
    bn_bake_refine_opts ro;
    double *val, area_err = 0, min_edge = 4, longest_across = 0;
    size_t np, calls = 0, nv0, flipped = 0;
    const bn_patch *pa = bn_scene_patches(s, &np);
    BN_ASSERT_STATUS(bn_bake_create(s, BN_BAKE_DEFAULT_CREASE, &b, &err), BN_OK);
    nv0 = bn_bake_vertex_count(b);
    fprintf(stderr, "%zu patches, %zu vertices, %zu T-junctions before\n", np, nv0, bn_bake_tjunction_count(b));
    BN_ASSERT(bn_bake_tjunction_count(b) > 0);   /* the test means something: the patches have T-junctions */
    bn_bake_refine_opts_default(&ro);
    ro.max_vertices = 100000;
    ro.min_edge = min_edge;
    ro.eval = eval_field;
    ro.user = &calls;
    BN_ASSERT_STATUS(bn_bake_refine(b, &ro, &val, &err), BN_OK);
    size_t nv = bn_bake_vertex_count(b), nf = bn_bake_face_count(b);
    const double *pos = bn_bake_vertex_positions(b);
    double *parea = calloc(np, sizeof *parea);
    BN_ASSERT(parea);
    fprintf(stderr, "refined: %zu vertices, %zu triangles, %zu evaluations\n", nv, nf, calls);
    BN_ASSERT_EQ(hanging_vertices(b, 1e-6), 0);
    for (size_t f = 0; f < nf; f++) {
        size_t v[4], p;
        double n[3];
        BN_ASSERT_EQ(bn_bake_face(b, f, v, &p), 3);
        parea[p] += tri_area(pos + 3 * v[0], pos + 3 * v[1], pos + 3 * v[2], n);
        flipped += n[0] * pa[p].normal[0] + n[1] * pa[p].normal[1] + n[2] * pa[p].normal[2] <= 0;
        for (int e = 0; e < 3; e++) {   /* an edge across the step (its ends' values too: each is
                                            evaluated 1% inside, which may be the step's other side): short */
            const double *A = pos + 3 * v[e], *B = pos + 3 * v[(e + 1) % 3];
            if ((A[0] < STEP_X) != (B[0] < STEP_X) && fabs(val[3 * v[e]] - val[3 * v[(e + 1) % 3]]) > 1)
                longest_across = fmax(longest_across, sqrt((A[0] - B[0]) * (A[0] - B[0]) + (A[1] - B[1]) * (A[1] - B[1]) +
                                                           (A[2] - B[2]) * (A[2] - B[2])));
        }
    }
    for (size_t p = 0; p < np; p++)
        area_err = fmax(area_err, fabs(parea[p] - pa[p].area) / pa[p].area);
    for (size_t v = 0; v < nv; v++)   /* each vertex holds its own point's value (1% inside: the ramp moves <1e-3) */
        if (fabs(pos[3 * v] - STEP_X) > 10)
            BN_ASSERT_NEAR(val[3 * v], field(pos + 3 * v), 2e-3);
    fprintf(stderr, "patch areas within %.2g, %zu triangles flipped, longest edge across the step %.3g mm\n", area_err,
            flipped, longest_across);
    BN_ASSERT_LT(area_err, 1e-9);
    BN_ASSERT_EQ(flipped, 0);
    BN_ASSERT_LE(longest_across, min_edge);
    BN_ASSERT_LT(nv, ro.max_vertices);
    free(val);
    free(parea);
    bn_bake_destroy(b);
    /* a budget: the vertices stay within it */
    BN_ASSERT_STATUS(bn_bake_create(s, BN_BAKE_DEFAULT_CREASE, &b, &err), BN_OK);
    ro.max_vertices = nv0 + 400;
    BN_ASSERT_STATUS(bn_bake_refine(b, &ro, &val, &err), BN_OK);
    fprintf(stderr, "budget %zu: %zu vertices\n", ro.max_vertices, bn_bake_vertex_count(b));
    BN_ASSERT_LE(bn_bake_vertex_count(b), ro.max_vertices);
    BN_ASSERT_GT(bn_bake_vertex_count(b), nv0 + 100);
    BN_ASSERT_EQ(hanging_vertices(b, 1e-6), 0);
    free(val);
    bn_bake_destroy(b);
    bn_scene_destroy(s);
}

/* The Cornell box solved (3 bounces kept), its ray scene kept for the gather. */
static void cornell_solved(bn_pipeline *p)
{
    bn_pipeline_opts o;
    bn_error err;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.ff.quiet = 1;
    o.ff.exact_visibility = 0;
    o.solve.quiet = 1;
    o.solve.bounces = 3;
    o.keep_rt = 1;
    if (bn_pipeline_run(bn_test_path("meshes/cornell-box.obj"), &o, p, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
}

typedef struct gather_ctx {
    const bn_pipeline *p;
    int light;
} gather_ctx;

static bn_status eval_gather(void *user, const double *x, const size_t *patch, size_t n, size_t first, double *out,
                             bn_error *err)
{
    const gather_ctx *g = user;
    bn_gather_opts go;
    bn_gather_opts_default(&go);
    go.light_samples = g->light;
    go.hemi_samples = 256;
    go.seed = 7 + first;
    go.quiet = 1;
    return bn_gather_points(g->p->rt, (const double *const *)g->p->res.terms, g->p->res.nterms - 1, g->p->rest, x,
                            patch, n, &go, out, NULL, err);
}

/* The bake's KE (layer 1 of E, KE, ...) at floor point (x, 0, z): the floor triangle holding it. */
static double bake_ke_at(const bn_bake *b, const double *val, double x, double z)
{
    const double *pos = bn_bake_vertex_positions(b);
    size_t nf = bn_bake_face_count(b), nv = bn_bake_vertex_count(b);
    for (size_t f = 0; f < nf; f++) {
        size_t v[4], p;
        bn_bake_face(b, f, v, &p);
        const double *A = pos + 3 * v[0], *B = pos + 3 * v[1], *C = pos + 3 * v[2];
        if (fabs(A[1]) + fabs(B[1]) + fabs(C[1]) > 1e-9)
            continue;
        double d = (B[0] - A[0]) * (C[2] - A[2]) - (C[0] - A[0]) * (B[2] - A[2]);
        double w1 = ((x - A[0]) * (C[2] - A[2]) - (C[0] - A[0]) * (z - A[2])) / d;
        double w2 = ((B[0] - A[0]) * (z - A[2]) - (x - A[0]) * (B[2] - A[2])) / d;
        if (w1 < -1e-12 || w2 < -1e-12 || w1 + w2 > 1 + 1e-12)
            continue;
        const double *k = val + 3 * nv;   /* layer 1: KE */
        return 0.2126 * ((1 - w1 - w2) * k[3 * v[0]] + w1 * k[3 * v[1]] + w2 * k[3 * v[2]]) +
               0.7152 * ((1 - w1 - w2) * k[3 * v[0] + 1] + w1 * k[3 * v[1] + 1] + w2 * k[3 * v[2] + 1]) +
               0.0722 * ((1 - w1 - w2) * k[3 * v[0] + 2] + w1 * k[3 * v[1] + 2] + w2 * k[3 * v[2] + 2]);
    }
    BN_FAIL("no floor triangle holds (%g, 0, %g)", x, z);
    return 0;
}

/* Floor patch q (convex, y = 0) holds (x, z). */
static int floor_patch_holds(const bn_scene *s, size_t q, double x, double z)
{
    const bn_patch *pa = &bn_scene_patches(s, NULL)[q];
    const double *pv = bn_scene_patch_vertices(s, NULL);
    int pos = 0, neg = 0;
    for (unsigned c = 0; c < pa->ncorners; c++) {
        const double *A = pv + 3 * pa->corner[c], *B = pv + 3 * pa->corner[(c + 1) % pa->ncorners];
        double cr = (B[0] - A[0]) * (z - A[2]) - (B[2] - A[2]) * (x - A[0]);
        pos |= cr > 1e-9;
        neg |= cr < -1e-9;
    }
    return !(pos && neg);
}

/* Where a profile first crosses `level` (linear between samples at x0 + i h). */
static double crossing(const double *y, size_t n, double x0, double h, double level)
{
    for (size_t i = 0; i + 1 < n; i++)
        if ((y[i] - level) * (y[i + 1] - level) <= 0 && y[i] != y[i + 1])
            return x0 + h * ((double)i + (level - y[i]) / (y[i + 1] - y[i]));
    return NAN;
}

/* Across the shadow the short block's vertical edge at (290, 114) casts on the floor, along z = 70 from
 * x = 255 (umbra) to 345 (lit): the gather at 0.25 mm steps (64 x 64 light strata) against the bake's
 * KE interpolated on its refined mesh (200k-vertex budget) and, for comparison, on the patches' vertices. */
BN_TEST(shadow_edge_crossing_within_2mm) /* BN_SLOW */
{
    enum { N = 361 };
    const double x0 = 255, h = 0.25, z = 70;
    bn_pipeline p;
    bn_error err;
    bn_bake_refine_opts ro;
    double *pts = calloc(3 * N, sizeof *pts), *ref = NULL, yref[N], ybake[N], ycoarse[N];
    size_t *patch = calloc(N, sizeof *patch), np;
    BN_ASSERT(pts && patch);
    cornell_solved(&p);
    const bn_patch *pa = bn_scene_patches(p.scene, &np);
    int nl = p.res.nterms + 2;
    gather_ctx g = {&p, 4096};
    for (size_t i = 0; i < N; i++) {   /* the floor's patch under each point */
        pts[3 * i] = x0 + h * (double)i;
        pts[3 * i + 2] = z;
        patch[i] = SIZE_MAX;
        for (size_t q = 0; q < np && patch[i] == SIZE_MAX; q++)
            if (pa[q].normal[1] > 0.99 && fabs(pa[q].centroid[1]) < 1e-6 && floor_patch_holds(p.scene, q, pts[3 * i], z))
                patch[i] = q;
        BN_ASSERT(patch[i] != SIZE_MAX);
    }
    ref = malloc((size_t)nl * N * 3 * sizeof *ref);
    BN_ASSERT(ref);
    BN_ASSERT_STATUS(eval_gather(&g, pts, patch, N, 0, ref, &err), BN_OK);
    for (size_t i = 0; i < N; i++)
        yref[i] = 0.2126 * ref[(N + i) * 3] + 0.7152 * ref[(N + i) * 3 + 1] + 0.0722 * ref[(N + i) * 3 + 2];
    double level = 0.5 * (yref[0] + yref[N - 1]), cref = crossing(yref, N, x0, h, level);
    for (int refined = 0; refined < 2; refined++) {
        bn_bake *b;
        double *val, *y = refined ? ybake : ycoarse;
        gather_ctx gb = {&p, BN_BAKE_GATHER_LIGHT};
        BN_ASSERT_STATUS(bn_bake_create(p.scene, BN_BAKE_DEFAULT_CREASE, &b, &err), BN_OK);
        bn_bake_exclude_enclosed(b, p.rt);
        bn_bake_refine_opts_default(&ro);
        ro.max_vertices = refined ? 200000 : 0;
        ro.nlayers = (size_t)nl;
        ro.key = (size_t)nl - 1;
        ro.eval = eval_gather;
        ro.user = &gb;
        BN_ASSERT_STATUS(bn_bake_refine(b, &ro, &val, &err), BN_OK);
        if (!refined) {   /* the patches as faces: their quads cut as the refinement cuts them, for bake_ke_at */
            bn_bake_destroy(b);
            free(val);
            BN_ASSERT_STATUS(bn_bake_create(p.scene, BN_BAKE_DEFAULT_CREASE, &b, &err), BN_OK);
            bn_bake_exclude_enclosed(b, p.rt);
            ro.max_vertices = 1;   /* triangles and T-junctions split, no refinement round */
            BN_ASSERT_STATUS(bn_bake_refine(b, &ro, &val, &err), BN_OK);
        }
        for (size_t i = 0; i < N; i++)
            y[i] = bake_ke_at(b, val, x0 + h * (double)i, z);
        fprintf(stderr, "%s: %zu vertices, KE crossing %.2f mm from the gather's\n", refined ? "refined" : "patches",
                bn_bake_vertex_count(b), crossing(y, N, x0, h, level) - cref);
        if (refined)
            BN_ASSERT_LT(fabs(crossing(y, N, x0, h, level) - cref), 2.0);
        free(val);
        bn_bake_destroy(b);
    }
    fprintf(stderr, "KE %.4g (umbra side) to %.4g (lit), 50%% at x = %.2f mm\n", yref[0], yref[N - 1], cref);
    BN_ASSERT(yref[0] < 0.3 * yref[N - 1]);   /* the line does cross the shadow's edge */
    free(ref);
    free(pts);
    free(patch);
    bn_pipeline_free(&p);
}

/* The CLI: a budget as 1k is 1,000 and holds; values it cannot be refused by name; the refinement's
 * options where there is no refinement refused. */
BN_TEST(cli_budget_and_bad_values)
{
    char cmd[1024], *out = NULL;
    const char *glb = bn_test_tmp("budget.glb");
    unsigned long nv = 0;
    snprintf(cmd, sizeof cmd, "bake %s --unit mm --patches 300 --ff-visibility rays --bake-vertices 1k -o %s",
             bn_test_path("meshes/cornell-box.obj"), glb);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    const char *w = strstr(out, "refined where L changes: ");
    BN_ASSERT(w && sscanf(w, "refined where L changes: %lu vertices", &nv) == 1);
    fprintf(stderr, "--bake-vertices 1k: %lu vertices\n", nv);
    BN_ASSERT_LE(nv, 1000);
    BN_ASSERT_GT(nv, 300);
    free(out);
    static const char *bad[][2] = {{"--bake-vertices 0.0005k", "'0.0005k' is not a whole number"},
                                   {"--bake-vertices 2G", "'2G' is not a finite number"},
                                   {"--bake-vertices -1k", "-1k is outside"},
                                   {"--bake-tol 0", "0 is outside"},
                                   {"--gather none --bake-vertices 5k", "not with --flat, --gather none or --mesh input"}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        out = NULL;
        snprintf(cmd, sizeof cmd, "bake %s --unit mm %s -o %s", bn_test_path("meshes/cornell-box.obj"), bad[i][0], glb);
        BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 2);
        fprintf(stderr, "%s: %s", bad[i][0], out);
        BN_ASSERT(strstr(out, bad[i][1]) != NULL);
        free(out);
    }
}

/* A contact cut a hair from an object's corner (tests/data/table-leg.obj, a table leg standing on the living
 * room's floor: the floor's cut point 3e-8 m from the leg's own corner, two points 4 eps apart): the closure
 * ends, in a mesh of the size the patches and the budget say (it once split the two triangles holding both
 * points for ever, into all of the machine's memory). */
BN_TEST(closure_ends_where_a_contact_point_nearly_meets_a_corner)
{
    char cmd[1024], *out = NULL;
    unsigned long nv = 0, nf = 0, np = 0;
    snprintf(cmd, sizeof cmd, "bake %s --unit m --patch-size 0.3 --transport hierarchical -o %s",
             bn_test_path("tests/data/table-leg.obj"), bn_test_tmp("leg.glb"));
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    const char *w = strstr(out, "refined where L changes: ");
    BN_ASSERT(w && sscanf(w, "refined where L changes: %lu vertices, %lu faces in %lu patches", &nv, &nf, &np) == 3);
    fprintf(stderr, "%lu vertices, %lu triangles for %lu patches\n", nv, nf, np);
    BN_ASSERT_GT(np, 500);
    BN_ASSERT_LT(nf, 4 * np);
    free(out);
}
