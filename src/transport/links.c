/* The frozen hierarchical operator: y = F_H x = push(gather(pull(x))). Planar receivers gather
 * one value per channel; (nearly flat) clusters one vector per channel, which each polygon below
 * dots with its normal (src/hierarchy/hierarchy_internal.h says when a cluster may). */
#include "transport/links.h"
#include "base/internal.h"
#include "bounce/dist.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Octahedral encoding of a unit vector in 8 + 8 bits (Meyer et al. 2010): ~1 degree. */
uint16_t bn__oct_encode(const double u[3])
{
    double l1 = fabs(u[0]) + fabs(u[1]) + fabs(u[2]), x = u[0] / l1, y = u[1] / l1;
    if (u[2] < 0) {
        double ox = x;
        x = (1 - fabs(y)) * (ox >= 0 ? 1 : -1);
        y = (1 - fabs(ox)) * (y >= 0 ? 1 : -1);
    }
    long qx = lround((x * 0.5 + 0.5) * 255), qy = lround((y * 0.5 + 0.5) * 255);
    return (uint16_t)((qx & 255) | ((qy & 255) << 8));
}

void bn__oct_decode(uint16_t e, double u[3])
{
    double x = (double)(e & 255) / 255 * 2 - 1, y = (double)(e >> 8) / 255 * 2 - 1, z = 1 - fabs(x) - fabs(y);
    if (z < 0) {
        double ox = x;
        x = (1 - fabs(y)) * (ox >= 0 ? 1 : -1);
        y = (1 - fabs(ox)) * (y >= 0 ? 1 : -1);
    }
    u[0] = x;
    u[1] = y;
    u[2] = z;
    bn_v3_normalize(u);
}

/* ---- links ordered by receiver, then source: an in-place radix sort ---- */

/* A link's sort key: receiver, then source (the partial bit left out). */
static inline uint64_t bn__link_key(const bn__link *l) { return (uint64_t)l->r << 32 | bn__link_s(l); }

static void bn__link_isort(bn__link *a, size_t n)
{
    for (size_t i = 1; i < n; i++) {
        bn__link v = a[i];
        uint64_t k = bn__link_key(&v);
        size_t j = i;
        for (; j > 0 && bn__link_key(&a[j - 1]) > k; j--)
            a[j] = a[j - 1];
        a[j] = v;
    }
}

/* The byte of the keys at `shift` puts every link in its bucket (each bucket's end into end[256]), in
 * place: each link moved where its byte says, the one found there moved on (an American flag sort). */
static void bn__link_flag(bn__link *a, size_t n, int shift, size_t end[256])
{
    size_t next[256], cnt[256] = {0}, s = 0;
    for (size_t i = 0; i < n; i++)
        cnt[bn__link_key(&a[i]) >> shift & 255]++;
    for (int b = 0; b < 256; b++) {
        next[b] = s;
        s += cnt[b];
        end[b] = s;
    }
    for (int b = 0; b < 256; b++)
        while (next[b] < end[b]) {
            bn__link v = a[next[b]];
            int d = (int)(bn__link_key(&v) >> shift & 255);
            while (d != b) {
                bn__link t = a[next[d]];
                a[next[d]++] = v;
                v = t;
                d = (int)(bn__link_key(&v) >> shift & 255);
            }
            a[next[b]++] = v;
        }
}

/* The keys' bits shift and below, from the byte at shift down (the last byte may reread bits its
 * bucket shares). */
static void bn__link_radix(bn__link *a, size_t n, int shift)
{
    size_t end[256];
    if (n <= 32) {
        bn__link_isort(a, n);
        return;
    }
    bn__link_flag(a, n, shift, end);
    for (int b = 0; shift > 0 && b < 256; b++) {
        size_t first = b ? end[b - 1] : 0;
        if (end[b] - first > 1)
            bn__link_radix(a + first, end[b] - first, shift >= 8 ? shift - 8 : 0);
    }
}

/* Sorts in place, no more memory than the call stack (glibc's qsort, a merge sort, mallocs a copy of
 * the links: 494 MB at 41 M), the first byte (the keys' top 8 bits) spreading them over 256 buckets
 * sorted in parallel: 3.1 s against qsort's 12.8 s for 41 M links in runs of one receiver in random
 * order (a pass's output is closer to sorted, where qsort gains: the living room's last passes 5-10%
 * faster). The order is the keys' (every link's (r, s) is its own), the same for
 * any thread count. */
