/* Form factors against published configuration factors, closed-box row sums and reciprocity,
 * occlusion bounds, thread invariance, CSR vs dense, sampling rates, and the CLI's files. */
#include "bn_test.h"
#include "bounce/formfactor.h"
#include "bounce/rt.h"

#include <stdint.h>

#define BN_PI_T 3.14159265358979323846

/* Tolerances, each with its reason:
 * - BN_TOL_PUBLISHED: the target for `analytic` against published factors.
 * - BN_TOL_ROWSUM: closed box row sums and reciprocity (issue 3, "Must show").
 * - BN_RATE_SLACK: a sampled error over 16x the samples must shrink at least to 1/sqrt(16)
 *   of what it was, with 50% slack for the spread of an RMS over 16 seeds. */
#define BN_TOL_PUBLISHED 1e-5
#define BN_TOL_ROWSUM 1e-6
#define BN_RATE_SLACK 1.5

/* ---- published configuration factors (Howell, "A Catalog of Radiation Heat Transfer
 * Configuration Factors", cases B-3, C-11, C-14, C-41) ---- */

/* Differential element parallel to an a x b rectangle at distance c, opposite one corner (B-3). */
static double pub_dA_rect(double a, double b, double c)
{
    double A = a / c, B = b / c;
    return (A / sqrt(1 + A * A) * atan(B / sqrt(1 + A * A)) + B / sqrt(1 + B * B) * atan(A / sqrt(1 + B * B))) /
           (2 * BN_PI_T);
}

/* Directly opposed parallel a x b rectangles at distance c (C-11). */
static double pub_parallel(double a, double b, double c)
{
    double X = a / c, Y = b / c, x2 = X * X, y2 = Y * Y;
    return 2 / (BN_PI_T * X * Y) *
           (0.5 * log((1 + x2) * (1 + y2) / (1 + x2 + y2)) + X * sqrt(1 + y2) * atan(X / sqrt(1 + y2)) +
            Y * sqrt(1 + x2) * atan(Y / sqrt(1 + x2)) - X * atan(X) - Y * atan(Y));
}

/* Coaxial parallel disks of radii r1 (emitter) and r2 at distance h (C-41). */
static double pub_disks(double r1, double r2, double h)
{
    double R1 = r1 / h, R2 = r2 / h, X = 1 + (1 + R2 * R2) / (R1 * R1);
    return 0.5 * (X - sqrt(X * X - 4 * (R2 / R1) * (R2 / R1)));
}

/* ---- scenes built in code ---- */

typedef struct sb {
    double v[3 * 512];
    unsigned poly[5 * 128];
    unsigned mat[128];
    size_t nv, np, npi;
} sb;

/* Quad with corners c, c+u, c+u+v, c+v; front towards u x v. */
static void sb_quad(sb *s, const double c[3], const double u[3], const double w[3], unsigned mat)
{
    unsigned base = (unsigned)s->nv;
    for (int k = 0; k < 4; k++)
        for (int d = 0; d < 3; d++)
            s->v[3 * (s->nv + k) + d] = c[d] + (k == 1 || k == 2 ? u[d] : 0) + (k >= 2 ? w[d] : 0);
    s->nv += 4;
    s->poly[s->npi++] = 4;
    for (unsigned k = 0; k < 4; k++)
        s->poly[s->npi++] = base + k;
    s->mat[s->np++] = mat;
}

/* Axis-aligned box [lo, hi]: faces facing in (inward = 1) or out; `bottom` 0 leaves out y = lo. */
static void sb_box(sb *s, const double lo[3], const double hi[3], int inward, int bottom, unsigned mat)
{
    double e[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++) {
            double c[3] = {lo[0], lo[1], lo[2]}, u[3] = {0, 0, 0}, w[3] = {0, 0, 0};
            int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
            /* u x w points along +axis */
            int plus = side == 0 ? inward : !inward;
            if (axis == 1 && side == 0 && !bottom)
                continue;
            c[axis] = side ? hi[axis] : lo[axis];
            if (plus) {
                u[a1] = e[a1];
                w[a2] = e[a2];
            } else {
                u[a2] = e[a2];
                w[a1] = e[a1];
            }
            sb_quad(s, c, u, w, mat);
        }
}

