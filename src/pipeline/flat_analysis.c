/* The flat API's analyses (include/bounce/flat.h): the path tracer's per-patch estimates and camera
 * images of a loaded or solved scene, and the cross-check, into the caller's arrays (the study's is
 * src/study/flat_study.c, above the pipeline). The
 * tracer shares the scene and the ray scene only, never F, K or the solve (the cross-check's
 * independence): a scene loaded without an operator gets a ray scene of its own here. */
#include "pipeline/flat_internal.h"
#include "bounce/trace.h"
#include "bounce/image.h"
#include "base/internal.h"

#include <stdlib.h>
#include <string.h>

/* The ray scene (built once and kept), the options checked. */
static bn_status bn__flat_trace_setup(bn_flat *f, size_t spp, int bounces, uint64_t seed, int threads,
                                      bn_trace_opts *o, char *msg, size_t msglen)
{
    bn_error err;
    bn_status st;
    char t[160];
    if (!f || !f->p.scene)
        return bn__flat_fail(BN_EUSAGE, "trace: no scene (a caller's operator has none)", msg, msglen);
    if (spp < 1 || bounces < 0 || bounces > 64 || threads < 0) {
        snprintf(t, sizeof t, "trace: spp %zu, bounces %d, threads %d: spp >= 1, bounces 0 to 64, threads >= 0", spp,
                 bounces, threads);
        return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
    }
    bn_trace_opts_default(o);
    o->spp = spp;
    o->bounces = bounces;
    o->seed = seed;
    o->threads = threads;
    o->quiet = 1;
    bn_error_clear(&err);
    if (!f->p.rt && (st = bn_rt_create(f->p.scene, threads, &f->p.rt, &err)) != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    return BN_OK;
}

bn_status bn_flat_trace_patches(bn_flat *f, size_t spp, int bounces, uint64_t seed, int threads, double *mean,
                                double *se, char *msg, size_t msglen)
{
    bn_trace_opts o;
    bn_trace_patches r;
    bn_error err;
    bn__flat_sig sg;
    bn_status st = bn__flat_trace_setup(f, spp, bounces, seed, threads, &o, msg, msglen);
    if (st != BN_OK)
        return st;
    if (!mean || !se)
        return bn__flat_fail(BN_EUSAGE, "trace: mean and se need room for (bounces + 3) x patches x 3", msg, msglen);
    memset(&r, 0, sizeof r);
    bn_error_clear(&err);
    bn__flat_sig_begin(&sg, f->sigint);
    st = bn_trace_patches_run(f->p.rt, &o, &r, &err);
    bn__flat_sig_end(&sg);
    if (st != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    memcpy(mean, r.mean, (size_t)r.nlayers * r.n * 3 * sizeof *mean);
    memcpy(se, r.se, (size_t)r.nlayers * r.n * 3 * sizeof *se);
    bn_trace_patches_free(&r);
    return BN_OK;
}

bn_status bn_flat_trace_image(bn_flat *f, int width, int height, size_t spp, int bounces, uint64_t seed,
                              const double *eye, const double *look, double fov_deg, int threads, float *mean,
                              float *var, char *msg, size_t msglen)
{
    bn_trace_opts o;
    bn_trace_image r;
    bn_camera cam;
    bn_error err;
    bn__flat_sig sg;
    bn_status st = bn__flat_trace_setup(f, spp, bounces, seed, threads, &o, msg, msglen);
    if (st != BN_OK)
        return st;
    if (width < 1 || height < 1)
        return bn__flat_fail(BN_EUSAGE, "trace: the image's width and height must be >= 1", msg, msglen);
    /* the tracer takes its samples per pixel from o.spp: the camera's own stays 1 */
    if ((st = bn__flat_camera(f, width, height, 1, eye, look, fov_deg, &cam, msg, msglen)) != BN_OK)
        return st;
    bn_error_clear(&err);
    if (!mean || !var)
        return bn__flat_fail(BN_EUSAGE, "trace: mean and var need room for (bounces + 3) x height x width x 3", msg,
                             msglen);
    memset(&r, 0, sizeof r);
    bn__flat_sig_begin(&sg, f->sigint);
    st = bn_trace_image_run(f->p.rt, &cam, &o, &r, &err);
    bn__flat_sig_end(&sg);
    if (st != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    size_t n = (size_t)r.nlayers * (size_t)width * (size_t)height * 3;
    memcpy(mean, r.mean, n * sizeof *mean);
    memcpy(var, r.var, n * sizeof *var);
    bn_trace_image_free(&r);
    return BN_OK;
}

/* ---- the cross-check: radiosity against the tracer, as `bounce crosscheck` (bn_crosscheck_run_scene) ---- */

struct bn_flat_check {
    bn_flat f;              /* the options' home (the transport's name) */
    bn_crosscheck_run run;
    double seconds;
};

void bn_flat_check_free(bn_flat_check *c)
{
    if (!c)
        return;
    bn_crosscheck_run_free(&c->run);
    free(c);
}

/* The cross-check's options from the flat ones and the check's own; BN_EUSAGE naming a bad one. */
static bn_status bn__flat_check_opts(const bn_flat_opts *o, size_t spp, int bounces, double alpha, const char *model,
                                     bn_flat_check *c, bn_crosscheck_opts *co, char *msg, size_t msglen)
{
    char t[200];
    bn_status st = bn__flat_popts(o, &c->f, msg, msglen);
    if (st != BN_OK)
        return st;
    bn_crosscheck_opts_default(co);
    co->pipeline = c->f.po;
    co->pipeline.solve.quiet = 1;
    co->trace.quiet = 1;
    co->trace.threads = o->threads;
    if (o->seed)
        co->trace.seed = o->seed;
    if (spp)
        co->trace.spp = spp;
    co->bounces = bounces;
    if (alpha > 0)
        co->alpha = alpha;
    if (bounces < 0 || bounces > 64 || !(alpha >= 0 && alpha < 1)) {
        snprintf(t, sizeof t, "crosscheck: bounces %d, alpha %g: bounces 0 to 64, alpha in (0, 1)", bounces, alpha);
        return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
    }
    if (model && bn_trace_model_parse(model, &co->trace.model) != 0) {
        snprintf(t, sizeof t, "crosscheck: model '%.64s' is not one of %s", model, bn_trace_model_names());
        return bn__flat_fail(BN_EUSAGE, t, msg, msglen);
    }
    return BN_OK;
}

bn_status bn_flat_crosscheck(const char *path, const bn_flat_opts *o, size_t spp, int bounces, double alpha,
                             const char *model, bn_flat_check **out, char *msg, size_t msglen)
{
    bn_flat_opts d;
    bn_crosscheck_opts co;
    bn_error err;
    bn__flat_sig sg;
    bn_flat_check *c;
    bn_status st;
    if (!out || !path)
        return bn__flat_fail(BN_EUSAGE, "crosscheck: path and out are required", msg, msglen);
    *out = NULL;
    if (!o) {
        bn_flat_opts_default(&d);
        o = &d;
    }
    if (!(c = bn__calloc(1, sizeof *c)))
        return bn__flat_fail(BN_ENOMEM, "crosscheck: out of memory", msg, msglen);
    if ((st = bn__flat_check_opts(o, spp, bounces, alpha, model, c, &co, msg, msglen)) != BN_OK) {
        free(c);
        return st;
    }
    bn_error_clear(&err);
    double t0 = bn__now();
    bn__flat_sig_begin(&sg, o->sigint);
    st = bn_crosscheck_run_scene(path, &co, &c->run, &err);
    bn__flat_sig_end(&sg);
    c->seconds = bn__now() - t0;
    if (st != BN_OK) {
        bn_flat_check_free(c);
        return bn__flat_fail(st, err.msg, msg, msglen);
    }
    *out = c;
    return BN_OK;
}

int bn_flat_check_pass(const bn_flat_check *c) { return c->run.result.pass; }
int bn_flat_check_layers(const bn_flat_check *c) { return c->run.result.nlayers; }
size_t bn_flat_check_entries(const bn_flat_check *c) { return c->run.trace.n; }

void bn_flat_check_figures(const bn_flat_check *c, double out[BN_FLAT_CHECK_FIGURES])
{
    const bn_crosscheck_result *r = &c->run.result;
    double v[BN_FLAT_CHECK_FIGURES] = {(double)r->family,    r->alpha,         r->crit,       (double)r->within,
                                       r->worst_z,           r->worst_z_raw,   r->power_crit, r->power_worst_z,
                                       (double)r->few_hits,  (double)c->run.trace.spp, c->seconds};
    memcpy(out, v, sizeof v);
}

void bn_flat_check_arrays(const bn_flat_check *c, double *rad, double *trace, double *se, double *tol)
{
    const bn_crosscheck_input *in = &c->run.in;
    size_t n = (size_t)c->run.result.nlayers * c->run.trace.n * 3;
    if (rad)
        memcpy(rad, in->rad, n * sizeof *rad);
    if (trace)
        memcpy(trace, in->trace->mean, n * sizeof *trace);
    if (se)
        memcpy(se, in->trace->se, n * sizeof *se);
    for (size_t k = 0; tol && k < n; k++)
        tol[k] = in->tol ? in->tol[k] * in->tol_scale : 0;
}