void bn__links_sort(bn__link *a, size_t n)
{
    size_t end[256];
    uint64_t top = 0;
    int shift;
    if (n <= 32) {
        bn__link_isort(a, n);
        return;
    }
    for (size_t i = 0; i < n; i++)
        top |= bn__link_key(&a[i]);
    for (shift = 0; shift < 56 && top >> (shift + 8); shift++)
        ;   /* the highest set bit minus 7 */
    bn__link_flag(a, n, shift, end);
    if (shift == 0)
        return;
#pragma omp parallel for schedule(dynamic, 1)
    for (int b = 0; b < 256; b++) {
        size_t first = b ? end[b - 1] : 0;
        if (end[b] - first > 1)
            bn__link_radix(a + first, end[b] - first, shift >= 8 ? shift - 8 : 0);
    }
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
    free(h->dir);
    free(h->Bn);
    free(h->bound);
    free(h->order);
    free(h->xchg);
    free(h->G);
    free(h->Gv);
    free(h->rowscale);
    free(h);
}

/* The bytes of the arrays with one element per link (src, F, dir), as they are allocated. */
size_t bn__hop_link_bytes(const bn__hop *h)
{
    return h->nlinks * (sizeof *h->src + sizeof *h->F + sizeof *h->dir);
}

size_t bn__hop_bytes(const void *ctx)
{
    const bn__hop *h = ctx;
    return h->n * (4 * sizeof(uint32_t) + sizeof(double) + 3 * sizeof(float) + sizeof(size_t) + 7 * sizeof(double)) +
           h->nclusters * 9 * sizeof(double) + bn__hop_link_bytes(h) +
           (h->distributed ? h->npatch * (sizeof(uint32_t) + 3 * sizeof(double)) : 0) +
           (h->rowscale ? h->npatch * sizeof(double) : 0);
}


/* Under mpirun (P > 1): every rank's first leaf and the leaf order copied, the exchange buffer. 0 when out
 * of memory. */
static int bn__hop_make_dist(bn__hop *h, const bn__hop_shape *t, const size_t *bound)
{
    size_t P = (size_t)bn_dist_size();
    h->bound = bn__malloc_array(P + 1, sizeof *h->bound);
    h->order = bn__malloc_array(t->npatch, sizeof(uint32_t));
    h->xchg = bn__malloc_array(3 * t->npatch, sizeof(double));
    if (!h->bound || !h->order || !h->xchg)
        return 0;
    memcpy(h->bound, bound, (P + 1) * sizeof *h->bound);
    memcpy(h->order, t->order, t->npatch * sizeof(uint32_t));
    h->plo = bound[bn_dist_rank()];
    h->phi = bound[bn_dist_rank() + 1];
    return 1;
}

/* The tree's shape copied: children, parents, areas, each leaf's patch, the clusters' numbers,
 * normals (float). */
static void bn__hop_copy_shape(bn__hop *h, const bn__hop_shape *t)
{
    size_t n = t->n;
    memcpy(h->child, t->child, n * sizeof(uint32_t));
    memcpy(h->parent, t->parent, n * sizeof(uint32_t));
    memcpy(h->area, t->area, n * sizeof(double));
    for (size_t v = 0; v < n; v++) {
        h->leaf_patch[v] = t->child[v] == BN__NONE ? t->order[t->lo[v]] : BN__NONE;
        h->cl[v] = t->plane[v] < 0 ? (uint32_t)h->nclusters++ : BN__NONE;
        for (int c = 0; c < 3; c++)
            h->normal[3 * v + c] = (float)t->normal[3 * v + c];
    }
}

/* The links with F > 0 (sorted by r then s) as rows: start, src, F, and a cluster receiver's
 * direction to each source. */
