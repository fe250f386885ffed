/* The path tracer against exact answers: the furnace box (K^k E = rho^k Le per patch and per
 * bounce), its own variance estimate over independent seeds, strategies and thread counts. */
#include "bn_test.h"
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/trace.h"

#include <math.h>


#include "base/vec.h"   /* BN_PI */

/* Tolerances and their reasons, in one place. */
#define FURNACE_RHO 0.5                 /* K^k E = 0.5^k, L = 2, rest after n = 3 is 0.125 */
#define FURNACE_LE 1.0
#define FURNACE_PATCHES 150             /* 5 x 5 per face: small patches, corners included */
#define FURNACE_SPP 128                 /* t bound with 127 dof; each run takes well under a second */
#define ALPHA 0.01                      /* family-wise false-failure rate of every statistical test */
#define SUM_RTOL 1e-12                  /* sum of bins vs L: the same doubles summed in another order */

/* A closed unit cube seen from inside (meshes/furnace-box.obj), one material. */
static bn_scene *furnace(double rho, double le, size_t patches)
{
    static const double v[] = {1, 0, 0, 0, 0, 0, 0, 0, 1, 1, 0, 1,   /* floor */
                               1, 1, 0, 1, 1, 1, 0, 1, 1, 0, 1, 0,   /* ceiling */
                               0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 1, 1,   /* x = 0 */
                               1, 0, 0, 1, 0, 1, 1, 1, 1, 1, 1, 0,   /* x = 1 */
                               0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0,   /* z = 0 */
                               1, 0, 1, 0, 0, 1, 0, 1, 1, 1, 1, 1};  /* z = 1 */
    unsigned polys[30], mat[6] = {0, 0, 0, 0, 0, 0};
    bn_material m = {"furnace", {rho, rho, rho}, {le, le, le}};
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_scene *s = NULL;
    bn_error err;
    for (unsigned f = 0; f < 6; f++) {
        polys[5 * f] = 4;
        for (unsigned k = 0; k < 4; k++)
            polys[5 * f + 1 + k] = 4 * f + k;
    }
    bn_load_opts_default(&lo);
    if (bn_scene_from_arrays("furnace", v, 24, polys, 6, mat, &m, 1, &lo, &s, &err) != BN_OK)
        BN_FAIL("furnace: %s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.target_patches = patches;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("mesh: %s", err.msg);
    return s;
}

static bn_rt *make_rt(const bn_scene *s)
{
    bn_rt *rt = NULL;
    bn_error err;
    if (bn_rt_create(s, 1, &rt, &err) != BN_OK)
        BN_FAIL("rt: %s", err.msg);
    return rt;
}

static void run_patches(const bn_rt *rt, const bn_trace_opts *o, bn_trace_patches *r)
{
    bn_error err;
    if (bn_trace_patches_run(rt, o, r, &err) != BN_OK)
        BN_FAIL("trace: %s", err.msg);
}

/* Exact furnace layers: K^k E = rho^k Le, rest = sum_{k > n} rho^k Le, L = Le / (1 - rho). */
static double furnace_exact(int layer, int bounces, double rho, double le)
{
    if (layer <= bounces)
        return pow(rho, layer) * le;
    if (layer == bounces + 1)
        return pow(rho, bounces + 1) * le / (1 - rho);
    return le / (1 - rho);
}

/* Every patch, layer and channel within a Sidak-corrected t bound of the exact value, and the
 * per-layer powers within a Sidak-corrected normal bound; through bn_crosscheck_compare with the
 * exact answer standing in for radiosity (no discretisation tolerance). */
static void furnace_check(bn_trace_strategy strategy)
{
    bn_scene *s = furnace(FURNACE_RHO, FURNACE_LE, FURNACE_PATCHES);
    bn_rt *rt = make_rt(s);
    bn_trace_opts o;
    bn_trace_patches r;
    bn_crosscheck_input in;
    bn_crosscheck_result cr;
    bn_error err;
    double *exact;
    size_t n;
    bn_trace_opts_default(&o);
    o.spp = FURNACE_SPP;
    o.bounces = 3;
    o.strategy = strategy;
    o.quiet = 1;
    run_patches(rt, &o, &r);
    n = r.n;
    BN_ASSERT_EQ(r.nlayers, 6);
    exact = malloc((size_t)r.nlayers * n * 3 * sizeof(double));
    for (int l = 0; l < r.nlayers; l++)
        for (size_t i = 0; i < n * 3; i++)
            exact[(size_t)l * n * 3 + i] = furnace_exact(l, o.bounces, FURNACE_RHO, FURNACE_LE);
    /* The E layer is the patch's own emission, exactly, with no variance. */
    for (size_t i = 0; i < n * 3; i++) {
        BN_ASSERT_EQ(r.mean[i], FURNACE_LE);
        BN_ASSERT_EQ(r.se[i], 0);
    }
    /* The bins sum to L in every patch. */
    for (size_t i = 0; i < n * 3; i++) {
        double sum = 0;
        for (int l = 0; l < r.nlayers - 1; l++)
            sum += r.mean[(size_t)l * n * 3 + i];
        BN_ASSERT_REL(sum, r.mean[(size_t)(r.nlayers - 1) * n * 3 + i], SUM_RTOL);
    }
    bn_crosscheck_input_default(&in);
    in.scene = s;
    in.trace = &r;
    in.rad = exact;
    in.alpha = ALPHA;
    in.worst = 5;
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("compare: %s", err.msg);
    if (!cr.pass)
        bn_crosscheck_print(&in, &cr, stderr);
    fprintf(stderr, "%s: %zu tests, worst |z| %.3f (bound %.3f), power worst %.3f (bound %.3f), %.3g rays in %.2f s\n",
            bn_trace_strategy_name(strategy), cr.family, cr.worst_z, cr.crit, cr.power_worst_z, cr.power_crit,
            (double)r.rays, r.seconds);
    BN_ASSERT_EQ(cr.within, cr.family);
    BN_ASSERT_LE(cr.power_worst_z, cr.power_crit);
    /* Powers: pi * 6 m^2 * rho^k Le. */
    for (int l = 0; l <= o.bounces; l++)
        BN_ASSERT_NEAR(cr.power_rad[3 * l], BN_PI * 6 * pow(FURNACE_RHO, l) * FURNACE_LE, 1e-9);
    /* The test must have teeth: the K2E estimates are far from the KE value. */
    {
        double zmin = INFINITY;
        for (size_t i = 0; i < n * 3; i++) {
            size_t k = 2 * n * 3 + i;
            zmin = fmin(zmin, fabs(r.mean[k] - furnace_exact(1, 3, FURNACE_RHO, FURNACE_LE)) / r.se[k]);
        }
        BN_ASSERT_GT(zmin, cr.crit);
    }
    bn_crosscheck_result_free(&cr);
    free(exact);
    bn_trace_patches_free(&r);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* NEE alone is not tested on the furnace: next to a shared edge its weight cos cos / d^2 has an
 * infinite second moment, so a z-test would be meaningless there. The plates below test it. */
BN_TEST(furnace_mis) { furnace_check(BN_TRACE_MIS); }
BN_TEST(furnace_bsdf_only) { furnace_check(BN_TRACE_BSDF); }

/* Configuration factor between directly opposed rectangles a x b at distance c (Howell C-11). */
static double F_parallel(double a, double b, double c)
{
    double X = a / c, Y = b / c, x1 = sqrt(1 + X * X), y1 = sqrt(1 + Y * Y);
    return 2 / (BN_PI * X * Y) *
           (log(x1 * y1 / sqrt(1 + X * X + Y * Y)) + X * y1 * atan(X / y1) + Y * x1 * atan(Y / x1) - X * atan(X) -
            Y * atan(Y));
}

/* Two opposed unit squares one apart (meshes/parallel-plates.obj): the receiver's KE is
 * rho Le F = 0.5 * 0.19982, its K2E is 0, for each of the three strategies. */
BN_TEST(plates_all_strategies)
{
    bn_scene *s = NULL;
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_rt *rt;
    size_t np;
    double exact = 0.5 * 1.0 * F_parallel(1, 1, 1);
    /* 3 strategies x 3 channels, Sidak at ALPHA, normal bound (1e5 samples). */
    double crit = bn_normal_quantile_upper(-expm1(log1p(-ALPHA) / 9.0) / 2);
    bn_load_opts_default(&lo);
    if (bn_scene_load(bn_test_path("meshes/parallel-plates.obj"), &lo, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.no_subdivide = 1;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    rt = make_rt(s);
    bn_scene_patches(s, &np);
    BN_ASSERT_EQ(np, 2);
    BN_ASSERT_NEAR(F_parallel(1, 1, 1), 0.19982, 5e-6);
    for (int st = BN_TRACE_MIS; st <= BN_TRACE_NEE; st++) {
        bn_trace_opts o;
        bn_trace_patches r;
        size_t recv;
        bn_trace_opts_default(&o);
        o.spp = 100000;   /* 2 patches: BSDF sampling alone needs this for 1% */
        o.bounces = 2;
        o.strategy = (bn_trace_strategy)st;
        o.quiet = 1;
        run_patches(rt, &o, &r);
        /* The receiver is the patch without emission. */
        recv = r.mean[0] > 0 ? 1 : 0;
        for (int c = 0; c < 3; c++) {
            double m = r.mean[(1 * np + recv) * 3 + c], se = r.se[(1 * np + recv) * 3 + c];
            fprintf(stderr, "%s: KE = %.6f +- %.6f, exact %.6f, z %.2f (bound %.2f)\n",
                    bn_trace_strategy_name(o.strategy), m, se, exact, (m - exact) / se, crit);
            BN_ASSERT_LE(fabs(m - exact) / se, crit);
            BN_ASSERT_LT(se, 0.01 * exact);   /* and the test resolves 1% */
            BN_ASSERT_EQ(r.mean[(2 * np + recv) * 3 + c], 0);   /* nothing reflects it back */
        }
        bn_trace_patches_free(&r);
    }
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* A floor and a wall, unit squares meeting at a right angle, one patch each; the wall emits 1
 * and both reflect 0.9. With F = bn_test_F_perpendicular(1, 1, 1) = 0.20004 both ways, the patch-constant
 * transport radiosity solves gives KE(floor) = 0.9 F, K2E(wall) = 0.81 F^2, K3E(floor) =
 * 0.729 F^3 exactly. The patch model must estimate those (Sidak over 3 layers, normal bound at
 * 2^18 samples, resolving 2%); light transport itself (the continuous model) has the same KE but a K2E above
 * 0.81 F^2, the floor's light being brightest by the edge the wall sees best: the gap the patch
 * model removes from the cross-check (constant elements at a concave corner): measured 35%,
 * asserted as 7 standard errors at least. */
BN_TEST(patch_model_is_the_patch_constant_transport)
{
    static const double v[] = {0, 0, 0, 0, 0, 1, 1, 0, 1, 1, 0, 0,    /* floor y = 0, normal +y */
                               0, 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1};   /* wall x = 0, normal +x */
    unsigned polys[10] = {4, 0, 1, 2, 3, 4, 4, 5, 6, 7}, mat[2] = {0, 1};
    bn_material m[2] = {{"floor", {0.9, 0.9, 0.9}, {0, 0, 0}}, {"wall", {0.9, 0.9, 0.9}, {1, 1, 1}}};
    double F = bn_test_F_perpendicular(1, 1, 1), exact[4] = {0, 0.9 * F, 0.81 * F * F, 0.729 * F * F * F};
    double crit = bn_normal_quantile_upper(-expm1(log1p(-ALPHA) / 3.0) / 2);
    bn_trace_patches r[2];
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_scene *s = NULL;
    bn_error err;
    bn_rt *rt;
    size_t np;
    bn_load_opts_default(&lo);
    if (bn_scene_from_arrays("corner", v, 8, polys, 2, mat, m, 2, &lo, &s, &err) != BN_OK)
        BN_FAIL("corner: %s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.no_subdivide = 1;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("mesh: %s", err.msg);
    bn_scene_patches(s, &np);
    BN_ASSERT_EQ(np, 2);
    BN_ASSERT_NEAR(F, 0.20004, 5e-6);
    rt = make_rt(s);
    for (int model = BN_TRACE_CONTINUOUS; model <= BN_TRACE_PATCH; model++) {
        bn_trace_opts o;
        bn_trace_opts_default(&o);
        o.spp = 1 << 18;
        o.quiet = 1;
        o.model = (bn_trace_model)model;
        run_patches(rt, &o, &r[model]);
    }
    for (int l = 1; l <= 3; l++) {
        size_t i = l == 2 ? 1 : 0, k = (l * np + i) * 3;   /* floor for KE and K3E, wall for K2E */
        double pm = r[BN_TRACE_PATCH].mean[k], pse = r[BN_TRACE_PATCH].se[k];
        double cm = r[BN_TRACE_CONTINUOUS].mean[k], cse = r[BN_TRACE_CONTINUOUS].se[k];
        fprintf(stderr, "K^%dE: exact (patch-constant) %.6f, patch model %.6f +- %.1e (z %.2f), continuous %.6f +- %.1e\n",
                l, exact[l], pm, pse, (pm - exact[l]) / pse, cm, cse);
        BN_ASSERT_LE(fabs(pm - exact[l]) / pse, crit);
        BN_ASSERT_LT(pse, 0.02 * exact[l]);
        if (l == 1)
            BN_ASSERT_LE(fabs(cm - exact[l]) / cse, crit);   /* the emitter is one patch: no restart yet */
        if (l == 2)
            BN_ASSERT_GT(cm - exact[l], 7 * hypot(cse, pse));
    }
    bn_trace_patches_free(&r[0]);
    bn_trace_patches_free(&r[1]);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* The reported standard error against the spread over independent seeds: for each patch, layer
 * and channel the variance of the S means about their average, pooled, over the average reported
 * se^2. The ratio is 1 in expectation; with P*(S-1) pooled degrees of freedom its sd is about
 * sqrt(2 / (P (S - 1))) for near-normal means; the bound is 4 sd (two-sided, below 1e-4 false
 * failures). An se off by sqrt(2) either way gives a ratio of 2 or 0.5 and fails. */
BN_TEST(variance_matches_spread)
{
    enum { SEEDS = 32 };
    bn_scene *s = furnace(0.7, 1.0, 24);   /* one patch per face x 4 */
    bn_rt *rt = make_rt(s);
    bn_trace_opts o;
    bn_trace_patches r[SEEDS];
    size_t n, m;
    bn_trace_opts_default(&o);
    o.spp = 64;
    o.bounces = 2;
    o.quiet = 1;
    for (int k = 0; k < SEEDS; k++) {
        o.seed = 1000 + (uint64_t)k;
        run_patches(rt, &o, &r[k]);
    }
    n = r[0].n;
    m = (size_t)r[0].nlayers * n * 3;
    for (int l = 1; l < r[0].nlayers; l++) {   /* E has no variance */
        double ss = 0, se2 = 0, ratio, bound;
        size_t P = 0;
        /* Channel R only: the material is grey, so the other channels repeat it exactly. */
        for (size_t i = (size_t)l * n * 3; i < (size_t)(l + 1) * n * 3; i += 3) {
            double mean = 0, v = 0;
            for (int k = 0; k < SEEDS; k++)
                mean += r[k].mean[i] / SEEDS;
            for (int k = 0; k < SEEDS; k++) {
                v += (r[k].mean[i] - mean) * (r[k].mean[i] - mean);
                se2 += r[k].se[i] * r[k].se[i] / SEEDS;
            }
            ss += v / (SEEDS - 1);
            P++;
        }
        ratio = ss / se2;
        bound = 4 * sqrt(2.0 / ((double)P * (SEEDS - 1)));
        fprintf(stderr, "layer %d: spread^2 / se^2 = %.4f (bound 1 +- %.3f over %zu estimates)\n", l, ratio, bound, P);
        BN_ASSERT_NEAR(ratio, 1.0, bound);
    }
    (void)m;
    for (int k = 0; k < SEEDS; k++)
        bn_trace_patches_free(&r[k]);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* Streams are keyed by (seed, patch, sample): 1 and 2 threads give bit-identical estimates. */
BN_TEST(thread_count_invariance)
{
    bn_scene *s = furnace(0.6, 1.0, 96);
    bn_rt *rt = make_rt(s);
    bn_trace_opts o;
    bn_trace_patches a, b;
    size_t m;
    bn_trace_opts_default(&o);
    o.spp = 16;
    o.quiet = 1;
    o.threads = 1;
    run_patches(rt, &o, &a);
    o.threads = 2;
    run_patches(rt, &o, &b);
    m = (size_t)a.nlayers * a.n * 3;
    BN_ASSERT(memcmp(a.mean, b.mean, m * sizeof(double)) == 0);
    BN_ASSERT(memcmp(a.se, b.se, m * sizeof(double)) == 0);
    BN_ASSERT_EQ(a.rays, b.rays);
    bn_trace_patches_free(&a);
    bn_trace_patches_free(&b);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* Quantiles used for the bounds, against published values. */
BN_TEST(quantiles)
{
    BN_ASSERT_NEAR(bn_normal_quantile_upper(0.025), 1.959963984540054, 1e-9);
    BN_ASSERT_NEAR(bn_normal_quantile_upper(0.005), 2.575829303548901, 1e-9);
    BN_ASSERT_NEAR(bn_normal_quantile_upper(1e-7), 5.199337582192817, 1e-8);
    BN_ASSERT_NEAR(bn_student_t_quantile_upper(0.025, 10), 2.228138851986274, 1e-9);
    BN_ASSERT_NEAR(bn_student_t_quantile_upper(0.005, 1), 63.65674116287399, 1e-7);
    BN_ASSERT_NEAR(bn_student_t_quantile_upper(0.05, 127), 1.656940, 1e-6);
}

/* Layer names follow `bounce bounces`: E, KE, K2E, ..., rest, L (never K1E). */
BN_TEST(layer_names)
{
    char b[16];
    BN_ASSERT(strcmp(bn_layer_name(0, 3, b, sizeof b), "E") == 0);
    BN_ASSERT(strcmp(bn_layer_name(1, 3, b, sizeof b), "KE") == 0);
    BN_ASSERT(strcmp(bn_layer_name(3, 3, b, sizeof b), "K3E") == 0);
    BN_ASSERT(strcmp(bn_layer_name(4, 3, b, sizeof b), "rest") == 0);
    BN_ASSERT(strcmp(bn_layer_name(5, 3, b, sizeof b), "L") == 0);
    BN_ASSERT(strcmp(bn_layer_name(1, 0, b, sizeof b), "rest") == 0);
}

/* The Cornell box at path (its light one quad or cut into triangles): the tracer's image means and
 * their standard errors of KE and K2E at 48 x 48. */
static void cornell_traced(const char *path, double mean[2][3], double se[2][3])
{
    bn_load_opts lo;
    bn_scene *s = NULL;
    bn_rt *rt;
    bn_error err;
    bn_camera cam;
    bn_trace_opts to;
    bn_trace_image ti;
    const size_t npix = 48 * 48;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    lo.unit = BN_UNIT_MM;
    BN_ASSERT_STATUS(bn_scene_load(path, &lo, &s, &err), BN_OK);
    BN_ASSERT_STATUS(bn_scene_mesh(s, NULL, &err), BN_OK);
    rt = make_rt(s);
    bn_camera_default(s, &cam);
    BN_ASSERT_STATUS(bn_camera_load_sidecar(bn_test_path("meshes/cornell-box.obj"), &cam, NULL, &err), BN_OK);
    cam.width = cam.height = 48;
    cam.spp = 1;
    bn_trace_opts_default(&to);
    to.spp = 256;
    to.bounces = 2;
    to.quiet = 1;
    BN_ASSERT_STATUS(bn_trace_image_run(rt, &cam, &to, &ti, &err), BN_OK);
    for (int l = 0; l < 2; l++)
        for (int c = 0; c < 3; c++) {
            double m = 0, v = 0;
            for (size_t k = 0; k < npix; k++) {
                m += ti.mean[((size_t)(l + 1) * npix + k) * 3 + c];
                v += ti.var[((size_t)(l + 1) * npix + k) * 3 + c];
            }
            mean[l][c] = m / (double)npix;
            se[l][c] = sqrt(v) / (double)npix;
        }
    bn_trace_image_free(&ti);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* Issue 33: next-event estimation from the light tree (the light cut into 512 triangles: more
 * emitting patches than BN_TRACE_TREE_EMITTERS, each probability depending on the path's point,
 * MIS weights included) is unbiased: the image means of KE and K2E match the one-quad light's
 * (patches chosen by power) within 4.5 combined standard errors. */
BN_TEST(light_tree_nee_matches_power_nee)
{
    double m1[2][3], s1[2][3], mc[2][3], sc[2][3];
    cornell_traced(bn_test_path("meshes/cornell-box.obj"), m1, s1);
    cornell_traced(bn_test_cornell_cut_light(16), mc, sc);
    for (int l = 0; l < 2; l++)
        for (int c = 0; c < 3; c++) {
            double tol = 4.5 * sqrt(s1[l][c] * s1[l][c] + sc[l][c] * sc[l][c]);
            printf("K%dE channel %d: one quad %.5g +- %.2g, 512 triangles %.5g +- %.2g\n", l + 1, c, m1[l][c], s1[l][c],
                   mc[l][c], sc[l][c]);
            BN_ASSERT_LE(fabs(m1[l][c] - mc[l][c]), tol);
        }
}

/* A point where several faces meet (a bake's vertex on a curved mesh) takes the face whose normal agrees
 * best with its own: on the ridge of a roof of two quads 10 degrees apart, each side's normal picks
 * that side whichever face the first ray meets. */
BN_TEST(points_on_a_ridge_take_the_face_their_normal_names)
{
    const char *obj = bn_test_tmp("ridge.obj");
    FILE *f = fopen(obj, "w");
    BN_ASSERT(f);
    double h = tan(5 * BN_PI / 180);   /* each side 5 degrees from the horizontal */
    fprintf(f, "v -1 0 -1\nv -1 0 1\nv 0 %.17g 1\nv 0 %.17g -1\nv 1 0 -1\nv 1 0 1\n", h, h);
    fprintf(f, "f 1 2 3 4\nf 4 3 6 5\n");
    BN_ASSERT(fclose(f) == 0);
    bn_load_opts lo;
    bn_scene *s = NULL;
    bn_error err;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    BN_ASSERT_STATUS(bn_scene_load(obj, &lo, &s, &err), BN_OK);
    BN_ASSERT_STATUS(bn_scene_mesh(s, NULL, &err), BN_OK);
    bn_rt *rt = make_rt(s);
    const bn_patch *pa = bn_scene_patches(s, NULL);
    const char *path = bn_test_tmp("ridge.txt");
    f = fopen(path, "w");
    BN_ASSERT(f);
    for (int k = 0; k < 6; k++) {   /* along the ridge, each side's normal in turn */
        double sgn = k % 2 ? 1 : -1, c = cos(5 * BN_PI / 180), sn = sin(5 * BN_PI / 180);
        fprintf(f, "0 %.17g %.3f %.17g %.17g 0\n", h, -0.8 + 0.3 * k, sgn * sn, c);
    }
    BN_ASSERT(fclose(f) == 0);
    bn_trace_point *pts = NULL;
    size_t n;
    BN_ASSERT_STATUS(bn_trace_points_read(path, rt, &pts, &n, &err), BN_OK);
    BN_ASSERT_EQ(n, 6);
    for (size_t i = 0; i < n; i++) {
        double want = i % 2 ? 1 : -1;   /* the normal's x: -sin 5 on the left side, +sin 5 on the right */
        const double *nn = pa[pts[i].patch].normal;
        if (!(nn[0] * want > 0.08))
            BN_FAIL("point %zu took a face with normal (%g, %g, %g), the other side's", i, nn[0], nn[1], nn[2]);
    }
    free(pts);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* Points (bounce trace --points): in the furnace every point's layers are rho^k Le whatever its place
 * (centres, near edges and corners, every wall); each estimate within 5 standard errors of it; a file
 * line that is not six numbers, a zero normal and a point with no face whose front agrees are refused
 * naming the line, and so is a line longer than the reader takes. */
BN_TEST(points_in_the_furnace_are_exact)
{
    bn_scene *s = furnace(0.6, 1.5, 300);
    bn_rt *rt = make_rt(s);
    bn_trace_opts o;
    bn_trace_patches r;
    bn_trace_point *pts = NULL;
    size_t n;
    bn_error err;
    const char *path = bn_test_tmp("points.txt");
    FILE *f = fopen(path, "w");
    BN_ASSERT(f);
    fprintf(f, "# x y z nx ny nz\n0.5 0 0.5 0 1 0\n\n0.01 1 0.02 0 -1 0\n1 0.5 0.3 -1 0 0\n0.2 0.7 0 0 0 2\n");
    BN_ASSERT(fclose(f) == 0);
    BN_ASSERT_STATUS(bn_trace_points_read(path, rt, &pts, &n, &err), BN_OK);
    BN_ASSERT_EQ(n, 4);
    BN_ASSERT_EQ(pts[1].line, 4);
    bn_trace_opts_default(&o);
    o.spp = 2048;
    o.bounces = 3;
    BN_ASSERT_STATUS(bn_trace_points_run(rt, pts, n, &o, &r, &err), BN_OK);
    double zmax = 0;
    for (int l = 0; l < r.nlayers; l++)
        for (size_t i = 0; i < n; i++) {
            double want = furnace_exact(l, 3, 0.6, 1.5), got = r.mean[((size_t)l * n + i) * 3];
            double se = r.se[((size_t)l * n + i) * 3];
            zmax = fmax(zmax, se > 0 ? fabs(got - want) / se : (fabs(got - want) < 1e-12 ? 0 : INFINITY));
        }
    printf("furnace points: worst |z| %.2f over %d layers x %zu points\n", zmax, r.nlayers, n);
    BN_ASSERT_LE(zmax, 5);
    bn_trace_patches_free(&r);
    free(pts);
    static const struct {
        const char *text, *says;
    } bad[] = {{"0.5 0 0.5 0 1\n", ":1: expected six numbers"},
               {"\n0.5 0 0.5 0 0 0\n", ":2: the normal (0, 0, 0) is zero"},
               {"0.5 0 0.5 0 -1 0\n", ":1: no face within"},
               {"0.5 0.5 0.5 0 1 0\n", ":1: no face within"},
               {"# nothing\n", "no points"}};
    for (size_t k = 0; k < sizeof bad / sizeof *bad; k++) {
        f = fopen(path, "w");
        BN_ASSERT(f);
        fputs(bad[k].text, f);
        BN_ASSERT(fclose(f) == 0);
        BN_ASSERT_STATUS(bn_trace_points_read(path, rt, &pts, &n, &err), BN_EINPUT);
        if (!strstr(err.msg, bad[k].says) || !strstr(err.msg, "points.txt"))
            BN_FAIL("'%s' does not say '%s'", err.msg, bad[k].says);
    }
    f = fopen(path, "w");   /* a line past the reader's buffer: refused, not read as two */
    BN_ASSERT(f);
    for (int k = 0; k < 700; k++)
        fputs("1 ", f);
    BN_ASSERT(fclose(f) == 0);
    BN_ASSERT_STATUS(bn_trace_points_read(path, rt, &pts, &n, &err), BN_EINPUT);
    if (!strstr(err.msg, ":1: a line longer than"))
        BN_FAIL("'%s' does not refuse the long line", err.msg);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}
