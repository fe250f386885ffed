/* Per-patch estimates of the patch-averaged outgoing radiance, binned by path length.
 *
 * For patch i: L_i = (1/A_i) integral over A_i of L_o(x) dx, L_o = Le + rho/pi * integral L_in cos dw.
 * Each sample draws x uniform on the patch and one path from it (path.c); samples are independent
 * (stream keyed by (seed, patch, sample)), so the standard error comes from the samples alone. */
#include "trace/trace_internal.h"
#include "bounce/dist.h"
#include "base/vec.h"

#include <math.h>
#include <omp.h>
#include <string.h>

#define BN__TRACE_TAG_REGION 0x726567696f6eULL   /* "region" */
#define BN__TRACE_TAG_POINT 0x706f696e74ULL      /* "point" */

/* What one item is: a patch (both NULL), a region of a partition, or a point. */
typedef struct bn__trace_what {
    const bn_partition *part;
    const bn_trace_point *pts;
} bn__trace_what;

/* Sample s's start for item i: the patch and the point on it (a point item: its own, every sample). */
static size_t bn__trace_start(const bn__tracer *t, const bn__trace_what *w, size_t i, bn__rng *rng, double x[3])
{
    size_t p = i;
    if (w->pts) {
        memcpy(x, w->pts[i].x, 3 * sizeof *x);
        return w->pts[i].patch;
    }
    if (w->part) {   /* the region's patch by area (independent draws: se from the samples) */
        double u0 = bn__rng_uniform(rng);
        size_t lo = w->part->start[i], hi = w->part->start[i + 1] - 1;
        while (lo < hi) {
            size_t mid = lo + (hi - lo) / 2;
            if (w->part->cum[mid] > u0)
                hi = mid;
            else
                lo = mid + 1;
        }
        p = w->part->patch[lo];
    }
    double u1 = bn__rng_uniform(rng), u2 = bn__rng_uniform(rng), u3 = bn__rng_uniform(rng);
    bn__tracer_patch_point(t, p, u1, u2, u3, x);
    return p;
}

/* Item i's spp samples (a patch, a region's patches by area, or a point) into out's mean and se. */
static void bn__trace_item(const bn__tracer *t, const bn__trace_what *w, const bn_trace_opts *o, size_t i, size_t n,
                           size_t nl, double *sample, double *mean, double *m2, bn_trace_patches *out,
                           unsigned long long *rays)
{
    const uint64_t tag = w->pts ? BN__TRACE_TAG_POINT : w->part ? BN__TRACE_TAG_REGION : BN__TRACE_TAG_PATCH;
    double rho[3];   /* a point's reflectance (its texture there), once for its samples; NULL: the patch's */
    const double *rho0 = NULL;
    if (w->pts) {
        bn_scene_reflectance_at(t->scene, t->patches[w->pts[i].patch].face, w->pts[i].x, rho);
        rho0 = rho;
    }
    size_t m = nl * 3;
    double *m3 = m2 + m;
    memset(mean, 0, m * sizeof(double));
    memset(m2, 0, 2 * m * sizeof(double));
    for (size_t s = 0; s < o->spp; s++) {
        if ((s & 4095) == 4095 && bn_interrupted() != BN_OK)
            break;   /* an item of 1e6 samples takes seconds: stop within one batch (discarded) */
        bn__rng rng = bn__rng_make(o->seed ^ tag, i, s);
        double x[3], *L = sample + 3 * (nl - 1);
        size_t p = bn__trace_start(t, w, i, &rng, x);
        memset(sample, 0, m * sizeof(double));
        /* Bin 0: the patch's own emission, seen directly. */
        for (int c = 0; c < 3; c++)
            sample[c] = t->Le[3 * p + c];
        bn__tracer_path(t, x, p, rho0, &rng, sample, rays);
        for (size_t l = 0; l + 1 < nl; l++)
            for (int c = 0; c < 3; c++)
                L[c] += sample[3 * l + c];
        bn__moments_add(mean, m2, m3, sample, m, s + 1);
    }
    for (size_t l = 0; l < nl; l++)
        for (int c = 0; c < 3; c++) {
            size_t k = (l * n + i) * 3 + (size_t)c, j = 3 * l + (size_t)c;
            double var = o->spp > 1 ? m2[j] / (double)(o->spp - 1) : 0;
            out->mean[k] = mean[j];
            out->se[k] = sqrt(fmax(var, 0.0) / (double)o->spp);
            out->skew[k] = m2[j] > 0 ? sqrt((double)o->spp) * m3[j] / pow(m2[j], 1.5) : 0;
        }
}

typedef struct bn__trace_items_ctx {
    const bn__tracer *t;
    const bn__trace_what *what;
    const bn_trace_opts *o;
    size_t n, nl;
    bn_trace_patches *out;
} bn__trace_items_ctx;

static void bn__trace_item_run(void *ctx, size_t i, double *sample, double *mean, double *m2, unsigned long long *rays)
{
    const bn__trace_items_ctx *c = ctx;
    bn__trace_item(c->t, c->what, c->o, i, c->n, c->nl, sample, mean, m2, c->out, rays);
}

