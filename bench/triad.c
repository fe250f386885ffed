/* The benches' triad and median (triad.h). */
#include "triad.h"
#include "base/internal.h"

#include <stdio.h>
#include <stdlib.h>

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

double bench_median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double bench_triad_gbs(size_t n, int reps)
{
    double *a = malloc(n * sizeof(double)), *b = malloc(n * sizeof(double)), *c = malloc(n * sizeof(double));
    double t[32], s = 3.0;
    long ln = (long)n;
    if (!a || !b || !c) {
        fprintf(stderr, "triad: out of memory for 3 x %zu doubles\n", n);
        exit(1);
    }
    reps = reps < 1 ? 1 : reps > 32 ? 32 : reps;
#pragma omp parallel for schedule(static)
    for (long i = 0; i < ln; i++) {
        a[i] = 0;
        b[i] = 1;
        c[i] = 2;
    }
    for (int r = 0; r < reps; r++) {
        double t0 = bn__now();
#pragma omp parallel for schedule(static)
        for (long i = 0; i < ln; i++)
            a[i] = b[i] + s * c[i];
        t[r] = bn__now() - t0;
    }
    if (a[n / 2] != 7.0)
        fprintf(stderr, "triad check failed\n");
    free(a);
    free(b);
    free(c);
    return 3.0 * 8.0 * (double)n / bench_median(t, reps) / 1e9;
}

