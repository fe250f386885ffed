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

int bn_cmd_study(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn_cli_scene so;
    bn_cli_ff ffo;
    const char *pos[1], *vary = NULL, *out = "study.csv", *plot = NULL, *report = NULL, *methods = NULL, *tols = NULL, *against = NULL;
    const char *title = NULL;
    size_t max_iter = 0, ref_patches = 0, spp = 0;
    const char *method = "direct";
    int ref_samples = 0, rr_depth = -1, refkind = 0;
    size_t ref_spp = 0;
    int metric = 0;
    double target = 0.01, values[BN__MAXV], tolv[BN__MAXV], againstv[BN__MAXV];
    size_t against_spp[BN__MAXV];
    bn_error err;
    bn_study_opts o;
    bn_study_result res;
    bn_status st;
    char prov[4096], ffdesc[512];
    int nv, nt = 0, na = 0;

    memset(&set, 0, sizeof set);
    memset(&so, 0, sizeof so);
    memset(&ffo, 0, sizeof ffo);
    set.usage = "bounce study SCENE --vary PARAM=V1,V2,... [fixed options] [-o study.csv] [--plot PREFIX]";
    set.summary =
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
    bn_optset_add(&set, (bn_opt){"vary", 0, BN_OPT_STRING, &vary, NULL, 0, 0, "PARAM=V1,V2,...",
                                 "the parameter and its settings (required)"});
    bn_optset_add(&set, (bn_opt){"output", 'o', BN_OPT_STRING, &out, NULL, 0, 0, "FILE",
                                 "the CSV (default study.csv; written atomically)"});
    bn_optset_add(&set, (bn_opt){"report", 0, BN_OPT_STRING, &report, NULL, 0, 0, "FILE.html",
                                 "also one self-contained page: the plots, the table and how the study was made"});
    bn_optset_add(&set, (bn_opt){"plot", 0, BN_OPT_STRING, &plot, NULL, 0, 0, "PREFIX",
                                 "also write PREFIX.png and PREFIX.svg (error vs time; error vs the parameter)"});
    bn_optset_add(&set, (bn_opt){"title", 0, BN_OPT_STRING, &title, NULL, 0, 0, "TEXT", "a title for the plot"});
    bn_cli_add_scene(&set, &so);
    bn_cli_add_ff(&set, &ffo);
    bn_optset_add(&set, (bn_opt){"method", 0, BN_OPT_NAME, &method, bn_solve_method_names(), 0, 0,
                                 "M", "solver for the mesh, samples, ff, spp and precision studies (default direct)"});
    bn_optset_add(&set, (bn_opt){"methods", 0, BN_OPT_STRING, &methods, NULL, 0, 0, "M1,M2",
                                 "methods compared by bounces, max-iter and tol (default all four)"});
    bn_optset_add(&set, (bn_opt){"tols", 0, BN_OPT_STRING, &tols, NULL, 0, 0, "T1,T2",
                                 "bounces: tolerances of the methods table (default 1e-2,1e-4,1e-6,1e-8)"});
    bn_optset_add(&set, (bn_opt){"max-iter", 0, BN_OPT_SIZE, &max_iter, NULL, 1, 1e9, "N",
                                 "iteration limit of the methods table (default 100000)"});
    bn_optset_add(&set, (bn_opt){"ref-patches", 0, BN_OPT_SIZE, &ref_patches, NULL, 1, 1e9, "N",
                                 "patches of the reference mesh (default 4x the finest setting, or 4x --patches)"});
    bn_optset_add(&set, (bn_opt){"ref", 0, BN_OPT_CHOICE, &refkind, "auto|radiosity|trace", 0, 0, "KIND",
                                 "patches, patch-size, spp: the reference: radiosity on a finer mesh, or the path "
                                 "tracer at --ref-spp (default auto: trace with --against-spp, else radiosity)"});
    bn_optset_add(&set, (bn_opt){"ref-spp", 0, BN_OPT_SIZE, &ref_spp, NULL, 1, 1e9, "N",
                                 "trace reference: spp (default from a 64-spp pilot: per-surface SE = target / 8)"});
    bn_optset_add(&set, (bn_opt){"ref-samples", 0, BN_OPT_INT, &ref_samples, NULL, 1, 1 << 24, "N",
                                 "shadow rays of the analytic reference (default 8x the largest setting, >= 256)"});
    bn_optset_add(&set, (bn_opt){"spp", 0, BN_OPT_SIZE, &spp, NULL, 1, 1e9, "N",
                                 "path-tracer samples per patch when not varied (default 64)"});
    bn_optset_add(&set, (bn_opt){"rr-depth", 0, BN_OPT_INT, &rr_depth, NULL, 0, 1000, "N",
                                 "path tracer: reflections before Russian roulette (default 3)"});
    bn_optset_add(&set, (bn_opt){"against-spp", 0, BN_OPT_STRING, &against, NULL, 0, 0, "S1,S2",
                                 "patches/patch-size/eps: also run the path tracer at these spp (equal-error comparison)"});
    bn_optset_add(&set, (bn_opt){"target", 0, BN_OPT_DOUBLE, &target, NULL, 1e-9, 1, "E",
                                 "equal-error target, per-surface relative error (default 0.01)"});
    bn_optset_add(&set, (bn_opt){"metric", 0, BN_OPT_CHOICE, &metric, "surface|patch", 0, 0, "surface|patch",
                                 "what --target bounds: the largest per-surface error (default), or the RMS error "
                                 "per patch on the reference's patches (the tracer then runs on the reference's mesh: "
                                 "give --ref-patches)"});
    bn_cli_add_common(&set, c);
    bn_error_clear(&err);
    {
        int prc;
        if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
            return prc;
    }
    if (!vary || !strchr(vary, '=')) {
        bn_error_set(&err, BN_EUSAGE, "study needs --vary PARAM=V1,V2,... (PARAM: bounces, max-iter, tol, patches, "
                                      "patch-size, samples, ff, spp, precision, eps)");
        return bn_cli_fail(&err);
    }

    bn_study_opts_default(&o);
    {
        char pname[64];
        size_t len = (size_t)(strchr(vary, '=') - vary);
        int (*conv)(const char *, double *) = bn__conv_num;
        if (len >= sizeof pname)
            len = sizeof pname - 1;
        memcpy(pname, vary, len);
        pname[len] = '\0';
        if (bn_study_param_parse(pname, &o.param) != 0) {
            bn_error_set(&err, BN_EUSAGE, "--vary: unknown parameter '%s' (bounces, max-iter, tol, patches, patch-size, "
                                          "samples, ff, spp, precision, eps)", pname);
            return bn_cli_fail(&err);
        }
        if (o.param == BN_STUDY_FF)
            conv = bn__conv_ff;
        else if (o.param == BN_STUDY_PRECISION)
            conv = bn__conv_prec;
        nv = bn__list("--vary", strchr(vary, '=') + 1, values, BN__MAXV, conv, &err);
        if (nv < 0)
            return bn_cli_fail(&err);
    }
    if (tols && (nt = bn__list("--tols", tols, tolv, BN__MAXV, bn__conv_num, &err)) < 0)
        return bn_cli_fail(&err);
    if (against) {
        if ((na = bn__list("--against-spp", against, againstv, BN__MAXV, bn__conv_num, &err)) < 0)
            return bn_cli_fail(&err);
        for (int i = 0; i < na; i++) {
            if (againstv[i] < 1 || againstv[i] != floor(againstv[i])) {
                bn_error_set(&err, BN_EUSAGE, "--against-spp: %g is not a whole number >= 1", againstv[i]);
                return bn_cli_fail(&err);
            }
            against_spp[i] = (size_t)againstv[i];
        }
    }
    if (methods) {
        double mv[8];
        int nm = bn__list("--methods", methods, mv, 8, bn__conv_method, &err);
        if (nm < 0)
            return bn_cli_fail(&err);
        o.methods = 0;
        for (int i = 0; i < nm; i++)
            o.methods |= 1u << (int)mv[i];
    }
    o.values = values;
    o.nvalues = (size_t)nv;
    o.load.unit = (bn_unit)so.unit;
    if (so.planar_tol > 0)
        o.load.planar_tol = so.planar_tol;
    o.load.log.fn = bn_cli_log;
    o.load.log.user = c;
    o.load.log.quiet = 1;   /* the scene is loaded once per setting: its notes once would be enough */
    o.mesh.patch_size = so.patch_size;
    if (so.patches)
        o.mesh.target_patches = so.patches;
    o.mesh.no_subdivide = so.no_subdivide;
    o.mesh.no_contacts = so.no_contacts;
    o.mesh.contact_gap = so.contact_gap;
    bn_cli_ff_opts(&ffo, c, &o.ff);
    o.ff.quiet = 1;
    o.ff.cache_path = NULL;   /* every setting is built and timed */
    o.transport = ffo.transport && strcmp(ffo.transport, "auto") ? ffo.transport : ffo.storage;
    bn_cli_hier_opts(&ffo, &o.hier);
    bn_solve_method_parse(method, &o.solve.method);   /* checked against the names when parsed */
    if (max_iter)
        o.solve.max_iter = max_iter;
    o.trace.seed = c->seed;
    o.threads = c->threads;
    if (spp)
        o.trace.spp = spp;
    if (rr_depth >= 0)
        o.trace.rr_depth = rr_depth;
    o.trace.bounces = 0;
    o.tols = nt ? tolv : NULL;
    o.ntols = (size_t)nt;
    o.ref_patches = ref_patches;
    o.ref_samples = ref_samples;
    o.ref = (bn_study_ref)refkind;
    o.ref_spp = ref_spp;
    o.against_spp = na ? against_spp : NULL;
    o.nagainst = (size_t)na;
    o.target = target;
    o.metric_patch = metric == 1;
    o.log.fn = bn_cli_log;
    o.log.user = c;
    o.log.quiet = c->quiet;

    st = bn_study_run(pos[0], &o, &res, &err);
    if (st != BN_OK)
        return bn_cli_fail(&err);

    bn_formfactor_opts_describe(&o.ff, ffdesc, sizeof ffdesc);
    snprintf(prov, sizeof prov,
             "# command=%s\n# version=%s\n# scene=%s\n# unit=%s\n# vary=%s\n# solver=%s\n# tolerance=%.9g\n"
             "# max_iter=%zu\n# formfactors=%s\n# seed=%llu\n# threads=%d\n# spp=%zu\n# ref=%s\n",
             c->cmdline ? c->cmdline : "bounce study", bn_version(), pos[0], bn_unit_name(o.load.unit), vary,
             bn_solve_method_name(o.solve.method), o.solve.tol, o.solve.max_iter, ffdesc,
             (unsigned long long)c->seed, bn_threads_resolve(c->threads), o.trace.spp, bn_study_ref_name(o.ref));
    st = bn_study_write_csv(&res, out, prov, &err);
    if (st == BN_OK && plot)
        st = bn_study_plot(&res, plot, title, &err);
    if (st == BN_OK && report)
        st = bn_study_write_report(&res, report, prov, title, &err);
    if (st != BN_OK) {
        bn_study_result_free(&res);
        return bn_cli_fail(&err);
    }
    if (!c->quiet)
        bn_study_print(&res, stdout);
    bn_study_result_free(&res);
    return 0;
}
