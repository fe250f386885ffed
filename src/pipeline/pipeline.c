/* The stages from a scene file to a solved result (include/bounce/pipeline.h): load and mesh;
 * ray scene and K; E, solve, terms and rest. Each stage is timed; nothing here knows how K is
 * stored. */
#include "bounce/pipeline.h"
#include "base/internal.h"
#include "base/vec.h"
#include "bounce/dist.h"

#include <math.h>
#include <string.h>
#include <threads.h>

void bn_pipeline_opts_default(bn_pipeline_opts *o)
{
    memset(o, 0, sizeof *o);
    bn_load_opts_default(&o->load);
    bn_mesh_opts_default(&o->mesh);
    bn_formfactor_opts_default(&o->ff);
    bn_solve_opts_default(&o->solve);
    bn_hierarchy_opts_default(&o->hier);
    o->tie_threshold = 1;
    o->auto_precision = 1;
    o->row_sum_rays = 256;
}

/* Float storage rounds each F_ij by 2^-24; the solve amplifies that by up to 1 / (1 - rho_max)
 * (rho_max the largest reflectance): above the requested tolerance, F is kept in double. */
static bn_precision bn__precision_by_need(const bn_pipeline_opts *o, const bn_scene *s, double *amplified)
{
    size_t nm;
    const bn_material *m = bn_scene_materials(s, &nm);
    double rho = 0;
    for (size_t k = 0; k < nm; k++)
        for (int c = 0; c < 3; c++)
            rho = fmax(rho, m[k].rho[c]);
    *amplified = rho < 1 ? bn_precision_epsilon(BN_PRECISION_FLOAT) / (1 - rho) : INFINITY;
    return *amplified > o->solve.tol ? BN_PRECISION_DOUBLE : o->ff.precision;
}

bn_status bn_pipeline_opts_check(const bn_pipeline_opts *o, bn_error *err)
{
    const bn_mesh_opts *m = &o->mesh;
    if (o->threads < 0 || o->ff.threads < 0 || o->hier.threads < 0)
        return bn_error_set(err, BN_EUSAGE, "threads %d is negative (0: all cores)",
                            o->threads < 0 ? o->threads : o->ff.threads < 0 ? o->ff.threads : o->hier.threads);
    if (!(m->patch_size >= 0 && isfinite(m->patch_size)))
        return bn_error_set(err, BN_EUSAGE, "patch_size %g is not a finite length >= 0 (0: from patches)", m->patch_size);
    if (m->target_patches > BN_PIPELINE_MAX_PATCHES)
        return bn_error_set(err, BN_EUSAGE, "patches %zu is above %.0e: not a patch count bounce can mesh (a negative "
                            "number converted to an unsigned one?)", m->target_patches, (double)BN_PIPELINE_MAX_PATCHES);
    if (!(o->hier.eps >= 0 && isfinite(o->hier.eps)))
        return bn_error_set(err, BN_EUSAGE, "eps %g is not a finite tolerance >= 0", o->hier.eps);
    if (o->ff.storage && !bn_storage_exists(o->ff.storage))
        return bn_error_set(err, BN_EUSAGE, "unknown storage '%s' (one of %s)", o->ff.storage, bn_storage_names());
    if (o->transport && !bn_pipeline_transport_exists(o->transport))
        return bn_error_set(err, BN_EUSAGE, "transport '%s' is not one of %s", o->transport, bn_pipeline_transports());
    return bn_solve_opts_check(&o->solve, err);
}

/* The per-bounce terms, L, rest and E: (bounces + 4) vectors of N x 3 doubles, refused above the
 * memory limit once the patch count is known, before K is built. */
static bn_status bn__check_terms_memory(const bn_pipeline_opts *o, size_t n, bn_error *err)
{
    size_t limit = o->ff.max_memory ? o->ff.max_memory : bn_memory_limit_default(), vec, need;
    size_t nvec = (size_t)(o->solve.bounces < 0 ? 0 : o->solve.bounces) + 4;
    if (!bn__mul_size(n, 3 * sizeof(double), &vec) || !bn__mul_size(vec, nvec, &need) || need > limit)
        return bn_error_set(err, BN_ENOMEM, "%zu bounce terms of %zu patches need %.3g GiB, above the limit of %.3g "
                            "GiB (`max_memory`): keep fewer `bounces` (the rest is summed in rest) or fewer patches",
                            nvec - 3, n, (double)nvec * (double)n * 24 / (1 << 30), (double)limit / (1 << 30));
    return BN_OK;
}