static bn_scene *sb_scene(sb *s, double patch_size)
{
    bn_material m[2] = {{"white", {0.7, 0.6, 0.5}, {0, 0, 0}}, {"light", {0.5, 0.5, 0.5}, {1, 1, 1}}};
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_scene *scene = NULL;
    bn_error err;
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    if (bn_scene_from_arrays("test", s->v, s->nv, s->poly, s->np, s->mat, m, 2, &lo, &scene, &err) != BN_OK)
        BN_FAIL("scene: %s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.patch_size = patch_size;
    mo.no_subdivide = patch_size <= 0;
    mo.no_contacts = 1;   /* walls and floor mesh the same with and without blocks standing on them */
    if (bn_scene_mesh(scene, &mo, &err) != BN_OK)
        BN_FAIL("mesh: %s", err.msg);
    return scene;
}

static bn_transport *build(const bn_scene *scene, const bn_formfactor_opts *o, bn_ff_diagnostics *d)
{
    bn_rt *rt = NULL;
    bn_transport *k = NULL;
    bn_error err;
    bn_error_clear(&err);
    if (bn_rt_create(scene, 0, &rt, &err) != BN_OK)
        BN_FAIL("rt: %s", err.msg);
    if (bn_formfactor_build(scene, rt, o, &k, d, &err) != BN_OK)
        BN_FAIL("build: %s", err.msg);
    bn_rt_destroy(rt);
    return k;
}

static bn_formfactor_opts opts(bn_ff_method m, int samples, uint64_t seed)
{
    bn_formfactor_opts o;
    bn_formfactor_opts_default(&o);
    o.method = m;
    o.samples = samples;
    o.seed = seed;
    o.quiet = 1;
    o.log.quiet = 1;
    return o;
}

/* Two opposed a x b plates at distance c (front sides facing). */
static bn_scene *parallel_scene(double a, double b, double c)
{
    static sb s;
    memset(&s, 0, sizeof s);
    sb_quad(&s, (double[]){0, 0, 0}, (double[]){0, 0, b}, (double[]){a, 0, 0}, 1);   /* +y */
    sb_quad(&s, (double[]){0, c, 0}, (double[]){a, 0, 0}, (double[]){0, 0, b}, 0);   /* -y */
    return sb_scene(&s, 0);
}

/* ---- tests ---- */

BN_TEST(differential_element_to_rectangle)
{
    const double sizes[] = {0.01, 0.1, 1, 10, 100};
    for (int ia = 0; ia < 5; ia++)
        for (int ib = 0; ib < 5; ib++) {
            double a = sizes[ia], b = sizes[ib], c = 1;
            double x[3] = {0, 0, 0}, n[3] = {0, 0, 1};
            double v[12] = {0, 0, c, 0, b, c, a, b, c, a, 0, c};   /* faces -z: CCW seen from below */
            BN_ASSERT_REL(bn_ff_point_to_polygon(x, n, v, 4), pub_dA_rect(a, b, c), BN_TOL_PUBLISHED);
        }
}

BN_TEST(parallel_rectangles_published)
{
    const double r[] = {0.01, 0.1, 1, 10, 100};
    /* separations c / a from 1e-2 to 1e2 for unit squares, and aspect ratios b / a at c = 1 */
    for (int k = 0; k < 5; k++) {
        double vi[12] = {0, 0, 0, 0, 0, 1, 1, 0, 1, 1, 0, 0};
        double vj[12] = {0, r[k], 0, 1, r[k], 0, 1, r[k], 1, 0, r[k], 1};
        BN_ASSERT_REL(bn_ff_polygon_pair(vi, 4, vj, 4, 0), pub_parallel(1, 1, r[k]), BN_TOL_PUBLISHED);
        {
            double b = r[k];
            double wi[12] = {0, 0, 0, 0, 0, b, 1, 0, b, 1, 0, 0};
            double wj[12] = {0, 1, 0, 1, 1, 0, 1, 1, b, 0, 1, b};
            BN_ASSERT_REL(bn_ff_polygon_pair(wi, 4, wj, 4, 0), pub_parallel(1, b, 1), BN_TOL_PUBLISHED);
        }
    }
    /* the whole assembly (scene, patches, F storage in double) on a few of them */
    for (int k = 0; k < 5; k += 2) {
        bn_scene *s = parallel_scene(1, 1, r[k]);
        bn_formfactor_opts o = opts(BN_FF_ANALYTIC, 0, 1);
        bn_ff_diagnostics d;
        bn_transport *K;
        o.precision = BN_PRECISION_DOUBLE;
        K = build(s, &o, &d);
        BN_ASSERT_REL(bn_test_F(K, 0, 1), pub_parallel(1, 1, r[k]), BN_TOL_PUBLISHED);
        BN_ASSERT_REL(bn_test_F(K, 1, 0), pub_parallel(1, 1, r[k]), BN_TOL_PUBLISHED);
        BN_ASSERT_EQ(d.rays, 0);   /* nothing in between: no shadow rays */
        bn_transport_destroy(K);
        bn_scene_destroy(s);
    }
}

BN_TEST(perpendicular_common_edge_published)
{
    const double r[] = {0.01, 0.1, 1, 10, 100};
    for (int a = 0; a < 5; a++)
        for (int b = 0; b < 5; b++) {
            double w = r[a], h = r[b];
            double fl[12] = {0, 0, 0, 0, 0, 1, w, 0, 1, w, 0, 0};   /* y = 0, facing +y, width w along x */
            double wa[12] = {0, 0, 0, 0, h, 0, 0, h, 1, 0, 0, 1};   /* x = 0, facing +x, height h */
            BN_ASSERT_REL(bn_ff_polygon_pair(fl, 4, wa, 4, 0), bn_test_F_perpendicular(w, h, 1), BN_TOL_PUBLISHED);
        }
}

BN_TEST(coaxial_disks_published)
{
    /* 64-gons whose circumradius makes their area the disk's: the area error is 0, and the
     * remaining shape error (the perimeter differs by about (pi/n)^2/6 = 4e-4 relative, which
     * moves 1 - F = 0.01 of the nearest pair by as much: 4e-6 in F) stays below the tolerance. */
    enum { NS = 64 };
    static double d1[3 * NS], d2[3 * NS];
    const double cases[][3] = {{1, 1, 0.01}, {1, 1, 1}, {1, 0.1, 1}, {0.1, 1, 1}, {1, 1, 100}, {1, 0.5, 0.1}};
    double fit = sqrt(2 * BN_PI_T / (NS * sin(2 * BN_PI_T / NS)));
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        double r1 = cases[c][0] * fit, r2 = cases[c][1] * fit, h = cases[c][2];
        for (int k = 0; k < NS; k++) {
            double t = 2 * BN_PI_T * k / NS;
            /* disk 1 at z = 0 facing +z (CCW seen from +z); disk 2 at z = h facing -z */
            d1[3 * k] = r1 * cos(t), d1[3 * k + 1] = r1 * sin(t), d1[3 * k + 2] = 0;
            d2[3 * k] = r2 * cos(-t), d2[3 * k + 1] = r2 * sin(-t), d2[3 * k + 2] = h;
        }
        BN_ASSERT_REL(bn_ff_polygon_pair(d1, NS, d2, NS, 0), pub_disks(cases[c][0], cases[c][1], h), BN_TOL_PUBLISHED);
    }
}

