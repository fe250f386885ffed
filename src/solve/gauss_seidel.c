/* Gauss-Seidel on (I - K) L = E: a forward sweep L_i <- (E_i + sum_{j<i} K_ij L_j^new
 * + sum_{j>i} K_ij L_j^old) / (1 - K_ii), in place; the symmetric variant follows it with a
 * backward sweep (SSOR with omega = 1). For nonnegative K with rho(K) < 1 it converges at least
 * as fast as Jacobi (Stein-Rosenberg; Varga, Matrix Iterative Analysis, thm. 3.8). The sweep is
 * serial by nature (so the result does not depend on the thread count); the residual of the new
 * iterate is left to the driver (one parallel application of K). */
#include "solve/solve_internal.h"
#include "base/internal.h"

typedef struct bn__gs {
    const bn__solve_ctx *ctx;
} bn__gs;

static bn_status bn__gs_setup(void *st, const bn__solve_ctx *ctx, const double *L0, const double *r0, bn_error *err)
{
    bn__gs *s = st;
    (void)L0;
    (void)r0;
    (void)err;
    s->ctx = ctx;
    return BN_OK;
}

static bn_status bn__gs_update(const bn__solve_ctx *ctx, size_t i, double *L, bn_error *err)
{
    double kl[3];
    const double *d = ctx->diag;
    /* kl <- (K L)_i with the newest L;  L_i <- (E_i + kl - K_ii L_i) / (1 - K_ii) */
    bn_status st = bn_transport_row(ctx->k, i, L, kl, err);
    if (st != BN_OK)
        return st;
    for (int c = 0; c < 3; c++) {
        size_t q = 3 * i + (size_t)c;
        L[q] = d ? (ctx->E[q] + kl[c] - d[q] * L[q]) / (1.0 - d[q]) : ctx->E[q] + kl[c];
    }
    return BN_OK;
}

static bn_status bn__gs_iterate(void *st, double *L, double *r, int *have_r, bn_error *err)
{
    bn__gs *s = st;
    bn_status rc = BN_OK;
    (void)r;
    *have_r = 0;
    for (size_t i = 0; i < s->ctx->n && rc == BN_OK; i++)
        rc = bn__gs_update(s->ctx, i, L, err);
    return rc;
}

static bn_status bn__gs_iterate_symmetric(void *st, double *L, double *r, int *have_r, bn_error *err)
{
    bn__gs *s = st;
    bn_status rc = BN_OK;
    (void)r;
    *have_r = 0;
    for (size_t i = 0; i < s->ctx->n && rc == BN_OK; i++)
        rc = bn__gs_update(s->ctx, i, L, err);
    for (size_t i = s->ctx->n; i-- > 0 && rc == BN_OK;)
        rc = bn__gs_update(s->ctx, i, L, err);
    return rc;
}

static void bn__gs_cleanup(void *st) { (void)st; }

const bn_solver_type bn__solver_gauss_seidel = {"gauss-seidel", BN_OP_ROWS, sizeof(bn__gs), 1, bn__gs_setup, bn__gs_iterate,
                                                bn__gs_cleanup, NULL, 0};
const bn_solver_type bn__solver_gauss_seidel_symmetric = {
    "gauss-seidel-symmetric", BN_OP_ROWS, sizeof(bn__gs), 2, bn__gs_setup, bn__gs_iterate_symmetric, bn__gs_cleanup, NULL, 0};
