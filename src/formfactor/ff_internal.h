/* Form-factor internals: the point-to-polygon kernel, polygon clipping, adaptive quadrature,
 * shaft culling and point sampling on convex polygons. Not installed. */
#ifndef BOUNCE_FF_INTERNAL_H
#define BOUNCE_FF_INTERNAL_H

#include <stddef.h>
#include <stdint.h>
#include "base/internal.h"

/* Largest polygon the per-pair code handles: a quad clipped by one plane has at most 5
 * corners; 8 leaves room. */
#define BN__FF_POLY_MAX 8

/* F from a differential area at x (unit normal n) to the polygon v[0..nv) (xyz triples,
 * counter-clockwise seen from its front): Lambert's contour integral
 *   F = -(1/2pi) sum_k gamma_k n . (R_k x R_k+1) / |R_k x R_k+1|,  R_k = v_k - x,
 * gamma_k = atan2(|R_k x R_k+1|, R_k . R_k+1) (no acos, so no clamping is needed).
 * The polygon must lie in x's front half-space (clip it first). */
double bn__ff_point_polygon(const double x[3], const double n[3], const double *v, size_t nv);

/* The most occluders bn__ff_point_visible takes; a pair with more has its visibility sampled. */
#define BN__VIS_OCC_MAX 32
/* F from x (unit normal n) to the part of the convex polygon b (nb corners, counter-clockwise seen
 * from its front, unit normal bn, wholly in front of x) that x sees past the occluders: nocc convex
 * polygons of occ_n[q] <= 4 corners at occ + 12 q. Exact (Lambert's contour integral over the
 * boundary of b minus the occluders' projections from x); tol: the scene's geometric tolerance.
 * *shadowed: bit q set if occluder q's projection from x meets b (the value is below F(x -> b) only
 * if some bit is set; once one projection covers b the later occluders are not looked at); where
 * it changes over a patch, the integrand has a crease. cull: NULL, or per occluder a plane (unit normal,
 * offset; NAN offset: none): an occluder with x on the plane's inner side is left out (a convex solid's
 * face seen from behind, when bn__solid_back_faces_hidden says its front faces hide all it would). */
double bn__ff_point_visible(const double x[3], const double n[3], const double *b, size_t nb, const double bn[3],
                            const double *occ, const unsigned *occ_n, const double *cull, size_t nocc, double tol,
                            uint32_t *shadowed);
/* The part the occluders hide, F(x -> b) minus bn__ff_point_visible, from the boundary of what they
 * hide of b (no difference of two sums: 0 where no occluder is in view, without a term); *sees
 * whether x sees any of b. */
double bn__ff_point_blocked(const double x[3], const double n[3], const double *b, size_t nb, const double bn[3],
                            const double *occ, const unsigned *occ_n, const double *cull, size_t nocc, double tol,
                            uint32_t *shadowed, int *sees);

/* Clips the convex polygon v (nv corners) to the half-space n.(y - p) >= 0; corners within
 * `tol` of the plane are snapped onto it. out needs room for nv + 1 corners. Returns the count
 * (0 if nothing is left). */
size_t bn__poly_clip(const double *v, size_t nv, const double n[3], const double p[3], double tol, double *out);
/* Area of a planar polygon, and its (Newell) unit normal. */
double bn__poly_area(const double *v, size_t nv, double n[3]);

/* Quadrature statistics of one pair. */
typedef struct bn__quad_stats {
    size_t evals;       /* kernel evaluations */
    size_t triangles;   /* triangles accepted */
    int    max_depth;
    int    capped;      /* the leaf limit stopped the refinement */
    size_t seen;        /* bn__ff_blocked_integral: evaluations at which some of pj was visible */
} bn__quad_stats;

/* Integral over the convex polygon pi (normal ni) of F(x -> pj) dA(x): A_i F_ij for the parts
 * given. Adaptive: each triangle is accepted when a degree-5 (7-point) and a degree-2 (3-point)
 * rule agree within its share of tol = max(rtol * |I|, atol), and it is no larger than kappa
 * times its centroid's distance to pj (near pairs get small triangles; far ones one or two). */
double bn__ff_polygon_integral(const double *pi, size_t ni, const double ni_n[3], const double *pj, size_t nj,
                               double rtol, double atol, bn__quad_stats *st);

/* The same integral of the part of F(x -> pj) that the occluders hide from x (F(x -> pj) minus
 * bn__ff_point_visible): A_i F_ij unoccluded minus with visibility, to max(rtol |I|, atol) by the
 * same adaptive rules. Zero wherever no occluder is in view, so the rules spend nothing there and
 * the unoccluded kernel's own peaks (shared edges, near pairs) are left to the closed form. */
double bn__ff_blocked_integral(const double *pi, size_t ni, const double ni_n[3], const double *pj, size_t nj,
                               const double *occ, const unsigned *occ_n, const double *cull, size_t nocc, double gtol,
                               int split, double rtol, double atol, bn__quad_stats *st);

