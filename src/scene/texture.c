/* Reflectance textures. A textured material's reflectance is its factor (glTF baseColorFactor, MTL Kd)
 * times the texture at the point. Transport is per patch, so K takes each patch's mean reflectance:
 * the texture integrated over the patch (the midpoint rule on a regular subdivision of each of its
 * triangles into sub-triangles no larger than about a texel, so exact for a texture linear over the
 * patch); the final gather's images take the reflectance at each pixel's point (bn_scene_reflectance_at),
 * so a textured floor looks textured at full resolution while the transport stays patch-based. Texture
 * coordinates belong to face corners (an affine map over each triangle; a quad face maps over its two
 * triangles 0-1-2 and 0-2-3, as a rasteriser draws it). */
#include "scene/scene_internal.h"
#include "adapters/adapters.h"
#include "base/vec.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static double bn__srgb_to_linear(double c)
{
    return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

bn_status bn__texture_decode(const char *name, const void *mem, size_t size, bn__texture *t, bn_error *err)
{
    int is_float = 0;
    bn_status st;
    size_t n;
    memset(t, 0, sizeof *t);
    if ((st = bn__oiio_read_rgb(name, mem, size, &t->w, &t->h, &t->rgb, &t->rgb8, &is_float, err)) != BN_OK)
        return st;
    n = 3 * (size_t)t->w * (size_t)t->h;
    for (int b = 0; b < 256; b++)   /* 8-bit images are sRGB: bytes stay bytes, decoded through the table */
        t->lut[b] = (float)bn__srgb_to_linear(b / 255.0);
    for (size_t k = 0; t->rgb && !is_float && k < n; k++)
        t->rgb[k] = (float)bn__srgb_to_linear(t->rgb[k]);
    for (size_t k = 0; t->rgb && k < n; k++)
        if (!(t->rgb[k] >= 0 && t->rgb[k] <= 1)) {
            bn_error_set(err, BN_EINPUT, "%s: texel %zu, %zu holds %g: a reflectance texture's values lie in [0, 1]", name,
                         k / 3 % (size_t)t->w, k / 3 / (size_t)t->w, t->rgb[k]);
            free(t->rgb);
            t->rgb = NULL;
            return BN_EINPUT;
        }
    snprintf(t->name, sizeof t->name, "%s", strrchr(name, '/') ? strrchr(name, '/') + 1 : name);
    return BN_OK;
}

void bn__texture_free(bn__texture *t, size_t n)
{
    for (size_t i = 0; t && i < n; i++) {
        free(t[i].rgb);
        free(t[i].rgb8);
    }
    free(t);
}

static int bn__wrap(int i, int n, int mode)
{
    if (mode == BN__WRAP_CLAMP)
        return i < 0 ? 0 : i >= n ? n - 1 : i;
    if (mode == BN__WRAP_MIRROR) {
        int p = ((i % (2 * n)) + 2 * n) % (2 * n);
        return p < n ? p : 2 * n - 1 - p;
    }
    return ((i % n) + n) % n;
}

void bn__texture_sample(const bn__texture *t, double u, double v, double rgb[3])
{
    double x = u * t->w, y = v * t->h;
    if (!isfinite(x) || !isfinite(y) || fabs(x) > 1e9 || fabs(y) > 1e9)
        x = y = 0;
    if (t->nearest) {
        size_t k = 3 * ((size_t)bn__wrap((int)floor(y), t->h, t->wrap[1]) * (size_t)t->w +
                        (size_t)bn__wrap((int)floor(x), t->w, t->wrap[0]));
        rgb[0] = bn__texel(t, k), rgb[1] = bn__texel(t, k + 1), rgb[2] = bn__texel(t, k + 2);
        return;
    }
    x -= 0.5, y -= 0.5;   /* texel centres at half-integers, as GPUs and glTF sample */
    int i0 = (int)floor(x), j0 = (int)floor(y);
    double fx = x - i0, fy = y - j0;
    int i[2] = {bn__wrap(i0, t->w, t->wrap[0]), bn__wrap(i0 + 1, t->w, t->wrap[0])};
    int j[2] = {bn__wrap(j0, t->h, t->wrap[1]), bn__wrap(j0 + 1, t->h, t->wrap[1])};
    for (int c = 0; c < 3; c++) {
        double a = bn__texel(t, 3 * ((size_t)j[0] * t->w + i[0]) + c), b = bn__texel(t, 3 * ((size_t)j[0] * t->w + i[1]) + c),
               d = bn__texel(t, 3 * ((size_t)j[1] * t->w + i[0]) + c), e = bn__texel(t, 3 * ((size_t)j[1] * t->w + i[1]) + c);
        rgb[c] = (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * d + fx * e);
    }
}

/* Corner k of polygon p's texture coordinates, NaN when it has none. */
static void bn__corner_uv(const bn__soup *s, size_t first, size_t k, double uv[2])
{
    size_t e = 2 * (first + k);
    uv[0] = s->cuv && e + 1 < s->cuv_cap ? s->cuv[e] : NAN;
    uv[1] = s->cuv && e + 1 < s->cuv_cap ? s->cuv[e + 1] : NAN;
}

static bn_status bn__scene_face_emission(bn_scene *sc, const bn__soup *s);

bn_status bn__scene_textures(bn_scene *sc, bn__soup *s)
{
    size_t *first;
    if (!s->tex || s->ntex == 0)
        return BN_OK;
    if (!(first = bn__malloc_array(s->npolys + 1, sizeof *first)) ||
        !(sc->fuv = bn__malloc_array(2 * sc->nfidx + 1, sizeof *sc->fuv)) ||
        !(sc->mat_tex = bn__malloc_array(sc->nmats + 1, sizeof *sc->mat_tex))) {
        free(first);
        return BN_ENOMEM;
    }
    first[0] = 0;
    for (size_t p = 0; p < s->npolys; p++)
        first[p + 1] = first[p] + s->counts[p];
    for (size_t m = 0; m < sc->nmats; m++)
        sc->mat_tex[m] = m < s->mat_tex_cap ? s->mat_tex[m] : -1;
    for (size_t f = 0; f < sc->nfaces; f++) {   /* each corner: the uv of its vertex in its polygon */
        const bn_face *fc = &sc->faces[f];
        size_t p = fc->source;
        for (unsigned j = 0; j < fc->nverts; j++) {
            size_t vi = sc->fidx[fc->first + j], k = 0;
            while (k < s->counts[p] && s->idx[first[p] + k] != vi)
                k++;
            bn__corner_uv(s, first[p], k < s->counts[p] ? k : 0, sc->fuv + 2 * (fc->first + j));
        }
    }
    free(first);
    sc->tex = s->tex, sc->ntex = s->ntex;   /* the soup's textures become the scene's */
    s->tex = NULL, s->ntex = s->tex_cap = 0;
    return bn__scene_face_emission(sc, s);
}

/* Texture coordinates at x (in face f's plane): barycentric over the face's triangle that holds x (a
 * quad: 0-1-2 or 0-2-3, by the side of the diagonal 0-2). 0 when the face has none. */
static int bn__uv_at(const bn_scene *sc, size_t f, const double x[3], double uv[2])
{
    const bn_face *fc = &sc->faces[f];
    const size_t *vi = sc->fidx + fc->first;
    const double *q = sc->fuv + 2 * fc->first;
    unsigned t = 0;
    double e1[3], e2[3], d[3], c[3], a, b;
    if (fc->nverts == 4) {   /* which side of the diagonal 0-2 */
        bn_v3_sub(sc->verts + 3 * vi[2], sc->verts + 3 * vi[0], e1);
        bn_v3_sub(x, sc->verts + 3 * vi[0], d);
        bn_v3_cross(e1, d, c);
        t = bn_v3_dot(c, fc->normal) > 0 ? 1 : 0;
    }
    size_t i0 = 0, i1 = 1 + t, i2 = 2 + t;
    if (isnan(q[2 * i0]) || isnan(q[2 * i1]) || isnan(q[2 * i2]))
        return 0;
    bn_v3_sub(sc->verts + 3 * vi[i1], sc->verts + 3 * vi[i0], e1);
    bn_v3_sub(sc->verts + 3 * vi[i2], sc->verts + 3 * vi[i0], e2);
    bn_v3_sub(x, sc->verts + 3 * vi[i0], d);
    double d11 = bn_v3_dot(e1, e1), d12 = bn_v3_dot(e1, e2), d22 = bn_v3_dot(e2, e2), den = d11 * d22 - d12 * d12;
    if (!(den > 0))
        return 0;
    a = (d22 * bn_v3_dot(d, e1) - d12 * bn_v3_dot(d, e2)) / den;
    b = (d11 * bn_v3_dot(d, e2) - d12 * bn_v3_dot(d, e1)) / den;
    for (int k = 0; k < 2; k++)
        uv[k] = q[2 * i0 + k] + a * (q[2 * i1 + k] - q[2 * i0 + k]) + b * (q[2 * i2 + k] - q[2 * i0 + k]);
    return 1;
}

void bn_scene_reflectance_at(const bn_scene *s, size_t face, const double x[3], double rho[3])
{
    const bn_material *m = &s->mats[s->faces[face].material];
    int t = s->mat_tex ? s->mat_tex[s->faces[face].material] : -1;
    double uv[2], tx[3];
    memcpy(rho, m->rho, 3 * sizeof *rho);
    if (t < 0 || !bn__uv_at(s, face, x, uv))
        return;
    bn__texture_sample(&s->tex[t], uv[0], uv[1], tx);
    for (int c = 0; c < 3; c++)
        rho[c] *= tx[c];
}

/* The mean of texture t over triangle (a, b, c) of face f (1 where the face has no coordinates); its
 * area returned. Midpoint rule on the triangle's k x k regular subdivision, sub-triangles of about a
 * texel (k from the triangle's area in texels, 1 .. 64): exact where the texture is linear. */
static double bn__tri_texture(const bn_scene *sc, size_t f, const bn__texture *t, const double *a, const double *b,
                              const double *c, double mean[3])
{
    double e1[3], e2[3], n[3], uv[3][2], uva, sum[3] = {0, 0, 0};
    bn_v3_sub(b, a, e1);
    bn_v3_sub(c, a, e2);
    bn_v3_cross(e1, e2, n);
    mean[0] = mean[1] = mean[2] = 1;
    if (!bn__uv_at(sc, f, a, uv[0]) || !bn__uv_at(sc, f, b, uv[1]) || !bn__uv_at(sc, f, c, uv[2]))
        return 0.5 * bn_v3_len(n);
    uva = 0.5 * fabs((uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1]) - (uv[2][0] - uv[0][0]) * (uv[1][1] - uv[0][1]));
    double kk = ceil(sqrt(2.0 * uva * t->w * t->h));
    int k = !(kk >= 1) ? 1 : kk > 64 ? 64 : (int)kk;
    bn_subtri it = {k, 0, 0, 0};
    double s1, s2, rgb[3];
    while (bn_subtri_next(&it, &s1, &s2)) {   /* k^2 sub-triangles */
        bn__texture_sample(t, uv[0][0] + s1 * (uv[1][0] - uv[0][0]) + s2 * (uv[2][0] - uv[0][0]),
                           uv[0][1] + s1 * (uv[1][1] - uv[0][1]) + s2 * (uv[2][1] - uv[0][1]), rgb);
        for (int ch = 0; ch < 3; ch++)
            sum[ch] += rgb[ch];
    }
    for (int ch = 0; ch < 3; ch++)
        mean[ch] = sum[ch] / ((double)k * k);
    return 0.5 * bn_v3_len(n);
}