BN_TEST(closed_box_row_sums_and_reciprocity)
{
    sb s;
    bn_scene *scene;
    bn_formfactor_opts o = opts(BN_FF_ANALYTIC, 0, 1);
    bn_ff_diagnostics d;
    bn_transport *K;
    size_t n;
    memset(&s, 0, sizeof s);
    sb_box(&s, (double[]){0, 0, 0}, (double[]){1, 1.5, 2}, 1, 1, 0);
    scene = sb_scene(&s, 0.5);
    K = build(scene, &o, &d);
    n = bn_transport_size(K);
    BN_ASSERT_GE(n, 40);
    BN_ASSERT_NEAR(d.row_sum_min, 1, BN_TOL_ROWSUM);
    BN_ASSERT_NEAR(d.row_sum_max, 1, BN_TOL_ROWSUM);
    BN_ASSERT_LT(d.reciprocity_residual, BN_TOL_ROWSUM);
    BN_ASSERT_EQ(d.rays, 0);   /* a convex room: every shaft is empty */
    BN_ASSERT_EQ(d.negative_entries + d.above_one_entries, 0);
    bn_transport_destroy(K);
    bn_scene_destroy(scene);
}

/* A closed box with two blocks on the floor (walls first so their patches keep their indices). */
static bn_scene *cornell_like(int blocks, double patch)
{
    static sb s;
    memset(&s, 0, sizeof s);
    sb_box(&s, (double[]){0, 0, 0}, (double[]){1, 1, 1}, 1, 1, 0);
    if (blocks) {
        sb_box(&s, (double[]){0.15, 0, 0.55}, (double[]){0.45, 0.6, 0.85}, 0, 0, 0);
        sb_box(&s, (double[]){0.55, 0, 0.15}, (double[]){0.85, 0.3, 0.45}, 0, 0, 0);
    }
    return sb_scene(&s, patch);
}

