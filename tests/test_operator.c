/* The operator interface from outside: an operator written here, with no storage behind it, runs
 * through every solver and gives the analytic answer; operators that fail or are interrupted
 * mid-apply stop every solver with their status and leave no answer; solvers say what an operator
 * lacks; the builder keeps what it is given in every storage.
 *
 * The matrix-free operator is the interior of a sphere cut into patches: every point of a sphere
 * sees every other with the same kernel, so F_ij = A_j / A (A the total area) for every i, j,
 * including i = j (a concave patch sees itself). Then F x = <x> (the area-weighted mean) for every
 * row, and with K = diag(rho) F:
 *   K^k E = rho^k <E>  (k >= 1, rho per channel, uniform),   L = E + rho <E> / (1 - rho),
 * so with E = Le on every patch, L = Le / (1 - rho) and K^k E = rho^k Le. */
#include "bn_test.h"
#include "bounce/solve.h"

#include <stdint.h>

/* ---- the sphere interior as a user operator ---- */

typedef struct sphere {
    size_t n;
    double *A, total;
    int fail_at;        /* apply number that fails (0: never) */
    bn_status fail_with;
    int calls;          /* apply calls so far */
    int row_fail_at;    /* row call that fails (0: never) */
    int row_calls;
    int nan_at;         /* apply number whose output holds a NaN (0: never) */
    int row_nan_at;     /* row call whose output is NaN (0: never) */
    int entry_nan;      /* 1: entry (n/2, n/2) is NaN */
    int destroyed;
} sphere;

/* <x>_c = sum_j A_j x_jc / A */
static void area_mean(const sphere *s, const double *x, double m[3])
{
    m[0] = m[1] = m[2] = 0;
    for (size_t j = 0; j < s->n; j++)
        for (int c = 0; c < 3; c++)
            m[c] += s->A[j] * x[3 * j + c];
    for (int c = 0; c < 3; c++)
        m[c] /= s->total;
}

static bn_status sphere_apply(void *ctx, const double *x, double *y, bn_error *err)
{
    sphere *s = ctx;
    double m[3];
    if (++s->calls == s->fail_at)
        return bn_error_set(err, s->fail_with, "sphere operator: apply %d failed on purpose", s->calls);
    area_mean(s, x, m);
    for (size_t i = 0; i < s->n; i++)
        for (int c = 0; c < 3; c++)
            y[3 * i + c] = m[c];
    if (s->calls == s->nan_at)
        y[3 * (s->n / 2) + 1] = NAN;   /* one entry, in the middle, green */
    return BN_OK;
}

static bn_status sphere_row(void *ctx, size_t i, const double *x, double out[3], bn_error *err)
{
    sphere *s = ctx;
    (void)i;
    if (++s->row_calls == s->row_fail_at)
        return bn_error_set(err, s->fail_with, "sphere operator: row %d failed on purpose", s->row_calls);
    area_mean(s, x, out);
    if (s->row_calls == s->row_nan_at)
        out[2] = NAN;
    return BN_OK;
}

static bn_status sphere_entry(void *ctx, size_t i, size_t j, double *v, bn_error *err)
{
    sphere *s = ctx;
    (void)err;
    *v = s->entry_nan && i == s->n / 2 && j == i ? NAN : s->A[j] / s->total;
    return BN_OK;
}

static bn_status sphere_diag(void *ctx, double *d, bn_error *err)
{
    sphere *s = ctx;
    (void)err;
    for (size_t i = 0; i < s->n; i++)
        d[i] = s->A[i] / s->total;
    return BN_OK;
}

static size_t sphere_bytes(const void *ctx)
{
    const sphere *s = ctx;
    return s->n * sizeof(double);
}

static void sphere_destroy(void *ctx)
{
    sphere *s = ctx;
    s->destroyed++;
}

static const bn_transport_ops sphere_full = {
    "sphere-test", BN_OP_ROWS | BN_OP_ENTRIES | BN_OP_DIAG, sphere_apply, sphere_row, sphere_entry, NULL,
    sphere_diag, sphere_bytes, sphere_destroy, NULL};
static const bn_transport_ops sphere_apply_only = {"sphere-apply-only", 0, sphere_apply, NULL, NULL, NULL, NULL,
                                                   NULL, sphere_destroy, NULL};

