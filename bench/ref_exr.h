/* The benches' reading of a `bounce trace` reference EXR (a layer and its variance, through the
 * OpenEXR C API) and its per-pixel error measure: the median over pixels of |x - ref| / ref in
 * luminance with the reference's own variance taken out (err^2 = max(0, (x - ref)^2 - var_ref)),
 * over the pixels whose reference exceeds 1e-3 of the brightest. */
#ifndef BOUNCE_BENCH_REF_EXR_H
#define BOUNCE_BENCH_REF_EXR_H

typedef struct exr_img {
    int w, h;
    float *L, *var;   /* 3wh each (var NULL when absent) */
} exr_img;

/* Layer `layer` (and `layer`_var with with_var) of an EXR into im (allocated; free it with exr_img_free
 * whatever the result); 0, with a message on stderr naming the file and layer, when absent. */
int exr_img_load(const char *path, const char *layer, exr_img *im, int with_var);
void exr_img_free(exr_img *im);
/* The median relative error (noise-corrected), raw, and the reference's own median standard error. */
void exr_median_err(const exr_img *ref, const float *x, double out[3]);

#endif
