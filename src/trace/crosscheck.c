/* The cross-check of radiosity against the per-patch path tracer (Mitsuba 3's statistical tests).
 *
 * For patch i, layer l (E, KE, ..., rest, L) and channel c, with R the radiosity value, T +- s the
 * tracer's mean and standard error (the larger of the samples' own and the face's pooled one) and
 * tau the allowance (from another mesh or eps level; 0 for the patch model on dense K):
 *   z = (R - T) / s,   z_excess = |t_H(sign(T - R) max(0, |R - T| - tau) / s)|,
 * t_H Hall's skew correction with the samples' skewness. The family of m = patches x layers x channels tests passes at family-wise level alpha when every
 * z_excess <= t_{nu}(alpha_1 / 2), alpha_1 = 1 - (1 - alpha)^(1/m) (Sidak), nu = spp - 1. Because tau
 * absorbs radiosity's own (deterministic) error, the verdict converges as spp grows instead of
 * failing once the noise falls below the discretisation error. Powers per layer are tested the
 * same way with the normal bound (they sum N independent patches). */
#include "bounce/trace.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <string.h>

/* A standard error of exactly 0 (the E layer is exact in both methods) becomes this share of the
 * values compared: far below anything the methods resolve (form factors are checked to 1e-9). */
#define BN__SE_FLOOR_REL 1e-9

void bn_crosscheck_input_default(bn_crosscheck_input *in)
{
    memset(in, 0, sizeof *in);
    in->tol_scale = 1;
    in->alpha = 0.01;
    in->worst = 10;
}

/* Is point x inside convex patch p (in its plane), with a tolerance of `eps` scene units? */
static int bn__inside(const bn_patch *p, const double *pv, const double x[3], double eps)
{
    for (unsigned k = 0; k < p->ncorners; k++) {
        const double *a = pv + 3 * p->corner[k], *b = pv + 3 * p->corner[(k + 1) % p->ncorners];
        double e[3], v[3], cr[3], len;
        bn_v3_sub(b, a, e);
        bn_v3_sub(x, a, v);
        bn_v3_cross(e, v, cr);
        len = bn_v3_len(e);
        if (len > 0 && bn_v3_dot(cr, p->normal) / len < -eps)
            return 0;
    }
    return 1;
}

/* Per compared item (patch, or region of in->part): area (m^2) and material. */
static void bn__item(const bn_crosscheck_input *in, size_t i, double *area_m2, unsigned *mat)
{
    size_t np;
    const bn_patch *p = bn_scene_patches(in->scene, &np);
    double m = bn_unit_to_metres(bn_scene_unit(in->scene));
    if (in->part) {
        *area_m2 = in->part->area[i] * m * m;
        *mat = in->part->material[i];
    } else {
        *area_m2 = p[i].area * m * m;
        *mat = p[i].material;
    }
}

/* Power of layer l of per-item values, and (se given) its standard error. */
static void bn__item_power(const bn_crosscheck_input *in, const double *v, const double *se, size_t n, size_t l,
                           double w[3], double ws[3])
{
    double var[3] = {0, 0, 0};
    w[0] = w[1] = w[2] = 0;
    for (size_t i = 0; i < n; i++) {
        double a;
        unsigned mat;
        bn__item(in, i, &a, &mat);
        for (int c = 0; c < 3; c++) {
            size_t k = (l * n + i) * 3 + (size_t)c;
            w[c] += a * v[k];
            if (se)
                var[c] += (a * se[k]) * (a * se[k]);
        }
    }
    for (int c = 0; c < 3; c++) {
        w[c] *= BN_PI;
        if (ws)
            ws[c] = BN_PI * sqrt(var[c]);
    }
}

/* The other level's patches bucketed by face (a counting sort): face f's are order[start[f] ..
 * start[f + 1]). 0 when out of memory (nothing kept). */
static int bn__patches_by_face(const bn_patch *q, size_t n2, size_t nf, size_t **start_out, size_t **order_out)
{
    size_t *start = bn__calloc(nf + 1, sizeof(size_t)), *order = bn__malloc_array(n2 ? n2 : 1, sizeof(size_t));
    size_t *fill = bn__malloc_array(nf ? nf : 1, sizeof(size_t));
    if (!start || !order || !fill) {
        free(start);
        free(order);
        free(fill);
        return 0;
    }
    for (size_t j = 0; j < n2; j++)
        start[q[j].face + 1]++;
    for (size_t f = 0; f < nf; f++)
        start[f + 1] += start[f];
    memcpy(fill, start, nf * sizeof(size_t));
    for (size_t j = 0; j < n2; j++)
        order[fill[q[j].face]++] = j;
    free(fill);
    *start_out = start;
    *order_out = order;
    return 1;
}