/* A transport given as "dense" (or "sparse"), not "auto", "hierarchical" or unset (a caller that only
 * meshes, as `bounce info`, or builds K itself later): its storage is fixed. */
static const char *bn__fixed_storage(const bn_pipeline_opts *o)
{
    if (!o->transport)
        return NULL;
    if (!strcmp(o->transport, "auto") || !strcmp(o->transport, "hierarchical"))
        return NULL;
    return o->transport;
}

/* A mesh whose F cannot fit is refused from the faces' sizes, before meshing (which takes seconds
 * for a million patches). */
static bn_status bn__check_size_early(const bn_pipeline_opts *o, const bn_scene *s, bn_error *err)
{
    bn_formfactor_opts fo = o->ff;
    double n;
    bn_status st;
    if (!(fo.storage = bn__fixed_storage(o)) || bn_dist_size() > 1)
        return BN_OK;
    st = bn_scene_mesh_estimate(s, &o->mesh, &n, err);
    return st == BN_OK ? bn_formfactor_check_memory(n, &fo, err) : st;
}

bn_status bn_pipeline_scene(const char *path, const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    double t0 = bn__now();
    bn_status st;
    memset(p, 0, sizeof *p);
    if ((st = bn_pipeline_opts_check(o, err)) != BN_OK)
        return st;
    st = bn_scene_load(path, &o->load, &p->scene, err);
    p->seconds_load = bn__now() - t0;
    t0 = bn__now();
    if (st == BN_OK)
        st = bn__check_size_early(o, p->scene, err);
    if (st == BN_OK) {
        /* a default mesh may be redone for the hierarchy: the first one then only counts, without
         * the contact cuts (seconds on a million polygons) */
        bn_mesh_opts m0 = o->mesh;
        m0.no_contacts |= o->mesh_auto;
        st = bn_scene_mesh(p->scene, &m0, err);
    }
    if (st == BN_OK && o->mesh_auto) {
        size_t n;
        bn_scene_patches(p->scene, &n);
        if (bn_pipeline_use_hierarchy(o, n, NULL, 0)) {
            bn_mesh_opts m = o->mesh;
            m.patch_size = 0;
            m.no_subdivide = 0;
            m.target_patches = BN_HIERARCHY_EXTRA_PATCHES;   /* on the faces it splits; the rest stay whole */
            st = bn_scene_mesh(p->scene, &m, err);
        } else if (!o->mesh.no_contacts) {
            st = bn_scene_mesh(p->scene, &o->mesh, err);
        }
    }
    p->seconds_mesh = bn__now() - t0;
    if (st == BN_OK) {
        size_t n;
        bn_scene_patches(p->scene, &n);
        st = bn__check_terms_memory(o, n, err);
    }
    if (st == BN_OK) {
        bn_scene_stats ss = bn_scene_stats_get(p->scene);
        if (ss.contact_faces > 0)
            bn_logf(&o->load.log, BN_LOG_INFO,
                    "contact lines: %zu segments on %zu face%s split %zu patches into %zu (`no_contacts`: off)",
                    ss.contact_segments, ss.contact_faces, ss.contact_faces == 1 ? "" : "s", ss.contact_patches_split,
                    ss.contact_patches_made);
    }
    if (st != BN_OK) {
        bn_scene_destroy(p->scene);
        p->scene = NULL;
        return st;
    }
    bn_scene_patches(p->scene, &p->n);
    return BN_OK;
}

/* The transports: auto, every storage of src/transport's registry, and the hierarchy. */
static char bn__transport_list[128];
static void bn__transport_list_make(void)
{
    snprintf(bn__transport_list, sizeof bn__transport_list, "auto|%s|hierarchical", bn_storage_names());
}

const char *bn_pipeline_transports(void)
{
    static once_flag once = ONCE_FLAG_INIT;
    call_once(&once, bn__transport_list_make);
    return bn__transport_list;
}

int bn_pipeline_transport_exists(const char *name)
{
    return name && (!strcmp(name, "auto") || !strcmp(name, "hierarchical") || bn_storage_exists(name));
}

