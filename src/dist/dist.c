/* bounce over MPI processes (include/bounce/dist.h). Without BN_HAVE_MPI: rank 0 of 1. */
#include "bounce/dist.h"
#include "base/internal.h"

#include <limits.h>
#include <stdlib.h>
#include <string.h>

#ifdef BN_HAVE_MPI
#include <mpi.h>
#endif

static int bn__rank = 0, bn__size = 1, bn__joined = 0;

int bn_dist_built(void)
{
#ifdef BN_HAVE_MPI
    return 1;
#else
    return 0;
#endif
}

bn_status bn_dist_init(int *argc, char ***argv, bn_error *err)
{
#ifdef BN_HAVE_MPI
    int provided = 0;
    if (!getenv("OMPI_COMM_WORLD_SIZE") && !getenv("PMIX_RANK") && !getenv("PMI_SIZE"))
        return BN_OK;   /* not started by mpirun: one process, no MPI */
    /* funneled: only the main thread calls MPI; OpenMP threads work between the calls */
    if (MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
        return bn_error_set(err, BN_EINTERNAL, "MPI_Init_thread failed");
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    MPI_Comm_rank(MPI_COMM_WORLD, &bn__rank);
    MPI_Comm_size(MPI_COMM_WORLD, &bn__size);
    bn__set_writer_rank(bn__rank);
    bn__joined = 1;
#else
    (void)argc;
    (void)argv;
    (void)err;
#endif
    return BN_OK;
}

void bn_dist_finalize(void)
{
#ifdef BN_HAVE_MPI
    if (bn__joined)
        MPI_Finalize();
    bn__joined = 0;
#endif
}

int bn_dist_rank(void) { return bn__rank; }
int bn_dist_size(void) { return bn__size; }
int bn_dist_mine(size_t i) { return bn__size == 1 || (int)(i % (size_t)bn__size) == bn__rank; }

#ifdef BN_HAVE_MPI
/* In place over all ranks, in pieces (MPI counts are int). */
static bn_status bn__allreduce_sum(void *x, size_t n, size_t elem, MPI_Datatype type, bn_error *err)
{
    size_t done = 0;
    while (bn__size > 1 && done < n) {
        int c = n - done > (size_t)(1 << 28) ? 1 << 28 : (int)(n - done);
        if (MPI_Allreduce(MPI_IN_PLACE, (char *)x + done * elem, c, type, MPI_SUM, MPI_COMM_WORLD) != MPI_SUCCESS)
            return bn_error_set(err, BN_EINTERNAL, "MPI_Allreduce of %zu values failed (rank %d of %d)", n, bn__rank,
                                bn__size);
        done += (size_t)c;
    }
    return BN_OK;
}
#endif

/* -0 + 0 = +0 on some ranks only: every zero is written as +0 first */
bn_status bn_dist_sum(double *x, size_t n, bn_error *err)
{
    for (size_t k = 0; k < n; k++)
        if (x[k] == 0)
            x[k] = 0;
#ifdef BN_HAVE_MPI
    return bn__allreduce_sum(x, n, sizeof *x, MPI_DOUBLE, err);
#else
    (void)err;
    return BN_OK;
#endif
}

bn_status bn_dist_sum_float(float *x, size_t n, bn_error *err)
{
    for (size_t k = 0; k < n; k++)
        if (x[k] == 0)
            x[k] = 0;
#ifdef BN_HAVE_MPI
    return bn__allreduce_sum(x, n, sizeof *x, MPI_FLOAT, err);
#else
    (void)err;
    return BN_OK;
#endif
}

bn_status bn_dist_sum_u64(unsigned long long *x, size_t n, bn_error *err)
{
#ifdef BN_HAVE_MPI
    if (bn__size > 1 && n > 0 &&
        MPI_Allreduce(MPI_IN_PLACE, x, (int)n, MPI_UNSIGNED_LONG_LONG, MPI_SUM, MPI_COMM_WORLD) != MPI_SUCCESS)
        return bn_error_set(err, BN_EINTERNAL, "MPI_Allreduce of %zu counts failed (rank %d of %d)", n, bn__rank,
                            bn__size);
#else
    (void)x;
    (void)n;
    (void)err;
#endif
    return BN_OK;
}

bn_status bn_dist_allgather(double *x, const size_t *bound, size_t width, bn_error *err)
{
#ifdef BN_HAVE_MPI
    size_t P = (size_t)bn__size;
    if (P > 1) {
        int *cnt = bn__calloc(2 * P, sizeof(int)), *disp;
        bn_status st = BN_OK;
        if (!cnt)
            return bn_error_set(err, BN_ENOMEM, "out of memory for an all-gather among %zu processes", P);
        disp = cnt + P;
        if (bound[P] * width > INT_MAX) {
            free(cnt);
            return bn_error_set(err, BN_ENOMEM, "an all-gather of more than 2^31 values");
        }
        for (size_t q = 0; q < P; q++) {
            cnt[q] = (int)((bound[q + 1] - bound[q]) * width);
            disp[q] = (int)(bound[q] * width);
        }
        if (MPI_Allgatherv(MPI_IN_PLACE, 0, MPI_DATATYPE_NULL, x, cnt, disp, MPI_DOUBLE, MPI_COMM_WORLD) != MPI_SUCCESS)
            st = bn_error_set(err, BN_EINTERNAL, "MPI_Allgatherv of %zu values failed (rank %d of %d)",
                              bound[P] * width, bn__rank, bn__size);
        free(cnt);
        return st;
    }
#else
    (void)x;
    (void)bound;
    (void)width;
#endif
    (void)err;
    return BN_OK;
}

bn_status bn_dist_exchange(const void *send, const size_t *count, size_t item, void **recv, size_t *nrecv,
                           bn_error *err)
{
    size_t P = (size_t)bn__size, total = 0;
    *recv = NULL;
    *nrecv = 0;
#ifdef BN_HAVE_MPI
    if (P > 1) {
        int *sc = bn__calloc(4 * P, sizeof(int)), *sd = sc + P, *rc = sc + 2 * P, *rd = sc + 3 * P;
        unsigned long long *all = bn__calloc(P * P, sizeof *all);
        MPI_Datatype type;
        size_t off = 0;
        bn_status st = BN_OK;
        if (!sc || !all) {
            free(sc);
            free(all);
            return bn_error_set(err, BN_ENOMEM, "out of memory for an exchange among %zu processes", P);
        }
        /* every rank's counts to every rank (as a sum: each row is one rank's) */
        for (size_t q = 0; q < P; q++)
            all[(size_t)bn__rank * P + q] = count[q];
        if ((st = bn_dist_sum_u64(all, P * P, err)) != BN_OK)
            goto out;
        for (size_t q = 0; q < P; q++) {
            unsigned long long in = all[q * P + (size_t)bn__rank];
            if (count[q] > INT_MAX || in > INT_MAX || off > INT_MAX || total > INT_MAX) {
                st = bn_error_set(err, BN_ENOMEM, "an exchange of more than 2^31 items between two processes");
                goto out;
            }
            sc[q] = (int)count[q];
            sd[q] = (int)off;
            rc[q] = (int)in;
            rd[q] = (int)total;
            off += count[q];
            total += in;
        }
        if (!(*recv = bn__malloc_array(total ? total : 1, item))) {
            st = bn_error_set(err, BN_ENOMEM, "out of memory for %zu items received", total);
            goto out;
        }
        if (MPI_Type_contiguous((int)item, MPI_BYTE, &type) != MPI_SUCCESS || MPI_Type_commit(&type) != MPI_SUCCESS) {
            st = bn_error_set(err, BN_EINTERNAL, "MPI_Type_contiguous of %zu bytes failed", item);
            goto out;
        }
        if (MPI_Alltoallv(send, sc, sd, type, *recv, rc, rd, type, MPI_COMM_WORLD) != MPI_SUCCESS)
            st = bn_error_set(err, BN_EINTERNAL, "MPI_Alltoallv of %zu items failed (rank %d of %d)", total, bn__rank,
                              bn__size);
        MPI_Type_free(&type);
    out:
        free(sc);
        free(all);
        if (st != BN_OK) {
            free(*recv);
            *recv = NULL;
            return st;
        }
        *nrecv = total;
        return BN_OK;
    }
#endif
    total = count[0];
    if (!(*recv = bn__malloc_array(total ? total : 1, item)))
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu items", total);
    if (total)
        memcpy(*recv, send, total * item);
    *nrecv = total;
    return BN_OK;
}

bn_status bn_dist_agree(bn_status st)
{
#ifdef BN_HAVE_MPI
    if (bn__size > 1) {
        /* the lowest failing rank, then its status from it: which failure wins depends on the
         * ranks, never on where a status stands in the status table */
        int mine = st != BN_OK ? bn__rank : bn__size, first = mine, all = (int)st;
        if (MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD) != MPI_SUCCESS)
            return BN_EINTERNAL;
        if (first == bn__size)
            return BN_OK;
        if (MPI_Bcast(&all, 1, MPI_INT, first, MPI_COMM_WORLD) != MPI_SUCCESS)
            return BN_EINTERNAL;
        return (bn_status)all;
    }
#endif
    return st;
}

void bn_dist_abort(int code)
{
#ifdef BN_HAVE_MPI
    if (bn__joined && bn__size > 1)
        MPI_Abort(MPI_COMM_WORLD, code);
#endif
    exit(code);
}
