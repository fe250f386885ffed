/* Contact lines: a block standing on a plane under a square light. The floor's patches must not
 * straddle the block's footprint; the hidden ones receive nothing; the lit ones next to the block
 * carry their own direct light, checked against the exact point-to-polygon form factor (Lambert's
 * contour formula, with the block's shadow clipped out of the light exactly) integrated over each
 * patch in this file, to 2% of what the patch would get without the block (the shadow rays' noise,
 * 256 a pair, is well inside that; a patch averaged with the hidden floor would be off by its hidden
 * share). */
#include "bn_test.h"
#include "bounce/pipeline.h"
#include "bounce/bake.h"
#include "bounce/rt.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define H_LIGHT 1.0     /* light plane height */
#define HALF_LIGHT 0.3  /* the light is a square of side 0.6 centred above the origin */
#define H_BLOCK 0.05    /* block height */
#define RHO 0.5

/* footprint: a rectangle 0.62 x 0.38 turned by 27 degrees about (0.137, -0.091) in (x, z) */
static void footprint(double fp[4][2])
{
    double c = cos(27 * M_PI / 180), s = sin(27 * M_PI / 180), cx = 0.137, cz = -0.091, hx = 0.31, hz = 0.19;
    double loc[4][2] = {{-hx, -hz}, {hx, -hz}, {hx, hz}, {-hx, hz}};
    for (int k = 0; k < 4; k++) {
        fp[k][0] = cx + c * loc[k][0] - s * loc[k][1];
        fp[k][1] = cz + s * loc[k][0] + c * loc[k][1];
    }
}

static void write_scene_lifted(double lift)
{
    double fp[4][2];
    FILE *fp_mtl = fopen(bn_test_tmp("block.mtl"), "w"), *f = fopen(bn_test_tmp("block.obj"), "w");
    BN_ASSERT(fp_mtl && f);
    fprintf(fp_mtl, "newmtl white\nKd %g %g %g\nnewmtl light\nKd 0 0 0\nKe 1 1 1\n", RHO, RHO, RHO);
    fclose(fp_mtl);
    footprint(fp);
    fprintf(f, "mtllib block.mtl\nusemtl white\n");
    /* floor 2 x 2 at y = 0 facing +y */
    fprintf(f, "v -1 0 -1\nv -1 0 1\nv 1 0 1\nv 1 0 -1\nf 1 2 3 4\n");
    /* the block: bottom (facing down, lying on the floor), top, four sides */
    for (int k = 0; k < 4; k++)
        fprintf(f, "v %.17g %.17g %.17g\n", fp[k][0], lift, fp[k][1]);            /* 5..8 */
    for (int k = 0; k < 4; k++)
        fprintf(f, "v %.17g %.17g %.17g\n", fp[k][0], lift + H_BLOCK, fp[k][1]); /* 9..12 */
    /* footprint order in (x, z) is counter-clockwise seen from -y, so as written it faces -y */
    fprintf(f, "f 5 6 7 8\nf 12 11 10 9\n");
    for (int k = 0; k < 4; k++) {
        int a = 5 + k, b = 5 + (k + 1) % 4;
        fprintf(f, "f %d %d %d %d\n", a, a + 4, b + 4, b);
    }
    fprintf(f, "usemtl light\nv %g %g %g\nv %g %g %g\nv %g %g %g\nv %g %g %g\nf 13 14 15 16\n", -HALF_LIGHT, H_LIGHT,
            -HALF_LIGHT, HALF_LIGHT, H_LIGHT, -HALF_LIGHT, HALF_LIGHT, H_LIGHT, HALF_LIGHT, -HALF_LIGHT, H_LIGHT,
            HALF_LIGHT);
    fclose(f);
}

static void write_scene(void) { write_scene_lifted(0); }

/* Signed side of (x, z) against the footprint: > 0 inside by that distance, < 0 outside. */
static double inside(const double fp[4][2], double x, double z)
{
    double m = INFINITY;
    for (int k = 0; k < 4; k++) {
        const double *a = fp[k], *b = fp[(k + 1) % 4];
        double ex = b[0] - a[0], ez = b[1] - a[1], len = hypot(ex, ez);
        /* the footprint is counter-clockwise in (x, z): inside is to the left */
        double d = (ex * (z - a[1]) - ez * (x - a[0])) / len;
        m = fmin(m, d);
    }
    return m;
}