int bn_pipeline_use_hierarchy(const bn_pipeline_opts *o, size_t n, char *why, size_t why_size)
{
    const char *t = o->transport;
    char tmp[8];
    if (!why) {
        why = tmp;
        why_size = sizeof tmp;
    }
    why[0] = 0;
    if (t && !strcmp(t, "hierarchical")) {
        snprintf(why, why_size, "asked for");
        return 1;
    }
    if (!t || strcmp(t, "auto"))
        return 0;
    size_t limit = o->ff.max_memory ? o->ff.max_memory : bn_memory_limit_default();
    size_t dense = bn_storage_bytes("dense", n, 0, o->ff.precision);
    if (dense == SIZE_MAX || dense > limit) {
        snprintf(why, why_size, "dense F of %zu patches would need %.3g GiB, above the %.3g GiB limit", n,
                 dense == SIZE_MAX ? INFINITY : (double)dense / (1 << 30), (double)limit / (1 << 30));
        return 1;
    }
    if (n > BN_AUTO_HIERARCHY_PATCHES) {
        snprintf(why, why_size, "%zu patches: above %d, every pair's form factor takes longer than the hierarchy", n,
                 BN_AUTO_HIERARCHY_PATCHES);
        return 1;
    }
    snprintf(why, why_size, "%zu patches: at most %d, every pair's form factor is affordable", n,
             BN_AUTO_HIERARCHY_PATCHES);
    return 0;
}

/* y = F 1: the row sums of F, per patch and channel (3n, allocated). */
static bn_status bn__row_sums(const bn_pipeline *p, double **y, bn_error *err)
{
    size_t n = p->n;
    double *one = bn__malloc_array(3 * n, sizeof(double));
    bn_status st = BN_OK;
    *y = bn__malloc_array(3 * n, sizeof(double));
    if (!one || !*y)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for %zu patches", n);
    for (size_t k = 0; st == BN_OK && k < 3 * n; k++)
        one[k] = 1;
    if (st == BN_OK)
        st = bn_transport_apply_F(p->k, one, *y, err);
    free(one);
    if (st != BN_OK) {
        free(*y);
        *y = NULL;
    }
    return st;
}

/* The hierarchy's report in the form-factor diagnostics the rest of the pipeline reads: row sums
 * of F_H (y = F_H 1) and ||K_H||_inf. */
static void bn__hierarchy_diag(bn_pipeline *p, const double *y)
{
    size_t n = p->n;
    const double *rho = bn_transport_rho(p->k);
    bn_ff_diagnostics *d = &p->ff;
    double ss = 0;
    memset(d, 0, sizeof *d);
    d->n = n;
    d->row_sum_min = INFINITY;
    d->row_sum_max = -INFINITY;
    for (size_t i = 0; i < n; i++) {
        double r = y[3 * i];
        d->row_sum_min = fmin(d->row_sum_min, r);
        d->row_sum_max = fmax(d->row_sum_max, r);
        ss += (r - 1) * (r - 1);
        for (int c = 0; c < 3; c++)
            d->k_norm_inf = fmax(d->k_norm_inf, rho[3 * i + c] * r);
    }
    d->row_sum_rms_dev = n ? sqrt(ss / (double)n) : 0;
    d->nonzeros = p->hier.links;
    d->rays = p->hier.rays;
    d->bytes = bn_transport_bytes(p->k);
    d->seconds = p->hier.seconds_tree + p->hier.seconds_refine;
    d->rays_per_second = d->seconds > 0 ? (double)d->rays / d->seconds : 0;
}

/* The variance of an escape term w (1 - e) estimated from `rays` rays: binomial, p (1 - p) / rays
 * (stratified rays do better: an upper bound). */
static double bn__escape_var(double w, double e, int rays)
{
    double q = fmin(fmax(1 - e, 0.0), 1.0);
    return rays > 0 ? w * w * q * (1 - q) / rays : 0;
}

/* sum_j A_j (1 - e_j) L_j, the light leaving the patches that does not reach a surface (escaping, or
 * meeting a back): the emitters' own (they dominate it) from their exact sums by many rays, and the
 * rest from the checked rows (every stride-th patch), scaled by the stride. Per channel, scene units;
 * var: its variance (the rays', and with a stride > 1 the unchecked rows', as a random sample's). */
