/* The cross-check: its statistics on known inputs, the mesh-level tolerance, and `bounce
 * crosscheck` passing on the furnace box (radiosity exact) and failing on wrong form factors. */
#include "bn_test.h"
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/trace.h"

#include <math.h>
#include <stdint.h>

#define ALPHA 0.01   /* family-wise false-failure rate */
#define BN_TEST_PI 3.14159265358979323846

static bn_scene *load(const char *rel, double patch_size, size_t patches)
{
    bn_scene *s = NULL;
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_load_opts_default(&lo);
    if (bn_scene_load(bn_test_path(rel), &lo, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.patch_size = patch_size;
    mo.target_patches = patches;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    return s;
}

/* The furnace box at 54 patches traced at 256 spp, and radiosity's exact answer per layer (E, KE,
 * K2E, K3E, rest, L: 1, 1/2, 1/4, 1/8, 1/8, 2) in rad (malloc'd, nlayers x n x 3). */
static bn_scene *furnace_traced(bn_rt **rt, bn_trace_patches *r, double **rad)
{
    bn_scene *s = load("meshes/furnace-box.obj", 0, 54);
    bn_trace_opts o;
    bn_error err;
    const double exact[6] = {1, 0.5, 0.25, 0.125, 0.125, 2};
    size_t m;
    if (bn_rt_create(s, 1, rt, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_trace_opts_default(&o);
    o.spp = 256;
    o.quiet = 1;
    if (bn_trace_patches_run(*rt, &o, r, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    m = (size_t)r->nlayers * r->n * 3;
    *rad = malloc(m * sizeof(double));
    for (size_t i = 0; i < m; i++)
        (*rad)[i] = exact[i / (r->n * 3)];
    return s;
}

/* The exact furnace answer passes; one patch's KE moved by 12 standard errors fails and is the
 * worst entry; a tolerance covering the move passes again, with the raw z still reported. */
BN_TEST(compare_detects_injected_error)
{
    bn_rt *rt = NULL;
    bn_trace_patches r;
    bn_crosscheck_input in;
    bn_crosscheck_result cr;
    bn_error err;
    double *rad, *tol;
    bn_scene *s = furnace_traced(&rt, &r, &rad);
    size_t n = r.n, m = (size_t)r.nlayers * n * 3, k;
    tol = calloc(m, sizeof(double));
    bn_crosscheck_input_default(&in);
    in.scene = s;
    in.trace = &r;
    in.rad = rad;
    in.alpha = ALPHA;
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(cr.pass);
    BN_ASSERT_EQ(cr.family, n * 6 * 3);
    /* Sidak: 1 - (1 - alpha_each)^family = alpha. */
    BN_ASSERT_REL(1 - pow(1 - cr.alpha_each, (double)cr.family), ALPHA, 1e-9);
    bn_crosscheck_result_free(&cr);

    k = (1 * n + 7) * 3 + 1;   /* KE, patch 7, G */
    rad[k] = r.mean[k] + 12 * r.se[k];
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(!cr.pass);
    BN_ASSERT_EQ(cr.within, cr.family - 1);
    BN_ASSERT_EQ(cr.worst[0].patch, 7);
    BN_ASSERT_EQ(cr.worst[0].layer, 1);
    BN_ASSERT_EQ(cr.worst[0].channel, 1);
    BN_ASSERT_NEAR(cr.worst[0].z, 12, 1e-9);
    bn_crosscheck_result_free(&cr);

    tol[k] = 12 * r.se[k];   /* the move is declared discretisation error, in the power too */
    in.tol = tol;
    {
        static double ptol[6 * 3];
        size_t np;
        ptol[3 * 1 + 1] = BN_TEST_PI * bn_scene_patches(s, &np)[7].area * tol[k];
        in.power_tol = ptol;
    }
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(cr.pass);
    BN_ASSERT_NEAR(cr.worst_z_raw, 12, 1e-9);
    BN_ASSERT_EQ(cr.within_raw, cr.family - 1);
    bn_crosscheck_result_free(&cr);

    free(rad);
    free(tol);
    bn_trace_patches_free(&r);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* A tracer estimate of exactly 0 with a standard error of 0 (no sample hit: a patch that sees a
 * sliver of the light) is judged by the zero-count bound: with samples 0 or a hit of size h, all
 * spp are 0 with probability exp(-spp mu / h), so a radiosity value mu passes up to
 * h ln(1/alpha_1) / spp and fails above, h = T + spp s^2 / T from the other patches of its face
 * (here all set to T = 0.5, s = 0.01). Before the bound, se 0 made any nonzero value fail. */
BN_TEST(zero_count_bound)
{
    bn_rt *rt = NULL;
    bn_trace_patches r;
    bn_crosscheck_input in;
    bn_crosscheck_result cr;
    bn_error err;
    double *rad, h, mu;
    bn_scene *s = furnace_traced(&rt, &r, &rad);
    size_t n = r.n, np, k, z = 7;
    const bn_patch *pa = bn_scene_patches(s, &np);
    for (size_t i = 0; i < n; i++)   /* KE, G: patch z's face all hit with T 0.5 +- 0.01, z never */
        if (pa[i].face == pa[z].face) {
            r.mean[(1 * n + i) * 3 + 1] = i == z ? 0 : 0.5;
            r.se[(1 * n + i) * 3 + 1] = i == z ? 0 : 0.01;
            r.skew[(1 * n + i) * 3 + 1] = 0;
        }
    h = 0.5 + 256 * 0.01 * 0.01 / 0.5;
    bn_crosscheck_input_default(&in);
    in.scene = s;
    in.trace = &r;
    in.rad = rad;
    in.alpha = ALPHA;
    k = (1 * n + z) * 3 + 1;
    rad[k] = 0;   /* both 0: no evidence either way */
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(cr.pass);
    mu = h * -log(cr.alpha_each) / 256;
    bn_crosscheck_result_free(&cr);
    rad[k] = 0.95 * mu;
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(cr.pass);
    bn_crosscheck_result_free(&cr);
    rad[k] = 1.05 * mu;
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(!cr.pass);
    BN_ASSERT_EQ(cr.within, cr.family - 1);
    BN_ASSERT_EQ(cr.worst[0].patch, z);
    BN_ASSERT_NEAR(cr.worst[0].z_excess, 1.05 * cr.crit, 1e-9);
    bn_crosscheck_result_free(&cr);
    free(rad);
    bn_trace_patches_free(&r);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* Every patch of patch p's face given the tracer estimate T +- se (skewness 0) in layer l, channel
 * c, and radiosity T: one face's entries drawn alike, as the pooled tail assumes. */
static void set_face(const bn_scene *s, bn_trace_patches *r, double *rad, size_t p, size_t l, int c, double T,
                     double se)
{
    size_t np, n = r->n;
    const bn_patch *pa = bn_scene_patches(s, &np);
    for (size_t i = 0; i < n; i++)
        if (pa[i].face == pa[p].face) {
            size_t k = (l * n + i) * 3 + (size_t)c;
            r->mean[k] = rad[k] = T;
            r->se[k] = se;
            r->skew[k] = 0;
        }
}

/* An entry with few hits (samples 0 or h, k = spp T^2 / (T^2 + spp s^2) effective hits) is shown,
 * not judged: T = 1e-3, s = 1e-4 (its whole face so) is k = 256e-6 / (1e-6 + 2.56e-6) = 72 hits,
 * and a radiosity value 20 s away passes (few_hits counts it; its light is too small to move the
 * power test); the same distance with s = 1e-5, k = 250 hits, fails, as a normal tail there holds. */
BN_TEST(few_hits_shown_not_judged)
{
    bn_rt *rt = NULL;
    bn_trace_patches r;
    bn_crosscheck_input in;
    bn_crosscheck_result cr;
    bn_error err;
    double *rad;
    bn_scene *s = furnace_traced(&rt, &r, &rad);
    size_t n = r.n, k = (1 * n + 3) * 3 + 2, base;
    bn_crosscheck_input_default(&in);
    in.scene = s;
    in.trace = &r;
    in.rad = rad;
    in.alpha = ALPHA;
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(cr.pass);
    base = cr.few_hits;
    bn_crosscheck_result_free(&cr);
    set_face(s, &r, rad, 3, 1, 2, 1e-3, 1e-4);   /* k_eff 72 */
    rad[k] = 1e-3 + 20 * 1e-4;
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(cr.pass);
    BN_ASSERT_GT(cr.few_hits, base);
    BN_ASSERT(cr.worst[0].untested == 1 || cr.worst[0].z_excess <= cr.crit);
    bn_crosscheck_result_free(&cr);
    set_face(s, &r, rad, 3, 1, 2, 1e-3, 1e-5);   /* k_eff 250 */
    rad[k] = 1e-3 + 20 * 1e-5;
    if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT(!cr.pass);
    BN_ASSERT_EQ(cr.few_hits, base);
    BN_ASSERT_EQ(cr.worst[0].patch, 3);
    BN_ASSERT_EQ(cr.worst[0].layer, 1);
    BN_ASSERT_NEAR(cr.worst[0].z, 20, 1e-6);
    bn_crosscheck_result_free(&cr);
    free(rad);
    bn_trace_patches_free(&r);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* Lognormal(0, sigma) draws by Box-Muller from a 64-bit LCG (the test's own stream). */
static double lognormal(uint64_t *st, double sigma)
{
    double u1, u2;
    *st = *st * 6364136223846793005ULL + 1442695040888963407ULL;
    u1 = ((double)(*st >> 11) + 0.5) / 9007199254740992.0;
    *st = *st * 6364136223846793005ULL + 1442695040888963407ULL;
    u2 = ((double)(*st >> 11) + 0.5) / 9007199254740992.0;
    return exp(sigma * sqrt(-2 * log(u1)) * cos(2 * BN_TEST_PI * u2));
}

/* The judged statistic holds its per-test level where the plain t test does not. Entries of 256
 * lognormal samples (sigma 0.7: skewness 2.9, the tracer's kind of tail, mostly moderate, now and
 * then large) with the true mean as "radiosity", judged at a per-test level of 1e-3 (alpha chosen
 * so), 100 replicates of the furnace's 810 sampled entries (those with under 100 effective hits
 * aside): about 81 rejections are nominal. The plain t test, |T - mu| / se_sample, rejects about
 * 3.4x that (simulated beforehand with numpy: 272 per 81,000), the left tail of a skewed mean's t
 * being heavy; the judged one (the face's pooled se, then Hall's correction) must stay below 2x
 * nominal (measured: 40, the pooled se being the larger when a sample lacks its rare large draws)
 * and the plain count above 200 (4 sd below its expectation). */
BN_TEST(judged_t_holds_its_level_on_skewed_samples)
{
    bn_rt *rt = NULL;
    bn_trace_patches r;
    bn_crosscheck_input in;
    bn_crosscheck_result cr;
    bn_error err;
    double *rad, sigma = 0.7, mu = exp(0.245), x[256];
    bn_scene *s = furnace_traced(&rt, &r, &rad);
    size_t n = r.n, fails = 0, fails_raw = 0, tested = 0, spp = 256;
    uint64_t st = 12345;
    double crit = bn_student_t_quantile_upper(0.5e-3, (double)(spp - 1));
    bn_crosscheck_input_default(&in);
    in.scene = s;
    in.trace = &r;
    in.rad = rad;
    in.alpha = -expm1((double)(n * 6 * 3) * log1p(-1e-3));   /* Sidak: 1e-3 per test */
    for (int rep = 0; rep < 100; rep++) {
        for (size_t k = n * 3; k < (size_t)r.nlayers * n * 3; k++) {   /* every layer but E */
            double m = 0, m2 = 0, m3 = 0;
            for (size_t j = 0; j < spp; j++)
                m += (x[j] = lognormal(&st, sigma)) / (double)spp;
            for (size_t j = 0; j < spp; j++) {
                m2 += (x[j] - m) * (x[j] - m);
                m3 += (x[j] - m) * (x[j] - m) * (x[j] - m);
            }
            r.mean[k] = m;
            r.se[k] = sqrt(m2 / (double)(spp - 1) / (double)spp);
            r.skew[k] = sqrt((double)spp) * m3 / pow(m2, 1.5);
            rad[k] = mu;
            tested++;
            fails_raw += fabs(m - mu) / r.se[k] > crit;   /* the plain t test */
        }
        if (bn_crosscheck_compare(&in, &cr, &err) != BN_OK)
            BN_FAIL("%s", err.msg);
        BN_ASSERT_NEAR(cr.alpha_each, 1e-3, 1e-9);
        tested -= cr.few_hits;   /* the rare sample with a huge draw: under 100 effective hits, not judged */
        fails += cr.family - cr.within;
        bn_crosscheck_result_free(&cr);
    }
    fprintf(stderr, "%zu tests at 1e-3 each: %zu rejected as judged, %zu by the plain t test (expected %.0f)\n",
            tested, fails, fails_raw, 1e-3 * (double)tested);
    BN_ASSERT_GE(tested, 80000);
    BN_ASSERT_LE(fails, 162);
    BN_ASSERT_GT(fails_raw, 200);
    free(rad);
    bn_trace_patches_free(&r);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

/* The tolerance from a second mesh level maps each patch to the other level's patch that holds
 * its centroid: with x of the centroid as the "solution", the difference is below one coarse
 * patch (0.5 m) and zero where the levels agree (the same mesh twice). */
BN_TEST(mesh_tolerance_mapping)
{
    bn_scene *fine = load("meshes/furnace-box.obj", 0.25, 0), *coarse = load("meshes/furnace-box.obj", 0.5, 0);
    int bounces = 0;
    size_t nf, nc, nl = (size_t)bn_layer_count(bounces);
    const bn_patch *pf = bn_scene_patches(fine, &nf), *pc = bn_scene_patches(coarse, &nc);
    double *lf = malloc(nl * nf * 3 * sizeof(double)), *lc = malloc(nl * nc * 3 * sizeof(double));
    double *tol = malloc(nl * nf * 3 * sizeof(double)), ptol[3 * 16], worst = 0; /* nl <= 16 layers */
    bn_error err;
    BN_ASSERT_EQ(nf, 96);
    BN_ASSERT_EQ(nc, 24);
    BN_ASSERT_LE(nl, 16);
    for (size_t l = 0; l < nl; l++) {
        for (size_t i = 0; i < nf * 3; i++)
            lf[l * nf * 3 + i] = pf[i / 3].centroid[0];
        for (size_t i = 0; i < nc * 3; i++)
            lc[l * nc * 3 + i] = pc[i / 3].centroid[0];
    }
    if (bn_crosscheck_mesh_tolerance(fine, lf, coarse, lc, bounces, tol, ptol, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    for (size_t i = 0; i < nl * nf * 3; i++)
        worst = fmax(worst, tol[i]);
    /* A fine patch's centroid is 0.125 m from its coarse patch's centroid along x, or 0 for faces
     * normal to x (constant x) and along y or z. */
    BN_ASSERT_NEAR(worst, 0.125, 1e-12);
    if (bn_crosscheck_mesh_tolerance(fine, lf, fine, lf, bounces, tol, ptol, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    for (size_t i = 0; i < nl * nf * 3; i++)
        BN_ASSERT_EQ(tol[i], 0);
    free(lf);
    free(lc);
    free(tol);
    bn_scene_destroy(fine);
    bn_scene_destroy(coarse);
}

static const char *verdict_line(const char *out)
{
    const char *v = out ? strstr(out, "\nverdict: ") : NULL;
    return v ? v + 1 : "(no verdict line)";
}

/* The furnace: radiosity is exact at every mesh level, so the cross-check passes for every
 * bounce at alpha = 0.01 (exit 0), powers included. Analytic form factors, 24 patches (a coarse
 * level of 6 for the tolerance), 256 samples per patch. */
BN_TEST(cli_furnace_passes)
{
    char cmd[1024], *out = NULL;
    int rc;
    snprintf(cmd, sizeof cmd, "crosscheck %s --patches 24 --spp 256 -n 3 --alpha 0.01 -q",
             bn_test_path("meshes/furnace-box.obj"));
    rc = bn_test_bounce(cmd, &out);
    fprintf(stderr, "%s", verdict_line(out));
    if (rc != 0)
        BN_FAIL("bounce %s -> %d\n%s", cmd, rc, out ? out : "");
    BN_ASSERT(strncmp(verdict_line(out), "verdict: pass alpha=0.01 family=432 ", 36) == 0);
    BN_ASSERT(strstr(out, "within=432/432") != NULL);
    free(out);
}

/* Wrong radiosity must fail: Monte Carlo form factors with 4 point pairs per patch pair have row
 * sums far from 1, which no mesh-level tolerance explains. Exit 6, verdict fail. */
BN_TEST(cli_wrong_form_factors_fail)
{
    char cmd[1024], *out = NULL;
    int rc;
    snprintf(cmd, sizeof cmd, "crosscheck %s --patches 24 --spp 256 --ff montecarlo --samples 4 -q",
             bn_test_path("meshes/furnace-box.obj"));
    rc = bn_test_bounce(cmd, &out);
    fprintf(stderr, "%s", verdict_line(out));
    BN_ASSERT_EQ(rc, 6);
    BN_ASSERT(strncmp(verdict_line(out), "verdict: fail ", 14) == 0);
    free(out);
}

/* Issue 33: the object partition against the scene's own listing: each polygon over 1% of the area
 * is a region alone, the others one region per (object, material) pair, counted here from the faces;
 * every patch lies in its face's region and the regions' areas sum to the scene's. The Cornell box
 * with its light cut into 512 triangles: the light is one region, each other face its own. */
BN_TEST(partition_by_object)
{
    bn_scene *s = NULL;
    bn_load_opts lo;
    size_t nf, np, nm, expect = 0;
    const bn_face *f;
    const bn_patch *pa;
    double total = 0, sum = 0;
    unsigned char *seen;
    bn_partition part;
    bn_error err;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    BN_ASSERT_STATUS(bn_scene_load(bn_test_cornell_cut_light(16), &lo, &s, &err), BN_OK);
    BN_ASSERT_STATUS(bn_scene_mesh(s, NULL, &err), BN_OK);
    f = bn_scene_faces(s, &nf);
    pa = bn_scene_patches(s, &np);
    bn_scene_materials(s, &nm);
    BN_ASSERT((seen = calloc(bn_scene_object_count(s) * nm, 1)) != NULL);
    for (size_t k = 0; k < nf; k++)
        total += f[k].area;
    for (size_t k = 0; k < nf; k++) {
        size_t key = f[k].object * nm + f[k].material;
        if (f[k].area >= BN_PARTITION_OWN_SHARE * total)
            expect++;
        else if (f[k].area > 0 && !seen[key]) {
            seen[key] = 1;
            expect++;
        }
    }
    BN_ASSERT_STATUS(bn_partition_objects(s, BN_PARTITION_OWN_SHARE, &part, &err), BN_OK);
    printf("%zu faces, %zu objects: %zu regions (expected %zu)\n", nf, bn_scene_object_count(s), part.n, expect);
    BN_ASSERT_EQ(part.n, expect);
    BN_ASSERT_EQ(part.n, nf - 512 + 1);
    for (size_t i = 0; i < np; i++)
        for (size_t j = i + 1; j < np && j < i + 40; j++)   /* patches of one face share its region */
            if (pa[i].face == pa[j].face)
                BN_ASSERT_EQ(part.of_patch[i], part.of_patch[j]);
    for (size_t g = 0; g < part.n; g++)
        sum += part.area[g];
    BN_ASSERT_REL(sum, total, 1e-9);
    bn_partition_free(&part);
    free(seen);
    bn_scene_destroy(s);
}
