/* The study driver: for each setting of the varied parameter, mesh -> form factors -> solve (or
 * trace) -> output, timed per phase, with its peak memory, compared against a reference that is
 * more accurate by construction and whose own error is estimated here too.
 *
 * Truncation (bounces): S_n = sum_{k<=n} K^k E against L = (I - K)^-1 E by a direct solve of the
 * identical K; L - S_n = sum_{k>n} K^k E, so ||L - S_n||_inf <= ||K||^(n+1) / (1 - ||K||) ||E||_inf
 * (infinity norms; the geometric a priori bound), and ~ rho(K)^(n+1) / (1 - rho(K)) ||E||_inf. */
#include "study/study_internal.h"
#include "base/internal.h"
#include "bounce/pipeline.h"

#include <ctype.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <string.h>
#include <strings.h>

/* The swept parameters, references and error metrics, each in its enum's order. */
#define BN__PARAMS(X)                                                                                  \
    X("bounces") X("max-iter") X("tol") X("patches") X("patch-size") X("samples") X("ff") X("spp")     \
    X("precision") X("eps")
BN__VOCABULARY(bn_study_param, bn_study_param, BN__PARAMS)
#define BN__REFS(X) X("auto") X("radiosity") X("trace")
BN__VOCABULARY(bn_study_ref, bn_study_ref, BN__REFS)
#define BN__METRICS(X) X("surface") X("patch")
BN__VOCABULARY(bn_study_metric, bn_study_metric, BN__METRICS)

void bn_study_opts_default(bn_study_opts *o)
{
    memset(o, 0, sizeof *o);
    o->param = BN_STUDY_BOUNCES;
    bn_load_opts_default(&o->load);
    bn_mesh_opts_default(&o->mesh);
    bn_formfactor_opts_default(&o->ff);
    o->ff.quiet = 1;
    bn_solve_opts_default(&o->solve);
    o->solve.method = BN_SOLVE_DIRECT;
    bn_hierarchy_opts_default(&o->hier);
    o->solve.quiet = 1;
    bn_trace_opts_default(&o->trace);
    o->trace.quiet = 1;
    o->methods = BN_STUDY_ALL_METHODS;
    o->target = 0.01;
}

/* ---- the run's state ---- */

typedef struct bn__study {
    const bn_study_opts *o;
    const char *path;
    double direct_iterate;   /* the reference direct solve's factorisation and solve alone */
    bn_load_opts load;   /* o->load without its log: the probe load has shown the scene's warnings once */
    bn_study_result *res;
    size_t cap;
} bn__study;