static void bn__escaping(const bn_pipeline *p, double esc[3], double var[3])
{
    const bn_patch *pa = bn_scene_patches(p->scene, &(size_t){0});
    double s = (double)p->rows.stride, sum[3] = {0, 0, 0}, sq[3] = {0, 0, 0};
    size_t m = 0;
    for (int c = 0; c < 3; c++)
        esc[c] = var[c] = 0;
    for (size_t k = 0; k < p->nemit; k++) {
        size_t j = p->emit_patch[k];
        for (int c = 0; c < 3; c++) {
            esc[c] += pa[j].area * (1 - p->emit_exact[k]) * p->res.L[3 * j + c];
            var[c] += bn__escape_var(pa[j].area * p->res.L[3 * j + c], p->emit_exact[k], p->emit_rays);
        }
    }
    for (size_t k = 0, e = 0; k < p->rows.rows; k++) {
        size_t j = k * p->rows.stride;
        while (e < p->nemit && p->emit_patch[e] < j)   /* both ascending: walked together */
            e++;
        if (e < p->nemit && p->emit_patch[e] == j)   /* an emitter: counted above */
            continue;
        m++;
        for (int c = 0; c < 3; c++) {
            double x = pa[j].area * (1 - p->row_exact[k]) * p->res.L[3 * j + c];
            esc[c] += s * x;
            var[c] += bn__escape_var(s * pa[j].area * p->res.L[3 * j + c], p->row_exact[k], p->rows.rays);
            sum[c] += x;
            sq[c] += x * x;
        }
    }
    for (int c = 0; c < 3 && s > 1 && m > 1; c++)   /* N^2 (1 - n/N) s^2 / n with N = stride n */
        var[c] += s * s * (double)m * (1 - 1 / s) * fmax(0.0, sq[c] - sum[c] * sum[c] / (double)m) / (double)(m - 1);
}

/* The emitting patches' exact row sums, by rays enough that their noise does not show in the
 * balance (they carry most of the light that escapes): 4e6 rays over them, 256 to 16384 each. */
static bn_status bn__emitters_exact(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    size_t nm;
    const bn_material *mat = bn_scene_materials(p->scene, &nm);
    const bn_patch *pa = bn_scene_patches(p->scene, &(size_t){0});
    p->nemit = 0;
    for (size_t j = 0; j < p->n; j++)
        p->nemit += mat[pa[j].material].Le[0] + mat[pa[j].material].Le[1] + mat[pa[j].material].Le[2] > 0;
    free(p->emit_patch);
    free(p->emit_exact);
    p->emit_patch = bn__malloc_array(p->nemit + 1, sizeof(size_t));
    p->emit_exact = bn__malloc_array(p->nemit + 1, sizeof(double));
    if (!p->emit_patch || !p->emit_exact)
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu emitting patches", p->nemit);
    int rays = p->nemit ? (int)fmin(16384, fmax(256, 4e6 / (double)p->nemit)) : 0;
    p->emit_rays = rays;
    size_t k = 0;
    for (size_t j = 0; j < p->n; j++)
        if (mat[pa[j].material].Le[0] + mat[pa[j].material].Le[1] + mat[pa[j].material].Le[2] > 0)
            p->emit_patch[k++] = j;
    long ln = (long)p->nemit;
#pragma omp parallel for schedule(dynamic, 1) num_threads(bn_threads_resolve(o->threads))
    for (long q = 0; q < ln; q++)
        p->emit_exact[q] = bn_ff_row_sum_exact(p->scene, p->rt, p->emit_patch[q], rays, rays,
                                               o->ff.seed ^ 0x657363617065ULL, NULL);
    return BN_OK;
}

/* F's row sums against the exact ones (bn_ff_row_sum_check), said in a note, and a warning when
 * more than 1% of the rows are off by more than 1% or any by more than 5%: light made or lost. */
