/* One path through the patches, binned by its number of reflections.
 *
 * L_o(x) = Le(x) + rho(x)/pi * integral over the hemisphere of L_i(x, w) cos(theta) dw. A path with
 * k reflections between the emitter and the first vertex contributes to the term K^k E. Each
 * reflection gathers emission by next-event estimation (a point on an emitter, chosen by power,
 * or above tree_emitters emitting patches from a light tree by its likely contribution at x)
 * and by cosine sampling, combined with the power heuristic (Veach 1997, ch. 9):
 *   w_nee = p_nee^2 / (p_nee^2 + p_bsdf^2),  p_nee = P(j | x) / A_j * d^2 / cos_y,  p_bsdf = cos_x / pi.
 * For a Lambertian surface both weighted contributions are bounded by rho Le / 2, so sample means
 * are close to normal. Russian roulette after rr_depth reflections survives with probability
 * min(0.95, max_c rho_c) and divides the throughput by it (unbiased; pbrt-v4 8.2). */
#include "trace/trace_internal.h"
#include "base/vec.h"

#include <math.h>
#include <string.h>

/* The models and strategies in their enums' order. */
#define BN__MODELS(X) X("continuous") X("patch")
BN__VOCABULARY(bn_trace_model, bn_trace_model, BN__MODELS)
#define BN__STRATEGIES(X) X("mis") X("bsdf") X("nee")
BN__VOCABULARY(bn_trace_strategy, bn_trace_strategy, BN__STRATEGIES)

void bn_trace_opts_default(bn_trace_opts *o)
{
    memset(o, 0, sizeof *o);
    o->spp = 64;
    o->bounces = 3;
    o->rr_depth = 3;
    o->max_depth = 100000;
    o->strategy = BN_TRACE_MIS;
    o->model = BN_TRACE_CONTINUOUS;
    o->seed = 1;
    o->tree_emitters = BN_TRACE_TREE_EMITTERS;
}

static double bn__tri_area(const double *a, const double *b, const double *c)
{
    double e1[3], e2[3], n[3];
    bn_v3_sub(b, a, e1);
    bn_v3_sub(c, a, e2);
    bn_v3_cross(e1, e2, n);
    return 0.5 * bn_v3_len(n);
}

/* The light tree over the emitting patches (corners, normal, area x summed radiance). */
static bn_status bn__tracer_tree(bn__tracer *t, bn_error *err)
{
    bn__light *l = bn__malloc_array(t->nem, sizeof *l);
    double *corners = bn__malloc_array(t->nem, 12 * sizeof(double));
    if (l && corners && (t->em_index = bn__malloc_array(t->np, sizeof *t->em_index)))
        for (size_t e = 0; e < t->nem; e++) {
            size_t i = t->em_patch[e];
            const bn_patch *p = &t->patches[i];
            t->em_index[i] = e;
            for (unsigned k = 0; k < p->ncorners; k++)
                memcpy(corners + 12 * e + 3 * k, t->pv + 3 * p->corner[k], 3 * sizeof(double));
            l[e] = (bn__light){corners + 12 * e, p->ncorners, {p->normal[0], p->normal[1], p->normal[2]},
                               p->area * (t->Le[3 * i] + t->Le[3 * i + 1] + t->Le[3 * i + 2])};
        }
    if (l && corners && t->em_index)
        t->tree = bn__lights_build(l, t->nem, 2 * t->eps);
    free(l);
    free(corners);
    if (!t->tree) {
        bn__tracer_free(t);
        return bn_error_set(err, BN_ENOMEM, "trace: out of memory for the light tree of %zu emitting patches", t->nem);
    }
    return BN_OK;
}

