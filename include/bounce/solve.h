/* bounce: solving (I - K) L = E per channel by Jacobi, Gauss-Seidel, the truncated Neumann series
 * and a direct LAPACK solve; one driver, one monitor, stop reasons (PETSc's KSP shape). */
#ifndef BOUNCE_SOLVE_H
#define BOUNCE_SOLVE_H

#include <stddef.h>
#include <stdio.h>
#include "bounce/transport.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum bn_solve_method { BN_SOLVE_JACOBI, BN_SOLVE_GAUSS_SEIDEL, BN_SOLVE_NEUMANN, BN_SOLVE_DIRECT } bn_solve_method;
const char *bn_solve_method_name(bn_solve_method m);   /* "jacobi", "gauss-seidel", "neumann", "direct" */

/* Why a solve stopped. Stopping is a reason, not an error (PETSc's KSPConvergedReason). */
typedef enum bn_stop_reason {
    BN_STOP_NONE,
    BN_STOP_CONVERGED_RTOL,   /* ||r||_inf <= tol * ||E||_inf (or the series tail bound is) */
    BN_STOP_CONVERGED_ATOL,   /* ||r||_inf <= atol */
    BN_STOP_DIRECT,           /* direct solve done */
    BN_STOP_MAX_ITER,         /* iteration limit reached first */
    BN_STOP_DIVERGED_NAN,
    BN_STOP_DIVERGED_GROWTH,
    BN_STOP_SINGULAR          /* ||K|| >= 1 - threshold: I - K is (near) singular */
} bn_stop_reason;
const char *bn_stop_reason_name(bn_stop_reason r);

typedef struct bn_solve_opts {
    bn_solve_method method;   /* default gauss-seidel */
    double tol;               /* relative to ||E||_inf over all channels (default 1e-6) */
    double atol;              /* absolute (default 0) */
    size_t max_iter;          /* default 100000 */
    int    symmetric;         /* Gauss-Seidel: forward then backward sweep */
    int    bounces;           /* keep K^0 E .. K^bounces E separately (default 3); -1: none */
    FILE  *log;               /* convergence table (CSV), NULL for none */
    const char *log_header;   /* `# key=value` lines written before the table (provenance) */
    int    quiet;
} bn_solve_opts;
void bn_solve_opts_default(bn_solve_opts *o);

typedef struct bn_solve_result {
    size_t n;                 /* patches */
    double *L;                /* N*3: the solution (owned) */
    int     nterms;           /* terms kept: K^0 E .. K^(nterms-1) E */
    double **terms;           /* nterms arrays of N*3 (owned) */
    bn_stop_reason reason;
    size_t iterations;
    double residual_max, residual_rms;   /* final ||E - (I - K) L|| (inf and RMS over all entries) */
    double norm_E;            /* ||E||_inf */
    double k_norm_inf;        /* ||K||_inf */
    double spectral_radius;   /* power-iteration estimate of rho(K) */
    size_t predicted_iterations;  /* from the spectral radius, before iterating */
    double seconds;
} bn_solve_result;

/* Solves (I - K) L = E. E: N*3 (borrowed). Fills *res (free with bn_solve_result_free). Returns
 * BN_OK when converged, BN_ENOTCONV at the iteration limit, BN_ENUMERIC when diverged or
 * singular (res->reason says which), BN_EINTR/BN_ETERM when interrupted. */
bn_status bn_solve(const bn_transport *k, const double *E, const bn_solve_opts *o, bn_solve_result *res,
                   bn_error *err);
void bn_solve_result_free(bn_solve_result *res);

#ifdef __cplusplus
}
#endif
#endif
