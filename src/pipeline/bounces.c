/* The per-bounce images of a solution (include/bounce/pipeline.h): every layer E, KE, K2E, ...,
 * rest, L rendered through one camera, written as one multi-layer EXR, an sRGB PNG per layer and
 * a labelled contact sheet. */
#include "bounce/pipeline.h"
#include "bounce/bake.h"
#include "bounce/gather.h"
#include "base/internal.h"

#include <string.h>

void bn_bounces_opts_default(bn_bounces_opts *o)
{
    memset(o, 0, sizeof *o);
    o->output = "bounces.exr";
    o->previews = 1;
    o->tile = 320;
    o->crease = BN_BAKE_DEFAULT_CREASE;
    o->auto_exposure = 1;
    o->seed = 1;
    o->light_samples = BN_GATHER_LIGHT_SAMPLES;
    o->gather_samples = BN_GATHER_HEMI_SAMPLES;
    o->gather_filter = BN_GATHER_FILTER;
    o->hit_emitters = BN_GATHER_HIT_EMITTERS;
    o->tree_emitters = BN_GATHER_TREE_EMITTERS;
}

/* "dir/out.exr" + ".KE.png" -> "dir/out.KE.png" (the extension of `path` replaced). */
static char *bn__sibling(const char *path, const char *suffix)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    size_t stem = (dot && (!slash || dot > slash)) ? (size_t)(dot - path) : strlen(path);
    char *s = malloc(stem + strlen(suffix) + 1);
    if (s) {
        memcpy(s, path, stem);
        strcpy(s + stem, suffix);
    }
    return s;
}

/* The gather's line in the log: what it chose and what it cost. */
static void bn__gather_log(const bn_bounces_opts *o, const bn_camera *cam, const bn_gather_stats *gs)
{
    char lights[96] = "";
    if (gs->lights != gs->emitters)
        snprintf(lights, sizeof lights, " as %zu light%s (coplanar pieces merged)", gs->lights,
                 gs->lights == 1 ? "" : "s");
    bn_logf(&o->log, BN_LOG_INFO,
            "gather: %dx%d x %d spp, %zu emitting face%s%s, %s %d (K2E's hits: KE %s); %.3g shadow rays, %.3g "
            "gather rays, %.2f s (%.3g rays/s)",
            cam->width, cam->height, cam->spp, gs->emitters, gs->emitters == 1 ? "" : "s", lights,
            gs->light_tree ? "picked from a light tree: more than" : "each visited: at most", o->tree_emitters,
            gs->hit_direct ? "from the emitters" : "of the patches (more lights than the limit)", gs->shadow_rays,
            gs->gather_rays, gs->seconds,
            (gs->shadow_rays + gs->gather_rays + gs->camera_rays) / (gs->seconds > 0 ? gs->seconds : 1e-9));
}

/* The layers' images at the camera's size, rendered (flat, or smooth through a bake). */
bn_status bn_bounces_render(const bn_scene *scene, const bn_rt *rt, const bn_camera *cam, const double *const *layers,
                            int bounces, const bn_bounces_opts *o, bn_image *imgs, bn_error *err)
{
    size_t nl = (size_t)bn_layer_count(bounces);
    bn_bake *bake = NULL;
    bn_status st = BN_OK;
    for (size_t l = 0; l < nl && st == BN_OK; l++)
        st = bn_image_alloc(&imgs[l], cam->width, cam->height, err);
    if (st == BN_OK && o->smooth) {
        st = bn_bake_create(scene, o->crease, &bake, err);
        if (st == BN_OK)
            bn_bake_exclude_enclosed(bake, rt);   /* the floor under a block does not darken the floor around it */
    }
    if (st == BN_OK && o->gather) {
        bn_gather_opts go;
        bn_gather_stats gs;
        int n = (int)nl - 3;
        bn_gather_opts_default(&go);
        go.light_samples = o->light_samples;
        go.hemi_samples = o->gather_samples;
        go.filter = o->gather_filter;
        go.hit_emitters = o->hit_emitters;
        go.tree_emitters = o->tree_emitters;
        go.smooth = bake;
        go.seed = o->seed;
        go.threads = o->threads;
        go.quiet = o->quiet;
        st = bn_gather_render(rt, cam, layers, n, layers[n + 1], &go, imgs, &gs, err);
        if (st == BN_OK && gs.front_hits < 0.01 * gs.camera_rays)
            bn_warnf(&o->log, BN_W_CAMERA, gs.camera_rays - gs.front_hits,
                     "the camera (eye %g, %g, %g) sees a surface's front in %.2g%% of its samples: the image is "
                     "black (is its eye outside a closed room, or behind the surfaces it looks at?)", cam->eye[0],
                     cam->eye[1], cam->eye[2], 100 * gs.front_hits / gs.camera_rays);
        if (st == BN_OK)
            bn__gather_log(o, cam, &gs);
    } else if (st == BN_OK) {
        st = bn_image_render(rt, cam, layers, nl, bake, o->seed, o->threads, imgs, err);
    }
    bn_bake_destroy(bake);
    return st;
}