static void bn__hop_copy_links(bn__hop *h, const bn__hop_shape *t, const bn__link *links, size_t nlinks)
{
    for (size_t l = 0, k = 0; l < nlinks; l++) {
        uint32_t r = links[l].r;
        if (!(links[l].F > 0))
            continue;
        h->start[r + 1]++;
        h->src[k] = bn__link_s(&links[l]);
        h->F[k] = links[l].F;
        if (h->cl[r] != BN__NONE) {
            double u[3];
            t->dir(t->dir_ctx, r, h->src[k], u);
            h->dir[k] = bn__oct_encode(u);   /* F is per unit cosine (src/hierarchy/refine.c) */
        }
        k++;
    }
    for (size_t v = 0; v < t->n; v++)
        h->start[v + 1] += h->start[v];
}

bn_status bn__hop_make(const bn__hop_shape *t, const bn__link *links, size_t nlinks, const size_t *bound, bn__hop **out,
                       bn_error *err)
{
    bn__hop *h = bn__calloc(1, sizeof *h);
    size_t n = t->n, kept = 0;
    *out = NULL;
    if (!h)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy");
    for (size_t l = 0; l < nlinks; l++)
        kept += links[l].F > 0;
    h->n = n;
    h->npatch = t->npatch;
    h->nlinks = kept;
    h->child = bn__malloc_array(n, sizeof(uint32_t));
    h->parent = bn__malloc_array(n, sizeof(uint32_t));
    h->leaf_patch = bn__malloc_array(n, sizeof(uint32_t));
    h->cl = bn__malloc_array(n, sizeof(uint32_t));
    h->area = bn__malloc_array(n, sizeof(double));
    h->normal = bn__malloc_array(3 * n, sizeof(float));
    h->start = bn__calloc(n + 1, sizeof(size_t));
    h->src = bn__malloc_array(kept ? kept : 1, sizeof *h->src);
    h->F = bn__malloc_array(kept ? kept : 1, sizeof *h->F);
    h->dir = bn__calloc(kept ? kept : 1, sizeof *h->dir);
    h->Bn = bn__calloc(4 * n, sizeof(double));   /* each node's fourth value stays 0 */
    h->G = bn__malloc_array(3 * n, sizeof(double));
    h->distributed = bn_dist_size() > 1;
    if ((h->distributed && !bn__hop_make_dist(h, t, bound)) || !h->child || !h->parent || !h->leaf_patch || !h->cl ||
        !h->area || !h->normal || !h->start || !h->src || !h->F || !h->dir || !h->Bn || !h->G)
        goto oom;
    bn__hop_copy_shape(h, t);
    h->Gv = bn__malloc_array(h->nclusters ? 9 * h->nclusters : 1, sizeof(double));
    if (!h->Gv)
        goto oom;
    bn__hop_copy_links(h, t, links, nlinks);
    *out = h;
    return BN_OK;
oom:
    bn__hop_destroy(h);
    return bn_error_set(err, BN_ENOMEM, "out of memory for %zu links of the hierarchy", kept);
}

/* Pull: each node's B, the area-weighted mean of its children's, children before parents; four
 * doubles a node (the fourth 0 from allocation), so that a link's source is one aligned load. */
static void bn__hop_pull(bn__hop *h, const double *x)
{
    double *B = h->Bn;
    for (size_t v = h->n; v-- > 0;) {
        uint32_t c = h->child[v];
        if (c == BN__NONE) {
            const double *xp = x + 3 * (size_t)h->leaf_patch[v];
            B[4 * v] = xp[0];
            B[4 * v + 1] = xp[1];
            B[4 * v + 2] = xp[2];
        } else {
            double a0 = h->area[c], a1 = h->area[c + 1], inv = 1.0 / h->area[v];
            for (int k = 0; k < 3; k++)
                B[4 * v + k] = (a0 * B[4 * (size_t)c + k] + a1 * B[4 * ((size_t)c + 1) + k]) * inv;
        }
    }
}

/* A cluster receiver's links into its 3 x 3 vector accumulator (per colour, a direction). */
static void bn__hop_gather_cluster(const bn__hop *h, size_t v)
{
    double *gv = h->Gv + (size_t)9 * h->cl[v];
    memset(gv, 0, 9 * sizeof(double));
    h->G[3 * v] = h->G[3 * v + 1] = h->G[3 * v + 2] = 0;
    for (size_t l = h->start[v]; l < h->start[v + 1]; l++) {
        const double *b = h->Bn + 4 * (size_t)h->src[l];
        double f = h->F[l], u[3];
        bn__oct_decode(h->dir[l], u);
        for (int c = 0; c < 3; c++)
            for (int k = 0; k < 3; k++)
                gv[3 * c + k] += f * b[c] * u[k];
    }
}

