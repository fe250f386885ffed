/* The truncated Neumann series L = sum_k K^k E: S_n = S_(n-1) + K^n E, from S_0 = E.
 * Its residual is the next term: E - (I - K) S_n = K^(n+1) E, so one application of K per
 * term gives both; the tail is bounded by ||L - S_n|| <= ||K^(n+1) E|| / (1 - ||K||) a posteriori
 * and ||K||^(n+1) / (1 - ||K||) ||E|| a priori (Kress, Linear Integral Equations, thm. 2.14).
 * Its residuals are the per-bounce terms K^1 E, K^2 E, ...: the driver keeps them (residual_is_term). */
#include "solve/solve_internal.h"
#include "base/internal.h"

#include <string.h>

typedef struct bn__neumann {
    const bn__solve_ctx *ctx;
    double *t, *u;   /* t = K^(n+1) E, the next term; u scratch */
} bn__neumann;

static bn_status bn__neumann_setup(void *st, const bn__solve_ctx *ctx, const double *L0, const double *r0,
                                   bn_error *err)
{
    bn__neumann *s = st;
    size_t m = 3 * ctx->n;
    (void)L0;
    s->ctx = ctx;
    s->t = bn__malloc_array(m ? m : 1, sizeof(double));
    s->u = bn__malloc_array(m ? m : 1, sizeof(double));
    if (!s->t || !s->u)
        return bn_error_set(err, BN_ENOMEM, "neumann: out of memory for %zu patches", ctx->n);
    /* t <- K E = r0 (L0 = E) */
    memcpy(s->t, r0, m * sizeof(double));
    return BN_OK;
}

static bn_status bn__neumann_iterate(void *st, double *L, double *r, int *have_r, bn_error *err)
{
    bn__neumann *s = st;
    size_t m = 3 * s->ctx->n;
    double *tmp;
    bn_status rc;
    /* S <- S + K^(n+1) E;  t <- K t = K^(n+2) E, the residual of the new S */
    for (size_t i = 0; i < m; i++)
        L[i] += s->t[i];
    rc = bn_transport_apply(s->ctx->k, s->t, s->u, err);
    if (rc != BN_OK)
        return rc;
    tmp = s->t;
    s->t = s->u;
    s->u = tmp;
    memcpy(r, s->t, m * sizeof(double));
    *have_r = 1;
    return BN_OK;
}

static void bn__neumann_cleanup(void *st)
{
    bn__neumann *s = st;
    free(s->t);
    free(s->u);
    s->t = s->u = NULL;
}

const bn_solver_type bn__solver_neumann = {"neumann", 0, sizeof(bn__neumann), 1, bn__neumann_setup, bn__neumann_iterate,
                                           bn__neumann_cleanup, NULL, 1};
