/* Images of per-patch values: primary rays through Embree, flat or smooth shading, stratified
 * jittered supersampling seeded per pixel and sample (identical for any thread count). */
#include "bounce/image.h"
#include "bounce/bake.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

bn_status bn_image_alloc(bn_image *img, int width, int height, bn_error *err)
{
    img->width = img->height = 0;
    img->rgb = NULL;
    if (width < 1 || height < 1)
        return bn_error_set(err, BN_EINPUT, "image size %dx%d is empty", width, height);
    img->rgb = bn__calloc((size_t)width * (size_t)height, 3 * sizeof(float));
    if (!img->rgb)
        return bn_error_set(err, BN_ENOMEM, "out of memory for a %dx%d image", width, height);
    img->width = width;
    img->height = height;
    return BN_OK;
}

void bn_image_free(bn_image *img)
{
    if (!img)
        return;
    free(img->rgb);
    img->rgb = NULL;
    img->width = img->height = 0;
}

/* The strata grid for n samples: sx * sy = n with sx <= sy as close to square as divides n. */
static void bn__strata(int n, int *sx, int *sy)
{
    int a = (int)floor(sqrt((double)n));
    while (a > 1 && n % a != 0)
        a--;
    *sx = a;
    *sy = n / a;
}

static void bn__free_layers(double **vv, size_t n)
{
    for (size_t l = 0; vv && l < n; l++)
        free(vv[l]);
    free(vv);
}

/* Smooth shading's vertex values of each layer (*vv, nlayers arrays), from the bake's mesh. */
static bn_status bn__render_vertex_values(const struct bn_bake *smooth, const double *const *values, size_t nlayers,
                                          double ***vv, bn_error *err)
{
    size_t nv = bn_bake_vertex_count(smooth);
    double **v = bn__calloc(nlayers ? nlayers : 1, sizeof *v);
    if (!v)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    for (size_t l = 0; l < nlayers; l++) {
        v[l] = bn__malloc_array(nv, 3 * sizeof(double));
        if (!v[l]) {
            bn__free_layers(v, l);
            return bn_error_set(err, BN_ENOMEM, "out of memory for %zu vertex values", nv);
        }
        bn_bake_vertex_values(smooth, values[l], v[l]);
    }
    *vv = v;
    return BN_OK;
}

/* Pixel (x, y): its spp jittered samples' values of every layer (flat: the patch's; smooth: the
 * bake's interpolation), averaged into out; acc is 3 nlayers doubles of scratch. */
static void bn__render_pixel(const bn_rt *rt, const bn_camera *cam, const double *const *values, size_t nlayers,
                             const struct bn_bake *smooth, double *const *vv, uint64_t seed, int sx, int sy, int x,
                             int y, double *acc, bn_image *out)
{
    size_t pix = (size_t)y * (size_t)cam->width + (size_t)x;
    memset(acc, 0, nlayers * 3 * sizeof(double));
    for (int s = 0; s < cam->spp; s++) {
        double fx = 0.5, fy = 0.5, o[3], d[3];
        bn_hit h;
        if (cam->spp > 1) {
            bn__rng r = bn__rng_make(seed, pix, (uint64_t)s);
            fx = ((s % sx) + bn__rng_uniform(&r)) / sx;
            fy = ((s / sx) + bn__rng_uniform(&r)) / sy;
        }
        bn_camera_ray(cam, x + fx, y + fy, o, d);
        if (!bn_rt_intersect(rt, o, d, 0, INFINITY, &h) || !h.front)
            continue;   /* misses and back faces are black: surfaces are one-sided */
        for (size_t l = 0; l < nlayers; l++) {
            double v[3];
            if (vv)
                bn_bake_interpolate(smooth, vv[l], h.patch, h.p, v);
            for (int c = 0; c < 3; c++)
                acc[3 * l + c] += vv ? v[c] : values[l][3 * h.patch + c];
        }
    }
    for (size_t l = 0; l < nlayers; l++)
        for (int c = 0; c < 3; c++)
            out[l].rgb[3 * pix + c] = (float)(acc[3 * l + c] / cam->spp);
}

static bn_status bn__image_render_body(const bn_rt *rt, const bn_camera *cam, const double *const *values,
                                       size_t nlayers, const struct bn_bake *smooth, uint64_t seed, bn_image *out,
                                       bn_error *err)
{
    bn_status st = bn_camera_validate(cam, err);
    double **vv = NULL;
    int sx, sy;
    volatile int stop = 0;
    if (st != BN_OK)
        return st;
    for (size_t l = 0; l < nlayers; l++)
        if (!out[l].rgb || out[l].width != cam->width || out[l].height != cam->height)
            return bn_error_set(err, BN_EINTERNAL, "render: output image %zu is not allocated at %dx%d", l, cam->width,
                                cam->height);
    if (smooth && (st = bn__render_vertex_values(smooth, values, nlayers, &vv, err)) != BN_OK)
        return st;
    bn__strata(cam->spp, &sx, &sy);
#pragma omp parallel for schedule(dynamic, 1)
    for (int y = 0; y < cam->height; y++) {
        double *acc;
        if (stop)
            continue;
        if (bn_interrupted() != BN_OK) {
            stop = 1;
            continue;
        }
        acc = malloc((nlayers ? nlayers : 1) * 3 * sizeof(double));
        if (!acc) {
            stop = 2;
            continue;
        }
        for (int x = 0; x < cam->width; x++)
            bn__render_pixel(rt, cam, values, nlayers, smooth, vv, seed, sx, sy, x, y, acc, out);
        free(acc);
    }
    bn__free_layers(vv, nlayers);
    if (stop == 2)
        return bn_error_set(err, BN_ENOMEM, "out of memory while rendering");
    if (stop || bn_interrupted() != BN_OK)
        return bn_error_set(err, bn_interrupted() != BN_OK ? bn_interrupted() : BN_EINTR, "interrupted");
    return BN_OK;
}

bn_status bn_image_render(const bn_rt *rt, const bn_camera *cam, const double *const *values, size_t nlayers,
                          const struct bn_bake *smooth, uint64_t seed, int threads, bn_image *out, bn_error *err)
{
    int prev = bn__threads_begin(threads);
    bn_status st = bn__image_render_body(rt, cam, values, nlayers, smooth, seed, out, err);
    bn__threads_end(prev);
    return st;
}
