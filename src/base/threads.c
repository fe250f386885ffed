/* Thread count for OpenMP loops, and the default memory limit. */
#include "bounce/status.h"
#include "base/internal.h"
#include <omp.h>
#include <stdint.h>

void bn_threads_set(int n) { omp_set_num_threads(n > 0 ? n : omp_get_num_procs()); }
int bn_threads_get(void) { return omp_get_max_threads(); }

size_t bn_memory_limit_default(void)
{
    size_t phys = bn__physical_memory();
    return phys ? phys / 10 * 8 : SIZE_MAX;
}
