/* Polygon primitives of the form factors, shared by the pair integrals (kernel.c) and the exact
 * visible parts (visible.c): Lambert's point-to-polygon kernel, clipping by a plane, the area.
 *   F_dA->P = -(1/2pi) sum_k gamma_k n . (R_k x R_k+1)/|R_k x R_k+1|   (Lambert 1760; Sparrow 1963) */
#include "formfactor/ff_internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

double bn__ff_point_polygon(const double x[3], const double n[3], const double *v, size_t nv)
{
    double s = 0, r0[3], ra[3], rb[3];
    if (nv < 3)
        return 0;
    bn_v3_sub(v, x, r0);
    memcpy(ra, r0, sizeof ra);
    for (size_t k = 0; k < nv; k++) {
        double c[3], cl, g;
        if (k + 1 < nv)
            bn_v3_sub(v + 3 * (k + 1), x, rb);
        else
            memcpy(rb, r0, sizeof rb);
        bn_v3_cross(ra, rb, c);
        cl = bn_v3_len(c);
        /* An edge through x (cl = 0) subtends no solid angle: skip it. */
        if (cl > 0) {
            g = atan2(cl, bn_v3_dot(ra, rb));
            s += g * bn_v3_dot(n, c) / cl;
        }
        memcpy(ra, rb, sizeof ra);
    }
    return -s / (2 * BN_PI);
}

size_t bn__poly_clip(const double *v, size_t nv, const double n[3], const double p[3], double tol, double *out)
{
    double d[64];
    size_t m = 0, inside = 0;
    double *dist = nv <= 64 ? d : bn__malloc_array(nv, sizeof(double));
    if (!dist)
        return 0;
    for (size_t k = 0; k < nv; k++) {
        double r[3];
        bn_v3_sub(v + 3 * k, p, r);
        dist[k] = bn_v3_dot(n, r);
        if (fabs(dist[k]) <= tol)
            dist[k] = 0;
        if (dist[k] >= 0)
            inside++;
    }
    if (inside == nv) {
        memcpy(out, v, 3 * nv * sizeof(double));
        if (dist != d)
            free(dist);
        return nv;
    }
    for (size_t k = 0; k < nv; k++) {
        size_t k1 = k + 1 < nv ? k + 1 : 0;
        double da = dist[k], db = dist[k1];
        if (da >= 0) {
            memcpy(out + 3 * m, v + 3 * k, 3 * sizeof(double));
            m++;
        }
        if ((da > 0 && db < 0) || (da < 0 && db > 0)) {
            double t = da / (da - db);
            for (int c = 0; c < 3; c++)
                out[3 * m + c] = v[3 * k + c] + t * (v[3 * k1 + c] - v[3 * k + c]);
            m++;
        }
    }
    if (dist != d)
        free(dist);
    return m >= 3 ? m : 0;
}

double bn__poly_area(const double *v, size_t nv, double n[3])
{
    double s[3] = {0, 0, 0}, len;
    for (size_t k = 0; k < nv; k++) {
        const double *a = v + 3 * k, *b = v + 3 * (k + 1 < nv ? k + 1 : 0);
        s[0] += (a[1] - b[1]) * (a[2] + b[2]);
        s[1] += (a[2] - b[2]) * (a[0] + b[0]);
        s[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    len = bn_v3_len(s);
    if (n) {
        if (len > 0)
            bn_v3_scale(s, 1 / len, n);
        else
            n[0] = n[1] = n[2] = 0;
    }
    return 0.5 * len;
}
