/* The solver-method interface behind bn_solve (GSL's fsolver_type, PETSc's KSP impls/):
 * one const table per method, one driver (solve.c) for all of them. Not installed. */
#ifndef BOUNCE_SOLVE_INTERNAL_H
#define BOUNCE_SOLVE_INTERNAL_H

#include "bounce/solve.h"

/* What every method's setup receives. All arrays are N*3, interleaved x[3i+c]; borrowed. */
typedef struct bn__solve_ctx {
    const bn_transport *k;
    const double *E;
    const double *diag;       /* K_ii = rho_ic F_ii, or NULL when every F_ii = 0 or the operator
                                 cannot say (the methods then iterate L <- E + K L) */
    const bn_solve_opts *o;
    size_t n;
} bn__solve_ctx;

typedef struct bn_solver_type {
    const char *name;
    unsigned    needs;        /* BN_OP_* capabilities of K the method cannot do without */
    size_t      state_size;
    int         sweeps;       /* applications of K per iteration, for the a priori bound */
    /* L0 = E and r0 = E - (I - K) L0 = K E are given (the driver computed them). */
    bn_status (*setup)(void *st, const bn__solve_ctx *ctx, const double *L0, const double *r0, bn_error *err);
    /* One iteration: L <- next iterate. Sets *have_r to 1 when it also wrote r = E - (I - K) L for
     * the new L as a by-product (one application of K per iteration), 0 when the driver must. */
    bn_status (*iterate)(void *st, double *L, double *r, int *have_r, bn_error *err);
    void      (*cleanup)(void *st);
    /* Non-iterative methods (direct) fill L instead of setup/iterate/cleanup. */
    bn_status (*solve)(const bn__solve_ctx *ctx, double *L, int *singular, bn_error *err);
    /* 1: the residual r after iteration k is exactly K^(k+1) E, made by applying K to K^k E as the
     * per-bounce terms are (the Neumann series): the driver keeps it as that term. */
    int residual_is_term;
} bn_solver_type;

extern const bn_solver_type bn__solver_jacobi;
extern const bn_solver_type bn__solver_gauss_seidel;
extern const bn_solver_type bn__solver_gauss_seidel_symmetric;
extern const bn_solver_type bn__solver_neumann;
extern const bn_solver_type bn__solver_direct;

#endif