static void bn__note(const bn__study *S, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static void bn__note(const bn__study *S, const char *fmt, ...)
{
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    bn_logf(&S->o->log, BN_LOG_INFO, "%s", buf);
}

static void bn__drop_log(void *user, const bn_message *m)
{
    (void)user;
    (void)m;
}

static bn_study_row *bn__row_new(bn__study *S, const char *method, const char *value, double x, bn_error *err)
{
    bn_study_result *r = S->res;
    bn_study_row *row;
    if (r->nrows == S->cap) {
        size_t cap = S->cap ? 2 * S->cap : 16;
        bn_study_row *p = bn__realloc_array(r->rows, cap, sizeof *p);
        if (!p) {
            bn_error_set(err, BN_ENOMEM, "study: out of memory for %zu rows", cap);
            return NULL;
        }
        r->rows = p;
        S->cap = cap;
    }
    row = &r->rows[r->nrows];
    memset(row, 0, sizeof *row);
    row->err_surface = bn__calloc(r->nsurfaces + 1, sizeof(double));
    if (!row->err_surface) {
        bn_error_set(err, BN_ENOMEM, "study: out of memory for a row");
        return NULL;
    }
    r->nrows++;
    snprintf(row->method, sizeof row->method, "%s", method);
    snprintf(row->value, sizeof row->value, "%s", value);
    row->x = x;
    row->bound = row->bound_ke = row->estimate = NAN;
    row->t_mesh = row->t_ff = row->t_solve = row->t_output = 0;
    row->k_norm = NAN;
    row->se_surface_max = NAN;
    row->t_iterate = NAN;
    return row;
}

static void bn__row_total(bn_study_row *row)
{
    row->t_total = row->t_mesh + row->t_ff + row->t_solve + row->t_output;
}

static bn_study_curve *bn__curve_new(bn__study *S, const char *label, size_t cap, bn_error *err)
{
    bn_study_result *r = S->res;
    bn_study_curve *p = bn__realloc_array(r->curves, r->ncurves + 1, sizeof *p), *c;
    if (!p) {
        bn_error_set(err, BN_ENOMEM, "study: out of memory for a curve");
        return NULL;
    }
    r->curves = p;
    c = &r->curves[r->ncurves];
    memset(c, 0, sizeof *c);
    c->t = bn__malloc_array(cap + 1, sizeof(double));
    c->err = bn__malloc_array(cap + 1, sizeof(double));
    if (!c->t || !c->err) {
        free(c->t);
        free(c->err);
        bn_error_set(err, BN_ENOMEM, "study: out of memory for a curve of %zu points", cap);
        return NULL;
    }
    r->ncurves++;
    snprintf(c->label, sizeof c->label, "%s", label);
    return c;
}

/* The pipeline's first stage with the study's load options and mesh m: *seconds is the meshing
 * time (loading is not part of what a study varies). */
static bn_status bn__scene(bn__study *S, const bn_mesh_opts *m, bn_scene **out, double *seconds, bn_error *err)
{
    bn_pipeline_opts po;
    bn_pipeline p;
    bn_status st;
    bn_pipeline_opts_default(&po);
    po.load = S->load;
    po.mesh = *m;
    st = bn_pipeline_scene(S->path, &po, &p, err);
    *out = p.scene;
    *seconds = p.seconds_mesh;
    return st;
}

/* The pipeline's second stage for a scene the study keeps: K, the ray caster released after the
 * assembly (its time counts as form-factor time). */
static bn_status bn__build_k(const bn_scene *s, const bn_formfactor_opts *ffo, const char *transport,
                             const bn_hierarchy_opts *hier, bn_transport **K, size_t *links, double *seconds,
                             bn_error *err)
{
    bn_pipeline_opts po;
    bn_pipeline p;
    bn_status st;
    bn_pipeline_opts_default(&po);
    po.ff = *ffo;
    po.transport = transport;
    po.row_sum_rays = 0;   /* the study times K's assembly; conservation is the pipeline runs' to say */
    if (hier) {
        po.hier = *hier;
        po.hier.quiet = 1;
    }
    memset(&p, 0, sizeof p);
    p.scene = (bn_scene *)s;   /* borrowed: taken back below */
    bn_scene_patches(s, &p.n);
    st = bn_pipeline_operator(&po, &p, err);
    free(p.row_exact);   /* what the pipeline made beside K (none with row_sum_rays 0) */
    free(p.D);
    free(p.emit_patch);
    free(p.emit_exact);
    *K = p.k;
    if (links)
        *links = p.hierarchical ? p.hier.links : p.ff.nonzeros;
    *seconds = p.seconds_operator;
    return st;
}

/* Solves with method opts; *L is malloc'd (N*3). A solve that stops at the iteration limit is a
 * result (the max-iter study asks for it), not an error. */
static bn_status bn__solve(const bn_transport *K, const double *E, const bn_solve_opts *so, double **L,
                           bn_solve_result *info, double *seconds, bn_error *err)
{
    bn_solve_opts o = *so;
    bn_solve_result res;
    bn_status st;
    double t0 = bn__now();
    memset(&res, 0, sizeof res);
    o.bounces = -1;
    o.quiet = 1;
    o.log = NULL;
    o.log_sink.fn = bn__drop_log;
    if (!bn_solve_method_runs_on(o.method, K)) {
        /* K_H: apply only; converged far below any error measured. Said, never silent. */
        bn_warnf(&so->log_sink, BN_W_METHOD, NAN,
                "%s needs %s of K, which the %s operator does not offer: jacobi to tol %g ran in its place, and "
                "its rows are labelled %s", bn_solve_method_name(o.method),
                o.method == BN_SOLVE_DIRECT ? "entries" : "rows", bn_transport_name(K), fmin(o.tol, 1e-10),
                bn_solve_method_name(o.method));
        o.method = BN_SOLVE_JACOBI;
        o.tol = fmin(o.tol, 1e-10);
    }
    st = bn_solve(K, E, &o, &res, err);
    *seconds = bn__now() - t0;
    if (st == BN_ENOTCONV && res.L) {
        bn_error_clear(err);
        st = BN_OK;
    }
    if (st != BN_OK) {
        bn_solve_result_free(&res);
        return st;
    }
    *L = res.L;
    res.L = NULL;
    if (info)
        *info = res;
    bn_solve_result_free(&res);
    return BN_OK;
}

/* The output phase: the per-patch table `bounce solve` writes (patch,face,material,area,L_R,L_G,L_B),
 * formatted into memory so the figure is the formatting cost and not the disk's. */
static double bn__output_time(const bn_scene *s, const double *L)
{
    size_t n, len = 0;
    const bn_patch *p = bn_scene_patches(s, &n);
    char *buf = NULL;
    double t0 = bn__now();
    FILE *fp = open_memstream(&buf, &len);
    if (!fp)
        return NAN;
    fputs("patch,face,material,area,L_R,L_G,L_B\n", fp);
    for (size_t i = 0; i < n; i++)
        fprintf(fp, "%zu,%zu,%u,%.9g,%.9g,%.9g,%.9g\n", i, p[i].face, p[i].material, p[i].area, L[3 * i],
                L[3 * i + 1], L[3 * i + 2]);
    fclose(fp);
    free(buf);
    return bn__now() - t0;
}

static double bn__geom(double q, int n, double normE)
{
    /* q^(n+1) / (1 - q) ||E||: the geometric tail sum_{k>n} q^k ||E|| */
    if (!(q < 1))
        return INFINITY;
    return pow(q, n + 1) / (1 - q) * normE;
}

/* ---- a reference solution: a direct solve (or the configured method) at a finer setting ---- */

typedef struct bn__sol {
    bn_scene *scene;
    double *L;
    size_t n;
    double seconds;
} bn__sol;

static void bn__sol_free(bn__sol *s)
{
    bn_scene_destroy(s->scene);
    free(s->L);
    memset(s, 0, sizeof *s);
}

/* Mesh with m, assemble with ffo, solve with the study's method (direct by default). */
static bn_status bn__radiosity(bn__study *S, const bn_mesh_opts *m, const bn_formfactor_opts *ffo, bn__sol *out,
                               bn_study_row *row, bn_error *err)
{
    bn_transport *K = NULL;
    double *E = NULL, tm = 0, tf = 0, ts = 0;
    bn_solve_result info;
    bn_status st;
    memset(out, 0, sizeof *out);
    if (row)
        bn__study_peak_reset();
    st = bn__scene(S, m, &out->scene, &tm, err);
    if (st == BN_OK) {   /* settings (a row) in the study's transport; references dense */
        const char *tr = row ? S->o->transport : NULL;
        bn_hierarchy_opts h = S->o->hier;
        if (row && S->o->param == BN_STUDY_EPS) {
            tr = "hierarchical";
            h.eps = row->x;
        }
        st = bn__build_k(out->scene, ffo, tr, &h, &K, row ? &row->k_entries : NULL, &tf, err);
    }
    if (st == BN_OK) {
        bn_scene_patches(out->scene, &out->n);
        E = bn__malloc_array(3 * out->n + 1, sizeof(double));
        if (!E)
            st = bn_error_set(err, BN_ENOMEM, "study: out of memory for E");
    }
    if (st == BN_OK) {
        bn_scene_patch_emission(out->scene, E);
        memset(&info, 0, sizeof info);
        st = bn__solve(K, E, &S->o->solve, &out->L, &info, &ts, err);
    }
    if (st == BN_OK && row) {
        row->patches = out->n;
        row->iterations = info.iterations;
        row->k_norm = info.k_norm_inf;
        row->t_mesh = tm;
        row->t_ff = tf;
        row->t_solve = ts;
        row->t_iterate = info.seconds_iterate;
        row->t_output = bn__output_time(out->scene, out->L);
        bn__row_total(row);
        row->peak_mb = bn__study_peak_mb();
        row->k_mb = (double)bn_transport_bytes(K) / 1048576.0;
    }
    out->seconds = tm + tf + ts;
    bn_transport_destroy(K);
    free(E);
    if (st != BN_OK)
        bn__sol_free(out);
    return st;
}

/* The reference error: the same reference method one level coarser (or with a quarter of the
 * samples), compared to the reference in the study's own metrics. For patch-constant radiosity
 * (first order in h) halving h halves the error, so |ref - coarser| ~ error(ref): an estimate
 * that is conservative for higher orders; for sampled form factors (1/sqrt(N)) it overestimates
 * the reference's error about twofold. */
static bn_status bn__ref_error(bn__study *S, const bn__study_ref *ref, const bn_mesh_opts *m,
                               const bn_formfactor_opts *ffo, const char *how, bn_error *err)
{
    bn__sol c;
    bn_study_row row;
    bn_status st;
    memset(&row, 0, sizeof row);
    row.err_surface = bn__calloc(ref->nsurf + 1, sizeof(double));
    if (!row.err_surface)
        return bn_error_set(err, BN_ENOMEM, "study: out of memory");
    st = bn__radiosity(S, m, ffo, &c, NULL, err);
    if (st == BN_OK)
        st = bn__study_compare(ref, c.scene, c.L, &row, err);
    if (st == BN_OK) {
        /* a sampled reference against one with a quarter of its samples (independent streams): the
         * difference is sqrt(5) standard errors of the reference; a mesh level differs by its error */
        double scale = S->o->param == BN_STUDY_SAMPLES || S->o->param == BN_STUDY_FF ? 1 / sqrt(5.0) : 1;
        row.err_surface_max *= scale;
        row.err_max_rel *= scale;
        S->res->ref_error = row.err_surface_max;
        S->res->ref_error_patch = row.err_max_rel;
        snprintf(S->res->ref_error_how, sizeof S->res->ref_error_how, "%s (%zu patches): per-surface %.3g, per-patch %.3g",
                 how, c.n, row.err_surface_max, row.err_max_rel);
    }
    free(row.err_surface);
    bn__sol_free(&c);
    return st;
}

/* ---- bounces, max-iter, tol: one mesh, one K, the direct solve of that K as reference ---- */

typedef struct bn__mon {
    const double *Lref;
    double normL, normE;
    size_t m;
    bn_study_curve *curve;
    size_t cap;
    const double *tols;   /* sorted descending */
    size_t ntols, next;
    double **Lat;         /* L at the first iterate meeting tols[t] */
    size_t *it_at;
    double *t_at;
    double t_row0;        /* seconds at row 0: the solver's analysis before the first sweep */
    double last_bound;
} bn__mon;

static int bn__monitor(void *user, const bn_solve_row *r, const double *L)
{
    bn__mon *M = user;
    double e = 0;
    if (r->iteration == 0)
        M->t_row0 = r->seconds;
    for (size_t q = 0; q < M->m; q++)
        e = fmax(e, fabs(L[q] - M->Lref[q]));
    if (M->curve && M->curve->n < M->cap) {
        M->curve->t[M->curve->n] = r->seconds;
        M->curve->err[M->curve->n] = M->normL > 0 ? e / M->normL : e;
        M->curve->n++;
    }
    /* The solver's own stop test: ||r||_inf <= tol ||E||_inf. */
    while (M->next < M->ntols && r->residual_max <= M->tols[M->next] * M->normE) {
        memcpy(M->Lat[M->next], L, M->m * sizeof(double));
        M->it_at[M->next] = r->iteration;
        M->t_at[M->next] = r->seconds;
        M->next++;
    }
    M->last_bound = r->bound;
    return 0;
}

static int bn__cmp_desc(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x < y) - (x > y);
}

/* The monitor's buffers for ntols tolerances (sorted, descending) of m values each. */
static bn_status bn__mon_init(bn__mon *M, const bn__study *S, const bn__study_ref *ref, double *tols, size_t ntols,
                              bn_error *err)
{
    memset(M, 0, sizeof *M);
    M->Lref = ref->L;
    M->normL = ref->norm_L;
    M->normE = S->res->norm_E;
    M->m = 3 * ref->n;
    M->tols = tols;
    M->ntols = ntols;
    M->Lat = bn__calloc(ntols + 1, sizeof(double *));
    M->it_at = bn__calloc(ntols + 1, sizeof(size_t));
    M->t_at = bn__calloc(ntols + 1, sizeof(double));
    if (!M->Lat || !M->it_at || !M->t_at)
        return bn_error_set(err, BN_ENOMEM, "study: out of memory");
    for (size_t t = 0; t < ntols; t++)
        if (!(M->Lat[t] = bn__malloc_array(M->m + 1, sizeof(double))))
            return bn_error_set(err, BN_ENOMEM, "study: out of memory");
    return BN_OK;
}

static void bn__mon_free(bn__mon *M)
{
    if (M->Lat)
        for (size_t t = 0; t < M->ntols; t++)
            free(M->Lat[t]);
    free(M->Lat);
    free(M->it_at);
    free(M->t_at);
}

/* One row per tolerance of an iterative method, from what the monitor kept. */
static bn_status bn__method_rows(bn__study *S, const bn__study_ref *ref, const bn__mon *M, const char *name,
                                 double t_mesh, double t_ff, bn_error *err)
{
    bn_status st = BN_OK;
    for (size_t t = 0; t < M->ntols && st == BN_OK; t++) {
        char v[32];
        bn_study_row *row;
        snprintf(v, sizeof v, "%g", M->tols[t]);
        if (!(row = bn__row_new(S, name, v, M->tols[t], err)))
            return err ? err->status : BN_ENOMEM;
        row->patches = ref->n;
        row->k_norm = S->res->k_norm;
        row->t_mesh = t_mesh;
        row->t_ff = t_ff;
        if (t < M->next) {
            row->iterations = M->it_at[t];
            row->t_solve = M->t_at[t];
            row->t_iterate = M->t_at[t] - M->t_row0;
            st = bn__study_compare(ref, ref->scene, M->Lat[t], row, err);
        } else {   /* never reached within max-iter */
            row->iterations = SIZE_MAX;
            row->t_solve = row->err_inf = row->err_inf_rel = row->err_max_rel = row->err_rms_rel = NAN;
            row->err_energy_rel = row->err_surface_max = row->err_surface_mean = NAN;
        }
        row->peak_mb = bn__study_peak_mb();
        bn__row_total(row);
    }
    return st;
}

