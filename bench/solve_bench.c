/* Solver benchmark: seconds per sweep and effective bandwidth of the dense-float K application
 * beside a STREAM-like triad measured in the same run (target >= 80%), and iterative against
 * direct solve times for N = 1k, 4k, 8k on a synthetic F. Prints a markdown table. Not a test.
 * usage: solve_bench [--quick] [--sizes 1024,4096,8192] [--reps R]                              */
#include "bounce/solve.h"
#include "bounce/transport.h"
#include "base/internal.h"
#include "triad.h"

#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static uint64_t rng = 0x2545F4914F6CDD1DULL;
static double urand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) * 0x1.0p-53;
}

/* A synthetic closed-room F in float: zero diagonal, rows summing to 0.9 .. 1. Filled through
 * the dense storage's builder, as the form factors are. */
static bn_transport *synthetic_k(size_t n, int grey)
{
    bn_builder_opts bo;
    bn_transport_builder *b;
    bn_transport *k = NULL;
    bn_error err;
    double *rho = malloc(3 * n * sizeof(double)), *row = malloc(n * sizeof(double));
    size_t *cols = malloc(n * sizeof(size_t));
    bn_builder_opts_default(&bo);
    if (bn_transport_builder_create(n, &bo, NULL, &b, &err) != BN_OK) {
        fprintf(stderr, "%s\n", err.msg);
        exit(4);
    }
    for (size_t j = 0; j < n; j++)
        cols[j] = j;
    for (size_t i = 0; i < n; i++) {
        double s = 0, target = 0.9 + 0.1 * urand();
        for (size_t j = 0; j < n; j++)
            s += row[j] = j == i ? 0.0 : (double)(float)(0.05 + urand() * urand());
        for (size_t j = 0; j < n; j++)
            row[j] *= target / s;
        bn_transport_builder_put_row(b, i, cols, row, n, &err);
        for (int c = 0; c < 3; c++)
            rho[3 * i + c] = grey ? 0.7 : (c == 0 ? 0.75 : c == 1 ? 0.6 : 0.5);
    }
    if (bn_transport_builder_finish(b, rho, &k, NULL, &err) != BN_OK) {
        fprintf(stderr, "%s\n", err.msg);
        exit(1);
    }
    free(rho);
    free(row);
    free(cols);
    return k;
}

typedef struct timing {
    double seconds;
    size_t iterations;
    const char *reason;
} timing;

static timing run(const bn_transport *k, const double *E, bn_solve_method m, double tol)
{
    bn_solve_opts o;
    bn_solve_result res;
    bn_error err;
    timing t;
    bn_solve_opts_default(&o);
    o.method = m;
    o.tol = tol;
    o.bounces = -1;
    o.log_sink.quiet = 1;
    if (bn_solve(k, E, &o, &res, &err) != BN_OK)
        fprintf(stderr, "%s: %s\n", bn_solve_method_name(m), err.msg);
    t.seconds = res.seconds_analyse + res.seconds_iterate;
    t.iterations = res.iterations;
    t.reason = bn_stop_reason_name(res.reason);
    bn_solve_result_free(&res);
    return t;
}

