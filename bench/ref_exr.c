/* bench/ref_exr.h: a reference EXR's layer and the median per-pixel error against it. */
#include "ref_exr.h"

#include <openexr.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const double WY[3] = {0.2126, 0.7152, 0.0722};

/* Channel `layer.C` of an EXR into out (w*h floats, C in R, G, B); 0 when absent. */
static int read_layer(const char *path, const char *layer, exr_img *im, float *out3)
{
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    const exr_attr_chlist_t *chl;
    exr_attr_box2i_t dw;
    int32_t lines;
    int found = 0;
    if (exr_start_read(&ctx, path, &init) != EXR_ERR_SUCCESS)
        return 0;
    exr_get_channels(ctx, 0, &chl);
    exr_get_data_window(ctx, 0, &dw);
    exr_get_scanlines_per_chunk(ctx, 0, &lines);
    im->w = dw.max.x - dw.min.x + 1;
    im->h = dw.max.y - dw.min.y + 1;
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    for (int y = 0; y < im->h; y += lines) {
        exr_chunk_info_t ci;
        if (exr_read_scanline_chunk_info(ctx, 0, y + dw.min.y, &ci) != EXR_ERR_SUCCESS)
            break;
        if (y == 0 ? exr_decoding_initialize(ctx, 0, &ci, &dec) : exr_decoding_update(ctx, 0, &ci, &dec))
            break;
        for (int c = 0; c < dec.channel_count; c++) {
            const char *name = dec.channels[c].channel_name, *dot = strrchr(name, '.');
            int k = dot ? (int)(strchr("RGB", dot[1]) ? strchr("RGB", dot[1]) - "RGB" : -1) : -1;
            dec.channels[c].decode_to_ptr = NULL;
            if (!dot || k < 0 || dot[2] || (size_t)(dot - name) != strlen(layer) || strncmp(name, layer, strlen(layer)))
                continue;
            found |= 1 << k;
            dec.channels[c].decode_to_ptr = (uint8_t *)(out3 + 3 * (size_t)(ci.start_y - dw.min.y) * im->w + k);
            dec.channels[c].user_pixel_stride = 12;
            dec.channels[c].user_line_stride = 12 * im->w;
            dec.channels[c].user_data_type = EXR_PIXEL_FLOAT;
            dec.channels[c].user_bytes_per_element = 4;
        }
        if (y == 0 && exr_decoding_choose_default_routines(ctx, 0, &dec) != EXR_ERR_SUCCESS)
            break;
        if (exr_decoding_run(ctx, 0, &dec) != EXR_ERR_SUCCESS)
            break;
    }
    exr_decoding_destroy(ctx, &dec);
    exr_finish(&ctx);
    return found == 7;
}

int exr_img_load(const char *path, const char *layer, exr_img *im, int with_var)
{
    char var[256];
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_attr_box2i_t dw;
    *im = (exr_img){0};   /* freeable whatever happens below */
    if (exr_start_read(&ctx, path, &init) != EXR_ERR_SUCCESS) {
        fprintf(stderr, "%s: cannot be read as OpenEXR\n", path);
        return 0;
    }
    exr_get_data_window(ctx, 0, &dw);
    exr_finish(&ctx);
    im->w = dw.max.x - dw.min.x + 1;
    im->h = dw.max.y - dw.min.y + 1;
    im->L = calloc((size_t)3 * im->w * im->h, sizeof(float));
    im->var = with_var ? calloc((size_t)3 * im->w * im->h, sizeof(float)) : NULL;
    if (!im->L || (with_var && !im->var)) {
        fprintf(stderr, "%s: out of memory for a %dx%d layer\n", path, im->w, im->h);
        return 0;
    }
    snprintf(var, sizeof var, "%s_var", layer);
    if (!read_layer(path, layer, im, im->L)) {
        fprintf(stderr, "%s: no layer %s (channels %s.R, %s.G, %s.B)\n", path, layer, layer, layer, layer);
        return 0;
    }
    if (with_var && !read_layer(path, var, im, im->var)) {
        fprintf(stderr, "%s: no layer %s (a reference from `bounce trace` has one per term)\n", path, var);
        return 0;
    }
    return 1;
}

void exr_img_free(exr_img *im)
{
    free(im->L);
    free(im->var);
    im->L = im->var = NULL;
}

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

void exr_median_err(const exr_img *ref, const float *L, double out[3])
{
    size_t n = (size_t)ref->w * ref->h, m = 0;
    double *e = malloc(3 * n * sizeof *e), ymax = 0;
    for (size_t i = 0; i < n; i++)
        ymax = fmax(ymax, WY[0] * ref->L[3 * i] + WY[1] * ref->L[3 * i + 1] + WY[2] * ref->L[3 * i + 2]);
    for (size_t i = 0; i < n; i++) {
        double y = 0, x = 0, v = 0, d;
        for (int c = 0; c < 3; c++) {
            y += WY[c] * ref->L[3 * i + c];
            x += WY[c] * L[3 * i + c];
            v += WY[c] * WY[c] * ref->var[3 * i + c];
        }
        if (!(y > 1e-3 * ymax))
            continue;
        d = x - y;
        e[m] = sqrt(fmax(0, d * d - v)) / y;
        e[n + m] = fabs(d) / y;
        e[2 * n + m] = sqrt(v) / y;
        m++;
    }
    for (int k = 0; k < 3; k++) {
        qsort(e + k * n, m, sizeof *e, cmp_d);
        out[k] = m ? e[k * n + m / 2] : NAN;
    }
    free(e);
}