/* The direct solve's rows: it is the reference, so its error is not measured against itself but
 * bounded a posteriori, ||r||_inf / (1 - ||K||_inf); and its one-point curve. */
static bn_status bn__direct_rows(bn__study *S, const bn__study_ref *ref, const double *tols, size_t ntols,
                                 double t_mesh, double t_ff, double t_direct, bn_error *err)
{
    bn_study_curve *c = bn__curve_new(S, "direct", 1, err);
    if (!c)
        return err ? err->status : BN_ENOMEM;
    for (size_t t = 0; t < ntols; t++) {
        char v[32];
        bn_study_row *row;
        snprintf(v, sizeof v, "%g", tols[t]);
        if (!(row = bn__row_new(S, "direct", v, tols[t], err)))
            return err ? err->status : BN_ENOMEM;
        row->patches = ref->n;
        row->k_norm = S->res->k_norm;
        row->t_mesh = t_mesh;
        row->t_ff = t_ff;
        row->t_solve = t_direct;
        row->t_iterate = S->direct_iterate;
        row->peak_mb = NAN;
        row->err_inf_rel = S->res->ref_error;
        row->err_inf = S->res->ref_error * ref->norm_L;
        row->err_max_rel = row->err_rms_rel = row->err_energy_rel = NAN;
        row->err_surface_max = row->err_surface_mean = NAN;
        for (size_t q = 0; q < ref->nsurf; q++)
            row->err_surface[q] = NAN;
        bn__row_total(row);
    }
    c->t[0] = t_direct;
    c->err[0] = S->res->ref_error > 0 ? S->res->ref_error : DBL_EPSILON;
    c->n = 1;
    return BN_OK;
}

static bn_status bn__methods(bn__study *S, const bn__study_ref *ref, const bn_transport *K, const double *E,
                             const double *tols_in, size_t ntols, double t_mesh, double t_ff, double t_direct,
                             bn_error *err)
{
    const bn_study_opts *o = S->o;
    double *tols = bn__malloc_array(ntols + 1, sizeof(double));
    bn__mon M;
    bn_status st;
    static const bn_solve_method iters[3] = {BN_SOLVE_JACOBI, BN_SOLVE_GAUSS_SEIDEL, BN_SOLVE_NEUMANN};
    if (!tols)
        return bn_error_set(err, BN_ENOMEM, "study: out of memory");
    memcpy(tols, tols_in, ntols * sizeof(double));
    qsort(tols, ntols, sizeof(double), bn__cmp_desc);
    st = bn__mon_init(&M, S, ref, tols, ntols, err);
    for (int q = 0; st == BN_OK && q < 3; q++) {
        bn_solve_method meth = iters[q];
        bn_solve_opts so = o->solve;
        double *L = NULL, ts;
        const char *name = bn_solve_method_name(meth);
        if (!(o->methods & (1u << meth)))
            continue;
        M.cap = so.max_iter + 1 < 200000 ? so.max_iter + 1 : 200000;
        M.curve = bn__curve_new(S, name, M.cap, err);
        if (!M.curve) {
            st = err ? err->status : BN_ENOMEM;
            break;
        }
        M.next = 0;
        so.method = meth;
        so.stop = BN_SOLVE_STOP_RESIDUAL;   /* one criterion for every method: ||r|| <= tol ||E|| */
        so.tol = tols[ntols - 1];
        so.monitor = bn__monitor;
        so.monitor_user = &M;
        bn__study_peak_reset();
        st = bn__solve(K, E, &so, &L, NULL, &ts, err);
        if (st == BN_OK)
            st = bn__method_rows(S, ref, &M, name, t_mesh, t_ff, err);
        free(L);
    }
    if (st == BN_OK && (o->methods & (1u << BN_SOLVE_DIRECT)))
        st = bn__direct_rows(S, ref, tols, ntols, t_mesh, t_ff, t_direct, err);
    bn__mon_free(&M);
    free(tols);
    return st;
}

/* What the bounces, tol and max-iter studies share: one scene, one K, its direct reference. */
typedef struct bn__opctx {
    bn_scene *sc;
    const bn_transport *K;
    const double *E;
    const bn__study_ref *ref;
    size_t n;
    double tm, tf, tdir;   /* meshing, form factors, the direct solve */
} bn__opctx;

/* The truncated series S_n = E + KE + ... + K^n E at each n asked, by repeated application timed
 * cumulatively (row n costs n applications of K), with both a priori bounds and the spectral
 * estimate of its error; then the methods table at the given tolerances. */
/* Row k of the truncated series (a study row when k is one of the values asked, else a scratch one
 * that feeds only the curve): S_k = Sn against the reference, the bounds, the tail estimate from
 * x = K^k E; t_apply: the applications so far; norm_ke = ||KE||_inf. */
static bn_status bn__series_row(bn__study *S, const bn__opctx *C, int k, double t_apply, double norm_ke,
                                const double *x, const double *Sn, bn_study_curve *curve, bn_error *err)
{
    const bn_study_result *R = S->res;
    bn_study_row tmp, *row = NULL;
    size_t m = 3 * C->n;
    double tn = 0, q = R->spectral_radius;
    bn_status st;
    for (size_t v = 0; v < S->o->nvalues && !row; v++)
        if ((int)S->o->values[v] == k) {
            char val[32];
            snprintf(val, sizeof val, "%d", k);
            if (!(row = bn__row_new(S, "truncated", val, k, err)))
                return err ? err->status : BN_ENOMEM;
        }
    memset(&tmp, 0, sizeof tmp);
    if (!row)
        row = &tmp;
    row->patches = C->n;
    row->iterations = (size_t)k;
    row->k_norm = R->k_norm;
    row->t_mesh = C->tm;
    row->t_ff = C->tf;
    row->t_solve = t_apply;
    row->t_iterate = t_apply;
    row->bound = bn__geom(R->k_norm, k, R->norm_E);
    /* L - S_n = sum_{j>=0} K^j (K^(n+1) E) = sum_{j>=n} K^j (KE): <= ||K||^n / (1 - ||K||) ||KE||. */
    row->bound_ke = bn__geom(R->k_norm, k - 1, norm_ke);
    /* the tail ~ K^n E (rho + rho^2 + ...) once K^n E is along the dominant eigenvector */
    for (size_t i = 0; i < m; i++)
        tn = fmax(tn, fabs(x[i]));
    row->estimate = q < 1 ? tn * q / (1 - q) : INFINITY;
    st = bn__study_compare(C->ref, C->sc, Sn, row, err);
    if (row != &tmp) {
        row->t_output = bn__output_time(C->sc, Sn);
        row->peak_mb = bn__study_peak_mb();
        bn__row_total(row);
    }
    curve->t[curve->n] = fmax(t_apply, 1e-7);   /* S_0 = E costs nothing: drawn at 0.1 us */
    curve->err[curve->n] = row->err_inf_rel;
    curve->n++;
    return st;
}

static bn_status bn__study_series(bn__study *S, const bn__opctx *C, bn_error *err)
{
    const bn_study_opts *o = S->o;
    const bn_transport *K = C->K;
    bn_status st = BN_OK;
    /* S_n by repeated application, timed cumulatively: row n costs n applications of K. */
    int nmax = 0;
    size_t m = 3 * C->n;
    double *x = bn__malloc_array(m + 1, sizeof(double)), *y = bn__malloc_array(m + 1, sizeof(double));
    double *Sn = bn__malloc_array(m + 1, sizeof(double)), t_apply = 0, norm_ke = 0;
    bn_study_curve *curve;
    for (size_t v = 0; v < o->nvalues; v++)
        nmax = (int)fmax(nmax, o->values[v]);
    curve = bn__curve_new(S, "truncated series", (size_t)nmax + 1, err);
    if (!x || !y || !Sn || !curve) {
        st = bn_error_set(err, BN_ENOMEM, "study: out of memory for the series");
        goto done;
    }
    /* ||KE||_inf for the second bound (one application, not timed). */
    st = bn_transport_apply(K, C->E, y, err);
    for (size_t q = 0; q < m; q++)
        norm_ke = fmax(norm_ke, fabs(y[q]));
    memcpy(x, C->E, m * sizeof(double));
    memcpy(Sn, C->E, m * sizeof(double));
    for (int k = 0; k <= nmax && st == BN_OK; k++) {
        if (k > 0) {
            double t0 = bn__now();
            if ((st = bn_transport_apply(K, x, y, err)) != BN_OK)   /* K^k E <- K (K^(k-1) E) */
                break;
            for (size_t q = 0; q < m; q++)
                Sn[q] += y[q];   /* S_k <- S_(k-1) + K^k E */
            t_apply += bn__now() - t0;
            memcpy(x, y, m * sizeof(double));
        }
        st = bn__series_row(S, C, k, t_apply, norm_ke, x, Sn, curve, err);
    }
done:
    free(x);
    free(y);
    free(Sn);
    if (st == BN_OK && o->methods) {
        static const double deftols[] = {1e-2, 1e-4, 1e-6, 1e-8};
        st = bn__methods(S, C->ref, K, C->E, o->ntols ? o->tols : deftols, o->ntols ? o->ntols : 4, C->tm, C->tf,
                         C->tdir, err);
    }
    return st;
}