/* The other level's patch holding patch p's centroid (within eps), else the nearest centroid on
 * the same face; (size_t)-1 when the face has none there. */
static size_t bn__matching_patch(const bn_patch *p, const bn_patch *q, const double *qv, const size_t *start,
                                 const size_t *order, double eps)
{
    size_t best = (size_t)-1;
    double bestd = INFINITY;
    for (size_t k = start[p->face]; k < start[p->face + 1]; k++) {
        size_t j = order[k];
        double d;
        if (bn__inside(&q[j], qv, p->centroid, eps))
            return j;
        d = bn_v3_dist(q[j].centroid, p->centroid);   /* fallback: nearest centroid in the face */
        if (d < bestd) {
            bestd = d;
            best = j;
        }
    }
    return best;
}

bn_status bn_crosscheck_mesh_tolerance(const bn_scene *fine, const double *fine_layers, const bn_scene *other,
                                       const double *other_layers, int bounces, double *tol, double *power_tol,
                                       bn_error *err)
{
    size_t nf, nf2, n, n2, npv2;
    const bn_patch *p = bn_scene_patches(fine, &n), *q = bn_scene_patches(other, &n2);
    const double *qv = bn_scene_patch_vertices(other, &npv2);
    size_t *start, *order, nl = (size_t)bn_layer_count(bounces);
    double eps;
    bn_scene_faces(fine, &nf);
    bn_scene_faces(other, &nf2);
    if (nf != nf2)
        return bn_error_set(err, BN_EINPUT, "crosscheck: the two mesh levels have different faces (%zu and %zu)", nf,
                            nf2);
    eps = 1e-9 * fmax(bn_scene_diameter(fine), 1e-300);   /* containment slack: rounding, far below any patch */
    if (!bn__patches_by_face(q, n2, nf, &start, &order))
        return bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory mapping %zu patches", n2);
    for (size_t i = 0; i < n; i++) {
        size_t best = bn__matching_patch(&p[i], q, qv, start, order, eps);
        if (best == (size_t)-1) {
            free(start);
            free(order);
            return bn_error_set(err, BN_EINPUT, "crosscheck: face %zu has no patch on the second mesh level",
                                p[i].face);
        }
        for (size_t l = 0; l < nl; l++)
            for (int c = 0; c < 3; c++)
                tol[(l * n + i) * 3 + (size_t)c] =
                    fabs(fine_layers[(l * n + i) * 3 + (size_t)c] - other_layers[(l * n2 + best) * 3 + (size_t)c]);
    }
    free(start);
    free(order);
    for (size_t l = 0; power_tol && l < nl; l++) {
        double a[3], b[3];
        bn_scene_power(fine, fine_layers + l * n * 3, a);   /* n, n2: the scenes' patch counts */
        bn_scene_power(other, other_layers + l * n2 * 3, b);
        for (int c = 0; c < 3; c++)
            power_tol[3 * l + (size_t)c] = fabs(a[c] - b[c]);
    }
    return BN_OK;
}

static int bn__entry_cmp(const void *a, const void *b)
{
    const bn_crosscheck_entry *x = a, *y = b;
    if (x->z_excess != y->z_excess)
        return x->z_excess < y->z_excess ? 1 : -1;
    if (fabs(x->z) != fabs(y->z))
        return fabs(x->z) < fabs(y->z) ? 1 : -1;
    if (x->patch != y->patch)
        return x->patch < y->patch ? -1 : 1;
    if (x->layer != y->layer)
        return x->layer < y->layer ? -1 : 1;
    return x->channel - y->channel;
}

/* z and z_excess of one comparison; se is floored at BN__SE_FLOOR_REL x `scale`, the largest
 * magnitude in the layer (so an exact 0 against a rounding-level value is not a failure). */
static void bn__ztest(double R, double T, double se, double tol, double scale, double *z, double *zx)
{
    double floor_ = BN__SE_FLOOR_REL * fmax(scale, fmax(fabs(R), fabs(T)));
    double s = fmax(se, floor_), d = R - T;
    if (s > 0) {
        *z = d / s;
        *zx = fmax(0.0, fabs(d) - tol) / s;
    } else {   /* both values exactly 0 */
        *z = 0;
        *zx = 0;
    }
}

