/* The frozen hierarchical operator: y = F_H x = push(gather(pull(x))). Planar receivers gather
 * one value per channel; clusters gather by direction bin and hand each polygon below them the
 * share its orientation sees (hierarchy_internal.h). */
#include "transport/hierarchy/hierarchy_internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define BN__S 0.57735026918962576   /* 1/sqrt(3) */
#define BN__E 0.70710678118654752   /* 1/sqrt(2) */
const double bn__bin_dir[BN__BINS][3] = {
    {1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1},
    {BN__E, BN__E, 0}, {BN__E, -BN__E, 0}, {-BN__E, BN__E, 0}, {-BN__E, -BN__E, 0},
    {BN__E, 0, BN__E}, {BN__E, 0, -BN__E}, {-BN__E, 0, BN__E}, {-BN__E, 0, -BN__E},
    {0, BN__E, BN__E}, {0, BN__E, -BN__E}, {0, -BN__E, BN__E}, {0, -BN__E, -BN__E},
    {BN__S, BN__S, BN__S}, {BN__S, BN__S, -BN__S}, {BN__S, -BN__S, BN__S}, {BN__S, -BN__S, -BN__S},
    {-BN__S, BN__S, BN__S}, {-BN__S, BN__S, -BN__S}, {-BN__S, -BN__S, BN__S}, {-BN__S, -BN__S, -BN__S}};

int bn__bin_of(const double u[3])
{
    int best = 0;
    double bd = -2;
    for (int b = 0; b < BN__BINS; b++) {
        double d = bn_v3_dot(u, bn__bin_dir[b]);
        if (d > bd) {
            bd = d;
            best = b;
        }
    }
    return best;
}

/* max(0, n . u_b) for every bin. */
static void bn__cosines(const float n[3], double c[BN__BINS])
{
    for (int b = 0; b < BN__BINS; b++)
        c[b] = fmax(0.0, n[0] * bn__bin_dir[b][0] + n[1] * bn__bin_dir[b][1] + n[2] * bn__bin_dir[b][2]);
}

void bn__hop_destroy(void *ctx)
{
    bn__hop *h = ctx;
    if (!h)
        return;
    free(h->child);
    free(h->parent);
    free(h->leaf_patch);
    free(h->cl);
    free(h->area);
    free(h->normal);
    free(h->start);
    free(h->src);
    free(h->F);
    free(h->bin);
    free(h->Bn);
    free(h->G);
    free(h->Gb);
    free(h);
}

size_t bn__hop_bytes(const void *ctx)
{
    const bn__hop *h = ctx;
    return h->n * (4 * sizeof(uint32_t) + sizeof(double) + 3 * sizeof(float) + sizeof(size_t) + 6 * sizeof(double)) +
           h->nclusters * 3 * BN__BINS * sizeof(double) + h->nlinks * (sizeof(uint32_t) + sizeof(float) + 1);
}

static void bn__centre(const bn__tree *t, uint32_t v, double c[3])
{
    const double *b = t->box + 6 * (size_t)v;
    for (int k = 0; k < 3; k++)
        c[k] = 0.5 * (b[k] + b[3 + k]);
}

