/* `bounce solve SCENE -o patches.csv`: mesh, form factors, then (I - K) L = E by the chosen method;
 * one CSV row per patch (L and, with -n, the bounce terms E, KE, K2E, ...), the convergence log
 * with --log, a summary on stderr. */
#include "cli/cli.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

/* The solve command's own options, beside the shared groups. */
typedef struct bn__solve_cli {
    bn_optset set;
    bn_cli_scene so;
    bn_cli_ff ffo;
    const char *method;
    int stop, symmetric, bounces, with_terms;
    double tol, atol, singular_threshold;
    size_t max_iter;
    const char *log, *output, *scene;
} bn__solve_cli;

/* Parses argv into *a; returns 1 to go on, or 0 with *rc the exit code. */
static int bn__solve_parse(int argc, char **argv, bn_cli_common *c, bn__solve_cli *a, int *rc)
{
    bn_optset *set = &a->set;
    bn_solve_opts d;
    const char *pos[1];
    bn_error err;
    bn_solve_opts_default(&d);
    a->method = NULL;   /* auto */
    a->tol = d.tol;
    a->atol = d.atol;
    a->max_iter = d.max_iter;
    a->bounces = d.bounces;
    a->singular_threshold = d.singular_threshold;
    set->usage = "bounce solve SCENE [meshing options] [--method M] [--tol T] [--atol A] [--max-iter N] [--bounces N]\n"
                 "                    [--symmetric] [--log conv.csv] -o patches.csv";
    set->summary =
        "Meshes SCENE into patches, computes the form factors F and solves (I - K) L = E per channel,\n"
        "K = diag(rho) F, for the outgoing radiance L of every patch (W m^-2 sr^-1). Writes one CSV row\n"
        "per patch: patch,face,material,area (m^2),L_R,L_G,L_B, and with -n N the bounce terms\n"
        "E, KE, K2E, ... K^N E (bounce k = light that reflected k times). The iterative methods stop when\n"
        "||E - (I - K) L||_inf <= tol ||E||_inf (or atol); neumann stops when its tail bound\n"
        "||K^(n+1) E|| / (1 - ||K||) is below it. Before iterating, ||K||_inf and the spectral radius\n"
        "(power iteration) are reported with the predicted iteration count, and a (near-)singular\n"
        "system (a closed scene with reflectance 1) is refused with exit code 5.";
    bn_cli_add_scene(set, &a->so);
    bn_cli_add_ff(set, &a->ffo);
    bn_optset_add(set, (bn_opt){"method", 'm', BN_OPT_NAME, &a->method,
                                bn_cli_auto_or(bn_solve_method_names()), 0, 0, "M",
                                "jacobi, gauss-seidel, neumann (series) or direct (LAPACK); auto (default): "
                                "gauss-seidel, or jacobi where K has no rows (the hierarchy)"});
    bn_optset_add(set, (bn_opt){"tol", 0, BN_OPT_DOUBLE, &a->tol, NULL, 0, 1, "T",
                                "stop when ||r||_inf <= T ||E||_inf (default 1e-6)"});
    bn_optset_add(set, (bn_opt){"atol", 0, BN_OPT_DOUBLE, &a->atol, NULL, 0, 1e300, "A",
                                "or when ||r||_inf <= A, W m^-2 sr^-1 (default 0: off)"});
    bn_optset_add(set, (bn_opt){"max-iter", 0, BN_OPT_SIZE, &a->max_iter, NULL, 0, 1e15, "N",
                                "iteration limit; reaching it exits with 5 (default 100000)"});
    bn_optset_add(set, (bn_opt){"bounces", 'n', BN_OPT_INT, &a->bounces, NULL, 0, 10000, "N",
                                "write the terms K^0 E .. K^N E as columns (default: none; 3 kept internally)"});
    bn_optset_add(set, (bn_opt){"symmetric", 0, BN_OPT_FLAG, &a->symmetric, NULL, 0, 0, NULL,
                                "gauss-seidel: a forward then a backward sweep per iteration"});
    bn_optset_add(set, (bn_opt){"stop", 0, BN_OPT_CHOICE, &a->stop, bn_solve_stop_names(), 0, 0, "S",
                                "what tol bounds: residual, the error bound ||r||/(1-||K||), or patch: every patch's "
                                "residual relative to its own radiance, for lights orders of magnitude apart (default: "
                                "bound for neumann, residual otherwise)"});
    bn_optset_add(set, (bn_opt){"singular-threshold", 0, BN_OPT_DOUBLE, &a->singular_threshold, NULL, 0, 0.5, "D",
                                "refuse when rho(K) >= 1 - D; set D to F's row-sum error (default 1e-6)"});
    bn_optset_add(set, (bn_opt){"log", 0, BN_OPT_STRING, &a->log, NULL, 0, 0, "FILE",
                                "convergence table (CSV, one row per iteration from 0)"});
    bn_optset_add(set, (bn_opt){"output", 'o', BN_OPT_STRING, &a->output, NULL, 0, 0, "FILE",
                                "per-patch CSV (required)"});
    bn_cli_add_common(set, c);
    if (!bn_cli_parse_scene_command(set, argc, argv, pos, rc))
        return 0;
    a->scene = pos[0];
    if (!a->output) {
        bn_error_set(&err, BN_EUSAGE, "solve needs -o FILE for the per-patch CSV (see --help)");
        *rc = bn_cli_fail(&err);
        return 0;
    }
    a->with_terms = bn_cli_given(set, "bounces");
    return 1;
}

