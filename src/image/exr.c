/* Multi-layer OpenEXR through the OpenEXR C API (OpenEXRCore): one scanline part, ZIP,
 * channels "<layer>.R/G/B", float or half, string attributes for provenance. */
#include "bounce/image.h"
#include "base/internal.h"

#include <math.h>
#include <openexr.h>
#include <string.h>

#define BN__HALF_MAX 65504.0f

static bn_status bn__exr_fail(bn_error *err, const char *path, const char *what, exr_result_t rv)
{
    return bn_error_set(err, rv == EXR_ERR_OUT_OF_MEMORY ? BN_ENOMEM : BN_EIO, "%s: OpenEXR %s: %s", path, what,
                        exr_get_default_error_message(rv));
}

/* Silence OpenEXR's default stderr printing: errors come back as codes and are reported by us. */
static void bn__exr_quiet(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    (void)code;
    (void)msg;
}

/* Every layer w x h with a name that fits, and finite. */
static bn_status bn__exr_check(const char *path, const bn_layer *layers, size_t nlayers, bn_error *err)
{
    int w = layers[0].img->width, h = layers[0].img->height;
    for (size_t l = 0; l < nlayers; l++) {
        const bn_image *im = layers[l].img;
        size_t n = (size_t)w * h * 3;
        if (im->width != w || im->height != h)
            return bn_error_set(err, BN_EINTERNAL, "%s: layer %s is %dx%d, not %dx%d", path, layers[l].name, im->width,
                                im->height, w, h);
        if (strlen(layers[l].name) + 3 > 128)
            return bn_error_set(err, BN_EINTERNAL, "%s: layer name too long", path);
        for (size_t i = 0; i < n; i++)
            if (!isfinite(im->rgb[i]))
                return bn_error_set(err, BN_ENUMERIC, "%s: layer %s has a non-finite value at pixel (%zu, %zu)", path,
                                    layers[l].name, (i / 3) % (size_t)w, (i / 3) / (size_t)w);
    }
    return BN_OK;
}

/* What each layer's pixels are written from: the image itself, or for half a copy clamped to
 * +-65504 when some value is beyond (said as a warning). src and clamped: nlayers each. */
static bn_status bn__exr_sources(const char *path, const bn_layer *layers, size_t nlayers, int half, const bn_log *log,
                                 const float **src, float **clamped, bn_error *err)
{
    for (size_t l = 0; l < nlayers; l++) {
        const bn_image *im = layers[l].img;
        size_t n = (size_t)im->width * im->height * 3, over = 0;
        src[l] = im->rgb;
        if (!half)
            continue;
        for (size_t i = 0; i < n; i++)
            over += fabsf(im->rgb[i]) > BN__HALF_MAX;
        if (!over)
            continue;
        clamped[l] = bn__malloc_array(n, sizeof(float));
        if (!clamped[l])
            return bn_error_set(err, BN_ENOMEM, "out of memory");
        for (size_t i = 0; i < n; i++)
            clamped[l][i] = fmaxf(-BN__HALF_MAX, fminf(BN__HALF_MAX, im->rgb[i]));
        src[l] = clamped[l];
        bn_warnf(log, BN_W_CLAMPED, (double)over, "%s: layer %s: %zu values above half's largest value 65504 were clamped", path,
                layers[l].name, over);
    }
    return BN_OK;
}

/* The part: its size, ZIP, a channel "<layer>.R/G/B" per layer and colour, the attributes; the
 * header written and the scanlines per chunk in *lines. */
