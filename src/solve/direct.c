/* The reference solve: (I - diag(rho_c) F) L_c = E_c per channel by LU with partial pivoting
 * (LAPACK dgesv through LAPACKE) on a dense double copy, column-major. When every patch is grey
 * (rho_R = rho_G = rho_B) one factorisation serves all three channels. Memory: N^2 doubles,
 * estimated and checked before allocating. Anderson et al., LAPACK Users' Guide, 3rd ed. */
#include "solve/solve_internal.h"
#include "base/internal.h"

#include <lapacke.h>
#include <string.h>

/* Rows of F fetched per block of the fill (bn__direct_fill). */
#define BN__FILL_ROWS 32

size_t bn_solve_direct_bytes(size_t n)
{
    size_t nn, a;
    if (!bn__mul_size(n, n, &nn) || !bn__mul_size(nn, sizeof(double), &a))
        return SIZE_MAX;
    return a + n * (sizeof(lapack_int) + sizeof(size_t) + (4 + BN__FILL_ROWS) * sizeof(double));
}

/* A <- I - diag(rho_c) F in column-major order (A[j n + i] = delta_ij - rho_ic F_ij). Each row's
 * stored entries are read once through the operator (any storage) into a block of dense rows,
 * which is then written out column by column, so both the reads and the writes stream. Serial:
 * an operator's entry functions need not be thread-safe. */
static bn_status bn__direct_fill(const bn_transport *k, const double *rho, int c, size_t n, double *A, double *blk,
                                 size_t *cols, double *vals, bn_error *err)
{
    for (size_t i0 = 0; i0 < n; i0 += BN__FILL_ROWS) {
        size_t nb = n - i0 < BN__FILL_ROWS ? n - i0 : BN__FILL_ROWS;
        memset(blk, 0, nb * n * sizeof(double));
        for (size_t q = 0; q < nb; q++) {
            size_t cnt;
            bn_status st = bn_transport_row_entries(k, i0 + q, cols, vals, &cnt, err);
            if (st != BN_OK)
                return st;
            for (size_t e = 0; e < cnt; e++)
                blk[q * n + cols[e]] = vals[e];
        }
        for (size_t j = 0; j < n; j++)
            for (size_t q = 0; q < nb; q++) {
                size_t i = i0 + q;
                A[j * n + i] = (i == j ? 1.0 : 0.0) - rho[3 * i + (size_t)c] * blk[q * n + j];
            }
    }
    return BN_OK;
}

/* The direct solve's buffers: I - K dense (column-major), the right-hand sides, LU pivots and the
 * row fill's scratch. */
typedef struct bn__direct_buf {
    double *A, *b, *vals, *blk;
    size_t *cols;
    lapack_int *ipiv;
} bn__direct_buf;

static void bn__direct_buf_free(bn__direct_buf *B)
{
    free(B->A);
    free(B->b);
    free(B->ipiv);
    free(B->cols);
    free(B->vals);
    free(B->blk);
}

/* Channel c (with grey reflectance: all three at once, nrhs 3) solved by LU into L. */
static bn_status bn__direct_channel(const bn__solve_ctx *ctx, const double *rho, int c, int nrhs, bn__direct_buf *B,
                                    double *L, int *singular, bn_error *err)
{
    size_t n = ctx->n;
    lapack_int info;
    bn_status st = bn__direct_fill(ctx->k, rho, c, n, B->A, B->blk, B->cols, B->vals, err);
    if (st != BN_OK)
        return st;
    for (size_t i = 0; i < n; i++)   /* b <- E_c (column-major n x nrhs) */
        for (int q = 0; q < nrhs; q++)
            B->b[(size_t)q * n + i] = ctx->E[3 * i + (size_t)(c + q)];
    info = LAPACKE_dgesv(LAPACK_COL_MAJOR, (lapack_int)n, nrhs, B->A, (lapack_int)n, B->ipiv, B->b, (lapack_int)n);
    if (info > 0) {
        *singular = 1;
        return bn_error_set(err, BN_ENUMERIC,
                            "direct solve: I - K is singular (channel %c: U(%d,%d) = 0 in the LU factorisation)",
                            "RGB"[c], (int)info, (int)info);
    }
    if (info < 0)
        return bn_error_set(err, BN_EINTERNAL, "direct solve: LAPACKE_dgesv argument %d is invalid", (int)-info);
    for (size_t i = 0; i < n; i++)
        for (int q = 0; q < nrhs; q++)
            L[3 * i + (size_t)(c + q)] = B->b[(size_t)q * n + i];
    return BN_OK;
}

static bn_status bn__direct_solve(const bn__solve_ctx *ctx, double *L, int *singular, bn_error *err)
{
    size_t n = ctx->n, need = bn_solve_direct_bytes(n), limit = ctx->o->max_memory;
    const double *rho = bn_transport_rho(ctx->k);
    bn__direct_buf B;
    int grey = 1;
    bn_status st = BN_OK;
    *singular = 0;
    if (limit == 0)
        limit = bn_memory_limit_default();
    if (n > (size_t)INT32_MAX)
        return bn_error_set(err, BN_ENOMEM, "direct solve: %zu patches exceed LAPACK's 32-bit index", n);
    if (need == SIZE_MAX || need > limit)
        return bn_error_set(err, BN_ENOMEM,
                            "direct solve: %zu patches need %.3g GiB for the dense double copy of I - K "
                            "(N^2 x 8 bytes), above the limit of %.3g GiB; use an iterative `method` "
                            "(jacobi, gauss-seidel, neumann) or fewer patches",
                            n, (double)need / 1073741824.0, (double)limit / 1073741824.0);
    if (n == 0)
        return BN_OK;
    B.A = bn__malloc_array(n * n, sizeof(double));
    B.b = bn__malloc_array(3 * n, sizeof(double));
    B.ipiv = bn__malloc_array(n, sizeof(lapack_int));
    B.cols = bn__malloc_array(n, sizeof(size_t));
    B.vals = bn__malloc_array(n, sizeof(double));
    B.blk = bn__malloc_array((size_t)BN__FILL_ROWS * n, sizeof(double));
    if (!B.A || !B.b || !B.ipiv || !B.cols || !B.vals || !B.blk)
        st = bn_error_set(err, BN_ENOMEM, "direct solve: cannot allocate %.3g GiB for %zu patches",
                          (double)need / 1073741824.0, n);
    for (size_t i = 0; i < n && grey; i++)
        grey = rho[3 * i] == rho[3 * i + 1] && rho[3 * i] == rho[3 * i + 2];
    for (int c = 0; c < (grey ? 1 : 3) && st == BN_OK; c++) {
        st = bn__direct_channel(ctx, rho, c, grey ? 3 : 1, &B, L, singular, err);
        if (st == BN_OK && !grey && bn_interrupted() != BN_OK)
            st = bn_error_set(err, bn_interrupted(), "direct solve interrupted");
    }
    bn__direct_buf_free(&B);
    return st;
}

const bn_solver_type bn__solver_direct = {"direct", BN_OP_ENTRIES, 0, 0, NULL, NULL, NULL, bn__direct_solve, 0};
