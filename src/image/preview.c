/* Previews a person looks at first: 8-bit sRGB PNGs at an exposure, and the labelled contact
 * sheet (row 1 one exposure for all layers, row 2 each layer normalised on its own). */
#include "bounce/image.h"
#include "adapters/adapters.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

#ifndef BN_FONT_DIR
#define BN_FONT_DIR "/usr/share/fonts/truetype/dejavu"
#endif

unsigned char bn_tonemap_srgb8(double v, double ev) { return bn__srgb8(v, ev); }

double bn_image_auto_exposure(const bn_image *img)
{
    return bn__auto_exposure(img->rgb, (size_t)img->width * img->height);
}

static void bn__to_rgb8(const bn_image *img, double ev, unsigned char *out)
{
    size_t n = (size_t)img->width * img->height * 3;
    for (size_t i = 0; i < n; i++)
        out[i] = bn_tonemap_srgb8(img->rgb[i], ev);
}

static bn_status bn__write_rgb8(const char *path, int w, int h, const unsigned char *rgb, const bn__label *labels,
                                size_t nlabels, const bn_attr *attrs, size_t nattrs, int *labels_ok, bn_error *err)
{
    char *tmp = NULL;
    bn_status st = bn__tmpname_reserve(path, &tmp, err);
    if (st != BN_OK)
        return st;
    st = bn__oiio_write_rgb8(tmp, w, h, rgb, labels, nlabels, BN_FONT_DIR "/DejaVuSans.ttf", attrs, nattrs,
                             labels_ok, err);
    if (st != BN_OK) {
        bn__tmpname_abort(tmp);
        /* Messages name the file the user asked for, not the temporary one. */
        if (err)
            bn_error_set(err, st, "%s: cannot write the image (%s)", path, err->msg);
        return st;
    }
    return bn__tmpname_commit(path, tmp, err);
}

bn_status bn_png_write(const char *path, const bn_image *img, double ev, const bn_attr *attrs, size_t nattrs,
                       bn_error *err)
{
    unsigned char *rgb = bn__malloc_array((size_t)img->width * img->height, 3);
    bn_status st;
    int ok;
    if (!rgb)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    bn__to_rgb8(img, ev, rgb);
    st = bn__write_rgb8(path, img->width, img->height, rgb, NULL, 0, attrs, nattrs, &ok, err);
    free(rgb);
    return st;
}

/* Box-downsamples img by an integer factor k into a (ceil(w/k) x ceil(h/k)) linear image. */
static bn_status bn__downsample(const bn_image *img, int k, bn_image *out, bn_error *err)
{
    int tw = (img->width + k - 1) / k, th = (img->height + k - 1) / k;
    bn_status st = bn_image_alloc(out, tw, th, err);
    if (st != BN_OK)
        return st;
    for (int ty = 0; ty < th; ty++)
        for (int tx = 0; tx < tw; tx++) {
            double s[3] = {0, 0, 0};
            int n = 0;
            for (int y = ty * k; y < ty * k + k && y < img->height; y++)
                for (int x = tx * k; x < tx * k + k && x < img->width; x++, n++)
                    for (int c = 0; c < 3; c++)
                        s[c] += img->rgb[3 * ((size_t)y * img->width + x) + c];
            for (int c = 0; c < 3; c++)
                out->rgb[3 * ((size_t)ty * tw + tx) + c] = (float)(s[c] / n);
        }
    return BN_OK;
}

/* The contact sheet's layout: tiles of tw x th (the layers shrunk k times), the sheet sw x sh. */
enum { BN__SHEET_MARGIN = 10, BN__SHEET_TITLE = 34, BN__SHEET_LABEL = 30, BN__SHEET_FONT = 20 };
typedef struct bn__sheet {
    int k, tw, th, sw, sh;
    unsigned char *rgb;
    bn__label *labels;
    char (*text)[96];
    size_t nl;
} bn__sheet;

/* The next label's text store (96 bytes), then the label at (x, y) with it. */
static char *bn__sheet_text(bn__sheet *S) { return S->text[S->nl]; }

static void bn__sheet_label(bn__sheet *S, int x, int y, int size)
{
    S->labels[S->nl] = (bn__label){x, y, size, S->text[S->nl]};
    S->nl++;
}