/* Each iterative method stopped at each iteration limit, its error against the reference and the
 * solver's own a priori bound after those sweeps. */
static bn_status bn__study_max_iter(bn__study *S, const bn__opctx *C, bn_error *err)
{
    const bn_study_opts *o = S->o;
    bn_study_result *R = S->res;
    const bn_transport *K = C->K;
    const double *E = C->E;
    const bn__study_ref *refp = C->ref;
    bn_scene *sc = C->sc;
    size_t n = C->n;
    double tm = C->tm, tf = C->tf;
    bn_solve_result info;
    bn_status st = BN_OK;
    static const bn_solve_method iters[3] = {BN_SOLVE_JACOBI, BN_SOLVE_GAUSS_SEIDEL, BN_SOLVE_NEUMANN};
    for (int q = 0; q < 3 && st == BN_OK; q++) {
        if (!(o->methods & (1u << iters[q])))
            continue;
        for (size_t v = 0; v < o->nvalues && st == BN_OK; v++) {
            bn_solve_opts so = o->solve;
            bn__mon M;
            double *Lk = NULL, ts;
            char val[32];
            bn_study_row *row;
            memset(&M, 0, sizeof M);
            M.Lref = refp->L;
            M.normL = refp->norm_L;
            M.m = 3 * n;
            M.last_bound = NAN;
            so.method = iters[q];
            so.stop = BN_SOLVE_STOP_RESIDUAL;
            so.tol = 0;   /* run to the limit */
            so.max_iter = (size_t)o->values[v];
            so.monitor = bn__monitor;
            so.monitor_user = &M;
            snprintf(val, sizeof val, "%zu", so.max_iter);
            if (!(row = bn__row_new(S, bn_solve_method_name(iters[q]), val, o->values[v], err))) {
                st = err ? err->status : BN_ENOMEM;
                break;
            }
            bn__study_peak_reset();
            st = bn__solve(K, E, &so, &Lk, &info, &ts, err);
            if (st != BN_OK)
                break;
            row->patches = n;
            row->iterations = info.iterations;
            row->k_norm = R->k_norm;
            row->t_mesh = tm;
            row->t_ff = tf;
            row->t_solve = ts;
            row->t_iterate = info.seconds_iterate;
            row->bound = M.last_bound;   /* the solver's a priori bound after these sweeps */
            row->estimate = bn__geom(R->spectral_radius, (int)info.iterations *
                                     (iters[q] == BN_SOLVE_GAUSS_SEIDEL && so.symmetric ? 2 : 1), R->norm_E);
            st = bn__study_compare(refp, sc, Lk, row, err);
            row->t_output = bn__output_time(sc, Lk);
            row->peak_mb = bn__study_peak_mb();
            bn__row_total(row);
            free(Lk);
        }
    }
    return st;
}

/* The reference's lines of the result: what it is (a direct solve of the identical K, n patches,
 * tdir seconds), the operator's norms, and its error by the a posteriori bound
 * ||E - (I - K) L||_inf / (1 - ||K||_inf) >= ||L - L*||_inf. */
static void bn__study_operator_ref(bn__study *S, const bn_solve_result *info, const bn__study_ref *ref, size_t n,
                                   double tdir)
{
    const bn_study_opts *o = S->o;
    bn_study_result *R = S->res;
    R->ref_patches = n;
    R->ref_seconds = tdir;
    S->direct_iterate = info->seconds_iterate;
    R->norm_E = info->norm_E;
    R->norm_L = ref->norm_L;
    R->k_norm = info->k_norm_inf;
    R->spectral_radius = info->spectral_radius;
    snprintf(R->reference, sizeof R->reference,
             "direct LAPACK solve of the identical K (%zu patches, ff %s, %s storage)", n,
             bn_ff_method_name(o->ff.method), bn_precision_name(o->ff.precision));
    R->ref_error = ref->norm_L > 0 ? info->error_bound / ref->norm_L : info->error_bound;
    R->ref_error_patch = R->ref_error;
    snprintf(R->ref_error_how, sizeof R->ref_error_how,
             "a posteriori bound ||r||_inf / (1 - ||K||_inf) = %.3g W m^-2 sr^-1 (residual %.3g)", info->error_bound,
             info->residual_max);
    bn__note(S, "reference: %s; ||K||_inf %.6g, spectral radius %.6g; its error <= %.3g (relative)", R->reference,
             R->k_norm, R->spectral_radius, R->ref_error);
}

static bn_status bn__study_operator(bn__study *S, bn_error *err)
{
    const bn_study_opts *o = S->o;
    bn_scene *sc = NULL;
    bn_transport *K = NULL;
    double *E = NULL, *L = NULL, tm = 0, tf = 0, tdir = 0;
    bn_solve_result info;
    bn_solve_opts dso = o->solve;
    bn__study_ref ref;
    bn_status st;
    size_t n = 0;
    memset(&ref, 0, sizeof ref);
    memset(&info, 0, sizeof info);

    st = bn__scene(S, &o->mesh, &sc, &tm, err);
    if (st == BN_OK)
        st = bn__build_k(sc, &o->ff, NULL, NULL, &K, NULL, &tf, err);
    if (st != BN_OK)
        goto done;
    bn_scene_patches(sc, &n);
    if (!(E = bn__malloc_array(3 * n + 1, sizeof(double)))) {
        st = bn_error_set(err, BN_ENOMEM, "study: out of memory");
        goto done;
    }
    bn_scene_patch_emission(sc, E);
    dso.method = BN_SOLVE_DIRECT;
    st = bn__solve(K, E, &dso, &L, &info, &tdir, err);
    if (st == BN_OK)
        st = bn__study_ref_init(&ref, sc, L, S->res->nsurfaces, err);
    if (st != BN_OK)
        goto done;
    bn__study_operator_ref(S, &info, &ref, n, tdir);
    {
        bn__opctx C = {sc, K, E, &ref, n, tm, tf, tdir};
        if (o->param == BN_STUDY_BOUNCES)
            st = bn__study_series(S, &C, err);
        else if (o->param == BN_STUDY_TOL)
            st = bn__methods(S, &ref, K, E, o->values, o->nvalues, tm, tf, tdir, err);
        else   /* max-iter */
            st = bn__study_max_iter(S, &C, err);
    }
done:
    bn__study_ref_free(&ref);
    free(L);
    free(E);
    bn_transport_destroy(K);
    bn_scene_destroy(sc);
    return st;
}

/* ---- patches, patch-size, samples, ff, precision, spp ---- */

/* log-log interpolation of the time at which err falls to target along rows of one method
 * (in the order of increasing time); NAN if never. */
/* The error the equal-error comparison reads. */
static double bn__row_err(const bn_study_result *R, const bn_study_row *r)
{
    return R->metric_patch ? r->err_rms_rel : r->err_surface_max;
}

static double bn__time_to(const bn_study_result *R, const char *method, double target, double *best)
{
    double tprev = NAN, eprev = NAN, found = NAN;
    size_t idx[256], k = 0;
    *best = INFINITY;
    for (size_t i = 0; i < R->nrows && k < 256; i++)
        if (strcmp(R->rows[i].method, method) == 0 && isfinite(bn__row_err(R, &R->rows[i])))
            idx[k++] = i;
    for (size_t a = 1; a < k; a++)   /* insertion sort by time */
        for (size_t b = a; b > 0 && R->rows[idx[b]].t_total < R->rows[idx[b - 1]].t_total; b--) {
            size_t t = idx[b];
            idx[b] = idx[b - 1];
            idx[b - 1] = t;
        }
    for (size_t a = 0; a < k; a++) {
        const bn_study_row *r = &R->rows[idx[a]];
        double e = bn__row_err(R, r), t = r->t_total;
        *best = fmin(*best, e);
        if (isnan(found) && e <= target) {
            if (a == 0 || !(eprev > target) || !(e > 0) || !(tprev > 0))
                found = t;
            else   /* straight line in log-log between the last point above and the first below */
                found = exp(log(tprev) + (log(target) - log(eprev)) * (log(t) - log(tprev)) / (log(e) - log(eprev)));
        }
        tprev = t;
        eprev = e;
    }
    return found;
}

/* Runs the tracer on scene sc (meshed) at spp with seed; *L receives the L layer (N*3, malloc'd);
 * rel_se_surf / rel_se_patch: the largest relative standard error per surface and per patch
 * (per patch scaled like the comparison: by max(L, the mean radiance)). */