/* The tracer's samples are skewed (mostly small, now and then a large contribution), and the
 * Student-t tail at the family's bound (|z| ~ 5, a per-test level of 5e-7) is then far off: the
 * studentized mean t = (T - mu) / se of right-skewed samples has a heavy left tail (a low mean comes
 * with a low se), P(t <= x) = Phi(x) + g (2x^2 + 1) phi(x) / (6 sqrt(n)) + O(1/n) (Edgeworth, g the
 * samples' skewness). Measured on the Cornell box at 1,024 samples with the patch model, where
 * radiosity is right: 16% of seeds failed at alpha 0.05, every failure a radiosity value above the
 * trace. Hall's transformation (Hall 1992, "On the removal of skewness by transformation", JRSS B
 * 54) removes that first-order term and is monotone:
 *     t_H = t + g t^2 / (3 sqrt(n)) + g^2 t^3 / (27 n) + g / (6 sqrt(n)),
 * with g the sample skewness; t_H is then compared with the normal bound as t was. */
static double bn__hall(double t, double g, size_t n)
{
    double rn = sqrt((double)n);
    return t + g * t * t / (3 * rn) + g * g * t * t * t / (27 * (double)n) + g / (6 * rn);
}

/* The t test's tail needs enough nonzero samples. An entry whose samples are mostly 0 and a few hits
 * of size h has skewness about 1/sqrt(spp p), p = T/h its hit rate, and the normal tail at the
 * family's bound (|z| ~ 4.6) is off by a factor of about 1 + (z^2 - 1) / (6 sqrt(spp p)) (Edgeworth):
 * 2 at 25 hits, as measured on the Cornell box (16 of 25 seeds failed at alpha 0.1, each on a deep
 * bounce's blue in a shadow with a handful of hits). Entries with fewer than BN__MIN_HITS effective
 * hits, k = spp T / h = spp T^2 / (T^2 + spp se^2), are therefore not judged one by one (their
 * share of the light is in the power test); an estimate of exactly 0 is judged below, by its bound. */
#define BN__MIN_HITS 100.0

static int bn__few_hits(double T, double se, size_t spp)
{
    double s2 = (double)spp * se * se;
    return T > 0 && se > 0 && (double)spp * T * T < BN__MIN_HITS * (T * T + s2);
}

/* A tracer estimate of exactly 0 with a standard error of 0: none of its spp samples was nonzero (a
 * patch that sees a sliver of the light in a corner, hit by 0.7 of 1,024 samples on average), and
 * the sample variance says nothing. Samples that are 0 or a hit of size h: P(all 0) = (1 - mu/h)^spp
 * <= exp(-spp mu / h), so a mean mu is rejected at alpha_1 when mu > h ln(1/alpha_1) / spp; with
 * se0 = h ln(1/alpha_1) / (spp crit), z_excess <= crit says exactly that. h is estimated as
 * E[X^2] / E[X] = T + spp s^2 / T (the hit size for hits of one size, a size-biased mean otherwise)
 * by its median over the other items of the same input face (per patch) or of the layer (regions)
 * with T > 0 in the same layer and channel; none: no bound (the floor). Not for E, which the tracer
 * does not sample (the emitted radiance itself in both). */
typedef struct bn__hsz {
    size_t g;
    double h;
} bn__hsz;

static int bn__hsz_cmp(const void *a, const void *b)
{
    const bn__hsz *x = a, *y = b;
    if (x->g != y->g)
        return x->g < y->g ? -1 : 1;
    return x->h < y->h ? -1 : x->h > y->h;
}

/* The tracer's samples carry rare large contributions (a path that finds its way out of a narrow gap
 * to a bright wall): at the Cornell box's patch 1077 (the tall block's side facing the red wall),
 * K3E blue, 0.5% of the samples carry 38% of the mean, the samples' skewness is 23, and 1,024 samples
 * hold about 5 such; a sample set with none or one is 45% low with a standard error six times too
 * small, so the sample se alone failed 12 of 195 independent sample sets at |z| > 4. The patches of
 * one face see the same paths, and their pooled samples hold the rare ones: the pooled size-biased
 * hit size hp = sum_i E_i[X^2] / sum_i E_i[X] (E_i[X^2] = T_i^2 + spp se_i^2) gives, for a mean mu,
 * the variance a compound of such hits has, mu (hp - mu), and the standard error used is the larger
 * of the sample's and sqrt(mu (hp - mu) / spp) with mu = max(R, T). Regions pool by material. */