bn_status bn__scene_patch_textures(bn_scene *sc, bn_error *err)
{
    free(sc->ptex);
    sc->ptex = NULL;
    if (!sc->mat_tex)
        return BN_OK;
    if (!(sc->ptex = bn__malloc_array(3 * sc->npatches + 1, sizeof *sc->ptex)))
        return bn_error_set(err, BN_ENOMEM, "out of memory for the patches' textured reflectance");
    for (size_t p = 0; p < sc->npatches; p++) {
        const bn_patch *q = &sc->patches[p];
        int t = sc->mat_tex[q->material];
        double acc[3] = {0, 0, 0}, wsum = 0, mean[3];
        for (unsigned k = 1; t >= 0 && k + 1 < q->ncorners; k++) {   /* the patch as a fan of triangles */
            double w = bn__tri_texture(sc, q->face, &sc->tex[t], sc->pverts + 3 * q->corner[0],
                                       sc->pverts + 3 * q->corner[k], sc->pverts + 3 * q->corner[k + 1], mean);
            wsum += w;
            for (int c = 0; c < 3; c++)
                acc[c] += w * mean[c];
        }
        for (int c = 0; c < 3; c++)
            sc->ptex[3 * p + c] = wsum > 0 ? acc[c] / wsum : 1;
    }
    return BN_OK;
}

