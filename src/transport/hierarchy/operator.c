/* The frozen hierarchical operator: y = F_H x = push(gather(pull(x))). */
#include "transport/hierarchy/hierarchy_internal.h"

#include <stdlib.h>
#include <string.h>

void bn__hop_destroy(void *ctx)
{
    bn__hop *h = ctx;
    if (!h)
        return;
    free(h->child);
    free(h->parent);
    free(h->leaf_patch);
    free(h->area);
    free(h->start);
    free(h->src);
    free(h->F);
    free(h->Bn);
    free(h->G);
    free(h);
}

size_t bn__hop_bytes(const void *ctx)
{
    const bn__hop *h = ctx;
    return h->n * (3 * sizeof(uint32_t) + sizeof(double) + sizeof(size_t) + 6 * sizeof(double)) +
           h->nlinks * (sizeof(uint32_t) + sizeof(float));
}

bn_status bn__hop_make(const bn__tree *t, const bn__link *links, size_t nlinks, bn__hop **out, bn_error *err)
{
    bn__hop *h = bn__calloc(1, sizeof *h);
    size_t n = t->n;
    *out = NULL;
    if (!h)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy");
    h->n = n;
    h->npatch = t->npatch;
    h->nlinks = nlinks;
    h->child = bn__malloc_array(n, sizeof(uint32_t));
    h->parent = bn__malloc_array(n, sizeof(uint32_t));
    h->leaf_patch = bn__malloc_array(n, sizeof(uint32_t));
    h->area = bn__malloc_array(n, sizeof(double));
    h->start = bn__calloc(n + 1, sizeof(size_t));
    h->src = bn__malloc_array(nlinks ? nlinks : 1, sizeof(uint32_t));
    h->F = bn__malloc_array(nlinks ? nlinks : 1, sizeof(float));
    h->Bn = bn__malloc_array(3 * n, sizeof(double));
    h->G = bn__malloc_array(3 * n, sizeof(double));
    if (!h->child || !h->parent || !h->leaf_patch || !h->area || !h->start || !h->src || !h->F || !h->Bn || !h->G) {
        bn__hop_destroy(h);
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu links of the hierarchy", nlinks);
    }
    memcpy(h->child, t->child, n * sizeof(uint32_t));
    memcpy(h->parent, t->parent, n * sizeof(uint32_t));
    memcpy(h->area, t->area, n * sizeof(double));
    for (size_t v = 0; v < n; v++)
        h->leaf_patch[v] = t->child[v] == BN__NONE ? t->order[t->lo[v]] : BN__NONE;
    for (size_t l = 0; l < nlinks; l++) {
        h->start[links[l].r + 1]++;
        h->src[l] = links[l].s;
        h->F[l] = links[l].F;
    }
    for (size_t v = 0; v < n; v++)
        h->start[v + 1] += h->start[v];
    *out = h;
    return BN_OK;
}

bn_status bn__hop_apply(void *ctx, const double *x, double *y, bn_error *err)
{
    bn__hop *h = ctx;
    size_t n = h->n;
    double *B = h->Bn, *G = h->G;
    (void)err;
    /* pull: area-weighted means, children before parents */
    for (size_t v = n; v-- > 0;) {
        uint32_t c = h->child[v];
        if (c == BN__NONE) {
            const double *xp = x + 3 * (size_t)h->leaf_patch[v];
            B[3 * v] = xp[0];
            B[3 * v + 1] = xp[1];
            B[3 * v + 2] = xp[2];
        } else {
            double a0 = h->area[c], a1 = h->area[c + 1], inv = 1.0 / h->area[v];
            for (int k = 0; k < 3; k++)
                B[3 * v + k] = (a0 * B[3 * (size_t)c + k] + a1 * B[3 * ((size_t)c + 1) + k]) * inv;
        }
    }
    /* gather along each receiver's links (each sum in link order: the same for any thread count) */
    long ln = (long)n;
#pragma omp parallel for schedule(dynamic, 1024)
    for (long lv = 0; lv < ln; lv++) {
        size_t v = (size_t)lv;
        double g0 = 0, g1 = 0, g2 = 0;
        for (size_t l = h->start[v]; l < h->start[v + 1]; l++) {
            const double *b = B + 3 * (size_t)h->src[l];
            double f = h->F[l];
            g0 += f * b[0];
            g1 += f * b[1];
            g2 += f * b[2];
        }
        G[3 * v] = g0;
        G[3 * v + 1] = g1;
        G[3 * v + 2] = g2;
    }
    /* push: every node's gathered value reaches all the leaves below it */
    for (size_t v = 1; v < n; v++) {
        size_t p = h->parent[v];
        G[3 * v] += G[3 * p];
        G[3 * v + 1] += G[3 * p + 1];
        G[3 * v + 2] += G[3 * p + 2];
    }
    for (size_t v = 0; v < n; v++)
        if (h->leaf_patch[v] != BN__NONE)
            memcpy(y + 3 * (size_t)h->leaf_patch[v], G + 3 * v, 3 * sizeof(double));
    return bn_interrupted() != BN_OK ? bn_error_set(err, bn_interrupted(), "interrupted") : BN_OK;
}

/* No link joins a node to itself or to a node above or below it, so F_H has a zero diagonal. */
static bn_status bn__hop_diag(void *ctx, double *d, bn_error *err)
{
    const bn__hop *h = ctx;
    (void)err;
    memset(d, 0, h->npatch * sizeof(double));
    return BN_OK;
}

const bn_transport_ops bn__hop_ops = {
    .name = "hierarchy",
    .caps = BN_OP_DIAG,
    .apply = bn__hop_apply,
    .diag = bn__hop_diag,
    .bytes = bn__hop_bytes,
    .destroy = bn__hop_destroy,
};
