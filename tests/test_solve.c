/* Solver tests against independent answers: furnaces (L = E / (1 - rho), K^k E = rho^k E), the
 * sphere (exact L for any E and areas), singular and non-finite systems, float against double,
 * and properties (Neumann = Jacobi, Gauss-Seidel faster, all methods agree with direct).
 *
 * Tolerances, each with its reason:
 *  - error of an iterative answer: ||L - L*||_inf <= ||r||_inf / (1 - ||K||_inf) (exact for the
 *    stored K), and the stop test gives ||r|| <= tol ||E||;
 *  - a row-sum error delta of F (measured on the stored F) adds rho delta / (1 - rho) relative;
 *  - float storage rounds each F_ij by u = 2^-24: ||L_f - L_d|| / ||L|| <= u ||K|| / (1 - ||K||);
 *  - double rounding of the sums themselves: BN_ROUND (1e-12 relative, N <= 1000, cond <= 1e4). */
#include "bn_test.h"
#include "bounce/solve.h"
#include "bounce/transport.h"

#include <stdint.h>

#define BN_ROUND 1e-12
#define PI 3.14159265358979323846

static uint64_t rng_state = 0x9e3779b97f4a7c15ULL;
static double urand(void)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (double)(rng_state >> 11) * 0x1.0p-53;
}

/* A random F with zero diagonal whose rows sum to row_sum (row_sum 1: a closed furnace). */
static double *random_F(size_t n, double row_sum_lo, double row_sum_hi)
{
    double *F = calloc(n * n, sizeof(double));
    for (size_t i = 0; i < n; i++) {
        double s = 0, target = row_sum_lo + (row_sum_hi - row_sum_lo) * urand();
        for (size_t j = 0; j < n; j++)
            if (j != i)
                s += (F[i * n + j] = 0.05 + urand() * urand());
        for (size_t j = 0; j < n; j++)
            F[i * n + j] *= target / s;
    }
    return F;
}

/* The unit cube, one patch per face: F between opposite faces from the closed form for parallel
 * aligned rectangles (X = Y = 1; Howell's catalogue C-11), between adjacent faces the rest of the
 * row by symmetry: (1 - F_opp) / 4. Published: 0.19982 and 0.20004. */
static double *cube_F(void)
{
    double X = 1, Y = 1, F_opp, F_adj;
    double *F = calloc(36, sizeof(double));
    F_opp = 2.0 / (PI * X * Y) *
            (0.5 * log((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y)) + X * sqrt(1 + Y * Y) * atan(X / sqrt(1 + Y * Y)) +
             Y * sqrt(1 + X * X) * atan(Y / sqrt(1 + X * X)) - X * atan(X) - Y * atan(Y));
    F_adj = (1 - F_opp) / 4;
    BN_ASSERT_NEAR(F_opp, 0.19982, 5e-6);
    BN_ASSERT_NEAR(F_adj, 0.20004, 5e-6);
    /* faces 0/1 = -x/+x, 2/3 = -y/+y, 4/5 = -z/+z: opposite when i/2 == j/2 */
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++)
            F[i * 6 + j] = i == j ? 0 : (i / 2 == j / 2 ? F_opp : F_adj);
    return F;
}

static bn_transport *make_k(size_t n, const double *F, const double *rho, bn_precision prec)
{
    bn_transport *k = NULL;
    bn_error err;
    if (bn_transport_from_array(n, F, rho, "dense", prec, 0, &k, &err) != BN_OK)
        BN_FAIL("from_array: %s", err.msg);
    return k;
}

/* delta = max_i |sum_j F_ij - 1| of the stored F (in double). */
static double row_sum_delta(const bn_transport *k)
{
    size_t n = bn_transport_size(k);
    double d = 0;
    for (size_t i = 0; i < n; i++) {
        double s = 0;
        for (size_t j = 0; j < n; j++)
            s += bn_test_F(k, i, j);
        d = fmax(d, fabs(s - 1));
    }
    return d;
}

static double *fill(size_t m, double v)
{
    double *x = malloc(m * sizeof(double));
    for (size_t i = 0; i < m; i++)
        x[i] = v;
    return x;
}

static int g_threads;   /* the solves' threads (0: the caller's) */

static bn_status solve(const bn_transport *k, const double *E, bn_solve_method method, double tol, size_t max_iter,
                       int bounces, bn_solve_result *res, bn_error *err)
{
    bn_solve_opts o;
    bn_solve_opts_default(&o);
    o.threads = g_threads;
    o.method = method;
    o.tol = tol;
    o.max_iter = max_iter;
    o.bounces = bounces;
    o.log_sink.quiet = 1;
    return bn_solve(k, E, &o, res, err);
}

static double max_abs_diff(const double *a, const double *b, size_t m)
{
    double d = 0;
    for (size_t i = 0; i < m; i++)
        d = fmax(d, fabs(a[i] - b[i]));
    return d;
}

static double max_abs(const double *a, size_t m)
{
    double d = 0;
    for (size_t i = 0; i < m; i++)
        d = fmax(d, fabs(a[i]));
    return d;
}

static const bn_solve_method all_methods[] = {BN_SOLVE_JACOBI, BN_SOLVE_GAUSS_SEIDEL, BN_SOLVE_NEUMANN, BN_SOLVE_DIRECT};

/* Two facing plates and nothing else (a cavity): K = [[0, a], [b, 0]] has the eigenvalues
 * +-sqrt(ab), so a power iteration's one-step ratio alternates between a and b for ever; the
 * estimate is the two-step ratio, sqrt(ab), with its lower bound below it. */
