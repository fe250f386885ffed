/* The hierarchy under mpirun: which leaves each process refines, split again by link cost after a
 * pass, and the counts summed over processes as one process's (refine.h). */
#include "hierarchy/refine.h"
#include "bounce/dist.h"

#include <stdlib.h>
#include <string.h>

/* A link's cost spread over its receiver's leaves, in fixed point (integer sums: every rank gets the
 * same figures, so the same ranges). */
#define BN__COST_ONE ((unsigned long long)1 << 24)

/* The first split, before any link is known: an equal share of the leaves, in rank order (rank k's). */
void bn__dist_leaves_of(size_t npatch, size_t k, size_t *lo, size_t *hi)
{
    size_t P = (size_t)bn_dist_size();
    *lo = npatch * k / P;
    *hi = npatch * (k + 1) / P;
}

/* c[i]: leaf i's cost, summed over ranks (each link counted by one rank, spread evenly over its
 * receiver's leaves through a difference array); *total: their sum. */
static bn_status bn__leaf_costs(const bn__ref *R, const bn__vec *work, unsigned long long *c,
                                unsigned long long *total, bn_error *err)
{
    const bn__tree *t = R->t;
    size_t np = t->npatch;
    bn_status st;
    for (size_t l = 0; l < work->n; l++) {
        uint32_t r = work->a[l].r;
        if (bn__receiver_counted(R, r)) {
            unsigned long long w = BN__COST_ONE / (t->hi[r] - t->lo[r]);
            c[t->lo[r]] += w;
            c[t->hi[r]] -= w;   /* modular arithmetic: the prefix sums come out right */
        }
    }
    if ((st = bn_dist_sum_u64(c, np + 1, err)) != BN_OK)
        return st;
    for (size_t i = 1; i <= np; i++)
        c[i] += c[i - 1];
    *total = 0;
    for (size_t i = 0; i < np; i++)
        *total += c[i];
    return BN_OK;
}

/* The present split's most loaded rank over the mean. */
static double bn__imbalance(const bn__ref *R, const unsigned long long *c, unsigned long long total)
{
    size_t P = (size_t)bn_dist_size();
    unsigned long long most = 0;
    for (size_t q = 0; q < P; q++) {
        unsigned long long load = 0;
        for (size_t i = R->bound[q]; i < R->bound[q + 1]; i++)
            load += c[i];
        most = load > most ? load : most;
    }
    return (double)most * (double)P / (double)total;
}

/* Rank q's leaves begin where the running cost first reaches q/P of the total. */
static void bn__cost_bounds(const unsigned long long *c, size_t np, unsigned long long total, size_t *bound)
{
    size_t P = (size_t)bn_dist_size(), q = 1;
    unsigned long long run = 0;
    bound[0] = 0;
    for (size_t i = 0; i < np && q < P; i++) {
        while (q < P && (long double)run * P >= (long double)total * q)
            bound[q++] = i;
        run += c[i];
    }
    while (q < P)
        bound[q++] = np;
    bound[P] = np;
}

/* Each link this rank counted goes to every rank whose new leaves (bound) its receiver meets: one
 * all-to-all; *work becomes what this rank received, sorted. cnt: 2P scratch. */
static bn_status bn__move_links(const bn__ref *R, bn__vec *work, const size_t *bound, size_t *cnt, size_t *moved,
                                bn_error *err)
{
    const bn__tree *t = R->t;
    size_t P = (size_t)bn_dist_size(), *at = cnt + P, nrecv = 0;
    bn__link *send = NULL;
    void *recv = NULL;
    bn_status st;
    for (int pass = 0; pass < 2; pass++) {
        size_t off = 0;
        for (size_t q = 0; q < P; q++) {
            at[q] = off;
            off += cnt[q];
        }
        if (pass == 1 && !(send = bn__malloc_array(off ? off : 1, sizeof *send)))
            return bn_error_set(err, BN_ENOMEM, "out of memory for %zu links to move among processes", off);
        for (size_t l = 0; l < work->n; l++) {
            uint32_t r = work->a[l].r;
            for (size_t q = 0; bn__receiver_counted(R, r) && q < P; q++)
                if (t->lo[r] < bound[q + 1] && t->hi[r] > bound[q]) {
                    if (pass == 0)
                        cnt[q]++;
                    else
                        send[at[q]++] = work->a[l];
                }
        }
    }
    free(work->a);
    work->a = NULL;
    work->n = work->cap = 0;
    st = bn_dist_exchange(send, cnt, sizeof *send, &recv, &nrecv, err);
    free(send);
    if (st != BN_OK)
        return st;
    *moved = nrecv - cnt[bn_dist_rank()];
    work->a = recv;
    work->n = work->cap = nrecv;
    bn__links_sort(work->a, work->n);
    return BN_OK;
}

