/* The flat C API for bindings (include/bounce/flat.h), under the sanitizers too (the Python tests
 * cannot load the sanitized library): the furnace's closed form, the stages, a caller's operator,
 * errors, the monitor's history. */
#include "bn_test.h"
#include "bounce/flat.h"
#include "bounce/bake.h"
#include "bounce/gather.h"
#include "bounce/pipeline.h"
#include "bounce/study.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* One vocabulary: names() lists `count` names (the enum's size, counted from the header), each
 * parses to its position and names itself; `anchor` parses to the enumerator `value` the header
 * gives it; a made-up name does not parse; a value past the end is "?". */
#define CHECK_VOCABULARY(P, T, count, anchor, value)                                                \
    do {                                                                                            \
        char list[256], *save = NULL;                                                               \
        int i = 0;                                                                                  \
        T v;                                                                                        \
        snprintf(list, sizeof list, "%s", P##_names());                                             \
        for (char *t = strtok_r(list, "|", &save); t; t = strtok_r(NULL, "|", &save), i++) {        \
            BN_ASSERT_EQ(P##_parse(t, &v), 0);                                                      \
            BN_ASSERT_EQ((int)v, i);                                                                \
            BN_ASSERT(strcmp(P##_name(v), t) == 0);                                                 \
        }                                                                                           \
        BN_ASSERT_EQ(i, (int)(count));                                                              \
        BN_ASSERT_EQ(P##_parse(anchor, &v), 0);                                                     \
        BN_ASSERT_EQ((int)v, (int)(value));                                                         \
        BN_ASSERT_EQ(P##_parse("no-such-name", &v), -1);                                            \
        BN_ASSERT_EQ(P##_parse(NULL, &v), -1);                                                      \
        BN_ASSERT(strcmp(P##_name((T)(count)), "?") == 0);                                          \
    } while (0)

/* Every vocabulary is one table: its list, its parse and its names agree, and the flat API hands
 * bindings the same lists. */
BN_TEST(vocabularies_list_parse_and_name_agree)
{
    CHECK_VOCABULARY(bn_solve_method, bn_solve_method, BN_SOLVE_DIRECT + 1, "gauss-seidel", BN_SOLVE_GAUSS_SEIDEL);
    CHECK_VOCABULARY(bn_solve_stop, bn_solve_stop, BN_SOLVE_STOP_PATCH + 1, "bound", BN_SOLVE_STOP_BOUND);
    CHECK_VOCABULARY(bn_ff_method, bn_ff_method, BN_FF_HEMISPHERE + 1, "hemisphere", BN_FF_HEMISPHERE);
    CHECK_VOCABULARY(bn_precision, bn_precision, BN_PRECISION_DOUBLE + 1, "double", BN_PRECISION_DOUBLE);
    CHECK_VOCABULARY(bn_unit, bn_unit, BN_UNIT_MM + 1, "mm", BN_UNIT_MM);
    CHECK_VOCABULARY(bn_trace_strategy, bn_trace_strategy, BN_TRACE_NEE + 1, "nee", BN_TRACE_NEE);
    CHECK_VOCABULARY(bn_trace_model, bn_trace_model, BN_TRACE_PATCH + 1, "patch", BN_TRACE_PATCH);
    CHECK_VOCABULARY(bn_disc, bn_disc, BN_DISC_NONE + 1, "fine", BN_DISC_FINE);
    CHECK_VOCABULARY(bn_gather_mode, bn_gather_mode, BN_GATHER_NONE + 1, "none", BN_GATHER_NONE);
    CHECK_VOCABULARY(bn_bake_mesh, bn_bake_mesh, BN_BAKE_INPUT + 1, "input", BN_BAKE_INPUT);
    CHECK_VOCABULARY(bn_study_param, bn_study_param, BN_STUDY_PARAM_COUNT, "eps", BN_STUDY_EPS);
    CHECK_VOCABULARY(bn_study_ref, bn_study_ref, BN_STUDY_REF_TRACE + 1, "trace", BN_STUDY_REF_TRACE);
    CHECK_VOCABULARY(bn_study_metric, bn_study_metric, BN_STUDY_METRIC_PATCH + 1, "patch", BN_STUDY_METRIC_PATCH);
    BN_ASSERT(strcmp(bn_flat_names("method"), bn_solve_method_names()) == 0);
    BN_ASSERT(strcmp(bn_flat_names("gather"), bn_gather_mode_names()) == 0);
    BN_ASSERT(strcmp(bn_flat_names("transport"), "auto|dense|sparse|hierarchical") == 0);
    BN_ASSERT(strcmp(bn_flat_names("storage"), "dense|sparse") == 0);
    BN_ASSERT(bn_flat_names("colour") == NULL && bn_flat_names(NULL) == NULL);
}

static const char *furnace(void) { return bn_test_path("meshes/furnace-box.obj"); }

BN_TEST(furnace_closed_form_and_history)
{
    bn_flat_opts o;
    bn_flat *f = NULL;
    char msg[512];
    const double *h;
    size_t n, rows;
    bn_flat_opts_default(&o);
    o.method = "jacobi";
    o.patches = 96;
    o.bounces = 4;
    o.tol = 1e-10;
    BN_ASSERT_EQ(bn_flat_solve(furnace(), &o, &f, msg, sizeof msg), BN_OK);
    n = bn_flat_patches(f);
    BN_ASSERT_GE(n, 96);
    BN_ASSERT_EQ(bn_flat_terms(f), 5);
    for (size_t i = 0; i < 3 * n; i++) {   /* rho 0.5, Le 1: L = 2, K^k E = 0.5^k */
        BN_ASSERT_NEAR(bn_flat_L(f)[i], 2.0, 1e-8);
        for (int k = 0; k < 5; k++)
            BN_ASSERT_NEAR(bn_flat_term(f, k)[i], ldexp(1.0, -k), 1e-6 * ldexp(1.0, -k));
        BN_ASSERT_NEAR(bn_flat_rest(f)[i], 2.0 - (1 + 0.5 + 0.25 + 0.125 + 0.0625), 1e-8);
    }
    BN_ASSERT(bn_flat_term(f, 5) == NULL);
    BN_ASSERT(strcmp(bn_flat_method(f), "jacobi") == 0);
    rows = bn_flat_history(f, &h);
    BN_ASSERT_EQ(rows, bn_flat_iterations(f) + 1);
    for (size_t r = 2; r < rows && r < 12; r++)   /* the residual falls by rho each iteration */
        BN_ASSERT_NEAR(h[7 * r + 1] / h[7 * (r - 1) + 1], 0.5, 1e-3);
    bn_flat_free(f);
}

BN_TEST(stages_and_form_factors)
{
    bn_flat_opts o;
    bn_flat *f = NULL;
    char msg[512];
    double d[12], *F, *area;
    size_t n;
    bn_flat_opts_default(&o);
    o.patches = 54;
    BN_ASSERT_EQ(bn_flat_load(furnace(), &o, &f, msg, sizeof msg), BN_OK);
    n = bn_flat_patches(f);
    BN_ASSERT(bn_flat_L(f) == NULL);
    bn_flat_ff_diagnostics(f, d);
    BN_ASSERT(isnan(d[1]));
    BN_ASSERT_EQ(bn_flat_operator(f, msg, sizeof msg), BN_OK);
    bn_flat_ff_diagnostics(f, d);
    BN_ASSERT_NEAR(d[1], 1.0, 1e-6);   /* row_sum_max of a closed cube */
    F = malloc(n * n * sizeof(double));
    area = malloc(n * sizeof(double));
    BN_ASSERT_EQ(bn_flat_form_factors(f, F, msg, sizeof msg), BN_OK);
    bn_flat_patch_data(f, area, NULL, NULL, NULL, NULL);
    for (size_t i = 0; i < n; i++) {
        double s = 0;
        for (size_t j = 0; j < n; j++) {
            s += F[i * n + j];
            BN_ASSERT_NEAR(area[i] * F[i * n + j], area[j] * F[j * n + i], 1e-6 * area[i]);
        }
        BN_ASSERT_NEAR(s, 1.0, 1e-6);
    }
    free(F);
    free(area);
    bn_flat_free(f);
}

/* K = rho times the mean over all patches (a furnace in which every patch sees all others alike) */
static int mean_op(void *user, const double *x, double *y)
{
    size_t n = *(size_t *)user;
    double m[3] = {0, 0, 0};
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++)
            m[c] += x[3 * i + c] / (double)n;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++)
            y[3 * i + c] = 0.8 * m[c];
    return 0;
}

static int failing_op(void *user, const double *x, double *y)
{
    (void)user, (void)x, (void)y;
    return 7;
}

BN_TEST(caller_operator)
{
    size_t n = 10;
    double E[30];
    bn_flat_opts o;
    bn_flat *f = NULL;
    char msg[512];
    for (int i = 0; i < 30; i++)
        E[i] = 1;
    bn_flat_opts_default(&o);
    o.tol = 1e-12;
    BN_ASSERT_EQ(bn_flat_solve_operator(n, E, mean_op, NULL, &n, &o, &f, msg, sizeof msg), BN_OK);
    for (size_t i = 0; i < 3 * n; i++)
        BN_ASSERT_NEAR(bn_flat_L(f)[i], 1 / (1 - 0.8), 1e-10);
    BN_ASSERT_NEAR(bn_flat_term(f, 2)[0], 0.64, 1e-14);
    bn_flat_free(f);
    BN_ASSERT_EQ(bn_flat_solve_operator(n, E, failing_op, NULL, &n, &o, &f, msg, sizeof msg), BN_EINPUT);
    BN_ASSERT(f == NULL && strstr(msg, "returned 7") != NULL);
    o.method = "direct";
    BN_ASSERT(bn_flat_solve_operator(n, E, mean_op, NULL, &n, &o, &f, msg, sizeof msg) != BN_OK);
    BN_ASSERT(f == NULL && msg[0] != '\0');
}

BN_TEST(errors_carry_the_message)
{
    bn_flat_opts o;
    bn_flat *f = (bn_flat *)1;
    char msg[512];
    bn_flat_opts_default(&o);
    BN_ASSERT_EQ(bn_flat_solve("/nonexistent/scene.obj", &o, &f, msg, sizeof msg), BN_EIO);
    BN_ASSERT(f == NULL && strstr(msg, "/nonexistent/scene.obj") != NULL);
    o.unit = "furlong";
    BN_ASSERT_EQ(bn_flat_solve(furnace(), &o, &f, msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(strstr(msg, "furlong") != NULL);
    bn_flat_opts_default(&o);
    o.transport = "telepathy";
    BN_ASSERT_EQ(bn_flat_load(furnace(), &o, &f, msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(strstr(msg, "telepathy") != NULL);
    bn_flat_free(NULL);
}

/* The command line's further options by their field names (bn_flat_opts.more, bn_flat_set): taken where
 * they belong, refused by name elsewhere or out of range, and they act (no_subdivide: one patch per face). */
BN_TEST(further_options_by_name)
{
    bn_flat_opts o;
    bn_flat *f = NULL;
    char msg[512];
    size_t cut;
    bn_flat_opts_default(&o);
    o.patches = 48;
    o.visibility = "rays";
    BN_ASSERT_EQ(bn_flat_load(furnace(), &o, &f, msg, sizeof msg), BN_OK);
    cut = bn_flat_patches(f);
    bn_flat_free(f);
    o.more = "no_subdivide=1\ncontact_gap=0.001";
    BN_ASSERT_EQ(bn_flat_load(furnace(), &o, &f, msg, sizeof msg), BN_OK);
    BN_ASSERT(bn_flat_patches(f) < cut);
    BN_ASSERT_EQ(bn_flat_set(f, "gather_samples=16\nup=0,0,1\nflat=1\nbake_tol=0.1", msg, sizeof msg), BN_OK);
    BN_ASSERT_EQ(bn_flat_set(f, "tile=8", msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(strstr(msg, "`tile`: 8 is outside [16, 4096]") != NULL);
    BN_ASSERT_EQ(bn_flat_set(f, "up=0,1", msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(strstr(msg, "not three numbers") != NULL);
    BN_ASSERT_EQ(bn_flat_set(f, "no_contacts=1", msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(strstr(msg, "`no_contacts` is an option of the scene") != NULL);
    o.more = "no_contacts=1";   /* a loaded scene keeps its patches and F: refused at its solve */
    BN_ASSERT_EQ(bn_flat_solve_loaded(f, &o, msg, sizeof msg), BN_EUSAGE);
    bn_flat_free(f);
    const char *bad[][2] = {{"samples=0", "outside"}, {"samples=2.5", "whole number"}, {"gather_rays=9", "of the bake"},
                            {"orient=up", "normals|winding"}, {"telepathy=1", "no option `telepathy`"},
                            {"contact_gap", "no option `contact_gap`"}, {"min_area=x", "not a number"}};
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
        f = (bn_flat *)1;
        o.more = bad[i][0];
        BN_ASSERT_EQ(bn_flat_load(furnace(), &o, &f, msg, sizeof msg), BN_EUSAGE);
        BN_ASSERT(f == NULL && strstr(msg, bad[i][1]) != NULL);
    }
    char longline[800];   /* a line the parser cannot hold is refused, never cut short */
    memset(longline, 'a', sizeof longline - 1);
    memcpy(longline, "two_sided=", 10);
    longline[sizeof longline - 1] = '\0';
    f = (bn_flat *)1;
    o.more = longline;
    BN_ASSERT_EQ(bn_flat_load(furnace(), &o, &f, msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(f == NULL && strstr(msg, "longer than") != NULL);
    BN_ASSERT(strstr(bn_flat_names("image_options"), "gather_filter") && strstr(bn_flat_names("bake_options"), "flat"));
}

/* The tracer and the cross-check through the flat API, in the furnace (rho 0.5, Le 1): bounce k is
 * 0.5^k everywhere, so every patch's estimate is within 6 of its standard errors of it and the mean
 * over pixels within 5%; radiosity agrees, so the cross-check passes; bad options are refused with a
 * message. */
BN_TEST(tracer_and_crosscheck_in_the_furnace)
{
    bn_flat_opts o;
    bn_flat *f = NULL;
    bn_flat_check *c = NULL;
    char msg[512];
    double fig[BN_FLAT_CHECK_FIGURES], *mean, *se;
    float *im, *var;
    size_t n;
    bn_flat_opts_default(&o);
    o.patches = 48;
    o.bounces = 2;
    BN_ASSERT_EQ(bn_flat_load(furnace(), &o, &f, msg, sizeof msg), BN_OK);   /* a scene, not solved */
    n = bn_flat_patches(f);
    mean = malloc(5 * n * 3 * sizeof *mean);
    se = malloc(5 * n * 3 * sizeof *se);
    BN_ASSERT_EQ(bn_flat_trace_patches(f, 64, 2, 1, 0, mean, se, msg, sizeof msg), BN_OK);
    for (size_t i = 0; i < 3 * n; i++)
        for (int k = 0; k < 3; k++)
            BN_ASSERT_NEAR(mean[(size_t)k * 3 * n + i], ldexp(1.0, -k), 6 * se[(size_t)k * 3 * n + i] + 1e-12);
    BN_ASSERT_EQ(bn_flat_trace_patches(f, 0, 2, 1, 0, mean, se, msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(strstr(msg, "spp 0") != NULL);
    im = malloc(5 * 8 * 6 * 3 * sizeof *im);
    var = malloc(5 * 8 * 6 * 3 * sizeof *var);
    const double eye[3] = {0.5, 0.5, 0.5}, look[3] = {0.5, 0.5, 1};   /* inside: the faces' fronts */
    BN_ASSERT_EQ(bn_flat_trace_image(f, 8, 6, 4, 2, 1, eye, look, 0, 0, im, var, msg, sizeof msg), BN_OK);
    double ke = 0;
    for (size_t p = 0; p < 8 * 6 * 3; p++)
        ke += im[8 * 6 * 3 + p] / (8 * 6 * 3);
    BN_ASSERT_NEAR(ke, 0.5, 0.025);   /* KE over the pixels */
    free(mean), free(se), free(im), free(var);
    bn_flat_free(f);
    BN_ASSERT_EQ(bn_flat_crosscheck(furnace(), &o, 64, 2, 0, "patch", &c, msg, sizeof msg), BN_OK);
    BN_ASSERT(bn_flat_check_pass(c));
    BN_ASSERT_EQ(bn_flat_check_layers(c), 5);
    bn_flat_check_figures(c, fig);
    BN_ASSERT_EQ(fig[0], (double)(5 * 3 * bn_flat_check_entries(c)));   /* the family: layers x entries x 3 */
    bn_flat_check_free(c);
    BN_ASSERT_EQ(bn_flat_crosscheck(furnace(), &o, 64, 2, 0, "mesh", &c, msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(c == NULL && strstr(msg, "'mesh'") != NULL);
}

/* The study through the flat API in the furnace (rho 0.5, Le 1, L 2): the series cut after K^n E misses
 * 2 x 0.5^(n+1) = 0.5^n everywhere, the truncated rows' err_inf; a parameter that is not one is refused. */
BN_TEST(study_in_the_furnace)
{
    bn_flat_opts o;
    bn_flat_study *s = NULL;
    char msg[512];
    const double n[] = {0, 1, 3};
    double row[BN_FLAT_STUDY_NCOLUMNS];
    size_t found = 0;
    bn_flat_opts_default(&o);
    o.patches = 48;
    BN_ASSERT_EQ(bn_flat_study_run(furnace(), &o, "bounces", n, 3, &s, msg, sizeof msg), BN_OK);
    BN_ASSERT(strncmp(bn_flat_study_columns(), "x,patches,", 10) == 0);
    for (size_t r = 0; r < bn_flat_study_rows(s); r++) {
        if (strcmp(bn_flat_study_label(s, r, 0), "truncated") != 0)
            continue;
        bn_flat_study_row(s, r, row);
        BN_ASSERT_NEAR(row[6], ldexp(1.0, -(int)row[0]), 1e-6);   /* err_inf */
        found++;
    }
    BN_ASSERT_EQ(found, 3);
    BN_ASSERT(strlen(bn_flat_study_reference(s, NULL)) > 0);
    bn_flat_study_free(s);
    BN_ASSERT_EQ(bn_flat_study_run(furnace(), &o, "colour", n, 3, &s, msg, sizeof msg), BN_EUSAGE);
    BN_ASSERT(s == NULL && strstr(msg, "'colour'") != NULL);
}