BN_TEST(occlusion_bounds_cornell_like) /* BN_SLOW */
{
    BN_SKIP_IF_SLOW_RUN();   /* 18 s under the sanitizers; test_ff_cornell's occluded Cornell box runs there */
    bn_scene *with = cornell_like(1, 0.125), *without = cornell_like(0, 0.125);
    bn_formfactor_opts o = opts(BN_FF_ANALYTIC, 0, 1);
    bn_ff_diagnostics dw, dn;
    bn_transport *Kw = build(with, &o, &dw), *Kn = build(without, &o, &dn);
    size_t nw = bn_transport_size(Kw), nn = bn_transport_size(Kn), npw, npn;
    const bn_patch *pw = bn_scene_patches(with, &npw), *pn = bn_scene_patches(without, &npn);
    BN_ASSERT_GT(nw, nn);
    BN_ASSERT_GT(dw.pairs_blocked, 0);
    BN_ASSERT_EQ(dw.negative_entries + dw.above_one_entries, 0);
    BN_ASSERT_LE(dw.row_sum_max, 1 + 0.05);
    for (size_t i = 0; i < nn; i++)
        for (int c = 0; c < 3; c++)
            BN_ASSERT_EQ(pw[i].centroid[c], pn[i].centroid[c]);   /* same wall patches */
    /* The room is closed: rows off the floor sum to 1 but for the sampled visible fractions,
     * whose noise averages out (the estimate is unbiased): the mean deviation over 400+ rows is
     * far below one row's noise (about 1e-3 at 32 samples). */
    {
        double mean = 0;
        size_t count = 0;
        for (size_t i = 0; i < nw; i++) {
            double rs = 0;
            if (pw[i].normal[1] > 0.5 && pw[i].centroid[1] == 0)
                continue;   /* floor: partly under the blocks, which have no bottom */
            for (size_t j = 0; j < nw; j++)
                rs += bn_test_F(Kw, i, j);
            BN_ASSERT_NEAR(rs, 1, 0.03);
            mean += rs - 1;
            count++;
        }
        mean /= (double)count;
        BN_ASSERT_NEAR(mean, 0, 3e-4);
    }
    for (size_t i = 0; i < nw; i++)
        for (size_t j = 0; j < nw; j++) {
            double f = bn_test_F(Kw, i, j);
            BN_ASSERT(f >= 0 && f <= 1);
            if (i < nn && j < nn && !(f <= bn_test_F(Kn, i, j)))
                BN_FAIL("F_occ[%zu][%zu] = %.9g > F_unocc = %.9g", i, j, f, bn_test_F(Kn, i, j));
        }
    bn_transport_destroy(Kw);
    bn_transport_destroy(Kn);
    bn_scene_destroy(with);
    bn_scene_destroy(without);
}

static double *dense_of(const bn_transport *K)
{
    size_t n = bn_transport_size(K);
    double *F = malloc(n * n * sizeof *F);
    if (bn_transport_to_dense(K, F, NULL) != BN_OK)
        BN_FAIL("to_dense");
    return F;
}

