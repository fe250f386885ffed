/* `bounce crosscheck SCENE`: radiosity (form factors + solve, with the same K^k E terms) against
 * the independent per-patch path tracer, per patch, bounce and channel: by default the tracer's
 * patch-constant transport (no discretisation between the two), or light transport itself with a
 * tolerance from a second mesh level; exit 6 when the verdict fails. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/trace.h"

#include <math.h>
#include <string.h>

typedef struct bn__xcheck_cli {
    bn_cli_scene so;
    bn_cli_ff ffo;
    size_t spp, regions, regions_above;
    int bounces, disc, worst, strategy, model;
    double alpha, ratio, tol_scale, rtol, solve_tol;
} bn__xcheck_cli;

static void bn__xcheck_options(bn_optset *set, bn__xcheck_cli *a, bn_cli_common *c)
{
    *a = (bn__xcheck_cli){.spp = 1024, .bounces = 3, .worst = 10, .alpha = 0.01, .ratio = 2, .tol_scale = 3,
                          .solve_tol = 1e-10, .model = BN_TRACE_PATCH, .regions_above = BN_CROSSCHECK_REGIONS_ABOVE};
    set->usage = "bounce crosscheck SCENE [meshing and form-factor options] [--spp N] [-n K] [--alpha A]";
    set->summary =
        "Compares the radiosity solution (form factors + solve, bounce terms E, KE, ..., K{n}E, rest, L)\n"
        "with the independent path tracer's per-patch estimates, per patch, layer and channel:\n"
        "z = (radiosity - trace) / se, se the larger of the patch's own and the one its face's pooled\n"
        "samples imply (their rare large paths), corrected for the samples' skewness (Hall 1992) and\n"
        "tested against the Sidak-corrected Student-t bound at --alpha over the family patches x layers\n"
        "x channels; per-layer powers pi sum A_i L_i the same way. By default\n"
        "(--model patch) the tracer restarts each path on the patch it hits, so it estimates the\n"
        "patch-constant transport radiosity solves on these patches: no discretisation lies between the\n"
        "two, and a failure is an error of the form factors, K or the solver (the hierarchy's own\n"
        "approximation is allowed from a second eps level). --model continuous compares with light\n"
        "transport itself and allows radiosity's discretisation error from a second mesh level (--disc):\n"
        "z_excess = max(0, |R - T| - tol) / se, tol = Fs |R(mesh) - R(other mesh)| / (r - 1); that\n"
        "estimate runs short at concave corners and contacts, so it has no stated false-alarm rate there.\n"
        "The last line is the machine-readable verdict; exit code 6 when it fails.";
    bn_optset_add(set, (bn_opt){"spp", 0, BN_OPT_SIZE, &a->spp, NULL, 2, 1e9, "N",
                                 "path-tracer samples per patch (default 1024; fewer make skewed patches' t-tests unreliable)"});
    bn_optset_add(set, (bn_opt){"regions", 0, BN_OPT_SIZE, &a->regions, NULL, 1, 1e6, "N",
                                 "compare area means over about N regions of whole polygons, one material each "
                                 "(split at area medians), --spp samples each, instead of every patch: for scenes "
                                 "with more patches than the tracer can resolve (default: per patch, or see "
                                 "--regions-above)"});
    bn_optset_add(set, (bn_opt){"regions-above", 0, BN_OPT_SIZE, &a->regions_above, NULL, 0, 1e12, "N",
                                 "without --regions, a scene meshed into more than N patches is compared per object "
                                 "and material (its o/g groups or material-name prefixes), each polygon over 1% of "
                                 "the area (a wall, the floor) a region of its own (default "
                                 BN__STR(BN_CROSSCHECK_REGIONS_ABOVE) "; 0: always per patch)"});
    bn_optset_add(set, (bn_opt){"bounces", 'n', BN_OPT_INT, &a->bounces, NULL, 0, 64, "K",
                                 "terms E .. K{K}E compared one by one, then rest and L (default 3)"});
    bn_optset_add(set, (bn_opt){"alpha", 0, BN_OPT_DOUBLE, &a->alpha, NULL, 1e-12, 0.5, "A",
                                 "family-wise false-failure rate of the verdict (default 0.01)"});
    bn_optset_add(set, (bn_opt){"model", 0, BN_OPT_CHOICE, &a->model, bn_trace_model_names(), 0, 0, bn_trace_model_names(),
                                 "what the tracer estimates: the patch-constant transport radiosity solves, or light "
                                 "transport itself (default patch)"});
    bn_optset_add(set, (bn_opt){"disc", 0, BN_OPT_CHOICE, &a->disc, bn_disc_names(), 0, 0,
                                 bn_disc_names(),
                                 "allowance levels: a second mesh level at patch size x ratio or / ratio (and the "
                                 "hierarchy's eps x or / ratio^2), or none; auto: the mesh level only with --model "
                                 "continuous, the eps level under the hierarchy (default auto)"});
    bn_optset_add(set, (bn_opt){"disc-ratio", 0, BN_OPT_DOUBLE, &a->ratio, NULL, 1.01, 16, "R",
                                 "patch-size ratio between the two levels (default 2)"});
    bn_optset_add(set, (bn_opt){"tol-scale", 0, BN_OPT_DOUBLE, &a->tol_scale, NULL, 0, 1e6, "S",
                                 "safety factor Fs of the grid-convergence estimate (default 3, Roache's two-level GCI)"});
    bn_optset_add(set, (bn_opt){"rtol", 0, BN_OPT_DOUBLE, &a->rtol, NULL, 0, 1, "R",
                                 "a further relative allowance, rtol |radiosity| (default 0)"});
    bn_optset_add(set, (bn_opt){"worst", 0, BN_OPT_INT, &a->worst, NULL, 0, 100000, "N",
                                 "worst entries listed (default 10)"});
    bn_optset_add(set, (bn_opt){"strategy", 0, BN_OPT_CHOICE, &a->strategy, bn_trace_strategy_names(), 0, 0, bn_trace_strategy_names(),
                                 "path-tracer strategy (default mis)"});
    bn_optset_add(set, (bn_opt){"solve-tol", 0, BN_OPT_DOUBLE, &a->solve_tol, NULL, 1e-15, 1e-2, "T",
                                 "radiosity solver tolerance, relative (default 1e-10: far below MC noise)"});
    bn_cli_add_ff(set, &a->ffo);
    bn_cli_add_scene(set, &a->so);
    bn_cli_add_common(set, c);
}

static void bn__xcheck_opts(const bn__xcheck_cli *a, bn_cli_common *c, bn_crosscheck_opts *xo)
{
    bn_crosscheck_opts_default(xo);
    bn_cli_pipeline_opts(&a->so, &a->ffo, NULL, c, &xo->pipeline);
    xo->pipeline.solve.quiet = 1;
    xo->pipeline.solve.log_sink = (bn_log){bn_cli_log, c, 1};   /* warnings only: the report says how the solve went */
    xo->trace.spp = a->spp;
    xo->trace.seed = c->seed;
    xo->trace.quiet = c->quiet;
    xo->trace.threads = c->threads;
    xo->trace.strategy = (bn_trace_strategy)a->strategy;
    xo->trace.model = (bn_trace_model)a->model;
    xo->bounces = a->bounces;
    xo->solve_tol = a->solve_tol;
    xo->disc = (bn_disc)a->disc;
    xo->ratio = a->ratio;
    xo->tol_scale = a->tol_scale;
    xo->rtol = a->rtol;
    xo->alpha = a->alpha;
    xo->worst = a->worst;
    xo->regions = a->regions;
    xo->regions_above = a->regions_above;
}