/* Every estimate finite, or BN_ENUMERIC naming the first that is not (out freed). */
static bn_status bn__trace_finite(const bn__trace_what *w, const bn_trace_opts *o, bn_trace_patches *out,
                                  bn_error *err)
{
    for (size_t l = 0; l < (size_t)out->nlayers; l++)
        for (size_t i = 0; i < out->n; i++)
            for (int c = 0; c < 3; c++) {
                size_t k = (l * out->n + i) * 3 + (size_t)c;
                if (!isfinite(out->mean[k]) || !isfinite(out->se[k])) {
                    char name[16];
                    bn_error_set(err, BN_ENUMERIC, "trace: non-finite estimate %g (se %g) for %s %zu, layer %s, "
                                 "channel %d", out->mean[k], out->se[k], w->pts ? "point" : w->part ? "region" : "patch",
                                 i, bn_layer_name((int)l, o->bounces, name, sizeof name), c);
                    bn_trace_patches_free(out);
                    return BN_ENUMERIC;
                }
            }
    return BN_OK;
}

/* One item per patch; per region of w->part, its points uniform in area over the region; or per point of
 * w->pts (n of them). */
static bn_status bn__trace_items_run_body(const bn_rt *rt, const bn__trace_what *w, size_t npts, const bn_trace_opts *o,
                                          bn_trace_patches *out, bn_error *err)
{
    const bn_partition *part = w->part;
    bn__tracer t;
    bn_status st;
    size_t n, nl, bytes;
    unsigned long long rays = 0;
    int no_buffers;   /* a thread could not allocate its sample buffers */
    bn__progress prog;
    double t0 = bn__now();

    memset(out, 0, sizeof *out);
    st = bn__tracer_init(&t, rt, o, err);
    if (st != BN_OK)
        return st;
    n = w->pts ? npts : part ? part->n : t.np;
    if (part && part->npatch != t.np) {
        bn__tracer_free(&t);
        return bn_error_set(err, BN_EINTERNAL, "trace: a partition of %zu patches for a scene of %zu", part->npatch, t.np);
    }
    nl = (size_t)bn_layer_count(o->bounces);
    if (!bn__mul_size(n, nl * 3 * sizeof(double), &bytes)) {
        bn__tracer_free(&t);
        return bn_error_set(err, BN_ENOMEM, "trace: %zu patches x %zu layers overflows", n, nl);
    }
    out->n = n;
    out->bounces = o->bounces;
    out->nlayers = (int)nl;
    out->spp = o->spp;
    out->mean = bn__calloc(n * nl * 3, sizeof(double));
    out->se = bn__calloc(n * nl * 3, sizeof(double));
    out->skew = bn__calloc(n * nl * 3, sizeof(double));
    if (!out->mean || !out->se || !out->skew) {
        bn__tracer_free(&t);
        bn_trace_patches_free(out);
        return bn_error_set(err, BN_ENOMEM, "trace: out of memory for 3 x %zu bytes of per-patch estimates", bytes);
    }
    bn__progress_begin(&prog, w->pts ? "path tracing points" : part ? "path tracing regions" : "path tracing", n,
                       o->quiet);

    bn__trace_items_ctx ctx = {&t, w, o, n, nl, out};
    no_buffers = bn__trace_parallel(n, nl * 3, 3, bn__trace_item_run, &ctx, &prog, &rays);
    bn__progress_end(&prog);
    bn__tracer_free(&t);
    if ((st = bn__trace_combine(no_buffers, out->mean, out->se, out->skew, 1, n * nl * 3, &rays, err)) != BN_OK ||
        (st = bn__trace_stopped(no_buffers, err)) != BN_OK) {
        bn_trace_patches_free(out);
        return st;
    }
    out->rays = rays;
    out->seconds = bn__now() - t0;
    return bn__trace_finite(w, o, out, err);
}

bn_status bn_trace_patches_run(const bn_rt *rt, const bn_trace_opts *o, bn_trace_patches *out, bn_error *err)
{
    int prev = bn__threads_begin(o->threads);
    bn__trace_what w = {NULL, NULL};
    bn_status st = bn__trace_items_run_body(rt, &w, 0, o, out, err);
    bn__threads_end(prev);
    return st;
}

bn_status bn_trace_points_run(const bn_rt *rt, const bn_trace_point *pts, size_t n, const bn_trace_opts *o,
                              bn_trace_patches *out, bn_error *err)
{
    int prev = bn__threads_begin(o->threads);
    bn__trace_what w = {NULL, pts};
    bn_status st = bn__trace_items_run_body(rt, &w, n, o, out, err);
    bn__threads_end(prev);
    return st;
}

bn_status bn_trace_regions_run(const bn_rt *rt, const bn_partition *part, const bn_trace_opts *o,
                               bn_trace_patches *out, bn_error *err)
{
    int prev = bn__threads_begin(o->threads);
    bn__trace_what w = {part, NULL};
    bn_status st = bn__trace_items_run_body(rt, &w, 0, o, out, err);
    bn__threads_end(prev);
    return st;
}

void bn_trace_patches_free(bn_trace_patches *r)
{
    if (!r)
        return;
    free(r->mean);
    free(r->se);
    free(r->skew);
    r->mean = r->se = r->skew = NULL;
}

void bn_trace_patches_power(const bn_scene *s, const bn_trace_patches *r, int layer, double watts[3], double se[3])
{
    size_t np;
    const bn_patch *p = bn_scene_patches(s, &np);
    double m = bn_unit_to_metres(bn_scene_unit(s)), m2 = m * m;
    double v[3] = {0, 0, 0};
    watts[0] = watts[1] = watts[2] = 0;
    for (size_t i = 0; i < r->n && i < np; i++)
        for (int c = 0; c < 3; c++) {
            size_t k = ((size_t)layer * r->n + i) * 3 + (size_t)c;
            double a = p[i].area * m2;
            watts[c] += a * r->mean[k];
            v[c] += (a * r->se[k]) * (a * r->se[k]);
        }
    for (int c = 0; c < 3; c++) {
        watts[c] *= BN_PI;
        se[c] = BN_PI * sqrt(v[c]);
    }
}