/* A PNG per layer and the contact sheet, beside the EXR. */
static bn_status bn__bounces_previews(const bn_layer *named, size_t nl, double ev, const bn_bounces_opts *o,
                                      bn_error *err)
{
    bn_status st = BN_OK;
    size_t npng = o->nattrs < 4 ? o->nattrs : 4;
    char *path;
    for (size_t l = 0; l < nl && st == BN_OK; l++) {
        char suffix[40];
        snprintf(suffix, sizeof suffix, ".%s.png", named[l].name);
        if (!(path = bn__sibling(o->output, suffix)))
            return bn_error_set(err, BN_ENOMEM, "out of memory");
        st = bn_png_write(path, named[l].img, ev, o->attrs, npng, err);
        if (st == BN_OK)
            bn_logf(&o->log, BN_LOG_INFO, "wrote %s (exposure %+.2f EV, sRGB)", path, ev);
        free(path);
    }
    if (st != BN_OK)
        return st;
    if (!(path = bn__sibling(o->output, ".sheet.png")))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    st = bn_contact_sheet_write(path, named, nl, ev, o->tile, o->attrs, npng, &o->log, err);
    if (st == BN_OK)
        bn_logf(&o->log, BN_LOG_INFO, "wrote %s (contact sheet: row 1 at %+.2f EV, row 2 each layer normalised)", path,
                ev);
    free(path);
    return st;
}

bn_status bn_bounces_check_memory(int width, int height, int bounces, size_t max_memory, bn_error *err)
{
    size_t limit = max_memory ? max_memory : bn_memory_limit_default(), px, need;
    int nl = bn_layer_count(bounces);
    /* every layer, and the gather's per-pixel sums beside them (as many again, in double) */
    if (width < 1 || height < 1 || nl < 1 || !bn__mul_size((size_t)width, (size_t)height, &px) ||
        !bn__mul_size(px, (size_t)nl * 3 * (sizeof(float) + sizeof(double)), &need) || need > limit)
        return bn_error_set(err, BN_ENOMEM, "images of %dx%d pixels in %d layers need %.3g GiB, above the limit of "
                            "%.3g GiB (`max_memory`): a smaller `size` or fewer `bounces`", width, height, nl,
                            (double)width * height * nl * 3 * (sizeof(float) + sizeof(double)) / (1 << 30),
                            (double)limit / (1 << 30));
    return BN_OK;
}

bn_status bn_bounces_write(const bn_scene *scene, const bn_rt *rt, const bn_camera *cam, const double *const *layers,
                           int bounces, const bn_bounces_opts *o, double *ev_used, bn_error *err)
{
    size_t nl = (size_t)bn_layer_count(bounces), na = o->nattrs + 2;
    bn_image *imgs = bn__calloc(nl, sizeof *imgs);
    bn_layer *named = bn__calloc(nl, sizeof *named);
    char (*names)[16] = bn__calloc(nl, sizeof *names);
    bn_attr *attrs = bn__calloc(na, sizeof *attrs);
    char evbuf[32], shading[480];
    double ev = o->ev;
    bn_status st = imgs && named && names && attrs ? BN_OK : bn_error_set(err, BN_ENOMEM, "out of memory");
    if (st == BN_OK)
        st = bn_bounces_render(scene, rt, cam, layers, bounces, o, imgs, err);
    if (st == BN_OK) {
        for (size_t l = 0; l < nl; l++) {
            named[l].name = bn_layer_name((int)l, bounces, names[l], sizeof names[l]);
            named[l].img = &imgs[l];
        }
        if (o->auto_exposure)
            ev = bn_image_auto_exposure(&imgs[nl - 1]);   /* L's */
        if (ev_used)
            *ev_used = ev;
        memcpy(attrs, o->attrs, o->nattrs * sizeof *attrs);
        snprintf(evbuf, sizeof evbuf, "%.4f", ev);
        if (o->gather)
            snprintf(shading, sizeof shading, "final gather: %d shadow rays per light (emitting faces, coplanar "
                     "pieces of one light merged), %d gather rays per pixel sample, same-face filter radius %d px; hits "
                     "read %s; KE at K2E's hits from the emitters up to %d lights; above %d lights, picked from a light "
                     "tree", o->light_samples,
                     o->gather_samples, o->gather_filter,
                     o->smooth ? "smooth (baked vertex values)" : "flat (patch values)", o->hit_emitters,
                     o->tree_emitters);
        else if (o->smooth)
            snprintf(shading, sizeof shading, "smooth (baked vertex values), crease %g degrees", o->crease);
        else
            snprintf(shading, sizeof shading, "flat (patch values)");
        attrs[o->nattrs] = (bn_attr){"bounce:shading", shading};
        attrs[o->nattrs + 1] = (bn_attr){"bounce:previewExposureEV", evbuf};
        st = bn_exr_write(o->output, named, nl, attrs, na, o->half, &o->log, err);
    }
    if (st == BN_OK)
        bn_logf(&o->log, BN_LOG_INFO, "wrote %s (%zu layers: E .. %s, rest, L; %dx%d, %s)", o->output, nl,
                names[bounces], cam->width, cam->height, o->half ? "half" : "float");
    if (st == BN_OK && o->previews) {
        bn_bounces_opts po = *o;
        po.attrs = attrs;
        po.nattrs = na;
        st = bn__bounces_previews(named, nl, ev, &po, err);
    }
    for (size_t l = 0; imgs && l < nl; l++)
        bn_image_free(&imgs[l]);
    free(imgs);
    free(named);
    free(names);
    free(attrs);
    return st;
}