static bn_status bn__trace_solution(const bn_scene *sc, const bn_trace_opts *base, size_t spp, uint64_t seed, double **L,
                                    double *rel_se_surf, double *rel_se_patch, double *seconds, bn_error *err)
{
    bn_rt *rt = NULL;
    bn_trace_patches tp;
    bn_trace_opts to = *base;
    size_t n, nm;
    const bn_patch *p = bn_scene_patches(sc, &n);
    double t0 = bn__now();
    bn_status st;
    bn_scene_materials(sc, &nm);
    memset(&tp, 0, sizeof tp);
    to.spp = spp;
    to.seed = seed;
    to.quiet = 1;
    st = bn_rt_create(sc, bn_threads_resolve(0), &rt, err);
    if (st == BN_OK)
        st = bn_trace_patches_run(rt, &to, &tp, err);
    *seconds = bn__now() - t0;
    if (st == BN_OK) {
        size_t li = (size_t)tp.nlayers - 1;
        double *sa = bn__calloc(nm + 1, sizeof(double)), *sv = bn__calloc(3 * nm + 1, sizeof(double));
        double *sm = bn__calloc(3 * nm + 1, sizeof(double)), a = 0, mean[3] = {0, 0, 0};
        *L = bn__malloc_array(3 * n + 1, sizeof(double));
        if (!*L || !sa || !sv || !sm)
            st = bn_error_set(err, BN_ENOMEM, "study: out of memory for the tracer's estimates");
        else {
            memcpy(*L, tp.mean + li * n * 3, 3 * n * sizeof(double));
            *rel_se_surf = *rel_se_patch = 0;
            for (size_t i = 0; i < n; i++) {
                size_t s = p[i].material;
                a += p[i].area;
                for (int c = 0; c < 3; c++) {
                    double e = p[i].area * tp.se[(li * n + i) * 3 + (size_t)c];
                    mean[c] += p[i].area * (*L)[3 * i + (size_t)c];
                    if (s < nm) {
                        sv[3 * s + (size_t)c] += e * e;   /* patches are independent */
                        sm[3 * s + (size_t)c] += p[i].area * (*L)[3 * i + (size_t)c];
                    }
                }
                if (s < nm)
                    sa[s] += p[i].area;
            }
            for (size_t i = 0; i < n; i++)
                for (int c = 0; c < 3; c++)
                    *rel_se_patch = fmax(*rel_se_patch, tp.se[(li * n + i) * 3 + (size_t)c] /
                                                            fmax((*L)[3 * i + (size_t)c], mean[c] / a));
            for (size_t s = 0; s < nm; s++)
                for (int c = 0; c < 3; c++)
                    if (sa[s] > 0 && sm[3 * s + (size_t)c] > 0)
                        *rel_se_surf = fmax(*rel_se_surf, sqrt(sv[3 * s + (size_t)c]) / sm[3 * s + (size_t)c]);
        }
        free(sa);
        free(sv);
        free(sm);
    }
    if (st != BN_OK) {
        free(*L);
        *L = NULL;
    }
    bn_trace_patches_free(&tp);
    bn_rt_destroy(rt);
    return st;
}

/* The tracer reference on mesh m: spp from a pilot unless given; a seed independent of the settings'. */
static bn_status bn__trace_reference(bn__study *S, const bn_mesh_opts *m, bn__sol *out, bn_error *err)
{
    const bn_study_opts *o = S->o;
    bn_study_result *R = S->res;
    uint64_t seed = bn__hash64(o->trace.seed ^ 0x5eed5eed5eedULL);   /* not any setting's stream */
    double se_s = 0, se_p = 0, t = 0, tm = 0, target = R->target;
    size_t spp = o->ref_spp;
    bn_status st;
    memset(out, 0, sizeof *out);
    st = bn__scene(S, m, &out->scene, &tm, err);
    if (st != BN_OK) {
        bn__sol_free(out);
        return st;
    }
    bn_scene_patches(out->scene, &out->n);
    if (spp == 0) {   /* pilot: SE ~ 1/sqrt(spp), so spp = 64 (se / (target / 8))^2 */
        double tp = 0;
        st = bn__trace_solution(out->scene, &o->trace, 64, seed + 1, &out->L, &se_s, &se_p, &tp, err);
        free(out->L);
        out->L = NULL;
        if (st != BN_OK) {
            bn__sol_free(out);
            return st;
        }
        if (o->metric_patch) {
            spp = (size_t)ceil(64.0 * (se_p / (target / 4)) * (se_p / (target / 4)));
            spp = spp < 64 ? 64 : spp > 65536 ? 65536 : spp;
            bn__note(S, "reference: a 64-spp pilot gives a per-patch standard error of %.3g (largest): %zu spp for %.3g",
                     se_p, spp, target / 4);
        } else {
            spp = (size_t)ceil(64.0 * (se_s / (target / 8)) * (se_s / (target / 8)));
            spp = spp < 64 ? 64 : spp > 65536 ? 65536 : spp;
            bn__note(S, "reference: a 64-spp pilot gives a per-surface standard error of %.3g: %zu spp for %.3g", se_s,
                     spp, target / 8);
        }
    }
    st = bn__trace_solution(out->scene, &o->trace, spp, seed, &out->L, &se_s, &se_p, &t, err);
    if (st != BN_OK) {
        bn__sol_free(out);
        return st;
    }
    out->seconds = tm + t;
    R->ref_error = 2 * se_s;
    R->ref_error_patch = 2 * se_p;
    snprintf(R->reference, sizeof R->reference, "path tracer, %zu spp per patch on %zu patches (edge %.4g), independent seed",
             spp, out->n, bn_scene_patch_size(out->scene));
    snprintf(R->ref_error_how, sizeof R->ref_error_how,
             "2 standard errors of its own samples (unbiased estimator): per-surface %.3g, per-patch %.3g", 2 * se_s,
             2 * se_p);
    return BN_OK;
}

static bn_status bn__trace_row(bn__study *S, const bn__study_ref *ref, const bn_mesh_opts *m, size_t spp,
                               bn_error *err)
{
    bn_scene *sc = NULL;
    bn_study_row *row;
    double tm = 0, *L = NULL, se_p = 0;
    char val[32];
    bn_status st;
    snprintf(val, sizeof val, "%zu", spp);
    if (!(row = bn__row_new(S, "trace", val, (double)spp, err)))
        return err ? err->status : BN_ENOMEM;
    bn__study_peak_reset();
    st = bn__scene(S, m, &sc, &tm, err);
    if (st == BN_OK)   /* t_solve: ray-caster build + tracing */
        st = bn__trace_solution(sc, &S->o->trace, spp, S->o->trace.seed, &L, &row->se_surface_max, &se_p,
                                &row->t_solve, err);
    if (st == BN_OK) {
        bn_scene_patches(sc, &row->patches);
        row->iterations = spp;
        row->t_mesh = tm;
        st = bn__study_compare(ref, sc, L, row, err);
        row->t_output = bn__output_time(sc, L);
    }
    row->peak_mb = bn__study_peak_mb();
    bn__row_total(row);
    bn_scene_destroy(sc);
    free(L);
    return st;
}

/* The reference of a settings study and the level below it, from which its error is estimated. */
typedef struct bn__ref_plan {
    bn_mesh_opts mref, mcoarse;
    bn_formfactor_opts fref, fcoarse;
    int mesh_study, use_trace;
} bn__ref_plan;

/* The reference's and the coarser level's meshes for a mesh (or spp) study: 4x the finest setting's
 * patches (or half the smallest patch size), and a quarter of that. */
static void bn__ref_mesh_levels(const bn_study_opts *o, bn__ref_plan *P)
{
    if (o->param == BN_STUDY_PATCHES || o->param == BN_STUDY_SPP) {
        size_t top = o->mesh.target_patches;
        if (o->param == BN_STUDY_PATCHES)
            for (size_t v = 0; v < o->nvalues; v++)
                top = v == 0 ? (size_t)o->values[v] : (size_t)fmax((double)top, o->values[v]);
        P->mref.patch_size = 0;
        P->mref.no_subdivide = 0;
        P->mref.target_patches = o->ref_patches ? o->ref_patches : 4 * top;
        P->mcoarse = P->mref;
        P->mcoarse.target_patches = P->mref.target_patches / 4 > 0 ? P->mref.target_patches / 4 : 1;
    } else {   /* patch size */
        double lo = INFINITY;
        for (size_t v = 0; v < o->nvalues; v++)
            lo = fmin(lo, o->values[v]);
        P->mref.target_patches = 0;
        P->mref.no_subdivide = 0;
        P->mref.patch_size = lo / 2;
        P->mcoarse = P->mref;
        P->mcoarse.patch_size = lo;
    }
}

/* The reference's form factors for an eps, samples or ff study: sampled like the settings (dense K
 * with many rays for eps: what K_H approximates), 32x the largest setting's samples (1/sqrt(32) of
 * its error), from independent streams (a reference sharing the settings' seed and stratification
 * would agree with them by correlation, not accuracy); the coarser level a quarter of the samples. */