BN_TEST(thread_count_invariance)
{
    bn_scene *s = cornell_like(1, 0.25);
    const bn_ff_method methods[] = {BN_FF_ANALYTIC, BN_FF_MONTECARLO, BN_FF_HEMISPHERE};
    for (int m = 0; m < 3; m++) {
        bn_formfactor_opts o = opts(methods[m], m == 2 ? 256 : 16, 7);
        bn_ff_diagnostics d1, d2;
        bn_transport *K1, *K2;
        double *F1, *F2;
        size_t n;
        o.threads = 1;
        K1 = build(s, &o, &d1);
        o.threads = 2;
        K2 = build(s, &o, &d2);
        n = bn_transport_size(K1);
        F1 = dense_of(K1);
        F2 = dense_of(K2);
        BN_ASSERT(memcmp(F1, F2, n * n * sizeof *F1) == 0);
        BN_ASSERT_EQ(d1.rays, d2.rays);
        free(F1);
        free(F2);
        bn_transport_destroy(K1);
        bn_transport_destroy(K2);
    }
    bn_scene_destroy(s);
}

BN_TEST(csr_matches_dense)
{
    bn_scene *s = cornell_like(1, 0.25);
    bn_formfactor_opts o = opts(BN_FF_ANALYTIC, 0, 3);
    bn_ff_diagnostics dd, ds, dt;
    bn_transport *Kd, *Ks, *Kt, *Ka;
    size_t n;
    double *x, *yd, *ys, *F;
    bn_error err;
    Kd = build(s, &o, &dd);
    o.storage = "sparse";
    Ks = build(s, &o, &ds);
    n = bn_transport_size(Kd);
    BN_ASSERT(strncmp(bn_transport_name(Ks), "csr", 3) == 0);
    BN_ASSERT_EQ(ds.nonzeros, dd.nonzeros);
    for (size_t i = 0; i < n; i++)
        for (size_t j = 0; j < n; j++)
            BN_ASSERT_EQ(bn_test_F(Ks, i, j), bn_test_F(Kd, i, j));
    x = malloc(3 * n * sizeof *x);
    yd = malloc(3 * n * sizeof *yd);
    ys = malloc(3 * n * sizeof *ys);
    for (size_t i = 0; i < 3 * n; i++)
        x[i] = 1.0 + (double)(i % 7) / 7;
    BN_ASSERT_STATUS(bn_transport_apply(Kd, x, yd, NULL), BN_OK);
    BN_ASSERT_STATUS(bn_transport_apply(Ks, x, ys, NULL), BN_OK);
    for (size_t i = 0; i < 3 * n; i++)
        BN_ASSERT_NEAR(ys[i], yd[i], 1e-14 * fabs(yd[i]) + 1e-300);
    /* a threshold drops entries and reports the mass each row lost */
    o.sparse_threshold = 1e-3;
    Kt = build(s, &o, &dt);
    BN_ASSERT_GT(dt.dropped_entries, 0);
    BN_ASSERT_GT(dt.dropped_mass_max, 0);
    /* It keeps exactly the entries of the unthresholded F at or above 1e-3 (same seed, same
     * values), zeroes the rest, and reports the largest row sum of what it dropped: all three
     * counted here from Ks itself. */
    {
        size_t kept = 0, below = 0;
        double worst = 0;
        for (size_t i = 0; i < n; i++) {
            double lost = 0;
            for (size_t j = 0; j < n; j++) {
                double f = bn_test_F(Ks, i, j);
                if (f >= 1e-3) {
                    kept++;
                    BN_ASSERT_EQ(bn_test_F(Kt, i, j), f);
                } else {
                    below += f > 0;
                    lost += f;
                    BN_ASSERT_EQ(bn_test_F(Kt, i, j), 0);
                }
            }
            worst = fmax(worst, lost);
        }
        BN_ASSERT_EQ(dt.nonzeros, kept);
        BN_ASSERT_EQ(dt.dropped_entries - ds.dropped_entries, below);   /* beyond the exact zeros */
        BN_ASSERT_REL(dt.dropped_mass_max, worst, 1e-12);
    }
    BN_ASSERT_NEAR(dt.row_sum_min, ds.row_sum_min, dt.dropped_mass_max + 1e-7);
    /* the array constructor agrees too */
    F = dense_of(Kd);
    BN_ASSERT_STATUS(bn_transport_from_array(n, F, bn_transport_rho(Kd), "sparse", BN_PRECISION_FLOAT, 0, &Ka, &err),
                     BN_OK);
    for (size_t i = 0; i < n; i++)
        for (size_t j = 0; j < n; j++)
            BN_ASSERT_EQ(bn_test_F(Ka, i, j), F[i * n + j]);
    free(F);
    free(x);
    free(yd);
    free(ys);
    bn_transport_destroy(Ka);
    bn_transport_destroy(Kt);
    bn_transport_destroy(Ks);
    bn_transport_destroy(Kd);
    bn_scene_destroy(s);
}

