/* `bounce study SCENE --vary PARAM=V1,V2,...`: speed-accuracy studies (CSV, summary, plots). */
#include "cli/cli.h"
#include "bounce/study.h"
#include "base/internal.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define BN__MAXV 256

/* Splits "a,b,c" and converts each item with conv; returns the count or -1 (message in err). */
static int bn__list(const char *what, const char *s, double *out, int max, int (*conv)(const char *, double *),
                    bn_error *err)
{
    char buf[4096], *save = NULL, *tok;
    int n = 0;
    if (strlen(s) >= sizeof buf) {
        bn_error_set(err, BN_EUSAGE, "%s: list too long", what);
        return -1;
    }
    memcpy(buf, s, strlen(s) + 1);
    for (tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        if (n >= max) {
            bn_error_set(err, BN_EUSAGE, "%s: more than %d values", what, max);
            return -1;
        }
        if (!conv(tok, &out[n])) {
            bn_error_set(err, BN_EUSAGE, "%s: '%s' is not a valid value", what, tok);
            return -1;
        }
        n++;
    }
    if (n == 0)
        bn_error_set(err, BN_EUSAGE, "%s: empty list", what);
    return n ? n : -1;
}

static int bn__conv_num(const char *s, double *x)
{
    char *end;
    errno = 0;
    *x = strtod(s, &end);
    return end != s && *end == '\0' && !errno && isfinite(*x);
}
static int bn__conv_ff(const char *s, double *x)
{
    const char *names[3] = {"analytic", "montecarlo", "hemisphere"};
    for (int i = 0; i < 3; i++)
        if (strcmp(s, names[i]) == 0) {
            *x = i;
            return 1;
        }
    return 0;
}
static int bn__conv_prec(const char *s, double *x)
{
    bn_precision p;
    if (bn_precision_parse(s, &p) != 0)
        return 0;
    *x = (double)p;
    return 1;
}
static int bn__conv_method(const char *s, double *x)
{
    bn_solve_method m;
    if (bn_solve_method_parse(s, &m) != 0)
        return 0;
    *x = (double)m;
    return 1;
}

typedef struct bn__study_cli {
    bn_cli_scene so;
    bn_cli_ff ff;
    const char *vary, *out, *plot, *report, *methods, *tols, *against, *title, *method;
    size_t max_iter, ref_patches, spp, ref_spp;
    int ref_samples, rr_depth, refkind, metric, nv, nt, na;
    double target, values[BN__MAXV], tolv[BN__MAXV], againstv[BN__MAXV];
    size_t against_spp[BN__MAXV];
} bn__study_cli;

