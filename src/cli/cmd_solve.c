/* `bounce solve SCENE -o patches.csv`: mesh, form factors, then (I - K) L = E by the chosen method;
 * one CSV row per patch (L and, with -n, the bounce terms E, KE, K2E, ...), the convergence log
 * with --log, a summary on stderr. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/rt.h"
#include "bounce/solve.h"

#include <math.h>
#include <string.h>

typedef struct bn__solve_cli {
    int method, stop, symmetric, bounces;
    double tol, atol, singular_threshold;
    size_t max_iter;
    const char *log, *output;
} bn__solve_cli;

static void bn__cli_note(void *user, bn_log_level level, const char *msg)
{
    const bn_cli_common *c = user;
    if (level == BN_LOG_WARN)
        fprintf(stderr, "bounce: warning: %s\n", msg);
    else if (level == BN_LOG_INFO && !c->quiet)
        fprintf(stderr, "bounce: %s\n", msg);
}

/* Bounce term names: E, KE, K2E, K3E, ... (bounce 1 is KE, never K1E). */
static void bn__term_name(int k, char *buf, size_t n)
{
    if (k == 0)
        snprintf(buf, n, "E");
    else if (k == 1)
        snprintf(buf, n, "KE");
    else
        snprintf(buf, n, "K%dE", k);
}

/* A CSV field: quoted when it holds a comma, quote or line break. */
static void bn__csv_str(FILE *fp, const char *s)
{
    if (!strpbrk(s, ",\"\r\n")) {
        fputs(s, fp);
        return;
    }
    fputc('"', fp);
    for (; *s; s++) {
        if (*s == '"')
            fputc('"', fp);
        fputc(*s, fp);
    }
    fputc('"', fp);
}

/* Provenance: the run's configuration as `# key=value` lines. `run` (command, scene, meshing,
 * form factors) heads the log, whose solver keys the solver writes itself; the CSV gets `run`
 * followed by the solver keys written here. */
static void bn__provenance_run(char *buf, size_t n, const bn_cli_common *c, const bn_scene *s, const bn_cli_ff *ffo,
                               const bn_ff_diagnostics *d)
{
    snprintf(buf, n,
             "# command=%s\n# scene=%s\n# unit=%s\n# seed=%llu\n# threads=%d\n# ff_method=%s\n"
             "# ff_row_sum_min=%.9g\n# ff_row_sum_max=%.9g\n# ff_reciprocity_residual=%.3g\n# ff_seconds=%.3f\n",
             c->cmdline ? c->cmdline : "bounce solve", bn_scene_path(s), bn_unit_name(bn_scene_unit(s)),
             (unsigned long long)c->seed, bn_threads_get(), bn_ff_method_name((bn_ff_method)ffo->method), d->row_sum_min,
             d->row_sum_max, d->reciprocity_residual, d->seconds);
}

static void bn__provenance_solve(FILE *fp, const bn_solve_opts *o, const bn_solve_result *res, const bn_transport *k)
{
    fprintf(fp,
            "# version=%s\n# patches=%zu\n# method=%s%s\n# tol=%.9g\n# atol=%.9g\n# max_iter=%zu\n# stop=%s\n"
            "# bounces=%d\n# singular_threshold=%.3g\n# transport=%s\n# radiance_unit=W m^-2 sr^-1\n# area_unit=m^2\n"
            "# stop_reason=%s\n# iterations=%zu\n# residual_max=%.9g\n# error_bound=%.9g\n# k_norm_inf=%.9g\n"
            "# spectral_radius=%.9g\n",
            bn_version(), res->n, bn_solve_method_name(o->method),
            o->symmetric && o->method == BN_SOLVE_GAUSS_SEIDEL ? "-symmetric" : "", o->tol, o->atol, o->max_iter,
            bn_solve_stop_name(o->stop), o->bounces, o->singular_threshold, bn_transport_name(k),
            bn_stop_reason_name(res->reason), res->iterations, res->residual_max, res->error_bound, res->k_norm_inf,
            res->spectral_radius);
}

