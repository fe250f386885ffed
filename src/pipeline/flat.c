/* The flat C API for bindings (include/bounce/flat.h): the pipeline behind plain types. */
#include "bounce/flat.h"
#include "bounce/pipeline.h"
#include "bounce/bake.h"
#include "bounce/image.h"
#include "bounce/gather.h"
#include "base/internal.h"
#include "pipeline/flat_internal.h"

#include <math.h>

#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>


/* SIGINT during a call (opts.sigint): the library's interrupt flag, which every long loop polls. */
static void bn__flat_on_sigint(int sig)
{
    (void)sig;
    bn_interrupt_raise(BN_EINTR);
}


void bn__flat_sig_begin(bn__flat_sig *s, int want)
{
    struct sigaction sa;
    s->on = 0;
    bn_interrupt_raise(BN_OK);
    if (!want)
        return;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = bn__flat_on_sigint;
    sigemptyset(&sa.sa_mask);
    s->on = sigaction(SIGINT, &sa, &s->old) == 0;
}

void bn__flat_sig_end(bn__flat_sig *s)
{
    if (s->on)
        sigaction(SIGINT, &s->old, NULL);
    bn_interrupt_raise(BN_OK);
}

size_t bn_flat_opts_size(void) { return sizeof(bn_flat_opts); }

void bn_flat_opts_default(bn_flat_opts *o)
{
    bn_solve_opts so;
    bn_hierarchy_opts ho;
    bn_solve_opts_default(&so);
    bn_hierarchy_opts_default(&ho);
    memset(o, 0, sizeof *o);
    o->bounces = so.bounces;
    o->tol = so.tol;
    o->eps = ho.eps;
    o->quiet = 1;
}

bn_status bn__flat_fail(bn_status st, const char *text, char *msg, size_t msglen)
{
    if (msg && msglen)
        snprintf(msg, msglen, "%s", text);
    return st;
}

/* A name of a vocabulary (NULL: the first, the default) to its enum value, or BN_EUSAGE naming the
 * parameter, the value and the choices. */
static bn_status bn__flat_name(const char *what, const char *name, const char *names, int (*index)(const char *),
                               int *out, char *msg, size_t msglen)
{
    char t[200];
    *out = name ? index(name) : 0;
    if (*out >= 0)
        return BN_OK;
    snprintf(t, sizeof t, "%s '%s' is not one of %s", what, name, names);
    return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
}

static int bn__bake_mesh_index(const char *s)
{
    bn_bake_mesh m;
    return bn_bake_mesh_parse(s, &m) == 0 ? (int)m : -1;
}

static int bn__gather_index(const char *s)
{
    bn_gather_mode m;
    return bn_gather_mode_parse(s, &m) == 0 ? (int)m : -1;
}

/* The vocabularies a binding offers, by the names of their parameters. */
#define BN__FLAT_VOCABULARIES(X)                                                                         \
    X("method", bn_solve_method_names) X("transport", bn_pipeline_transports)                            \
    X("storage", bn_storage_names) X("precision", bn_precision_names) X("ff", bn_ff_method_names)        \
    X("visibility", bn_ff_visibility_names) X("unit", bn_unit_names) X("stop", bn_solve_stop_names)      \
    X("mesh", bn_bake_mesh_names) X("gather", bn_gather_mode_names) X("strategy", bn_trace_strategy_names) \
    X("model", bn_trace_model_names) X("scene_options", bn__flat_scene_options)                             \
    X("solve_options", bn__flat_solve_options) X("image_options", bn__flat_image_options)                   \
    X("bake_options", bn__flat_bake_options)
#define BN__FLAT_VOCAB(k, f) {k, f},

const char *bn_flat_names(const char *vocabulary)
{
    static const struct {
        const char *key;
        const char *(*names)(void);
    } table[] = {BN__FLAT_VOCABULARIES(BN__FLAT_VOCAB)};
    for (size_t i = 0; vocabulary && i < sizeof table / sizeof *table; i++)
        if (strcmp(vocabulary, table[i].key) == 0)
            return table[i].names();
    return NULL;
}

/* The flat options' own ranges (those with no counterpart in the library's structs); the rest is
 * checked by bn_pipeline_opts_check / bn_solve_opts_check, once for every front end. */
static bn_status bn__flat_ranges(const bn_flat_opts *o, char *msg, size_t msglen)
{
    char t[160];
    if (!(o->tol > 0 && isfinite(o->tol)))
        snprintf(t, sizeof t, "tol %g is not a finite tolerance > 0 (the solve stops at tol x the brightest emission)",
                 o->tol);
    else if (!(o->patch_size >= 0 && isfinite(o->patch_size)))
        snprintf(t, sizeof t, "patch_size %g is not a finite length >= 0 (0: from patches)", o->patch_size);
    else
        return BN_OK;
    return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
}

static int bn__stop_index(const char *s)
{
    bn_solve_stop v;
    return bn_solve_stop_parse(s, &v) == 0 ? (int)v : -1;
}

static int bn__precision_index(const char *s)
{
    bn_precision v;
    return !strcmp(s, "auto") ? 0 : bn_precision_parse(s, &v) == 0 ? (int)v + 1 : -1;
}

static int bn__ff_index(const char *s)
{
    bn_ff_method v;
    return bn_ff_method_parse(s, &v) == 0 ? (int)v : -1;
}

static int bn__storage_index(const char *s) { return bn_storage_exists(s) ? 0 : -1; }

