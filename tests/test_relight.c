/* Relighting a solved scene on its own F (bn_pipeline_relight): new emission and reflectance, every
 * term solved again without a form factor computed. Against a fresh solve of the edited scene
 * (dense: the same answer to 1e-6 per patch, every term); under the hierarchy, against the terms the
 * test computes itself from the frozen links (K'^k E' by repeated y = rho' (F x)) and against a fresh
 * refinement for the edited scene (within the eps level: the difference between eps and 4 eps);
 * bad edits refused with the answer kept; the command line's edits reuse a cached F. */
#include "bn_test.h"

#include "bounce/pipeline.h"

#include <ctype.h>

#define BOUNCES 4

static void quiet_opts(bn_pipeline_opts *o, const char *transport, size_t patches)
{
    bn_pipeline_opts_default(o);
    o->transport = transport;
    o->mesh.target_patches = patches;
    o->ff.quiet = 1;
    o->hier.quiet = 1;
    o->solve.tol = 1e-13;
    o->solve.bounces = BOUNCES;
    o->row_sum_rays = 64;
    o->method_auto = 1;
}

/* The Cornell box's light doubled and its red wall made green-ish. */
static void edits(bn_material_edit e[2])
{
    memset(e, 0, 2 * sizeof *e);
    strcpy(e[0].material, "light");
    e[0].has_Le = 1;
    e[0].Le[0] = 34, e[0].Le[1] = 24, e[0].Le[2] = 8;
    strcpy(e[1].material, "red");
    e[1].has_rho = 1;
    e[1].rho[0] = 0.1, e[1].rho[1] = 0.6, e[1].rho[2] = 0.1;
}

static void run(const bn_pipeline_opts *o, bn_pipeline *p)
{
    bn_error err;
    if (bn_pipeline_run(bn_test_path("meshes/cornell-box.obj"), o, p, &err) != BN_OK)
        BN_FAIL("solve: %s", err.msg);
}

/* The largest |a - b| per patch relative to max(|b|, floor x the layer's largest). */
static double max_rel(const double *a, const double *b, size_t n3, double floor)
{
    double top = 0, worst = 0;
    for (size_t k = 0; k < n3; k++)
        top = fmax(top, fabs(b[k]));
    for (size_t k = 0; k < n3; k++)
        worst = fmax(worst, fabs(a[k] - b[k]) / fmax(fabs(b[k]), floor * top));
    return worst;
}

static double rms_diff(const double *a, const double *b, size_t n3)
{
    double s = 0;
    for (size_t k = 0; k < n3; k++)
        s += (a[k] - b[k]) * (a[k] - b[k]);
    return sqrt(s / (double)n3);
}

/* Every term, rest and L of p against q. */
static void same_answer(const bn_pipeline *p, const bn_pipeline *q, double tol)
{
    BN_ASSERT_EQ(p->n, q->n);
    BN_ASSERT_EQ(p->res.nterms, q->res.nterms);
    for (size_t k = 0; k < (size_t)p->res.nterms; k++) {
        double d = max_rel(p->res.terms[k], q->res.terms[k], 3 * p->n, 1e-9);
        if (!(d <= tol))
            BN_FAIL("term K^%zu E: relit and fresh differ by %.3g relative (tolerance %g)", k, d, tol);
    }
    BN_ASSERT_LE(max_rel(p->rest, q->rest, 3 * p->n, 1e-9), tol);
    BN_ASSERT_LE(max_rel(p->res.L, q->res.L, 3 * p->n, 1e-9), tol);
}

