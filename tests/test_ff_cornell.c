/* Form factors on the published Cornell box: entries in [0, 1], row sums reported, and
 * F(occluded) <= F(unoccluded) for every pair of wall patches, F built with and without the
 * two blocks as occluders (the same wall patches in both scenes). */
#include "bn_test.h"
#include "bounce/formfactor.h"

static bn_scene *load_meshed(const char *path, double patch_size)
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_scene *s = NULL;
    bn_load_opts_default(&lo);
    lo.unit = BN_UNIT_MM;
    lo.log.quiet = 1;
    if (bn_scene_load(path, &lo, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.patch_size = patch_size;
    mo.no_contacts = 1;   /* the floor meshes the same with and without the blocks standing on it */
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    return s;
}

static bn_transport *build(const bn_scene *s, bn_ff_diagnostics *d)
{
    bn_rt *rt = NULL;
    bn_transport *k = NULL;
    bn_formfactor_opts o;
    bn_error err;
    if (bn_rt_create(s, 0, &rt, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_formfactor_opts_default(&o);
    o.quiet = 1;
    o.log.quiet = 1;
    if (bn_formfactor_build(s, rt, &o, &k, d, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_rt_destroy(rt);
    return k;
}

BN_TEST(cornell_occluded_at_most_unoccluded)
{
    /* The walls alone: the OBJ up to the first block, written beside a copy of its MTL. */
    char *text = bn_test_read_file(bn_test_path("meshes/cornell-box.obj"), NULL), *mtl;
    char *cut;
    FILE *fp;
    bn_scene *with, *without;
    bn_ff_diagnostics dw, dn;
    bn_transport *Kw, *Kn;
    size_t nw, nn, walls = 0, pairs = 0, tighter = 0;
    const bn_patch *pw;
    double worst_excess = 0, rmin = 2, rmax = 0;
    BN_ASSERT(text != NULL);
    cut = strstr(text, "\no short_block");
    BN_ASSERT(cut != NULL);
    cut[1] = '\0';
    fp = fopen(bn_test_tmp("walls.obj"), "w");
    fputs(text, fp);
    fclose(fp);
    free(text);
    mtl = bn_test_read_file(bn_test_path("meshes/cornell-box.mtl"), NULL);
    fp = fopen(bn_test_tmp("cornell-box.mtl"), "w");
    fputs(mtl, fp);
    fclose(fp);
    free(mtl);

    with = load_meshed(bn_test_path("meshes/cornell-box.obj"), 80.0);
    without = load_meshed(bn_test_tmp("walls.obj"), 80.0);
    Kw = build(with, &dw);
    Kn = build(without, &dn);
    nw = bn_transport_size(Kw);
    nn = bn_transport_size(Kn);
    pw = bn_scene_patches(with, NULL);
    /* Faces 0-9 (floor, light, ceiling, walls) come first in both scenes and mesh identically. */
    for (size_t i = 0; i < nw; i++)
        if (pw[i].face < 10)
            walls++;
    BN_ASSERT_EQ(walls, nn);
    BN_ASSERT_GT(nw, nn);
    BN_ASSERT_EQ(dw.negative_entries + dw.above_one_entries, 0);
    BN_ASSERT_GT(dw.pairs_blocked, 0);
    for (size_t i = 0; i < nw; i++) {
        double row = 0;
        for (size_t j = 0; j < nw; j++) {
            double f = bn_test_F(Kw, i, j);
            BN_ASSERT(f >= 0 && f <= 1);
            row += f;
        }
        rmin = fmin(rmin, row);
        rmax = fmax(rmax, row);
    }
    for (size_t i = 0; i < nn; i++)
        for (size_t j = 0; j < nn; j++) {
            double fo = bn_test_F(Kw, i, j), fu = bn_test_F(Kn, i, j);
            pairs++;
            if (fo < fu)
                tighter++;
            worst_excess = fmax(worst_excess, fo - fu);
        }
    fprintf(stderr, "Cornell box, %zu patches (%zu on the walls): row sums %.6f .. %.6f (reported %.6f .. %.6f); "
                    "%zu of %zu wall pairs reduced by the blocks; largest F_occ - F_unocc %.3g\n",
            nw, nn, rmin, rmax, dw.row_sum_min, dw.row_sum_max, tighter, pairs, worst_excess);
    BN_ASSERT_LE(worst_excess, 0.0);      /* exactly: F_occ = F_unocc x visible fraction */
    BN_ASSERT_GT(tighter, pairs / 20);    /* and the blocks do block something */
    BN_ASSERT_NEAR(dw.row_sum_max, rmax, 1e-6);
    BN_ASSERT_NEAR(dw.row_sum_min, rmin, 1e-6);
    bn_transport_destroy(Kw);
    bn_transport_destroy(Kn);
    bn_scene_destroy(with);
    bn_scene_destroy(without);
}