static void bn__ref_ff_levels(const bn_study_opts *o, bn__ref_plan *P)
{
    int top = 0;
    for (size_t v = 0; o->param == BN_STUDY_SAMPLES && v < o->nvalues; v++)
        top = (int)fmax(top, o->values[v]);
    P->fref.method = BN_FF_ANALYTIC;
    P->fref.exact_visibility = 0;
    if (o->param == BN_STUDY_EPS)
        P->fref.samples = o->ref_samples ? o->ref_samples : 256;
    else
        P->fref.samples = o->ref_samples ? o->ref_samples : (32 * top > 1024 ? 32 * top : 1024);
    P->fref.seed = bn__hash64(o->ff.seed ^ 0x7265666572656e63ULL);
    P->fcoarse = P->fref;
    P->fcoarse.samples = P->fref.samples / 4 > 0 ? P->fref.samples / 4 : 1;
    P->fcoarse.seed = bn__hash64(P->fref.seed + 1);
}

/* Whether the reference is the tracer (asked, or a mesh or eps study compared against it) and then
 * its mesh: the finest setting's (its rows compare patch by patch), or the study's own for eps (dense
 * K with many rays would be a reference of K_H alone, not of the light). */
static void bn__ref_trace_choice(const bn_study_opts *o, bn__ref_plan *P)
{
    int asked = o->ref == BN_STUDY_REF_TRACE;
    if (P->mesh_study || o->param == BN_STUDY_SPP) {
        P->use_trace = asked || (o->ref == BN_STUDY_REF_AUTO && P->mesh_study && o->nagainst > 0);
        if (P->use_trace && !o->ref_patches) {
            P->mref = o->mesh;
            if (o->param == BN_STUDY_PATCHES) {
                P->mref.patch_size = 0;
                P->mref.target_patches = (size_t)o->values[0];
                for (size_t v = 1; v < o->nvalues; v++)
                    P->mref.target_patches = (size_t)fmax((double)P->mref.target_patches, o->values[v]);
            } else if (o->param == BN_STUDY_PATCH_SIZE)
                P->mref.patch_size = P->mcoarse.patch_size;
        }
    }
    if (o->param == BN_STUDY_EPS && (asked || (o->ref == BN_STUDY_REF_AUTO && o->nagainst > 0))) {
        P->use_trace = 1;
        P->mref = o->mesh;
    }
}

static void bn__ref_levels(const bn_study_opts *o, bn__ref_plan *P)
{
    P->mref = P->mcoarse = o->mesh;
    P->fref = P->fcoarse = o->ff;
    P->mesh_study = o->param == BN_STUDY_PATCHES || o->param == BN_STUDY_PATCH_SIZE;
    P->use_trace = 0;
    if (P->mesh_study || o->param == BN_STUDY_SPP)
        bn__ref_mesh_levels(o, P);
    else if (o->param == BN_STUDY_EPS || o->param == BN_STUDY_SAMPLES || o->param == BN_STUDY_FF)
        bn__ref_ff_levels(o, P);
    else   /* precision */
        P->fref.precision = P->fcoarse.precision = BN_PRECISION_DOUBLE;
    bn__ref_trace_choice(o, P);
}

/* Richardson extrapolation of a mesh study's reference (Richardson 1911; Roache, "Quantification of
 * uncertainty in computational fluid dynamics", 1997). Levels 0 (the reference), 1 and 2, each with
 * twice the patch edge of the one before; per surface and channel the means S_0, S_1, S_2 on each
 * level's own mesh. The order
 *   p = log2(max |S_2 - S_1| / max |S_1 - S_0|)       (relative to the surfaces' means; clamped to [0.5, 3])
 * gives the extrapolated per-surface reference S* = S_0 + (S_0 - S_1) / (2^p - 1). Its own error is
 * the larger of two spreads: the same extrapolation one level coarser, |S*_01 - S*_12|, and the
 * extrapolation with the method's asymptotic order for area means, 2 (piecewise-constant radiosity
 * with a smooth kernel), |S*(p) - S*(2)|. The second matters when the levels are not yet asymptotic:
 * the fitted order then still rises with refinement, both neighbouring extrapolations overshoot
 * alike, and their difference alone understates the error (the parallel-plates test shows it
 * 15-fold). Level 0's own error, |S* - S_0|, is reported beside it. Patch values are
 * not extrapolated: across shadow and contact edges the piecewise-constant levels differ by jumps
 * that an extrapolation would overshoot. The per-patch reference stays level 0, and its error is
 * Richardson's estimate |L_0 - L_1| / (2^p - 1) (level 1 seen on level 0's mesh). */
typedef struct bn__levels {
    bn__sol sol[2];          /* levels 1 and 2 */
    double *S[3];            /* surface means, nsurf*3 each */
    double *Lm[2];           /* levels 1 and 2 on level 0's mesh, n0*3 */
} bn__levels;

static void bn__levels_free(bn__levels *V)
{
    for (int k = 0; k < 2; k++) {
        bn__sol_free(&V->sol[k]);
        free(V->Lm[k]);
    }
    for (int k = 0; k < 3; k++)
        free(V->S[k]);
}

/* max over surfaces and channels of |a - b| / max(ref, 1e-6 of the brightest surface) */
static double bn__surf_diff(const double *a, const double *b, const double *ref, size_t nsurf)
{
    double top = 0, d = 0;
    for (size_t i = 0; i < 3 * nsurf; i++)
        top = fmax(top, fabs(ref[i]));
    for (size_t i = 0; i < 3 * nsurf; i++)
        if (top > 0 && ref[i] != 0)
            d = fmax(d, fabs(a[i] - b[i]) / fmax(fabs(ref[i]), 1e-6 * top));
    return d;
}

static bn_status bn__richardson(bn__study *S, const bn__ref_plan *P, bn__sol *ref, bn__study_ref *rr, bn_error *err)
{
    bn_study_result *R = S->res;
    size_t nsurf = rr->nsurf, n0 = ref->n;
    bn_mesh_opts m[2] = {P->mcoarse, P->mcoarse};
    bn__levels V;
    double p, f, e_surf = 0, e_patch = 0, d01, d12;
    double *S01 = NULL, *S12 = NULL, *S2nd = NULL;
    bn_status st = BN_OK;
    memset(&V, 0, sizeof V);
    if (m[1].patch_size > 0)
        m[1].patch_size *= 2;
    else
        m[1].target_patches = m[1].target_patches / 4 > 0 ? m[1].target_patches / 4 : 1;
    for (int k = 0; k < 2 && st == BN_OK; k++) {
        st = bn__radiosity(S, &m[k], &P->fref, &V.sol[k], NULL, err);
        V.Lm[k] = bn__malloc_array(3 * n0 + 1, sizeof(double));
        V.S[k + 1] = bn__malloc_array(3 * nsurf + 1, sizeof(double));
        if (st == BN_OK && (!V.Lm[k] || !V.S[k + 1]))
            st = bn_error_set(err, BN_ENOMEM, "study: out of memory for the reference levels");
        if (st == BN_OK)
            st = bn__study_map_onto(ref->scene, V.sol[k].scene, V.sol[k].L, V.Lm[k], err);
        if (st == BN_OK)
            bn__study_surface_means(V.sol[k].scene, V.sol[k].L, nsurf, V.S[k + 1]);
    }
    V.S[0] = bn__malloc_array(3 * nsurf + 1, sizeof(double));
    S01 = bn__malloc_array(3 * nsurf + 1, sizeof(double));
    S12 = bn__malloc_array(3 * nsurf + 1, sizeof(double));
    S2nd = bn__malloc_array(3 * nsurf + 1, sizeof(double));
    if (st == BN_OK && (!V.S[0] || !S01 || !S12 || !S2nd))
        st = bn_error_set(err, BN_ENOMEM, "study: out of memory for the reference levels");
    if (st == BN_OK && !(V.sol[1].n < V.sol[0].n && V.sol[0].n < n0))
        st = BN_ENOTSUP;   /* the levels did not refine: no extrapolation (the caller falls back) */
    if (st != BN_OK)
        goto done;
    memcpy(V.S[0], rr->surf_mean, 3 * nsurf * sizeof(double));
    d01 = bn__surf_diff(V.S[1], V.S[0], V.S[0], nsurf);
    d12 = bn__surf_diff(V.S[2], V.S[1], V.S[0], nsurf);
    p = d01 > 0 && d12 > 0 ? log2(d12 / d01) : 1;
    p = fmin(fmax(p, 0.5), 3);
    f = 1 / (pow(2, p) - 1);
    for (size_t i = 0; i < 3 * nsurf; i++) {
        S01[i] = V.S[0][i] + (V.S[0][i] - V.S[1][i]) * f;
        S12[i] = V.S[1][i] + (V.S[1][i] - V.S[2][i]) * f;
        S2nd[i] = V.S[0][i] + (V.S[0][i] - V.S[1][i]) / 3;   /* order 2 */
    }
    e_surf = fmax(bn__surf_diff(S01, S12, S01, nsurf), bn__surf_diff(S01, S2nd, S01, nsurf));
    R->ref_error_raw = bn__surf_diff(V.S[0], S01, S01, nsurf);
    for (size_t i = 0; i < 3 * n0; i++)   /* level 0's per-patch error, Richardson's estimate */
        e_patch = fmax(e_patch, fabs(ref->L[i] - V.Lm[0][i]) * f / fmax(fabs(ref->L[i]), rr->floor[i % 3]));
    memcpy(rr->surf_mean, S01, 3 * nsurf * sizeof(double));   /* the levels' own means, extrapolated */
    R->ref_order = p;
    R->ref_error = e_surf;
    R->ref_error_patch = e_patch;
    snprintf(R->ref_error_how, sizeof R->ref_error_how,
             "per surface Richardson-extrapolated from %zu, %zu and %zu patches, order %.2f, its error %.3g (the "
             "larger of |S*(%zu, %zu) - S*(%zu, %zu)| and |S*(p) - S*(2)|); per patch level 0, its error |L0 - L1| / "
             "(2^p - 1) %.3g (level 0 per surface: %.3g)",
             n0, V.sol[0].n, V.sol[1].n, p, e_surf, n0, V.sol[0].n, V.sol[0].n, V.sol[1].n, e_patch, R->ref_error_raw);
done:
    bn__levels_free(&V);
    free(S01);
    free(S12);
    free(S2nd);
    return st;
}

