/* `bounce trace SCENE --spp N [-n K] -o pt.exr [--patches-out pt.csv]`: the path tracer's
 * per-bounce layers E, KE, ..., rest, L with their variances, and per-patch estimates. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/trace.h"

#include <math.h>
#include <string.h>

typedef struct bn__trace_cli {
    bn_cli_scene so;
    bn_cli_camera co;
    const char *out, *patches_out, *points;
    int bounces, strategy, model, rr_depth, half;
} bn__trace_cli;

static void bn__trace_options(bn_optset *set, bn__trace_cli *a, bn_cli_common *c)
{
    set->usage = "bounce trace SCENE --spp N [-n K] -o pt.exr [--patches-out pt.csv] [camera, meshing options]\n"
                 "       bounce trace SCENE --points FILE --spp N [-n K] -o out.csv";
    set->summary =
        "Monte Carlo path tracing over the same patches and materials as radiosity (nothing else is shared:\n"
        "no form factors, no K, no solver). Every contribution is binned by its number of reflections:\n"
        "E (emission seen directly), KE (direct light), K2E, ..., K{n}E, rest (longer paths) and L (their\n"
        "sum), with the variance of each pixel's mean as E_var, KE_var, .... Next-event estimation and\n"
        "cosine sampling are combined by multiple importance sampling; Russian roulette after --rr-depth\n"
        "reflections. Per-patch estimates (patch-averaged outgoing radiance, with standard errors) go to\n"
        "--patches-out. --model patch restarts each path, after every reflection, at a uniform point of the\n"
        "patch it hit: the estimate is then the patch-constant transport radiosity solves on these patches\n"
        "(what `bounce crosscheck` compares with), and images show each patch's mean. Results are identical\n"
        "for any --threads. --points FILE: estimates at points instead (one a line, `x y z nx ny nz` in\n"
        "scene units, the normal on the side wanted; each on the face within 1e-6 of the scene's diameter\n"
        "whose front agrees), one CSV row per point in the file's order: an independent reference for\n"
        "per-vertex values such as a bake's.";
    bn_optset_add(set, (bn_opt){"bounces", 'n', BN_OPT_INT, &a->bounces, NULL, 0, 64, "K",
                                 "terms E .. K{K}E kept as layers; longer paths go to rest (default 3)"});
    bn_optset_add(set, (bn_opt){"output", 'o', BN_OPT_STRING, &a->out, NULL, 0, 0, "FILE.exr",
                                 "multi-layer OpenEXR of the camera image"});
    bn_optset_add(set, (bn_opt){"patches-out", 0, BN_OPT_STRING, &a->patches_out, NULL, 0, 0, "FILE.csv",
                                 "per-patch estimates and standard errors (CSV)"});
    bn_optset_add(set, (bn_opt){"points", 0, BN_OPT_STRING, &a->points, NULL, 0, 0, "FILE",
                                 "estimate at the points of FILE (x y z nx ny nz a line); -o is then the CSV"});
    bn_optset_add(set, (bn_opt){"strategy", 0, BN_OPT_CHOICE, &a->strategy, bn_trace_strategy_names(), 0, 0, bn_trace_strategy_names(),
                                 "how reflections gather emission (default mis: NEE + cosine sampling)"});
    bn_optset_add(set, (bn_opt){"model", 0, BN_OPT_CHOICE, &a->model, bn_trace_model_names(), 0, 0, bn_trace_model_names(),
                                 "light transport itself, or the patch-constant transport of radiosity on these "
                                 "patches (default continuous)"});
    bn_optset_add(set, (bn_opt){"rr-depth", 0, BN_OPT_INT, &a->rr_depth, NULL, 1, 1000000, "D",
                                 "reflections before Russian roulette (default 3)"});
    bn_optset_add(set, (bn_opt){"half", 0, BN_OPT_FLAG, &a->half, NULL, 0, 0, NULL, "store half floats in the EXR"});
    bn_cli_add_camera(set, &a->co);
    /* The camera group's --spp is the tracer's sample count, per pixel and per patch. */
    for (size_t i = 0; i < set->n; i++)
        if (strcmp(set->opt[i].name, "spp") == 0) {
            set->opt[i].max = 1 << 30;
            set->opt[i].help = "independent samples per pixel and per patch (default 64)";
        }
    bn_cli_add_scene(set, &a->so);
    bn_cli_add_common(set, c);
}