bn_status bn__tracer_init(bn__tracer *t, const bn_rt *rt, const bn_trace_opts *o, bn_error *err)
{
    size_t npv;
    double W = 0;
    memset(t, 0, sizeof *t);
    t->rt = rt;
    t->scene = bn_rt_scene(rt);
    t->patches = bn_scene_patches(t->scene, &t->np);
    t->pv = bn_scene_patch_vertices(t->scene, &npv);
    t->o = *o;
    t->nbins = o->bounces + 2;
    t->eps = bn_rt_epsilon(rt);
    t->pl = bn_scene_lights(t->scene, &t->npl);
    t->unit = bn_unit_to_metres(bn_scene_unit(t->scene));
    if (o->spp < 1 || o->bounces < 0 || o->rr_depth < 1 || o->max_depth < 1)
        return bn_error_set(err, BN_EUSAGE, "trace: spp %zu, bounces %d, rr_depth %d, max_depth %d: each must be >= 1 "
                            "(bounces >= 0)", o->spp, o->bounces, o->rr_depth, o->max_depth);
    t->rho = bn__malloc_array(t->np, 3 * sizeof(double));
    t->Le = bn__malloc_array(t->np, 3 * sizeof(double));
    t->tri0 = bn__malloc_array(t->np, sizeof(double));
    t->pdf_area = bn__calloc(t->np, sizeof(double));
    t->em_patch = bn__malloc_array(t->np, sizeof(size_t));
    t->em_cdf = bn__malloc_array(t->np, sizeof(double));
    if (!t->rho || !t->Le || !t->tri0 || !t->pdf_area || !t->em_patch || !t->em_cdf) {
        bn__tracer_free(t);
        return bn_error_set(err, BN_ENOMEM, "trace: out of memory for the tables of %zu patches", t->np);
    }
    bn_scene_patch_reflectance(t->scene, t->rho);
    bn_scene_patch_emission(t->scene, t->Le);
    for (size_t i = 0; i < t->np; i++) {
        const bn_patch *p = &t->patches[i];
        const double *a = t->pv + 3 * p->corner[0], *b = t->pv + 3 * p->corner[1], *c = t->pv + 3 * p->corner[2];
        double w;
        if (p->ncorners == 4) {
            double a0 = bn__tri_area(a, b, c), a1 = bn__tri_area(a, c, t->pv + 3 * p->corner[3]);
            t->tri0[i] = a0 + a1 > 0 ? a0 / (a0 + a1) : 1;
        } else {
            t->tri0[i] = 1;
        }
        w = p->area * (t->Le[3 * i] + t->Le[3 * i + 1] + t->Le[3 * i + 2]);
        if (w > 0) {
            t->em_patch[t->nem] = i;
            W += w;
            t->em_cdf[t->nem++] = W;
        }
    }
    for (size_t e = 0; e < t->nem; e++) {
        size_t i = t->em_patch[e];
        double w = t->patches[i].area * (t->Le[3 * i] + t->Le[3 * i + 1] + t->Le[3 * i + 2]);
        t->em_cdf[e] /= W;
        t->pdf_area[i] = (w / W) / t->patches[i].area;
    }
    if (t->nem)
        t->em_cdf[t->nem - 1] = 1;
    return t->nem > (size_t)o->tree_emitters ? bn__tracer_tree(t, err) : BN_OK;
}

void bn__tracer_free(bn__tracer *t)
{
    free(t->rho);
    free(t->Le);
    free(t->tri0);
    free(t->pdf_area);
    free(t->em_patch);
    free(t->em_cdf);
    free(t->em_index);
    bn__lights_free(t->tree);
    memset(t, 0, sizeof *t);
}

void bn__tracer_patch_point(const bn__tracer *t, size_t p, double u1, double u2, double u3, double x[3])
{
    const bn_patch *pa = &t->patches[p];
    const double *a = t->pv + 3 * pa->corner[0], *b, *c;
    double s, wa, wb, wc;
    if (pa->ncorners == 4 && u3 >= t->tri0[p]) {
        b = t->pv + 3 * pa->corner[2];
        c = t->pv + 3 * pa->corner[3];
    } else {
        b = t->pv + 3 * pa->corner[1];
        c = t->pv + 3 * pa->corner[2];
    }
    /* Uniform on a triangle: s = sqrt(u1) (Shirley and Chiu). */
    s = sqrt(u1);
    wa = 1 - s;
    wb = s * (1 - u2);
    wc = s * u2;
    for (int k = 0; k < 3; k++)
        x[k] = wa * a[k] + wb * b[k] + wc * c[k];
}

/* The hits' and next-event picks choose among the patches of a node subtending less than this sine
 * by power alone (src/rt/lights.h). */
#define BN__TRACE_FAR 0.3

/* Next-event estimation's emitter for the point x (normal n) from u: by power, or from the light
 * tree; *pdf_area its probability over its area. SIZE_MAX when none can light x. */