/* RMS error of F_01 over 16 seeds. */
static double rms_error(bn_scene *s, bn_ff_method m, int samples, double exact)
{
    double e2 = 0;
    for (uint64_t seed = 1; seed <= 16; seed++) {
        bn_formfactor_opts o = opts(m, samples, seed);
        bn_ff_diagnostics d;
        bn_transport *K = build(s, &o, &d);
        double f = bn_test_F(K, 0, 1);
        e2 += (f - exact) * (f - exact);
        bn_transport_destroy(K);
    }
    return sqrt(e2 / 16);
}

BN_TEST(montecarlo_converges_at_its_rate)
{
    /* plates at distance 1 and 0.25 of their size */
    const double c[] = {1, 0.25};
    for (int k = 0; k < 2; k++) {
        bn_scene *s = parallel_scene(1, 1, c[k]);
        double exact = pub_parallel(1, 1, c[k]);
        double e16 = rms_error(s, BN_FF_MONTECARLO, 16, exact), e256 = rms_error(s, BN_FF_MONTECARLO, 256, exact),
               e4096 = rms_error(s, BN_FF_MONTECARLO, 4096, exact);
        fprintf(stderr, "montecarlo c=%g: RMS error %.3g (16), %.3g (256), %.3g (4096)\n", c[k], e16, e256, e4096);
        BN_ASSERT_LT(e256, e16 * BN_RATE_SLACK / 4);
        BN_ASSERT_LT(e4096, e256 * BN_RATE_SLACK / 4);
        BN_ASSERT_LT(e4096 / exact, 5e-2);   /* c = 0.25: the kernel peaks at 5x its mean */
        bn_scene_destroy(s);
    }
}

BN_TEST(hemisphere_converges_at_its_rate)
{
    bn_scene *s = parallel_scene(1, 1, 1);
    double exact = pub_parallel(1, 1, 1);
    double e256 = rms_error(s, BN_FF_HEMISPHERE, 256, exact), e4096 = rms_error(s, BN_FF_HEMISPHERE, 4096, exact),
           e65536 = rms_error(s, BN_FF_HEMISPHERE, 65536, exact);
    /* Counting hits of independent rays is binomial: the error promised is
     * sqrt(F (1 - F) / N); stratification may only do better. */
    double b256 = sqrt(exact * (1 - exact) / 256), b4096 = sqrt(exact * (1 - exact) / 4096),
           b65536 = sqrt(exact * (1 - exact) / 65536);
    fprintf(stderr, "hemisphere: RMS error %.3g (256), %.3g (4096), %.3g (65536); binomial %.3g %.3g %.3g\n", e256,
            e4096, e65536, b256, b4096, b65536);
    BN_ASSERT_LT(e256, BN_RATE_SLACK * b256);
    BN_ASSERT_LT(e4096, BN_RATE_SLACK * b4096);
    BN_ASSERT_LT(e65536, BN_RATE_SLACK * b65536);
    BN_ASSERT_LT(e65536, e256 * BN_RATE_SLACK / 16);   /* 256x the rays: at least 16x smaller */
    bn_scene_destroy(s);
}

BN_TEST(hemisphere_rows_at_most_one)
{
    bn_scene *s = cornell_like(1, 0.25);
    bn_formfactor_opts o = opts(BN_FF_HEMISPHERE, 1024, 5);
    bn_ff_diagnostics d;
    bn_transport *K = build(s, &o, &d);
    size_t n, np;
    const bn_patch *p = bn_scene_patches(s, &np);
    BN_ASSERT_LE(d.row_sum_max, 1 + 1e-6);
    /* a closed room: every ray hits a front side, except from floor patches under the blocks
     * (which have no bottom face), so every other row sums to 1 */
    n = bn_transport_size(K);
    for (size_t i = 0; i < n; i++) {
        double rs = 0;
        if (p[i].normal[1] > 0.5 && p[i].centroid[1] == 0)
            continue;
        for (size_t j = 0; j < n; j++)
            rs += bn_test_F(K, i, j);
        BN_ASSERT_NEAR(rs, 1, 1e-6);
    }
    bn_transport_destroy(K);
    bn_scene_destroy(s);
}