/* How radiosity was solved: the hierarchy's links or the form factors, the solver, the time. */
static void bn__xcheck_radiosity(const bn_crosscheck_opts *xo, const bn_crosscheck_run *run)
{
    char ffdesc[256];
    bn_formfactor_opts_describe(&xo->pipeline.ff, ffdesc, sizeof ffdesc);
    if (run->fine.hierarchical)
        printf("# radiosity: %zu patches (patch size %.6g), K hierarchy eps %g (%zu links, %zu planes of %zu polygons, "
               "min area %.3g), %s tol %g (%s, %zu iterations), %.2f s\n",
               run->fine.n, bn_scene_patch_size(run->fine.scene), xo->pipeline.hier.eps, run->fine.hier.links,
               run->fine.hier.planes, run->fine.hier.polygons, run->fine.hier.min_area,
               bn_solve_method_name(run->fine.method_used), xo->solve_tol, bn_stop_reason_name(run->fine.res.reason),
               run->fine.res.iterations, run->seconds_fine);
    else
        printf("# radiosity: %zu patches (patch size %.6g), form factors %s, %s tol %g (%s, %zu iterations), %.2f s\n",
               run->fine.n, bn_scene_patch_size(run->fine.scene), ffdesc, bn_solve_method_name(run->fine.method_used),
               xo->solve_tol, bn_stop_reason_name(run->fine.res.reason), run->fine.res.iterations, run->seconds_fine);
}