static void bn__pooled_hits(const bn_crosscheck_input *in, const bn_patch *pa, size_t ng, size_t l, int c,
                            double *num, double *den, double *hp)
{
    const bn_trace_patches *tr = in->trace;
    size_t n = tr->n;
    for (size_t g = 0; g < ng; g++)
        num[g] = den[g] = 0;
    for (size_t i = 0; i < n; i++) {
        size_t k = (l * n + i) * 3 + (size_t)c, g = in->part ? in->part->material[i] : pa[i].face;
        double T = tr->mean[k], se = tr->se[k];
        if (T > 0 && isfinite(T) && isfinite(se) && g < ng) {
            num[g] += T * T + (double)tr->spp * se * se;
            den[g] += T;
        }
    }
    for (size_t g = 0; g < ng; g++)
        hp[g] = den[g] > 0 ? num[g] / den[g] : NAN;
}

/* hg[g]: the median h of group g (NAN: none), and *hall: of every item; buf: n entries. */
static void bn__hit_sizes(const bn_crosscheck_input *in, const bn_patch *pa, size_t ng, size_t l, int c,
                          bn__hsz *buf, double *hg, double *hall)
{
    const bn_trace_patches *tr = in->trace;
    size_t n = tr->n, m = 0;
    for (size_t g = 0; g < ng; g++)
        hg[g] = NAN;
    *hall = NAN;
    for (size_t i = 0; i < n; i++) {
        size_t k = (l * n + i) * 3 + (size_t)c;
        double T = tr->mean[k], se = tr->se[k];
        if (T > 0 && isfinite(T) && isfinite(se)) {
            buf[m].g = in->part ? 0 : pa[i].face;
            buf[m++].h = T + (double)tr->spp * se * se / T;
        }
    }
    qsort(buf, m, sizeof *buf, bn__hsz_cmp);
    for (size_t a = 0; a < m;) {
        size_t b = a;
        while (b < m && buf[b].g == buf[a].g)
            b++;
        hg[buf[a].g] = buf[a + (b - a) / 2].h;
        a = b;
    }
    for (size_t i = 0; i < m; i++)
        buf[i].g = 0;
    qsort(buf, m, sizeof *buf, bn__hsz_cmp);
    if (m)
        *hall = buf[m / 2].h;
}

/* One entry (item i, layer l, channel c at index k) compared and judged into out's counts; h: the
 * hit size for an estimate of exactly 0 (NAN: none); scale: the tolerance's; lscale: the layer's
 * largest magnitude. */
static void bn__judge(const bn_crosscheck_input *in, size_t k, size_t i, int l, int c, double h, double hp,
                      double scale, double lscale, bn_crosscheck_entry *e, bn_crosscheck_result *out)
{
    const bn_trace_patches *tr = in->trace;
    double R = in->rad[k], T = tr->mean[k];
    e->patch = i;
    e->layer = l;
    e->channel = c;
    e->radiosity = R;
    e->trace = T;
    e->se = tr->se[k];
    e->untested = 0;
    if (l > 0 && T == 0 && e->se == 0 && tr->spp > 1 && out->crit > 0 && isfinite(h))
        /* no sample was nonzero (E, layer 0, is not sampled: exact in both) */
        e->se = h * -log(out->alpha_each) / ((double)tr->spp * out->crit);
    else if (l > 0 && T > 0 && R >= 0 && isfinite(hp)) {
        double mu = fmax(R, T);
        e->se = fmax(e->se, sqrt(mu * fmax(hp - mu, 0.0) / (double)tr->spp));   /* the face's pooled tail */
    }
    e->tol = (in->tol ? scale * in->tol[k] : 0) + in->rtol * fabs(R);
    bn__ztest(R, T, e->se, e->tol, lscale, &e->z, &e->z_excess);
    if (tr->skew && l > 0 && T > 0 && tr->spp > 2) {
        /* the test on the trace's t = (T - R') / se, R' the nearest point of R +- tol: skew-corrected */
        double t = e->z > 0 ? -e->z_excess : e->z_excess;
        e->z_excess = fabs(bn__hall(t, tr->skew[k], tr->spp));
    }
    if (!isfinite(R) || !isfinite(T)) {
        e->z = e->z_excess = INFINITY;
    } else if (l > 0 && bn__few_hits(T, e->se, tr->spp)) {
        e->untested = 1;   /* the t tail does not hold: shown, not judged (the power test is) */
        e->z_excess = 0;
        out->few_hits++;
    }
    if (e->z_excess <= out->crit) {
        out->within++;
        out->layer_within[l]++;
    }
    if (fabs(e->z) <= out->crit)
        out->within_raw++;
    out->worst_z = fmax(out->worst_z, e->z_excess);
    out->worst_z_raw = fmax(out->worst_z_raw, fabs(e->z));
    out->layer_worst_z[l] = fmax(out->layer_worst_z[l], e->z_excess);
}

