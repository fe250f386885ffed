/* Small 3-vector helpers in double (scene geometry is held in double). */
#ifndef BOUNCE_BASE_VEC_H
#define BOUNCE_BASE_VEC_H

#include <math.h>

#define BN_PI 3.14159265358979323846

static inline void bn_v3_sub(const double a[3], const double b[3], double o[3])
{
    o[0] = a[0] - b[0]; o[1] = a[1] - b[1]; o[2] = a[2] - b[2];
}
static inline void bn_v3_add(const double a[3], const double b[3], double o[3])
{
    o[0] = a[0] + b[0]; o[1] = a[1] + b[1]; o[2] = a[2] + b[2];
}
static inline double bn_v3_dot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
static inline void bn_v3_cross(const double a[3], const double b[3], double o[3])
{
    double x = a[1] * b[2] - a[2] * b[1], y = a[2] * b[0] - a[0] * b[2], z = a[0] * b[1] - a[1] * b[0];
    o[0] = x; o[1] = y; o[2] = z;
}
static inline double bn_v3_len(const double a[3]) { return sqrt(bn_v3_dot(a, a)); }
static inline void bn_v3_scale(const double a[3], double s, double o[3])
{
    o[0] = a[0] * s; o[1] = a[1] * s; o[2] = a[2] * s;
}
/* o = a + s * b */
static inline void bn_v3_madd(const double a[3], double s, const double b[3], double o[3])
{
    o[0] = a[0] + s * b[0]; o[1] = a[1] + s * b[1]; o[2] = a[2] + s * b[2];
}
static inline double bn_v3_normalize(double a[3])
{
    double l = bn_v3_len(a);
    if (l > 0) { a[0] /= l; a[1] /= l; a[2] /= l; }
    return l;
}
/* s, t: an orthonormal basis of the plane normal to unit n (Duff et al. 2017, branchless) */
static inline void bn_v3_basis(const double n[3], double s[3], double t[3])
{
    double sign = copysign(1.0, n[2]), a = -1.0 / (sign + n[2]), b = n[0] * n[1] * a;
    s[0] = 1 + sign * n[0] * n[0] * a;
    s[1] = sign * b;
    s[2] = -sign * n[0];
    t[0] = b;
    t[1] = sign + n[1] * n[1] * a;
    t[2] = -n[1];
}
/* The cosine-weighted direction about unit n (basis s, t: bn_v3_basis) at (u1, u2) in [0,1)^2:
 * sin^2 theta = u1, phi = 2 pi u2 (Malley's method). */
static inline void bn_v3_cosine_dir(const double n[3], const double s[3], const double t[3], double u1, double u2,
                                    double d[3])
{
    double rr = sqrt(u1), ph = 2 * BN_PI * u2, lx = rr * cos(ph), ly = rr * sin(ph), lz = sqrt(1 - u1);
    for (int k = 0; k < 3; k++)
        d[k] = lx * s[k] + ly * t[k] + lz * n[k];
}
static inline double bn_v3_dist(const double a[3], const double b[3])
{
    double d[3];
    bn_v3_sub(a, b, d);
    return bn_v3_len(d);
}
static inline double bn_clamp(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

/* The midpoint rule on a triangle's k x k regular subdivision: each of its k^2 equal sub-triangles'
 * centroid as (s1, s2), the point a + s1 (b - a) + s2 (c - a). Start from {k} (the rest zero):
 *   bn_subtri it = {k}; while (bn_subtri_next(&it, &s1, &s2)) ...                                  */
typedef struct bn_subtri {
    int k, i, j, up;
} bn_subtri;
static inline int bn_subtri_next(bn_subtri *t, double *s1, double *s2)
{
    while (t->i < t->k) {
        if (t->j + t->i >= t->k || t->up > 1 || (t->up == 1 && t->i + t->j + 1 >= t->k)) {
            if (t->j + t->i >= t->k) {   /* row i done */
                t->i++;
                t->j = 0;
            } else {
                t->j++;
            }
            t->up = 0;
            continue;
        }
        double third = t->up ? 2.0 / 3 : 1.0 / 3;   /* the cell's lower or upper (turned) sub-triangle */
        *s1 = (t->i + third) / t->k;
        *s2 = (t->j + third) / t->k;
        t->up++;
        return 1;
    }
    return 0;
}

#endif
