/* bounce: cameras, images of per-patch radiance, OpenEXR (C API) and PNG previews. */
#ifndef BOUNCE_IMAGE_H
#define BOUNCE_IMAGE_H

#include <stddef.h>
#include <stdint.h>
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/layers.h"

#ifdef __cplusplus
extern "C" {
#endif

struct bn_bake;   /* bounce/bake.h: vertex values for smooth shading */

/* A pinhole camera. Image row 0 is the top; the image's right is forward x up (so a scene seen
 * from -z with up +y has +x on the left: the Cornell box's red wall). Positions in scene units. */
typedef struct bn_camera {
    double eye[3], look[3], up[3];
    double fov_deg;          /* vertical field of view, degrees, in (0, 180) */
    int    width, height;    /* pixels */
    int    spp;              /* supersamples per pixel (stratified, jittered), 1 = pixel centres */
} bn_camera;
/* Default: the scene file's camera when it has one (bn_scene_camera; its aspect ratio at 512 pixels
 * wide), else looking at the bounding box's centre from outside its front (-z side), up +y, fov 40,
 * 512x512, spp 1, the eye far enough back for the whole box to fit the view. */
void bn_camera_default(const bn_scene *s, bn_camera *cam);
/* Reads NAME.camera beside the scene (scene path with its extension replaced by .camera) if it
 * exists. Format: one `key value` per line, '#' comments; keys eye X,Y,Z / look X,Y,Z / up X,Y,Z /
 * fov DEG / size WxH / spp N (any subset). Returns BN_OK and leaves *cam unchanged when there is
 * none; BN_EINPUT naming the file and line for a bad line. *found (may be NULL) is set to 1 when a
 * sidecar was read. */
bn_status bn_camera_load_sidecar(const char *scene_path, bn_camera *cam, int *found, bn_error *err);
/* Checks a camera: finite vectors, eye != look, up not parallel to the view, fov in (0, 180),
 * sizes in [1, 32768], spp in [1, 65536]. */
bn_status bn_camera_validate(const bn_camera *cam, bn_error *err);
/* The primary ray through image position (x, y) in pixels (0,0 = top-left corner of the image,
 * (width, height) the bottom-right). dir is unit length. */
void bn_camera_ray(const bn_camera *cam, double x, double y, double org[3], double dir[3]);

/* A float RGB image, row-major, row 0 at the top. Values are radiance, W m^-2 sr^-1. */
typedef struct bn_image {
    int width, height;
    float *rgb;   /* width*height*3 (owned) */
} bn_image;
bn_status bn_image_alloc(bn_image *img, int width, int height, bn_error *err);   /* zero-filled */
void bn_image_free(bn_image *img);   /* NULL rgb is a no-op */

/* Renders per-patch values seen through `cam`: a pixel is the mean over its spp samples of the
 * value of the patch each primary ray hits first (misses and back faces count 0). values[l] is
 * N*3 (patch-major, a[3*i+c], borrowed), out[l] must be allocated at the camera's size. With
 * `smooth` (NULL = flat), values are first baked to vertices and interpolated across each patch.
 * Jitter for spp > 1 is seeded per pixel and sample from `seed`: the result does not depend on
 * the thread count (`threads`, 0 = the caller's; OpenMP over rows). */
bn_status bn_image_render(const bn_rt *rt, const bn_camera *cam, const double *const *values, size_t nlayers,
                          const struct bn_bake *smooth, uint64_t seed, int threads, bn_image *out, bn_error *err);

/* A named layer for multi-layer output: "E", "KE", "K2E", ..., "rest", "L", "E_var", ... */
typedef struct bn_layer {
    const char *name;
    const bn_image *img;
} bn_layer;

/* Key/value attributes recorded in file headers (command line, version, solver, tolerance...). */
typedef struct bn_attr {
    const char *key, *value;
} bn_attr;

/* Writes a multi-layer OpenEXR (OpenEXR C API, scanline, ZIP), channels "<layer>.R/G/B"; half = 1
 * stores half floats (values above 65504 clamped with a warning). Attributes are string
 * attributes under their keys. Images must have equal sizes and no NaN or infinity (BN_ENUMERIC).
 * Atomic: temp name, then rename. */
bn_status bn_exr_write(const char *path, const bn_layer *layers, size_t nlayers, const bn_attr *attrs,
                       size_t nattrs, int half, const bn_log *log, bn_error *err);

/* Display: value * 2^ev, clamped to [0, 1], sRGB transfer, 8 bits. */
unsigned char bn_tonemap_srgb8(double value, double ev);
/* An exposure (EV) that maps the 99th percentile of the image's non-zero luminance to 0.9
 * (0 for a black image). Deterministic (sorts a copy). */
double bn_image_auto_exposure(const bn_image *img);
/* Writes an 8-bit sRGB PNG of img at exposure ev through OpenImageIO; attrs become PNG text
 * chunks. Atomic. */
bn_status bn_png_write(const char *path, const bn_image *img, double ev, const bn_attr *attrs, size_t nattrs,
                       bn_error *err);
/* A contact sheet: the layers side by side, each labelled with its name. Row 1: every layer at
 * exposure ev; row 2: each layer at its own auto exposure (labelled with its EV) so faint high
 * bounces show. Tiles are box-downsampled to at most `tile` pixels wide (0: 320). Labels use
 * DejaVu Sans; without the font the sheet is written unlabelled with a warning. Atomic PNG. */
bn_status bn_contact_sheet_write(const char *path, const bn_layer *layers, size_t nlayers, double ev, int tile,
                                 const bn_attr *attrs, size_t nattrs, const bn_log *log, bn_error *err);

#ifdef __cplusplus
}
#endif
#endif