BN_TEST(dense_relight_equals_a_fresh_solve_of_the_edited_scene)
{
    bn_pipeline_opts o;
    bn_pipeline p, q;
    bn_material_edit e[2];
    bn_error err;
    quiet_opts(&o, "dense", 200);
    run(&o, &p);
    double *L0 = malloc(3 * p.n * sizeof *L0);
    memcpy(L0, p.res.L, 3 * p.n * sizeof *L0);
    edits(e);
    if (bn_pipeline_relight(&o, &p, e, 2, 0, &err) != BN_OK)
        BN_FAIL("relight: %s", err.msg);
    BN_ASSERT_GT(max_rel(p.res.L, L0, 3 * p.n, 1e-9), 0.5);   /* the edit changed the answer */
    BN_ASSERT_GT(p.relight_gain, 2 * 0.6 / 0.065 * 0.9);   /* the red wall's green under a doubled light */
    o.load.edits = e;
    o.load.nedits = 2;
    run(&o, &q);   /* F computed again for the edited file */
    same_answer(&p, &q, 1e-6);
    /* a Neumann relight reads its spectral radius from its terms, no power steps
     * (bn_solve_opts.power_lazy): within 1% of the fresh solve's power iteration on the same K */
    o.method_auto = 0;
    o.solve.method = BN_SOLVE_NEUMANN;
    if (bn_pipeline_relight(&o, &p, e, 2, 0, &err) != BN_OK)
        BN_FAIL("relight: %s", err.msg);
    same_answer(&p, &q, 1e-6);
    BN_ASSERT_EQ(p.res.power_iterations, 0);
    BN_ASSERT_GT(q.res.power_iterations, 2);
    BN_ASSERT_LE(fabs(p.res.spectral_radius - q.res.spectral_radius), 0.01 * q.res.spectral_radius);
    free(L0);
    bn_pipeline_free(&p);
    bn_pipeline_free(&q);
}

/* The terms from the frozen links by the test's own loop: x_0 = E', x_{k+1} = rho' (F x_k). */
static void own_terms(const bn_pipeline *p, double tol)
{
    size_t n3 = 3 * p->n;
    double *x = malloc(n3 * sizeof *x), *y = malloc(n3 * sizeof *y), *rho = malloc(n3 * sizeof *rho);
    double *L = calloc(n3, sizeof *L);
    bn_error err;
    bn_scene_patch_emission(p->scene, x);
    bn_scene_patch_reflectance(p->scene, rho);
    for (int k = 0; k < 400; k++) {
        if (k < (int)p->res.nterms)
            BN_ASSERT_LE(max_rel(p->res.terms[k], x, n3, 1e-9), tol);
        for (size_t i = 0; i < n3; i++)
            L[i] += x[i];
        if (bn_transport_apply_F(p->k, x, y, &err) != BN_OK)
            BN_FAIL("apply: %s", err.msg);
        for (size_t i = 0; i < n3; i++)
            x[i] = rho[i] * y[i];
    }
    BN_ASSERT_LE(max_rel(p->res.L, L, n3, 1e-9), 1e-9);
    free(x), free(y), free(rho), free(L);
}

BN_TEST(hierarchy_relight_is_a_solve_on_the_same_links)
{
    bn_pipeline_opts o;
    bn_pipeline p, q, q4, r;
    bn_material_edit e[2];
    bn_error err;
    quiet_opts(&o, "hierarchical", 600);
    run(&o, &p);
    size_t links = p.hier.links;
    edits(e);
    if (bn_pipeline_relight(&o, &p, e, 2, 0, &err) != BN_OK)
        BN_FAIL("relight: %s", err.msg);
    BN_ASSERT_EQ(p.hier.links, links);   /* frozen */
    own_terms(&p, 1e-9);
    o.load.edits = e;   /* fresh refinements for the edited scene, at eps and at 4 eps */
    o.load.nedits = 2;
    run(&o, &q);
    o.hier.eps *= 4;
    run(&o, &q4);
    double frozen = rms_diff(p.res.L, q.res.L, 3 * p.n), level = rms_diff(q4.res.L, q.res.L, 3 * p.n);
    fprintf(stderr, "RMS L: frozen links - fresh %.3g, eps level (4 eps - eps) %.3g\n", frozen, level);
    BN_ASSERT_LE(frozen, level);
    o.hier.eps /= 4;   /* refine 1: links made for the new light, the fresh refinement's answer */
    o.load.nedits = 0;
    o.keep_rt = 1;     /* its ray scene made again, the old one released (the sanitized run's leak check) */
    run(&o, &r);
    if (bn_pipeline_relight(&o, &r, e, 2, 1, &err) != BN_OK)
        BN_FAIL("relight with refine: %s", err.msg);
    BN_ASSERT_EQ(r.hier.links, q.hier.links);
    same_answer(&r, &q, 1e-12);
    bn_pipeline_free(&p), bn_pipeline_free(&q), bn_pipeline_free(&q4), bn_pipeline_free(&r);
}