int bn_cmd_solve(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn_cli_scene so;
    bn_cli_ff ffo;
    bn_rt *rt = NULL;
    bn__solve_cli a;
    bn_solve_opts o;
    bn_solve_result res;
    bn_ff_diagnostics diag;
    const char *pos[1];
    size_t np;
    int rc = 0, with_terms;
    bn_error err, serr;
    bn_scene *s = NULL;
    bn_transport *k = NULL;
    double *E = NULL, t0, t_load, t_ff, t_out = 0, m2;
    bn__outfile logf, outf;
    char prov[4096];
    bn_status st;
    const bn_patch *patches;
    const bn_material *mats;
    size_t nm;

    memset(&set, 0, sizeof set);
    memset(&so, 0, sizeof so);
    memset(&ffo, 0, sizeof ffo);
    memset(&a, 0, sizeof a);
    memset(&res, 0, sizeof res);
    memset(&logf, 0, sizeof logf);
    memset(&outf, 0, sizeof outf);
    bn_solve_opts_default(&o);
    a.method = (int)o.method;
    a.tol = o.tol;
    a.atol = o.atol;
    a.max_iter = o.max_iter;
    a.bounces = o.bounces;
    a.singular_threshold = o.singular_threshold;
    set.usage = "bounce solve SCENE [meshing options] [--method M] [--tol T] [--atol A] [--max-iter N] [--bounces N]\n"
                "                    [--symmetric] [--log conv.csv] -o patches.csv";
    set.summary =
        "Meshes SCENE into patches, computes the form factors F and solves (I - K) L = E per channel,\n"
        "K = diag(rho) F, for the outgoing radiance L of every patch (W m^-2 sr^-1). Writes one CSV row\n"
        "per patch: patch,face,material,area (m^2),L_R,L_G,L_B, and with -n N the bounce terms\n"
        "E, KE, K2E, ... K^N E (bounce k = light that reflected k times). The iterative methods stop when\n"
        "||E - (I - K) L||_inf <= tol ||E||_inf (or atol); neumann stops when its tail bound\n"
        "||K^(n+1) E|| / (1 - ||K||) is below it. Before iterating, ||K||_inf and the spectral radius\n"
        "(power iteration) are reported with the predicted iteration count, and a (near-)singular\n"
        "system (a closed scene with reflectance 1) is refused with exit code 5.";
    bn_cli_add_scene(&set, &so);
    bn_cli_add_ff(&set, &ffo);
    bn_optset_add(&set, (bn_opt){"method", 'm', BN_OPT_CHOICE, &a.method, "jacobi|gauss-seidel|neumann|direct", 0, 0,
                                 "M", "jacobi, gauss-seidel, neumann (series) or direct (LAPACK) (default gauss-seidel)"});
    bn_optset_add(&set, (bn_opt){"tol", 0, BN_OPT_DOUBLE, &a.tol, NULL, 0, 1, "T",
                                 "stop when ||r||_inf <= T ||E||_inf (default 1e-6)"});
    bn_optset_add(&set, (bn_opt){"atol", 0, BN_OPT_DOUBLE, &a.atol, NULL, 0, 1e300, "A",
                                 "or when ||r||_inf <= A, W m^-2 sr^-1 (default 0: off)"});
    bn_optset_add(&set, (bn_opt){"max-iter", 0, BN_OPT_SIZE, &a.max_iter, NULL, 0, 1e15, "N",
                                 "iteration limit; reaching it exits with 5 (default 100000)"});
    bn_optset_add(&set, (bn_opt){"bounces", 'n', BN_OPT_INT, &a.bounces, NULL, 0, 10000, "N",
                                 "write the terms K^0 E .. K^N E as columns (default: none; 3 kept internally)"});
    bn_optset_add(&set, (bn_opt){"symmetric", 0, BN_OPT_FLAG, &a.symmetric, NULL, 0, 0, NULL,
                                 "gauss-seidel: a forward then a backward sweep per iteration"});
    bn_optset_add(&set, (bn_opt){"stop", 0, BN_OPT_CHOICE, &a.stop, "default|residual|bound", 0, 0, "S",
                                 "what tol bounds: residual, or the error bound ||r||/(1-||K||) (default: bound for "
                                 "neumann, residual otherwise)"});
    bn_optset_add(&set, (bn_opt){"singular-threshold", 0, BN_OPT_DOUBLE, &a.singular_threshold, NULL, 0, 0.5, "D",
                                 "refuse when rho(K) >= 1 - D; set D to F's row-sum error (default 1e-6)"});
    bn_optset_add(&set, (bn_opt){"log", 0, BN_OPT_STRING, &a.log, NULL, 0, 0, "FILE",
                                 "convergence table (CSV, one row per iteration from 0)"});
    bn_optset_add(&set, (bn_opt){"output", 'o', BN_OPT_STRING, &a.output, NULL, 0, 0, "FILE",
                                 "per-patch CSV (required)"});
    bn_cli_add_common(&set, c);
    bn_error_clear(&err);
    {
        int prc;
        if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
            return prc;
    }
    if (!a.output) {
        bn_error_set(&err, BN_EUSAGE, "solve needs -o FILE for the per-patch CSV (see --help)");
        return bn_cli_fail(&err);
    }
    with_terms = bn_cli_given(&set, "bounces");
    o.method = (bn_solve_method)a.method;
    o.tol = a.tol;
    o.atol = a.atol;
    o.max_iter = a.max_iter;
    o.bounces = with_terms ? a.bounces : 3;
    o.symmetric = a.symmetric;
    o.stop = (bn_solve_stop)a.stop;
    o.singular_threshold = a.singular_threshold;
    o.quiet = c->quiet;
    o.log_sink.fn = bn__cli_note;
    o.log_sink.user = c;
    o.log_sink.quiet = c->quiet;
    bn_cli_apply_threads(c);

    t0 = bn__now();
    st = bn_cli_load_scene(pos[0], &so, c, &s);
    if (st != BN_OK)
        return bn_status_exit_code(st);
    t_load = bn__now() - t0;
    patches = bn_scene_patches(s, &np);
    mats = bn_scene_materials(s, &nm);
    m2 = bn_unit_to_metres(bn_scene_unit(s));
    m2 *= m2;

    t0 = bn__now();
    st = bn_cli_build_ff(s, &ffo, c, &rt, &k, &diag, NULL);   /* prints its own errors */
    t_ff = bn__now() - t0;
    if (st != BN_OK) {
        rc = bn_status_exit_code(st);
        goto done;
    }
    /* Tie the singular threshold to F's accuracy: no row of F can sum above 1, so the excess is a
     * measured part of F's row-sum error delta, and 1 - ||K|| below delta leaves no accuracy. */
    if (diag.row_sum_max - 1.0 > o.singular_threshold) {
        if (!c->quiet)
            fprintf(stderr, "bounce: F's rows sum up to %.9g: singular threshold raised from %g to %.3g (F's "
                            "measured row-sum error)\n", diag.row_sum_max, o.singular_threshold, diag.row_sum_max - 1.0);
        o.singular_threshold = diag.row_sum_max - 1.0;
    }
    E = bn__malloc_array(3 * np + 1, sizeof(double));
    if (!E) {
        bn_error_set(&err, BN_ENOMEM, "out of memory for %zu patches", np);
        rc = bn_cli_fail(&err);
        goto done;
    }
    bn_scene_patch_emission(s, E);
    bn__provenance_run(prov, sizeof prov, c, s, &ffo, &diag);
    if (a.log) {
        if (bn__outfile_open(&logf, a.log, "w", &err) != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
        o.log = logf.fp;
        o.log_header = prov;
    }
    bn_error_clear(&serr);
    st = bn_solve(k, E, &o, &res, &serr);
    if (a.log && (st == BN_EINTR || st == BN_ETERM)) {
        /* an interrupted run leaves nothing behind, not even its partial log */
        bn__outfile_abort(&logf);
    } else if (a.log) {
        /* the log documents failed solves too */
        fprintf(logf.fp, "# stop_reason=%s\n", bn_stop_reason_name(res.reason));
        if (bn__outfile_commit(&logf, &err) != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
    }
    if (!c->quiet || st != BN_OK)
        fprintf(stderr, "bounce: solve: %zu patches, %s, K %s (%.3g MiB); ||K||_inf %.6g, spectral radius %.6g (>= %.6g)\n",
                np, bn_solve_method_name(o.method), bn_transport_name(k), (double)bn_transport_bytes(k) / 1048576.0,
                res.k_norm_inf, res.spectral_radius, res.spectral_radius_lower);
    if ((!c->quiet || st != BN_OK) && res.reason != BN_STOP_NONE && res.reason != BN_STOP_SINGULAR) {
        fprintf(stderr,
                "bounce: stopped: %s after %zu iteration%s (predicted %s%zu); residual max %.3g, rms %.3g "
                "(R %.3g G %.3g B %.3g); tol %g x ||E||_inf %.6g = %.3g; error bound %.3g\n",
                bn_stop_reason_name(res.reason),
                res.iterations, res.iterations == 1 ? "" : "s", res.predicted_iterations == SIZE_MAX ? "inf " : "",
                res.predicted_iterations == SIZE_MAX ? (size_t)0 : res.predicted_iterations, res.residual_max,
                res.residual_rms, res.residual_ch[0], res.residual_ch[1], res.residual_ch[2], o.tol, res.norm_E,
                o.tol * res.norm_E, res.error_bound);
    }
    if (st != BN_OK) {
        rc = bn_cli_fail(&serr);
        if (st == BN_ENOTCONV)
            fprintf(stderr, "bounce: no output written (the answer is not within the tolerance)\n");
        goto done;
    }

    t0 = bn__now();
    if (bn__outfile_open(&outf, a.output, "w", &err) != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    fputs(prov, outf.fp);
    bn__provenance_solve(outf.fp, &o, &res, k);
    fputs("patch,face,material,area,L_R,L_G,L_B", outf.fp);
    if (with_terms)
        for (int q = 0; q < res.nterms; q++) {
            char nm_[32];
            bn__term_name(q, nm_, sizeof nm_);
            fprintf(outf.fp, ",%s_R,%s_G,%s_B", nm_, nm_, nm_);
        }
    fputc('\n', outf.fp);
    for (size_t i = 0; i < np; i++) {
        fprintf(outf.fp, "%zu,%zu,", i, patches[i].face);
        bn__csv_str(outf.fp, patches[i].material < nm ? mats[patches[i].material].name : "?");
        fprintf(outf.fp, ",%.10g,%.9g,%.9g,%.9g", patches[i].area * m2, res.L[3 * i], res.L[3 * i + 1], res.L[3 * i + 2]);
        if (with_terms)
            for (int q = 0; q < res.nterms; q++)
                fprintf(outf.fp, ",%.9g,%.9g,%.9g", res.terms[q][3 * i], res.terms[q][3 * i + 1], res.terms[q][3 * i + 2]);
        fputc('\n', outf.fp);
    }
    if (bn__outfile_commit(&outf, &err) != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    t_out = bn__now() - t0;
    if (!c->quiet)
        fprintf(stderr,
                "bounce: time: load+mesh %.3f s, form factors %.3f s, solve %.3f s (analysis %.3f, %s %.3f, bounce "
                "terms %.3f), output %.3f s\nbounce: wrote %s (%zu patches%s)\n",
                t_load, t_ff, res.seconds, res.seconds_analyse, o.method == BN_SOLVE_DIRECT ? "factorisation" : "iterations",
                res.seconds_iterate, res.seconds_terms, t_out, a.output, np, with_terms ? ", with bounce terms" : "");
done:
    if (logf.fp)
        bn__outfile_abort(&logf);
    if (outf.fp)
        bn__outfile_abort(&outf);
    bn_solve_result_free(&res);
    bn_transport_destroy(k);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
    free(E);
    return rc;
}
