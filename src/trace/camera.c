/* Camera images from the path tracer: per pixel and layer, the mean of `spp` independent samples
 * (uniform jitter inside the pixel) of the radiance leaving the surface seen, and its variance. */
#include "trace/trace_internal.h"
#include "bounce/dist.h"
#include "base/vec.h"

#include <math.h>
#include <omp.h>
#include <string.h>

size_t bn_trace_image_bytes(const bn_camera *cam, int bounces)
{
    size_t px, b;
    if (cam->width <= 0 || cam->height <= 0 || bounces < 0)
        return 0;
    if (!bn__mul_size((size_t)cam->width, (size_t)cam->height, &px) ||
        !bn__mul_size(px, (size_t)bn_layer_count(bounces) * 3 * 2 * sizeof(float), &b))
        return (size_t)-1;
    return b;
}

/* Pixel (row, col)'s spp jittered samples into out's mean and variance. */
static void bn__trace_pixel(const bn__tracer *t, const bn_rt *rt, const bn_camera *cam, const bn_trace_opts *o, int row,
                            int col, size_t npx, size_t nl, double *sample, double *mean, double *m2,
                            bn_trace_image *out, unsigned long long *rays)
{
    size_t m = nl * 3, W = (size_t)cam->width;
    size_t px = (size_t)row * W + (size_t)col;
    memset(mean, 0, m * sizeof(double));
    memset(m2, 0, m * sizeof(double));
    for (size_t s = 0; s < o->spp; s++) {
        if ((s & 4095) == 4095 && bn_interrupted() != BN_OK)
            break;   /* a row of many samples takes seconds: stop within one batch (discarded) */
        bn__rng rng = bn__rng_make(o->seed ^ BN__TRACE_TAG_PIXEL, px, s);
        double org[3], dir[3], *L = sample + 3 * (nl - 1);
        double jx = o->spp == 1 ? 0.5 : bn__rng_uniform(&rng), jy = o->spp == 1 ? 0.5 : bn__rng_uniform(&rng);
        bn_hit h;
        memset(sample, 0, m * sizeof(double));
        bn_camera_ray(cam, col + jx, row + jy, org, dir);
        (*rays)++;
        if (bn_rt_intersect(rt, org, dir, 0, INFINITY, &h) && h.front) {
            for (int c = 0; c < 3; c++)
                sample[c] = t->Le[3 * h.patch + c];
            double rho0[3];
            int at_point = o->model != BN_TRACE_PATCH && bn_scene_textured(t->scene);
            if (o->model == BN_TRACE_PATCH)
                bn__tracer_restart(t, h.patch, &rng, h.p);   /* each patch shows its mean, as radiosity's flat images */
            if (at_point)   /* the texture at the point seen, as the gather's pixels; patch means beyond */
                bn_scene_reflectance_at(t->scene, t->patches[h.patch].face, h.p, rho0);
            bn__tracer_path(t, h.p, h.patch, at_point ? rho0 : NULL, &rng, sample, rays);
        }
        for (size_t l = 0; l + 1 < nl; l++)
            for (int c = 0; c < 3; c++)
                L[c] += sample[3 * l + c];
        bn__welford_add(mean, m2, sample, m, s + 1);
    }
    for (size_t l = 0; l < nl; l++)
        for (int c = 0; c < 3; c++) {
            size_t k = (l * npx + px) * 3 + (size_t)c, j = 3 * l + (size_t)c;
            double var = o->spp > 1 ? m2[j] / (double)(o->spp - 1) / (double)o->spp : 0;
            out->mean[k] = (float)mean[j];
            out->var[k] = (float)fmax(var, 0.0);
        }
}

typedef struct bn__trace_rows_ctx {
    const bn__tracer *t;
    const bn_rt *rt;
    const bn_camera *cam;
    const bn_trace_opts *o;
    size_t npx, nl;
    bn_trace_image *out;
} bn__trace_rows_ctx;

