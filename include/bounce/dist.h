/* bounce over MPI processes: who this process is among P, and the few collectives the
 * distributed parts use. Built with MPI (CMake option BOUNCE_MPI, on when MPI is found) a process
 * started by mpirun joins MPI_COMM_WORLD; every other process (and every process of a build
 * without MPI) is rank 0 of 1, so the serial path is unchanged.
 *
 * Determinism: the distributed parts split whole items (a patch's or region's samples, an image
 * row) among ranks, each item computed exactly as one process computes it, and bn_dist_sum
 * combines arrays in which each element is nonzero on at most one rank: x + 0 + ... + 0 = x
 * exactly, so P processes give one process's bits (zeros are written as +0). */
#ifndef BOUNCE_DIST_H
#define BOUNCE_DIST_H

#include "bounce/status.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Joins MPI when built with it and started by mpirun (OMPI_COMM_WORLD_SIZE, PMIX_RANK or PMI_SIZE
 * in the environment); else nothing (no MPI start-up cost for a plain run). Call once, first. */
bn_status bn_dist_init(int *argc, char ***argv, bn_error *err);
void bn_dist_finalize(void);
int bn_dist_rank(void);       /* 0 .. size - 1 */
int bn_dist_size(void);       /* 1 without MPI */
int bn_dist_built(void);      /* 1 when this library was built with MPI */
/* Does item i belong to this rank? (cyclic: i mod P == rank; all items with one process) */
int bn_dist_mine(size_t i);
/* In place over all ranks: x[k] = sum over ranks of x[k], in rank order (see Determinism). */
bn_status bn_dist_sum(double *x, size_t n, bn_error *err);
bn_status bn_dist_sum_float(float *x, size_t n, bn_error *err);
bn_status bn_dist_sum_u64(unsigned long long *x, size_t n, bn_error *err);
/* In place: rank q's block x[bound[q] * width .. bound[q + 1] * width) goes to every rank (bound: P + 1
 * nondecreasing element offsets, the same on every rank). Values are copied, not combined: exact. */
bn_status bn_dist_allgather(double *x, const size_t *bound, size_t width, bn_error *err);
/* Every rank sends count[q] items of `item` bytes to rank q (send: the blocks in rank order) and
 * receives what every rank sends it, in rank order, into *recv (malloc'd; *nrecv items; NULL when
 * none). One process: a copy of its own block. */
bn_status bn_dist_exchange(const void *send, const size_t *count, size_t item, void **recv, size_t *nrecv,
                           bn_error *err);
/* Any rank's failure ends them all: every rank returns the status of the lowest-numbered rank that
 * failed (BN_OK only when all are OK). A collective: every rank must call it. */
bn_status bn_dist_agree(bn_status st);
/* Ends every rank (MPI_Abort) with exit code `code`; a plain exit without MPI. */
void bn_dist_abort(int code);

#ifdef __cplusplus
}
#endif
#endif