/* The discretisation allowance: the second mesh level, the hierarchy's eps level, or none. */
static void bn__xcheck_disc(const bn__xcheck_cli *a, const bn_crosscheck_run *run)
{
    if (run->other.scene)
        printf("# discretisation: second level %zu patches (patch size %.6g, %s by r = %g%s), %.2f s; tolerance = "
               "Fs %g x %s|difference| / (r - 1) = %g x |difference| (two-level GCI, order 1)\n",
               run->other.n, bn_scene_patch_size(run->other.scene), a->disc != BN_DISC_FINE ? "coarser" : "finer",
               a->ratio, run->other_eps.scene ? ", hierarchy eps as asked" : "", run->seconds_other, a->tol_scale,
               a->disc != BN_DISC_FINE ? "" : "r ", run->in.tol_scale);
    if (run->other_eps.scene)
        printf("# discretisation: eps level %zu patches (the mesh asked, hierarchy eps %s r^2, %zu links), %.2f s; its "
               "|difference| adds to the mesh level's in the tolerance\n",
               run->other_eps.n, a->disc != BN_DISC_FINE ? "x" : "/", run->other_eps.hier.links, run->seconds_other_eps);
    if (!run->other.scene && !run->other_eps.scene)
        printf("# discretisation: no allowance (%s)\n",
               a->disc == BN_DISC_NONE ? "--disc none"
                                       : "the tracer's patch-constant transport is radiosity's own: --model patch");
}

int bn_cmd_crosscheck(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn__xcheck_cli a;
    bn_crosscheck_opts xo;
    bn_crosscheck_run run;
    const char *pos[1];
    int rc, prc;
    bn_error err;

    memset(&set, 0, sizeof set);
    memset(&run, 0, sizeof run);
    bn__xcheck_options(&set, &a, c);
    bn_error_clear(&err);
    if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
        return prc;
    bn__xcheck_opts(&a, c, &xo);
    if (bn_crosscheck_run_scene(pos[0], &xo, &run, &err) != BN_OK) {
        rc = bn_cli_fail(&err);
        bn_crosscheck_run_free(&run);
        return rc;
    }
    printf("# command=%s\n# bounce=%s\n# scene=%s unit=%s\n", c->cmdline, bn_version(), pos[0],
           bn_unit_name(bn_scene_unit(run.fine.scene)));
    bn__xcheck_radiosity(&xo, &run);
    bn__xcheck_disc(&a, &run);
    if (run.regioned == 1)
        printf("# regions: %zu regions of whole polygons (asked %zu), one material each, area-balanced\n",
               run.part.n, a.regions);
    else if (run.regioned == 2)
        printf("# regions: %zu regions, one per object and material, each polygon over %g%% of the area its own, "
               "chosen because %zu patches are more than --regions-above %zu (the tracer at %zu samples each)\n",
               run.part.n, 100 * BN_PARTITION_OWN_SHARE, run.fine.n, a.regions_above, a.spp);
    printf("# path tracer: %s transport, %zu samples per %s, %s, rr_depth %d, seed %llu, %.3g rays in %.2f s "
           "(%.3g rays/s)\n",
           bn_trace_model_name(xo.trace.model), a.spp, run.regioned ? "region" : "patch",
           bn_trace_strategy_name(xo.trace.strategy), xo.trace.rr_depth,
           (unsigned long long)c->seed, (double)run.trace.rays, run.trace.seconds,
           (double)run.trace.rays / fmax(run.trace.seconds, 1e-9));
    bn_crosscheck_print(&run.in, &run.result, stdout);
    fflush(stdout);
    rc = run.result.pass ? 0 : bn_status_exit_code(BN_EVERDICT);
    bn_crosscheck_run_free(&run);
    return rc;
}
