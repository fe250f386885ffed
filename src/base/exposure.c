/* What images and bakes share for display: the automatic exposure (the 99th percentile of the
 * luminance of n RGB values, Rec. 709 weights, positive finite ones only, placed at 0.9) and the
 * 8-bit sRGB encoding of an exposed linear value. */
#include "base/internal.h"

#include <math.h>
#include <stdlib.h>

static int bn__cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

double bn__auto_exposure(const float *rgb, size_t n)
{
    size_t m = 0;
    float *lum = bn__malloc_array(n ? n : 1, sizeof(float));
    double p, ev = 0;
    if (!lum)
        return 0;
    for (size_t i = 0; i < n; i++) {
        const float *c = rgb + 3 * i;
        float y = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
        if (y > 0 && isfinite(y))
            lum[m++] = y;
    }
    if (m > 0) {
        qsort(lum, m, sizeof *lum, bn__cmp_float);
        p = lum[(size_t)floor(0.99 * (double)(m - 1))];
        ev = p > 0 ? log2(0.9 / p) : 0;
    }
    free(lum);
    return ev;
}

unsigned char bn__srgb8(double v, double ev)
{
    double x = v * exp2(ev), s;
    if (!(x > 0))
        return 0;   /* also NaN */
    if (x >= 1)
        return 255;
    s = x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1 / 2.4) - 0.055;
    return (unsigned char)floor(s * 255 + 0.5);
}