int main(int argc, char **argv)
{
    size_t sizes[8] = {1024, 4096, 8192}, nsizes = 3;
    int reps = 9, quick = 0, threads = omp_get_max_threads();
    double triad1, triad, tol = 1e-6;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--quick") == 0) {
            quick = 1;
            sizes[0] = 512, sizes[1] = 1024, nsizes = 2, reps = 5;
        } else if (strcmp(argv[i], "--reps") == 0 && i + 1 < argc) {
            reps = atoi(argv[++i]);
            if (reps < 1 || reps > 32)
                reps = 9;
        } else if (strcmp(argv[i], "--sizes") == 0 && i + 1 < argc) {
            char *p = argv[++i];
            nsizes = 0;
            while (*p && nsizes < 8) {
                sizes[nsizes++] = strtoul(p, &p, 10);
                if (*p == ',')
                    p++;
            }
        } else {
            fprintf(stderr, "usage: solve_bench [--quick] [--sizes N1,N2,...] [--reps R]\n");
            return 2;
        }
    }
    /* the triad over 3 x 256 MiB (3 x 32 MiB quick): larger than any cache */
    {
        size_t tn = quick ? (size_t)1 << 22 : (size_t)1 << 25;
        omp_set_num_threads(1);
        triad1 = bench_triad_gbs(tn, reps);
        omp_set_num_threads(threads);
        triad = bench_triad_gbs(tn, reps);
    }
    printf("# solve_bench: dense-float K application and solves (%d threads; median of %d)\n\n", threads, reps);
    printf("STREAM-like triad: %.1f GB/s on 1 thread, %.1f GB/s on %d threads\n\n", triad1, triad, threads);
    printf("| N | K bytes | apply s/sweep (%dT) | GB/s | / triad | apply 1T GB/s | / triad 1T | GS s/sweep (serial) | "
           "rho(K) | Jacobi it | Jacobi s | GS it | GS s | Neumann it | Neumann s | direct s | direct / GS |\n",
           threads);
    printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (size_t q = 0; q < nsizes; q++) {
        size_t n = sizes[q], m = 3 * n;
        bn_transport *k = synthetic_k(n, 1);
        double *x = malloc(m * sizeof(double)), *y = malloc(m * sizeof(double)), *E = calloc(m, sizeof(double));
        double t[32], t1[32], bytes = (double)n * (double)n * 4.0, apply, apply1, gs_sweep, est, low;
        size_t steps;
        timing tj, tg, tn, td;
        bn_error err;
        for (size_t i = 0; i < m; i++)
            x[i] = 1.0 + 1e-3 * (double)(i % 17);
        for (size_t i = 0; i < n; i += 97)
            E[3 * i] = E[3 * i + 1] = E[3 * i + 2] = 10.0;
        bn_transport_apply(k, x, y, NULL);   /* warm */
        for (int r = 0; r < reps; r++) {
            double t0 = bn__now();
            bn_transport_apply(k, x, y, NULL);
            t[r] = bn__now() - t0;
        }
        apply = bench_median(t, reps);
        omp_set_num_threads(1);
        for (int r = 0; r < reps; r++) {
            double t0 = bn__now();
            bn_transport_apply(k, x, y, NULL);
            t1[r] = bn__now() - t0;
        }
        omp_set_num_threads(threads);
        apply1 = bench_median(t1, reps);
        {
            double t0 = bn__now();
            for (size_t i = 0; i < n; i++) {
                double out[3];
                bn_transport_row(k, i, x, out, NULL);
                x[3 * i] = out[0] * 1e-9 + 1.0;   /* in place, like a sweep */
            }
            gs_sweep = bn__now() - t0;
        }
        bn_solve_spectral_radius(k, 100, &est, &low, &steps, &err);
        tj = run(k, E, BN_SOLVE_JACOBI, tol);
        tg = run(k, E, BN_SOLVE_GAUSS_SEIDEL, tol);
        tn = run(k, E, BN_SOLVE_NEUMANN, tol);
        td = run(k, E, BN_SOLVE_DIRECT, tol);
        printf("| %zu | %.0f MiB | %.4f | %.1f | %.0f%% | %.1f | %.0f%% | %.4f | %.3f | %zu | %.3f | %zu | %.3f | %zu | %.3f | "
               "%.3f | %.1fx |\n",
               n, bytes / 1048576.0, apply, bytes / apply / 1e9, 100.0 * bytes / apply / 1e9 / triad,
               bytes / apply1 / 1e9, 100.0 * bytes / apply1 / 1e9 / triad1, gs_sweep, est, tj.iterations, tj.seconds,
               tg.iterations, tg.seconds, tn.iterations, tn.seconds, td.seconds, td.seconds / tg.seconds);
        fflush(stdout);
        bn_transport_destroy(k);
        free(x);
        free(y);
        free(E);
    }
    printf("\nSolves to tol %g (relative to ||E||_inf); iterative times include the analysis (norm, power iteration)\n"
           "and one K application per iteration for the residual; GS sweeps are serial (thread-count invariant).\n"
           "direct: LAPACKE_dgesv on a dense double copy; rho is grey here, so one LU serves the three channels\n"
           "(a coloured scene needs three). Synthetic F: random, zero diagonal, row sums 0.9..1.\n", tol);
    return 0;
}
