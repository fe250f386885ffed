/* Building K_H (include/bounce/hierarchy.h): the tree, refinement's state, the start links, passes
 * of refine and gather until the links settle, then the links frozen into the operator of
 * src/transport/links.c. */
#include "hierarchy/refine.h"
#include "bounce/dist.h"
#include "formfactor/ff_internal.h"
#include "base/vec.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

/* The link set has settled when a pass splits fewer than this fraction of its links: the next
 * pass would weigh them by a brightness that the few new links hardly change (on the bunny box,
 * pass 4 splits 2,557 of 18.9 M, pass 5 17, pass 6 none, at 6 s a pass). */
#define BN__SETTLED 1e-3
void bn_hierarchy_opts_default(bn_hierarchy_opts *o)
{
    memset(o, 0, sizeof *o);
    o->eps = BN_HIERARCHY_EPS_DEFAULT;
    o->clusters = 1;
    o->samples = 8;
    o->max_passes = 12;
    o->flat_clusters = 1;
    o->volume_links = 1;
    bn_formfactor_opts_default(&o->ff);
}

static bn_status bn__check_opts(const bn_hierarchy_opts *o, bn_error *err)
{
    if (!(o->eps >= 0 && isfinite(o->eps)))
        return bn_error_set(err, BN_EINPUT, "hierarchy: eps %g is not a finite number >= 0", o->eps);
    if (o->samples < 0 || o->samples > (1 << 20))
        return bn_error_set(err, BN_EINPUT, "hierarchy: %d samples per link is outside [1, 2^20]", o->samples);
    if (isnan(o->min_area) || isinf(o->min_area))
        return bn_error_set(err, BN_EINPUT, "hierarchy: min area %g is not a finite number", o->min_area);
    if (o->max_passes < 1)
        return bn_error_set(err, BN_EINPUT, "hierarchy: %d passes (at least 1)", o->max_passes);
    return BN_OK;
}

/* Everything a build holds until the links are frozen. */
typedef struct bn__build {
    bn__tree t;
    bn__ref R;
    bn__vec work;             /* the links */
    bn__pass_stats ps;        /* splits of the last pass; rays and the peak of link bytes so far */
    size_t vol_bytes;         /* the volume links' kept rays (R.vol) */
    bn__worker *W;
    int nt;
    size_t np;
    double *E, *rho, *L;      /* N x 3: emission, reflectance, the brightness estimate */
    double t0;
} bn__build;

/* Every leaf's corners, normal and fan share, in leaf order (bn__leaf_geom). */
static bn_status bn__leaf_geoms(bn__ref *R, size_t np, bn_error *err)
{
    if (!(R->vol = bn__calloc(np + 1, sizeof *R->vol)))
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy of %zu patches", np);
    if (!(R->leaf = bn__calloc(np + 1, sizeof *R->leaf)))
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy of %zu patches", np);
    for (size_t q = 0; q < np; q++) {
        const bn_patch *p = &R->patch[R->t->order[q]];
        bn__leaf_geom *g = &R->leaf[q];
        const double *v0 = R->pverts + 3 * p->corner[0], *v2 = R->pverts + 3 * p->corner[2];
        double a0 = 0, a1 = 0;
        if (p->ncorners == 4) {
            double e1[3], e2[3], e3[3], c[3];
            bn_v3_sub(R->pverts + 3 * p->corner[1], v0, e1);
            bn_v3_sub(v2, v0, e2);
            bn_v3_sub(R->pverts + 3 * p->corner[3], v0, e3);
            bn_v3_cross(e1, e2, c);
            a0 = 0.5 * bn_v3_len(c);
            bn_v3_cross(e2, e3, c);
            a1 = 0.5 * bn_v3_len(c);
        }
        g->fan0 = a0 + a1 > 0 ? a0 / (a0 + a1) : 1;
        g->nc = p->ncorners;
        for (unsigned c = 0; c < p->ncorners; c++)
            memcpy(g->v[c], R->pverts + 3 * p->corner[c], sizeof g->v[c]);
        memcpy(g->n, p->normal, sizeof g->n);
    }
    return BN_OK;
}

/* What refinement reads: the scene, tolerances, the smallest element, the first split of the leaves
 * among processes. */
