/* The flat API's path tracer (include/bounce/flat.h): per-patch estimates and camera images of a loaded
 * or solved scene, into the caller's arrays. The tracer shares the scene and the ray scene only, never
 * F, K or the solve (the cross-check's independence): a scene loaded without an operator gets a ray
 * scene of its own here. */
#include "pipeline/flat_internal.h"
#include "bounce/trace.h"
#include "bounce/image.h"
#include "base/internal.h"

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
    bn_error_clear(&err);
    bn_camera_default(f->p.scene, &cam);
    if ((st = bn_camera_load_sidecar(bn_scene_path(f->p.scene), &cam, NULL, &err)) != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
    if (eye)
        memcpy(cam.eye, eye, sizeof cam.eye);
    if (look)
        memcpy(cam.look, look, sizeof cam.look);
    if (fov_deg > 0)
        cam.fov_deg = fov_deg;
    cam.width = width;
    cam.height = height;
    cam.spp = 1;   /* the tracer takes its samples per pixel from o.spp */
    if ((st = bn_camera_validate(&cam, &err)) != BN_OK)
        return bn__flat_fail(st, err.msg, msg, msglen);
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