/* n patches with areas from 0.1 to 10 (a deterministic spread), rho per channel. */
static void sphere_init(sphere *s, size_t n)
{
    memset(s, 0, sizeof *s);
    s->n = n;
    s->A = malloc(n * sizeof(double));
    for (size_t i = 0; i < n; i++) {
        s->A[i] = 0.1 + 9.9 * (double)((i * 7919) % n) / (double)n;
        s->total += s->A[i];
    }
    s->fail_with = BN_ENUMERIC;
}

static const double RHO[3] = {0.9, 0.5, 0.25};

static bn_transport *sphere_k(sphere *s, const bn_transport_ops *ops)
{
    bn_transport *k = NULL;
    bn_error err;
    double *rho = malloc(3 * s->n * sizeof(double));
    for (size_t i = 0; i < s->n; i++)
        memcpy(rho + 3 * i, RHO, sizeof RHO);
    if (bn_transport_create(s->n, rho, ops, s, &k, &err) != BN_OK)
        BN_FAIL("create: %s", err.msg);
    free(rho);
    return k;
}

static bn_solve_opts solve_opts(bn_solve_method m, int symmetric)
{
    bn_solve_opts o;
    bn_solve_opts_default(&o);
    o.method = m;
    o.symmetric = symmetric;
    o.tol = 1e-15;
    o.atol = 1e-300;
    o.bounces = 6;
    o.quiet = 1;
    return o;
}

#define N_SPHERE 40
/* Every method, every channel, every term: the analytic answer to 1e-12. */
static void sphere_case(const bn_transport_ops *ops, const bn_solve_method *methods, size_t nm, int nonuniform)
{
    sphere s;
    bn_transport *k;
    double *E = malloc(3 * N_SPHERE * sizeof(double)), mE[3];
    sphere_init(&s, N_SPHERE);
    k = sphere_k(&s, ops);
    for (size_t i = 0; i < N_SPHERE; i++)
        for (int c = 0; c < 3; c++)
            E[3 * i + c] = nonuniform ? (i % 3 == 0 ? 5.0 + (double)c : 0.0) : 1.0;
    area_mean(&s, E, mE);
    for (size_t q = 0; q < nm; q++)
        for (int sym = 0; sym <= (methods[q] == BN_SOLVE_GAUSS_SEIDEL); sym++) {
            bn_solve_opts o = solve_opts(methods[q], sym);
            bn_solve_result res;
            bn_error err;
            if (bn_solve(k, E, &o, &res, &err) != BN_OK)
                BN_FAIL("%s%s on %s: %s", bn_solve_method_name(methods[q]), sym ? " (symmetric)" : "", ops->name,
                        err.msg);
            BN_ASSERT_EQ(res.nterms, 7);
            for (size_t i = 0; i < N_SPHERE; i++)
                for (int c = 0; c < 3; c++) {
                    size_t x = 3 * i + (size_t)c;
                    double L = E[x] + RHO[c] * mE[c] / (1 - RHO[c]), rk = 1;
                    BN_ASSERT_REL(res.L[x], L, 1e-12);
                    BN_ASSERT_EQ(res.terms[0][x], E[x]);
                    for (int t = 1; t < res.nterms; t++) {
                        rk *= RHO[c];
                        BN_ASSERT_REL(res.terms[t][x], rk * mE[c], 1e-12);
                    }
                }
            /* ||K||_inf = max rho (rows of F sum to 1); spectral radius the same */
            BN_ASSERT_REL(res.k_norm_inf, RHO[0], 1e-14);
            BN_ASSERT_REL(res.spectral_radius, RHO[0], 1e-9);
            bn_solve_result_free(&res);
        }
    bn_transport_destroy(k);
    BN_ASSERT_EQ(s.destroyed, 1);
    free(s.A);
    free(E);
}

static const bn_solve_method ALL[] = {BN_SOLVE_JACOBI, BN_SOLVE_GAUSS_SEIDEL, BN_SOLVE_NEUMANN, BN_SOLVE_DIRECT};

BN_TEST(matrix_free_sphere_uniform_every_method) { sphere_case(&sphere_full, ALL, 4, 0); }
BN_TEST(matrix_free_sphere_nonuniform_every_method) { sphere_case(&sphere_full, ALL, 4, 1); }

/* Apply alone serves Jacobi and the series (no diagonal: they iterate L <- E + K L). */
BN_TEST(matrix_free_apply_only_jacobi_neumann)
{
    const bn_solve_method m[] = {BN_SOLVE_JACOBI, BN_SOLVE_NEUMANN};
    sphere_case(&sphere_apply_only, m, 2, 1);
}

