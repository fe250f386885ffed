/* `bounce crosscheck SCENE`: radiosity (form factors + solve, with the same K^k E terms) against
 * the independent per-patch path tracer, per patch, bounce and channel, with a discretisation
 * tolerance estimated from a second mesh level; exit 6 when the verdict fails. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/formfactor.h"
#include "bounce/solve.h"
#include "bounce/trace.h"

#include <math.h>
#include <string.h>

/* One radiosity level: scene, rays, K, solution, and its layers in the tracer's layout. */
typedef struct bn__level {
    bn_scene *s;
    bn_rt *rt;
    bn_transport *k;
    bn_solve_result res;
    double *layers;
    size_t n;
    double seconds;
} bn__level;

static void bn__level_free(bn__level *l)
{
    free(l->layers);
    bn_solve_result_free(&l->res);
    bn_transport_destroy(l->k);
    bn_rt_destroy(l->rt);
    bn_scene_destroy(l->s);
    memset(l, 0, sizeof *l);
}

/* Loads and meshes `path` with `so`, builds K with `fo` and solves with `sopt`. */
static bn_status bn__level_run(const char *path, const bn_cli_scene *so, const bn_cli_common *c,
                               const bn_formfactor_opts *fo, const bn_solve_opts *sopt, int bounces, bn__level *lv,
                               bn_error *err)
{
    bn_status st;
    const double *const *terms;
    double *E;
    double t0 = bn__now();
    memset(lv, 0, sizeof *lv);
    st = bn_cli_load_scene(path, so, c, &lv->s);
    if (st != BN_OK)
        return bn_error_set(err, st, "%s", "");   /* already printed */
    bn_scene_patches(lv->s, &lv->n);
    st = bn_rt_create(lv->s, c->threads, &lv->rt, err);
    if (st == BN_OK)
        st = bn_formfactor_build(lv->s, lv->rt, fo, &lv->k, NULL, err);
    if (st != BN_OK)
        return st;
    E = bn__malloc_array(lv->n, 3 * sizeof(double));
    lv->layers = bn__malloc_array(lv->n * (size_t)bn_trace_nlayers(bounces), 3 * sizeof(double));
    if (!E || !lv->layers) {
        free(E);
        return bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory for %zu patches", lv->n);
    }
    bn_scene_patch_emission(lv->s, E);
    st = bn_solve(lv->k, E, sopt, &lv->res, err);
    free(E);
    if (st != BN_OK)
        return st;
    if (lv->res.nterms != bounces + 1)
        return bn_error_set(err, BN_EINTERNAL, "crosscheck: the solver kept %d terms, %d asked", lv->res.nterms,
                            bounces + 1);
    terms = (const double *const *)lv->res.terms;
    bn_crosscheck_layers(terms, lv->res.L, lv->n, bounces, lv->layers);
    lv->seconds = bn__now() - t0;
    return BN_OK;
}

int bn_cmd_crosscheck(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn_cli_scene so, so2;
    bn_formfactor_opts fo;
    bn_cli_ff ffo;
    bn_solve_opts sopt;
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
    bn_cli_apply_threads(c);

    bn_cli_ff_opts(&ffo, c, &fo);
    bn_formfactor_opts_describe(&fo, ffdesc, sizeof ffdesc);
    bn_solve_opts_default(&sopt);
    sopt.tol = solve_tol;
    sopt.bounces = bounces;
    sopt.quiet = 1;
    sopt.log_sink = (bn_log){NULL, NULL, 1};   /* warnings only: the report says how the solve went */

    /* Radiosity at the mesh asked. */
    st = bn__level_run(pos[0], &so, c, &fo, &sopt, bounces, &fine, &err);
    if (st != BN_OK) {
        rc = err.msg[0] ? bn_cli_fail(&err) : bn_status_exit_code(st);
        goto done;
    }
    /* The path tracer on the same patches. */
    bn_trace_opts_default(&to);
    to.spp = spp;
    to.bounces = bounces;
    to.seed = c->seed;
    to.quiet = c->quiet;
    to.strategy = (bn_trace_strategy)strategy;
    st = bn_trace_patches_run(fine.rt, &to, &tr, &err);
    if (st != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    /* The second mesh level, for the discretisation tolerance. */
    if (disc != 2) {
        double h = bn_scene_patch_size(fine.s);
        size_t nl = (size_t)bn_trace_nlayers(bounces);
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
        fo.cache_path = NULL;   /* the cache holds the mesh asked for */
        st = bn__level_run(pos[0], &so2, c, &fo, &sopt, bounces, &other, &err);
        if (st != BN_OK) {
            rc = err.msg[0] ? bn_cli_fail(&err) : bn_status_exit_code(st);
            goto done;
        }
        tol = bn__malloc_array(fine.n * nl, 3 * sizeof(double));
        power_tol = bn__malloc_array(nl, 3 * sizeof(double));
        if (!tol || !power_tol) {
            bn_error_set(&err, BN_ENOMEM, "crosscheck: out of memory");
            rc = bn_cli_fail(&err);
            goto done;
        }
        st = bn_crosscheck_mesh_tolerance(fine.s, fine.layers, other.s, other.layers, bounces, tol, power_tol, &err);
        if (st != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
    }

    bn_crosscheck_input_default(&in);
    in.scene = fine.s;
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
           bn_unit_name(bn_scene_unit(fine.s)));
    printf("# radiosity: %zu patches (patch size %.6g), form factors %s, %s tol %g (%s, %zu iterations), %.2f s\n",
           fine.n, bn_scene_patch_size(fine.s), ffdesc, bn_solve_method_name(sopt.method), sopt.tol,
           bn_stop_reason_name(fine.res.reason), fine.res.iterations, fine.seconds);
    if (other.s)
        printf("# discretisation: second level %zu patches (patch size %.6g, %s by r = %g), %.2f s; tolerance = "
               "Fs %g x %s|difference| / (r - 1) = %g x |difference| (two-level GCI, order 1)\n",
               other.n, bn_scene_patch_size(other.s), disc == 0 ? "coarser" : "finer", ratio, other.seconds,
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