/* The command line's other solve options (max_iter, atol, stop, seed, precision, storage, cache, ff):
 * names checked here, values by bn_pipeline_opts_check. */
static bn_status bn__flat_more(const bn_flat_opts *o, bn_pipeline_opts *po, char *msg, size_t msglen)
{
    int v;
    if (o->max_iter)
        po->solve.max_iter = o->max_iter;
    po->solve.atol = o->atol;
    if (o->seed)
        po->ff.seed = o->seed;
    po->ff.cache_path = o->cache;
    if (o->stop && bn__flat_name("stop", o->stop, bn_solve_stop_names(), bn__stop_index, &v, msg, msglen) != BN_OK)
        return BN_EUSAGE;
    if (o->stop)
        po->solve.stop = (bn_solve_stop)v;
    if (o->precision && bn__flat_name("precision", o->precision, "auto|float|double", bn__precision_index, &v, msg,
                                      msglen) != BN_OK)
        return BN_EUSAGE;
    if (o->precision && v > 0) {
        po->ff.precision = (bn_precision)(v - 1);
        po->auto_precision = 0;
    }
    if (o->storage && bn__flat_name("storage", o->storage, bn_storage_names(), bn__storage_index, &v, msg, msglen))
        return BN_EUSAGE;
    if (o->storage)
        po->ff.storage = o->storage;
    if (o->ff && bn__flat_name("ff", o->ff, bn_ff_method_names(), bn__ff_index, &v, msg, msglen) != BN_OK)
        return BN_EUSAGE;
    if (o->ff)
        po->ff.method = (bn_ff_method)v;
    return BN_OK;
}

/* A solver by its name (bn_solve_method_names). */
static bn_status bn__flat_method(const char *name, bn_solve_method *out, char *msg, size_t msglen)
{
    char t[192];
    if (bn_solve_method_parse(name, out) == 0)
        return BN_OK;
    snprintf(t, sizeof t, "method '%.64s' is not one of auto|%s", name, bn_solve_method_names());
    return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
}

/* The pipeline options from the flat ones (strings checked; transport copied into f). */
bn_status bn__flat_popts(const bn_flat_opts *o, bn_flat *f, char *msg, size_t msglen)
{
    bn_pipeline_opts *po = &f->po;
    bn_pipeline_opts_default(po);
    if (o->unit && bn_unit_parse(o->unit, &po->load.unit) != 0) {
        char t[128];
        snprintf(t, sizeof t, "unit '%s' is not one of m, cm, mm", o->unit);
        return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
    }
    po->method_auto = 1;
    if (o->method && strcmp(o->method, "auto") != 0) {
        bn_status st = bn__flat_method(o->method, &po->solve.method, msg, msglen);
        if (st != BN_OK)
            return st;
        po->method_auto = 0;
    }
    if (o->transport) {
        if (!bn_pipeline_transport_exists(o->transport)) {
            char t[192];
            snprintf(t, sizeof t, "transport '%.64s' is not one of %s", o->transport, bn_pipeline_transports());
            return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
        }
        snprintf(f->transport_opt, sizeof f->transport_opt, "%s", o->transport);
        po->transport = f->transport_opt;
    }
    /* the hierarchy's ff is copied from po->ff */
    if (o->visibility && bn_ff_visibility_parse(o->visibility, &po->ff.exact_visibility) != 0) {
        char t[160];
        snprintf(t, sizeof t, "visibility '%.64s' is not one of %s", o->visibility, bn_ff_visibility_names());
        return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
    }
    if (bn__flat_ranges(o, msg, msglen) != BN_OK || bn__flat_more(o, po, msg, msglen) != BN_OK)
        return BN_EUSAGE;
    po->solve.bounces = o->bounces < 0 ? -1 : o->bounces;
    po->solve.tol = o->tol;
    if (o->patch_size > 0)
        po->mesh.patch_size = o->patch_size;
    else if (o->patches)
        po->mesh.target_patches = o->patches;
    po->mesh_auto = !(o->patch_size > 0) && !o->patches;
    po->hier.eps = o->eps;
    po->threads = o->threads;
    po->keep_rt = 1;   /* images (bn_flat_images) */
    po->ff.quiet = po->hier.quiet = po->solve.quiet = o->quiet;
    po->load.log.quiet = po->ff.log.quiet = po->hier.log.quiet = po->solve.log_sink.quiet = 1;   /* warnings only */
    bn__flat_call_default(&f->call);
    return bn__flat_more_pipeline(o->more, 0, f, po, msg, msglen);
}

/* The solver's monitor: keeps every row (a failed allocation drops the row, never the solve). */
static int bn__flat_monitor(void *user, const bn_solve_row *row, const double *L)
{
    bn_flat *f = user;
    (void)L;
    if (f->nhist == f->caphist) {
        size_t cap = f->caphist ? 2 * f->caphist : 64;
        double *h = bn__realloc_array(f->hist, cap, BN_FLAT_HISTORY * sizeof(double));
        if (!h)
            return 0;
        f->hist = h;
        f->caphist = cap;
    }
    double *r = f->hist + BN_FLAT_HISTORY * f->nhist++;
    r[0] = (double)row->iteration;
    r[1] = row->residual_max;
    r[2] = row->residual_rms;
    r[3] = row->change;
    r[4] = row->bound;
    r[5] = row->error_bound;
    r[6] = row->seconds;
    return 0;
}