/* What is varied and what the study writes. */
static void bn__study_options(bn_optset *set, bn__study_cli *a)
{
    set->usage = "bounce study SCENE --vary PARAM=V1,V2,... [fixed options] [-o study.csv] [--plot PREFIX]";
    set->summary =
        "Measures how the error falls and the cost grows as one parameter varies. PARAM is the option it varies:\n"
        "bounces (the truncated series S_n, beside the bound ||K||^(n+1)/(1-||K||) ||E||, and Jacobi, Gauss-Seidel,\n"
        "Neumann and direct to each --tols), max-iter, tol, patches, patch-size, samples, ff (analytic,montecarlo,\n"
        "hemisphere), spp (path tracer), precision (float,double) or eps (the hierarchy's link tolerance: K_H on\n"
        "the fixed mesh against dense K with --ref-samples rays; with --against-spp against the path tracer on that\n"
        "mesh, the equal-error comparison). --transport hierarchical makes every setting's K\n"
        "the hierarchy (references stay dense). Each setting is compared with a stated, more\n"
        "accurate reference whose own error is estimated and printed: bounces/max-iter/tol/precision: a direct solve\n"
        "of the same K (double for precision); patches/patch-size/spp: a finer mesh (--ref-patches) or the path\n"
        "tracer (--ref trace; automatic with --against-spp, the equal-error comparison); samples/ff:\n"
        "analytic form factors with --ref-samples shadow rays. Errors: max and RMS relative per patch (on the\n"
        "reference's patches by centroid when meshes differ), per-surface area-weighted means, reflected power.\n"
        "Writes the CSV (with '# key=value' provenance), a summary on stdout and PREFIX.png / PREFIX.svg.";
    bn_optset_add(set, (bn_opt){"vary", 0, BN_OPT_STRING, &a->vary, NULL, 0, 0, "PARAM=V1,V2,...",
                                 "the parameter and its settings (required)"});
    bn_optset_add(set, (bn_opt){"output", 'o', BN_OPT_STRING, &a->out, NULL, 0, 0, "FILE",
                                 "the CSV (default study.csv; written atomically)"});
    bn_optset_add(set, (bn_opt){"report", 0, BN_OPT_STRING, &a->report, NULL, 0, 0, "FILE.html",
                                 "also one self-contained page: the plots, the table and how the study was made"});
    bn_optset_add(set, (bn_opt){"plot", 0, BN_OPT_STRING, &a->plot, NULL, 0, 0, "PREFIX",
                                 "also write PREFIX.png and PREFIX.svg (error vs time; error vs the parameter)"});
    bn_optset_add(set, (bn_opt){"title", 0, BN_OPT_STRING, &a->title, NULL, 0, 0, "TEXT", "a title for the plot"});
    bn_cli_add_scene(set, &a->so);
    bn_cli_add_ff(set, &a->ff);
    bn_optset_add(set, (bn_opt){"method", 0, BN_OPT_NAME, &a->method, bn_solve_method_names(), 0, 0,
                                 "M", "solver for the mesh, samples, ff, spp and precision studies (default direct)"});
    bn_optset_add(set, (bn_opt){"methods", 0, BN_OPT_STRING, &a->methods, NULL, 0, 0, "M1,M2",
                                 "methods compared by bounces, max-iter and tol (default all four)"});
    bn_optset_add(set, (bn_opt){"tols", 0, BN_OPT_STRING, &a->tols, NULL, 0, 0, "T1,T2",
                                 "bounces: tolerances of the methods table (default 1e-2,1e-4,1e-6,1e-8)"});
    bn_optset_add(set, (bn_opt){"max-iter", 0, BN_OPT_SIZE, &a->max_iter, NULL, 1, 1e9, "N",
                                 "iteration limit of the methods table (default 100000)"});
}

/* How each setting is judged: the reference and the equal-error comparison. */
static void bn__study_ref_options(bn_optset *set, bn__study_cli *a)
{
    bn_optset_add(set, (bn_opt){"ref-patches", 0, BN_OPT_SIZE, &a->ref_patches, NULL, 1, 1e9, "N",
                                 "patches of the reference mesh (default 4x the finest setting, or 4x --patches)"});
    bn_optset_add(set, (bn_opt){"ref", 0, BN_OPT_CHOICE, &a->refkind, bn_study_ref_names(), 0, 0, "KIND",
                                 "patches, patch-size, spp: the reference: radiosity on a finer mesh, or the path "
                                 "tracer at --ref-spp (default auto: trace with --against-spp, else radiosity)"});
    bn_optset_add(set, (bn_opt){"ref-spp", 0, BN_OPT_SIZE, &a->ref_spp, NULL, 1, 1e9, "N",
                                 "trace reference: spp (default from a 64-spp pilot: per-surface SE = target / 8)"});
    bn_optset_add(set, (bn_opt){"ref-samples", 0, BN_OPT_INT, &a->ref_samples, NULL, 1, 1 << 24, "N",
                                 "shadow rays of the analytic reference (default 8x the largest setting, >= 256)"});
    bn_optset_add(set, (bn_opt){"spp", 0, BN_OPT_SIZE, &a->spp, NULL, 1, 1e9, "N",
                                 "path-tracer samples per patch when not varied (default 64)"});
    bn_optset_add(set, (bn_opt){"rr-depth", 0, BN_OPT_INT, &a->rr_depth, NULL, 0, 1000, "N",
                                 "path tracer: reflections before Russian roulette (default 3)"});
    bn_optset_add(set, (bn_opt){"against-spp", 0, BN_OPT_STRING, &a->against, NULL, 0, 0, "S1,S2",
                                 "patches/patch-size/eps: also run the path tracer at these spp (equal-error comparison)"});
    bn_optset_add(set, (bn_opt){"target", 0, BN_OPT_DOUBLE, &a->target, NULL, 1e-9, 1, "E",
                                 "equal-error target, per-surface relative error (default 0.01)"});
    bn_optset_add(set, (bn_opt){"metric", 0, BN_OPT_CHOICE, &a->metric, bn_study_metric_names(), 0, 0, bn_study_metric_names(),
                                 "what --target bounds: the largest per-surface error (default), or the RMS error "
                                 "per patch on the reference's patches (the tracer then runs on the reference's mesh: "
                                 "give --ref-patches)"});
}

