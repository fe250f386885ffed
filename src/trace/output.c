/* The tracer's outputs: per-patch estimates as CSV, and the image as a multi-layer EXR with each
 * layer's variance beside it. */
#include "bounce/trace.h"
#include "base/internal.h"

#include <string.h>

void bn__trace_csv_layer_head(FILE *fp, const bn_trace_patches *r)
{
    char name[16];
    for (int l = 0; l < r->nlayers; l++) {
        bn_layer_name(l, r->bounces, name, sizeof name);
        fprintf(fp, ",%s.R,%s.G,%s.B,%s.R_se,%s.G_se,%s.B_se", name, name, name, name, name, name);
    }
    fputc('\n', fp);
}

void bn__trace_csv_layer_row(FILE *fp, const bn_trace_patches *r, size_t i)
{
    for (int l = 0; l < r->nlayers; l++) {
        const double *v = r->mean + ((size_t)l * r->n + i) * 3, *e = r->se + ((size_t)l * r->n + i) * 3;
        fprintf(fp, ",%.9g,%.9g,%.9g,%.6g,%.6g,%.6g", v[0], v[1], v[2], e[0], e[1], e[2]);
    }
    fputc('\n', fp);
}

bn_status bn_trace_patches_write_csv(const char *path, const bn_scene *s, const bn_trace_patches *r,
                                     const char *header, bn_error *err)
{
    bn__outfile f;
    bn_status st = bn__outfile_open(&f, path, "w", err);
    size_t n;
    const bn_patch *p = bn_scene_patches(s, &n);
    const bn_material *mats = bn_scene_materials(s, NULL);
    double m = bn_unit_to_metres(bn_scene_unit(s));
    if (st != BN_OK)
        return st;
    fputs(header, f.fp);
    fprintf(f.fp, "patch,face,material,area_m2,cx,cy,cz");
    bn__trace_csv_layer_head(f.fp, r);
    for (size_t i = 0; i < r->n; i++) {
        fprintf(f.fp, "%zu,%zu,%s,%.10g,%.10g,%.10g,%.10g", i, p[i].face, mats[p[i].material].name, p[i].area * m * m,
                p[i].centroid[0], p[i].centroid[1], p[i].centroid[2]);
        bn__trace_csv_layer_row(f.fp, r, i);
    }
    return bn__outfile_commit(&f, err);
}

bn_status bn_trace_image_write(const bn_trace_image *img, const char *path, const bn_attr *attrs, size_t nattrs,
                               int half, const bn_log *log, bn_error *err)
{
    size_t nl = (size_t)img->nlayers, npx = (size_t)img->width * (size_t)img->height;
    bn_layer *layers = calloc(2 * nl, sizeof *layers);
    bn_image *views = calloc(2 * nl, sizeof *views);
    char (*names)[24] = calloc(2 * nl, sizeof *names);
    bn_status st;
    if (!layers || !views || !names) {
        st = bn_error_set(err, BN_ENOMEM, "out of memory");
    } else {
        for (size_t l = 0; l < nl; l++) {
            char name[16];
            bn_layer_name((int)l, img->bounces, name, sizeof name);
            snprintf(names[l], sizeof names[l], "%s", name);
            snprintf(names[nl + l], sizeof names[0], "%s_var", name);
            views[l] = (bn_image){img->width, img->height, img->mean + l * npx * 3};
            views[nl + l] = (bn_image){img->width, img->height, img->var + l * npx * 3};
        }
        for (size_t l = 0; l < 2 * nl; l++)
            layers[l] = (bn_layer){names[l], &views[l]};
        st = bn_exr_write(path, layers, 2 * nl, attrs, nattrs, half, log, err);
    }
    free(layers);
    free(views);
    free(names);
    return st;
}