/* The same integral, A_i F_ij, as a double contour integral whose inner integral is closed-form and
 * whose outer one is adaptive Gauss-Kronrod to max(rtol |A_i F_ij|, atol) (see kernel.c): exact to that at every
 * separation, for polygons wholly in front of each other (clip them first). */
double bn__ff_contour(const double *pi, size_t ni, const double *pj, size_t nj, double rtol, double atol,
                      bn__quad_stats *st);
/* The tolerance the tests run the contour at. */
#define BN_FF_EXACT_RTOL 1e-12

/* The pair is near: its centroids closer than the larger diameter (the quadrature's integrand has
 * features smaller than the patches there). */
int bn__ff_near(const double *pi, size_t ni, const double *pj, size_t nj);

/* A_i F_ij unoccluded, the way every caller gets it: by the contour for every pair of convex
 * polygons of up to BN__FF_POLY_MAX corners (its Gauss-Kronrod panels converge geometrically on
 * the smooth outer integrand, so its cost hardly depends on rtol: 3-7 us for a far pair at 1e-5
 * and at 1e-11, against 3-13 us and 5-40 ms for the point kernel's quadrature); larger convex
 * polygons as the sum over their fan pieces. To max(rtol |A_i F_ij|, atol). The hierarchy's quick
 * leaf links (1e-3, by the million) keep the quadrature where the pair is not near: it is cheaper
 * at that tolerance (10 kernel evaluations against the contour's 60 panel points). */
double bn__ff_unoccluded(const double *pi, size_t ni, const double ni_n[3], const double *pj, size_t nj, double rtol,
                         double atol, bn__quad_stats *st);

/* Convex solids among the scene's faces (solids.c): connected faces (by vertex index or equal
 * coordinates) with every vertex inside every face's plane, closed but for at most one planar
 * missing facet (a box standing on a floor without its bottom). fv, fnc, fn: per face its corners
 * (12 doubles), corner count and unit normal; fidx + ffirst[f]: its vertex indices. */
typedef struct bn__solids bn__solids;
bn_status bn__solids_find(const double *fv, const unsigned *fnc, const double *fn, const size_t *fidx,
                          const size_t *ffirst, size_t nf, double tol, bn__solids **out);
void bn__solids_free(bn__solids *s);   /* NULL is a no-op */
size_t bn__solids_count(const bn__solids *s);
/* The solid face f belongs to, or SIZE_MAX. */
size_t bn__solid_of(const bn__solids *s, size_t f);
/* Does solid k hide every segment between the convex polygons a and b (neither a polygon of the
 * solid)? Exact up to tol: every segment meets the solid's interior shrunk by tol. */
int bn__solid_blocks_all(const bn__solids *s, size_t k, const double *a, size_t na, const double *b, size_t nb,
                         double tol);
/* May the faces of solid k seen from behind be left out of what hides anything from every point x of
 * polygon v (nv corners)? Yes when v lies beyond tol outside one of H's planes and on the inner side
 * of its missing facet (if any): a segment from such an x that meets a face of k seen from behind
 * enters H first, nearer x, through a face seen from the front, which hides the same points. */
int bn__solid_back_faces_hidden(const bn__solids *s, size_t k, const double *v, size_t nv, double tol);
/* The outward plane (unit normal, offset: inside n.x <= d) of solid k that holds the face with unit
 * normal fn through point p, into out; 0 when none does. */
int bn__solid_face_plane(const bn__solids *s, size_t k, const double fn[3], const double p[3], double tol,
                         double out[4]);

/* Uniform point in a convex polygon from (u, v) in [0,1)^2 (fan triangles chosen by area). */
void bn__poly_sample(const double *v, size_t nv, double u, double w, double out[3]);

/* Distance from x to the convex polygon v with unit normal n. */
double bn__point_polygon_dist(const double x[3], const double *v, size_t nv, const double n[3]);

/* Directions from a point x into a convex polygon (in x's front half-space, at most
 * BN__FF_POLY_MAX corners), uniform in solid angle: Arvo, "Stratified sampling of spherical
 * triangles" (SIGGRAPH 1995), on a fan of spherical triangles chosen by their solid angles. */
typedef struct bn__sph_poly {
    double v[3 * BN__FF_POLY_MAX];      /* unit directions from x to the corners */
    double omega[BN__FF_POLY_MAX];      /* solid angle of fan triangle (0, t+1, t+2) */
    size_t nv;
    double total;                       /* the polygon's solid angle */
    double cmax;                        /* an upper bound of n . w over the polygon, in (0, 1] */
} bn__sph_poly;
/* 0 if the polygon subtends no solid angle from x (x on it, or degenerate). */
int bn__sph_poly_init(bn__sph_poly *sp, const double x[3], const double n[3], const double *v, size_t nv);
/* Unit direction for (u, w) in [0,1)^2, uniform in solid angle over the polygon. */
void bn__sph_poly_sample(const bn__sph_poly *sp, double u, double w, double dir[3]);

#endif