/* Per-patch estimates to the CSV, and each layer's power on stdout. */
static bn_status bn__trace_patches_out(const bn__trace_cli *a, const bn_cli_common *c, const bn_rt *rt,
                                       const bn_scene *s, const bn_trace_opts *to, const char *header, bn_error *err)
{
    bn_trace_patches r;
    char name[16];
    bn_status st = bn_trace_patches_run(rt, to, &r, err);
    if (st != BN_OK)
        return st;
    st = bn_trace_patches_write_csv(a->patches_out, s, &r, header, err);
    if (st == BN_OK && !c->quiet) {
        printf("per-patch: %zu patches x %zu samples, %.3g rays in %.2f s (%.3g rays/s); wrote %s\n", r.n, to->spp,
               (double)r.rays, r.seconds, (double)r.rays / fmax(r.seconds, 1e-9), a->patches_out);
        printf("  %-6s %34s %34s\n", "layer", "power W (R G B)", "standard error W");
        for (int l = 0; l < r.nlayers; l++) {
            double w[3], e[3];
            bn_trace_patches_power(s, &r, l, w, e);
            printf("  %-6s %11.5g %11.5g %11.5g  %11.3g %11.3g %11.3g\n",
                   bn_layer_name(l, a->bounces, name, sizeof name), w[0], w[1], w[2], e[0], e[1], e[2]);
        }
    }
    bn_trace_patches_free(&r);
    return st;
}

/* The outputs asked for go together. */
static bn_status bn__trace_check(const bn__trace_cli *a, bn_error *err)
{
    if (!a->out && !a->patches_out)
        return bn_error_set(err, BN_EUSAGE, "trace needs -o FILE.exr, --patches-out FILE.csv, or both");
    if (a->points && (!a->out || strlen(a->out) < 4 || strcmp(a->out + strlen(a->out) - 4, ".csv") || a->patches_out))
        return bn_error_set(err, BN_EUSAGE, "trace --points FILE writes its estimates to -o FILE.csv (and no image or "
                            "--patches-out)");
    return BN_OK;
}

/* The estimates at the points of --points, to the CSV -o. */
static bn_status bn__trace_points_out(const bn__trace_cli *a, const bn_cli_common *c, const bn_rt *rt,
                                      const bn_scene *s, const bn_trace_opts *to, const char *header, bn_error *err)
{
    bn_trace_point *pts = NULL;
    bn_trace_patches r;
    size_t n;
    bn_status st = bn_trace_points_read(a->points, rt, &pts, &n, err);
    if (st == BN_OK && (st = bn_trace_points_run(rt, pts, n, to, &r, err)) == BN_OK) {
        st = bn_trace_points_write_csv(a->out, s, pts, &r, header, err);
        if (st == BN_OK && !c->quiet)
            printf("points: %zu x %zu samples, %.3g rays in %.2f s; wrote %s\n", n, to->spp, (double)r.rays, r.seconds,
                   a->out);
        bn_trace_patches_free(&r);
    }
    free(pts);
    return st;
}