/* --vary's parameter and values, --tols, --against-spp and --methods into o. */
static bn_status bn__study_lists(bn__study_cli *a, bn_study_opts *o, bn_error *err)
{
    char pname[64];
    size_t len = (size_t)(strchr(a->vary, '=') - a->vary);
    int (*conv)(const char *, double *) = bn__conv_num;
    snprintf(pname, sizeof pname, "%.*s", (int)(len < sizeof pname ? len : sizeof pname - 1), a->vary);
    if (bn_study_param_parse(pname, &o->param) != 0)
        return bn_error_set(err, BN_EUSAGE, "--vary: unknown parameter '%s' (bounces, max-iter, tol, patches, "
                            "patch-size, samples, ff, spp, precision, eps)", pname);
    if (o->param == BN_STUDY_FF)
        conv = bn__conv_ff;
    else if (o->param == BN_STUDY_PRECISION)
        conv = bn__conv_prec;
    if ((a->nv = bn__list("--vary", strchr(a->vary, '=') + 1, a->values, BN__MAXV, conv, err)) < 0)
        return err->status;
    if (a->tols && (a->nt = bn__list("--tols", a->tols, a->tolv, BN__MAXV, bn__conv_num, err)) < 0)
        return err->status;
    if (a->against && (a->na = bn__list("--against-spp", a->against, a->againstv, BN__MAXV, bn__conv_num, err)) < 0)
        return err->status;
    for (int i = 0; i < a->na; i++) {
        if (a->againstv[i] < 1 || a->againstv[i] != floor(a->againstv[i]))
            return bn_error_set(err, BN_EUSAGE, "--against-spp: %g is not a whole number >= 1", a->againstv[i]);
        a->against_spp[i] = (size_t)a->againstv[i];
    }
    if (a->methods) {
        double mv[8];
        int nm = bn__list("--methods", a->methods, mv, 8, bn__conv_method, err);
        if (nm < 0)
            return err->status;
        o->methods = 0;
        for (int i = 0; i < nm; i++)
            o->methods |= 1u << (int)mv[i];
    }
    return BN_OK;
}

/* The scene, meshing, form-factor and solver options of every setting. */
static void bn__study_fixed(const bn__study_cli *a, bn_cli_common *c, bn_study_opts *o)
{
    o->load.unit = (bn_unit)a->so.unit;
    if (a->so.planar_tol > 0)
        o->load.planar_tol = a->so.planar_tol;
    o->load.orient = (bn_orient)a->so.orient;
    o->load.two_sided = a->so.two_sided;
    o->load.edits = a->so.edits.e;
    o->load.nedits = a->so.edits.n;
    o->load.log = (bn_log){bn_cli_log, c, 1};   /* the scene is loaded once per setting: its notes once would do */
    o->mesh.patch_size = a->so.patch_size;
    if (a->so.patches)
        o->mesh.target_patches = a->so.patches;
    o->mesh.no_subdivide = a->so.no_subdivide;
    o->mesh.no_contacts = a->so.no_contacts;
    o->mesh.self_contacts = a->so.self_contacts;
    o->mesh.contact_gap = a->so.contact_gap;
    bn_cli_ff_opts(&a->ff, c, &o->ff);
    o->ff.quiet = 1;
    o->ff.cache_path = NULL;   /* every setting is built and timed */
    o->transport = a->ff.transport && strcmp(a->ff.transport, "auto") ? a->ff.transport : a->ff.storage;
    bn_cli_hier_opts(&a->ff, &o->hier);
    bn_solve_method_parse(a->method, &o->solve.method);   /* checked against the names when parsed */
    if (a->max_iter)
        o->solve.max_iter = a->max_iter;
    o->threads = c->threads;
    o->log = (bn_log){bn_cli_log, c, c->quiet};
}