/* Every entry judged into all[] (n items x nl layers x 3) and out's counts; BN_ENOMEM. */
static bn_status bn__judge_entries(const bn_crosscheck_input *in, bn_crosscheck_entry *all, bn_crosscheck_result *out)
{
    const bn_trace_patches *tr = in->trace;
    size_t n = tr->n, nl = (size_t)tr->nlayers, np, nmat, nf, ng, npg;
    const bn_patch *pa = bn_scene_patches(in->scene, &np);
    double scale = in->tol_scale >= 0 ? in->tol_scale : 1, *hg, *hp;
    bn__hsz *hsz;
    bn_scene_materials(in->scene, &nmat);
    bn_scene_faces(in->scene, &nf);
    ng = in->part ? 1 : nf + 1;           /* hit-size groups: the faces, or one */
    npg = in->part ? nmat + 1 : nf + 1;   /* pooling groups: the faces, or the regions' materials */
    hsz = bn__malloc_array(n ? n : 1, sizeof *hsz);
    hg = bn__malloc_array(3 * ng, sizeof *hg);
    hp = bn__malloc_array(3 * npg, sizeof *hp);   /* num, den, hp */
    for (size_t l = 0; hsz && hg && hp && l < nl; l++) {
        double lscale = 0, hall[3];
        for (size_t k = l * n * 3; k < (l + 1) * n * 3; k++)
            if (isfinite(in->rad[k]) && isfinite(tr->mean[k]))
                lscale = fmax(lscale, fmax(fabs(in->rad[k]), fabs(tr->mean[k])));
        for (int c = 0; c < 3; c++)
            bn__hit_sizes(in, pa, ng, l, c, hsz, hg + (size_t)c * ng, &hall[c]);
        for (int c = 0; c < 3; c++) {
            bn__pooled_hits(in, pa, npg, l, c, hp, hp + npg, hp + 2 * npg);
            for (size_t i = 0; i < n; i++) {
                size_t k = (l * n + i) * 3 + (size_t)c;
                double h = hg[(size_t)c * ng + (in->part ? 0 : pa[i].face)];
                double hpi = hp[2 * npg + (in->part ? in->part->material[i] : pa[i].face)];
                bn__judge(in, k, i, (int)l, c, isfinite(h) ? h : hall[c], hpi, scale, lscale, &all[k], out);
            }
        }
    }
    free(hsz);
    free(hg);
    free(hp);
    return hsz && hg && hp ? BN_OK : BN_ENOMEM;
}

/* Per-layer powers of both methods, and their test. */
static void bn__judge_powers(const bn_crosscheck_input *in, bn_crosscheck_result *out)
{
    const bn_trace_patches *tr = in->trace;
    size_t n = tr->n, nl = (size_t)tr->nlayers;
    double scale = in->tol_scale >= 0 ? in->tol_scale : 1;
    out->power_family = nl * 3;
    out->power_crit = bn_normal_quantile_upper(-expm1(log1p(-in->alpha) / (double)out->power_family) / 2);
    for (size_t l = 0; l < nl; l++) {
        double w[3], se[3];
        bn__item_power(in, in->rad, NULL, n, l, out->power_rad + 3 * l, NULL);
        bn__item_power(in, tr->mean, tr->se, n, l, w, se);
        for (int c = 0; c < 3; c++) {
            size_t k = 3 * l + (size_t)c;
            double z, zx;
            out->power_pt[k] = w[c];
            out->power_se[k] = se[c];
            out->power_tol[k] = (in->power_tol ? scale * in->power_tol[k] : 0) + in->rtol * fabs(out->power_rad[k]);
            bn__ztest(out->power_rad[k], w[c], se[c], out->power_tol[k], 0, &z, &zx);
            if (!isfinite(out->power_rad[k]) || !isfinite(w[c]))
                zx = INFINITY;
            out->power_worst_z = fmax(out->power_worst_z, zx);
        }
    }
}