static size_t bn__pick_emitter(const bn__tracer *t, const double x[3], const double n[3], double u, double *pdf_area)
{
    size_t lo = 0, hi = t->nem - 1;
    if (t->tree) {
        double p;
        size_t e = bn__lights_pick(t->tree, x, n, u, BN__TRACE_FAR, &p);
        if (e == BN__LIGHTS_NONE)
            return SIZE_MAX;
        *pdf_area = p / t->patches[t->em_patch[e]].area;
        return t->em_patch[e];
    }
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (u < t->em_cdf[mid])
            hi = mid;
        else
            lo = mid + 1;
    }
    *pdf_area = t->pdf_area[t->em_patch[lo]];
    return t->em_patch[lo];
}

/* The area density with which next-event estimation at x (normal n) picks points on emitting patch j. */
static double bn__emitter_pdf(const bn__tracer *t, const double x[3], const double n[3], size_t j)
{
    if (!t->tree)
        return t->pdf_area[j];
    return bn__lights_pdf(t->tree, x, n, t->em_index[j], BN__TRACE_FAR) / t->patches[j].area;
}

/* Next-event estimation at x (normal n, ray origin o): a point y on an emitter, its light times
 * the throughput bx (MIS-weighted against cosine sampling with mis) added to bins[3 bin ..]. */
static void bn__nee(const bn__tracer *t, const double x[3], const double n[3], const double o[3], const double bx[3],
                    int mis, bn__rng *rng, double *bins, int bin, unsigned long long *rays)
{
    double ua = bn__rng_uniform(rng), ub = bn__rng_uniform(rng), uc = bn__rng_uniform(rng), ud = bn__rng_uniform(rng);
    double y[3], d[3], dist2, dist, cx, cy, pa, pl, pb, wgt, ye[3], sd[3], len, g;
    size_t j = bn__pick_emitter(t, x, n, ua, &pa);
    if (j == SIZE_MAX)
        return;
    bn__tracer_patch_point(t, j, ub, uc, ud, y);
    bn_v3_sub(y, x, d);
    dist2 = bn_v3_dot(d, d);
    dist = sqrt(dist2);
    if (!(dist > 0))
        return;
    bn_v3_scale(d, 1.0 / dist, d);
    cx = bn_v3_dot(n, d);
    cy = -bn_v3_dot(t->patches[j].normal, d);
    if (!(cx > 0 && cy > 0 && pa > 0))
        return;
    pl = pa * dist2 / cy;
    pb = cx / BN_PI;
    wgt = mis ? pl * pl / (pl * pl + pb * pb) : 1.0;
    /* Shadow ray between offset end points, stopping short by eps. */
    bn_v3_madd(y, t->eps, t->patches[j].normal, ye);
    bn_v3_sub(ye, o, sd);
    len = bn_v3_len(sd);
    (*rays)++;
    if (!(len > 2 * t->eps))
        return;
    bn_v3_scale(sd, 1.0 / len, sd);
    if (bn_rt_occluded(t->rt, o, sd, 0, len - t->eps))
        return;
    g = wgt * cx / (BN_PI * pl);
    for (int c = 0; c < 3; c++)
        bins[3 * bin + c] += bx[c] * t->Le[3 * j + c] * g;
}

/* The punctual lights' light at x (normal n, ray origin o) times the throughput bx, added to bins[3 bin ..]:
 * one shadow ray to each (a delta light: no other strategy can reach it, whatever the strategy). */
static void bn__nee_punctual(const bn__tracer *t, const double x[3], const double n[3], const double o[3],
                             const double bx[3], double *bins, int bin, unsigned long long *rays)
{
    for (size_t k = 0; k < t->npl; k++) {
        double E[3], wi[3], d;
        if (!bn_light_irradiance(&t->pl[k], t->unit, x, n, E, wi, &d))
            continue;
        (*rays)++;
        if (bn_rt_occluded(t->rt, o, wi, 0, isinf(d) ? INFINITY : d * (1 - 1e-9) - t->eps))
            continue;
        for (int c = 0; c < 3; c++)
            bins[3 * bin + c] += bx[c] * E[c] / BN_PI;
    }
}

void bn__tracer_restart(const bn__tracer *t, size_t p, bn__rng *rng, double x[3])
{
    double u1 = bn__rng_uniform(rng), u2 = bn__rng_uniform(rng), u3 = bn__rng_uniform(rng);
    bn__tracer_patch_point(t, p, u1, u2, u3, x);
}