bn_status bn__hop_make(const bn__tree *t, const bn__link *links, size_t nlinks, bn__hop **out, bn_error *err)
{
    bn__hop *h = bn__calloc(1, sizeof *h);
    size_t n = t->n;
    float *cbar = NULL;   /* BN__BINS per cluster: the area-mean of max(0, n . u_b) below it */
    *out = NULL;
    if (!h)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy");
    h->n = n;
    h->npatch = t->npatch;
    h->nlinks = nlinks;
    h->child = bn__malloc_array(n, sizeof(uint32_t));
    h->parent = bn__malloc_array(n, sizeof(uint32_t));
    h->leaf_patch = bn__malloc_array(n, sizeof(uint32_t));
    h->cl = bn__malloc_array(n, sizeof(uint32_t));
    h->area = bn__malloc_array(n, sizeof(double));
    h->normal = bn__malloc_array(3 * n, sizeof(float));
    h->start = bn__calloc(n + 1, sizeof(size_t));
    h->src = bn__malloc_array(nlinks ? nlinks : 1, sizeof(uint32_t));
    h->F = bn__malloc_array(nlinks ? nlinks : 1, sizeof(float));
    h->bin = bn__calloc(nlinks ? nlinks : 1, 1);
    h->Bn = bn__malloc_array(3 * n, sizeof(double));
    h->G = bn__malloc_array(3 * n, sizeof(double));
    if (!h->child || !h->parent || !h->leaf_patch || !h->cl || !h->area || !h->normal || !h->start || !h->src ||
        !h->F || !h->bin || !h->Bn || !h->G)
        goto oom;
    memcpy(h->child, t->child, n * sizeof(uint32_t));
    memcpy(h->parent, t->parent, n * sizeof(uint32_t));
    memcpy(h->area, t->area, n * sizeof(double));
    for (size_t v = 0; v < n; v++) {
        h->leaf_patch[v] = t->child[v] == BN__NONE ? t->order[t->lo[v]] : BN__NONE;
        h->cl[v] = t->face[v] < 0 ? (uint32_t)h->nclusters++ : BN__NONE;
        for (int c = 0; c < 3; c++)
            h->normal[3 * v + c] = (float)t->normal[3 * v + c];
    }
    h->Gb = bn__malloc_array(h->nclusters ? 3 * BN__BINS * h->nclusters : 1, sizeof(double));
    cbar = bn__malloc_array(h->nclusters ? BN__BINS * h->nclusters : 1, sizeof(float));
    if (!h->Gb || !cbar)
        goto oom;
    /* the clusters' mean cosines, children before parents (children of a cluster: two nodes) */
    for (size_t v = n; v-- > 0;) {
        if (h->cl[v] == BN__NONE)
            continue;
        double acc[BN__BINS] = {0}, cs[BN__BINS];
        for (uint32_t c = h->child[v]; c < h->child[v] + 2; c++) {
            if (h->cl[c] == BN__NONE)
                bn__cosines(h->normal + 3 * (size_t)c, cs);
            else
                for (int b = 0; b < BN__BINS; b++)
                    cs[b] = cbar[(size_t)BN__BINS * h->cl[c] + (size_t)b];
            for (int b = 0; b < BN__BINS; b++)
                acc[b] += h->area[c] * cs[b];
        }
        for (int b = 0; b < BN__BINS; b++)
            cbar[(size_t)BN__BINS * h->cl[v] + (size_t)b] = (float)(acc[b] / h->area[v]);
    }
    for (size_t l = 0; l < nlinks; l++) {
        uint32_t r = links[l].r;
        h->start[r + 1]++;
        h->src[l] = links[l].s;
        h->F[l] = links[l].F;
        if (h->cl[r] != BN__NONE) {
            double cr[3], cs[3], u[3];
            bn__centre(t, r, cr);
            bn__centre(t, links[l].s, cs);
            bn_v3_sub(cs, cr, u);
            bn_v3_normalize(u);
            int b = bn__bin_of(u);
            double m = cbar[(size_t)BN__BINS * h->cl[r] + (size_t)b];
            h->bin[l] = (uint8_t)b;
            h->F[l] = m > 1e-6 ? (float)(links[l].F / m) : 0.0f;
        }
    }
    for (size_t v = 0; v < n; v++)
        h->start[v + 1] += h->start[v];
    free(cbar);
    *out = h;
    return BN_OK;
oom:
    free(cbar);
    bn__hop_destroy(h);
    return bn_error_set(err, BN_ENOMEM, "out of memory for %zu links of the hierarchy", nlinks);
}

bn_status bn__hop_apply(void *ctx, const double *x, double *y, bn_error *err)
{
    bn__hop *h = ctx;
    size_t n = h->n;
    double *B = h->Bn, *G = h->G, *Gb = h->Gb;
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
        if (h->cl[v] == BN__NONE) {
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
        } else {
            double *gb = Gb + (size_t)3 * BN__BINS * h->cl[v];
            memset(gb, 0, 3 * BN__BINS * sizeof(double));
            G[3 * v] = G[3 * v + 1] = G[3 * v + 2] = 0;
            for (size_t l = h->start[v]; l < h->start[v + 1]; l++) {
                const double *b = B + 3 * (size_t)h->src[l];
                double f = h->F[l], *g = gb + 3 * h->bin[l];
                g[0] += f * b[0];
                g[1] += f * b[1];
                g[2] += f * b[2];
            }
        }
    }
    /* push: clusters pass their bins down to clusters; a polygon's topmost node takes from its
     * cluster parent the share of each bin its normal sees; planar nodes pass values down */
    for (size_t v = 1; v < n; v++) {
        size_t p = h->parent[v];
        if (h->cl[v] != BN__NONE) {
            double *gv = Gb + (size_t)3 * BN__BINS * h->cl[v];
            const double *gp = Gb + (size_t)3 * BN__BINS * h->cl[p];
            for (int k = 0; k < 3 * BN__BINS; k++)
                gv[k] += gp[k];
        } else if (h->cl[p] != BN__NONE) {
            double cs[BN__BINS];
            const double *gp = Gb + (size_t)3 * BN__BINS * h->cl[p];
            bn__cosines(h->normal + 3 * v, cs);
            for (int b = 0; b < BN__BINS; b++)
                if (cs[b] > 0)
                    for (int k = 0; k < 3; k++)
                        G[3 * v + k] += cs[b] * gp[3 * b + k];
        } else {
            G[3 * v] += G[3 * p];
            G[3 * v + 1] += G[3 * p + 1];
            G[3 * v + 2] += G[3 * p + 2];
        }
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