/* Per surface (material): area-weighted L (the last layer) of both methods, and the tracer's se. */
static void bn__surfaces(const bn_crosscheck_input *in, bn_crosscheck_result *out)
{
    const bn_trace_patches *tr = in->trace;
    size_t n = tr->n, l = (size_t)tr->nlayers - 1;
    for (size_t i = 0; i < n; i++) {
        double a;
        unsigned s;
        bn__item(in, i, &a, &s);
        out->surf_area[s] += a;
        for (int c = 0; c < 3; c++) {
            size_t k = (l * n + i) * 3 + (size_t)c;
            out->surf_rad[3 * s + (size_t)c] += a * in->rad[k];
            out->surf_pt[3 * s + (size_t)c] += a * tr->mean[k];
            out->surf_se[3 * s + (size_t)c] += (a * tr->se[k]) * (a * tr->se[k]);
        }
    }
    for (size_t s = 0; s < out->nsurfaces; s++)
        for (int c = 0; c < 3; c++) {
            double a = out->surf_area[s];
            size_t k = 3 * s + (size_t)c;
            out->surf_rad[k] = a > 0 ? out->surf_rad[k] / a : 0;
            out->surf_pt[k] = a > 0 ? out->surf_pt[k] / a : 0;
            out->surf_se[k] = a > 0 ? sqrt(out->surf_se[k]) / a : 0;
        }
}

/* out's arrays for nl layers and nmat surfaces; 0 when out of memory. */
static int bn__result_alloc(bn_crosscheck_result *out, size_t nl, size_t nmat)
{
    out->nlayers = (int)nl;
    out->layer_within = bn__calloc(nl, sizeof(size_t));
    out->layer_worst_z = bn__calloc(nl, sizeof(double));
    out->power_rad = bn__calloc(nl * 3, sizeof(double));
    out->power_pt = bn__calloc(nl * 3, sizeof(double));
    out->power_se = bn__calloc(nl * 3, sizeof(double));
    out->power_tol = bn__calloc(nl * 3, sizeof(double));
    out->nsurfaces = nmat;
    out->surf_area = bn__calloc(nmat ? nmat : 1, sizeof(double));
    out->surf_rad = bn__calloc(nmat ? nmat * 3 : 1, sizeof(double));
    out->surf_pt = bn__calloc(nmat ? nmat * 3 : 1, sizeof(double));
    out->surf_se = bn__calloc(nmat ? nmat * 3 : 1, sizeof(double));
    return out->layer_within && out->layer_worst_z && out->power_rad && out->power_pt && out->power_se &&
           out->power_tol && out->surf_area && out->surf_rad && out->surf_pt && out->surf_se;
}

bn_status bn_crosscheck_compare(const bn_crosscheck_input *in, bn_crosscheck_result *out, bn_error *err)
{
    const bn_trace_patches *tr = in->trace;
    size_t n = tr->n, nl = (size_t)tr->nlayers, np, nmat, m;
    bn_crosscheck_entry *all;

    memset(out, 0, sizeof *out);
    bn_scene_materials(in->scene, &nmat);
    bn_scene_patches(in->scene, &np);
    if (in->part ? in->part->n != n || in->part->npatch != np : np != n)
        return bn_error_set(err, BN_EINPUT, "crosscheck: the tracer has %zu %s, the scene %zu", n,
                            in->part ? "regions" : "patches", in->part ? in->part->n : np);
    if (!(in->alpha > 0 && in->alpha < 1))
        return bn_error_set(err, BN_EUSAGE, "crosscheck: alpha %g is not in (0, 1)", in->alpha);
    m = n * nl * 3;
    all = bn__malloc_array(m ? m : 1, sizeof *all);
    out->family = m;
    out->alpha = in->alpha;
    /* alpha_1 = 1 - (1 - alpha)^(1/m), by expm1/log1p to keep its digits when it is tiny. */
    out->alpha_each = -expm1(log1p(-in->alpha) / (double)(m ? m : 1));
    out->crit = bn_student_t_quantile_upper(out->alpha_each / 2, tr->spp > 1 ? (double)(tr->spp - 1) : 1);
    if (!all || !bn__result_alloc(out, nl, nmat) || bn__judge_entries(in, all, out) != BN_OK) {
        free(all);
        bn_crosscheck_result_free(out);
        return bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory for %zu comparisons", m);
    }
    qsort(all, m, sizeof *all, bn__entry_cmp);
    out->nworst = in->worst < 0 ? 0 : (in->worst > (int)m ? (int)m : in->worst);
    out->worst = bn__malloc_array(out->nworst ? (size_t)out->nworst : 1, sizeof *all);
    if (!out->worst) {
        free(all);
        bn_crosscheck_result_free(out);
        return bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory");
    }
    memcpy(out->worst, all, (size_t)out->nworst * sizeof *all);
    free(all);
    bn__judge_powers(in, out);
    bn__surfaces(in, out);
    out->pass = out->within == out->family && out->power_worst_z <= out->power_crit;
    return BN_OK;
}

