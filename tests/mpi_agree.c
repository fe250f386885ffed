/* bn_dist_agree under mpirun -np 2: every rank returns the status of the lowest failing rank,
 * whatever the statuses' places in the status table (the largest number won before: an
 * interruption on rank 1 hid the bad input rank 0 had found). Prints "ok"/"FAIL" lines; exit 1 on
 * a failure. Run by tests/mpi.cmake. */
#include "bounce/dist.h"

#include <stdio.h>

static int fails = 0;

static void expect(bn_status mine0, bn_status mine1, bn_status want, const char *what)
{
    bn_status got = bn_dist_agree(bn_dist_rank() == 0 ? mine0 : mine1);
    if (got != want)
        fails++;
    printf("%s rank %d: %s -> %s (want %s)\n", got == want ? "ok  " : "FAIL", bn_dist_rank(), what,
           bn_status_name(got), bn_status_name(want));
}

int main(int argc, char **argv)
{
    bn_error err;
    if (bn_dist_init(&argc, &argv, &err) != BN_OK || bn_dist_size() != 2) {
        fprintf(stderr, "mpi_agree: run under mpirun -np 2\n");
        return 2;
    }
    expect(BN_OK, BN_OK, BN_OK, "both OK");
    expect(BN_EINPUT, BN_ETERM, BN_EINPUT, "rank 0 bad input, rank 1 interrupted");
    expect(BN_OK, BN_ENOMEM, BN_ENOMEM, "rank 1 alone out of memory");
    expect(BN_ENUMERIC, BN_OK, BN_ENUMERIC, "rank 0 alone numerical");
    bn_dist_finalize();
    return fails ? 1 : 0;
}