size_t bn_flat_history(const bn_flat *f, const double **rows)
{
    if (rows)
        *rows = f->hist;
    return f->nhist;
}

/* Runs fn(f) with SIGINT caught when asked. */
static bn_status bn__flat_stage(bn_flat *f, int sigint, int stage, const char *path, bn_error *err)
{
    bn__flat_sig sg;
    bn_status st;
    bn__flat_sig_begin(&sg, sigint);
    st = stage == 0 ? bn_pipeline_scene(path, &f->po, &f->p, err)
         : stage == 1 ? bn_pipeline_operator(&f->po, &f->p, err)
                      : bn_pipeline_solve(&f->po, &f->p, err);
    bn__flat_sig_end(&sg);
    return st;
}

bn_status bn_flat_load(const char *path, const bn_flat_opts *o, bn_flat **out, char *msg, size_t msglen)
{
    bn_flat_opts d;
    bn_error err;
    bn_flat *f;
    bn_status st;
    if (out)
        *out = NULL;
    if (msg && msglen)
        msg[0] = '\0';
    if (!out || !path)
        return bn__flat_fail(BN_EUSAGE, "path and out are required", msg, msglen);
    if (!o) {
        bn_flat_opts_default(&d);
        o = &d;
    }
    if (!(f = bn__calloc(1, sizeof *f)))
        return bn__flat_fail(BN_ENOMEM, "out of memory", msg, msglen);
    if ((st = bn__flat_popts(o, f, msg, msglen)) != BN_OK) {
        free(f);
        return st;
    }
    f->sigint = o->sigint;
    bn_error_clear(&err);
    st = bn__flat_stage(f, o->sigint, 0, path, &err);
    if (st == BN_OK && !(f->p.E = bn__malloc_array(3 * f->p.n + 1, sizeof(double))))
        st = bn_error_set(&err, BN_ENOMEM, "out of memory");
    if (st != BN_OK) {
        bn__flat_fail(st, err.msg, msg, msglen);
        bn_pipeline_free(&f->p);
        free(f);
        return st;
    }
    bn_scene_patch_emission(f->p.scene, f->p.E);
    *out = f;
    return BN_OK;
}