void bn__texture_mean(const bn__texture *t, double mean[3])
{
    size_t n = (size_t)t->w * (size_t)t->h;
    mean[0] = mean[1] = mean[2] = 0;
    for (size_t k = 0; k < n; k++)
        for (int c = 0; c < 3; c++)
            mean[c] += bn__texel(t, 3 * k + c) / (double)n;
}

int bn_scene_material_texture(const bn_scene *s, size_t m, const char **name, int *w, int *h, double mean[3])
{
    int t = s->mat_tex && m < s->nmats ? s->mat_tex[m] : -1;
    if (t < 0)
        return 0;
    const bn__texture *x = &s->tex[t];
    *name = x->name, *w = x->w, *h = x->h;
    bn__texture_mean(x, mean);
    return 1;
}

/* Each face of a material with an emission texture: the texture's mean over the face (a fan of its
 * triangles, each integrated as the patches' reflectance is): emission stays uniform over a face (the
 * final gather's closed-form direct light needs it), its power as the texture gives it there. */
static bn_status bn__scene_face_emission(bn_scene *sc, const bn__soup *s)
{
    int any = 0;
    for (size_t m = 0; m < sc->nmats && m < s->mat_etex_cap; m++)
        any |= s->mat_etex[m] >= 0;
    if (!any)
        return BN_OK;
    if (!(sc->mat_etex = bn__malloc_array(sc->nmats + 1, sizeof *sc->mat_etex)) ||
        !(sc->femit = bn__malloc_array(3 * sc->nfaces + 1, sizeof *sc->femit)))
        return BN_ENOMEM;
    for (size_t m = 0; m < sc->nmats; m++)
        sc->mat_etex[m] = m < s->mat_etex_cap ? s->mat_etex[m] : -1;
    for (size_t f = 0; f < sc->nfaces; f++) {
        const bn_face *fc = &sc->faces[f];
        const size_t *vi = sc->fidx + fc->first;
        int t = sc->mat_etex[fc->material];
        double acc[3] = {0, 0, 0}, wsum = 0, mean[3];
        for (unsigned k = 1; t >= 0 && k + 1 < fc->nverts; k++) {
            double w = bn__tri_texture(sc, f, &sc->tex[t], sc->verts + 3 * vi[0], sc->verts + 3 * vi[k],
                                       sc->verts + 3 * vi[k + 1], mean);
            wsum += w;
            for (int c = 0; c < 3; c++)
                acc[c] += w * mean[c];
        }
        for (int c = 0; c < 3; c++)
            sc->femit[3 * f + c] = wsum > 0 ? acc[c] / wsum : 1;
    }
    return BN_OK;
}

void bn_scene_patch_texture_factors(const bn_scene *s, double *rho_f, double *Le_f)
{
    for (size_t p = 0; p < s->npatches; p++)
        for (int c = 0; c < 3; c++) {
            if (rho_f)
                rho_f[3 * p + c] = s->ptex ? s->ptex[3 * p + c] : 1;
            if (Le_f)
                Le_f[3 * p + c] = s->femit ? s->femit[3 * s->patches[p].face + c] : 1;
        }
}

void bn_scene_face_emission(const bn_scene *s, size_t f, double Le[3])
{
    const double *m = s->mats[s->faces[f].material].Le;
    for (int c = 0; c < 3; c++)
        Le[c] = s->femit ? m[c] * s->femit[3 * f + c] : m[c];
}