BN_TEST(bad_edits_are_refused_and_the_answer_kept)
{
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_material_edit e[2];
    bn_error err;
    quiet_opts(&o, "dense", 100);
    run(&o, &p);
    double L0 = p.res.L[0];
    edits(e);
    strcpy(e[1].material, "blue");
    BN_ASSERT_STATUS(bn_pipeline_relight(&o, &p, e, 2, 0, &err), BN_EUSAGE);
    BN_ASSERT(strstr(err.msg, "'blue'") && strstr(err.msg, "red"));
    edits(e);
    e[1].rho[1] = 1.5;
    BN_ASSERT_STATUS(bn_pipeline_relight(&o, &p, e, 2, 0, &err), BN_EUSAGE);
    BN_ASSERT(strstr(err.msg, "1.5"));
    edits(e);
    e[0].Le[2] = -1;
    BN_ASSERT_STATUS(bn_pipeline_relight(&o, &p, e, 2, 0, &err), BN_EUSAGE);
    BN_ASSERT(strstr(err.msg, "-1"));
    e[0].Le[2] = NAN;
    BN_ASSERT_STATUS(bn_pipeline_relight(&o, &p, e, 2, 0, &err), BN_EUSAGE);
    size_t nm;   /* nothing applied: the light and the red wall as the file has them, the answer kept */
    const bn_material *m = bn_scene_materials(p.scene, &nm);
    BN_ASSERT_EQ(m[3].Le[0], 17);
    BN_ASSERT_EQ(m[1].rho[1], 0.065);
    BN_ASSERT_EQ(p.res.L[0], L0);
    bn_pipeline_free(&p);
}

/* The sum of the L_R column of a `bounce solve` CSV. */
static double csv_sum_L(const char *path)
{
    char *text = bn_test_read_file(path, NULL), *line, *save = NULL;
    double sum = 0;
    int col = -1;
    BN_ASSERT(text);
    for (line = strtok_r(text, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
        if (line[0] == '#')
            continue;
        char *f, *s2 = NULL;
        int c = 0;
        for (f = strtok_r(line, ",", &s2); f; f = strtok_r(NULL, ",", &s2), c++) {
            if (col < 0 && !strcmp(f, "L_R"))
                col = c;
            else if (col >= 0 && c == col && isdigit((unsigned char)f[0]))
                sum += atof(f);
        }
    }
    BN_ASSERT_GE(col, 0);
    free(text);
    return sum;
}

BN_TEST(cli_edits_reuse_a_cached_F)
{
    char args[1024], *out = NULL;
    const char *F = bn_test_tmp("F.bnff"), *scene = bn_test_path("meshes/cornell-box.obj");
    const char *ed = "--set-Le light=34,24,8 --set-rho red=0.1,0.6,0.1";
    snprintf(args, sizeof args, "solve %s --patches 200 --tol 1e-10 --cache %s -o %s", scene, F, bn_test_tmp("a.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, NULL), 0);
    snprintf(args, sizeof args, "solve %s --patches 200 --tol 1e-10 --cache %s %s -o %s", scene, F, ed,
             bn_test_tmp("b.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 0);
    BN_ASSERT(strstr(out, "read from cache"));
    free(out);
    snprintf(args, sizeof args, "solve %s --patches 200 --tol 1e-10 %s -o %s", scene, ed, bn_test_tmp("c.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, NULL), 0);
    double a = csv_sum_L(bn_test_tmp("a.csv")), b = csv_sum_L(bn_test_tmp("b.csv")), c = csv_sum_L(bn_test_tmp("c.csv"));
    BN_ASSERT_GT(b, 1.5 * a);   /* the light doubled */
    BN_ASSERT_REL(b, c, 1e-6);  /* the cached F relit as the fresh one */
    snprintf(args, sizeof args, "solve %s --patches 50 --set-rho blue=0.5 -o %s", scene, bn_test_tmp("d.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 2);
    BN_ASSERT(strstr(out, "'blue' is not a material"));
    free(out);
    snprintf(args, sizeof args, "solve %s --patches 50 --set-Le light=-3 -o %s", scene, bn_test_tmp("d.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 2);
    BN_ASSERT(strstr(out, "-3"));
    BN_ASSERT(!bn_test_file_exists(bn_test_tmp("d.csv")));
    free(out);
}
