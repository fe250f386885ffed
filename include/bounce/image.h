/* bounce: cameras, images of per-patch radiance, OpenEXR (C API) and PNG previews. */
#ifndef BOUNCE_IMAGE_H
#define BOUNCE_IMAGE_H

#include <stddef.h>
#include "bounce/scene.h"
#include "bounce/rt.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A pinhole camera. Image row 0 is the top; the image's right is forward x up. */
typedef struct bn_camera {
    double eye[3], look[3], up[3];
    double fov_deg;          /* vertical field of view */
    int    width, height;
    int    spp;              /* supersamples per pixel (stratified), 1 = pixel centres */
} bn_camera;
/* Default: looks at the bounding box's centre from outside its front (-z side), up +y. */
void bn_camera_default(const bn_scene *s, bn_camera *cam);
/* Reads NAME.camera beside the scene if it exists (keys eye, look, up, fov, size, spp);
 * returns BN_OK and leaves *cam unchanged when there is none. */
bn_status bn_camera_load_sidecar(const char *scene_path, bn_camera *cam, bn_error *err);
/* The primary ray through image position (x, y) in pixels (0,0 = top-left corner). */
void bn_camera_ray(const bn_camera *cam, double x, double y, double org[3], double dir[3]);

/* A float RGB image, row-major, row 0 at the top. */
typedef struct bn_image {
    int width, height;
    float *rgb;   /* width*height*3 */
} bn_image;
bn_status bn_image_alloc(bn_image *img, int width, int height, bn_error *err);
void bn_image_free(bn_image *img);

/* A named layer for multi-layer output: "E", "KE", "K2E", ..., "rest", "L", "E_var", ... */
typedef struct bn_layer {
    const char *name;
    const bn_image *img;
} bn_layer;

/* Key/value attributes recorded in file headers (command line, version, solver, tolerance...). */
typedef struct bn_attr {
    const char *key, *value;
} bn_attr;

/* Writes a multi-layer OpenEXR (OpenEXR C API), channels "<layer>.R/G/B"; half = 1 stores half
 * floats (values above 65504 clamped with a warning). Atomic: temp name, then rename. */
bn_status bn_exr_write(const char *path, const bn_layer *layers, size_t nlayers, const bn_attr *attrs,
                       size_t nattrs, int half, const bn_log *log, bn_error *err);

#ifdef __cplusplus
}
#endif
#endif