/* Layer l's two tiles (row 1 at ev, row 2 at its own exposure) and their labels. */
static bn_status bn__sheet_layer(bn__sheet *S, const bn_layer *layer, size_t l, double ev, bn_error *err)
{
    bn_image small;
    unsigned char *rgb;
    double own;
    bn_status st = bn__downsample(layer->img, S->k, &small, err);
    if (st != BN_OK)
        return st;
    rgb = bn__malloc_array((size_t)S->tw * S->th, 3);
    if (!rgb) {
        bn_image_free(&small);
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    own = bn_image_auto_exposure(&small);
    for (int row = 0; row < 2; row++) {
        int x0 = BN__SHEET_MARGIN + (int)l * (S->tw + BN__SHEET_MARGIN);
        int y0 = BN__SHEET_TITLE + row * (BN__SHEET_LABEL + S->th + BN__SHEET_MARGIN) + BN__SHEET_LABEL;
        bn__to_rgb8(&small, row == 0 ? ev : own, rgb);
        for (int y = 0; y < S->th; y++)
            memcpy(S->rgb + 3 * ((size_t)(y0 + y) * S->sw + x0), rgb + 3 * (size_t)y * S->tw, 3 * (size_t)S->tw);
        if (row == 0)
            snprintf(bn__sheet_text(S), 96, "%s", layer->name);
        else
            snprintf(bn__sheet_text(S), 96, "%s %+.1f EV", layer->name, own);
        bn__sheet_label(S, x0 + 2, y0 - 8, BN__SHEET_FONT);
    }
    free(rgb);
    bn_image_free(&small);
    return BN_OK;
}

bn_status bn_contact_sheet_write(const char *path, const bn_layer *layers, size_t nlayers, double ev, int tile,
                                 const bn_attr *attrs, size_t nattrs, const bn_log *log, bn_error *err)
{
    int w, h, ok = 1;
    bn__sheet S = {0};
    bn_status st = BN_OK;
    if (nlayers == 0)
        return bn_error_set(err, BN_EINTERNAL, "%s: no layers", path);
    if (tile <= 0)
        tile = 320;
    w = layers[0].img->width;
    h = layers[0].img->height;
    S.k = (w + tile - 1) / tile;
    S.tw = (w + S.k - 1) / S.k;
    S.th = (h + S.k - 1) / S.k;
    S.sw = BN__SHEET_MARGIN + (int)nlayers * (S.tw + BN__SHEET_MARGIN);
    S.sh = BN__SHEET_TITLE + 2 * (BN__SHEET_LABEL + S.th + BN__SHEET_MARGIN);
    S.rgb = bn__malloc_array((size_t)S.sw * S.sh, 3);
    S.labels = bn__calloc(2 * nlayers + 2, sizeof *S.labels);
    S.text = bn__calloc(2 * nlayers + 2, sizeof *S.text);
    if (!S.rgb || !S.labels || !S.text) {
        st = bn_error_set(err, BN_ENOMEM, "out of memory for the contact sheet");
        goto done;
    }
    memset(S.rgb, 24, (size_t)S.sw * S.sh * 3);
    snprintf(bn__sheet_text(&S), 96, "row 1: every layer at %+.2f EV", ev);
    bn__sheet_label(&S, BN__SHEET_MARGIN, 24, 18);
    snprintf(bn__sheet_text(&S), 96, "row 2: each layer normalised on its own");
    bn__sheet_label(&S, BN__SHEET_MARGIN + S.sw / 2, 24, 18);
    for (size_t l = 0; l < nlayers && st == BN_OK; l++) {
        if (layers[l].img->width != w || layers[l].img->height != h)
            st = bn_error_set(err, BN_EINTERNAL, "%s: layers differ in size", path);
        else
            st = bn__sheet_layer(&S, &layers[l], l, ev, err);
    }
    if (st == BN_OK)
        st = bn__write_rgb8(path, S.sw, S.sh, S.rgb, S.labels, S.nl, attrs, nattrs, &ok, err);
    if (st == BN_OK && !ok)
        bn_warnf(log, BN_W_FONT, NAN, "%s: labels could not be drawn (font %s/DejaVuSans.ttf missing?); the sheet is "
                "unlabelled", path, BN_FONT_DIR);
done:
    free(S.rgb);
    free(S.labels);
    free(S.text);
    return st;
}