BN_TEST(memory_limit_is_a_clear_error)
{
    bn_scene *s = cornell_like(1, 0.25);
    bn_formfactor_opts o = opts(BN_FF_ANALYTIC, 0, 1);
    bn_rt *rt;
    bn_transport *K = NULL;
    bn_error err;
    size_t n;
    char want[64];
    bn_scene_patches(s, &n);
    bn_error_clear(&err);
    BN_ASSERT_STATUS(bn_rt_create(s, 0, &rt, &err), BN_OK);
    o.max_memory = 1000;
    BN_ASSERT_STATUS(bn_formfactor_build(s, rt, &o, &K, NULL, &err), BN_ENOMEM);
    BN_ASSERT(K == NULL);
    snprintf(want, sizeof want, "%zu patches", n);
    BN_ASSERT(strstr(err.msg, want) != NULL);
    BN_ASSERT(strstr(err.msg, "`storage` sparse") != NULL);
    BN_ASSERT(strstr(err.msg, "`patch_size`") != NULL);
    BN_ASSERT_GT(bn_formfactor_bytes_needed(s, &o), n * n * 4);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

BN_TEST(cli_outputs_cache_and_limits)
{
    char *out = NULL, cmd[2048], *txt;
    const char *scene = bn_test_path("meshes/parallel-plates.obj");
    const char *csv = bn_test_tmp("F.csv"), *bin = bn_test_tmp("F.bin"), *cache = bn_test_tmp("F.cache");
    size_t size;
    snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide -o %s", scene, csv);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    free(out);
    txt = bn_test_read_file(csv, &size);
    BN_ASSERT(txt && strncmp(txt, "# ", 2) == 0);
    BN_ASSERT(strstr(txt, "\npatch,area,F0,F1\n") != NULL);
    BN_ASSERT(strstr(txt, "method=analytic") != NULL);
    BN_ASSERT(strstr(txt, "\n0,1,0,0.199824") != NULL);   /* Howell C-11, X = Y = 1: 0.19982 */
    free(txt);
    snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide --precision double -o %s", scene, bin);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    free(out);
    txt = bn_test_read_file(bin, &size);
    BN_ASSERT(txt && memcmp(txt, "BNFF", 4) == 0);
    {
        /* the layout documented in doc/formfactors.md (BNFF v2): a 64-byte typed header */
        uint64_t n, nnz, klen, tlen;
        uint32_t version, vb, layout;
        double f01;
        memcpy(&version, txt + 4, 4);
        memcpy(&n, txt + 8, 8);
        memcpy(&nnz, txt + 16, 8);
        memcpy(&vb, txt + 24, 4);
        memcpy(&layout, txt + 28, 4);
        memcpy(&klen, txt + 48, 8);
        memcpy(&tlen, txt + 56, 8);
        BN_ASSERT_EQ(version, 2);
        BN_ASSERT_EQ(n, 2);
        BN_ASSERT_EQ(nnz, 4);
        BN_ASSERT_EQ(vb, 8);
        BN_ASSERT_EQ(layout, 0);   /* full rows: dense */
        BN_ASSERT(strncmp(txt + 32, "dense-double", 16) == 0);
        BN_ASSERT_EQ(size, 64 + klen + tlen + 2 * 8 + 4 * 8);
        memcpy(&f01, txt + 64 + klen + tlen + 16 + 8, 8);
        BN_ASSERT_REL(f01, pub_parallel(1, 1, 1), BN_TOL_PUBLISHED);
    }
    free(txt);
    /* the cache: written, then reused when the key matches, never when it does not */
    snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide --cache %s", scene, cache);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    BN_ASSERT(strstr(out, "read from the cache") == NULL);
    free(out);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    BN_ASSERT(strstr(out, "read from the cache") != NULL);
    free(out);
    /* another seed: F drew no random sample (no occluder, the closed form), so the cache holds */
    snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide --cache %s --seed 7", scene, cache);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    BN_ASSERT(strstr(out, "read from the cache") != NULL);
    free(out);
    snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide --cache %s --samples 8", scene, cache);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    BN_ASSERT(strstr(out, "read from the cache") == NULL);
    free(out);
    /* other colours and lights, the same geometry: F is reused, and K takes the new reflectance */
    {
        const char *obj = bn_test_tmp("recolour.obj"), *mtl = bn_test_tmp("plates.mtl"), *csv2 = bn_test_tmp("K.csv");
        char *src = bn_test_read_file(scene, NULL), *k;
        FILE *fp = fopen(obj, "w");
        BN_ASSERT(src && fp);
        fputs(src, fp);
        fclose(fp);
        free(src);
        fp = fopen(mtl, "w");
        BN_ASSERT(fp != NULL);
        fputs("newmtl emitter\nKd 0 0 0\nKe 2 2 2\nnewmtl receiver\nKd 0.25 0.25 0.25\n", fp);
        fclose(fp);
        snprintf(cmd, sizeof cmd, "solve %s --no-subdivide --cache %s --samples 8 -n 1 -o %s", obj, cache, csv2);
        BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
        BN_ASSERT(strstr(out, "form factors read from cache") != NULL);
        free(out);
        k = bn_test_read_file(csv2, NULL);
        BN_ASSERT(k != NULL);
        /* the receiver's KE_R (the 11th column: patch,face,material,area,L_RGB,E_RGB,KE_R) is
         * rho Le F = 0.25 x 2 x 0.199824 with the cached F and the new materials */
        {
            const char *row = strstr(k, "\n1,1,receiver,");
            double ke = NAN;
            BN_ASSERT(row != NULL);
            row++;
            for (int field = 0; field < 10 && row; field++) {
                row = strchr(row, ',');
                row = row ? row + 1 : NULL;
            }
            BN_ASSERT(row != NULL);
            ke = strtod(row, NULL);
            BN_ASSERT_REL(ke, 0.25 * 2 * 0.199824, 1e-5);
        }
        free(k);
    }
    /* Monte Carlo pairs draw on the seed: the same seed hits, another one misses */
    snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide --ff montecarlo --cache %s", scene, cache);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    free(out);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    BN_ASSERT(strstr(out, "read from the cache") != NULL);
    free(out);
    snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide --ff montecarlo --cache %s --seed 7", scene, cache);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    BN_ASSERT(strstr(out, "read from the cache") == NULL);
    free(out);
    snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide --cache %s --samples 8", scene, cache);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    free(out);
    /* a corrupted F (View3D's F = 1.31) is never let through, even from a cache */
    {
        FILE *fp;
        uint64_t klen, tlen;
        float bad = 1.31f;
        txt = bn_test_read_file(cache, &size);
        BN_ASSERT(txt != NULL);
        memcpy(&klen, txt + 48, 8);
        memcpy(&tlen, txt + 56, 8);
        free(txt);
        snprintf(cmd, sizeof cmd, "formfactors %s --no-subdivide --cache %s --samples 8", scene, cache);
        fp = fopen(cache, "r+b");
        BN_ASSERT(fp != NULL);
        fseek(fp, (long)(64 + klen + tlen + 2 * 8 + 4), SEEK_SET);   /* F_01, float32 */
        fwrite(&bad, sizeof bad, 1, fp);
        fclose(fp);
        BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 5);
        BN_ASSERT(strstr(out, "F[0][1] = 1.3099999") != NULL && strstr(out, "outside [0, 1]") != NULL);
        free(out);
    }
    /* resource limit: exit 4 with the numbers and the remedies */
    snprintf(cmd, sizeof cmd, "formfactors %s --max-memory 100", scene);
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 4);
    BN_ASSERT(strstr(out, "--storage sparse") != NULL);
    free(out);
    snprintf(cmd, sizeof cmd, "formfactors %s -o %s", scene, bn_test_tmp("F.txt"));
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 2);
    free(out);
}