/* Builds the reference (radiosity or the tracer), its comparison data and its own error. */
static bn_status bn__build_reference(bn__study *S, const bn__ref_plan *P, bn__sol *refp, bn__study_ref *rr,
                                     bn_error *err)
{
    const bn_study_opts *o = S->o;
    bn_study_result *R = S->res;
    bn_mesh_opts mref = P->mref, mcoarse = P->mcoarse;
    bn_formfactor_opts fref = P->fref, fcoarse = P->fcoarse;
    int mesh_study = P->mesh_study, use_trace = P->use_trace;
    bn__sol ref;
    bn_status st;
    bn__note(S, "study %s: building the reference (%s)", bn_study_param_name(o->param),
             use_trace ? "path tracer" : "radiosity");
    st = use_trace ? bn__trace_reference(S, &mref, &ref, err) : bn__radiosity(S, &mref, &fref, &ref, NULL, err);
    if (st != BN_OK)
        return st;
    st = bn__study_ref_init(rr, ref.scene, ref.L, R->nsurfaces, err);
    if (st != BN_OK) {
        bn__sol_free(&ref);
        return st;
    }
    *refp = ref;
    R->ref_patches = ref.n;
    R->ref_seconds = ref.seconds;
    R->norm_L = rr->norm_L;
    {
        double e = 0;
        for (size_t i = 0; i < 3 * ref.n; i++)
            e = fmax(e, fabs(rr->E[i]));
        R->norm_E = e;
    }
    if (!use_trace)
        snprintf(R->reference, sizeof R->reference, "%s solve, %zu patches (edge %.4g), ff %s with %d samples, %s storage",
             bn_solve_method_name(o->solve.method), ref.n, bn_scene_patch_size(ref.scene), bn_ff_method_name(fref.method),
             fref.samples ? fref.samples : bn_formfactor_default_samples(fref.method),
             bn_precision_name(fref.precision));
    if (use_trace) {
        /* its error was set from its standard errors */
    } else if (o->param == BN_STUDY_PRECISION) {
        R->ref_error = R->ref_error_patch = 0;
        snprintf(R->ref_error_how, sizeof R->ref_error_how,
                 "same mesh and form factors in double: rounding only (~1e-15 relative per operation)");
    } else {
        const char *how = mesh_study || o->param == BN_STUDY_SPP
                              ? "|reference - the same at half the patch density per axis| (first order in h: ~ its own error)"
                              : "its standard error, |reference - the same with a quarter of the shadow rays| / sqrt(5) "
                                "(independent streams at N and N/4: the difference's variance is (1 + 4) sigma^2 / N)";
        st = mesh_study ? bn__richardson(S, P, refp, rr, err) : BN_ENOTSUP;
        if (st == BN_OK)
            snprintf(R->reference + strlen(R->reference), sizeof R->reference - strlen(R->reference),
                     ", per-surface means extrapolated (Richardson, order %.2f)", R->ref_order);
        else if (st == BN_ENOTSUP)
            st = bn__ref_error(S, rr, &mcoarse, &fcoarse, how, err);
    }
    if (st == BN_OK && (R->ref_surface_mean = bn__malloc_array(3 * rr->nsurf + 1, sizeof(double))) != NULL)
        memcpy(R->ref_surface_mean, rr->surf_mean, 3 * rr->nsurf * sizeof(double));
    if (st == BN_OK)
        bn__note(S, "reference: %s (%.2f s); its error ~ %.3g per surface (%s)", R->reference, ref.seconds, R->ref_error,
                 R->ref_error_how);
    return st;
}

/* Setting v of the varied parameter: mesh and form-factor options, its label and its method. */
static void bn__setting(const bn_study_opts *o, size_t v, bn_mesh_opts *mo, bn_formfactor_opts *fo, char *val,
                        size_t nval, const char **methodp)
{
    bn_mesh_opts m = o->mesh;
    bn_formfactor_opts f = o->ff;
    const char *method = "radiosity";
    switch (o->param) {
    case BN_STUDY_PATCHES:
        m.patch_size = 0;
        m.no_subdivide = 0;
        m.target_patches = (size_t)o->values[v];
        snprintf(val, nval, "%zu", m.target_patches);
        break;
    case BN_STUDY_PATCH_SIZE:
        m.target_patches = 0;
        m.no_subdivide = 0;
        m.patch_size = o->values[v];
        snprintf(val, nval, "%g", m.patch_size);
        break;
    case BN_STUDY_SAMPLES:
        f.samples = (int)o->values[v];
        f.exact_visibility = 0;   /* the samples are shadow rays (analytic), which the exact path has none of */
        snprintf(val, nval, "%d", f.samples);
        method = bn_ff_method_name(f.method);
        break;
    case BN_STUDY_FF:
        f.method = (bn_ff_method)(int)o->values[v];
        snprintf(val, nval, "%s", bn_ff_method_name(f.method));
        method = val;
        break;
    case BN_STUDY_EPS:
        snprintf(val, nval, "%g", o->values[v]);
        method = "hierarchy";
        break;
    default:   /* precision */
        f.precision = (bn_precision)(int)o->values[v];
        snprintf(val, nval, "%s", bn_precision_name(f.precision));
        break;
    }
    *mo = m;
    *fo = f;
    *methodp = method;
}

/* A reference is only useful well below what it measures: say so when it is not. */
static void bn__warn_reference(const bn__study *S)
{
    const bn_study_result *R = S->res;
    double best = INFINITY;
    for (size_t i = 0; i < R->nrows; i++)
        if (isfinite(R->rows[i].err_surface_max))
            best = fmin(best, R->rows[i].err_surface_max);
    if (isfinite(best) && R->ref_error > best / 3)
        bn_warnf(&S->o->log, BN_W_REFERENCE, R->ref_error,
                "the reference's estimated error (%.3g per surface) is not well below the smallest error measured "
                "(%.3g): errors near it are uncertain; use a finer reference (`ref_patches`, `ref_samples`, `ref_spp`)",
                R->ref_error, best);
}

/* The equal-error comparison: the tracer on the first setting's mesh (per patch: on the reference's,
 * mref), and the times at which each method reaches the target error. */
static bn_status bn__equal_error(bn__study *S, const bn__study_ref *rr, const bn_mesh_opts *mref, bn_error *err)
{
    const bn_study_opts *o = S->o;
    bn_study_result *R = S->res;
    bn_mesh_opts m = o->mesh;
    bn_status st = BN_OK;
    double b;
    if (o->metric_patch || o->param == BN_STUDY_EPS) {
        m = *mref;
    } else if (o->param == BN_STUDY_PATCHES) {
        m.patch_size = 0;
        m.target_patches = (size_t)o->values[0];
    } else {
        m.target_patches = 0;
        m.patch_size = o->values[0];
    }
    for (size_t a = 0; a < o->nagainst && st == BN_OK; a++) {
        bn__note(S, "equal-error: path tracer at %zu spp", o->against_spp[a]);
        st = bn__trace_row(S, rr, &m, o->against_spp[a], err);
    }
    if (st != BN_OK)
        return st;
    const char *rad = o->param == BN_STUDY_EPS ? "hierarchy" : "radiosity";   /* the rows' method */
    R->t_radiosity = bn__time_to(R, rad, R->target, &R->best_radiosity);
    R->t_trace = bn__time_to(R, "trace", R->target, &R->best_trace);
    R->ratio = R->t_trace / R->t_radiosity;
    R->fine_target = 3 * (o->metric_patch ? R->ref_error_patch : R->ref_error);
    if (R->fine_target > 0 && R->fine_target < R->target) {
        R->t_radiosity_fine = bn__time_to(R, rad, R->fine_target, &b);
        R->t_trace_fine = bn__time_to(R, "trace", R->fine_target, &b);
        R->ratio_fine = R->t_trace_fine / R->t_radiosity_fine;
    }
    return BN_OK;
}