/* The camera image as a multi-layer EXR with its provenance. */
static bn_status bn__trace_image_out(const bn_optset *set, bn__trace_cli *a, bn_cli_common *c, const char *scene_path,
                                     const bn_rt *rt, const bn_scene *s, const bn_trace_opts *to, bn_error *err)
{
    bn_camera cam;
    bn_trace_image img;
    bn_log lg = {bn_cli_log, c, c->quiet};
    char spp_s[32], n_s[16], method[96];
    bn_status st = bn_cli_make_camera(set, &a->co, scene_path, s, c, &cam, err);
    if (st == BN_OK)
        st = bn_trace_image_run(rt, &cam, to, &img, err);
    if (st != BN_OK)
        return st;
    snprintf(spp_s, sizeof spp_s, "%zu", to->spp);
    snprintf(n_s, sizeof n_s, "%d", a->bounces);
    snprintf(method, sizeof method, "path tracer (%s transport, strategy %s, Russian roulette after %d)",
             bn_trace_model_name(to->model), bn_trace_strategy_name(to->strategy), to->rr_depth);
    bn_attr attrs[6] = {
        {"bounce:command", c->cmdline}, {"bounce:version", bn_version()}, {"bounce:method", method},
        {"bounce:spp", spp_s},          {"bounce:bounces", n_s},
        {"bounce:units", "radiance W m^-2 sr^-1; *_var: variance of the pixel mean"},
    };
    st = bn_trace_image_write(&img, a->out, attrs, 6, a->half, &lg, err);
    if (st == BN_OK && !c->quiet)
        printf("image: %dx%d x %zu samples, %.3g rays in %.2f s (%.3g rays/s); wrote %s (layers E .. L and *_var)\n",
               img.width, img.height, to->spp, (double)img.rays, img.seconds,
               (double)img.rays / fmax(img.seconds, 1e-9), a->out);
    bn_trace_image_free(&img);
    return st;
}

int bn_cmd_trace(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn__trace_cli a;
    bn_trace_opts to;
    const char *pos[1];
    size_t np;
    int rc = 0, prc;
    bn_error err;
    bn_scene *s = NULL;
    bn_rt *rt = NULL;
    bn_status st;
    char header[2048];

    memset(&set, 0, sizeof set);
    memset(&a, 0, sizeof a);
    a.bounces = 3;
    a.rr_depth = 3;
    bn__trace_options(&set, &a, c);
    bn_error_clear(&err);
    if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
        return prc;
    if (bn__trace_check(&a, &err) != BN_OK)
        return bn_cli_fail(&err);
    if ((st = bn_cli_load_scene(pos[0], &a.so, c, NULL, &s)) != BN_OK)
        return bn_status_exit_code(st);
    bn_trace_opts_default(&to);
    to.spp = bn_cli_given(&set, "spp") ? (size_t)a.co.spp : 64;   /* the camera group's --spp, also per patch */
    to.bounces = a.bounces;
    to.rr_depth = a.rr_depth;
    to.strategy = (bn_trace_strategy)a.strategy;
    to.model = (bn_trace_model)a.model;
    to.seed = c->seed;
    to.quiet = c->quiet;
    to.threads = c->threads;
    bn_scene_patches(s, &np);
    snprintf(header, sizeof header,
             "# command=%s\n# bounce=%s\n# scene=%s\n# unit=%s\n# patches=%zu\n# spp=%zu\n# bounces=%d\n"
             "# model=%s\n# strategy=%s\n# rr_depth=%d\n# seed=%llu\n# radiance=W m^-2 sr^-1\n",
             c->cmdline, bn_version(), pos[0], bn_unit_name(bn_scene_unit(s)), np, to.spp, a.bounces,
             bn_trace_model_name(to.model), bn_trace_strategy_name(to.strategy), a.rr_depth,
             (unsigned long long)c->seed);
    st = bn_rt_create(s, c->threads, &rt, &err);
    if (st == BN_OK && a.points)
        st = bn__trace_points_out(&a, c, rt, s, &to, header, &err);
    else if (st == BN_OK && a.patches_out)
        st = bn__trace_patches_out(&a, c, rt, s, &to, header, &err);
    if (st == BN_OK && a.out && !a.points)
        st = bn__trace_image_out(&set, &a, c, pos[0], rt, s, &to, &err);
    if (st != BN_OK)
        rc = bn_cli_fail(&err);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
    return rc;
}
