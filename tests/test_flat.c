/* The flat C API for bindings (include/bounce/flat.h), under the sanitizers too (the Python tests
 * cannot load the sanitized library): the furnace's closed form, the stages, a caller's operator,
 * errors, the monitor's history. */
#include "bn_test.h"
#include "bounce/flat.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

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