void bn_crosscheck_result_free(bn_crosscheck_result *r)
{
    if (!r)
        return;
    free(r->worst);
    free(r->layer_within);
    free(r->layer_worst_z);
    free(r->power_rad);
    free(r->power_pt);
    free(r->power_se);
    free(r->power_tol);
    free(r->surf_area);
    free(r->surf_rad);
    free(r->surf_pt);
    free(r->surf_se);
    memset(r, 0, sizeof *r);
}

static const char bn__ch[3] = {'R', 'G', 'B'};

/* The per-entry test: its bounds, and each layer's share within and worst z_excess. */
static void bn__print_layers(const bn_crosscheck_input *in, const bn_crosscheck_result *r, FILE *fp)
{
    const bn_trace_patches *tr = in->trace;
    size_t n = tr->n;
    char name[16];
    fprintf(fp, "\nper-%s test: %zu %s x %d layers x 3 channels = %zu tests; alpha %g (family-wise), "
                "Sidak per test %.3g, bound |z| <= %.3f (Student t, %zu dof)\n",
            in->part ? "region" : "patch", n, in->part ? "regions" : "patches", r->nlayers, r->family, r->alpha,
            r->alpha_each, r->crit, tr->spp - 1);
    fprintf(fp, "  z = (radiosity - trace) / se;  z_excess = max(0, |radiosity - trace| - tol) / se, skew-corrected "
                "(Hall),  tol = %g x discretisation estimate%s\n",
            in->tol_scale, in->rtol > 0 ? " + rtol |radiosity|" : "");
    fprintf(fp, "  %-6s %12s %12s\n", "layer", "within", "worst z_exc");
    for (int l = 0; l < r->nlayers; l++)
        fprintf(fp, "  %-6s %11.2f%% %12.3f\n", bn_layer_name(l, tr->bounces, name, sizeof name),
                100.0 * (double)r->layer_within[l] / (double)(n * 3), r->layer_worst_z[l]);
    fprintf(fp, "  all    %11.2f%% %12.3f   (without the discretisation allowance: %.2f%% within, worst |z| %.3f)\n",
            100.0 * (double)r->within / (double)r->family, r->worst_z, 100.0 * (double)r->within_raw / (double)r->family,
            r->worst_z_raw);
    fprintf(fp, "  %zu entr%s with fewer than %.0f effective nonzero samples %s shown, not judged one by one (the normal "
                "tail does not hold there; the power test below covers their light)\n",
            r->few_hits, r->few_hits == 1 ? "y" : "ies", BN__MIN_HITS, r->few_hits == 1 ? "is" : "are");
}

/* The worst entries, and with a partition where the regions they name are. */
static void bn__print_worst(const bn_crosscheck_input *in, const bn_crosscheck_result *r, FILE *fp)
{
    const bn_patch *patches = bn_scene_patches(in->scene, NULL);
    const bn_material *mats = bn_scene_materials(in->scene, NULL);
    char name[16];
    if (r->nworst <= 0)
        return;
    fprintf(fp, "\nworst entries:\n  %7s %6s %-6s %2s %13s %13s %11s %11s %9s %9s\n", in->part ? "region" : "patch",
            in->part ? "mat" : "face", "layer", "ch", "radiosity", "trace", "se", "tol", "z", "z_excess");
    for (int k = 0; k < r->nworst; k++) {
        const bn_crosscheck_entry *e = &r->worst[k];
        fprintf(fp, "  %7zu %6zu %-6s %2c %13.6g %13.6g %11.4g %11.4g %9.3f %9.3f\n", e->patch,
                in->part ? (size_t)in->part->material[e->patch] : patches[e->patch].face,
                bn_layer_name(e->layer, in->trace->bounces, name, sizeof name), bn__ch[e->channel], e->radiosity,
                e->trace, e->se, e->tol, e->z, e->z_excess);
    }
    if (!in->part)
        return;
    fprintf(fp, "\nregions above: %7s %-12s %12s %12s %12s %12s\n", "region", "material", "area", "cx", "cy", "cz");
    for (int k = 0; k < r->nworst; k++) {
        size_t g = r->worst[k].patch;
        int seen = 0;
        for (int q = 0; q < k; q++)
            seen |= r->worst[q].patch == g;
        if (!seen)
            fprintf(fp, "               %7zu %-12s %12.6g %12.6g %12.6g %12.6g\n", g, mats[in->part->material[g]].name,
                    in->part->area[g], in->part->centroid[3 * g], in->part->centroid[3 * g + 1],
                    in->part->centroid[3 * g + 2]);
    }
}