static bn_status bn__ref_init(bn__build *B, const bn_scene *scene, const bn_rt *rt, const bn_hierarchy_opts *o,
                              bn_error *err)
{
    bn__ref *R = &B->R;
    size_t npv;
    R->t = &B->t;
    R->vol_bytes = &B->vol_bytes;
    R->scene = scene;
    R->rt = rt;
    R->o = o;
    R->patch = bn_scene_patches(scene, &B->np);
    R->pverts = bn_scene_patch_vertices(scene, &npv);
    R->tol = 1e-9 * fmax(bn_scene_diameter(scene), 1e-300);
    R->ray_eps = bn_rt_epsilon(rt);
    R->force = o->eps == 0;
    R->min_area = o->min_area > 0 ? o->min_area : o->min_area == 0 ? ldexp(B->t.area[0], -20) : 0;
    if (!(R->bound = bn__calloc((size_t)bn_dist_size() + 1, sizeof *R->bound)))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    for (int q = 0; q < bn_dist_size(); q++)
        bn__dist_leaves_of(B->np, (size_t)q, &R->bound[q], &R->bound[q + 1]);
    R->plo = R->bound[bn_dist_rank()];
    R->phi = R->bound[bn_dist_rank() + 1];
    return bn__leaf_geoms(R, B->np, err);
}

/* E, rho, L = E, the oracle's Bmax, eps in radiance, the per-thread workers. */
static bn_status bn__build_buffers(bn__build *B, bn_error *err)
{
    size_t np = B->np;
    double emax = 0;
    bn_status st;
    B->E = bn__malloc_array(3 * np, sizeof(double));
    B->rho = bn__malloc_array(3 * np, sizeof(double));
    B->L = bn__malloc_array(3 * np, sizeof(double));
    B->R.Bmax = bn__malloc_array(3 * B->t.n, sizeof(double));
    B->R.Bmin = bn__malloc_array(3 * B->t.n, sizeof(double));
    B->W = bn__calloc((size_t)B->nt, sizeof *B->W);
    if (!B->E || !B->rho || !B->L || !B->R.Bmax || !B->R.Bmin || !B->W)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the hierarchy of %zu patches", np);
    if ((st = bn__ff_pairs_create(B->R.scene, B->R.rt, &B->R.o->ff, &B->R.pairs, err)) != BN_OK)
        return st;
    for (int k = 0; k < B->nt; k++)
        if (!(B->W[k].ff = bn__ff_worker_create(B->R.pairs)))
            return bn_error_set(err, BN_ENOMEM, "out of memory for per-thread buffers");
    bn_scene_patch_emission(B->R.scene, B->E);
    for (size_t k = 0; B->R.o->direct && k < 3 * np; k++)
        B->E[k] += B->R.o->direct[k];   /* the punctual lights' direct light: part of the source */
    bn_scene_patch_reflectance(B->R.scene, B->rho);
    memcpy(B->L, B->E, 3 * np * sizeof(double));
    for (size_t k = 0; k < 3 * np; k++)
        emax = fmax(emax, B->E[k]);
    B->R.eps_abs = B->R.o->eps * emax;
    bn__bmax(&B->t, B->E, B->R.Bmax, B->R.Bmin);
    return BN_OK;
}

/* The start: the root's self-link, or (no clusters) every pair of planes' topmost nodes. */
static bn_status bn__start_links(bn__build *B, bn_error *err)
{
    const bn__tree *t = &B->t;
    uint32_t *fnode;
    size_t m = 0;
    if (B->R.o->clusters) {
        bn__vec_push(&B->work, 0, 0, -1, 0);
        return B->work.oom ? bn_error_set(err, BN_ENOMEM, "out of memory") : BN_OK;
    }
    if (!(fnode = bn__malloc_array(t->n, sizeof(uint32_t))))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    for (uint32_t v = 0; v < t->n; v++)
        if (t->plane[v] >= 0 && (v == 0 || t->plane[t->parent[v]] < 0))
            fnode[m++] = v;
    for (size_t a = 0; a < m && !B->work.oom; a++)
        for (size_t b = 0; b < m; b++)
            if (a != b)
                bn__vec_push(&B->work, fnode[a], fnode[b], -1, 0);
    free(fnode);
    if (B->work.oom)
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu^2 polygon pairs (build with clusters)", m);
    return BN_OK;
}