/* Clips the convex polygon p (n points in the light's plane, as (x, z)) to the convex polygon q. */
static int clip(double p[][2], int n, const double q[][2], int m)
{
    double tmp[32][2];
    double orient = 0;
    for (int k = 0; k < m; k++)
        orient += q[k][0] * q[(k + 1) % m][1] - q[(k + 1) % m][0] * q[k][1];
    for (int k = 0; k < m && n > 0; k++) {
        const double *a = q[k], *b = q[(k + 1) % m];
        int t = 0;
        for (int i = 0; i < n; i++) {
            const double *u = p[i], *v = p[(i + 1) % n];
            double su = ((b[0] - a[0]) * (u[1] - a[1]) - (b[1] - a[1]) * (u[0] - a[0])) * orient;
            double sv = ((b[0] - a[0]) * (v[1] - a[1]) - (b[1] - a[1]) * (v[0] - a[0])) * orient;
            if (su >= 0)
                memcpy(tmp[t++], u, sizeof tmp[0]);
            if ((su >= 0) != (sv >= 0)) {
                double s = su / (su - sv);
                tmp[t][0] = u[0] + s * (v[0] - u[0]);
                tmp[t][1] = u[1] + s * (v[1] - u[1]);
                t++;
            }
        }
        n = t;
        memcpy(p, tmp, (size_t)n * sizeof tmp[0]);
    }
    return n;
}

/* Lambert: form factor from a point on the floor (normal +y) to a polygon in the plane y = H. */
static double lambert(const double x[3], double poly[][2], int n)
{
    double sum = 0;
    for (int k = 0; k < n; k++) {
        double r0[3] = {poly[k][0] - x[0], H_LIGHT - x[1], poly[k][1] - x[2]};
        double r1[3] = {poly[(k + 1) % n][0] - x[0], H_LIGHT - x[1], poly[(k + 1) % n][1] - x[2]};
        double cr[3] = {r0[1] * r1[2] - r0[2] * r1[1], r0[2] * r1[0] - r0[0] * r1[2], r0[0] * r1[1] - r0[1] * r1[0]};
        double l0 = sqrt(r0[0] * r0[0] + r0[1] * r0[1] + r0[2] * r0[2]);
        double l1 = sqrt(r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2]);
        double lc = sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        double ang = acos(fmax(-1.0, fmin(1.0, (r0[0] * r1[0] + r0[1] * r1[1] + r0[2] * r1[2]) / (l0 * l1))));
        if (lc > 0)
            sum += ang * cr[1] / lc;
    }
    return fabs(sum) / (2 * M_PI);
}

/* The form factor from floor point (px, 0, pz) to the whole light (no block). */
static double open_ff(double px, double pz)
{
    double x[3] = {px, 0, pz}, light[4][2] = {{-HALF_LIGHT, -HALF_LIGHT}, {HALF_LIGHT, -HALF_LIGHT},
                                              {HALF_LIGHT, HALF_LIGHT}, {-HALF_LIGHT, HALF_LIGHT}};
    return lambert(x, light, 4);
}

/* The exact direct form factor from floor point x to the light, the block's shadow removed: the
 * block is convex, so its shadow on the light's plane (seen from x) is the convex hull of its
 * corners projected from x; visible = light - (light ∩ hull). */
static double point_ff(const double fp[4][2], double px, double pz)
{
    double x[3] = {px, 0, pz}, light[32][2] = {{-HALF_LIGHT, -HALF_LIGHT}, {HALF_LIGHT, -HALF_LIGHT},
                                               {HALF_LIGHT, HALF_LIGHT}, {-HALF_LIGHT, HALF_LIGHT}};
    double full = lambert(x, light, 4), pts[8][2], hull[8][2];
    int np = 0, nh = 0, start = 0;
    if (inside(fp, px, pz) > -1e-12)
        return 0;
    for (int k = 0; k < 4; k++) {
        /* bottom corners lie in the floor's plane with x: they project to infinity along the floor;
         * use the top corners and the bottom corners lifted by a hair (same shadow in the limit) */
        for (int lvl = 0; lvl < 2; lvl++) {
            double y = lvl ? H_BLOCK : 1e-7, t = H_LIGHT / y;
            pts[np][0] = px + t * (fp[k][0] - px);
            pts[np][1] = pz + t * (fp[k][1] - pz);
            np++;
        }
    }
    /* convex hull (gift wrapping) of the 8 projected points */
    for (int i = 1; i < np; i++)
        if (pts[i][0] < pts[start][0])
            start = i;
    {
        int cur = start;
        do {
            int nxt = (cur + 1) % np;
            memcpy(hull[nh++], pts[cur], sizeof hull[0]);
            for (int i = 0; i < np; i++) {
                double cr = (pts[nxt][0] - pts[cur][0]) * (pts[i][1] - pts[cur][1]) -
                            (pts[nxt][1] - pts[cur][1]) * (pts[i][0] - pts[cur][0]);
                if (cr < 0)
                    nxt = i;
            }
            cur = nxt;
        } while (cur != start && nh < 8);
    }
    {
        int n = clip(light, 4, (const double(*)[2])hull, nh);
        return full - (n >= 3 ? lambert(x, light, n) : 0);
    }
}