static double bn__max3(const double *v) { return fmax(v[0], fmax(v[1], v[2])); }

/* The emission the cosine-sampled ray from x (normal n, direction w, cosine cz) meets at h, times the
 * throughput bx, MIS-weighted against next-event estimation with mis, added to bins[3 bin ..]. */
static void bn__hit_emission(const bn__tracer *t, const double x[3], const double n[3], const double w[3], double cz,
                             const bn_hit *h, int mis, const double bx[3], double *bins, int bin)
{
    const double *le = t->Le + 3 * h->patch;
    double wgt = 1.0;
    if (!(le[0] > 0 || le[1] > 0 || le[2] > 0))
        return;
    if (mis && t->pdf_area[h->patch] > 0) {
        double cy = -bn_v3_dot(t->patches[h->patch].normal, w);
        double dd = bn_v3_dist(h->p, x);
        double pb = cz / BN_PI, pl = cy > 0 ? bn__emitter_pdf(t, x, n, h->patch) * dd * dd / cy : INFINITY;
        wgt = isinf(pl) ? 0.0 : pb * pb / (pb * pb + pl * pl);
    }
    for (int c = 0; c < 3; c++)
        bins[3 * bin + c] += bx[c] * le[c] * wgt;
}

void bn__tracer_path(const bn__tracer *t, const double x0[3], size_t p0, const double *rho0, bn__rng *rng,
                     double *bins, unsigned long long *rays)
{
    double beta[3] = {1, 1, 1}, x[3];
    size_t p = p0;
    const int use_nee = t->o.strategy != BN_TRACE_BSDF && t->nem > 0;
    const int use_hit = t->o.strategy != BN_TRACE_NEE;
    const int mis = t->o.strategy == BN_TRACE_MIS;
    memcpy(x, x0, sizeof x);
    for (int r = 1;; r++) {
        const double *rho = r == 1 && rho0 ? rho0 : t->rho + 3 * p, *n = t->patches[p].normal;
        double bx[3], o[3], t1[3], t2[3], w[3], u1, u2, cz, rr = bn__max3(rho);
        int bin = r <= t->o.bounces ? r : t->o.bounces + 1;
        bn_hit h;
        if (rr <= 0 || r > t->o.max_depth)
            break;
        if (r > t->o.rr_depth) {
            double q = fmin(0.95, rr);
            if (bn__rng_uniform(rng) >= q)
                break;
            bn_v3_scale(beta, 1.0 / q, beta);
        }
        /* bx: throughput after the reflection at x (f cos / p_bsdf = rho for cosine sampling). */
        for (int c = 0; c < 3; c++)
            bx[c] = beta[c] * rho[c];
        bn_v3_madd(x, t->eps, n, o);
        if (use_nee)
            bn__nee(t, x, n, o, bx, mis, rng, bins, bin, rays);
        if (t->npl)
            bn__nee_punctual(t, x, n, o, bx, bins, bin, rays);
        /* Cosine sampling: w = (r cos phi, r sin phi, sqrt(1 - u1)) around n. */
        u1 = bn__rng_uniform(rng);
        u2 = bn__rng_uniform(rng);
        {
            double rad = sqrt(u1), phi = 2 * BN_PI * u2;
            double lx = rad * cos(phi), ly = rad * sin(phi);
            cz = sqrt(fmax(0.0, 1 - u1));
            bn_v3_basis(n, t1, t2);
            for (int k = 0; k < 3; k++)
                w[k] = lx * t1[k] + ly * t2[k] + cz * n[k];
        }
        (*rays)++;
        if (cz <= 0 || !bn_rt_intersect(t->rt, o, w, 0, INFINITY, &h) || !h.front)
            break;   /* escaped, grazing, or the black back of a surface */
        if (use_hit)
            bn__hit_emission(t, x, n, w, cz, &h, mis, bx, bins, bin);
        memcpy(beta, bx, sizeof beta);
        p = h.patch;
        if (t->o.model == BN_TRACE_PATCH)
            bn__tracer_restart(t, p, rng, x);   /* the patch-constant transport: anywhere on p */
        else
            memcpy(x, h.p, sizeof x);
    }
}
