/* The transport operator K = diag(rho) F: the generic wrapper over any operator for F (a storage
 * or a user's own), the capability checks the solvers rely on, and the names of precisions. */
#include "bounce/transport.h"
#include "base/internal.h"

#include <math.h>
#include <stdatomic.h>
#include <string.h>

struct bn_transport {
    size_t n;
    double *rho;
    const bn_transport_ops *ops;
    void *ctx;
    _Atomic size_t *calls;   /* applications and row calls so far (named in a non-finite failure), and
                                the patch of the last non-finite value (SIZE_MAX: none) */
};

static void bn__ctx_destroy(const bn_transport_ops *ops, void *ctx)
{
    if (ops && ops->destroy)
        ops->destroy(ctx);
}

/* Each capability bit and the function(s) it promises. */
static const char *bn__ops_missing(const bn_transport_ops *ops)
{
    if (!ops->apply)
        return "apply";
    if ((ops->caps & BN_OP_ROWS) && !ops->row)
        return "row (BN_OP_ROWS)";
    if ((ops->caps & BN_OP_ENTRIES) && !ops->entry)
        return "entry (BN_OP_ENTRIES)";
    if ((ops->caps & BN_OP_DIAG) && !ops->diag)
        return "diag (BN_OP_DIAG)";
    return NULL;
}

/* Every reflectance in [0, 1]: BN_EINPUT naming the first that is not. */
static bn_status bn__rho_check(size_t n, const double *rho, bn_error *err)
{
    for (size_t i = 0; i < 3 * n; i++)
        if (!(rho[i] >= 0 && rho[i] <= 1))
            return bn_error_set(err, BN_EINPUT, "patch %zu: reflectance %g is outside [0, 1]", i / 3, rho[i]);
    return BN_OK;
}