/* Refines every link once; every rank stops together (one that failed alone would leave the others
 * in a sum). cnt: links, links between patches, splits, over all ranks. */
static bn_status bn__one_pass(bn__build *B, int pass, size_t limit, bn_hierarchy_report *rep, unsigned long long cnt[3],
                              bn_error *err)
{
    const bn_hierarchy_opts *o = B->R.o;
    char label[64];
    bn_status st, all;
    snprintf(label, sizeof label, "hierarchy pass %d", pass + 1);
    st = bn__pass(&B->R, B->W, B->nt, &B->work, &B->ps, label, err);
    rep->rays = B->ps.rays;
    if (st == BN_OK && B->work.n * sizeof(bn__link) + bn__tree_bytes(&B->t) > limit)
        st = bn_error_set(err, BN_ENOMEM, "the hierarchy needs %zu links (%.3g GiB) at eps %g, above the memory "
                          "limit (`max_memory`): raise `eps`", B->work.n,
                          (double)(B->work.n * sizeof(bn__link)) / (1 << 30), o->eps);
    all = bn_dist_agree(st);
    if (all != BN_OK && st == BN_OK)
        st = bn_error_set(err, all, "hierarchy: another MPI process failed (%s)", bn_status_str(all));
    if (st != BN_OK)
        return st;
    rep->passes = (size_t)pass + 1;
    cnt[0] = cnt[1] = 0;
    for (size_t l = 0; l < B->work.n; l++)
        if (bn__receiver_counted(&B->R, B->work.a[l].r)) {
            cnt[0]++;
            cnt[1] += bn__tree_is_leaf(&B->t, B->work.a[l].r) && bn__tree_is_leaf(&B->t, bn__link_s(&B->work.a[l]));
        }
    cnt[2] = B->ps.splits;
    if ((st = bn_dist_sum_u64(cnt, 3, err)) != BN_OK)
        return st;
    bn_logf(&o->log, BN_LOG_INFO, "hierarchy pass %d: %llu links (%llu between patches), %llu split, %.1f s",
            pass + 1, cnt[0], cnt[1], cnt[2], bn__now() - B->t0);
    return BN_OK;
}

/* Between passes: the leaves split again among processes if uneven, then the brightness the next
 * pass weighs links by. */
static bn_status bn__between_passes(bn__build *B, bn_error *err)
{
    double imb;
    unsigned long long mv = 0;
    size_t moved;
    bn_status st = bn__rebalance(&B->R, &B->work, &imb, &moved, err);
    mv = moved;
    if (st == BN_OK && imb > BN__IMBALANCE && (st = bn_dist_sum_u64(&mv, 1, err)) == BN_OK)
        bn_logf(&B->R.o->log, BN_LOG_INFO, "hierarchy: leaves split again among %d processes (the most loaded "
                "held %.2fx the mean); %llu links moved", bn_dist_size(), imb, mv);
    if (st == BN_OK)
        st = bn__estimate(&B->t, &B->work, B->R.bound, B->E, B->rho, B->R.eps_abs, B->L, err);
    if (st == BN_OK) {
        bn__bmax(&B->t, B->L, B->R.Bmax, B->R.Bmin);
        B->R.btyp = bn__typical_radiance(&B->t, B->L, B->E);
    }
    return st;
}

/* Passes until a pass splits fewer than BN__SETTLED of the links (or eps 0, or max_passes). */
static bn_status bn__passes(bn__build *B, bn_hierarchy_report *rep, bn_error *err)
{
    const bn_hierarchy_opts *o = B->R.o;
    size_t limit = o->max_memory ? o->max_memory : bn_memory_limit_default();
    bn_status st = BN_OK;
    for (int pass = 0; pass < o->max_passes && st == BN_OK; pass++) {
        unsigned long long cnt[3];
        if ((st = bn__one_pass(B, pass, limit, rep, cnt, err)) != BN_OK)
            break;
        if (pass > 0 && (double)cnt[2] < BN__SETTLED * (double)cnt[0]) {
            rep->settled = 1;
            break;
        }
        if (B->R.force || pass + 1 == o->max_passes)
            break;   /* eps 0: the links are at the patches already; nothing can split */
        st = bn__between_passes(B, err);
    }
    if (st == BN_OK && B->R.force)
        rep->settled = 1;
    if (st == BN_OK && !rep->settled)
        bn_warnf(&o->log, BN_W_LINKS, NAN, "hierarchy: links still splitting after %d passes; frozen as they are",
                o->max_passes);
    return st;
}

