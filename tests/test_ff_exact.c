/* The form factors at bounce's default settings (bn_ff_polygon_pair, the routine the assembly
 * uses: every pair by the double contour integral with its inner integral in closed form, polygons
 * of more than BN__FF_POLY_MAX corners as fan pieces) against the view-factor catalogue at every
 * separation and aspect ratio. References are evaluated here in quadruple precision (__float128), where the catalogue's
 * formulas lose digits in double (their terms cancel to the result's size at gap/side 1e3):
 * - parallel rectangles in any position: Ehlert and Smith's sum over corner differences (J.
 *   Thermophysics Heat Transfer 7, 1993), which for directly opposed ones is Howell's C-11;
 * - perpendicular rectangles with a common edge: Howell's C-14. */
#include "bn_test.h"
#include "bounce/formfactor.h"
#include "formfactor/ff_internal.h"

#include <quadmath.h>

typedef __float128 q;

static q es_g(q x, q y, q z)
{
    q a = sqrtq(y * y + z * z), b = sqrtq(x * x + z * z), r2 = x * x + y * y + z * z, t = 0;
    if (a > 0)
        t += x * a * atanq(x / a);
    if (b > 0)
        t += y * b * atanq(y / b);
    if (r2 > 0)
        t -= z * z / 2 * logq(r2);
    return t;
}

/* F from [x1,x2]x[y1,y2] at z = 0 to [e1,e2]x[n1,n2] at z = c (parallel, facing each other) */
static double es(double x1, double x2, double y1, double y2, double e1, double e2, double n1, double n2, double c)
{
    q xs[2] = {x1, x2}, ys[2] = {y1, y2}, ee[2] = {e1, e2}, nn[2] = {n1, n2}, s = 0;
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++)
            for (int k = 0; k < 2; k++)
                for (int l = 0; l < 2; l++)
                    s += (((i + j + k + l) % 2) ? -1 : 1) * es_g(xs[i] - ee[k], ys[j] - nn[l], c);
    return (double)(s / (2 * M_PIq) / (((q)x2 - x1) * ((q)y2 - y1)));
}

/* Howell C-14: from a w x l rectangle to an h x l one at right angles, sharing the edge l. */
static double c14(double w, double h, double l)
{
    q W = (q)w / l, H = (q)h / l, W2 = W * W, H2 = H * H, R = sqrtq(W2 + H2);
    q t = W * atanq(1 / W) + H * atanq(1 / H) - R * atanq(1 / R);
    q lg = logq((1 + W2) * (1 + H2) / (1 + W2 + H2)) + W2 * logq(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2))) +
           H2 * logq(H2 * (1 + H2 + W2) / ((1 + H2) * (H2 + W2)));
    return (double)((t + lg / 4) / (M_PIq * W));
}

static void rect_z(double *v, double x1, double x2, double y1, double y2, double z, int up)
{
    /* counter-clockwise seen from +z (up) or from -z */
    double a[4][2] = {{x1, y1}, {x2, y1}, {x2, y2}, {x1, y2}};
    for (int k = 0; k < 4; k++) {
        int s = up ? k : (4 - k) % 4;
        v[3 * k] = a[s][0];
        v[3 * k + 1] = a[s][1];
        v[3 * k + 2] = z;
    }
}

/* F_ab at bounce's default settings (the public pair routine, rtol 0); and the closed-form path's
 * reciprocity residual |A_a F_ab - A_b F_ba| / (A_a F_ab) (the contour both ways, at 1e-12). */
static double ff(const double *a, const double *b, double *recip_rel)
{
    if (recip_rel) {
        double ab = bn__ff_contour(a, 4, b, 4, BN_FF_EXACT_RTOL, 0, NULL), ba = bn__ff_contour(b, 4, a, 4, BN_FF_EXACT_RTOL, 0, NULL);
        *recip_rel = fabs(ab - ba) / fmax(fabs(ab), 1e-300);
    }
    return bn_ff_polygon_pair(a, 4, b, 4, 0);
}

/* Records got against want in *worst (relative) and fails past 1e-6 relative, naming the case. */
static void check(double got, double want, double *worst, const char *what)
{
    *worst = fmax(*worst, fabs(got - want) / want);
    if (fabs(got - want) > 1e-6 * want)
        BN_FAIL("%s: F %.15g, exact %.15g (%.2e)", what, got, want, (got - want) / want);
}

BN_TEST(parallel_rectangles_every_gap_and_aspect)
{
    double gaps[] = {1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1, 10, 100, 1000};
    double aspects[] = {1, 10, 100, 1e4};
    double worst = 0, worst_recip = 0;
    for (size_t g = 0; g < 10; g++)
        for (size_t k = 0; k < 4; k++) {
            double a[12], b[12], c = gaps[g], w = aspects[k], rr;
            double want = es(0, w, 0, 1, 0, w, 0, 1, c), got;
            rect_z(a, 0, w, 0, 1, 0, 1);
            rect_z(b, 0, w, 0, 1, c, 0);
            char what[64];
            got = ff(a, b, &rr);
            snprintf(what, sizeof what, "gap %g, %g x 1", c, w);
            check(got, want, &worst, what);
            worst_recip = fmax(worst_recip, rr);
        }
    fprintf(stderr, "directly opposed rectangles, gap/side 1e-6 .. 1e3, aspect 1 .. 1e4: worst %.2e, reciprocity %.2e\n",
            worst, worst_recip);
    BN_ASSERT_LE(worst_recip, 1e-12);
}