static bn_status bn__study_settings(bn__study *S, bn_error *err)
{
    const bn_study_opts *o = S->o;
    bn__ref_plan P;
    bn__sol ref;
    bn__study_ref rr;
    bn_status st;
    memset(&ref, 0, sizeof ref);
    memset(&rr, 0, sizeof rr);
    bn__ref_levels(o, &P);
    st = bn__build_reference(S, &P, &ref, &rr, err);
    for (size_t v = 0; v < o->nvalues && st == BN_OK; v++) {
        bn_mesh_opts m;
        bn_formfactor_opts f;
        char val[BN_STUDY_LABEL];
        const char *method;
        bn_study_row *row;
        bn__sol sol;
        if (o->param == BN_STUDY_SPP) {
            st = bn__trace_row(S, &rr, &o->mesh, (size_t)o->values[v], err);
            continue;
        }
        bn__setting(o, v, &m, &f, val, sizeof val, &method);
        if (!(row = bn__row_new(S, method, val, o->values[v], err))) {
            st = err ? err->status : BN_ENOMEM;
            break;
        }
        bn__note(S, "setting %s=%s", bn_study_param_name(o->param), val);
        st = bn__radiosity(S, &m, &f, &sol, row, err);
        if (st == BN_OK)
            st = bn__study_compare(&rr, sol.scene, sol.L, row, err);
        bn__sol_free(&sol);
    }
    if (st == BN_OK)
        bn__warn_reference(S);
    if (st == BN_OK && (P.mesh_study || (o->param == BN_STUDY_EPS && P.use_trace)) && o->nagainst > 0)
        st = bn__equal_error(S, &rr, &P.mref, err);
    bn__study_ref_free(&rr);
    bn__sol_free(&ref);
    return st;
}

/* ---- warnings gathered: each kind (code) said once per study, with its count and worst ----
 * A study assembles form factors and solves once per setting, and each would repeat the same
 * warning (rows of F above 1, ...). The worst occurrence is the one with the largest measure. */
typedef struct bn__warn_kind {
    char worst[2048];
    double value;
    size_t count;
} bn__warn_kind;
typedef struct bn__warnings {
    bn_log out;   /* where they go in the end */
    bn__warn_kind kind[BN_WARNING_COUNT];
} bn__warnings;

static void bn__gather(void *user, const bn_message *m)
{
    bn__warnings *W = user;
    bn__warn_kind *k;
    if (m->level != BN_LOG_WARN) {
        bn_logf(&W->out, m->level, "%s", m->text);
        return;
    }
    if ((unsigned)m->code >= BN_WARNING_COUNT) {   /* not a code of this library: said now */
        bn_warnf(&W->out, m->code, m->value, "%s", m->text);
        return;
    }
    k = &W->kind[m->code];
    if (k->count++ == 0 || (isfinite(m->value) && !(m->value <= k->value))) {
        k->value = m->value;
        snprintf(k->worst, sizeof k->worst, "%s", m->text);
    }
}

static void bn__warnings_flush(const bn__warnings *W)
{
    for (int c = 0; c < BN_WARNING_COUNT; c++) {
        const bn__warn_kind *k = &W->kind[c];
        if (k->count == 1)
            bn_warnf(&W->out, (bn_warning)c, k->value, "%s", k->worst);
        else if (k->count > 1)
            bn_warnf(&W->out, (bn_warning)c, k->value, "%s [%zu times in this study; the worst shown]", k->worst,
                     k->count);
    }
}

/* Each value the study varies, checked against its parameter's range. */
static bn_status bn__study_check_value(bn_study_param param, double x, bn_error *err)
{
    int whole = x == floor(x);
    switch (param) {
    case BN_STUDY_BOUNCES:
        if (!whole || x < 0 || x > 100000)
            return bn_error_set(err, BN_EUSAGE, "study: bounces must be whole numbers in [0, 100000] (got %g)", x);
        break;
    case BN_STUDY_MAX_ITER: case BN_STUDY_PATCHES: case BN_STUDY_SAMPLES: case BN_STUDY_SPP:
        if (!whole || x < 1 || x > 1e9)
            return bn_error_set(err, BN_EUSAGE, "study: %s must be whole numbers >= 1 (got %g)",
                                bn_study_param_name(param), x);
        break;
    case BN_STUDY_TOL:
        if (!(x > 0 && x < 1))
            return bn_error_set(err, BN_EUSAGE, "study: tol must be in (0, 1) (got %g)", x);
        break;
    case BN_STUDY_PATCH_SIZE:
        if (!(x > 0) || !isfinite(x))
            return bn_error_set(err, BN_EUSAGE, "study: patch-size must be > 0 (got %g)", x);
        break;
    case BN_STUDY_FF:
        if (!whole || x < 0 || x > 2)
            return bn_error_set(err, BN_EUSAGE, "study: bad form-factor method index %g", x);
        break;
    case BN_STUDY_PRECISION:
        if (!whole || x < 0 || x > 1)
            return bn_error_set(err, BN_EUSAGE, "study: bad precision index %g", x);
        break;
    case BN_STUDY_EPS:
        if (!(x > 0 && x < 1))
            return bn_error_set(err, BN_EUSAGE, "study: eps must be in (0, 1) (got %g)", x);
        break;
    }
    return BN_OK;
}

/* The study's surfaces: the scene's materials, their names and areas (m^2). */
static bn_status bn__study_surfaces(const char *path, const bn_load_opts *load, bn_study_result *res,
                                    bn_error *err)
{
    bn_scene *probe = NULL;
    const bn_material *mats;
    const bn_face *f;
    size_t nm, nf;
    double u;
    bn_status st = bn_scene_load(path, load, &probe, err);
    if (st != BN_OK)
        return st;
    bn_scene_lights(probe, &nm);
    if (nm > 0) {   /* the sweeps' reference and truncations are of E alone */
        bn_scene_destroy(probe);
        return bn_error_set(err, BN_EUSAGE, "%s: %zu punctual lights: a study's sweeps take their light from emitting "
                            "surfaces only (solve, bounces, bake and crosscheck read punctual lights)", path, nm);
    }
    mats = bn_scene_materials(probe, &nm);
    f = bn_scene_faces(probe, &nf);
    u = bn_unit_to_metres(bn_scene_unit(probe));
    res->nsurfaces = nm;
    res->surface = bn__calloc(nm + 1, sizeof *res->surface);
    res->surface_area = bn__calloc(nm + 1, sizeof(double));
    if (!res->surface || !res->surface_area) {
        bn_scene_destroy(probe);
        return bn_error_set(err, BN_ENOMEM, "study: out of memory");
    }
    for (size_t m = 0; m < nm; m++)
        snprintf(res->surface[m], BN_NAME_MAX, "%s", mats[m].name);
    for (size_t i = 0; i < nf; i++)
        if (f[i].material < nm)
            res->surface_area[f[i].material] += f[i].area * u * u;
    bn_scene_destroy(probe);
    return BN_OK;
}

static bn_status bn__study_run_body(const char *path, const bn_study_opts *o_in, bn_study_result *res, bn_error *err)
{
    bn_study_opts oo = *o_in, *o = &oo;
    bn__warnings W;
    bn__study S;
    bn_status st;
    memset(res, 0, sizeof *res);
    memset(&S, 0, sizeof S);
    memset(&W, 0, sizeof W);
    W.out = o_in->ff.log;
    oo.ff.log = (bn_log){bn__gather, &W, o_in->ff.log.quiet};
    oo.solve.log_sink = (bn_log){bn__gather, &W, o_in->solve.log_sink.quiet};
    S.o = o;
    S.path = path;
    S.res = res;
    S.load = o->load;
    S.load.log.fn = bn__drop_log;
    res->param = o->param;
    res->target = o->target > 0 ? o->target : 0.01;
    res->metric_patch = o->metric_patch;
    res->t_radiosity = res->t_trace = res->ratio = res->best_radiosity = res->best_trace = NAN;
    res->fine_target = res->t_radiosity_fine = res->t_trace_fine = res->ratio_fine = NAN;
    res->ref_error = res->ref_error_patch = res->ref_order = res->ref_error_raw = NAN;
    if (!o->values || o->nvalues == 0)
        return bn_error_set(err, BN_EUSAGE, "study: `vary` needs at least one value");
    for (size_t v = 0; v < o->nvalues; v++)
        if ((st = bn__study_check_value(o->param, o->values[v], err)) != BN_OK)
            return st;
    if ((st = bn__study_surfaces(path, &o->load, res, err)) != BN_OK) {
        bn_study_result_free(res);
        return st;
    }
    if (o->param == BN_STUDY_BOUNCES || o->param == BN_STUDY_MAX_ITER || o->param == BN_STUDY_TOL)
        st = bn__study_operator(&S, err);
    else
        st = bn__study_settings(&S, err);
    bn__warnings_flush(&W);
    if (st != BN_OK)
        bn_study_result_free(res);
    return st;
}

bn_status bn_study_run(const char *path, const bn_study_opts *o, bn_study_result *res, bn_error *err)
{
    int prev = bn__threads_begin(o->threads);   /* every phase inherits it */
    bn_status st = bn__study_run_body(path, o, res, err);
    bn__threads_end(prev);
    return st;
}

void bn_study_result_free(bn_study_result *res)
{
    if (!res)
        return;
    free(res->ref_surface_mean);
    for (size_t i = 0; i < res->nrows; i++)
        free(res->rows[i].err_surface);
    free(res->rows);
    for (size_t i = 0; i < res->ncurves; i++) {
        free(res->curves[i].t);
        free(res->curves[i].err);
    }
    free(res->curves);
    free(res->surface);
    free(res->surface_area);
    memset(res, 0, sizeof *res);
}
