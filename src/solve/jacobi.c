/* Jacobi on (I - K) L = E:  L_i <- (E_i + sum_{j != i} K_ij L_j) / (1 - K_ii), from L0 = E.
 * With F_ii = 0 (planar patches) this is L <- E + K L, whose iterates are the partial sums of
 * the Neumann series. The residual of the new iterate costs nothing extra: with y = K L,
 * r = E + y - L (Saad, Iterative Methods for Sparse Linear Systems, 2nd ed., sec. 4.1). */
#include "solve/solve_internal.h"
#include "base/internal.h"

#include <string.h>

typedef struct bn__jacobi {
    const bn__solve_ctx *ctx;
    double *y;   /* K L for the current L */
} bn__jacobi;

static bn_status bn__jacobi_setup(void *st, const bn__solve_ctx *ctx, const double *L0, const double *r0,
                                  bn_error *err)
{
    bn__jacobi *s = st;
    size_t m = 3 * ctx->n;
    s->ctx = ctx;
    s->y = bn__malloc_array(m ? m : 1, sizeof(double));
    if (!s->y)
        return bn_error_set(err, BN_ENOMEM, "jacobi: out of memory for %zu patches", ctx->n);
    /* y <- K L0 = r0 - E + L0 */
    for (size_t i = 0; i < m; i++)
        s->y[i] = r0[i] - ctx->E[i] + L0[i];
    return BN_OK;
}

static bn_status bn__jacobi_iterate(void *st, double *L, double *r, int *have_r, bn_error *err)
{
    bn__jacobi *s = st;
    const double *E = s->ctx->E, *d = s->ctx->diag;
    size_t m = 3 * s->ctx->n;
    bn_status rc;
    /* L <- (E + K L - D L) / (1 - D) */
    if (d)
        for (size_t i = 0; i < m; i++)
            L[i] = (E[i] + s->y[i] - d[i] * L[i]) / (1.0 - d[i]);
    else
        for (size_t i = 0; i < m; i++)
            L[i] = E[i] + s->y[i];
    /* y <- K L;  r <- E - (I - K) L */
    rc = bn_transport_apply(s->ctx->k, L, s->y, err);
    if (rc != BN_OK)
        return rc;
    for (size_t i = 0; i < m; i++)
        r[i] = E[i] + s->y[i] - L[i];
    *have_r = 1;
    return BN_OK;
}

static void bn__jacobi_cleanup(void *st)
{
    bn__jacobi *s = st;
    free(s->y);
    s->y = NULL;
}

const bn_solver_type bn__solver_jacobi = {"jacobi", 0, sizeof(bn__jacobi), 1, bn__jacobi_setup, bn__jacobi_iterate,
                                          bn__jacobi_cleanup, NULL, 0};