/* Under mpirun, after a pass: the leaves are split again so that every rank's receivers hold about the
 * same number of links (each link's cost spread evenly over its receiver's leaves, counted once over
 * ranks and summed), and the links move to the ranks whose new leaves their receivers meet (one
 * all-to-all; each link is sent by the rank that counted it, so no link arrives twice). The links of a
 * receiver do not depend on which rank refines them, so the answer stays one process's. *moved: links
 * this rank received from others. */
bn_status bn__rebalance(bn__ref *R, bn__vec *work, double *imbalance, size_t *moved, bn_error *err)
{
    size_t np = R->t->npatch, P = (size_t)bn_dist_size(), me = (size_t)bn_dist_rank();
    unsigned long long *c = NULL, total = 0;
    size_t *bound = NULL, *cnt = NULL;
    bn_status st = BN_OK;
    *imbalance = 1;
    *moved = 0;
    if (P == 1)
        return BN_OK;
    c = bn__calloc(np + 1, sizeof *c);
    bound = bn__calloc(P + 1, sizeof *bound);
    cnt = bn__calloc(2 * P, sizeof *cnt);
    if (!c || !bound || !cnt)
        st = bn_error_set(err, BN_ENOMEM, "out of memory to balance %zu leaves among %zu processes", np, P);
    if (st == BN_OK)
        st = bn__leaf_costs(R, work, c, &total, err);
    if (st == BN_OK && total > 0 && (*imbalance = bn__imbalance(R, c, total)) > BN__IMBALANCE) {
        bn__cost_bounds(c, np, total, bound);
        st = bn__move_links(R, work, bound, cnt, moved, err);
        if (st == BN_OK) {
            memcpy(R->bound, bound, (P + 1) * sizeof *bound);
            R->plo = bound[me];
            R->phi = bound[me + 1];
        }
    }
    free(c);
    free(bound);
    free(cnt);
    return st;
}

/* The log line of what each process stores: its receivers' links and the shared top's (all of them
 * with one process), and the leaves' values it receives per application. */
static bn_status bn__log_storage(const bn__ref *R, size_t here, size_t links, const bn_log *log, bn_error *err)
{
    size_t P = (size_t)bn_dist_size(), np = R->t->npatch, recv = 0;
    unsigned long long most = 0, *all = bn__calloc(P, sizeof *all);
    bn_status st;
    if (!all)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    all[bn_dist_rank()] = here;
    if ((st = bn_dist_sum_u64(all, P, err)) != BN_OK) {
        free(all);
        return st;
    }
    for (size_t k = 0; k < P; k++) {   /* the all-gather: the leaves a rank does not own, 3 doubles each */
        most = all[k] > most ? all[k] : most;
        if (P > 1 && np - (R->bound[k + 1] - R->bound[k]) > recv)
            recv = np - (R->bound[k + 1] - R->bound[k]);
    }
    bn_logf(log, BN_LOG_INFO, "hierarchy: %d process%s %llu links at most each (%.2f of the %zu kept, F > 0; "
            "rank 0 %llu); per application of K a process receives at most %zu bytes", (int)P,
            P > 1 ? "es store" : " stores", most, links ? (double)most / (double)links : 0.0, links, all[0],
            recv * 3 * sizeof(double));
    free(all);
    return BN_OK;
}

/* Counted by the rank holding each receiver's first leaf, summed: one process's counts. */
bn_status bn__count_links(const bn__ref *R, const bn__vec *work, bn_hierarchy_report *rep, const bn_log *log,
                          bn_error *err)
{
    const bn__tree *t = R->t;
    unsigned long long cnt[3] = {0, 0, 0};
    bn_status st;
    for (size_t l = 0; l < work->n; l++) {
        uint32_t r = work->a[l].r, s = bn__link_s(&work->a[l]);
        if (!bn__receiver_counted(R, r))
            continue;
        cnt[0]++;
        cnt[1] += bn__tree_is_leaf(t, r) && bn__tree_is_leaf(t, s);
        cnt[2] += t->plane[r] < 0 || t->plane[s] < 0;
    }
    if ((st = bn_dist_sum_u64(cnt, 3, err)) != BN_OK)
        return st;
    rep->links = cnt[0];
    rep->leaf_links = cnt[1];
    rep->cluster_links = cnt[2];
    rep->links_here = work->n;
    return bn__log_storage(R, work->n, rep->links, log, err);
}