/* What the operator lacks is named, with what would serve instead; nothing is left in res. */
BN_TEST(solvers_say_what_the_operator_lacks)
{
    sphere s;
    bn_transport *k;
    double E[3 * N_SPHERE];
    const bn_solve_method m[] = {BN_SOLVE_GAUSS_SEIDEL, BN_SOLVE_DIRECT};
    const char *lack[] = {"row access", "single entries"};
    sphere_init(&s, N_SPHERE);
    k = sphere_k(&s, &sphere_apply_only);
    for (size_t i = 0; i < 3 * N_SPHERE; i++)
        E[i] = 1;
    for (int q = 0; q < 2; q++) {
        bn_solve_opts o = solve_opts(m[q], 0);
        bn_solve_result res;
        bn_error err;
        BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_ENOTSUP);
        fprintf(stderr, "%s: %s\n", bn_solve_method_name(m[q]), err.msg);
        BN_ASSERT(strstr(err.msg, lack[q]) != NULL);
        BN_ASSERT(strstr(err.msg, "sphere-apply-only") != NULL);
        BN_ASSERT(res.L == NULL && res.terms == NULL);
        BN_ASSERT_EQ(s.calls, 0);   /* refused before any work */
    }
    BN_ASSERT_EQ(bn_status_exit_code(BN_ENOTSUP), 2);
    bn_transport_destroy(k);
    free(s.A);
}

/* An operator that fails (or is interrupted) at its c-th application, for every c a solve makes:
 * in the analysis, the iterations and the per-bounce terms. Every method stops with exactly that
 * status and message and leaves no L and no terms. */
static void failing_case(bn_status with)
{
    double E[3 * N_SPHERE];
    for (size_t i = 0; i < 3 * N_SPHERE; i++)
        E[i] = 1 + (double)(i % 5);
    for (size_t q = 0; q < 4; q++) {
        int total;
        sphere s;
        bn_transport *k;
        bn_solve_opts o = solve_opts(ALL[q], 0);
        bn_solve_result res;
        bn_error err;
        o.tol = 1e-10;
        o.atol = 0;
        /* how many applications a clean solve makes */
        sphere_init(&s, N_SPHERE);
        k = sphere_k(&s, &sphere_full);
        BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_OK);
        bn_solve_result_free(&res);
        total = s.calls;
        BN_ASSERT_GT(total, 4);
        for (int c = 1; c <= total; c++) {
            s.calls = 0;
            s.fail_at = c;
            s.fail_with = with;
            BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), with);
            BN_ASSERT(strstr(err.msg, "failed on purpose") != NULL);
            BN_ASSERT(res.L == NULL && res.terms == NULL && res.nterms == 0);
        }
        /* Gauss-Seidel also fails through its rows */
        if (ALL[q] == BN_SOLVE_GAUSS_SEIDEL) {
            s.fail_at = 0;
            s.calls = 0;
            s.row_calls = 0;
            s.row_fail_at = N_SPHERE + 3;   /* in the second row of the second sweep */
            BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), with);
            BN_ASSERT(strstr(err.msg, "row") != NULL && res.L == NULL);
        }
        bn_transport_destroy(k);
        free(s.A);
    }
}

BN_TEST(failing_operator_stops_every_solver) { failing_case(BN_ENUMERIC); }

/* An operator that returns success but a NaN at its c-th application, for every c a clean solve
 * makes (the norm, the power steps, every iteration, the terms): every method stops with
 * BN_ENUMERIC naming the call, the patch and the channel, and leaves no answer. Before, a NaN after
 * the first call was dropped by the monitor's fmax and the solve said converged. */