static exr_result_t bn__exr_header(exr_context_t ctx, int *part, const bn_layer *layers, size_t nlayers,
                                   const bn_attr *attrs, size_t nattrs, int half, int32_t *lines)
{
    char name[128];
    exr_result_t rv = exr_add_part(ctx, "bounce", EXR_STORAGE_SCANLINE, part);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr_simple(ctx, *part, layers[0].img->width, layers[0].img->height,
                                                 EXR_COMPRESSION_ZIP);
    for (size_t l = 0; l < nlayers && rv == EXR_ERR_SUCCESS; l++)
        for (int c = 0; c < 3 && rv == EXR_ERR_SUCCESS; c++) {
            snprintf(name, sizeof name, "%s.%c", layers[l].name, "RGB"[c]);
            rv = exr_add_channel(ctx, *part, name, half ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT,
                                 EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
        }
    for (size_t a = 0; a < nattrs && rv == EXR_ERR_SUCCESS; a++)
        rv = exr_attr_set_string(ctx, *part, attrs[a].key, attrs[a].value);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_write_header(ctx);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_scanlines_per_chunk(ctx, *part, lines);
    return rv;
}

/* Points each of the chunk's channels (sorted by name) at its layer's colour in src. */
static void bn__exr_point(exr_encode_pipeline_t *enc, const exr_chunk_info_t *ci, const bn_layer *layers,
                          size_t nlayers, const float **src, int w)
{
    for (int16_t c = 0; c < enc->channel_count; c++) {
        exr_coding_channel_info_t *ch = &enc->channels[c];
        const char *nm = ch->channel_name, *dot = strrchr(nm, '.');
        size_t l;
        int k;
        for (l = 0; l < nlayers; l++)
            if (dot && strlen(layers[l].name) == (size_t)(dot - nm) && strncmp(layers[l].name, nm, dot - nm) == 0)
                break;
        BN_CHECK(l < nlayers && dot && dot[1] && !dot[2]);
        k = dot[1] == 'R' ? 0 : dot[1] == 'G' ? 1 : 2;
        ch->user_pixel_stride = 3 * sizeof(float);
        ch->user_line_stride = w * 3 * (int32_t)sizeof(float);
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = sizeof(float);
        ch->encode_from_ptr = (const uint8_t *)(src[l] + ((size_t)ci->start_y * w) * 3 + k);
    }
}

/* Every chunk of scanlines encoded and written; *enc_init says whether enc needs destroying. */
static bn_status bn__exr_chunks(exr_context_t ctx, int part, int32_t lines, exr_encode_pipeline_t *enc, int *enc_init,
                                const char *path, const bn_layer *layers, size_t nlayers, const float **src,
                                bn_error *err)
{
    int w = layers[0].img->width, h = layers[0].img->height;
    for (int y = 0; y < h; y += lines) {
        exr_chunk_info_t ci;
        exr_result_t rv = exr_write_scanline_chunk_info(ctx, part, y, &ci);
        if (rv == EXR_ERR_SUCCESS)
            rv = *enc_init ? exr_encoding_update(ctx, part, &ci, enc) : exr_encoding_initialize(ctx, part, &ci, enc);
        if (rv != EXR_ERR_SUCCESS)
            return bn__exr_fail(err, path, "chunk", rv);
        *enc_init = 1;
        bn__exr_point(enc, &ci, layers, nlayers, src, w);
        if (y == 0)
            rv = exr_encoding_choose_default_routines(ctx, part, enc);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_encoding_run(ctx, part, enc);
        if (rv != EXR_ERR_SUCCESS)
            return bn__exr_fail(err, path, "encoding", rv);
        if (bn_interrupted() != BN_OK)
            return bn_error_set(err, bn_interrupted(), "interrupted");
    }
    return BN_OK;
}

bn_status bn_exr_write(const char *path, const bn_layer *layers, size_t nlayers, const bn_attr *attrs,
                       size_t nattrs, int half, const bn_log *log, bn_error *err)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_context_t ctx = NULL;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    exr_result_t rv;
    int part = 0, enc_init = 0;
    int32_t lines = 1;
    char *tmp = NULL;
    const float **src = NULL;
    float **clamped = NULL;
    bn_status st;

    if (nlayers == 0)
        return bn_error_set(err, BN_EINTERNAL, "%s: no layers to write", path);
    if ((st = bn__exr_check(path, layers, nlayers, err)) != BN_OK)
        return st;
    src = bn__calloc(nlayers, sizeof *src);
    clamped = bn__calloc(nlayers, sizeof *clamped);
    st = src && clamped ? bn__exr_sources(path, layers, nlayers, half, log, src, clamped, err)
                        : bn_error_set(err, BN_ENOMEM, "out of memory");
    if (st == BN_OK)
        st = bn__tmpname_reserve(path, &tmp, err);
    if (st != BN_OK)
        goto done;
    init.error_handler_fn = bn__exr_quiet;
    rv = exr_start_write(&ctx, tmp, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv != EXR_ERR_SUCCESS) {
        st = bn__exr_fail(err, path, "cannot create the file", rv);
        goto done;
    }
    rv = bn__exr_header(ctx, &part, layers, nlayers, attrs, nattrs, half, &lines);
    if (rv != EXR_ERR_SUCCESS) {
        st = bn__exr_fail(err, path, "header", rv);
        goto done;
    }
    st = bn__exr_chunks(ctx, part, lines, &enc, &enc_init, path, layers, nlayers, src, err);
    if (st != BN_OK)
        goto done;
    if (enc_init) {
        exr_encoding_destroy(ctx, &enc);
        enc_init = 0;
    }
    rv = exr_finish(&ctx);
    ctx = NULL;
    if (rv != EXR_ERR_SUCCESS) {
        st = bn__exr_fail(err, path, "finishing the file", rv);
        goto done;
    }
    st = bn__tmpname_commit(path, tmp, err);
    tmp = NULL;
done:
    if (enc_init)
        exr_encoding_destroy(ctx, &enc);
    if (ctx)
        exr_finish(&ctx);
    if (tmp)
        bn__tmpname_abort(tmp);
    if (clamped)
        for (size_t l = 0; l < nlayers; l++)
            free(clamped[l]);
    free(clamped);
    free(src);
    return st;
}