/* The links with F > 0 frozen into the operator; the report's counts and sizes. */


static bn_status bn__freeze(bn__build *B, bn_hierarchy_report *rep, bn_transport **out, bn_error *err)
{
    const bn__tree *t = &B->t;
    bn__hop *h = NULL;
    bn__hop_shape shape = bn__tree_shape(t);
    bn_status st;
    size_t held_links = B->work.n;   /* refinement's, those with F = 0 included */
    B->work.n = bn__compact(&B->work);
    if (B->work.n && B->work.n < B->work.cap) {   /* beside the operator made from them, only what is kept */
        bn__link *a = bn__realloc_array(B->work.a, B->work.n, sizeof *a);
        if (a) {
            B->work.a = a;
            B->work.cap = B->work.n;
        }
    }
    if ((st = bn__count_links(&B->R, &B->work, rep, &B->R.o->log, err)) != BN_OK)
        return st;
    if ((st = bn__hop_make(&shape, B->work.a, B->work.n, B->R.bound, &h, err)) != BN_OK)
        return st;
    if ((st = bn__rows_normalize(&B->R, h, rep, err)) != BN_OK) {
        bn__hop_destroy(h);
        return st;
    }
    bn_logf(&B->R.o->log, BN_LOG_INFO,
            "hierarchy: F_H's rows against their exact sums: %.1f%% of %zu leaves (at most 16384 measured) within 1%%, "
            "%zu above +5%%, from "
            "%+.3g to %+.3g; %s (factors %.3g .. %.3g)%s",
            100 * rep->rows_within_1pct, B->np, rep->rows_above_5pct, rep->row_dev_min, rep->row_dev_max,
            rep->normalized ? "each scaled to its exact sum" : "left as they are (normalize_rows 0)",
            rep->row_scale_min, rep->row_scale_max, rep->rows_unscalable ? "; some leaves have no links" : "");
    rep->patches = B->np;
    rep->nodes = t->n;
    bn_scene_faces(B->R.scene, &rep->polygons);
    rep->planes = t->nplanes;
    rep->min_area = B->R.min_area;
    for (size_t v = 0; v < t->n; v++) {
        rep->clusters += t->plane[v] < 0;
        rep->planar_nodes += t->plane[v] >= 0 && t->child[v] != BN__NONE;
    }
    rep->bytes = bn__hop_bytes(h);
    rep->bytes_per_link = h->nlinks ? (double)bn__hop_link_bytes(h) / (double)h->nlinks : 0;
    {   /* the links with the operator made from them (as every estimate between passes, with fewer) */
        size_t held = B->work.cap * sizeof(bn__link) + bn__hop_link_bytes(h) + B->vol_bytes;
        rep->peak_link_bytes = held > B->ps.peak_bytes ? held : B->ps.peak_bytes;
        rep->peak_bytes_per_link = held_links ? (double)rep->peak_link_bytes / (double)held_links : 0;
    }
    bn_logf(&B->R.o->log, BN_LOG_INFO, "hierarchy: refinement held at most %.1f MiB of links (the volume links' rays "
            "%.1f MiB of it), %.1f B per link of the %zu it ended with (%.1f B per link of the %zu with F > 0 kept); "
            "the frozen operator %.1f B per link", (double)rep->peak_link_bytes / 1048576.0,
            (double)B->vol_bytes / 1048576.0, rep->peak_bytes_per_link, held_links,
            h->nlinks ? (double)rep->peak_link_bytes / (double)h->nlinks : 0.0, h->nlinks, rep->bytes_per_link);
    rep->seconds_refine = bn__now() - B->t0;
    return bn_transport_create(B->np, B->rho, &bn__hop_ops, h, out, err);   /* h owned by *out, or destroyed */
}