static bn_status bn__row_sum_check(const bn_pipeline_opts *o, bn_pipeline *p, const double *y, bn_error *err)
{
    bn_row_sum_check *c = &p->rows;
    double *rs = bn__malloc_array(p->n ? p->n : 1, sizeof(double));
    bn_status st = rs ? BN_OK : bn_error_set(err, BN_ENOMEM, "out of memory for %zu row sums", p->n);
    free(p->row_exact);
    if (st == BN_OK && !(p->row_exact = bn__malloc_array(BN_PIPELINE_ROW_SUM_ROWS, sizeof(double))))
        st = bn_error_set(err, BN_ENOMEM, "out of memory for %d row sums", BN_PIPELINE_ROW_SUM_ROWS);
    for (size_t i = 0; st == BN_OK && i < p->n; i++)
        rs[i] = y[3 * i];
    if (st == BN_OK)
        st = bn_ff_row_sum_check(p->scene, p->rt, rs, BN_PIPELINE_ROW_SUM_ROWS, o->row_sum_rays, o->ff.seed ^ 0x636865636bULL,
                                 o->threads, c, p->row_exact, err);
    free(rs);
    if (st == BN_OK)
        st = bn__emitters_exact(o, p, err);
    if (st != BN_OK || c->rows == 0)
        return st;
    bn_logf(&o->solve.log_sink, BN_LOG_INFO,
            "F row sums against the exact (%zu rows x %d rays, %zu closed): sum - exact %+.2g%% at the 1st "
            "percentile, %+.2g%% median, %+.2g%% at the 99th, %+.2g%% worst (patch %zu); %.1f%% of rows within 1%%",
            c->rows, c->rays, c->closed, 100 * c->dev_p01, 100 * c->dev_p50, 100 * c->dev_p99, 100 * c->dev_max,
            c->worst_row, 100 * c->within_1pct);
    /* the hierarchy's rows are off by design where the light is dim (doc/hierarchy.md): its measure
     * is the energy balance after the solve; for F made pair by pair an off row is a broken F */
    if (!p->hierarchical && (c->within_1pct < 0.99 || c->above_5pct > 0))
        bn_warnf(&o->solve.log_sink, BN_W_ROW_SUM, c->dev_max,
                 "F's row sums are off the exact ones: %.1f%% of %zu rows within 1%%, %zu above +5%% (worst %+.3g at "
                 "patch %zu): the %s operator %s light",
                 100 * c->within_1pct, c->rows, c->above_5pct, c->dev_max, c->worst_row, bn_transport_name(p->k),
                 c->dev_p50 < 0 ? "loses" : "makes");
    return BN_OK;
}

/* After K: the hierarchy's diagnostics and the row-sum check, each from y = F 1. */
static bn_status bn__operator_checks(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    double *y = NULL;
    bn_status st;
    if (!p->hierarchical && (o->row_sum_rays <= 0 || !p->rt))
        return BN_OK;
    st = bn__row_sums(p, &y, err);
    if (st == BN_OK && p->hierarchical)
        bn__hierarchy_diag(p, y);
    if (st == BN_OK && o->row_sum_rays > 0 && p->rt)
        st = bn__row_sum_check(o, p, y, err);
    free(y);
    return st;
}

/* The punctual lights' share of bounce 1 for the scene's reflectances: D = rho x D_white. */
static bn_status bn__direct(bn_pipeline *p, bn_error *err)
{
    if (!p->D_white)
        return BN_OK;
    if (!p->D && !(p->D = bn__malloc_array(3 * p->n + 1, sizeof(double))))
        return bn_error_set(err, BN_ENOMEM, "out of memory for the punctual lights' light on %zu patches", p->n);
    bn_scene_patch_reflectance(p->scene, p->D);
    for (size_t k = 0; k < 3 * p->n; k++)
        p->D[k] *= p->D_white[k];
    return BN_OK;
}

bn_status bn_pipeline_operator(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    bn_formfactor_opts fo = o->ff;
    double t0 = bn__now(), amp;
    char why[160];
    p->hierarchical = bn_pipeline_use_hierarchy(o, p->n, why, sizeof why);
    if (bn_dist_size() > 1 && !p->hierarchical) {   /* dense and sparse K are single-process */
        if (o->transport && strcmp(o->transport, "auto"))
            return bn_error_set(err, BN_EUSAGE,
                                "`transport` %s is single-process: under mpirun -np %d use `transport` hierarchical "
                                "(auto picks it there)", o->transport, bn_dist_size());
        p->hierarchical = 1;
        snprintf(why, sizeof why, "%d MPI processes: dense and sparse K are single-process", bn_dist_size());
    }
    if (o->transport && !strcmp(o->transport, "auto"))
        bn_logf(&o->solve.log_sink, BN_LOG_INFO, "transport: %s (%s)", p->hierarchical ? "hierarchical" : "dense",
                why);
    if (o->transport && strcmp(o->transport, "auto") && strcmp(o->transport, "hierarchical"))
        fo.storage = o->transport;
    if (!p->hierarchical && o->auto_precision && fo.precision != bn__precision_by_need(o, p->scene, &amp)) {
        fo.precision = BN_PRECISION_DOUBLE;
        bn_logf(&o->solve.log_sink, BN_LOG_INFO,
                "F stored in double: float's rounding (2^-24) amplified by 1 / (1 - rho_max) is %.2g, above the "
                "tolerance %g (`precision` float keeps float)", amp, o->solve.tol);
    }
    bn_status st = bn_rt_create(p->scene, o->threads, &p->rt, err);
    if (st == BN_OK && !p->D_white)
        st = bn_punctual_direct(p->scene, p->rt, o->threads, &p->D_white, err);
    if (st == BN_OK)
        st = bn__direct(p, err);
    if (!fo.threads)
        fo.threads = o->threads;
    if (st == BN_OK && p->hierarchical) {
        bn_hierarchy_opts ho = o->hier;
        ho.ff = fo;
        ho.ff.cache_path = NULL;
        if (!ho.threads)
            ho.threads = fo.threads;
        if (!ho.max_memory)
            ho.max_memory = fo.max_memory;
        ho.quiet = ho.quiet || fo.quiet;
        ho.direct = p->D;
        if (!ho.log.fn)
            ho.log = fo.log;
        st = bn_hierarchy_build(p->scene, p->rt, &ho, &p->k, &p->hier, err);
    } else if (st == BN_OK) {
        st = bn_formfactor_build(p->scene, p->rt, &fo, &p->k, &p->ff, err);
    }
    p->seconds_operator = bn__now() - t0;   /* K itself: the checks below are not its time */
    if (st == BN_OK)
        st = bn__operator_checks(o, p, err);
    if (st != BN_OK || !o->keep_rt) {
        bn_rt_destroy(p->rt);
        p->rt = NULL;
    }
    return st;
}