/* Offset, partly overlapping and side-by-side parallel rectangles (the superpositions). Where they
 * sit side by side at a tiny gap, F is of the order of the gap squared (2.6e-14 at 1e-6): the
 * contour's terms are of order one and cancel to it, so there it is exact to 1e-15 absolute (far
 * below anything a row of F can notice), not relative; every F above 1e-12 to 1e-6 relative. */
BN_TEST(parallel_rectangles_offset_and_overlapping)
{
    double gaps[] = {1e-6, 1e-3, 1, 1000};
    double offs[][2] = {{0.5, 0}, {0.5, 0.5}, {1, 0}, {1, 1}, {2, 0}, {0.999, 0.25}, {3, 7}};
    double worst = 0, worst_recip = 0, worst_abs = 0;
    for (size_t g = 0; g < 4; g++)
        for (size_t k = 0; k < sizeof offs / sizeof offs[0]; k++) {
            double a[12], b[12], c = gaps[g], dx = offs[k][0], dy = offs[k][1], rr;
            char what[64];
            double want = es(0, 1, 0, 2, dx, dx + 1.5, dy, dy + 1, c), got;
            rect_z(a, 0, 1, 0, 2, 0, 1);
            rect_z(b, dx, dx + 1.5, dy, dy + 1, c, 0);
            got = ff(a, b, &rr);
            if (want < 1e-12) {
                worst_abs = fmax(worst_abs, fabs(got - want));
                if (fabs(got - want) > 1e-15)
                    BN_FAIL("gap %g, offset (%g, %g): F %.6g, exact %.6g", c, dx, dy, got, want);
                continue;
            }
            snprintf(what, sizeof what, "gap %g, offset (%g, %g)", c, dx, dy);
            check(got, want, &worst, what);
            if (want > 1e-6)   /* below, reciprocity goes with the accuracy: 3.8e-9 at F = 1.8e-10 */
                worst_recip = fmax(worst_recip, rr);
        }
    fprintf(stderr, "offset parallel rectangles: worst %.2e (F < 1e-12: %.2e absolute), reciprocity (F > 1e-6) %.2e\n", worst,
            worst_abs, worst_recip);
    BN_ASSERT_LE(worst_recip, 1e-12);
}

BN_TEST(perpendicular_common_edge_every_aspect)
{
    double sides[] = {1e-4, 1e-2, 1, 1e2, 1e4};
    double worst = 0, worst_recip = 0, recip_moderate = 0;
    for (size_t i = 0; i < 5; i++)
        for (size_t j = 0; j < 5; j++) {
            double w = sides[i], h = sides[j], l = 1, rr;
            /* floor w x l in z = 0 (facing +z), wall h x l in x = 0 (facing +x), common edge on the y axis */
            double a[12] = {0, 0, 0, w, 0, 0, w, l, 0, 0, l, 0};
            double b[12] = {0, 0, 0, 0, l, 0, 0, l, h, 0, 0, h};
            double want = c14(w, h, l), got = ff(a, b, &rr);
            char what[64];
            snprintf(what, sizeof what, "w %g, h %g", w, h);
            check(got, want, &worst, what);
            worst_recip = fmax(worst_recip, rr);
            if (w >= 1e-2 && w <= 1e2 && h >= 1e-2 && h <= 1e2)
                recip_moderate = fmax(recip_moderate, rr);
        }
    fprintf(stderr, "perpendicular rectangles with a common edge, sides 1e-4 .. 1e4: worst %.2e, reciprocity %.2e\n",
            worst, worst_recip);
    /* a 1e-4-wide strip against a 1e4-long wall: F is a difference across the strip's width, 1e-4
     * of the terms (2.5e-12 measured); up to aspect 1e2 reciprocity holds to 1e-12 */
    BN_ASSERT_LE(worst_recip, 5e-12);
    BN_ASSERT_LE(recip_moderate, 1e-12);
}

/* Polygons of more corners than the contour takes at once (BN__FF_POLY_MAX) go as fan pieces: a
 * 1 x 2 rectangle and a 1.5 x 1 one written with extra corners along every edge (m per edge, so
 * 4 (m + 1) corners, up to 36) are still the rectangles of the catalogue, at every gap. */
static void rect_many(double *v, double x1, double x2, double y1, double y2, double z, int up, int m)
{
    double r[12];
    size_t n = 0;
    rect_z(r, x1, x2, y1, y2, z, up);
    for (int k = 0; k < 4; k++)
        for (int t = 0; t <= m; t++, n++)
            for (int c = 0; c < 3; c++)
                v[3 * n + c] = r[3 * k + c] + (double)t / (m + 1) * (r[3 * ((k + 1) % 4) + c] - r[3 * k + c]);
}