static void bn__build_free(bn__build *B)
{
    if (B->W)
        for (int k = 0; k < B->nt; k++) {
            free(B->W[k].links.a);
            free(B->W[k].pending.a);
            bn__ff_worker_destroy(B->W[k].ff);
        }
    free(B->W);
    bn__ff_pairs_destroy(B->R.pairs);
    free(B->R.Bmax);
    free(B->R.Bmin);
    for (size_t q = 0; B->R.vol && q < B->np; q++)
        free(B->R.vol[q]);
    free(B->R.vol);
    free(B->R.leaf);
    free(B->R.bound);
    free(B->work.a);
    free(B->E);
    free(B->rho);
    free(B->L);
    bn__tree_free(&B->t);
}

static bn_status bn__hierarchy_body(const bn_scene *scene, const bn_rt *rt, const bn_hierarchy_opts *o,
                                    bn_transport **out, bn_hierarchy_report *rep, bn_error *err)
{
    bn__build B;
    bn_status st;
    *out = NULL;
    memset(rep, 0, sizeof *rep);
    memset(&B, 0, sizeof B);
    B.nt = omp_get_max_threads();
    B.t0 = bn__now();
    if ((st = bn__check_opts(o, err)) != BN_OK)
        return st;
    if (!rt || bn_rt_scene(rt) != scene)
        return bn_error_set(err, BN_EINTERNAL, "bn_hierarchy_build: rt was built for another scene");
    {   /* covered patches (under a block, a slab, the bunny) kept apart from open ones in the tree */
        size_t np;
        bn_scene_patches(scene, &np);
        unsigned char *cover = bn__calloc(np ? np : 1, 1);
        if (!cover)
            return bn_error_set(err, BN_ENOMEM, "out of memory for %zu patches", np);
        if (bn_rt_cover_classes(rt, cover) == SIZE_MAX) {
            free(cover);
            return bn_error_set(err, BN_ENOMEM, "out of memory for the cover classes of %zu patches", np);
        }
        st = bn__tree_build(scene, !(o->eps == 0 || o->exact_leaf_links), cover, &B.t, err);
        free(cover);
        if (st != BN_OK)
            return st;
    }
    if (B.t.n >= BN__LINK_PARTIAL) {   /* a link's source takes 31 bits */
        bn__tree_free(&B.t);
        return bn_error_set(err, BN_ENOMEM, "the hierarchy of %zu patches needs %zu nodes, above 2^31", B.t.npatch, B.t.n);
    }
    rep->seconds_tree = bn__now() - B.t0;
    B.t0 = bn__now();
    if ((st = bn__ref_init(&B, scene, rt, o, err)) == BN_OK && (st = bn__build_buffers(&B, err)) == BN_OK) {
        rep->eps_abs = B.R.eps_abs;
        st = bn__start_links(&B, err);
    }
    if (st == BN_OK)
        st = bn__passes(&B, rep, err);
    if (st == BN_OK)
        st = bn__freeze(&B, rep, out, err);
    bn__build_free(&B);
    return st;
}

bn_status bn_hierarchy_build(const bn_scene *scene, const bn_rt *rt, const bn_hierarchy_opts *o, bn_transport **out,
                             bn_hierarchy_report *rep, bn_error *err)
{
    bn_hierarchy_report local;
    int prev = bn__threads_begin(o->threads);
    bn_status st = bn__hierarchy_body(scene, rt, o, out, rep ? rep : &local, err);
    bn__threads_end(prev);
    return st;
}

void bn_hierarchy_report_print(const bn_hierarchy_report *r, FILE *fp)
{
    fprintf(fp, "polygons %zu\nplanes %zu\nmin_area %.6g\n", r->polygons, r->planes, r->min_area);
    fprintf(fp, "patches %zu\nnodes %zu\nclusters %zu\nplanar_nodes %zu\nlinks %zu\nleaf_links %zu\n"
                "cluster_links %zu\nlinks_per_patch %.3g\npasses %zu\nsettled %d\nrays %zu\nbytes %zu\n"
                "bytes_per_link %.3g\npeak_link_bytes %zu\npeak_bytes_per_link %.3g\neps_abs %.6g\nseconds_tree %.3f\n"
                "seconds_refine %.3f\n",
            r->patches, r->nodes, r->clusters, r->planar_nodes, r->links, r->leaf_links, r->cluster_links,
            r->patches ? (double)r->links / (double)r->patches : 0.0, r->passes, r->settled, r->rays, r->bytes,
            r->bytes_per_link, r->peak_link_bytes, r->peak_bytes_per_link, r->eps_abs, r->seconds_tree,
            r->seconds_refine);
}