bn_status bn_transport_create(size_t n, const double *rho, const bn_transport_ops *ops, void *ctx,
                              bn_transport **out, bn_error *err)
{
    bn_transport *k;
    const char *missing;
    bn_status st;
    *out = NULL;
    if (!ops || (missing = bn__ops_missing(ops)) != NULL) {
        bn__ctx_destroy(ops, ctx);
        return bn_error_set(err, BN_EUSAGE, "transport operator %s: no %s function", ops && ops->name ? ops->name : "?",
                            ops ? missing : "ops table");
    }
    if ((st = bn__rho_check(n, rho, err)) != BN_OK) {
        bn__ctx_destroy(ops, ctx);
        return st;
    }
    k = calloc(1, sizeof *k);
    if (k) {
        k->rho = bn__malloc_array(n ? 3 * n : 1, sizeof(double));
        k->calls = calloc(3, sizeof *k->calls);
        if (k->calls)
            atomic_store(&k->calls[2], SIZE_MAX);
    }
    if (!k || !k->rho || !k->calls) {
        if (k) {
            free(k->rho);
            free((void *)k->calls);
        }
        free(k);
        bn__ctx_destroy(ops, ctx);
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    memcpy(k->rho, rho, 3 * n * sizeof(double));
    k->n = n;
    k->ops = ops;
    k->ctx = ctx;
    *out = k;
    return BN_OK;
}

void bn_transport_destroy(bn_transport *k)
{
    if (!k)
        return;
    bn__ctx_destroy(k->ops, k->ctx);
    free(k->rho);
    free((void *)k->calls);
    free(k);
}

size_t bn_transport_size(const bn_transport *k) { return k->n; }
size_t bn_transport_nonfinite_patch(const bn_transport *k) { return atomic_load(&k->calls[2]); }
const double *bn_transport_rho(const bn_transport *k) { return k->rho; }

bn_status bn_transport_set_rho(bn_transport *k, const double *rho, bn_error *err)
{
    bn_status st = bn__rho_check(k->n, rho, err);
    if (st == BN_OK)
        memcpy(k->rho, rho, 3 * k->n * sizeof(double));
    return st;
}
const char *bn_transport_name(const bn_transport *k) { return k->ops->name ? k->ops->name : "user"; }
unsigned bn_transport_caps(const bn_transport *k) { return k->ops->caps; }

size_t bn_transport_bytes(const bn_transport *k)
{
    return (k->ops->bytes ? k->ops->bytes(k->ctx) : 0) + 3 * k->n * sizeof(double);
}

bn_status bn_transport_require(const bn_transport *k, unsigned need, const char *who, bn_error *err)
{
    unsigned lack = need & ~k->ops->caps;
    if (!lack)
        return BN_OK;
    return bn_error_set(err, BN_ENOTSUP, "%s needs %s of K, which the %s operator does not offer%s", who,
                        lack & BN_OP_ENTRIES ? "single entries" : lack & BN_OP_ROWS ? "row access" : "the diagonal",
                        bn_transport_name(k),
                        lack & BN_OP_ENTRIES ? ": use an iterative method (jacobi, gauss-seidel, neumann)"
                        : lack & BN_OP_ROWS  ? ": use jacobi or neumann, which need only y = K x"
                                             : "");
}

/* Calls an operator function with a fresh error record of its own, so that a caller's earlier
 * error is never touched by a call that succeeds; a failure without a message still says which
 * operator and call failed. */
#define BN__OP_CALL(k, err, what, call)                                                             \
    do {                                                                                           \
        bn_error op_err_;                                                                          \
        bn_status op_st_;                                                                          \
        bn_error *err_ = &op_err_;                                                                 \
        op_err_.status = BN_OK;                                                                    \
        op_err_.msg[0] = '\0';                                                                     \
        op_st_ = (call);                                                                           \
        if (op_st_ != BN_OK) {                                                                     \
            if (op_err_.status == op_st_ && op_err_.msg[0]) {                                      \
                if (err)                                                                           \
                    *(err) = op_err_;                                                              \
            } else {                                                                               \
                bn_error_set(err, op_st_, "%s operator: %s failed (%s)", bn_transport_name(k), what, \
                             bn_status_str(op_st_));                                               \
            }                                                                                      \
            return op_st_;                                                                         \
        }                                                                                          \
        (void)err_;                                                                                \
    } while (0)

/* Every value an operator hands out is checked: a non-finite one stops the caller with
 * BN_ENUMERIC naming the operator, the call (counted from the transport's creation), the patch and
 * the channel, so no NaN reaches a solver's monitor (whose fmax would drop it) or an answer. */
static bn_status bn__nonfinite(const bn_transport *k, const char *what, size_t call, const double *y, size_t m,
                               size_t patch0, bn_error *err)
{
    size_t q = 0;
    while (q < m && isfinite(y[q]))
        q++;
    atomic_store(&k->calls[2], patch0 + q / 3);
    return bn_error_set(err, BN_ENUMERIC, "%s operator: %s call %zu gave a non-finite value (%g) at patch %zu, channel %c",
                        bn_transport_name(k), what, call, q < m ? y[q] : NAN, patch0 + q / 3, "RGB"[q % 3]);
}

/* 0 * y is 0 for every finite y and NaN otherwise: one pass, no branch per entry, four independent
 * sums so the adds overlap (about 1% of a dense apply at N = 8192). */
static int bn__all_finite(const double *y, size_t m)
{
    double z[4] = {0, 0, 0, 0};
    size_t i = 0;
    for (; i + 4 <= m; i += 4)
        for (int l = 0; l < 4; l++)
            z[l] += 0.0 * y[i + (size_t)l];
    for (; i < m; i++)
        z[0] += 0.0 * y[i];
    return z[0] + z[1] + z[2] + z[3] == 0;
}

bn_status bn_transport_apply_F(const bn_transport *k, const double *x, double *y, bn_error *err)
{
    size_t call = atomic_fetch_add_explicit(&k->calls[0], 1, memory_order_relaxed) + 1;
    BN__OP_CALL(k, err, "apply", k->ops->apply(k->ctx, x, y, err_));
    if (!bn__all_finite(y, 3 * k->n))
        return bn__nonfinite(k, "apply (y = F x)", call, y, 3 * k->n, 0, err);
    return BN_OK;
}

bn_status bn_transport_apply(const bn_transport *k, const double *x, double *y, bn_error *err)
{
    /* y <- F x (checked finite), then y <- diag(rho) y (rho in [0, 1]: stays finite) */
    bn_status st = bn_transport_apply_F(k, x, y, err);
    if (st != BN_OK)
        return st;
    for (size_t i = 0; i < 3 * k->n; i++)
        y[i] *= k->rho[i];
    return BN_OK;
}

bn_status bn_transport_row(const bn_transport *k, size_t i, const double *x, double out[3], bn_error *err)
{
    size_t call;
    if (!(k->ops->caps & BN_OP_ROWS))
        return bn_transport_require(k, BN_OP_ROWS, "row access", err);
    call = atomic_fetch_add_explicit(&k->calls[1], 1, memory_order_relaxed) + 1;
    BN__OP_CALL(k, err, "row", k->ops->row(k->ctx, i, x, out, err_));
    if (!bn__all_finite(out, 3))
        return bn__nonfinite(k, "row", call, out, 3, i, err);
    for (int c = 0; c < 3; c++)
        out[c] *= k->rho[3 * i + (size_t)c];
    return BN_OK;
}

bn_status bn_transport_entry(const bn_transport *k, size_t i, size_t j, double *v, bn_error *err)
{
    if (!(k->ops->caps & BN_OP_ENTRIES))
        return bn_transport_require(k, BN_OP_ENTRIES, "entry access", err);
    BN__OP_CALL(k, err, "entry", k->ops->entry(k->ctx, i, j, v, err_));
    if (!isfinite(*v)) {
        atomic_store(&k->calls[2], i);
        return bn_error_set(err, BN_ENUMERIC, "%s operator: entry F(%zu, %zu) is not finite (%g)", bn_transport_name(k),
                            i, j, *v);
    }
    return BN_OK;
}

bn_status bn_transport_row_entries(const bn_transport *k, size_t i, size_t *cols, double *vals, size_t *count,
                                   bn_error *err)
{
    if (!(k->ops->caps & BN_OP_ENTRIES))
        return bn_transport_require(k, BN_OP_ENTRIES, "entry access", err);
    if (k->ops->row_entries) {
        BN__OP_CALL(k, err, "row_entries", k->ops->row_entries(k->ctx, i, cols, vals, count, err_));
        for (size_t q = 0; q < *count; q++)
            if (!isfinite(vals[q])) {
                atomic_store(&k->calls[2], i);
                return bn_error_set(err, BN_ENUMERIC, "%s operator: entry F(%zu, %zu) is not finite (%g)",
                                    bn_transport_name(k), i, cols[q], vals[q]);
            }
        return BN_OK;
    }
    *count = 0;
    for (size_t j = 0; j < k->n; j++) {
        double v;
        bn_status st = bn_transport_entry(k, i, j, &v, err);
        if (st != BN_OK)
            return st;
        if (v != 0) {
            cols[*count] = j;
            vals[(*count)++] = v;
        }
    }
    return BN_OK;
}

bn_status bn_transport_diag(const bn_transport *k, double *d, bn_error *err)
{
    if (k->ops->caps & BN_OP_DIAG) {
        BN__OP_CALL(k, err, "diag", k->ops->diag(k->ctx, d, err_));
        for (size_t i = 0; i < k->n; i++)
            if (!isfinite(d[i])) {
                atomic_store(&k->calls[2], i);
                return bn_error_set(err, BN_ENUMERIC, "%s operator: diagonal F(%zu, %zu) is not finite (%g)",
                                    bn_transport_name(k), i, i, d[i]);
            }
        return BN_OK;
    }
    if (!(k->ops->caps & BN_OP_ENTRIES))
        return bn_transport_require(k, BN_OP_DIAG, "the diagonal", err);
    for (size_t i = 0; i < k->n; i++) {
        bn_status st = bn_transport_entry(k, i, i, &d[i], err);
        if (st != BN_OK)
            return st;
    }
    return BN_OK;
}

bn_status bn_transport_norm_inf(const bn_transport *k, double *norm, double per_channel[3], size_t *bad_patch,
                                bn_error *err)
{
    /* ||K||_inf = max_i rho_ic sum_j |F_ij| (F >= 0): the row sums are F applied to ones. */
    size_t m = 3 * k->n;
    double *ones = bn__malloc_array(m ? m : 1, sizeof(double)), *rs = bn__malloc_array(m ? m : 1, sizeof(double));
    double pc[3] = {0, 0, 0};
    bn_status st;
    *norm = NAN;
    if (!ones || !rs) {
        free(ones);
        free(rs);
        return bn_error_set(err, BN_ENOMEM, "||K||: out of memory for %zu patches", k->n);
    }
    for (size_t i = 0; i < m; i++)
        ones[i] = 1.0;
    st = bn_transport_apply(k, ones, rs, err);
    for (size_t i = 0; st == BN_OK && i < m; i++) {
        if (!isfinite(rs[i]) || rs[i] < 0) {
            if (bad_patch)
                *bad_patch = i / 3;
            st = bn_error_set(err, BN_ENUMERIC, "K is not finite and nonnegative: row of patch %zu (channel %c) sums to %g",
                              i / 3, "RGB"[i % 3], rs[i]);
        }
        pc[i % 3] = fmax(pc[i % 3], rs[i]);
    }
    if (st == BN_OK) {
        *norm = fmax(pc[0], fmax(pc[1], pc[2]));
        if (per_channel)
            memcpy(per_channel, pc, sizeof pc);
    }
    free(ones);
    free(rs);
    return st;
}

bn_status bn_transport_to_dense(const bn_transport *k, double *F, bn_error *err)
{
    size_t *cols = bn__malloc_array(k->n ? k->n : 1, sizeof(size_t)), cnt;
    double *vals = bn__malloc_array(k->n ? k->n : 1, sizeof(double));
    bn_status st = (cols && vals) ? BN_OK : bn_error_set(err, BN_ENOMEM, "out of memory");
    for (size_t i = 0; i < k->n && st == BN_OK; i++) {
        st = bn_transport_row_entries(k, i, cols, vals, &cnt, err);
        memset(F + i * k->n, 0, k->n * sizeof(double));
        for (size_t q = 0; st == BN_OK && q < cnt; q++)
            F[i * k->n + cols[q]] = vals[q];
    }
    free(cols);
    free(vals);
    return st;
}

/* ---- precisions: one table (the enum's order) ---- */

#define BN__PRECISIONS(X) X("float") X("double")
BN__VOCABULARY(bn_precision, bn_precision, BN__PRECISIONS)

double bn_precision_epsilon(bn_precision p) { return p == BN_PRECISION_DOUBLE ? 0x1p-53 : 0x1p-24; }
unsigned bn_precision_bytes(bn_precision p) { return p == BN_PRECISION_DOUBLE ? 8 : 4; }
int bn_precision_digits(bn_precision p) { return p == BN_PRECISION_DOUBLE ? 17 : 9; }

/* ---- F exported as links (bn_transport_links) ---- */

void bn_transport_links_free(bn_transport_links *l)
{
    if (!l)
        return;
    free(l->child);
    free(l->leaf_patch);
    free(l->cluster);
    free(l->area);
    free(l->normal);
    free(l->start);
    free(l->src);
    free(l->F);
    free(l->dir);
    free(l->rowscale);
    memset(l, 0, sizeof *l);
}

/* Dense and sparse F's nonzero entries counted (count_only) or exported: a leaf per patch. */
static bn_status bn__links_from_entries(const bn_transport *k, bn_transport_links *out, int count_only, bn_error *err)
{
    size_t n = k->n, *cols = bn__malloc_array(n ? n : 1, sizeof *cols), total = 0, cap = 0, cnt;
    double *vals = bn__malloc_array(n ? n : 1, sizeof *vals);
    bn_status st = BN_OK;
    out->npatch = out->nnodes = n;
    if (!cols || !vals)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for a row of %zu entries", n);
    for (size_t i = 0; st == BN_OK && i < n; i++) {
        if ((st = bn_transport_row_entries(k, i, cols, vals, &cnt, err)) != BN_OK)
            break;
        size_t kept = 0;
        for (size_t q = 0; q < cnt; q++)   /* a dense row's exact zeros (no sight, one plane) are not links */
            if (vals[q] != 0) {
                cols[kept] = cols[q];
                vals[kept++] = vals[q];
            }
        cnt = kept;
        if (!count_only && total + cnt > cap) {   /* the link arrays grow by half */
            size_t want = (total + cnt) + (total + cnt) / 2 + 1024;
            uint32_t *s2 = realloc(out->src, want * sizeof *s2);
            float *f2 = s2 ? realloc(out->F, want * sizeof *f2) : NULL;
            out->src = s2 ? s2 : out->src;
            out->F = f2 ? f2 : out->F;
            if (!s2 || !f2) {
                st = bn_error_set(err, BN_ENOMEM, "out of memory for %zu links", want);
                break;
            }
            cap = want;
        }
        for (size_t q = 0; !count_only && q < cnt; q++) {
            out->src[total + q] = (uint32_t)cols[q];
            out->F[total + q] = (float)vals[q];
        }
        if (!count_only)
            out->start[i + 1] = (uint32_t)(total + cnt);
        total += cnt;
        if (total >= BN_LINK_NONE)
            st = bn_error_set(err, BN_ENOMEM, "F has more than 2^32 entries: too many to export as links");
    }
    free(cols);
    free(vals);
    out->nlinks = total;
    return st;
}

/* The tree of one leaf per patch, flat. */
static bn_status bn__links_leaves(size_t n, bn_transport_links *out, bn_error *err)
{
    out->child = bn__malloc_array(n + 1, sizeof *out->child);
    out->leaf_patch = bn__malloc_array(n + 1, sizeof *out->leaf_patch);
    out->cluster = bn__calloc(n + 1, 1);
    out->area = bn__malloc_array(n + 1, sizeof *out->area);
    out->normal = bn__calloc(3 * n + 1, sizeof *out->normal);
    out->start = bn__calloc(n + 1, sizeof *out->start);
    if (!out->child || !out->leaf_patch || !out->cluster || !out->area || !out->normal || !out->start)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the links of %zu patches", n);
    for (size_t i = 0; i < n; i++) {
        out->child[i] = BN_LINK_NONE;
        out->leaf_patch[i] = (uint32_t)i;
        out->area[i] = 1;
    }
    return BN_OK;
}

static bn_status bn__links(const bn_transport *k, bn_transport_links *out, int count_only, bn_error *err)
{
    bn_status st;
    memset(out, 0, sizeof *out);
    if (k->ops->links)
        st = k->ops->links(k->ctx, out, count_only, err);
    else if (!(k->ops->caps & BN_OP_ENTRIES))
        return bn_error_set(err, BN_EUSAGE, "%s operator: neither links nor entries to export",
                            bn_transport_name(k));
    else if (!count_only && (st = bn__links_leaves(k->n, out, err)) != BN_OK)
        ;
    else
        st = bn__links_from_entries(k, out, count_only, err);
    if (st != BN_OK)
        bn_transport_links_free(out);
    return st;
}

bn_status bn_transport_links_get(const bn_transport *k, bn_transport_links *out, bn_error *err)
{
    return bn__links(k, out, 0, err);
}

bn_status bn_transport_links_bytes(const bn_transport *k, size_t *bytes, bn_error *err)
{
    bn_transport_links l;
    bn_status st = bn__links(k, &l, 1, err);
    *bytes = 0;
    if (st != BN_OK)
        return st;
    /* per node child, leaf_patch, cluster, area, normal, start; per link src, F, dir; per patch rowscale */
    *bytes = l.nnodes * (4 + 4 + 1 + 4 + 12 + 4) + 4 + l.nlinks * (4 + 4 + (l.nnodes > l.npatch ? 2 : 0)) +
             l.npatch * 4;
    return BN_OK;
}