bn_solve_method bn_pipeline_method(const bn_pipeline_opts *o, const bn_pipeline *p)
{
    if (o->method_auto && p->k && !bn_solve_method_runs_on(o->solve.method, p->k))
        return BN_SOLVE_JACOBI;   /* auto's Gauss-Seidel on an operator without rows (the hierarchy) */
    return o->solve.method;
}

/* The energy balance (bn_pipeline.balance): F L against the light leaving towards surfaces, each
 * in watts. */
/* The power the source puts out: the emission, and the punctual lights' light where it first leaves a
 * surface (pi sum A (E + D)). */
static void bn__source_power(const bn_pipeline *p, double w[3])
{
    double d[3] = {0, 0, 0};
    bn_scene_power(p->scene, p->E, w);
    if (p->D)
        bn_scene_power(p->scene, p->D, d);
    for (int c = 0; c < 3; c++)
        w[c] += d[c];
}

static bn_status bn__energy_balance(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    const bn_patch *pa = bn_scene_patches(p->scene, &(size_t){0});
    double m = bn_unit_to_metres(bn_scene_unit(p->scene)), *y = bn__malloc_array(3 * p->n + 1, sizeof(double));
    double towards[3] = {0, 0, 0}, arriving[3] = {0, 0, 0}, escape[3] = {0, 0, 0}, var[3] = {0, 0, 0};
    bn_status st = y ? bn_transport_apply_F(p->k, p->res.L, y, err) : bn_error_set(err, BN_ENOMEM, "out of memory");
    for (size_t i = 0; st == BN_OK && i < p->n; i++)
        for (int c = 0; c < 3; c++) {
            arriving[c] += BN_PI * pa[i].area * m * m * y[3 * i + c];
            towards[c] += BN_PI * pa[i].area * m * m * p->res.L[3 * i + c];
        }
    if (st == BN_OK) {
        bn__escaping(p, escape, var);
        for (int c = 0; c < 3; c++) {
            escape[c] *= BN_PI * m * m;
            var[c] *= (BN_PI * m * m) * (BN_PI * m * m);
        }
    }
    free(y);
    if (st != BN_OK)
        return st;
    bn__source_power(p, p->power_emitted);
    for (int c = 0; c < 3; c++) {
        p->power_arriving[c] = arriving[c];
        p->power_towards[c] = towards[c] - escape[c];
        p->balance[c] = p->power_emitted[c] > 0 ? (arriving[c] - p->power_towards[c]) / p->power_emitted[c] : 0;
        p->balance_se[c] = p->power_emitted[c] > 0 ? sqrt(var[c]) / p->power_emitted[c] : 0;
    }
    bn_logf(&o->solve.log_sink, BN_LOG_INFO,
            "energy balance: light arriving at surfaces %+.2g%% %+.2g%% %+.2g%% of the emitted power against what leaves "
            "them towards surfaces, +- %.2g%% (the escape rays' standard error; 0 for any exact F; + the %s operator "
            "makes light, - it loses it)", 100 * p->balance[0], 100 * p->balance[1], 100 * p->balance[2],
            100 * fmax(p->balance_se[0], fmax(p->balance_se[1], p->balance_se[2])), bn_transport_name(p->k));
    double worst = 0;   /* beyond its noise: by more than 1% and more than 3 standard errors */
    for (int c = 0; c < 3; c++)
        if (fabs(p->balance[c]) > 3 * p->balance_se[c])
            worst = fmax(worst, fabs(p->balance[c]));
    if (worst > 0.01)
        bn_warnf(&o->solve.log_sink, BN_W_BALANCE, worst,
                 "the %s operator %s %.2g%% of the emitted light (energy balance; doc/hierarchy.md)",
                 bn_transport_name(p->k), p->balance[0] + p->balance[1] + p->balance[2] > 0 ? "makes" : "loses",
                 100 * worst);
    return BN_OK;
}