static void nan_case(const bn_transport_ops *ops, const bn_solve_method *methods, size_t nm)
{
    double E[3 * N_SPHERE];
    char want[64];
    for (size_t i = 0; i < 3 * N_SPHERE; i++)
        E[i] = 1 + (double)(i % 5);
    snprintf(want, sizeof want, "at patch %d, channel G", N_SPHERE / 2);
    for (size_t q = 0; q < nm; q++) {
        sphere s;
        bn_transport *k;
        bn_solve_opts o = solve_opts(methods[q], 0);
        bn_solve_result res;
        bn_error err;
        int total;
        o.tol = 1e-10;
        sphere_init(&s, N_SPHERE);
        k = sphere_k(&s, ops);
        BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_OK);
        bn_solve_result_free(&res);
        total = s.calls;
        BN_ASSERT_GT(total, 4);
        for (int c = 1; c <= total; c++) {
            char call[48];
            bn_transport_destroy(k);   /* a fresh operator: its calls are counted from 1 */
            free(s.A);
            sphere_init(&s, N_SPHERE);
            k = sphere_k(&s, ops);
            s.nan_at = c;
            BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_ENUMERIC);
            snprintf(call, sizeof call, "apply (y = F x) call %d ", c);
            if (!strstr(err.msg, call) || !strstr(err.msg, want))
                BN_FAIL("%s, NaN at apply %d of %d: message '%s'", bn_solve_method_name(methods[q]), c, total, err.msg);
            BN_ASSERT(res.L == NULL && res.terms == NULL && res.nterms == 0);
        }
        bn_transport_destroy(k);
        free(s.A);
    }
}

BN_TEST(nan_from_operator_at_every_application_stops_every_solver) { nan_case(&sphere_full, ALL, 4); }
BN_TEST(nan_from_apply_only_operator_stops_jacobi_neumann)
{
    static const bn_solve_method m[] = {BN_SOLVE_JACOBI, BN_SOLVE_NEUMANN};
    nan_case(&sphere_apply_only, m, 2);
}

/* NaN from Gauss-Seidel's rows, at every row call of its first sweeps; and an entry for the direct
 * solve. */
BN_TEST(nan_from_rows_and_entries_stops_gauss_seidel_and_direct)
{
    double E[3 * N_SPHERE];
    bn_solve_result res;
    bn_error err;
    for (size_t i = 0; i < 3 * N_SPHERE; i++)
        E[i] = 1;
    for (int c = 1; c <= 3 * N_SPHERE; c++) {
        sphere s;
        bn_transport *k;
        bn_solve_opts o = solve_opts(BN_SOLVE_GAUSS_SEIDEL, 0);
        o.tol = 1e-12;
        sphere_init(&s, N_SPHERE);
        k = sphere_k(&s, &sphere_full);
        s.row_nan_at = c;
        BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_ENUMERIC);
        if (!strstr(err.msg, "row call") || !strstr(err.msg, "channel B"))
            BN_FAIL("row NaN at call %d: '%s'", c, err.msg);
        BN_ASSERT(res.L == NULL);
        bn_transport_destroy(k);
        free(s.A);
    }
    {
        sphere s;
        bn_transport *k;
        bn_solve_opts o = solve_opts(BN_SOLVE_DIRECT, 0);
        char want[64];
        sphere_init(&s, N_SPHERE);
        k = sphere_k(&s, &sphere_full);
        s.entry_nan = 1;
        BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_ENUMERIC);
        snprintf(want, sizeof want, "F(%d, %d) is not finite", N_SPHERE / 2, N_SPHERE / 2);
        if (!strstr(err.msg, want))
            BN_FAIL("entry NaN: '%s'", err.msg);
        BN_ASSERT(res.L == NULL);
        bn_transport_destroy(k);
        free(s.A);
    }
}
BN_TEST(interrupted_operator_stops_every_solver) { failing_case(BN_EINTR); }

/* The table is checked when the operator is made; ctx is released even then. */
BN_TEST(create_checks_the_ops_table)
{
    static const bn_transport_ops no_apply = {"no-apply", 0, NULL, NULL, NULL, NULL, NULL, NULL, sphere_destroy,
                                              NULL};
    static const bn_transport_ops rows_missing = {"rows-missing", BN_OP_ROWS, sphere_apply, NULL, NULL, NULL, NULL,
                                                  NULL, sphere_destroy, NULL};
    sphere s;
    bn_transport *k = NULL;
    bn_error err;
    double rho[3 * 4] = {0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 1.5};
    sphere_init(&s, 4);
    BN_ASSERT_STATUS(bn_transport_create(4, rho, &no_apply, &s, &k, &err), BN_EUSAGE);
    BN_ASSERT(strstr(err.msg, "apply") != NULL && k == NULL);
    BN_ASSERT_STATUS(bn_transport_create(4, rho, &rows_missing, &s, &k, &err), BN_EUSAGE);
    BN_ASSERT(strstr(err.msg, "BN_OP_ROWS") != NULL);
    BN_ASSERT_STATUS(bn_transport_create(4, rho, &sphere_full, &s, &k, &err), BN_EINPUT);   /* rho 1.5 */
    BN_ASSERT(strstr(err.msg, "patch 3") != NULL);
    BN_ASSERT_EQ(s.destroyed, 3);
    free(s.A);
}