/* The tracer and the reference. */
static void bn__study_refs(const bn__study_cli *a, const bn_cli_common *c, bn_study_opts *o)
{
    o->values = a->values;
    o->nvalues = (size_t)a->nv;
    o->trace.seed = c->seed;
    if (a->spp)
        o->trace.spp = a->spp;
    if (a->rr_depth >= 0)
        o->trace.rr_depth = a->rr_depth;
    o->trace.bounces = 0;
    o->tols = a->nt ? a->tolv : NULL;
    o->ntols = (size_t)a->nt;
    o->ref_patches = a->ref_patches;
    o->ref_samples = a->ref_samples;
    o->ref = (bn_study_ref)a->refkind;
    o->ref_spp = a->ref_spp;
    o->against_spp = a->na ? a->against_spp : NULL;
    o->nagainst = (size_t)a->na;
    o->target = a->target;
    o->metric_patch = a->metric == BN_STUDY_METRIC_PATCH;
}

/* The CSV with its provenance, the plots and the report. */
static bn_status bn__study_write(const bn__study_cli *a, const bn_cli_common *c, const char *scene,
                                 const bn_study_opts *o, const bn_study_result *res, bn_error *err)
{
    char prov[4096], ffdesc[512];
    bn_status st;
    bn_formfactor_opts_describe(&o->ff, ffdesc, sizeof ffdesc);
    snprintf(prov, sizeof prov,
             "# command=%s\n# version=%s\n# scene=%s\n# unit=%s\n# vary=%s\n# solver=%s\n# tolerance=%.9g\n"
             "# max_iter=%zu\n# formfactors=%s\n# seed=%llu\n# threads=%d\n# spp=%zu\n# ref=%s\n",
             c->cmdline ? c->cmdline : "bounce study", bn_version(), scene, bn_unit_name(o->load.unit), a->vary,
             bn_solve_method_name(o->solve.method), o->solve.tol, o->solve.max_iter, ffdesc,
             (unsigned long long)c->seed, bn_threads_resolve(c->threads), o->trace.spp, bn_study_ref_name(o->ref));
    st = bn_study_write_csv(res, a->out, prov, err);
    if (st == BN_OK && a->plot)
        st = bn_study_plot(res, a->plot, a->title, err);
    if (st == BN_OK && a->report)
        st = bn_study_write_report(res, a->report, prov, a->title, err);
    return st;
}

int bn_cmd_study(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn__study_cli a;
    const char *pos[1];
    bn_error err;
    bn_study_opts o;
    bn_study_result res;
    int prc;

    memset(&set, 0, sizeof set);
    memset(&a, 0, sizeof a);
    a.out = "study.csv";
    a.method = "direct";
    a.rr_depth = -1;
    a.target = 0.01;
    bn__study_options(&set, &a);
    bn__study_ref_options(&set, &a);
    bn_cli_add_common(&set, c);
    bn_error_clear(&err);
    if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
        return prc;
    if (!a.vary || !strchr(a.vary, '=')) {
        bn_error_set(&err, BN_EUSAGE, "study needs --vary PARAM=V1,V2,... (PARAM: bounces, max-iter, tol, patches, "
                                      "patch-size, samples, ff, spp, precision, eps)");
        return bn_cli_fail(&err);
    }
    bn_study_opts_default(&o);
    if (bn__study_lists(&a, &o, &err) != BN_OK)
        return bn_cli_fail(&err);
    bn__study_fixed(&a, c, &o);
    bn__study_refs(&a, c, &o);
    if (bn_study_run(pos[0], &o, &res, &err) != BN_OK)
        return bn_cli_fail(&err);
    if (bn__study_write(&a, c, pos[0], &o, &res, &err) != BN_OK) {
        bn_study_result_free(&res);
        return bn_cli_fail(&err);
    }
    if (!c->quiet)
        bn_study_print(&res, stdout);
    bn_study_result_free(&res);
    return 0;
}