bn_status bn_pipeline_solve(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    bn_solve_opts so = o->solve;
    double t0 = bn__now();
    if (!so.threads)
        so.threads = o->threads;
    bn_status st;
    if (!p->E) {   /* the patches' emission (a caller that loaded the scene may have made it already) */
        p->E = bn__malloc_array(p->n ? 3 * p->n : 1, sizeof(double));
        if (!p->E)
            return bn_error_set(err, BN_ENOMEM, "out of memory for the emission of %zu patches", p->n);
        bn_scene_patch_emission(p->scene, p->E);
    }
    /* The hierarchy's row sums carry the sampling noise of its links (reported, not a sign of a
     * singular system): its singularity check rests on the spectral radius alone. */
    if (o->tie_threshold && !p->hierarchical && p->ff.row_sum_max - 1.0 > so.singular_threshold) {
        bn_logf(&so.log_sink, BN_LOG_INFO,
                "F's rows sum up to %.9g: singular threshold raised from %g to %.3g (F's measured row-sum error)",
                p->ff.row_sum_max, so.singular_threshold, p->ff.row_sum_max - 1.0);
        so.singular_threshold = p->ff.row_sum_max - 1.0;
    }
    p->singular_threshold = so.singular_threshold;
    if (so.method != bn_pipeline_method(o, p)) {
        so.method = bn_pipeline_method(o, p);
        bn_logf(&so.log_sink, BN_LOG_INFO, "solver: %s (K is %s, which keeps no rows for gauss-seidel)",
                bn_solve_method_name(so.method), bn_transport_name(p->k));
    }
    p->method_used = so.method;
    so.direct = p->D;
    if (!p->power && !(p->power = bn__calloc(3 * p->n + 1, sizeof(double))))
        return bn_error_set(err, BN_ENOMEM, "out of memory for the power iteration of %zu patches", p->n);
    so.power_start = p->power;   /* a relight's solve starts where the last one ended */
    st = bn_solve(p->k, p->E, &so, &p->res, err);
    if ((st == BN_OK || st == BN_ENOTCONV) && p->res.nterms > 0) {
        p->rest = bn__malloc_array(3 * p->n + 1, sizeof(double));
        if (!p->rest)
            st = bn_error_set(err, BN_ENOMEM, "out of memory for rest");
        else
            bn_layers_rest((const double *const *)p->res.terms, p->res.nterms, p->res.L, 3 * p->n, p->rest);
    }
    if (st == BN_OK && p->rows.rows > 0 && p->scene && p->k)
        st = bn__energy_balance(o, p, err);
    p->seconds_solve = bn__now() - t0;
    return st;
}

bn_status bn_pipeline_run(const char *path, const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    bn_status st = bn_pipeline_scene(path, o, p, err);
    if (st == BN_OK)
        st = bn_pipeline_operator(o, p, err);
    if (st == BN_OK)
        st = bn_pipeline_solve(o, p, err);
    return st;
}

/* ---- relighting: new materials on the same F ---- */

/* The largest ratio of new to old radiance over patches and channels (the old L's values below a
 * millionth of its largest read as that floor), and where. */
static double bn__gain(const double *L0, const double *L1, size_t n, size_t *at)
{
    double top = 0, gain = 0;
    for (size_t k = 0; k < 3 * n; k++)
        top = fmax(top, L0[k]);
    *at = 0;
    for (size_t k = 0; k < 3 * n && top > 0; k++) {
        double g = L1[k] / fmax(L0[k], 1e-6 * top);
        if (g > gain) {
            gain = g;
            *at = k / 3;
        }
    }
    return gain;
}