/* Mean of point_ff over a floor patch: each triangle cut 12 x 12, centroid rule. */
static double patch_ff(const double fp[4][2], const double *pv, const bn_patch *p)
{
    double sum = 0, area = 0;
    for (unsigned t = 0; t + 2 < p->ncorners; t++) {
        const double *a = pv + 3 * p->corner[0], *b = pv + 3 * p->corner[t + 1], *c = pv + 3 * p->corner[t + 2];
        double ar = 0.5 * fabs((b[0] - a[0]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[0] - a[0]));
        const int m = 12;
        for (int i = 0; i < m; i++)
            for (int j = 0; i + j < m; j++)
                for (int up = 0; up < 2; up++) {
                    double u, v;
                    if (up && i + j + 1 >= m)
                        continue;
                    u = up ? (i + 2.0 / 3) / m : (i + 1.0 / 3) / m;
                    v = up ? (j + 2.0 / 3) / m : (j + 1.0 / 3) / m;
                    sum += ar / (m * m) * point_ff(fp, a[0] + u * (b[0] - a[0]) + v * (c[0] - a[0]),
                                                   a[2] + u * (b[2] - a[2]) + v * (c[2] - a[2]));
                }
        area += ar;
    }
    return sum / area;
}

/* How far inside the footprint patch i's corners reach: the least and the most. */
static void corner_sides(const double fp[4][2], const bn_scene *s, size_t i, double *lo, double *hi)
{
    const bn_patch *pt = bn_scene_patches(s, NULL) + i;
    const double *pv = bn_scene_patch_vertices(s, NULL);
    *lo = INFINITY;
    *hi = -INFINITY;
    for (unsigned k = 0; k < pt->ncorners; k++) {
        double d = inside(fp, pv[3 * pt->corner[k]], pv[3 * pt->corner[k] + 2]);
        *lo = fmin(*lo, d);
        *hi = fmax(*hi, d);
    }
}

/* Floor patches whose corners lie on both sides of the footprint's outline. */
static size_t straddling(const double fp[4][2], const bn_scene *s)
{
    size_t np, n = 0;
    const bn_patch *pt = bn_scene_patches(s, &np);
    for (size_t i = 0; i < np; i++) {
        double lo, hi;
        if (pt[i].face != 0)
            continue;
        corner_sides(fp, s, i, &lo, &hi);
        n += lo < -1e-9 && hi > 1e-9;
    }
    return n;
}

