/* Points for the tracer (bn_trace_points_read, _write_csv): a file of `x y z nx ny nz` lines placed on
 * the scene's faces, and the per-point estimates written back in the file's order. */
#include "trace/trace_internal.h"
#include "base/vec.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define BN__POINT_AGREE 0.95   /* a face's normal agrees with a point's within about 18 degrees */

/* The front of the face within tol of x along n: a ray from x + tol n towards -n, 2 tol long, that
 * arrives on a patch's front side; a point on a face's edge or corner (a bake's vertex) may slip past
 * it, so more rays around it, on rings tol / 4, tol / 2 and 9 tol / 10 aside, 32 a ring (a sliver's
 * corner a few degrees wide is met), look for the faces it bounds. Of the faces met, the one whose
 * normal agrees best with n (at a vertex of a curved mesh several faces meet, and their radiances differ
 * near a shadow's edge: n says which is wanted); at least BN__POINT_AGREE (at a convex corner a ray may
 * graze the other face there). 1 and the patch, or 0. */
static int bn__point_patch(const bn_rt *rt, const double x[3], const double n[3], double tol, size_t *patch)
{
    static const double ring[3] = {0.25, 0.5, 0.9};
    const bn_patch *pa = bn_scene_patches(bn_rt_scene(rt), NULL);
    double d[3] = {-n[0], -n[1], -n[2]}, s[3], t[3], best = BN__POINT_AGREE;
    int found = 0;
    bn_v3_basis(n, s, t);
    for (int k = 0; k < 1 + 3 * 32 && best < 1 - 1e-12; k++) {
        double o[3], a = 2 * 3.14159265358979323846 * ((k - 1) % 32) / 32, r = k ? ring[(k - 1) / 32] * tol : 0;
        bn_hit h;
        for (int c = 0; c < 3; c++)
            o[c] = x[c] + tol * n[c] + r * (cos(a) * s[c] + sin(a) * t[c]);
        if (bn_rt_intersect(rt, o, d, 0, 2 * tol, &h) && h.front && bn_v3_dot(pa[h.patch].normal, n) >= best) {
            best = bn_v3_dot(pa[h.patch].normal, n);
            *patch = h.patch;
            found = 1;
        }
    }
    return found;
}

/* One line's point: 1 placed, 0 blank or a comment, -1 bad (err set). */
static int bn__point_line(const char *path, unsigned line, char *buf, const bn_rt *rt, double tol, bn_trace_point *pt,
                          bn_error *err)
{
    double v[6];
    char *p = buf, *end;
    while (*p == ' ' || *p == '\t')
        p++;
    if (*p == '\0' || *p == '\n' || *p == '\r' || *p == '#')
        return 0;
    for (int k = 0; k < 6; k++, p = end) {
        errno = 0;
        v[k] = strtod(p, &end);
        if (end == p || errno == ERANGE || !isfinite(v[k])) {
            bn_error_set(err, BN_EINPUT, "%s:%u: expected six numbers (x y z nx ny nz), value %d is not a finite number",
                         path, line, k + 1);
            return -1;
        }
    }
    double n[3] = {v[3], v[4], v[5]};
    if (!(bn_v3_normalize(n) > 0)) {
        bn_error_set(err, BN_EINPUT, "%s:%u: the normal (%g, %g, %g) is zero", path, line, v[3], v[4], v[5]);
        return -1;
    }
    memcpy(pt->x, v, 3 * sizeof *v);
    pt->line = line;
    if (!bn__point_patch(rt, pt->x, n, tol, &pt->patch)) {
        bn_error_set(err, BN_EINPUT, "%s:%u: no face within %g of (%g, %g, %g) whose front faces (%g, %g, %g)", path, line,
                     tol, v[0], v[1], v[2], n[0], n[1], n[2]);
        return -1;
    }
    bn_scene_point_inset(bn_rt_scene(rt), pt->patch, pt->x, pt->x);   /* off an edge */
    return 1;
}

static int bn__points_grow(bn_trace_point **pts, size_t *cap)
{
    size_t nc = *cap ? 2 * *cap : 256;
    bn_trace_point *q = nc < SIZE_MAX / sizeof *q ? realloc(*pts, nc * sizeof *q) : NULL;
    if (!q)
        return 0;
    *pts = q;
    *cap = nc;
    return 1;
}

bn_status bn_trace_points_read(const char *path, const bn_rt *rt, bn_trace_point **pts, size_t *n, bn_error *err)
{
    const bn_scene *s = bn_rt_scene(rt);
    size_t cap = 0;
    unsigned line = 0;
    char buf[1024];
    bn_status st = BN_OK;
    FILE *f = fopen(path, "r");
    *pts = NULL;
    *n = 0;
    if (!f)
        return bn_error_set(err, BN_EIO, "%s: %s", path, strerror(errno));
    double tol = fmax(1e-6 * bn_scene_diameter(s), 4 * bn_rt_epsilon(rt));
    while (st == BN_OK && fgets(buf, sizeof buf, f)) {
        bn_trace_point pt;
        size_t len = strlen(buf);
        int r = len + 1 == sizeof buf && buf[len - 1] != '\n' && !feof(f)
                    ? (bn_error_set(err, BN_EINPUT, "%s:%u: a line longer than %zu characters", path, line + 1,
                                    sizeof buf - 2), -1)
                    : bn__point_line(path, ++line, buf, rt, tol, &pt, err);
        if (r < 0)
            st = BN_EINPUT;
        else if (r > 0 && *n == cap && !bn__points_grow(pts, &cap))
            st = bn_error_set(err, BN_ENOMEM, "%s: out of memory for %zu points", path, *n + 1);
        else if (r > 0)
            (*pts)[(*n)++] = pt;
    }
    if (st == BN_OK && ferror(f))
        st = bn_error_set(err, BN_EIO, "%s: read error", path);
    if (st == BN_OK && *n == 0)
        st = bn_error_set(err, BN_EINPUT, "%s: no points (one a line: x y z nx ny nz)", path);
    fclose(f);
    if (st != BN_OK) {
        free(*pts);
        *pts = NULL;
        *n = 0;
    }
    return st;
}

bn_status bn_trace_points_write_csv(const char *path, const bn_scene *s, const bn_trace_point *pts,
                                    const bn_trace_patches *r, const char *header, bn_error *err)
{
    bn__outfile f;
    bn_status st = bn__outfile_open(&f, path, "w", err);
    const bn_patch *p = bn_scene_patches(s, NULL);
    if (st != BN_OK)
        return st;
    fputs(header, f.fp);
    fprintf(f.fp, "point,line,face,patch,x,y,z");
    bn__trace_csv_layer_head(f.fp, r);
    for (size_t i = 0; i < r->n; i++) {
        fprintf(f.fp, "%zu,%u,%zu,%zu,%.10g,%.10g,%.10g", i, pts[i].line, p[pts[i].patch].face, pts[i].patch,
                pts[i].x[0], pts[i].x[1], pts[i].x[2]);
        bn__trace_csv_layer_row(f.fp, r, i);
    }
    return bn__outfile_commit(&f, err);
}