/* ---- the builder: every storage keeps what it is given ---- */

/* A random sparse F (about a third of the entries zero), both storages and precisions: entries,
 * rows, the diagonal and K x agree with the array to the precision's rounding. */
BN_TEST(builder_every_storage_keeps_the_array)
{
    const size_t n = 37;
    double F[37 * 37], rho[3 * 37], x[3 * 37], y[3 * 37], want[3 * 37];
    const char *storages[] = {"dense", "sparse"};
    uint64_t r = 88172645463325252ULL;
    for (size_t i = 0; i < n * n; i++) {
        r ^= r << 13, r ^= r >> 7, r ^= r << 17;
        F[i] = (r % 3 == 0) ? 0 : (double)(r >> 11) * 0x1.0p-53 / (double)n;
    }
    for (size_t i = 0; i < 3 * n; i++) {
        rho[i] = 0.2 + 0.7 * (double)(i % 5) / 4;
        x[i] = 1 + (double)(i % 11);
    }
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            double s = 0;
            for (size_t j = 0; j < n; j++)
                s += F[i * n + j] * x[3 * j + c];
            want[3 * i + c] = rho[3 * i + c] * s;
        }
    for (int st = 0; st < 2; st++)
        for (int p = 0; p < 2; p++) {
            bn_precision prec = p ? BN_PRECISION_DOUBLE : BN_PRECISION_FLOAT;
            double eps = bn_precision_epsilon(prec), d[37], row[3];
            bn_transport *k;
            bn_error err;
            BN_ASSERT_STATUS(bn_transport_from_array(n, F, rho, storages[st], prec, 0, &k, &err), BN_OK);
            for (size_t i = 0; i < n; i++)
                for (size_t j = 0; j < n; j++)
                    BN_ASSERT_NEAR(bn_test_F(k, i, j), F[i * n + j], eps * F[i * n + j]);
            BN_ASSERT_STATUS(bn_transport_apply(k, x, y, &err), BN_OK);
            for (size_t i = 0; i < 3 * n; i++)
                /* stored rounding (eps per entry) plus double sums in another order (n 2^-53) */
                BN_ASSERT_NEAR(y[i], want[i], (4 * eps + (double)n * 0x1p-53) * want[i] + 1e-300);
            BN_ASSERT_STATUS(bn_transport_diag(k, d, &err), BN_OK);
            for (size_t i = 0; i < n; i++) {
                BN_ASSERT_NEAR(d[i], F[i * n + i], eps * F[i * n + i]);
                /* a row is the product's row, bit for bit */
                BN_ASSERT_STATUS(bn_transport_row(k, i, x, row, &err), BN_OK);
                for (int c = 0; c < 3; c++)
                    BN_ASSERT_EQ(row[c], y[3 * i + c]);
            }
            /* the sparse storage keeps only the nonzeros */
            if (st == 1) {
                size_t nz = 0;
                for (size_t i = 0; i < n * n; i++)
                    nz += F[i] != 0;
                BN_ASSERT_LT(bn_transport_bytes(k), nz * 12 + (n + 1) * 8 + 3 * n * 8 + 1);
            }
            bn_transport_destroy(k);
        }
}

/* Values outside the pattern are counted, not stored; unknown storages are usage errors. */
static size_t diagonal_only(void *user, size_t i, uint32_t *cols)
{
    (void)user;
    if (cols)
        cols[0] = (uint32_t)i;
    return 1;
}