/* AVX2 where the CPU has it (chosen at run time), SSE2 otherwise; ISO C mode (-std=c17) keeps
 * floating-point contraction off, so both clones compute the very same sums. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
#define BN__CLONES __attribute__((target_clones("avx2", "default")))
#else
#define BN__CLONES
#endif

/* A planar receiver's links [lo, hi): g = sum F B over four partial sums (link l into sum l mod 4,
 * added in a fixed order at the end: the same for any thread count). Each link is one 4-double
 * source; four independent chains keep the adds' latency off the critical path. */
BN__CLONES static void bn__hop_gather_planar(const uint32_t *src, const float *F, size_t lo, size_t hi,
                                             const double *B, double g[3])
{
    double a[4][4] = {{0}};
    size_t l = lo;
    for (; l + 4 <= hi; l += 4)
        for (int m = 0; m < 4; m++) {
            const double *b = B + 4 * (size_t)src[l + (size_t)m];
            double f = (double)F[l + (size_t)m];
            for (int k = 0; k < 4; k++)
                a[m][k] += f * b[k];
        }
    for (size_t m = 0; l + m < hi; m++) {
        const double *b = B + 4 * (size_t)src[l + m];
        double f = (double)F[l + m];
        for (int k = 0; k < 4; k++)
            a[m][k] += f * b[k];
    }
    for (int k = 0; k < 3; k++)
        g[k] = (a[0][k] + a[1][k]) + (a[2][k] + a[3][k]);
}

/* Gather along each receiver's links (each sum in a fixed order: the same for any thread count). */
static void bn__hop_gather(bn__hop *h)
{
    long ln = (long)h->n;
#pragma omp parallel for schedule(dynamic, 1024)
    for (long lv = 0; lv < ln; lv++) {
        size_t v = (size_t)lv;
        if (h->cl[v] != BN__NONE)
            bn__hop_gather_cluster(h, v);
        else
            bn__hop_gather_planar(h->src, h->F, h->start[v], h->start[v + 1], h->Bn, h->G + 3 * v);
    }
}

/* Push: clusters pass their vectors down to clusters; a polygon's topmost node dots its cluster
 * parent's vectors with its normal; planar nodes pass values down. Then the leaves into y. */
static void bn__hop_push(bn__hop *h, double *y)
{
    double *G = h->G, *Gv = h->Gv;
    for (size_t v = 1; v < h->n; v++) {
        size_t p = h->parent[v];
        if (h->cl[v] != BN__NONE) {
            double *gv = Gv + (size_t)9 * h->cl[v];
            const double *gp = Gv + (size_t)9 * h->cl[p];
            for (int k = 0; k < 9; k++)
                gv[k] += gp[k];
        } else if (h->cl[p] != BN__NONE) {
            const double *gp = Gv + (size_t)9 * h->cl[p];
            const float *nv = h->normal + 3 * v;
            for (int c = 0; c < 3; c++)
                G[3 * v + c] += nv[0] * gp[3 * c] + nv[1] * gp[3 * c + 1] + nv[2] * gp[3 * c + 2];
        } else {
            for (int c = 0; c < 3; c++)
                G[3 * v + c] += G[3 * p + c];
        }
    }
    for (size_t v = 0; v < h->n; v++)
        if (h->leaf_patch[v] != BN__NONE) {
            size_t p = h->leaf_patch[v];
            double sc = h->rowscale ? h->rowscale[p] : 1;
            for (int c = 0; c < 3; c++)
                y[3 * p + (size_t)c] = sc * G[3 * v + (size_t)c];
        }
}

bn_status bn__hop_apply(void *ctx, const double *x, double *y, bn_error *err)
{
    bn__hop *h = ctx;
    bn_status st;
    bn__hop_pull(h, x);
    bn__hop_gather(h);
    bn__hop_push(h, y);
    /* every rank's status first (a rank that stops alone would leave the others in the collective) */
    if ((st = bn_dist_agree(bn_interrupted())) != BN_OK)
        return bn_error_set(err, st, "interrupted");
    if (h->distributed) {   /* this rank's leaves (exact here) in leaf order, every rank's gathered */
        for (size_t i = h->plo; i < h->phi; i++)
            memcpy(h->xchg + 3 * i, y + 3 * (size_t)h->order[i], 3 * sizeof(double));
        if ((st = bn_dist_allgather(h->xchg, h->bound, 3, err)) != BN_OK)
            return st;
        for (size_t i = 0; i < h->npatch; i++)
            memcpy(y + 3 * (size_t)h->order[i], h->xchg + 3 * i, 3 * sizeof(double));
    }
    return BN_OK;
}

