/* Contact lines: a block standing on a plane under a square light. The floor's patches must not
 * straddle the block's footprint; the hidden ones receive nothing; the lit ones next to the block
 * carry their own direct light, checked against the exact point-to-polygon form factor (Lambert's
 * contour formula, with the block's shadow clipped out of the light exactly) integrated over each
 * patch in this file, to 2% of what the patch would get without the block (the shadow rays' noise,
 * 256 a pair, is well inside that; a patch averaged with the hidden floor would be off by its hidden
 * share). */
#include "bn_test.h"
#include "bounce/pipeline.h"

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
    bn_scene_destroy(s);
}