BN_TEST(builder_pattern_and_names)
{
    bn_builder_opts o;
    bn_transport_builder *b;
    bn_transport *k;
    bn_builder_report rep;
    bn_error err;
    double rho[3 * 5];
    size_t need;
    for (int i = 0; i < 15; i++)
        rho[i] = 0.5;
    bn_builder_opts_default(&o);
    o.storage = "sparse";
    o.pattern = diagonal_only;
    BN_ASSERT_STATUS(bn_transport_builder_create(5, &o, &need, &b, &err), BN_OK);
    BN_ASSERT_EQ(need, bn_storage_bytes("sparse", 5, 5, BN_PRECISION_FLOAT));
    BN_ASSERT_EQ(bn_transport_builder_put(b, 2, 2, 0.25), 1);
    BN_ASSERT_EQ(bn_transport_builder_put(b, 2, 3, 0.5), 0);   /* outside the pattern */
    BN_ASSERT_STATUS(bn_transport_builder_finish(b, rho, &k, &rep, &err), BN_OK);
    BN_ASSERT_EQ(rep.lost_puts, 1);
    BN_ASSERT_EQ(rep.dropped_entries, 4);   /* the four diagonal slots left at 0 */
    BN_ASSERT_EQ(bn_test_F(k, 2, 2), 0.25);
    BN_ASSERT_EQ(bn_test_F(k, 2, 3), 0);
    bn_transport_destroy(k);
    /* a limit below the need is refused with the need said */
    o.storage = "dense";
    o.max_bytes = 10;
    BN_ASSERT_STATUS(bn_transport_builder_create(5, &o, &need, &b, &err), BN_ENOMEM);
    BN_ASSERT_EQ(need, 5 * 5 * sizeof(float));
    o.storage = "hierarchical-someday";
    BN_ASSERT_STATUS(bn_transport_builder_create(5, &o, &need, &b, &err), BN_EUSAGE);
    BN_ASSERT(strstr(err.msg, "dense|sparse") != NULL);
    BN_ASSERT(bn_storage_exists("dense") && bn_storage_exists("sparse") && !bn_storage_exists("csr"));
}

/* F exported as links (the live page's data): dense and sparse give one leaf per patch and a link per
 * nonzero of the array, in row order, values to the precision; the byte count needs no export; an
 * operator with neither links nor entries is a usage error naming it. */
BN_TEST(links_export_is_the_array)
{
    const size_t n = 23;
    double F[23 * 23], rho[3 * 23];
    const char *storages[] = {"dense", "sparse"};
    size_t nz = 0;
    for (size_t i = 0; i < n * n; i++) {
        F[i] = (i * 7 % 5 == 0 || i % (n + 1) == 0) ? 0 : (double)(i % 13 + 1) / (13.0 * (double)n);
        nz += F[i] != 0;
    }
    for (size_t i = 0; i < 3 * n; i++)
        rho[i] = 0.5;
    for (int st = 0; st < 2; st++) {
        bn_transport *k;
        bn_transport_links l;
        bn_error err;
        size_t bytes, at = 0;
        BN_ASSERT_STATUS(bn_transport_from_array(n, F, rho, storages[st], BN_PRECISION_DOUBLE, 0, &k, &err), BN_OK);
        BN_ASSERT_STATUS(bn_transport_links_get(k, &l, &err), BN_OK);
        BN_ASSERT_EQ(l.npatch, n);
        BN_ASSERT_EQ(l.nnodes, n);
        BN_ASSERT_EQ(l.nlinks, nz);
        BN_ASSERT(l.dir == NULL && l.rowscale == NULL);
        for (size_t i = 0; i < n; i++) {
            BN_ASSERT_EQ(l.child[i], BN_LINK_NONE);
            BN_ASSERT_EQ(l.leaf_patch[i], (uint32_t)i);
            BN_ASSERT_EQ(l.start[i], (uint32_t)at);
            for (size_t j = 0; j < n; j++)
                if (F[i * n + j] != 0) {
                    BN_ASSERT_EQ(l.src[at], (uint32_t)j);
                    BN_ASSERT_NEAR(l.F[at], F[i * n + j], 1e-7 * F[i * n + j]);
                    at++;
                }
        }
        BN_ASSERT_EQ(l.start[n], (uint32_t)nz);
        BN_ASSERT_STATUS(bn_transport_links_bytes(k, &bytes, &err), BN_OK);
        BN_ASSERT_EQ(bytes, n * 29 + 4 + nz * 8 + n * 4);
        bn_transport_links_free(&l);
        bn_transport_destroy(k);
    }
    {
        sphere s;
        bn_transport *k;
        bn_transport_links l;
        bn_error err;
        sphere_init(&s, 8);
        k = sphere_k(&s, &sphere_apply_only);
        BN_ASSERT_STATUS(bn_transport_links_get(k, &l, &err), BN_EUSAGE);
        BN_ASSERT(strstr(err.msg, "sphere-apply-only") != NULL);
        bn_transport_destroy(k);
        free(s.A);
    }
}
