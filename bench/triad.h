/* The machine's memory bandwidth as the benches measure it: a STREAM-like triad a = b + s c over
 * arrays far larger than the caches, bytes counted as STREAM does (3 x 8 per element, no
 * write-allocate), on the threads OpenMP has; and a median. Shared by solve_bench and hop_bench. */
#ifndef BN_BENCH_TRIAD_H
#define BN_BENCH_TRIAD_H
#include <stddef.h>

/* GB/s, the median of reps (at most 32) runs over n doubles per array. */
double bench_triad_gbs(size_t n, int reps);
/* The median of v[0 .. n) (v is sorted). */
double bench_median(double *v, int n);

#endif
