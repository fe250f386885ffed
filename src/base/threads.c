/* Thread count for OpenMP loops, and the default memory limit. */
#include "bounce/status.h"
#include "base/internal.h"
#include <omp.h>
#include <stdint.h>

int bn_threads_resolve(int threads) { return threads > 0 ? threads : omp_get_max_threads(); }

/* The calling thread's OpenMP thread count for the duration of one library call (OpenMP keeps it
 * per calling thread), restored afterwards; 0 leaves it as the caller has it, so a call inside
 * another (the study's solves) inherits the outer call's count. */
int bn__threads_begin(int threads)
{
    int prev = omp_get_max_threads();
    if (threads > 0)
        omp_set_num_threads(threads);
    return prev;
}

void bn__threads_end(int prev) { omp_set_num_threads(prev); }

size_t bn_memory_limit_default(void)
{
    size_t phys = bn__physical_memory();
    return phys ? phys / 10 * 8 : SIZE_MAX;
}