static void bn__solve_opts(const bn__solve_cli *a, const bn_cli_common *c, bn_pipeline_opts *po)
{
    bn_solve_opts *o = &po->solve;
    bn_cli_pipeline_opts(&a->so, &a->ffo, NULL, c, po);
    bn_cli_method(a->method, &o->method, &po->method_auto);
    o->tol = a->tol;
    o->atol = a->atol;
    o->max_iter = a->max_iter;
    o->bounces = a->with_terms ? a->bounces : 3;
    o->symmetric = a->symmetric;
    o->stop = (bn_solve_stop)a->stop;
    o->singular_threshold = a->singular_threshold;
}

/* The solve, with its convergence table in an atomic file when --log is given: a failed solve's
 * log is kept (it documents the failure), an interrupted one's is dropped. */
static bn_status bn__solve_logged(const bn__solve_cli *a, bn_pipeline_opts *po, bn_pipeline *p, const char *prov,
                                  bn_error *err)
{
    bn__outfile logf;
    bn_status st;
    memset(&logf, 0, sizeof logf);
    if (a->log) {
        st = bn__outfile_open(&logf, a->log, "w", err);
        if (st != BN_OK)
            return st;
        po->solve.log = logf.fp;
        po->solve.log_header = prov;
    }
    st = bn_pipeline_solve(po, p, err);
    po->solve.log = NULL;
    if (!a->log)
        return st;
    if (st == BN_EINTR || st == BN_ETERM) {
        bn__outfile_abort(&logf);
        return st;
    }
    fprintf(logf.fp, "# stop_reason=%s\n", bn_stop_reason_name(p->res.reason));
    {
        bn_error lerr;
        if (bn__outfile_commit(&logf, &lerr) != BN_OK) {
            if (st == BN_OK)
                *err = lerr;
            return st == BN_OK ? lerr.status : st;
        }
    }
    return st;
}

/* The summary on stderr: always on failure, else unless --quiet. */
static void bn__solve_report(const bn_pipeline_opts *po, const bn_pipeline *p, bn_status st, int quiet)
{
    const bn_solve_result *res = &p->res;
    const bn_solve_opts *o = &po->solve;
    if (quiet && st == BN_OK)
        return;
    fprintf(stderr, "bounce: solve: %zu patches, %s, K %s (%.3g MiB); ||K||_inf %.6g, spectral radius %.6g (>= %.6g)\n",
            p->n, bn_solve_method_name(p->res.L ? p->method_used : o->method), bn_transport_name(p->k),
            (double)bn_transport_bytes(p->k) / 1048576.0, res->k_norm_inf, res->spectral_radius,
            res->spectral_radius_lower);
    if (res->reason != BN_STOP_NONE && res->reason != BN_STOP_SINGULAR)
        fprintf(stderr,
                "bounce: stopped: %s after %zu iteration%s (predicted %s%zu); residual max %.3g, rms %.3g "
                "(R %.3g G %.3g B %.3g); tol %g x ||E||_inf %.6g = %.3g; error bound %.3g\n",
                bn_stop_reason_name(res->reason), res->iterations, res->iterations == 1 ? "" : "s",
                res->predicted_iterations == SIZE_MAX ? "inf " : "",
                res->predicted_iterations == SIZE_MAX ? (size_t)0 : res->predicted_iterations, res->residual_max,
                res->residual_rms, res->residual_ch[0], res->residual_ch[1], res->residual_ch[2], o->tol, res->norm_E,
                o->tol * res->norm_E, res->error_bound);
}

int bn_cmd_solve(int argc, char **argv, bn_cli_common *c)
{
    bn__solve_cli a;
    bn_pipeline_opts po;
    bn_pipeline p;
    bn_error err;
    bn_status st;
    char prov[4096];
    double t_out;
    int rc = 0;

    memset(&a, 0, sizeof a);
    memset(&p, 0, sizeof p);
    if (!bn__solve_parse(argc, argv, c, &a, &rc))
        return rc;
    bn__solve_opts(&a, c, &po);
    bn_error_clear(&err);
    st = bn_pipeline_scene(a.scene, &po, &p, &err);
    if (st == BN_OK)
        st = bn_pipeline_operator(&po, &p, &err);
    if (st == BN_OK) {
        po.solve.method = bn_pipeline_method(&po, &p);   /* what runs, for the provenance */
        bn_cli_provenance_run(prov, sizeof prov, c, &po, &p);
        st = bn__solve_logged(&a, &po, &p, prov, &err);
        bn__solve_report(&po, &p, st, c->quiet);
    }
    if (st != BN_OK) {
        rc = bn_cli_fail(&err);
        if (st == BN_ENOTCONV)
            fprintf(stderr, "bounce: no output written (the answer is not within the tolerance)\n");
        bn_pipeline_free(&p);
        return rc;
    }
    t_out = bn__now();
    st = bn_cli_patches_csv_write(a.output, prov, &po.solve, &p, a.with_terms, &err);
    t_out = bn__now() - t_out;
    if (st != BN_OK)
        rc = bn_cli_fail(&err);
    else if (!c->quiet)
        fprintf(stderr,
                "bounce: time: load+mesh %.3f s, form factors %.3f s, solve %.3f s (analysis %.3f, %s %.3f, bounce "
                "terms %.3f), output %.3f s\nbounce: wrote %s (%zu patches%s)\n",
                p.seconds_load + p.seconds_mesh, p.seconds_operator, p.res.seconds, p.res.seconds_analyse,
                po.solve.method == BN_SOLVE_DIRECT ? "factorisation" : "iterations", p.res.seconds_iterate,
                p.res.seconds_terms, t_out, a.output, p.n, a.with_terms ? ", with bounce terms" : "");
    bn_pipeline_free(&p);
    return rc;
}
