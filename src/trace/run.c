/* The parallel run the camera and the per-patch estimators share: items (pixel rows, patches,
 * regions) over the threads with per-thread sample buffers, this process's share under mpirun,
 * the interrupt, and the combination of the ranks' sums. */
#include "trace/trace_internal.h"
#include "bounce/dist.h"

#include <stdlib.h>

int bn__trace_parallel(size_t n, size_t m, size_t moments, bn__trace_item_fn item, void *ctx, bn__progress *prog,
                       unsigned long long *rays)
{
    int no_buffers = 0;
    size_t done = 0;
    unsigned long long total = 0;
#pragma omp parallel reduction(+ : total)
    {
        double *sample = malloc(m * sizeof(double)), *mean = malloc(m * sizeof(double)),
               *m2 = malloc(moments * m * sizeof(double));
        if (!sample || !mean || !m2) {
#pragma omp atomic write
            no_buffers = 1;
        }
#pragma omp for schedule(dynamic, 1)
        for (size_t i = 0; i < n; i++) {
            /* after an interrupt (or without buffers) the remaining iterations do nothing; under
             * mpirun each rank runs its own items (bn_dist_mine), whole, as one process would */
            if (!sample || !mean || !m2 || bn_interrupted() != BN_OK || !bn_dist_mine(i))
                continue;
            item(ctx, i, sample, mean, m2, &total);
            bn__progress_step(prog, &done, 1);
        }
        free(sample);
        free(mean);
        free(m2);
    }
    *rays += total;
    return no_buffers;
}

bn_status bn__trace_stopped(int no_buffers, bn_error *err)
{
    bn_status s = bn_interrupted();
    if (s != BN_OK)
        return bn_error_set(err, s, "trace: interrupted");
    if (no_buffers)
        return bn_error_set(err, BN_ENOMEM, "trace: out of memory for per-thread sample buffers");
    return BN_OK;
}

bn_status bn__trace_combine(int no_buffers, void *mean, void *spread, double *third, int dbl, size_t n,
                            unsigned long long *rays, bn_error *err)
{
    bn_status here = no_buffers ? BN_ENOMEM : bn_interrupted(), all = bn_dist_agree(here), st;
    if (all != BN_OK && here == BN_OK)
        return bn_error_set(err, all, "trace: another MPI process failed (%s)", bn_status_str(all));
    if (all != BN_OK)
        return BN_OK;   /* this rank's own failure: reported by the caller */
    st = dbl ? bn_dist_sum(mean, n, err) : bn_dist_sum_float(mean, n, err);
    if (st == BN_OK)
        st = dbl ? bn_dist_sum(spread, n, err) : bn_dist_sum_float(spread, n, err);
    if (st == BN_OK && third)
        st = bn_dist_sum(third, n, err);
    if (st == BN_OK)
        st = bn_dist_sum_u64(rays, 1, err);
    return st;
}