/* Under frozen links: what the old refinement means for the new answer, said in a note. */
static void bn__relight_note(const bn_pipeline_opts *o, bn_pipeline *p, const double *L0)
{
    size_t at = 0;
    p->relight_gain = L0 && p->res.L ? bn__gain(L0, p->res.L, p->n, &at) : 0;
    if (!p->hierarchical || !L0)
        return;
    bn_logf(&o->solve.log_sink, BN_LOG_INFO,
            "relit on the hierarchy's links as refined for the old light: each link's error was held to eps (%.3g "
            "absolute) for the old brightness; the new L is up to %.3g times the old (patch %zu), and where it is "
            "brighter the links' error may be as much larger (relight with refine, Python's relight(refine=True), "
            "builds links for the new light)", p->hier.eps_abs, p->relight_gain, at);
}

bn_status bn_pipeline_relight(const bn_pipeline_opts *o, bn_pipeline *p, const bn_material_edit *e, size_t n,
                              int refine, bn_error *err)
{
    double t0 = bn__now(), *rho = NULL, *L0 = NULL;
    bn_status st;
    int relink = refine && p->hierarchical;
    if (!p->scene || !p->k)
        return bn_error_set(err, BN_EUSAGE, "relight: no solved scene (its operator K is not built)");
    if ((st = bn_scene_edit_materials(p->scene, e, n, err)) != BN_OK)
        return st;
    if (!relink)
        rho = bn__malloc_array(3 * p->n + 1, sizeof *rho);
    if (p->res.L && (L0 = bn__malloc_array(3 * p->n + 1, sizeof *L0)))
        memcpy(L0, p->res.L, 3 * p->n * sizeof *L0);
    if ((!relink && !rho) || (p->res.L && !L0))
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the reflectances of %zu patches", p->n);
    if (st == BN_OK && relink) {   /* new links for the new light (and a new ray scene) */
        bn_transport_destroy(p->k);
        bn_rt_destroy(p->rt);
        p->k = NULL;
        p->rt = NULL;
        st = bn_pipeline_operator(o, p, err);
    } else if (st == BN_OK) {
        bn_scene_patch_reflectance(p->scene, rho);
        st = bn_transport_set_rho(p->k, rho, err);
        if (st == BN_OK)
            st = bn__direct(p, err);
    }
    bn_solve_result_free(&p->res);
    free(p->rest);
    free(p->E);
    p->rest = p->E = NULL;
    if (st == BN_OK) {
        bn_pipeline_opts ro = *o;
        ro.solve.power_lazy = 1;   /* no power steps where ||K|| < 1 already bounds the solve */
        st = bn_pipeline_solve(&ro, p, err);
    }
    if (st == BN_OK || st == BN_ENOTCONV)
        bn__relight_note(o, p, refine ? NULL : L0);
    p->seconds_relight = bn__now() - t0;
    free(rho);
    free(L0);
    return st;
}

void bn_pipeline_free(bn_pipeline *p)
{
    if (!p)
        return;
    bn_solve_result_free(&p->res);
    free(p->rest);
    free(p->E);
    free(p->D);
    free(p->D_white);
    free(p->power);
    free(p->row_exact);
    free(p->emit_patch);
    free(p->emit_exact);
    bn_transport_destroy(p->k);
    bn_rt_destroy(p->rt);
    bn_scene_destroy(p->scene);
    memset(p, 0, sizeof *p);
}

void bn_pipeline_describe_solve(const bn_pipeline_opts *o, const bn_pipeline *p, char *buf, size_t size)
{
    bn_solve_method m = p->res.L ? p->method_used : o->solve.method;
    snprintf(buf, size, "%s%s tol=%g max_iter=%zu: %s after %zu iterations, residual %.3g%s%s",
             bn_solve_method_name(m), o->solve.symmetric && m == BN_SOLVE_GAUSS_SEIDEL ? "-symmetric" : "",
             o->solve.tol, o->solve.max_iter, bn_stop_reason_name(p->res.reason), p->res.iterations,
             p->res.residual_max, p->hierarchical ? "; K: hierarchy, " : "", p->hierarchical ? "" : "");
    if (p->hierarchical) {
        size_t len = strlen(buf);
        snprintf(buf + len, size > len ? size - len : 0,
                 "eps=%g (%.3g absolute), min area %.3g, %zu links, %zu nodes, %zu planes of %zu polygons",
                 o->hier.eps, p->hier.eps_abs, p->hier.min_area, p->hier.links, p->hier.nodes, p->hier.planes,
                 p->hier.polygons);
    }
}