BN_TEST(spectral_radius_of_a_cavity)
{
    const double F[4] = {0, 0.9, 0.5, 0}, rho_v = 0.8, want = rho_v * sqrt(0.9 * 0.5);
    double *rho = fill(6, rho_v), est, low;
    size_t steps;
    bn_error err;
    bn_transport *k = make_k(2, F, rho, BN_PRECISION_DOUBLE);
    BN_ASSERT_STATUS(bn_solve_spectral_radius(k, 100, &est, &low, &steps, &err), BN_OK);
    printf("cavity: estimate %.12g (exact %.12g) after %zu steps, lower bound %.6g\n", est, want, steps, low);
    BN_ASSERT_NEAR(est, want, 1e-12);
    BN_ASSERT_LE(low, want + 1e-12);
    BN_ASSERT_LT(steps, 10);
    bn_transport_destroy(k);
    free(rho);
}

/* The furnace: closed (row-stochastic F), uniform rho and Le: L = Le / (1 - rho), K^k E = rho^k E. */
static void furnace(double rho_v, bn_precision prec, int use_cube)
{
    size_t n = use_cube ? 6 : 40, m = 3 * n;
    double *F = use_cube ? cube_F() : random_F(n, 1, 1), *rho = fill(m, rho_v), *E = fill(m, 2.5);
    bn_transport *k = make_k(n, F, rho, prec);
    double delta = row_sum_delta(k), Lx = 2.5 / (1 - rho_v), tol = 1e-8;
    fprintf(stderr, "furnace rho=%g %s: row-sum error delta of stored F = %.3g; F error bound rho*delta/(1-rho) = %.3g\n",
            rho_v, prec == BN_PRECISION_FLOAT ? "float" : "double", delta, rho_v * delta / (1 - rho_v));
    for (size_t q = 0; q < 4; q++) {
        bn_solve_result res;
        bn_error err;
        bn_status st = solve(k, E, all_methods[q], tol, 10000000, 5, &res, &err);
        double knorm, bound, worst = 0;
        if (st != BN_OK)
            BN_FAIL("%s: %s", bn_solve_method_name(all_methods[q]), err.msg);
        knorm = res.k_norm_inf;
        /* solver error (relative to L*) + F error + rounding */
        bound = tol * 2.5 / (1 - knorm) / Lx + rho_v * delta / (1 - rho_v) + BN_ROUND / (1 - rho_v);
        for (size_t i = 0; i < m; i++)
            worst = fmax(worst, fabs(res.L[i] - Lx) / Lx);
        fprintf(stderr, "  %-12s iterations %7zu (predicted %7zu)  max rel error %.3g <= bound %.3g\n",
                bn_solve_method_name(all_methods[q]), res.iterations, res.predicted_iterations, worst, bound);
        BN_ASSERT_LE(worst, bound);
        BN_ASSERT_NEAR(res.spectral_radius, rho_v, rho_v * delta + 1e-12);
        BN_ASSERT_EQ(res.nterms, 6);
        for (int t = 0; t < res.nterms; t++)
            for (size_t i = 0; i < m; i++)
                BN_ASSERT_REL(res.terms[t][i], 2.5 * pow(rho_v, t), t * delta * 1.01 + 1e-14);
        bn_solve_result_free(&res);
    }
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

BN_TEST(furnace_rho_0_5) { furnace(0.5, BN_PRECISION_FLOAT, 0); }
BN_TEST(furnace_rho_0_9) { furnace(0.9, BN_PRECISION_FLOAT, 0); }
BN_TEST(furnace_rho_0_99) { furnace(0.99, BN_PRECISION_FLOAT, 0); }
BN_TEST(furnace_rho_0_999) { furnace(0.999, BN_PRECISION_FLOAT, 0); }
BN_TEST(furnace_cube_rho_0_9_float) { furnace(0.9, BN_PRECISION_FLOAT, 1); }

/* rho = 0.9999 with double K on the analytic cube: ~1e5 iterations, predicted before starting. */
BN_TEST(furnace_rho_0_9999_double_predicted)
{
    size_t n = 6, m = 18;
    double *F = cube_F(), *rho = fill(m, 0.9999), *E = fill(m, 1.0);
    bn_transport *k = make_k(n, F, rho, BN_PRECISION_DOUBLE);
    double delta = row_sum_delta(k), Lx = 1 / (1 - 0.9999), tol = 1e-6;
    bn_solve_method methods[] = {BN_SOLVE_JACOBI, BN_SOLVE_NEUMANN, BN_SOLVE_GAUSS_SEIDEL};
    fprintf(stderr, "cube double: delta = %.3g, rho*delta/(1-rho) = %.3g\n", delta, 0.9999 * delta / 1e-4);
    for (int q = 0; q < 3; q++) {
        bn_solve_result res;
        bn_error err;
        double worst = 0, bound;
        bn_status st = solve(k, E, methods[q], tol, 1000000, 3, &res, &err);
        if (st != BN_OK)
            BN_FAIL("%s: %s", bn_solve_method_name(methods[q]), err.msg);
        for (size_t i = 0; i < m; i++)
            worst = fmax(worst, fabs(res.L[i] - Lx) / Lx);
        bound = tol / (1 - res.k_norm_inf) / Lx + 0.9999 * delta / 1e-4 + 1e-9;
        fprintf(stderr, "  %-12s predicted %zu, ran %zu iterations, rel error %.3g <= %.3g\n",
                bn_solve_method_name(methods[q]), res.predicted_iterations, res.iterations, worst, bound);
        BN_ASSERT_LE(worst, bound);
        if (methods[q] != BN_SOLVE_GAUSS_SEIDEL) {
            /* ~1e5 predicted (log(tol)/log(rho) = 1.38e5; the series stops on its tail bound,
             * log(tol (1 - rho))/log(rho) = 2.3e5), and the prediction is the count (the furnace
             * residual is exactly rho^(k+1) E) */
            BN_ASSERT_GE(res.predicted_iterations, 1e5);
            BN_ASSERT_LE(res.predicted_iterations, 3e5);
            BN_ASSERT_LE(fabs((double)res.iterations - (double)res.predicted_iterations), 2);
        } else {
            BN_ASSERT_LE(res.iterations, res.predicted_iterations);
        }
        bn_solve_result_free(&res);
    }
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* rho = 1 in a closed scene: refused before iterating, exit status 5, no NaN, no L. */
BN_TEST(singular_rho_1)
{
    size_t n = 30, m = 90;
    double *F = random_F(n, 1, 1), *rho = fill(m, 1.0), *E = fill(m, 1.0);
    for (int prec = 0; prec < 2; prec++) {
        bn_transport *k = make_k(n, F, rho, prec ? BN_PRECISION_DOUBLE : BN_PRECISION_FLOAT);
        for (size_t q = 0; q < 4; q++) {
            bn_solve_result res;
            bn_error err;
            bn_status st = solve(k, E, all_methods[q], 1e-6, 100000000, 3, &res, &err);
            BN_ASSERT_EQ(st, BN_ENUMERIC);
            BN_ASSERT_EQ(bn_status_exit_code(st), 5);
            BN_ASSERT_EQ(res.reason, BN_STOP_SINGULAR);
            BN_ASSERT_EQ(res.iterations, 0);
            BN_ASSERT(res.L == NULL && res.terms == NULL);
            BN_ASSERT(strstr(err.msg, "singular") != NULL);
            BN_ASSERT_LT(res.seconds, 5);
            if (q == 0)
                fprintf(stderr, "%s: %s\n", prec ? "double" : "float", err.msg);
            bn_solve_result_free(&res);
        }
        bn_transport_destroy(k);
    }
    free(F);
    free(rho);
    free(E);
}

/* Just below the threshold's reach it solves; just inside it (1 - 1e-7) it is refused. */
BN_TEST(singular_threshold_edges)
{
    size_t n = 12, m = 36;
    double *F = random_F(n, 1, 1), *E = fill(m, 1.0);
    double *rho_in = fill(m, 1 - 1e-7), *rho_out = fill(m, 1 - 1e-4);
    bn_transport *k = make_k(n, F, rho_in, BN_PRECISION_DOUBLE), *k2 = make_k(n, F, rho_out, BN_PRECISION_DOUBLE);
    bn_solve_result res;
    bn_error err;
    BN_ASSERT_EQ(solve(k, E, BN_SOLVE_DIRECT, 1e-6, 10, 0, &res, &err), BN_ENUMERIC);
    BN_ASSERT_EQ(res.reason, BN_STOP_SINGULAR);
    bn_solve_result_free(&res);
    BN_ASSERT_EQ(solve(k2, E, BN_SOLVE_DIRECT, 1e-6, 10, 0, &res, &err), BN_OK);
    BN_ASSERT_REL(res.L[0], 1e4, 1e-9);
    bn_solve_result_free(&res);
    bn_transport_destroy(k);
    bn_transport_destroy(k2);
    free(F);
    free(E);
    free(rho_in);
    free(rho_out);
}

/* ||K||_inf = 1 on one row (a white patch that sees only closed surroundings) but the scene is
 * open: the spectral radius is below 1, so it must solve (with a warning), not be refused. */
BN_TEST(norm_one_but_open_scene_solves)
{
    size_t n = 20, m = 60;
    double *F = random_F(n, 0.4, 0.6), *rho = fill(m, 1.0), *E = fill(m, 1.0);
    bn_transport *k;
    bn_solve_result rd, rj;
    bn_error err;
    for (size_t j = 1; j < n; j++)   /* row 0 closed */
        F[j] *= 1.0 / 0.5;
    {
        double s = 0;
        for (size_t j = 0; j < n; j++)
            s += F[j];
        for (size_t j = 0; j < n; j++)
            F[j] /= s;
    }
    k = make_k(n, F, rho, BN_PRECISION_DOUBLE);
    BN_ASSERT_STATUS(solve(k, E, BN_SOLVE_DIRECT, 1e-9, 100, 0, &rd, &err), BN_OK);
    BN_ASSERT_STATUS(solve(k, E, BN_SOLVE_JACOBI, 1e-9, 100000, 0, &rj, &err), BN_OK);
    BN_ASSERT_NEAR(rd.k_norm_inf, 1.0, 1e-12);
    BN_ASSERT_LT(rj.spectral_radius, 0.99);
    BN_ASSERT_LE(max_abs_diff(rj.L, rd.L, m), 1e-6 * max_abs(rd.L, m));
    bn_solve_result_free(&rd);
    bn_solve_result_free(&rj);
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* Emission from 1e-6 to 1e6 in one scene: two identical closed rooms (block-diagonal F), one lit
 * at 1e-6 and one at 1e6. Each patch gets its own L = Le / (1 - rho) to the relative tolerance. */
BN_TEST(emission_range_1e_minus6_to_1e6)
{
    size_t h = 25, n = 2 * h, m = 3 * n;
    double *Fh = random_F(h, 1, 1), *F = calloc(n * n, sizeof(double)), *rho = fill(m, 0.9), *E = fill(m, 1e-6);
    bn_transport *k;
    for (size_t i = 0; i < h; i++)
        for (size_t j = 0; j < h; j++)
            F[i * n + j] = F[(i + h) * n + (j + h)] = Fh[i * h + j];
    for (size_t i = 3 * h; i < m; i++)
        E[i] = 1e6;
    k = make_k(n, F, rho, BN_PRECISION_FLOAT);
    double delta = row_sum_delta(k);
    for (size_t q = 0; q < 4; q++) {
        bn_solve_result res;
        bn_error err;
        double worst[2] = {0, 0}, tol = 1e-9, bound;
        if (solve(k, E, all_methods[q], tol, 1000000, 2, &res, &err) != BN_OK)
            BN_FAIL("%s: %s", bn_solve_method_name(all_methods[q]), err.msg);
        for (size_t i = 0; i < m; i++) {
            double Lx = E[i] / (1 - 0.9);
            worst[i >= 3 * h] = fmax(worst[i >= 3 * h], fabs(res.L[i] - Lx) / Lx);
        }
        bound = tol * (1 - 0.9) / (1 - res.k_norm_inf) + 0.9 * delta / (1 - 0.9) + BN_ROUND;
        fprintf(stderr, "  %-12s rel error dim room %.3g, bright room %.3g (bound %.3g)\n",
                bn_solve_method_name(all_methods[q]), worst[0], worst[1], bound);
        BN_ASSERT_LE(worst[0], bound);
        BN_ASSERT_LE(worst[1], bound);
        bn_solve_result_free(&res);
    }
    bn_transport_destroy(k);
    free(Fh);
    free(F);
    free(rho);
    free(E);
}

/* Inside a sphere F_ij = A_j / A (every point sees every patch in proportion to its area, itself
 * included), so for uniform rho and any E: L_i = E_i + rho Ebar / (1 - rho), Ebar = sum A_j E_j / A.
 * One patch of area 1 and 299 of 1e-8 (ratio 1e8): F_00 ~ 1 - 3e-6 exercises the diagonal. */
BN_TEST(area_ratio_1e8_sphere)
{
    size_t n = 300, m = 3 * n;
    double *A = malloc(n * sizeof(double)), *F = malloc(n * n * sizeof(double)), *rho = fill(m, 0.8), *E = fill(m, 0);
    double Atot = 0, Ebar[3] = {0, 0, 0};
    bn_transport *k;
    for (size_t i = 0; i < n; i++)
        Atot += A[i] = i == 0 ? 1.0 : 1e-8;
    for (size_t i = 0; i < n; i++) {
        for (size_t j = 0; j < n; j++)
            F[i * n + j] = A[j] / Atot;
        for (int c = 0; c < 3; c++)
            E[3 * i + c] = i == 0 ? 1.0 * (c + 1) : (i % 2 ? 1e3 : 0.0);
    }
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++)
            Ebar[c] += A[i] * E[3 * i + c] / Atot;
    k = make_k(n, F, rho, BN_PRECISION_DOUBLE);
    for (size_t q = 0; q < 4; q++) {
        bn_solve_result res;
        bn_error err;
        double worst = 0, tol = 1e-10;
        if (solve(k, E, all_methods[q], tol, 100000, 1, &res, &err) != BN_OK)
            BN_FAIL("%s: %s", bn_solve_method_name(all_methods[q]), err.msg);
        for (size_t i = 0; i < n; i++)
            for (int c = 0; c < 3; c++) {
                double Lx = E[3 * i + c] + 0.8 * Ebar[c] / (1 - 0.8);
                worst = fmax(worst, fabs(res.L[3 * i + c] - Lx) / Lx);
            }
        fprintf(stderr, "  %-12s %5zu iterations, max rel error %.3g\n", bn_solve_method_name(all_methods[q]),
                res.iterations, worst);
        /* error <= tol ||E|| / (1 - ||K||) absolute; the smallest L is 0.8 Ebar / 0.2 ~ 4.0 */
        BN_ASSERT_LE(worst, tol * max_abs(E, m) / (1 - res.k_norm_inf) / 4.0 + 1e-12);
        bn_solve_result_free(&res);
    }
    bn_transport_destroy(k);
    free(A);
    free(F);
    free(rho);
    free(E);
}

/* K stored in float against double: both solved directly; the difference is below
 * u ||K|| / (1 - ||K||) ||L|| with u = 2^-24 (each F_ij rounded once). */
BN_TEST(float_vs_double_bound)
{
    size_t n = 200, m = 3 * n;
    double *F = random_F(n, 0.7, 1.0), *rho = malloc(m * sizeof(double)), *E = fill(m, 0);
    bn_transport *kf, *kd;
    bn_solve_result rf, rd;
    bn_error err;
    double diff, bound;
    for (size_t i = 0; i < m; i++)
        rho[i] = 0.5 + 0.45 * urand();
    for (size_t i = 0; i < n; i += 7)
        for (int c = 0; c < 3; c++)
            E[3 * i + c] = 10.0 * urand();
    kf = make_k(n, F, rho, BN_PRECISION_FLOAT);
    kd = make_k(n, F, rho, BN_PRECISION_DOUBLE);
    BN_ASSERT_STATUS(solve(kf, E, BN_SOLVE_DIRECT, 0, 1, 0, &rf, &err), BN_OK);
    BN_ASSERT_STATUS(solve(kd, E, BN_SOLVE_DIRECT, 0, 1, 0, &rd, &err), BN_OK);
    diff = max_abs_diff(rf.L, rd.L, m) / max_abs(rd.L, m);
    bound = 0x1.0p-24 * rd.k_norm_inf / (1 - rd.k_norm_inf) + BN_ROUND;
    fprintf(stderr, "||K|| = %.6g: float vs double relative difference %.3g <= bound %.3g\n", rd.k_norm_inf, diff, bound);
    BN_ASSERT_LE(diff, bound);
    BN_ASSERT_GT(diff, 0);   /* the float copy really differs */
    bn_solve_result_free(&rf);
    bn_solve_result_free(&rd);
    bn_transport_destroy(kf);
    bn_transport_destroy(kd);
    free(F);
    free(rho);
    free(E);
}

/* Capture every iterate through the monitor. */
typedef struct capture {
    size_t m, count;
    double *rows;   /* up to 64 iterates */
} capture;
static int capture_fn(void *user, const bn_solve_row *row, const double *L)
{
    capture *c = user;
    if (row->iteration < 64) {
        memcpy(c->rows + row->iteration * c->m, L, c->m * sizeof(double));
        c->count = row->iteration + 1;
    }
    return 0;
}

/* With F_ii = 0, Jacobi from L0 = E produces the Neumann partial sums S_k = sum_{q<=k} K^q E. */
BN_TEST(neumann_partial_sums_equal_jacobi_iterates)
{
    size_t n = 60, m = 3 * n, iters = 40;
    double *F = random_F(n, 0.8, 1.0), *rho = malloc(m * sizeof(double)), *E = fill(m, 0);
    capture cj = {m, 0, calloc(64 * m, sizeof(double))}, cn = {m, 0, calloc(64 * m, sizeof(double))};
    bn_transport *k;
    bn_solve_result rj, rn;
    bn_solve_opts o;
    bn_error err;
    for (size_t i = 0; i < m; i++)
        rho[i] = 0.3 + 0.6 * urand();
    E[0] = 5;
    E[4] = 3;
    E[3 * 17 + 2] = 1;
    k = make_k(n, F, rho, BN_PRECISION_FLOAT);
    bn_solve_opts_default(&o);
    o.tol = 0;
    o.max_iter = iters;
    o.bounces = (int)iters;
    o.log_sink.quiet = 1;
    o.monitor = capture_fn;
    o.method = BN_SOLVE_JACOBI;
    o.monitor_user = &cj;
    BN_ASSERT_STATUS(bn_solve(k, E, &o, &rj, &err), BN_ENOTCONV);
    o.method = BN_SOLVE_NEUMANN;
    o.monitor_user = &cn;
    BN_ASSERT_STATUS(bn_solve(k, E, &o, &rn, &err), BN_ENOTCONV);
    BN_ASSERT_EQ(rj.reason, BN_STOP_MAX_ITER);
    BN_ASSERT_EQ(cj.count, iters + 1);
    BN_ASSERT_EQ(cn.count, iters + 1);
    {
        double *S = calloc(m, sizeof(double)), worst = 0;
        for (size_t it = 0; it <= iters; it++) {
            double scale;
            for (size_t i = 0; i < m; i++)
                S[i] += rn.terms[it][i];   /* S_it = sum_{q <= it} K^q E from the kept terms */
            scale = max_abs(S, m);
            worst = fmax(worst, max_abs_diff(cj.rows + it * m, cn.rows + it * m, m) / scale);
            BN_ASSERT_LE(max_abs_diff(cn.rows + it * m, S, m), 1e-13 * scale);
        }
        fprintf(stderr, "max relative difference Jacobi iterate vs Neumann partial sum over %zu iterations: %.3g\n",
                iters, worst);
        BN_ASSERT_LE(worst, 1e-13);
        free(S);
    }
    bn_solve_result_free(&rj);
    bn_solve_result_free(&rn);
    bn_transport_destroy(k);
    free(cj.rows);
    free(cn.rows);
    free(F);
    free(rho);
    free(E);
}

/* Gauss-Seidel needs fewer sweeps than Jacobi to the same tolerance (Stein-Rosenberg). */
BN_TEST(gauss_seidel_fewer_sweeps_than_jacobi)
{
    size_t n = 150, m = 3 * n;
    double *F = random_F(n, 0.9, 1.0), *rho = malloc(m * sizeof(double)), *E = fill(m, 0);
    bn_transport *k;
    bn_solve_result rj, rg, rs;
    bn_solve_opts o;
    bn_error err;
    /* Cornell-like: white 0.75, red and green walls, one light */
    for (size_t i = 0; i < n; i++) {
        double r = 0.75, g = 0.75, b = 0.75;
        if (i % 5 == 1)
            r = 0.63, g = 0.06, b = 0.04;
        else if (i % 5 == 2)
            r = 0.15, g = 0.48, b = 0.09;
        rho[3 * i] = r, rho[3 * i + 1] = g, rho[3 * i + 2] = b;
    }
    E[0] = 17, E[1] = 12, E[2] = 4;
    k = make_k(n, F, rho, BN_PRECISION_FLOAT);
    BN_ASSERT_STATUS(solve(k, E, BN_SOLVE_JACOBI, 1e-8, 100000, 0, &rj, &err), BN_OK);
    BN_ASSERT_STATUS(solve(k, E, BN_SOLVE_GAUSS_SEIDEL, 1e-8, 100000, 0, &rg, &err), BN_OK);
    bn_solve_opts_default(&o);
    o.method = BN_SOLVE_GAUSS_SEIDEL;
    o.symmetric = 1;
    o.tol = 1e-8;
    o.log_sink.quiet = 1;
    BN_ASSERT_STATUS(bn_solve(k, E, &o, &rs, &err), BN_OK);
    fprintf(stderr, "sweeps to tol 1e-8: jacobi %zu, gauss-seidel %zu, symmetric gauss-seidel %zu (x2 sweeps); "
                    "spectral radius %.4f, predicted %zu\n",
            rj.iterations, rg.iterations, rs.iterations, rj.spectral_radius, rj.predicted_iterations);
    BN_ASSERT_LT(rg.iterations, rj.iterations);
    BN_ASSERT_LE(rg.iterations, rj.predicted_iterations);
    bn_solve_result_free(&rj);
    bn_solve_result_free(&rg);
    bn_solve_result_free(&rs);
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* Every method agrees with the direct solve to the tolerance asked: ||L - L_direct|| <= tol ||E|| /
 * (1 - ||K||), and the a posteriori error bound each reports is not below the true error. */
BN_TEST(all_methods_agree_with_direct)
{
    size_t n = 120, m = 3 * n;
    double *F = random_F(n, 0.6, 0.98), *rho = malloc(m * sizeof(double)), *E = fill(m, 0);
    bn_transport *k;
    bn_solve_result rd;
    bn_error err;
    for (size_t i = 0; i < m; i++)
        rho[i] = 0.2 + 0.75 * urand();
    for (size_t i = 0; i < n; i += 11)
        E[3 * i] = E[3 * i + 1] = E[3 * i + 2] = 1 + 9 * urand();
    k = make_k(n, F, rho, BN_PRECISION_FLOAT);
    BN_ASSERT_STATUS(solve(k, E, BN_SOLVE_DIRECT, 0, 1, 0, &rd, &err), BN_OK);
    BN_ASSERT_EQ(rd.reason, BN_STOP_DIRECT);
    BN_ASSERT_LE(rd.residual_max, 1e-12 * max_abs(E, m));
    for (double tol = 1e-3; tol >= 1e-11; tol *= 1e-4)
        for (size_t q = 0; q < 3; q++) {
            bn_solve_result res;
            double e, allowed;
            BN_ASSERT_STATUS(solve(k, E, all_methods[q], tol, 100000, 0, &res, &err), BN_OK);
            e = max_abs_diff(res.L, rd.L, m);
            allowed = tol * res.norm_E / (1 - res.k_norm_inf) + BN_ROUND * max_abs(rd.L, m);
            fprintf(stderr, "  tol %-6g %-12s %4zu iterations  ||L - L_direct|| = %.3g <= %.3g (error_bound %.3g)\n",
                    tol, bn_solve_method_name(all_methods[q]), res.iterations, e, allowed, res.error_bound);
            BN_ASSERT_LE(e, allowed);
            BN_ASSERT_LE(e, res.error_bound + BN_ROUND * max_abs(rd.L, m));
            bn_solve_result_free(&res);
        }
    bn_solve_result_free(&rd);
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* The result is bit-identical for 1, 2 and 3 threads. */
BN_TEST(thread_count_invariance)
{
    size_t n = 400, m = 3 * n;
    double *F = random_F(n, 0.8, 1.0), *rho = fill(m, 0.7), *E = fill(m, 0);
    bn_transport *k;
    E[5] = 1;
    E[3 * 200] = 2;
    k = make_k(n, F, rho, BN_PRECISION_FLOAT);
    for (size_t q = 0; q < 4; q++) {
        double *L1 = NULL;
        size_t it1 = 0;
        for (int t = 1; t <= 3; t++) {
            bn_solve_result res;
            bn_error err;
            g_threads = t;
            BN_ASSERT_STATUS(solve(k, E, all_methods[q], 1e-10, 100000, 3, &res, &err), BN_OK);
            if (t == 1) {
                L1 = malloc(m * sizeof(double));
                memcpy(L1, res.L, m * sizeof(double));
                it1 = res.iterations;
            } else {
                if (memcmp(L1, res.L, m * sizeof(double)) != 0)
                    BN_FAIL("%s: L differs between 1 and %d threads (max diff %.3g)",
                            bn_solve_method_name(all_methods[q]), t, max_abs_diff(L1, res.L, m));
                BN_ASSERT_EQ(res.iterations, it1);
            }
            bn_solve_result_free(&res);
        }
        free(L1);
    }
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* NaN in K, NaN in E, overflow during the iterations: each reported with its patch. */
BN_TEST(nonfinite_detected_with_patch)
{
    size_t n = 10, m = 30;
    double *F = random_F(n, 0.5, 0.9), *rho = fill(m, 0.9), *E = fill(m, 1);
    bn_transport *k;
    bn_solve_result res;
    bn_error err;
    k = make_k(n, F, rho, BN_PRECISION_DOUBLE);
    E[3 * 4 + 1] = NAN;
    BN_ASSERT_STATUS(solve(k, E, BN_SOLVE_JACOBI, 1e-6, 100, 0, &res, &err), BN_EINPUT);
    BN_ASSERT_EQ(res.bad_patch, 4);
    BN_ASSERT(strstr(err.msg, "patch 4") != NULL);
    bn_transport_destroy(k);
    E[3 * 4 + 1] = 1;
    F[7 * n + 3] = NAN;
    k = make_k(n, F, rho, BN_PRECISION_DOUBLE);
    BN_ASSERT_STATUS(solve(k, E, BN_SOLVE_GAUSS_SEIDEL, 1e-6, 100, 0, &res, &err), BN_ENUMERIC);
    BN_ASSERT_EQ(res.bad_patch, 7);
    BN_ASSERT(res.L == NULL);
    fprintf(stderr, "%s\n", err.msg);
    bn_transport_destroy(k);
    F[7 * n + 3] = 0.01;
    /* L ~ E / (1 - 0.9 * 0.9): 1e308 overflows during the sweeps */
    k = make_k(n, F, rho, BN_PRECISION_DOUBLE);
    for (size_t i = 0; i < m; i++)
        E[i] = 1.5e308;
    for (size_t q = 0; q < 3; q++) {
        BN_ASSERT_STATUS(solve(k, E, all_methods[q], 1e-6, 100, 0, &res, &err), BN_ENUMERIC);
        BN_ASSERT_EQ(res.reason, BN_STOP_DIVERGED_NAN);
        BN_ASSERT(res.bad_patch < n);
        BN_ASSERT(res.L == NULL);
        fprintf(stderr, "%s\n", err.msg);
    }
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* The iteration limit is a stop reason with its own status; L is kept (finite). */
BN_TEST(iteration_limit)
{
    size_t n = 20, m = 60;
    double *F = random_F(n, 1, 1), *rho = fill(m, 0.99), *E = fill(m, 1);
    bn_transport *k = make_k(n, F, rho, BN_PRECISION_FLOAT);
    bn_solve_result res;
    bn_error err;
    BN_ASSERT_STATUS(solve(k, E, BN_SOLVE_JACOBI, 1e-8, 10, 2, &res, &err), BN_ENOTCONV);
    BN_ASSERT_EQ(bn_status_exit_code(BN_ENOTCONV), 5);
    BN_ASSERT_EQ(res.reason, BN_STOP_MAX_ITER);
    BN_ASSERT_EQ(res.iterations, 10);
    BN_ASSERT(res.L != NULL && res.nterms == 3);
    BN_ASSERT(strstr(err.msg, "10 iterations") != NULL);
    BN_ASSERT_GE(res.predicted_iterations, 1000);
    bn_solve_result_free(&res);
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* Direct refuses a copy above its memory limit, with the numbers and the remedy. */
BN_TEST(direct_memory_estimate)
{
    size_t n = 100, m = 300;
    double *F = random_F(n, 0.5, 0.5), *rho = fill(m, 0.5), *E = fill(m, 1);
    bn_transport *k = make_k(n, F, rho, BN_PRECISION_FLOAT);
    bn_solve_opts o;
    bn_solve_result res;
    bn_error err;
    bn_solve_opts_default(&o);
    o.method = BN_SOLVE_DIRECT;
    o.max_memory = 1000;
    o.log_sink.quiet = 1;
    BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_ENOMEM);
    BN_ASSERT(strstr(err.msg, "100 patches") != NULL && strstr(err.msg, "`method`") != NULL);
    BN_ASSERT_GE(bn_solve_direct_bytes(n), n * n * 8);
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* The convergence log: provenance lines, the header row, rows from 0, residual falling. */
BN_TEST(log_format)
{
    size_t n = 30, m = 90;
    double *F = random_F(n, 0.9, 1.0), *rho = fill(m, 0.8), *E = fill(m, 0);
    bn_transport *k = make_k(n, F, rho, BN_PRECISION_FLOAT);
    bn_solve_opts o;
    bn_solve_result res;
    bn_error err;
    FILE *fp = fopen(bn_test_tmp("conv.csv"), "w");
    char *text, *hdr, line[512];
    size_t rows = 0;
    double prev = INFINITY;
    E[0] = 1;
    bn_solve_opts_default(&o);
    o.method = BN_SOLVE_JACOBI;
    o.log = fp;
    o.log_header = "# command=test\n# seed=1";
    o.log_sink.quiet = 1;
    BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_OK);
    fclose(fp);
    text = bn_test_read_file(bn_test_tmp("conv.csv"), NULL);
    BN_ASSERT(strncmp(text, "# command=test\n# seed=1\n", 24) == 0);
    BN_ASSERT(strstr(text, "# method=jacobi\n") && strstr(text, "# tol=1e-06\n") && strstr(text, "# patches=30\n"));
    BN_ASSERT(strstr(text, "# predicted_iterations="));
    hdr = strstr(text, "\niteration,");
    BN_ASSERT(hdr != NULL);
    /* Every column of every row against the Jacobi iterates recomputed here from the stored
     * (float) F with zero diagonal: L_0 = E, L_k+1 = E + K L_k, r_k = E - (I - K) L_k, and the
     * bounds ||K||^(k+1) / (1 - ||K||) ||E|| and ||r_k|| / (1 - ||K||). Columns are found by the
     * names the header gives them. */
    {
        const char *want[] = {"iteration", "residual_max", "residual_rms", "residual_max_R", "residual_max_G",
                              "residual_max_B", "change", "bound", "error_bound", "seconds"};
        int col[10];
        double *L = malloc(m * sizeof(double)), *Lp = malloc(m * sizeof(double)), *r = malloc(m * sizeof(double));
        double knorm = 0, last_t = 0;
        char names[512], *tok, *save = NULL;
        FILE *in;
        for (size_t i = 0; i < n; i++) {
            double rs = 0;
            for (size_t j = 0; j < n; j++)
                rs += (double)(float)F[i * n + j];
            knorm = fmax(knorm, 0.8 * rs);
        }
        snprintf(names, sizeof names, "%.*s", (int)strcspn(hdr + 1, "\n"), hdr + 1);
        for (int q = 0; q < 10; q++)
            col[q] = -1;
        tok = strtok_r(names, ",", &save);
        for (int c = 0; tok; c++, tok = strtok_r(NULL, ",", &save))
            for (int q = 0; q < 10; q++)
                if (strcmp(tok, want[q]) == 0)
                    col[q] = c;
        for (int q = 0; q < 10; q++)
            if (col[q] < 0)
                BN_FAIL("log column %s missing", want[q]);
        memcpy(L, E, m * sizeof(double));
        memset(Lp, 0, m * sizeof(double));
        in = fopen(bn_test_tmp("conv.csv"), "r");
        while (fgets(line, sizeof line, in)) {
            double v[16], ch[3] = {0, 0, 0}, s2 = 0, change = 0;
            char *p = line, *end;
            int nv = 0;
            if (line[0] == '#' || line[0] == 'i')
                continue;
            while (nv < 16) {
                v[nv++] = strtod(p, &end);
                if (*end != ',')
                    break;
                p = end + 1;
            }
            BN_ASSERT_EQ(nv, 10);
            if (rows > 0) {   /* L <- E + K L */
                memcpy(Lp, L, m * sizeof(double));
                for (size_t i = 0; i < n; i++)
                    for (int c = 0; c < 3; c++) {
                        double acc = 0;
                        for (size_t j = 0; j < n; j++)
                            acc += (double)(float)F[i * n + j] * Lp[3 * j + c];
                        L[3 * i + c] = E[3 * i + c] + 0.8 * acc;
                    }
                for (size_t q = 0; q < m; q++)
                    change = fmax(change, fabs(L[q] - Lp[q]));
            }
            for (size_t i = 0; i < n; i++)   /* r <- E - (I - K) L */
                for (int c = 0; c < 3; c++) {
                    double acc = 0;
                    for (size_t j = 0; j < n; j++)
                        acc += (double)(float)F[i * n + j] * L[3 * j + c];
                    r[3 * i + c] = E[3 * i + c] - L[3 * i + c] + 0.8 * acc;
                    ch[c] = fmax(ch[c], fabs(r[3 * i + c]));
                    s2 += r[3 * i + c] * r[3 * i + c];
                }
            BN_ASSERT_EQ(v[col[0]], rows);
            BN_ASSERT_REL(v[col[1]], fmax(ch[0], fmax(ch[1], ch[2])), 1e-7);
            BN_ASSERT_REL(v[col[2]], sqrt(s2 / (double)m), 1e-7);
            for (int c = 0; c < 3; c++)
                BN_ASSERT_NEAR(v[col[3 + c]], ch[c], 1e-7 * ch[c] + 1e-300);
            BN_ASSERT_NEAR(v[col[6]], change, 1e-7 * change);
            BN_ASSERT_REL(v[col[7]], pow(knorm, (double)rows + 1) / (1 - knorm) * 1.0, 1e-7);
            BN_ASSERT_REL(v[col[8]], v[col[1]] / (1 - knorm), 1e-7);
            BN_ASSERT_GE(v[col[9]], last_t);
            last_t = v[col[9]];
            BN_ASSERT_LE(v[col[1]], prev * (1 + 1e-12));   /* Jacobi on nonnegative K: monotone here */
            prev = v[col[1]];
            rows++;
        }
        fclose(in);
        free(L);
        free(Lp);
        free(r);
    }
    BN_ASSERT_EQ(rows, res.iterations + 1);
    BN_ASSERT_LE(prev, 1e-6 * res.norm_E);
    free(text);
    bn_solve_result_free(&res);
    bn_transport_destroy(k);
    free(F);
    free(rho);
    free(E);
}

/* Emission over six orders of magnitude: two closed rooms that cannot see each other (two cubes,
 * F block-diagonal), a bright one (Le 1e6, rho 0.5) and a dim one (Le 1, rho 0.99). Exact: L = Le /
 * (1 - rho), 2e6 and 100. The default stop (residual <= tol ||E||_inf = 1) is met long before the
 * slow dim room converges: its answer is far off. The patch stop holds every patch to tol of its
 * own radiance: the dim room comes out to tol / (1 - rho). */
BN_TEST(stop_patch_dim_light)
{
    double *cube = cube_F(), F[144] = {0}, rho[36], E[36];
    bn_transport *k;
    for (int b = 0; b < 2; b++)
        for (int i = 0; i < 6; i++) {
            for (int j = 0; j < 6; j++)
                F[(6 * b + i) * 12 + 6 * b + j] = cube[i * 6 + j];
            for (int c = 0; c < 3; c++) {
                rho[3 * (6 * b + i) + c] = b ? 0.99 : 0.5;
                E[3 * (6 * b + i) + c] = b ? 1 : 1e6;
            }
        }
    k = make_k(12, F, rho, BN_PRECISION_DOUBLE);
    for (int s = 0; s < 2; s++) {
        bn_solve_opts o;
        bn_solve_result res;
        bn_error err;
        double worst_dim = 0;
        bn_solve_opts_default(&o);
        o.method = BN_SOLVE_JACOBI;
        o.stop = s ? BN_SOLVE_STOP_PATCH : BN_SOLVE_STOP_DEFAULT;
        o.log_sink.quiet = 1;
        o.quiet = 1;
        BN_ASSERT_STATUS(bn_solve(k, E, &o, &res, &err), BN_OK);
        for (int i = 6; i < 12; i++)
            for (int c = 0; c < 3; c++)
                worst_dim = fmax(worst_dim, fabs(res.L[3 * i + c] - 100) / 100);
        for (int i = 0; i < 6; i++)
            BN_ASSERT_REL(res.L[3 * i], 2e6, 1e-6);   /* the bright room is fine either way */
        fprintf(stderr, "stop %s: %zu iterations, dim room's worst relative error %.3g\n", bn_solve_stop_name(o.stop),
                res.iterations, worst_dim);
        if (s)
            BN_ASSERT_LE(worst_dim, 1e-6 / (1 - 0.99) * 1.01);
        else
            BN_ASSERT_GT(worst_dim, 0.1);   /* the need was real */
        bn_solve_result_free(&res);
    }
    bn_transport_destroy(k);
    free(cube);
}
