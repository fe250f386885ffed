/* `bounce crosscheck SCENE`: radiosity (form factors + solve, with the same K^k E terms) against
 * the independent per-patch path tracer, per patch, bounce and channel, with a discretisation
 * tolerance estimated from a second mesh level; exit 6 when the verdict fails. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/trace.h"

#include <math.h>
#include <string.h>

/* One radiosity level: the pipeline's result (scene, rays, K, solution) and its layers stacked in
 * the tracer's layout. */
typedef struct bn__level {
    bn_pipeline p;
    double *layers;
    double seconds;
} bn__level;

static void bn__level_free(bn__level *l)
{
    free(l->layers);
    bn_pipeline_free(&l->p);
    memset(l, 0, sizeof *l);
}

/* The whole pipeline for `path` at meshing `so`, with the rays kept for the tracer. */
static bn_status bn__level_run(const char *path, const bn_pipeline_opts *po, const bn_cli_scene *so,
                               const bn_cli_common *c, int bounces, bn__level *lv, bn_error *err)
{
    bn_pipeline_opts o = *po;
    bn_pipeline_opts mesh;
    bn_status st;
    double t0 = bn__now();
    memset(lv, 0, sizeof *lv);
    bn_cli_pipeline_opts(so, NULL, NULL, c, &mesh);
    o.mesh = mesh.mesh;
    o.keep_rt = 1;
    st = bn_pipeline_run(path, &o, &lv->p, err);
    if (st != BN_OK)
        return st;
    lv->layers = bn__malloc_array(lv->p.n * (size_t)bn_layer_count(bounces), 3 * sizeof(double));
    if (!lv->layers)
        return bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory for %zu patches", lv->p.n);
    bn_layers_stack((const double *const *)lv->p.res.terms, lv->p.res.L, lv->p.n, bounces, lv->layers);
    lv->seconds = bn__now() - t0;
    return BN_OK;
}