/* Power per layer, radiosity against the tracer, and the power test's bound. */
static void bn__print_power(const bn_crosscheck_input *in, const bn_crosscheck_result *r, FILE *fp)
{
    char name[16];
    fprintf(fp, "\npower per layer, pi sum_i A_i L_i (W; R G B), radiosity | trace +- se | (rad - trace)/se | tol:\n");
    for (int l = 0; l < r->nlayers; l++) {
        const double *a = r->power_rad + 3 * l, *b = r->power_pt + 3 * l, *s = r->power_se + 3 * l,
                     *t = r->power_tol + 3 * l;
        fprintf(fp, "  %-5s %11.5g %11.5g %11.5g | %11.5g %11.5g %11.5g +- %9.3g %9.3g %9.3g | %7.2f %7.2f %7.2f | "
                    "%8.3g %8.3g %8.3g\n",
                bn_layer_name(l, in->trace->bounces, name, sizeof name), a[0], a[1], a[2], b[0], b[1], b[2], s[0],
                s[1], s[2], s[0] > 0 ? (a[0] - b[0]) / s[0] : 0.0, s[1] > 0 ? (a[1] - b[1]) / s[1] : 0.0,
                s[2] > 0 ? (a[2] - b[2]) / s[2] : 0.0, t[0], t[1], t[2]);
    }
    fprintf(fp, "  power test: %zu tests, bound %.3f (normal, Sidak), worst z_excess %.3f\n", r->power_family,
            r->power_crit, r->power_worst_z);
}

/* Area-weighted L per surface (material), radiosity against the tracer. */
static void bn__print_surfaces(const bn_crosscheck_input *in, const bn_crosscheck_result *r, FILE *fp)
{
    const bn_material *mats = bn_scene_materials(in->scene, NULL);
    fprintf(fp, "\nper surface (material), area-weighted L (W m^-2 sr^-1; R G B), radiosity | trace +- se | "
                "relative difference:\n");
    for (size_t s = 0; s < r->nsurfaces; s++) {
        const double *a = r->surf_rad + 3 * s, *b = r->surf_pt + 3 * s, *e = r->surf_se + 3 * s;
        if (r->surf_area[s] <= 0)
            continue;
        fprintf(fp, "  %-12s %9.4g m2 | %10.5g %10.5g %10.5g | %10.5g %10.5g %10.5g +- %8.2g %8.2g %8.2g | %+7.3f%% "
                    "%+7.3f%% %+7.3f%%\n",
                mats[s].name, r->surf_area[s], a[0], a[1], a[2], b[0], b[1], b[2], e[0], e[1], e[2],
                b[0] != 0 ? 100 * (a[0] - b[0]) / b[0] : 0.0, b[1] != 0 ? 100 * (a[1] - b[1]) / b[1] : 0.0,
                b[2] != 0 ? 100 * (a[2] - b[2]) / b[2] : 0.0);
    }
}

void bn_crosscheck_print(const bn_crosscheck_input *in, const bn_crosscheck_result *r, FILE *fp)
{
    bn__print_layers(in, r, fp);
    bn__print_worst(in, r, fp);
    bn__print_power(in, r, fp);
    bn__print_surfaces(in, r, fp);
    fprintf(fp, "\nverdict: %s alpha=%g family=%zu crit=%.4f within=%zu/%zu worst_z=%.4f worst_z_raw=%.4f "
                "tol_scale=%g rtol=%g power_family=%zu power_crit=%.4f power_worst_z=%.4f spp=%zu bounces=%d few_hits=%zu\n",
            r->pass ? "pass" : "fail", r->alpha, r->family, r->crit, r->within, r->family, r->worst_z, r->worst_z_raw,
            in->tol_scale, in->rtol, r->power_family, r->power_crit, r->power_worst_z, in->trace->spp,
            in->trace->bounces, r->few_hits);
}