static void solve(int no_contacts, bn_pipeline *p)
{
    bn_pipeline_opts o;
    bn_error err;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.mesh.patch_size = 0.1;
    o.mesh.no_contacts = no_contacts;
    o.transport = "dense";
    o.ff.quiet = 1;
    o.ff.samples = 256;
    o.solve.quiet = 1;
    o.solve.log_sink.quiet = 1;
    o.solve.bounces = 1;
    if (bn_pipeline_run(bn_test_tmp("block.obj"), &o, p, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
}

BN_TEST(block_on_plane)
{
    double fp[4][2];
    bn_pipeline p;
    size_t np, npv, hidden = 0, beside = 0;
    const bn_patch *pt;
    const double *pv;
    double worst = 0;
    write_scene();
    footprint(fp);

    /* without the cuts, floor patches straddle the footprint (the test's premise) */
    solve(1, &p);
    BN_ASSERT_GT(straddling(fp, p.scene), 10);
    bn_pipeline_free(&p);

    solve(0, &p);
    BN_ASSERT_EQ(bn_scene_stats_get(p.scene).contact_faces, 1);
    pt = bn_scene_patches(p.scene, &np);
    pv = bn_scene_patch_vertices(p.scene, &npv);
    for (size_t i = 0; i < np; i++) {
        double lo, hi;
        const double *ke = p.res.terms[1] + 3 * i, *L = p.res.L + 3 * i;
        if (pt[i].face != 0)
            continue;
        corner_sides(fp, p.scene, i, &lo, &hi);
        /* no patch straddles the contact outline */
        if (lo < -1e-9 && hi > 1e-9)
            BN_FAIL("floor patch %zu straddles the footprint (corners %.3g .. %.3g inside)", i, lo, hi);
        if (lo >= -1e-9) {
            /* hidden under the block: receives nothing, not even reflected light */
            hidden++;
            for (int c = 0; c < 3; c++) {
                BN_ASSERT_EQ(ke[c], 0);
                BN_ASSERT_EQ(L[c], 0);
            }
        } else if (hi > -1e-9) {
            /* beside the block (a corner on the outline): its own direct light, not an average
             * with the hidden floor */
            double want = RHO * patch_ff(fp, pv, &pt[i]), scale = RHO * open_ff(pt[i].centroid[0], pt[i].centroid[2]);
            beside++;
            worst = fmax(worst, fabs(ke[1] - want) / scale);
            if (fabs(ke[1] - want) > 0.02 * scale)
                BN_FAIL("floor patch %zu beside the block: KE %.6g, exact %.6g (without the block %.6g)", i, ke[1], want,
                        scale);
        }
    }
    fprintf(stderr, "%zu hidden patches, %zu beside the block, worst KE error %.3g of the KE without the block\n", hidden,
            beside, worst);
    BN_ASSERT_GT(hidden, 10);
    BN_ASSERT_GT(beside, 20);
    bn_pipeline_free(&p);
}

/* A block 2 mm above the floor does not touch it; --contact-gap 5 mm says it does, and then no floor
 * patch straddles its footprint (projected onto the floor). */
BN_TEST(block_lifted_needs_gap)
{
    double fp[4][2];
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_scene *s;
    bn_error err;
    write_scene_lifted(0.002);
    footprint(fp);
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    BN_ASSERT_STATUS(bn_scene_load(bn_test_tmp("block.obj"), &lo, &s, &err), BN_OK);
    bn_mesh_opts_default(&mo);
    mo.patch_size = 0.1;
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    BN_ASSERT_EQ(bn_scene_stats_get(s).contact_faces, 0);
    BN_ASSERT_GT(straddling(fp, s), 10);
    mo.contact_gap = 0.005;
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    BN_ASSERT_EQ(bn_scene_stats_get(s).contact_faces, 1);
    BN_ASSERT_EQ(straddling(fp, s), 0);
    mo.contact_gap = -1;
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_EINPUT);
    mo.contact_gap = 1e300;   /* every face would touch every other */
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_EINPUT);
    bn_scene_destroy(s);
}

/* Random blocks (turned, overlapping each other, some running off the floor's edge, some sunk into
 * it so their sides pierce it) on a floor at
 * random patch sizes: the mesher must keep its invariants with every cut: patch areas sum to the
 * floor's, every patch is counter-clockwise with positive area, no patch straddles any footprint
 * edge inside the floor, and no T-junction (every patch edge inside the floor is shared by two
 * patches with the same two corners). */
static double urand(unsigned *st)
{
    *st = *st * 1103515245u + 12345u;
    return ((*st >> 8) & 0xffffff) / 16777216.0;
}

typedef struct { size_t a, b; } pedge;

static int cmp_pedge(const void *x, const void *y)
{
    const pedge *e = x, *f = y;
    if (e->a != f->a)
        return e->a < f->a ? -1 : 1;
    return e->b < f->b ? -1 : (e->b > f->b);
}

/* The length of segment p0-p1 (in (x, z)) inside floor patch p. */
static double inside_length(const double p0[2], const double p1[2], const double *pv, const bn_patch *p)
{
    double lo = 0, hi = 1, d[2] = {p1[0] - p0[0], p1[1] - p0[1]}, orient = 0;
    unsigned n = p->ncorners;
    for (unsigned k = 0; k < n; k++) {
        const double *a = pv + 3 * p->corner[k], *b = pv + 3 * p->corner[(k + 1) % n];
        orient += a[0] * b[2] - b[0] * a[2];
    }
    for (unsigned k = 0; k < n; k++) {
        const double *a = pv + 3 * p->corner[k], *b = pv + 3 * p->corner[(k + 1) % n];
        /* inside: the side of edge a-b the polygon turns to */
        double m[2] = {-(b[2] - a[2]), b[0] - a[0]};
        double sa = (m[0] * (p0[0] - a[0]) + m[1] * (p0[1] - a[2])) * orient;
        double sd = (m[0] * d[0] + m[1] * d[1]) * orient;
        if (sd == 0) {
            if (sa < 0)
                return 0;
        } else if (sd > 0) {
            lo = fmax(lo, -sa / sd);
        } else {
            hi = fmin(hi, -sa / sd);
        }
    }
    return hi > lo ? (hi - lo) * hypot(d[0], d[1]) : 0;
}