/* No link joins a node to itself or to a node above or below it, so F_H has a zero diagonal. */
static bn_status bn__hop_diag(void *ctx, double *d, bn_error *err)
{
    const bn__hop *h = ctx;
    (void)err;
    memset(d, 0, h->npatch * sizeof(double));
    return BN_OK;
}

void bn_transport_links_dir(uint16_t e, double u[3]) { bn__oct_decode(e, u); }

/* The nodes' arrays of the export. */
static bn_status bn__hop_links_nodes(const bn__hop *h, bn_transport_links *o, bn_error *err)
{
    size_t n = h->n;
    o->child = bn__malloc_array(n, sizeof *o->child);
    o->leaf_patch = bn__malloc_array(n, sizeof *o->leaf_patch);
    o->cluster = bn__malloc_array(n, 1);
    o->area = bn__malloc_array(n, sizeof *o->area);
    o->normal = bn__malloc_array(3 * n, sizeof *o->normal);
    o->start = bn__malloc_array(n + 1, sizeof *o->start);
    if (h->rowscale)
        o->rowscale = bn__malloc_array(h->npatch, sizeof *o->rowscale);
    if (!o->child || !o->leaf_patch || !o->cluster || !o->area || !o->normal || !o->start ||
        (h->rowscale && !o->rowscale))
        return bn_error_set(err, BN_ENOMEM, "out of memory for the export of %zu nodes", n);
    memcpy(o->child, h->child, n * sizeof *o->child);
    memcpy(o->leaf_patch, h->leaf_patch, n * sizeof *o->leaf_patch);
    memcpy(o->normal, h->normal, 3 * n * sizeof *o->normal);
    for (size_t v = 0; v < n; v++) {
        o->cluster[v] = h->cl[v] != BN__NONE;
        o->area[v] = (float)h->area[v];
    }
    for (size_t v = 0; v <= n; v++)
        o->start[v] = (uint32_t)h->start[v];
    for (size_t i = 0; h->rowscale && i < h->npatch; i++)
        o->rowscale[i] = (float)h->rowscale[i];
    return BN_OK;
}

static bn_status bn__hop_links(const void *ctx, bn_transport_links *o, int count_only, bn_error *err)
{
    const bn__hop *h = ctx;
    bn_status st;
    o->npatch = h->npatch;
    o->nnodes = h->n;
    o->nlinks = h->nlinks;
    if (h->distributed)
        return bn_error_set(err, BN_EUSAGE, "the hierarchy's links are spread over MPI ranks: export them from "
                                            "one process");
    if (h->nlinks >= BN__NONE)
        return bn_error_set(err, BN_ENOMEM, "%zu links: too many to export (2^32)", h->nlinks);
    if (count_only)
        return BN_OK;
    if ((st = bn__hop_links_nodes(h, o, err)) != BN_OK)
        return st;
    o->src = bn__malloc_array(h->nlinks + 1, sizeof *o->src);
    o->F = bn__malloc_array(h->nlinks + 1, sizeof *o->F);
    o->dir = bn__malloc_array(h->nlinks + 1, sizeof *o->dir);
    if (!o->src || !o->F || !o->dir)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the export of %zu links", h->nlinks);
    memcpy(o->src, h->src, h->nlinks * sizeof *o->src);
    memcpy(o->F, h->F, h->nlinks * sizeof *o->F);
    memcpy(o->dir, h->dir, h->nlinks * sizeof *o->dir);
    return BN_OK;
}

const bn_transport_ops bn__hop_ops = {
    .name = "hierarchical",   /* as the transport option names it */
    .caps = BN_OP_DIAG,
    .apply = bn__hop_apply,
    .diag = bn__hop_diag,
    .bytes = bn__hop_bytes,
    .destroy = bn__hop_destroy,
    .links = bn__hop_links,
};