BN_TEST(many_corners_as_fan_pieces)
{
    double gaps[] = {1e-6, 1e-3, 1, 1000}, worst = 0;
    int ms[] = {1, 2, 5, 8};
    for (size_t g = 0; g < 4; g++)
        for (size_t k = 0; k < 4; k++) {
            double a[3 * 36], b[3 * 36], c = gaps[g], want = es(0, 1, 0, 2, 0.5, 2, 0.25, 1.25, c);
            size_t n = 4 * (size_t)(ms[k] + 1);
            char what[64];
            rect_many(a, 0, 1, 0, 2, 0, 1, ms[k]);
            rect_many(b, 0.5, 2, 0.25, 1.25, c, 0, ms[k]);
            snprintf(what, sizeof what, "gap %g, %zu corners", c, n);
            check(bn_ff_polygon_pair(a, n, b, n, 0), want, &worst, what);
            /* and against a 4-corner partner */
            rect_z(b, 0.5, 2, 0.25, 1.25, c, 0);
            check(bn_ff_polygon_pair(a, n, b, 4, 0), want, &worst, what);
        }
    fprintf(stderr, "rectangles of 8 to 36 corners, gap 1e-6 .. 1e3: worst %.2e\n", worst);
}

/* A closed 2 x 3 x 5 box, one polygon a face: every row of F sums to 1, on the closed-form path to
 * 1e-12 and at the default settings (the pair routine's tolerance, 1e-6) to 1e-7. */
BN_TEST(closed_box_rows_sum_to_one)
{
    double L[3] = {2, 3, 5}, faces[6][12], area[6], worst = 0, worst_default = 0;
    for (int ax = 0; ax < 3; ax++)
        for (int side = 0; side < 2; side++) {
            int u = (ax + 1) % 3, v = (ax + 2) % 3, f = 2 * ax + side;
            double c[4][2] = {{0, 0}, {L[u], 0}, {L[u], L[v]}, {0, L[v]}};
            for (int k = 0; k < 4; k++) {
                /* inward normal: +ax at side 0, -ax at side 1 (reverse the order there) */
                int s = side ? (4 - k) % 4 : k;
                double *p = faces[f] + 3 * k;
                p[ax] = side ? L[ax] : 0;
                p[u] = c[s][0];
                p[v] = c[s][1];
            }
            area[f] = L[u] * L[v];
        }
    for (int i = 0; i < 6; i++) {
        double row = 0, row_default = 0;
        for (int j = 0; j < 6; j++)
            if (j != i) {
                row += bn__ff_contour(faces[i], 4, faces[j], 4, BN_FF_EXACT_RTOL, 0, NULL) / area[i];
                row_default += bn_ff_polygon_pair(faces[i], 4, faces[j], 4, 0);
            }
        worst = fmax(worst, fabs(row - 1));
        worst_default = fmax(worst_default, fabs(row_default - 1));
    }
    fprintf(stderr, "closed box: worst |row sum - 1| %.2e (closed form), %.2e (default settings)\n", worst,
            worst_default);
    BN_ASSERT_LE(worst, 1e-12);
    BN_ASSERT_LE(worst_default, 1e-7);
}

/* Polygons that see each other edge-on give terms that cancel to rounding, of either sign: F is 0,
 * never negative (a negative entry stops the assembly). Seen between triangles of a decimated
 * bunny after clipping, F = -4e-16; here the extreme case, triangles in one plane (the kernel is 0
 * everywhere), half of them with the winding reversed. Before the clamp, half came out negative. */
BN_TEST(edge_on_pairs_are_never_negative)
{
    uint64_t x = 12345;
    size_t neg = 0;
    double worst = 0;
    for (int t = 0; t < 4000; t++) {
        double a[9], b[9];
        for (int k = 0; k < 3; k++) {
            int kb = t % 2 ? 2 - k : k;
            for (int c = 0; c < 2; c++) {
                x = x * 6364136223846793005ull + 1442695040888963407ull;
                a[3 * k + c] = 10 * ((double)(x >> 11) / 9007199254740992.0);
                x = x * 6364136223846793005ull + 1442695040888963407ull;
                b[3 * kb + c] = 10 * ((double)(x >> 11) / 9007199254740992.0) + (c == 0 ? 20 : 0);
            }
            a[3 * k + 2] = b[3 * kb + 2] = 0;
        }
        for (int dir = 0; dir < 2; dir++) {
            double f = dir ? bn__ff_contour(b, 3, a, 3, 1e-9, 0, NULL) : bn__ff_contour(a, 3, b, 3, 1e-9, 0, NULL);
            neg += f < 0;
            worst = fmax(worst, fabs(f));
        }
    }
    fprintf(stderr, "edge-on pairs: %zu negative, largest |A F| %.2e\n", neg, worst);
    BN_ASSERT_EQ(neg, 0);
    BN_ASSERT_LE(worst, 1e-12);
}