/* How far patch p reaches to the lesser side of the line through p0-p1. */
static double side_extent(const double p0[2], const double p1[2], const double *pv, const bn_patch *p)
{
    double ex = p1[0] - p0[0], ez = p1[1] - p0[1], len = hypot(ex, ez), dmin = INFINITY, dmax = -INFINITY;
    for (unsigned q = 0; q < p->ncorners; q++) {
        const double *v = pv + 3 * p->corner[q];
        double dd = (ex * (v[2] - p0[1]) - ez * (v[0] - p0[0])) / len;
        dmin = fmin(dmin, dd);
        dmax = fmax(dmax, dd);
    }
    return fmin(-dmin, dmax);
}

BN_TEST(random_blocks_keep_mesh_invariants)
{
    unsigned st = 12345;
    for (int trial = 0; trial < 40; trial++) {
        int nb = 1 + (int)(urand(&st) * 3);
        double fps[3][4][2];
        FILE *f = fopen(bn_test_tmp("rand.obj"), "w");
        bn_load_opts lo;
        bn_mesh_opts mo;
        bn_scene *s;
        bn_error err;
        size_t np, nv, nfloor = 0, ne = 0;
        const bn_patch *pt;
        const double *pv;
        double area = 0;
        pedge *edges;
        FILE *m = fopen(bn_test_tmp("rand.mtl"), "w");
        fprintf(m, "newmtl white\nKd 0.5 0.5 0.5\nKe 1 1 1\n");
        fclose(m);
        fprintf(f, "mtllib rand.mtl\nusemtl white\nv -1 0 -1\nv -1 0 1\nv 1 0 1\nv 1 0 -1\nf 1 2 3 4\n");
        for (int b = 0; b < nb; b++) {
            double ang = urand(&st) * M_PI, c = cos(ang), sn = sin(ang), cx = urand(&st) * 2.4 - 1.2,
                   cz = urand(&st) * 2.4 - 1.2, hx = 0.05 + urand(&st) * 0.5, hz = 0.05 + urand(&st) * 0.5,
                   h = 0.02 + urand(&st) * 0.3, y0 = urand(&st) < 0.3 ? -0.9 * h * urand(&st) : 0;   /* some sunk in, not under */
            double loc[4][2] = {{-hx, -hz}, {hx, -hz}, {hx, hz}, {-hx, hz}};
            int base = 5 + 8 * b;
            for (int k = 0; k < 4; k++) {
                fps[b][k][0] = cx + c * loc[k][0] - sn * loc[k][1];
                fps[b][k][1] = cz + sn * loc[k][0] + c * loc[k][1];
                fprintf(f, "v %.17g %.17g %.17g\n", fps[b][k][0], y0, fps[b][k][1]);
            }
            for (int k = 0; k < 4; k++)
                fprintf(f, "v %.17g %.17g %.17g\n", fps[b][k][0], y0 + h, fps[b][k][1]);
            fprintf(f, "f %d %d %d %d\nf %d %d %d %d\n", base, base + 1, base + 2, base + 3, base + 7, base + 6,
                    base + 5, base + 4);
            for (int k = 0; k < 4; k++) {
                int a = base + k, bb = base + (k + 1) % 4;
                fprintf(f, "f %d %d %d %d\n", a, a + 4, bb + 4, bb);
            }
        }
        fclose(f);
        bn_load_opts_default(&lo);
        lo.log.quiet = 1;
        BN_ASSERT_STATUS(bn_scene_load(bn_test_tmp("rand.obj"), &lo, &s, &err), BN_OK);
        bn_mesh_opts_default(&mo);
        mo.patch_size = 0.03 + urand(&st) * 0.4;
        BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
        pt = bn_scene_patches(s, &np);
        pv = bn_scene_patch_vertices(s, &nv);
        edges = malloc(4 * np * sizeof *edges);
        for (size_t i = 0; i < np; i++) {
            if (pt[i].face != 0)
                continue;
            nfloor++;
            area += pt[i].area;
            for (unsigned k = 0; k < pt[i].ncorners; k++) {
                const double *a = pv + 3 * pt[i].corner[k], *b = pv + 3 * pt[i].corner[(k + 1) % pt[i].ncorners],
                             *d = pv + 3 * pt[i].corner[(k + 2) % pt[i].ncorners];
                /* counter-clockwise seen from +y: (b - a) x (d - b) has a positive y */
                double cr = (b[2] - a[2]) * (d[0] - b[0]) - (b[0] - a[0]) * (d[2] - b[2]);
                if (!(cr > 0))
                    BN_FAIL("trial %d: floor patch %zu turns the wrong way at corner %u (%g)", trial, i, k, cr);
                edges[ne].a = pt[i].corner[k];
                edges[ne].b = pt[i].corner[(k + 1) % pt[i].ncorners];
                ne++;
            }
            for (int b = 0; b < nb; b++) {
                double lo_s, hi_s;
                corner_sides(fps[b], s, i, &lo_s, &hi_s);
                if (lo_s < -1e-9 && hi_s > 1e-9) {
                    /* a footprint edge may leave the floor: only its part inside the floor cuts,
                     * so test the patch against each edge's line where the edge passes through it */
                    for (int k = 0; k < 4; k++) {
                        double len = inside_length(fps[b][k], fps[b][(k + 1) % 4], pv, &pt[i]);
                        /* the mesher leaves a piece whole when an edge crosses it for less than
                         * 1% of a patch edge, or passes within that of a corner */
                        if (len > 0.011 * mo.patch_size && side_extent(fps[b][k], fps[b][(k + 1) % 4], pv, &pt[i]) >
                                                               0.011 * mo.patch_size)
                            BN_FAIL("trial %d: floor patch %zu straddles block %d's edge %d (inside it for %g)",
                                    trial, i, b, k, len);
                    }
                }
            }
        }
        BN_ASSERT_REL(area, 4.0, 1e-12);
        qsort(edges, ne, sizeof *edges, cmp_pedge);
        for (size_t e = 0; e < ne; e++) {
            pedge twin = {edges[e].b, edges[e].a};
            const double *a = pv + 3 * edges[e].a, *b = pv + 3 * edges[e].b;
            int on_boundary = (fabs(fabs(a[0]) - 1) < 1e-12 && fabs(a[0] - b[0]) < 1e-12) ||
                              (fabs(fabs(a[2]) - 1) < 1e-12 && fabs(a[2] - b[2]) < 1e-12);
            if (!on_boundary && !bsearch(&twin, edges, ne, sizeof *edges, cmp_pedge))
                BN_FAIL("trial %d: floor edge %zu-%zu has no twin (a T-junction or a crack)", trial, edges[e].a,
                        edges[e].b);
        }
        BN_ASSERT_GT(nfloor, 0);
        free(edges);
        bn_scene_destroy(s);
    }
}

