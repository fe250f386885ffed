/* The solver-method interface behind bn_solve (GSL's fsolver_type, PETSc's KSP impls/):
 * one const table per method, one driver (solve.c) for all of them. Not installed. */
#ifndef BOUNCE_SOLVE_INTERNAL_H
#define BOUNCE_SOLVE_INTERNAL_H

#include "bounce/solve.h"

/* What every method's setup receives. All arrays are N*3, interleaved x[3i+c]; borrowed. */
typedef struct bn__solve_ctx {
    const bn_transport *k;
    const double *E;
    const double *diag;       /* K_ii = rho_ic F_ii, or NULL when every F_ii = 0 */
    const bn_solve_opts *o;
    size_t n;
} bn__solve_ctx;

typedef struct bn_solver_type {
    const char *name;
    size_t      state_size;
    int         sweeps;       /* applications of K per iteration, for the a priori bound */
    /* L0 = E and r0 = E - (I - K) L0 = K E are given (the driver computed them). */
    bn_status (*setup)(void *st, const bn__solve_ctx *ctx, const double *L0, const double *r0, bn_error *err);
    /* One iteration: L <- next iterate. Returns 1 when it also wrote r = E - (I - K) L for the
     * new L as a by-product (one application of K per iteration), 0 when the driver must. */
    int       (*iterate)(void *st, double *L, double *r);
    void      (*cleanup)(void *st);
    /* Non-iterative methods (direct) fill L instead of setup/iterate/cleanup. */
    bn_status (*solve)(const bn__solve_ctx *ctx, double *L, int *singular, bn_error *err);
} bn_solver_type;

extern const bn_solver_type bn__solver_jacobi;
extern const bn_solver_type bn__solver_gauss_seidel;
extern const bn_solver_type bn__solver_gauss_seidel_symmetric;
extern const bn_solver_type bn__solver_neumann;
extern const bn_solver_type bn__solver_direct;

#endif
