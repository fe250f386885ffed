/* The flat API's study (include/bounce/flat.h): bn_study_run with the flat options, its rows as numbers
 * for bindings (python/bounce's bounce.study). Here, above the pipeline, as the study is. */
#include "pipeline/flat_internal.h"
#include "bounce/study.h"
#include "base/internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct bn_flat_study {
    bn_study_result res;
};

void bn_flat_study_free(bn_flat_study *s)
{
    if (!s)
        return;
    bn_study_result_free(&s->res);
    free(s);
}

const char *bn_flat_study_columns(void) { return BN_FLAT_STUDY_COLUMNS; }

/* The study's options from the flat ones: the scene, mesh, form factors, transport and solver of
 * every setting (method: the study's default, direct, unless one is named); BN_EUSAGE naming a bad one. */
static bn_status bn__flat_study_opts(const bn_flat_opts *o, const char *vary, bn_flat *f, bn_study_opts *so,
                                     char *msg, size_t msglen)
{
    char t[256];
    bn_status st = bn__flat_popts(o, f, msg, msglen);
    if (st != BN_OK)
        return st;
    bn_study_opts_default(so);
    if (!vary || bn_study_param_parse(vary, &so->param) != 0) {
        snprintf(t, sizeof t, "study: vary '%.64s' is not one of %s", vary ? vary : "(null)", bn_study_param_names());
        return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
    }
    so->load = f->po.load;
    so->mesh = f->po.mesh;
    so->ff = f->po.ff;
    so->ff.cache_path = NULL;   /* every setting is built and timed */
    so->transport = f->po.transport && strcmp(f->po.transport, "auto") != 0 ? f->po.transport : NULL;
    so->hier = f->po.hier;
    if (!f->po.method_auto)
        so->solve.method = f->po.solve.method;
    if (o->max_iter)
        so->solve.max_iter = o->max_iter;
    if (o->seed)
        so->trace.seed = o->seed;
    so->threads = o->threads;
    so->log.quiet = 1;
    return BN_OK;
}

bn_status bn_flat_study_run(const char *path, const bn_flat_opts *o, const char *vary, const double *values, size_t n,
                            bn_flat_study **out, char *msg, size_t msglen)
{
    bn_flat_opts d;
    bn_study_opts so;
    bn_flat *f;
    bn_flat_study *s;
    bn_error err;
    bn__flat_sig sg;
    bn_status st;
    if (!out || !path || (!values && n))
        return bn__flat_fail(BN_EUSAGE, "study: path, values and out are required", msg, msglen);
    *out = NULL;
    if (!o) {
        bn_flat_opts_default(&d);
        o = &d;
    }
    f = bn__calloc(1, sizeof *f);
    s = bn__calloc(1, sizeof *s);
    if (!f || !s) {
        free(f), free(s);
        return bn__flat_fail(BN_ENOMEM, "study: out of memory", msg, msglen);
    }
    if ((st = bn__flat_study_opts(o, vary, f, &so, msg, msglen)) == BN_OK) {
        so.values = values;
        so.nvalues = n;
        bn_error_clear(&err);
        bn__flat_sig_begin(&sg, o->sigint);
        st = bn_study_run(path, &so, &s->res, &err);
        bn__flat_sig_end(&sg);
        if (st != BN_OK)
            bn__flat_fail(st, err.msg, msg, msglen);
    }
    free(f);   /* so borrowed its transport name only until the run */
    if (st != BN_OK) {
        bn_flat_study_free(s);
        return st;
    }
    *out = s;
    return BN_OK;
}

size_t bn_flat_study_rows(const bn_flat_study *s) { return s->res.nrows; }

void bn_flat_study_row(const bn_flat_study *s, size_t r, double out[BN_FLAT_STUDY_NCOLUMNS])
{
    const bn_study_row *w = &s->res.rows[r];
    double v[] = {w->x,           (double)w->patches, (double)w->k_entries, w->k_mb,
                  (double)w->iterations, (double)w->ground, w->err_inf, w->err_inf_rel,
                  w->err_max_rel, w->err_rms_rel, w->err_l1_rel, w->err_energy_rel,
                  w->err_surface_max, w->err_surface_mean, w->bound, w->bound_ke,
                  w->estimate,    w->t_mesh,          w->t_ff,              w->t_solve,
                  w->t_output,    w->t_total,         w->peak_mb,           w->k_norm,
                  w->se_surface_max, w->t_iterate};
    memcpy(out, v, sizeof v);
}

const char *bn_flat_study_label(const bn_flat_study *s, size_t r, int value)
{
    return value ? s->res.rows[r].value : s->res.rows[r].method;
}

const char *bn_flat_study_reference(const bn_flat_study *s, double *ref_error)
{
    if (ref_error)
        *ref_error = s->res.ref_error;
    return s->res.reference;
}