/* The smooth bake next to the block: the floor under it is found enclosed (rays from it meet the
 * block's inside) and left out of the vertex averages, so a vertex on the contact outline carries the
 * area mean of the lit floor beside it alone, not the darkness under the block. */
BN_TEST(smooth_bake_leaves_out_the_floor_under_the_block)
{
    double fp[4][2];
    bn_pipeline p;
    bn_rt *rt = NULL;
    bn_bake *b = NULL;
    bn_error err;
    size_t np, nv, hidden = 0, enclosed, outline = 0;
    const bn_patch *pt;
    unsigned char *hid;
    double *vv, *sum, *area;
    int *has_hidden;
    write_scene();
    footprint(fp);
    solve(0, &p);
    pt = bn_scene_patches(p.scene, &np);
    if (bn_rt_create(p.scene, 0, &rt, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    BN_ASSERT_STATUS(bn_bake_create(p.scene, 30, &b, &err), BN_OK);
    enclosed = bn_bake_exclude_enclosed(b, rt);
    hid = calloc(np, 1);
    for (size_t i = 0; i < np; i++) {
        int pos = 0, neg = 0;
        if (pt[i].face != 0)
            continue;
        for (int k = 0; k < 4; k++) {   /* the test's own geometry: the centroid inside the footprint */
            const double *a = fp[k], *q = fp[(k + 1) % 4];
            double cr = (q[0] - a[0]) * (pt[i].centroid[2] - a[1]) - (q[1] - a[1]) * (pt[i].centroid[0] - a[0]);
            pos += cr > 0;
            neg += cr < 0;
        }
        hid[i] = pos == 4 || neg == 4;
        hidden += hid[i];
    }
    fprintf(stderr, "%zu floor patches under the block, %zu patches found enclosed\n", hidden, enclosed);
    BN_ASSERT_GT(hidden, 10);
    BN_ASSERT_EQ(enclosed, hidden);
    nv = bn_bake_vertex_count(b);
    vv = calloc(3 * nv, sizeof *vv);
    sum = calloc(nv, sizeof *sum);
    area = calloc(nv, sizeof *area);
    has_hidden = calloc(nv, sizeof *has_hidden);
    bn_bake_vertex_values(b, p.res.terms[1], vv);   /* KE */
    for (size_t i = 0; i < np; i++) {
        if (pt[i].face != 0)
            continue;
        for (unsigned c = 0; c < pt[i].ncorners; c++) {
            size_t v = bn_bake_corner_vertex(b, i, c);
            if (hid[i]) {
                has_hidden[v] = 1;
                continue;
            }
            sum[v] += pt[i].area * p.res.terms[1][3 * i + 1];
            area[v] += pt[i].area;
        }
    }
    for (size_t v = 0; v < nv; v++)
        if (has_hidden[v] && area[v] > 0) {   /* on the outline: lit floor on one side, hidden on the other */
            outline++;
            BN_ASSERT_GT(vv[3 * v + 1], 0);
            BN_ASSERT_REL(vv[3 * v + 1], sum[v] / area[v], 1e-12);
        }
    fprintf(stderr, "%zu vertices on the contact outline checked\n", outline);
    BN_ASSERT_GT(outline, 10);
    free(hid);
    free(vv);
    free(sum);
    free(area);
    free(has_hidden);
    bn_bake_destroy(b);
    bn_rt_destroy(rt);
    bn_pipeline_free(&p);
}

/* A chair on a floor, as a furniture library names it: materials `floor`, `chair_seat` and
 * `chair_leg` (objects by prefix: floor, chair); a leg (a box) stands on the floor and passes up
 * through the seat (a flat box) as real assets' parts do. groups: write `o` lines instead (objects
 * from the file); mat_all: every face one material "white" (one object, not an assembly). */
static void write_chair(int groups, int mat_all)
{
    FILE *m = fopen(bn_test_tmp("chair.mtl"), "w"), *f = fopen(bn_test_tmp("chair.obj"), "w");
    /* boxes: lo, hi corners; faces outward */
    static const double box[2][6] = {{-0.05, 0, -0.05, 0.05, 0.6, 0.05},   /* the leg, 0.6 high */
                                     {-0.3, 0.4, -0.3, 0.3, 0.45, 0.3}};   /* the seat, pierced by the leg */
    static const int q[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {2, 3, 7, 6}, {1, 2, 6, 5}, {3, 0, 4, 7}};
    const char *names[2] = {"chair_leg", "chair_seat"};
    BN_ASSERT(m && f);
    fprintf(m, "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl chair_leg\nKd 0.5 0.5 0.5\nnewmtl chair_seat\nKd 0.5 0.5 0.5\n"
               "newmtl white\nKd 0.5 0.5 0.5\nnewmtl light\nKd 0 0 0\nKe 1 1 1\n");
    fclose(m);
    fprintf(f, "mtllib chair.mtl\n%susemtl %s\n", groups ? "o floor\n" : "", mat_all ? "white" : "floor");
    fprintf(f, "v -1 0 -1\nv -1 0 1\nv 1 0 1\nv 1 0 -1\nf 1 2 3 4\n");
    for (int b = 0; b < 2; b++) {
        const double *c = box[b];
        fprintf(f, "%susemtl %s\n", groups && b == 0 ? "o chair\n" : "", mat_all ? "white" : names[b]);
        for (int k = 0; k < 8; k++)   /* corner k: bits x, z, y */
            fprintf(f, "v %g %g %g\n", c[(k & 1) ? 3 : 0], c[(k & 4) ? 4 : 1], c[(k & 2) ? 5 : 2]);
        for (int k = 0; k < 6; k++) {
            static const int corner[8] = {0, 1, 3, 2, 4, 5, 7, 6};   /* bottom ring, then top ring */
            fprintf(f, "f %d %d %d %d\n", 5 + 8 * b + corner[q[k][0]], 5 + 8 * b + corner[q[k][1]],
                    5 + 8 * b + corner[q[k][2]], 5 + 8 * b + corner[q[k][3]]);
        }
    }
    fprintf(f, "%susemtl light\nv -0.3 2 -0.3\nv 0.3 2 -0.3\nv 0.3 2 0.3\nv -0.3 2 0.3\nf 21 22 23 24\n",
            groups ? "o lamp\n" : "");
    fclose(f);
}

/* Faces that got contact segments, meshing the chair with or without self_contacts. */
static size_t chair_contact_faces(int self, size_t *objects, int *from_file)
{
    bn_scene *s = NULL;
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    size_t n;
    bn_load_opts_default(&lo);
    bn_mesh_opts_default(&mo);
    mo.self_contacts = self;
    BN_ASSERT_STATUS(bn_scene_load(bn_test_tmp("chair.obj"), &lo, &s, &err), BN_OK);
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    n = bn_scene_stats_get(s).contact_faces;
    *objects = bn_scene_object_count(s);
    *from_file = bn_scene_objects_from_file(s);
    bn_scene_destroy(s);
    return n;
}

/* Contacts between objects are cut, an object's own only when asked: the floor under the leg is
 * the one face cut by default (its footprint); with self_contacts the seat's two faces the leg
 * passes through and the leg's four sides where the seat's edges cross them are cut too. The same
 * with the objects named by `o` lines; and with every face "white" (no prefix: one object that is
 * not an assembly) everything is cut as before objects existed. */
BN_TEST(contacts_between_objects)
{
    size_t nobj, dflt, self;
    int from_file;
    for (int groups = 0; groups < 2; groups++) {
        write_chair(groups, 0);
        dflt = chair_contact_faces(0, &nobj, &from_file);
        self = chair_contact_faces(1, &nobj, &from_file);
        fprintf(stderr, "%s: %zu objects; faces cut %zu, with self contacts %zu\n",
                groups ? "o groups" : "material prefixes", nobj, dflt, self);
        BN_ASSERT_EQ(from_file, groups);
        BN_ASSERT_EQ(nobj, 3);   /* floor, chair, lamp | floor, chair, light (white: no face uses it) */
        BN_ASSERT_EQ(dflt, 1);
        BN_ASSERT_EQ(self, 7);
    }
    write_chair(0, 1);
    dflt = chair_contact_faces(0, &nobj, &from_file);
    fprintf(stderr, "one material: %zu objects; faces cut %zu\n", nobj, dflt);
    BN_ASSERT_EQ(nobj, 2);   /* white, light */
    BN_ASSERT_EQ(dflt, 7);
}

/* A table leg's foot on the living room's floor (tests/data/table-leg.obj): two contact cuts cross a few
 * 1e-8 m apart near the leg's corner. Their cut points are one (within the contacts' resolution, 1e-6 of
 * the scene's diameter), so no floor patch is a sliver between them: every patch is wider than that, the
 * floor's patches still cover its 20 m2, and the default solve (dense, the closed form) accepts its F (a
 * sliver 2.7e-8 m wide got F = -0.011 to the leg, and the run refused it). */
BN_TEST(cuts_crossing_near_an_objects_corner_make_no_sliver)
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_scene *s;
    bn_error err;
    size_t np, nv;
    double floor_area = 0, thinnest = INFINITY, diam = sqrt(5.0 * 5.0 + 2.6 * 2.6 + 4.0 * 4.0);
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    BN_ASSERT_STATUS(bn_scene_load(bn_test_path("tests/data/table-leg.obj"), &lo, &s, &err), BN_OK);
    bn_mesh_opts_default(&mo);
    BN_ASSERT_STATUS(bn_scene_mesh(s, &mo, &err), BN_OK);
    const bn_patch *pt = bn_scene_patches(s, &np);
    const double *pv = bn_scene_patch_vertices(s, &nv);
    for (size_t i = 0; i < np; i++) {
        double lmax = 0;
        for (unsigned k = 0; k < pt[i].ncorners; k++) {
            const double *a = pv + 3 * pt[i].corner[k], *b = pv + 3 * pt[i].corner[(k + 1) % pt[i].ncorners];
            double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            lmax = fmax(lmax, sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
        }
        thinnest = fmin(thinnest, (pt[i].ncorners == 3 ? 2 : 1) * pt[i].area / lmax);
        if (pt[i].face <= 1)   /* the floor: the file's first two triangles */
            floor_area += pt[i].area;
    }
    fprintf(stderr, "%zu patches, the thinnest %.3g m wide (1e-6 of the diameter: %.3g m), floor %.12g m2\n", np,
            thinnest, 1e-6 * diam, floor_area);
    BN_ASSERT_GT(thinnest, 1e-6 * diam);
    BN_ASSERT_REL(floor_area, 20.0, 1e-9);
    bn_scene_destroy(s);
    char cmd[1024], *out = NULL;
    snprintf(cmd, sizeof cmd, "solve %s --unit m -o %s", bn_test_path("tests/data/table-leg.obj"),
             bn_test_tmp("leg.csv"));
    int rc = bn_test_bounce(cmd, &out);
    if (rc != 0)
        fprintf(stderr, "%s", out);
    BN_ASSERT_EQ(rc, 0);
    free(out);
}