bn_status bn_flat_operator(bn_flat *f, char *msg, size_t msglen)
{
    bn_error err;
    bn_status st;
    if (msg && msglen)
        msg[0] = '\0';
    if (f->p.k)
        return BN_OK;
    bn_error_clear(&err);
    st = bn__flat_stage(f, f->sigint, 1, NULL, &err);
    if (st != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    snprintf(f->transport, sizeof f->transport, "%s", bn_transport_name(f->p.k));
    return BN_OK;
}

bn_status bn_flat_solve(const char *path, const bn_flat_opts *o, bn_flat **out, char *msg, size_t msglen)
{
    bn_flat_opts d;
    bn_error err;
    bn_flat *f = NULL;
    bn_status st;
    if (out)
        *out = NULL;
    if (!out)
        return bn__flat_fail(BN_EUSAGE, "bn_flat_solve: out is required", msg, msglen);
    if (!o) {
        bn_flat_opts_default(&d);
        o = &d;
    }
    if ((st = bn_flat_load(path, o, &f, msg, msglen)) != BN_OK)
        return st;
    if ((st = bn_flat_operator(f, msg, msglen)) != BN_OK) {
        bn_flat_free(f);
        return st;
    }
    bn_error_clear(&err);
    f->po.solve.monitor = bn__flat_monitor;
    f->po.solve.monitor_user = f;
    st = bn__flat_stage(f, o->sigint, 2, NULL, &err);
    if (st != BN_OK && st != BN_ENOTCONV) {
        bn__flat_fail(st, err.msg, msg, msglen);
        bn_flat_free(f);
        return st;
    }
    if (st == BN_ENOTCONV)
        bn__flat_fail(st, err.msg, msg, msglen);
    *out = f;
    return st;
}

/* The edits of bn_flat_relight: material i's rho and Le rows (n x 3; NULL, or a row of NaN: not set). */
static bn_status bn__flat_edits(size_t n, const char *const *materials, const double *rho, const double *Le,
                                bn_material_edit *e, bn_error *err)
{
    for (size_t i = 0; i < n; i++) {
        memset(&e[i], 0, sizeof e[i]);
        if (!materials || !materials[i] || strlen(materials[i]) >= sizeof e[i].material)
            return bn_error_set(err, BN_EUSAGE, "relight: material %zu has no name (or one above %d bytes)", i,
                                BN_NAME_MAX - 1);
        strcpy(e[i].material, materials[i]);
        e[i].has_rho = rho && !(isnan(rho[3 * i]) && isnan(rho[3 * i + 1]) && isnan(rho[3 * i + 2]));
        e[i].has_Le = Le && !(isnan(Le[3 * i]) && isnan(Le[3 * i + 1]) && isnan(Le[3 * i + 2]));
        for (int c = 0; c < 3; c++) {
            e[i].rho[c] = e[i].has_rho ? rho[3 * i + c] : 0;
            e[i].Le[c] = e[i].has_Le ? Le[3 * i + c] : 0;
        }
    }
    return BN_OK;
}

bn_status bn_flat_relight(bn_flat *f, size_t n, const char *const *materials, const double *rho, const double *Le,
                          int refine, char *msg, size_t msglen)
{
    bn_material_edit *e = bn__malloc_array(n + 1, sizeof *e);
    bn__flat_sig sg;
    bn_error err;
    bn_status st;
    bn_error_clear(&err);
    if (!f || !f->p.scene || !f->p.k || !f->p.res.L)
        st = bn_error_set(&err, BN_EUSAGE, "relight: not a solved scene (a scene file's, with its K)");
    else if (!e)
        st = bn_error_set(&err, BN_ENOMEM, "out of memory");
    else
        st = bn__flat_edits(n, materials, rho, Le, e, &err);
    if (st == BN_OK) {
        f->nhist = 0;   /* the new solve's monitor */
        bn__flat_sig_begin(&sg, f->sigint);
        st = bn_pipeline_relight(&f->po, &f->p, e, n, refine, &err);
        bn__flat_sig_end(&sg);
    }
    free(e);
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}

bn_status bn_flat_solve_loaded(bn_flat *f, const bn_flat_opts *o, char *msg, size_t msglen)
{
    bn_flat tmp;
    bn_error err;
    bn_status st;
    memset(&tmp, 0, sizeof tmp);
    if (!f || !f->p.scene || !o)
        return bn__flat_fail(BN_EUSAGE, "solve: no loaded scene (or no options)", msg, msglen);
    if ((st = bn__flat_popts(o, &tmp, msg, msglen)) != BN_OK ||   /* checked as at load; the solver's taken */
        (st = bn__flat_more_pipeline(o->more, 1, &tmp, &tmp.po, msg, msglen)) != BN_OK)
        return st;
    f->po.solve.symmetric = tmp.po.solve.symmetric;
    f->po.solve.singular_threshold = tmp.po.solve.singular_threshold;
    f->po.solve.method = tmp.po.solve.method;
    f->po.method_auto = tmp.po.method_auto;
    f->po.solve.bounces = tmp.po.solve.bounces;
    f->po.solve.tol = tmp.po.solve.tol;
    f->po.solve.atol = tmp.po.solve.atol;
    f->po.solve.max_iter = tmp.po.solve.max_iter;
    f->po.solve.stop = tmp.po.solve.stop;
    f->po.threads = tmp.po.threads;
    f->po.solve.quiet = tmp.po.solve.quiet;
    if ((st = bn_flat_operator(f, msg, msglen)) != BN_OK)
        return st;
    bn_solve_result_free(&f->p.res);
    free(f->p.rest);
    f->p.rest = NULL;
    f->nhist = 0;
    f->po.solve.monitor = bn__flat_monitor;
    f->po.solve.monitor_user = f;
    bn_error_clear(&err);
    st = bn__flat_stage(f, f->sigint, 2, NULL, &err);
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}

void bn_flat_ff_diagnostics(const bn_flat *f, double out[12])
{
    const bn_ff_diagnostics *d = &f->p.ff;
    int built = f->p.k != NULL;
    double v[12] = {d->row_sum_min, d->row_sum_max, d->row_sum_rms_dev, d->reciprocity_residual, d->k_norm_inf,
                    d->occluded_fraction, (double)d->rays, (double)d->nonzeros, (double)d->bytes, d->seconds,
                    (double)d->rows_above_one, d->row_sum_tol};
    for (int k = 0; k < 12; k++)
        out[k] = built ? v[k] : NAN;
}

void bn_flat_free(bn_flat *f)
{
    if (!f)
        return;
    bn_pipeline_free(&f->p);
    free(f->op);
    free(f->hist);
    free(f);
}

size_t bn_flat_patches(const bn_flat *f) { return f->p.n; }
int bn_flat_terms(const bn_flat *f) { return f->p.res.nterms; }
const double *bn_flat_L(const bn_flat *f) { return f->p.res.L; }
const double *bn_flat_term(const bn_flat *f, int k)
{
    return k >= 0 && k < f->p.res.nterms ? f->p.res.terms[k] : NULL;
}
const double *bn_flat_rest(const bn_flat *f) { return f->p.rest; }
const double *bn_flat_emission(const bn_flat *f) { return f->p.E; }
const char *bn_flat_stop_reason(const bn_flat *f) { return bn_stop_reason_name(f->p.res.reason); }
const char *bn_flat_method(const bn_flat *f) { return bn_solve_method_name(f->p.method_used); }
size_t bn_flat_iterations(const bn_flat *f) { return f->p.res.iterations; }
double bn_flat_residual(const bn_flat *f) { return f->p.res.residual_max; }
double bn_flat_relight_gain(const bn_flat *f) { return f->p.relight_gain; }
const char *bn_flat_transport(const bn_flat *f) { return f->transport; }

void bn_flat_patch_data(const bn_flat *f, double *area, double *normal, double *centroid, double *reflectance,
                        size_t *face)
{
    size_t n;
    if (!f->p.scene)
        return;
    const bn_patch *pa = bn_scene_patches(f->p.scene, &n);
    if (reflectance)
        bn_scene_patch_reflectance(f->p.scene, reflectance);
    for (size_t i = 0; i < n; i++) {
        if (area)
            area[i] = pa[i].area;
        if (face)
            face[i] = pa[i].face;
        for (int c = 0; c < 3; c++) {
            if (normal)
                normal[3 * i + c] = pa[i].normal[c];
            if (centroid)
                centroid[3 * i + c] = pa[i].centroid[c];
        }
    }
}

bn_status bn_flat_form_factors(const bn_flat *f, double *F, char *msg, size_t msglen)
{
    bn_error err;
    bn_status st;
    bn_error_clear(&err);
    if (!f->p.k)
        return bn__flat_fail(BN_EUSAGE, "no operator", msg, msglen);
    st = bn_transport_to_dense(f->p.k, F, &err);
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}

/* Row i's nonzero stored entries into cols/vals (room for N); *count set. */
static bn_status bn__flat_row_nonzeros(const bn_flat *f, size_t i, size_t *cols, double *vals, size_t *count,
                                       bn_error *err)
{
    size_t m = 0, k;
    bn_status st = bn_transport_row_entries(f->p.k, i, cols, vals, count, err);
    for (k = 0; st == BN_OK && k < *count; k++)
        if (vals[k] != 0) {
            cols[m] = cols[k];
            vals[m++] = vals[k];
        }
    *count = m;
    return st;
}

bn_status bn_flat_form_factors_csr(const bn_flat *f, size_t *indptr, size_t *indices, double *data, size_t *nnz,
                                   char *msg, size_t msglen)
{
    bn_error err;
    bn_status st = BN_OK;
    size_t n = f ? f->p.n : 0, *cols = NULL, have = nnz ? *nnz : 0, total = 0;
    double *vals = NULL;
    bn_error_clear(&err);
    if (!f || !f->p.k || !indptr || !nnz)
        return bn__flat_fail(BN_EUSAGE, "no operator (or no indptr, nnz)", msg, msglen);
    cols = bn__malloc_array(n + 1, sizeof *cols);
    vals = bn__malloc_array(n + 1, sizeof *vals);
    if (!cols || !vals)
        st = bn_error_set(&err, BN_ENOMEM, "out of memory for a row of %zu patches", n);
    indptr[0] = 0;
    for (size_t i = 0; st == BN_OK && i < n; i++) {
        size_t c;
        st = bn__flat_row_nonzeros(f, i, cols, vals, &c, &err);
        for (size_t k = 0; st == BN_OK && indices && data && k < c && total + k < have; k++) {
            indices[total + k] = cols[k];
            data[total + k] = vals[k];
        }
        total += c;
        indptr[i + 1] = total;
    }
    free(cols);
    free(vals);
    if (st == BN_OK && indices && data && total > have)
        st = bn_error_set(&err, BN_EUSAGE, "F has %zu nonzero entries, the arrays room for %zu", total, have);
    *nnz = total;
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}

bn_status bn_flat_apply(const bn_flat *f, int with_rho, const double *x, double *y, char *msg, size_t msglen)
{
    bn_error err;
    bn_status st;
    bn_error_clear(&err);
    if (!f || !f->p.k || !x || !y || x == y)
        return bn__flat_fail(BN_EUSAGE, "apply: no operator, or x and y missing or the same array", msg, msglen);
    st = with_rho ? bn_transport_apply(f->p.k, x, y, &err) : bn_transport_apply_F(f->p.k, x, y, &err);
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}

/* ---- a caller's operator ---- */

typedef struct bn__flat_op {
    bn_flat_apply_fn fn;
    bn_flat_row_fn row;
    void *user;
} bn__flat_op;

static bn_status bn__flat_op_apply(void *ctx, const double *x, double *y, bn_error *err)
{
    bn__flat_op *op = ctx;
    int rc = op->fn(op->user, x, y);
    if (rc != 0)
        return bn_error_set(err, BN_EINPUT, "the operator failed (its apply returned %d)", rc);
    return bn_interrupted() != BN_OK ? bn_error_set(err, bn_interrupted(), "interrupted") : BN_OK;
}

static bn_status bn__flat_op_row(void *ctx, size_t i, const double *x, double out[3], bn_error *err)
{
    bn__flat_op *op = ctx;
    int rc = op->row(op->user, i, x, out);
    if (rc != 0)
        return bn_error_set(err, BN_EINPUT, "the operator failed (its row %zu returned %d)", i, rc);
    return BN_OK;
}

static const bn_transport_ops bn__flat_op_ops = {.name = "caller", .caps = 0, .apply = bn__flat_op_apply};
static const bn_transport_ops bn__flat_op_rows = {
    .name = "caller", .caps = BN_OP_ROWS, .apply = bn__flat_op_apply, .row = bn__flat_op_row};

/* The solve options of an operator solve, checked: BN_OK, or the failure with msg set. */
static bn_status bn__flat_op_opts(size_t n, int rows, const bn_flat_opts *o, bn_solve_opts *so, char *msg, size_t msglen)
{
    bn_error err;
    bn_status st;
    bn_pipeline_opts more;   /* max_iter, atol, stop as for a scene's solve */
    bn_error_clear(&err);
    bn_pipeline_opts_default(&more);
    if (bn__flat_ranges(o, msg, msglen) != BN_OK || bn__flat_more(o, &more, msg, msglen) != BN_OK)
        return BN_EUSAGE;
    bn_solve_opts_default(so);
    so->max_iter = more.solve.max_iter;
    so->atol = more.solve.atol;
    so->stop = more.solve.stop;
    so->method = rows ? BN_SOLVE_GAUSS_SEIDEL : BN_SOLVE_JACOBI;
    if (o->method && strcmp(o->method, "auto") != 0 && (st = bn__flat_method(o->method, &so->method, msg, msglen)) != BN_OK)
        return st;
    so->bounces = o->bounces < 0 ? -1 : o->bounces;
    so->tol = o->tol;
    so->quiet = o->quiet;
    so->log_sink.quiet = 1;
    so->threads = o->threads;
    if (n > BN_PIPELINE_MAX_PATCHES)
        bn_error_set(&err, BN_EUSAGE, "patches %zu is above %.0e (a negative number converted?)", n,
                     (double)BN_PIPELINE_MAX_PATCHES);
    else if (bn_solve_opts_check(so, &err) == BN_OK)
        err.status = BN_OK;
    return err.status != BN_OK ? bn__flat_fail(err.status, err.msg, msg, msglen) : BN_OK;
}

/* The result holding a copy of E and the caller's operator as K (no reflectance on top: K is the
 * caller's); *out NULL on failure. */
static bn_status bn__flat_op_make(size_t n, const double *E, bn_flat_apply_fn apply, bn_flat_row_fn row, void *user,
                                  bn_flat **out, bn_error *err)
{
    bn_flat *f = bn__calloc(1, sizeof *f);
    bn__flat_op *op = bn__malloc_array(1, sizeof *op);
    double *ones = bn__malloc_array(3 * n, sizeof(double));
    bn_status st = BN_ENOMEM;
    *out = NULL;
    if (f)
        bn__flat_call_default(&f->call);
    if (f && op && ones && (f->p.E = bn__malloc_array(3 * n, sizeof(double)))) {
        for (size_t i = 0; i < 3 * n; i++)
            ones[i] = 1;
        memcpy(f->p.E, E, 3 * n * sizeof(double));
        *op = (bn__flat_op){.fn = apply, .row = row, .user = user};
        st = bn_transport_create(n, ones, row ? &bn__flat_op_rows : &bn__flat_op_ops, op, &f->p.k, err);
    } else
        bn_error_set(err, BN_ENOMEM, "out of memory");
    free(ones);
    if (st != BN_OK) {
        free(op);
        bn_flat_free(f);
        return st;
    }
    f->op = op;
    f->p.n = n;
    snprintf(f->transport, sizeof f->transport, "caller");
    *out = f;
    return BN_OK;
}

bn_status bn_flat_solve_operator(size_t n, const double *E, bn_flat_apply_fn apply, bn_flat_row_fn row, void *user,
                                 const bn_flat_opts *o, bn_flat **out, char *msg, size_t msglen)
{
    bn_flat_opts d;
    bn_solve_opts so;
    bn_error err;
    bn_flat *f;
    bn_status st;
    if (out)
        *out = NULL;
    if (msg && msglen)
        msg[0] = '\0';
    bn_error_clear(&err);
    if (!out || !E || !apply)
        return bn__flat_fail(BN_EUSAGE, "an operator solve needs E, apply and a result pointer", msg, msglen);
    if (n == 0)
        return bn__flat_fail(BN_EUSAGE, "patches 0: an operator needs at least one patch", msg, msglen);
    if (!o) {
        bn_flat_opts_default(&d);
        o = &d;
    }
    if ((st = bn__flat_op_opts(n, row != NULL, o, &so, msg, msglen)) != BN_OK)
        return st;
    if ((st = bn__flat_op_make(n, E, apply, row, user, &f, &err)) != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    bn__flat_sig sg;
    so.monitor = bn__flat_monitor;
    so.monitor_user = f;
    bn__flat_sig_begin(&sg, o->sigint);
    st = bn_solve(f->p.k, f->p.E, &so, &f->p.res, &err);
    bn__flat_sig_end(&sg);
    f->p.method_used = so.method;
    if (st != BN_OK && st != BN_ENOTCONV) {
        bn__flat_fail(st, err.msg, msg, msglen);
        bn_flat_free(f);
        return st;
    }
    if (f->p.res.nterms > 0 && (f->p.rest = bn__malloc_array(3 * n, sizeof(double))))   /* rest = L - the kept terms */
        bn_layers_rest((const double *const *)f->p.res.terms, f->p.res.nterms, f->p.res.L, 3 * n, f->p.rest);
    if (st == BN_ENOTCONV)
        bn__flat_fail(st, err.msg, msg, msglen);
    *out = f;
    return st;
}

/* The bake's vertex values by the final gather (gather "final"; the element mesh refined up to `vertices`
 * (< 0: the default budget)), or the patches' values ("none", or the input mesh). */
static bn_status bn__flat_bake_gather(const bn_flat *f, bn_bake *b, int input_mesh, const char *gather,
                                      long long vertices, bn_bake_layer *layers, size_t nl, double **vbuf,
                                      char *msg, size_t msglen)
{
    int mode;
    bn_error err;
    bn_bake_gather_opts go;
    bn_status st = bn__flat_name("bake: gather", gather, bn_gather_mode_names(), bn__gather_index, &mode, msg, msglen);
    if (st == BN_OK && vertices >= 0 && (mode != BN_GATHER_FINAL || input_mesh || f->call.flat))
        return bn__flat_fail(BN_EUSAGE, "bake: `vertices`: the refined mesh is the element mesh's with the gather at its "
                             "vertices (not with gather none, the input mesh or flat)", msg, msglen);
    if (st != BN_OK || mode != BN_GATHER_FINAL)
        return st;
    bn_bake_gather_opts_default(&go);
    go.gather_rays = f->call.gather_rays;
    go.tol = f->call.bake_tol;
    if (f->call.flat)
        vertices = 0;   /* the flat bake's own vertices */
    if (vertices >= 0 || input_mesh)   /* the input mesh: gathered at its own vertices, as `bounce bake` does */
        go.max_vertices = input_mesh ? 0 : (size_t)vertices;
    go.seed = f->po.ff.seed;
    go.threads = f->po.threads;
    go.quiet = 1;
    bn_error_clear(&err);
    st = bn_pipeline_bake_gather(&f->p, b, &go, layers, nl, vbuf, &err);
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}

bn_status bn_flat_bake(const bn_flat *f, const char *out, int per_bounce, const char *mesh, int ldr, double exposure_ev,
                       double crease_deg, const char *gather, long long vertices, const char *caller, char *msg,
                       size_t msglen)
{
    int nb = f->p.res.nterms - 1;
    size_t nl = nb >= 0 ? (size_t)bn_layer_count(nb) : 1;
    bn_bake_layer layers[72];
    char names[72][16], solver[160], patches[32], tol[48];
    bn_bake *b = NULL;
    bn_bake_write_opts wo;
    bn_error err;
    bn_status st;
    double *vbuf = NULL;
    if (!f->p.scene)
        return bn__flat_fail(BN_EUSAGE, "bake: this result has no scene (a caller's operator)", msg, msglen);
    if (nl > 72)
        return bn__flat_fail(BN_EUSAGE, "bake: too many terms", msg, msglen);
    int input_mesh;
    st = bn__flat_name("bake: mesh", mesh, bn_bake_mesh_names(), bn__bake_mesh_index, &input_mesh, msg, msglen);
    if (st != BN_OK)
        return st;
    layers[0] = (bn_bake_layer){"L", f->p.res.L, NULL};
    for (size_t l = 1; l < nl; l++) {
        int layer = (int)l - 1;
        bn_layer_name(layer, nb, names[l], sizeof names[l]);
        layers[l] = (bn_bake_layer){names[l], layer <= nb ? f->p.res.terms[layer] : f->p.rest, NULL};
    }
    bn_error_clear(&err);
    if (f->call.flat && crease_deg > 0)
        return bn__flat_fail(BN_EUSAGE, "bake: `flat` and `crease`: a flat bake shares no vertices, so no crease applies",
                             msg, msglen);
    st = bn_bake_create(f->p.scene, f->call.flat ? BN_BAKE_FLAT : crease_deg > 0 ? crease_deg : BN_BAKE_DEFAULT_CREASE,
                        &b, &err);
    if (st != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    if (f->p.rt && !f->call.flat)
        bn_bake_exclude_enclosed(b, f->p.rt);   /* as `bounce bake` */
    if ((st = bn__flat_bake_gather(f, b, input_mesh, gather, vertices, layers, nl, &vbuf, msg, msglen)) != BN_OK) {
        bn_bake_destroy(b);
        free(vbuf);
        return st;
    }
    nl = per_bounce ? nl : 1;
    snprintf(solver, sizeof solver, "%s: %s after %zu iterations, residual %.3g", bn_solve_method_name(f->p.method_used),
             bn_stop_reason_name(f->p.res.reason), f->p.res.iterations, f->p.res.residual_max);
    snprintf(patches, sizeof patches, "%zu", f->p.n);
    snprintf(tol, sizeof tol, "K: %s", f->transport);
    {
        bn_attr attrs[] = {{"caller", caller ? caller : "bn_flat_bake"}, {"scene", bn_scene_path(f->p.scene)},
                           {"solver", solver}, {"patches", patches}, {"operator", tol}};
        memset(&wo, 0, sizeof wo);
        wo.input_mesh = input_mesh;
        wo.ldr = ldr;
        wo.colour_sets = !f->call.no_colour_sets;   /* as bounce bake writes them */
        wo.exposure_ev = isfinite(exposure_ev) ? exposure_ev : bn_bake_auto_exposure(f->p.res.L, f->p.n);
        wo.attrs = attrs;
        wo.nattrs = sizeof attrs / sizeof attrs[0];
        st = bn_bake_write(b, out, layers, nl, &wo, &err);
    }
    bn_bake_destroy(b);
    free(vbuf);
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}

bn_status bn__flat_camera(const bn_flat *f, int width, int height, int spp, const double *eye, const double *look,
                          double fov_deg, bn_camera *cam, char *msg, size_t msglen)
{
    bn_error err;
    bn_status st;
    bn_error_clear(&err);
    bn_camera_default(f->p.scene, cam);
    if ((st = bn_camera_load_sidecar(bn_scene_path(f->p.scene), cam, NULL, &err)) != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    if (eye)
        memcpy(cam->eye, eye, sizeof cam->eye);
    if (look)
        memcpy(cam->look, look, sizeof cam->look);
    if (f->call.has_up)
        memcpy(cam->up, f->call.up, sizeof cam->up);
    if (fov_deg > 0)
        cam->fov_deg = fov_deg;
    if (width > 0)
        cam->width = width;
    if (height > 0)
        cam->height = height;
    if (spp > 0)
        cam->spp = spp;
    if ((st = bn_camera_validate(cam, &err)) != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    return BN_OK;
}

/* The camera of bn_flat_images and bn_flat_render (the scene's sidecar or default, then what is given),
 * validated with the images' memory, and the layers (at most 72); *gather_mode from `gather`. */
static bn_status bn__flat_view(const bn_flat *f, int width, int height, int spp, const double *eye,
                               const double *look, double fov_deg, const char *gather, bn_camera *cam_out,
                               const double **layers, int *gather_mode, char *msg, size_t msglen)
{
    int nb = f->p.res.nterms - 1;
    bn_camera cam;
    bn_error err;
    bn_status st;
    if (!f->p.scene || !f->p.rt)
        return bn__flat_fail(BN_EUSAGE, "images: this result has no scene (a caller's operator)", msg, msglen);
    if (nb < 0 || bn_layer_count(nb) > 72)
        return bn__flat_fail(BN_EUSAGE, "images: the solve kept no terms (bounces >= 0 needed)", msg, msglen);
    if ((st = bn__flat_name("images: gather", gather, bn_gather_mode_names(), bn__gather_index, gather_mode, msg,
                            msglen)))
        return st;
    if ((st = bn__flat_camera(f, width, height, spp, eye, look, fov_deg, &cam, msg, msglen)) != BN_OK)
        return st;
    bn_error_clear(&err);
    if ((st = bn_bounces_check_memory(cam.width, cam.height, nb, f->po.ff.max_memory, &err)) != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    for (int l = 0; l < bn_layer_count(nb); l++)
        layers[l] = l <= nb ? f->p.res.terms[l] : l == nb + 1 ? f->p.rest : f->p.res.L;
    *cam_out = cam;
    return BN_OK;
}

int bn_flat_layers(const bn_flat *f) { return f->p.res.nterms > 0 ? bn_layer_count(f->p.res.nterms - 1) : 0; }

const char *bn_flat_layer_name(const bn_flat *f, int layer, char *buf, size_t size)
{
    return layer >= 0 && layer < bn_flat_layers(f) ? bn_layer_name(layer, f->p.res.nterms - 1, buf, size) : NULL;
}

bn_status bn_flat_render(const bn_flat *f, int width, int height, int spp, const double *eye, const double *look,
                         double fov_deg, int smooth, const char *gather, float *out, char *msg, size_t msglen)
{
    const double *layers[72];
    bn_image imgs[72];
    bn_camera cam;
    bn_bounces_opts bo;
    bn_error err;
    int mode, nb = f->p.res.nterms - 1;
    bn_status st = bn__flat_view(f, width, height, spp, eye, look, fov_deg, gather, &cam, layers, &mode, msg, msglen);
    if (st != BN_OK)
        return st;
    if (!out || cam.width != width || cam.height != height)
        return bn__flat_fail(BN_EUSAGE, "render: width and height must be given (> 0) with room for them in out",
                             msg, msglen);
    memset(imgs, 0, sizeof imgs);
    bo = f->call.bo;   /* the defaults and bn_flat_set's options */
    bo.smooth = smooth;
    bo.gather = mode == BN_GATHER_FINAL;
    bo.log.quiet = 1;
    bn_error_clear(&err);
    st = bn_bounces_render(f->p.scene, f->p.rt, &cam, layers, nb, &bo, imgs, &err);
    size_t px = (size_t)width * (size_t)height * 3;
    for (int l = 0; l < bn_layer_count(nb); l++) {
        if (st == BN_OK)
            memcpy(out + (size_t)l * px, imgs[l].rgb, px * sizeof *out);
        bn_image_free(&imgs[l]);
    }
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}

bn_status bn_flat_images(const bn_flat *f, const char *out, int width, int height, int spp, const double *eye,
                         const double *look, double fov_deg, int previews, int smooth, int half, const char *gather,
                         const char *caller, char *msg, size_t msglen)
{
    int nb = f->p.res.nterms - 1, mode;
    const double *layers[72];
    bn_camera cam;
    bn_bounces_opts bo;
    bn_error err;
    char solver[160], patches[32];
    bn_status st = bn__flat_view(f, width, height, spp, eye, look, fov_deg, gather, &cam, layers, &mode, msg, msglen);
    if (st != BN_OK)
        return st;
    bn_error_clear(&err);
    snprintf(solver, sizeof solver, "%s: %s after %zu iterations, residual %.3g", bn_solve_method_name(f->p.method_used),
             bn_stop_reason_name(f->p.res.reason), f->p.res.iterations, f->p.res.residual_max);
    snprintf(patches, sizeof patches, "%zu", f->p.n);
    {
        const bn_attr attrs[] = {
            {"bounce:caller", caller ? caller : "bn_flat_images"},
            {"bounce:version", bn_version()},
            {"bounce:scene", bn_scene_path(f->p.scene)},
            {"bounce:solver", solver},
            {"bounce:patches", patches},
            {"bounce:units", "radiance, W m^-2 sr^-1 (L = E + K L solved in radiance)"},
            {"bounce:layers", "E = K^0 E (emission), KE = K^1 E (direct), K2E = K^2 E, ...; rest = L - their sum"},
        };
        bo = f->call.bo;   /* the defaults and bn_flat_set's options */
        bo.output = out;
        bo.previews = previews;
        bo.smooth = smooth;
        bo.half = half;
        bo.gather = mode == BN_GATHER_FINAL;
        bo.attrs = attrs;
        bo.nattrs = sizeof attrs / sizeof attrs[0];
        bo.log.quiet = 1;
        st = bn_bounces_write(f->p.scene, f->p.rt, &cam, layers, nb, &bo, NULL, &err);
    }
    if (st != BN_OK)
        bn__flat_fail(st, err.msg, msg, msglen);
    return st;
}