int bn_cmd_crosscheck(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn_cli_scene so, so2;
    bn_cli_ff ffo;
    bn_pipeline_opts po;
    bn_trace_opts to;
    bn_trace_patches tr;
    bn_crosscheck_input in;
    bn_crosscheck_result cr;
    bn__level fine, other;
    const char *pos[1];
    size_t spp = 1024;
    int bounces = 3, disc = 0, worst = 10, rc = 0, strategy = 0;
    double alpha = 0.01, ratio = 2, tol_scale = 3, rtol = 0, solve_tol = 1e-10;
    double *tol = NULL, *power_tol = NULL;
    bn_error err;
    bn_status st;
    char ffdesc[256];

    memset(&set, 0, sizeof set);
    memset(&so, 0, sizeof so);
    memset(&ffo, 0, sizeof ffo);
    memset(&fine, 0, sizeof fine);
    memset(&other, 0, sizeof other);
    memset(&tr, 0, sizeof tr);
    memset(&cr, 0, sizeof cr);
    set.usage = "bounce crosscheck SCENE [meshing and form-factor options] [--spp N] [-n K] [--alpha A]";
    set.summary =
        "Compares the radiosity solution (form factors + solve, bounce terms E, KE, ..., K{n}E, rest, L)\n"
        "with the independent path tracer's per-patch estimates, per patch, layer and channel:\n"
        "z = (radiosity - trace) / se. Radiosity's discretisation error is estimated by solving a second\n"
        "mesh level (--disc) and allowed as a tolerance tol = |R(mesh) - R(other mesh)| per patch, so the\n"
        "test is z_excess = max(0, |R - T| - tol) / se <= the Sidak-corrected Student-t bound at --alpha\n"
        "over the family patches x layers x channels. Per-layer powers pi sum A_i L_i are tested the same\n"
        "way. The last line is the machine-readable verdict; exit code 6 when it fails.";
    bn_optset_add(&set, (bn_opt){"spp", 0, BN_OPT_SIZE, &spp, NULL, 2, 1e9, "N",
                                 "path-tracer samples per patch (default 1024; fewer make skewed patches' t-tests unreliable)"});
    bn_optset_add(&set, (bn_opt){"bounces", 'n', BN_OPT_INT, &bounces, NULL, 0, 64, "K",
                                 "terms E .. K{K}E compared one by one, then rest and L (default 3)"});
    bn_optset_add(&set, (bn_opt){"alpha", 0, BN_OPT_DOUBLE, &alpha, NULL, 1e-12, 0.5, "A",
                                 "family-wise false-failure rate of the verdict (default 0.01)"});
    bn_optset_add(&set, (bn_opt){"disc", 0, BN_OPT_CHOICE, &disc, "coarse|fine|none", 0, 0, "coarse|fine|none",
                                 "second mesh level for the discretisation tolerance: patch size x ratio, / ratio, "
                                 "or no allowance (default coarse)"});
    bn_optset_add(&set, (bn_opt){"disc-ratio", 0, BN_OPT_DOUBLE, &ratio, NULL, 1.01, 16, "R",
                                 "patch-size ratio between the two levels (default 2)"});
    bn_optset_add(&set, (bn_opt){"tol-scale", 0, BN_OPT_DOUBLE, &tol_scale, NULL, 0, 1e6, "S",
                                 "safety factor Fs of the grid-convergence estimate (default 3, Roache's two-level GCI)"});
    bn_optset_add(&set, (bn_opt){"rtol", 0, BN_OPT_DOUBLE, &rtol, NULL, 0, 1, "R",
                                 "a further relative allowance, rtol |radiosity| (default 0)"});
    bn_optset_add(&set, (bn_opt){"worst", 0, BN_OPT_INT, &worst, NULL, 0, 100000, "N",
                                 "worst entries listed (default 10)"});
    bn_optset_add(&set, (bn_opt){"strategy", 0, BN_OPT_CHOICE, &strategy, "mis|bsdf|nee", 0, 0, "mis|bsdf|nee",
                                 "path-tracer strategy (default mis)"});
    bn_optset_add(&set, (bn_opt){"solve-tol", 0, BN_OPT_DOUBLE, &solve_tol, NULL, 1e-15, 1e-2, "T",
                                 "radiosity solver tolerance, relative (default 1e-10: far below MC noise)"});
    bn_cli_add_ff(&set, &ffo);
    bn_cli_add_scene(&set, &so);
    bn_cli_add_common(&set, c);
    bn_error_clear(&err);
    {
        int prc;
        if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
            return prc;
    }

    bn_cli_pipeline_opts(&so, &ffo, NULL, c, &po);
    bn_formfactor_opts_describe(&po.ff, ffdesc, sizeof ffdesc);
    po.solve.tol = solve_tol;
    po.solve.bounces = bounces;
    po.solve.quiet = 1;
    po.solve.log_sink = (bn_log){NULL, NULL, 1};   /* warnings only: the report says how the solve went */

    /* Radiosity at the mesh asked. */
    st = bn__level_run(pos[0], &po, &so, c, bounces, &fine, &err);
    if (st != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    /* The path tracer on the same patches. */
    bn_trace_opts_default(&to);
    to.spp = spp;
    to.bounces = bounces;
    to.seed = c->seed;
    to.quiet = c->quiet;
    to.threads = c->threads;
    to.strategy = (bn_trace_strategy)strategy;
    st = bn_trace_patches_run(fine.p.rt, &to, &tr, &err);
    if (st != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    /* The second mesh level, for the discretisation tolerance. */
    if (disc != 2) {
        double h = bn_scene_patch_size(fine.p.scene);
        size_t nl = (size_t)bn_layer_count(bounces);
        so2 = so;
        so2.patches = 0;
        so2.no_subdivide = 0;
        so2.patch_size = h > 0 ? (disc == 0 ? h * ratio : h / ratio) : 0;
        if (!(so2.patch_size > 0)) {
            bn_error_set(&err, BN_EUSAGE, "crosscheck: --no-subdivide has no patch size to vary; use --disc none or "
                         "--patch-size");
            rc = bn_cli_fail(&err);
            goto done;
        }
        po.ff.cache_path = NULL;   /* the cache holds the mesh asked for */
        st = bn__level_run(pos[0], &po, &so2, c, bounces, &other, &err);
        if (st != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
        tol = bn__malloc_array(fine.p.n * nl, 3 * sizeof(double));
        power_tol = bn__malloc_array(nl, 3 * sizeof(double));
        if (!tol || !power_tol) {
            bn_error_set(&err, BN_ENOMEM, "crosscheck: out of memory");
            rc = bn_cli_fail(&err);
            goto done;
        }
        st = bn_crosscheck_mesh_tolerance(fine.p.scene, fine.layers, other.p.scene, other.layers, bounces, tol, power_tol, &err);
        if (st != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
    }

    bn_crosscheck_input_default(&in);
    in.scene = fine.p.scene;
    in.trace = &tr;
    in.rad = fine.layers;
    in.tol = tol;
    in.power_tol = power_tol;
    /* Two-level grid-convergence estimate (Roache 1994, GCI) with order p = 1 (patch-constant radiosity):
     * the error of the mesh asked is |R_h - R_other| / (r - 1) when the other level is coarser by r,
     * and r |R_h - R_other| / (r - 1) when it is finer; times the safety factor Fs = --tol-scale. */
    in.tol_scale = disc == 2 ? 0 : tol_scale * (disc == 0 ? 1 / (ratio - 1) : ratio / (ratio - 1));
    in.rtol = rtol;
    in.alpha = alpha;
    in.worst = worst;
    st = bn_crosscheck_compare(&in, &cr, &err);
    if (st != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    printf("# command=%s\n# bounce=%s\n# scene=%s unit=%s\n", c->cmdline, bn_version(), pos[0],
           bn_unit_name(bn_scene_unit(fine.p.scene)));
    printf("# radiosity: %zu patches (patch size %.6g), form factors %s, %s tol %g (%s, %zu iterations), %.2f s\n",
           fine.p.n, bn_scene_patch_size(fine.p.scene), ffdesc, bn_solve_method_name(po.solve.method), po.solve.tol,
           bn_stop_reason_name(fine.p.res.reason), fine.p.res.iterations, fine.seconds);
    if (other.p.scene)
        printf("# discretisation: second level %zu patches (patch size %.6g, %s by r = %g), %.2f s; tolerance = "
               "Fs %g x %s|difference| / (r - 1) = %g x |difference| (two-level GCI, order 1)\n",
               other.p.n, bn_scene_patch_size(other.p.scene), disc == 0 ? "coarser" : "finer", ratio, other.seconds,
               tol_scale, disc == 0 ? "" : "r ", in.tol_scale);
    else
        printf("# discretisation: no allowance (--disc none)\n");
    printf("# path tracer: %zu samples per patch, %s, rr_depth %d, seed %llu, %.3g rays in %.2f s (%.3g rays/s)\n",
           spp, bn_trace_strategy_name(to.strategy), to.rr_depth, (unsigned long long)c->seed, (double)tr.rays,
           tr.seconds, (double)tr.rays / fmax(tr.seconds, 1e-9));
    bn_crosscheck_print(&in, &cr, stdout);
    fflush(stdout);
    rc = cr.pass ? 0 : bn_status_exit_code(BN_EVERDICT);
done:
    bn_crosscheck_result_free(&cr);
    bn_trace_patches_free(&tr);
    free(tol);
    free(power_tol);
    bn__level_free(&fine);
    bn__level_free(&other);
    return rc;
}