/* One row of pixels. */
static void bn__trace_row(void *ctx, size_t row, double *sample, double *mean, double *m2, unsigned long long *rays)
{
    const bn__trace_rows_ctx *c = ctx;
    for (int col = 0; col < c->cam->width; col++)
        bn__trace_pixel(c->t, c->rt, c->cam, c->o, (int)row, col, c->npx, c->nl, sample, mean, m2, c->out, rays);
}

static bn_status bn__trace_image_run_body(const bn_rt *rt, const bn_camera *cam, const bn_trace_opts *o, bn_trace_image *out,
                             bn_error *err)
{
    bn__tracer t;
    bn_status st;
    size_t npx, nl, bytes;
    unsigned long long rays = 0;
    int no_buffers;   /* a thread could not allocate its sample buffers */
    bn__progress prog;
    double t0 = bn__now();
    const int W = cam->width, H = cam->height;

    memset(out, 0, sizeof *out);
    bytes = bn_trace_image_bytes(cam, o->bounces);
    if (bytes == 0)
        return bn_error_set(err, BN_EUSAGE, "trace: image size %dx%d and %d bounces", W, H, o->bounces);
    if (bytes == (size_t)-1 || bytes > bn_memory_limit_default())
        return bn_error_set(err, BN_ENOMEM, "trace: %dx%d pixels x %d layers x (mean, variance) need %.3g GiB, more "
                            "than 80%% of memory; use a smaller `size` or fewer `bounces`", W, H,
                            bn_layer_count(o->bounces), (double)bytes / 1073741824.0);
    st = bn__tracer_init(&t, rt, o, err);
    if (st != BN_OK)
        return st;
    npx = (size_t)W * (size_t)H;
    nl = (size_t)bn_layer_count(o->bounces);
    out->width = W;
    out->height = H;
    out->bounces = o->bounces;
    out->nlayers = (int)nl;
    out->spp = o->spp;
    out->mean = bn__calloc(npx * nl * 3, sizeof(float));
    out->var = bn__calloc(npx * nl * 3, sizeof(float));
    if (!out->mean || !out->var) {
        bn__tracer_free(&t);
        bn_trace_image_free(out);
        return bn_error_set(err, BN_ENOMEM, "trace: out of memory for %zu bytes of image layers", bytes);
    }
    bn__progress_begin(&prog, "path tracing", (size_t)H, o->quiet);

    bn__trace_rows_ctx ctx = {&t, rt, cam, o, npx, nl, out};
    no_buffers = bn__trace_parallel((size_t)H, nl * 3, 1, bn__trace_row, &ctx, &prog, &rays);
    bn__progress_end(&prog);
    bn__tracer_free(&t);
    if ((st = bn__trace_combine(no_buffers, out->mean, out->var, NULL, 0, npx * nl * 3, &rays, err)) != BN_OK ||
        (st = bn__trace_stopped(no_buffers, err)) != BN_OK) {
        bn_trace_image_free(out);
        return st;
    }
    out->rays = rays;
    out->seconds = bn__now() - t0;
    for (size_t k = 0; k < npx * nl * 3; k++)
        if (!isfinite(out->mean[k]) || !isfinite(out->var[k])) {
            size_t l = k / (npx * 3), px = (k / 3) % npx;
            char name[16];
            bn_error_set(err, BN_ENUMERIC, "trace: non-finite value %g (variance %g) at pixel (%zu, %zu), layer %s",
                         (double)out->mean[k], (double)out->var[k], px % (size_t)W, px / (size_t)W,
                         bn_layer_name((int)l, o->bounces, name, sizeof name));
            bn_trace_image_free(out);
            return BN_ENUMERIC;
        }
    return BN_OK;
}

bn_status bn_trace_image_run(const bn_rt *rt, const bn_camera *cam, const bn_trace_opts *o, bn_trace_image *out,
                             bn_error *err)
{
    int prev = bn__threads_begin(o->threads);
    bn_status st = bn__trace_image_run_body(rt, cam, o, out, err);
    bn__threads_end(prev);
    return st;
}

void bn_trace_image_free(bn_trace_image *r)
{
    if (!r)
        return;
    free(r->mean);
    free(r->var);
    r->mean = r->var = NULL;
}
