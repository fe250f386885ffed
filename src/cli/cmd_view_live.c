/* `bounce view --live SCENE -o page.html`: the viewer page that relights the scene in the browser
 * (bn_pipeline_live_write): solved once here, F embedded within --budget; above it the page is built
 * coarser (the hierarchy at a larger eps, dense and sparse F on fewer patches) and says so. */
#include "cli/cli.h"
#include "base/internal.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

typedef struct bn__live_cli {
    bn_optset set;
    bn_cli_scene so;
    bn_cli_ff ff;
    bn_cli_solution sol;
    int bounces, live;
    double budget_mb;
    const char *out;
} bn__live_cli;

static int bn__live_parse(int argc, char **argv, bn_cli_common *c, bn__live_cli *a, const char **scene, int *rc)
{
    bn_optset *set = &a->set;
    a->bounces = 5;
    a->budget_mb = BN_LIVE_DEFAULT_BUDGET_MB;
    a->out = "view.html";
    set->usage = "bounce view --live SCENE [-o page.html] [--budget MB] [--bounces N] [scene, form-factor and solver "
                 "options]";
    set->summary =
        "Writes one self-contained HTML page that relights SCENE in the browser: F (the form factors, dense,\n"
        "sparse or the hierarchy's links) is computed here once and embedded; the page's Web Worker sums\n"
        "E + KE + K^2E + ... itself whenever a slider moves: each emitting material's Le (intensity and colour),\n"
        "each material's rho, the punctual lights' intensity, and the bounce count (the truncated series\n"
        "E, E+KE, ...). Patches are drawn flat (their own values; bounce bake's gathered vertices are not a\n"
        "function of the sliders). Above --budget the page is built coarser and says so: the hierarchy at\n"
        "a larger eps, dense and sparse F on fewer patches. The URL holds the sliders' state\n"
        "(#rho.NAME=r,g,b&Le.NAME=r,g,b&punctual=s&shown=b) besides the viewer's own keys.";
    bn_cli_add_scene(set, &a->so);
    bn_cli_add_ff(set, &a->ff);
    bn_cli_add_solution(set, &a->sol);
    bn_optset_add(set, (bn_opt){"live", 0, BN_OPT_FLAG, &a->live, NULL, 0, 0, NULL, "the live page (this command)"});
    bn_optset_add(set, (bn_opt){"budget", 0, BN_OPT_DOUBLE, &a->budget_mb, NULL, 0.01, 1e6, "MB",
                                "the page's data for F and the patches, MiB (default 64; the page is 4/3 of it)"});
    bn_optset_add(set, (bn_opt){"bounces", 'n', BN_OPT_INT, &a->bounces, NULL, 0, 64, "N",
                                "terms E .. K^N E shown one by one, then rest (default 5)"});
    bn_optset_add(set, (bn_opt){"output", 'o', BN_OPT_STRING, &a->out, NULL, 0, 0, "FILE.html",
                                "the page (default view.html)"});
    bn_cli_add_common(set, c);
    if (!bn_cli_parse_scene_command(set, argc, argv, scene, rc))
        return 0;
    size_t n = strlen(a->out);
    if (n < 5 || strcasecmp(a->out + n - 5, ".html") != 0) {
        fprintf(stderr, "bounce: error: -o %s: the page is written as .html\n", a->out);
        *rc = 2;
        return 0;
    }
    return 1;
}

/* Coarser options after a page of `bytes` over `budget`: the hierarchy's eps times the excess^2.5, at
 * least 2 (the bunny box's links fell as eps^-0.4: the patches' own links to their neighbours stay),
 * else the patches cut by the square root of the excess (F's entries go as N^2). Returns the line the
 * page and the summary say. */
static void bn__live_coarser(bn_pipeline_opts *po, const bn_pipeline *p, size_t bytes, size_t budget, char *why,
                             size_t n)
{
    if (p->hierarchical) {
        double eps = po->hier.eps;
        po->hier.eps = eps * fmin(16, fmax(2, pow((double)bytes / (double)budget, 2.5)));
        snprintf(why, n, "F at eps %g needs %.1f MiB, over the budget %.3g MiB: built at eps %g", eps,
                 (double)bytes / 1048576, (double)budget / 1048576, po->hier.eps);
    } else {
        size_t was = p->n;
        po->mesh.patch_size = 0;
        po->mesh.target_patches = (size_t)(0.9 * (double)p->n * sqrt((double)budget / (double)bytes));
        if (po->mesh.target_patches < 16)
            po->mesh.target_patches = 16;
        snprintf(why, n, "F on %zu patches needs %.1f MiB, over the budget %.3g MiB: built on about %zu patches", was,
                 (double)bytes / 1048576, (double)budget / 1048576, po->mesh.target_patches);
    }
}

/* The pipeline within the budget: at most 8 tries, each coarser. */
static bn_status bn__live_solve(const char *scene, bn_pipeline_opts *po, size_t budget, bn_pipeline *p, char *note,
                                size_t nnote, size_t *bytes, bn_error *err)
{
    bn_status st = BN_OK;
    note[0] = '\0';
    for (int attempt = 0; attempt < 8; attempt++) {
        char why[256];
        memset(p, 0, sizeof *p);
        if ((st = bn_pipeline_run(scene, po, p, err)) != BN_OK || (st = bn_pipeline_live_bytes(p, bytes, err)) != BN_OK)
            return st;
        if (*bytes <= budget) {
            if (note[0] && p->hierarchical)   /* the first excess, then what was built */
                snprintf(note + strlen(note), nnote - strlen(note), "; built at eps %g: %.1f MiB (bounce view --budget)",
                         po->hier.eps, (double)*bytes / 1048576);
            else if (note[0])
                snprintf(note + strlen(note), nnote - strlen(note), "; built on %zu patches: %.1f MiB (bounce view "
                         "--budget)", p->n, (double)*bytes / 1048576);
            return BN_OK;
        }
        bn__live_coarser(po, p, *bytes, budget, why, sizeof why);
        fprintf(stderr, "bounce: view: %s\n", why);
        if (!note[0])
            snprintf(note, nnote, "%.*s", (int)(strchr(why, ':') - why), why);
        bn_pipeline_free(p);
        memset(p, 0, sizeof *p);
    }
    return bn_error_set(err, BN_ENOMEM, "the live page stays over --budget %.3g MiB after 8 coarser tries: %s",
                        (double)budget / 1048576, note);
}

int bn_cmd_view_live(int argc, char **argv, bn_cli_common *c)
{
    bn__live_cli a;
    const char *pos[1];
    bn_pipeline_opts po;
    bn_pipeline p;
    bn_live_opts lo;
    bn_error err;
    char note[512], solver[256], patches[64], bud[64];
    size_t bytes = 0, budget;
    int rc = 0;
    memset(&a, 0, sizeof a);
    memset(&p, 0, sizeof p);
    bn_error_clear(&err);
    if (!bn__live_parse(argc, argv, c, &a, pos, &rc))
        return rc;
    budget = (size_t)(a.budget_mb * 1048576.0);
    bn_cli_pipeline_opts(&a.so, &a.ff, &a.sol, c, &po);
    po.solve.bounces = a.bounces;
    bn_status st = bn__live_solve(pos[0], &po, budget, &p, note, sizeof note, &bytes, &err);
    if (st == BN_OK) {
        const char *title = strrchr(pos[0], '/') ? strrchr(pos[0], '/') + 1 : pos[0];
        bn_pipeline_describe_solve(&po, &p, solver, sizeof solver);
        snprintf(patches, sizeof patches, "%zu", p.n);
        snprintf(bud, sizeof bud, "%.1f of %.0f MiB", (double)bytes / 1048576, a.budget_mb);
        bn_attr attrs[] = {{"command line", c->cmdline}, {"version", bn_version()},
                           {"scene", bn_scene_path(p.scene)}, {"solver", solver},
                           {"transport", bn_transport_name(p.k)}, {"patches", patches}, {"data", bud}};
        bn_live_opts_default(&lo);
        lo.bounces = a.bounces;
        lo.note = note;
        lo.attrs = attrs;
        lo.nattrs = sizeof attrs / sizeof *attrs;
        st = bn_pipeline_live_write(&p, &lo, title, a.out, &err);
    }
    if (st != BN_OK)
        rc = err.status != BN_OK ? bn_cli_fail(&err) : bn_status_exit_code(st);
    else if (!c->quiet)
        printf("wrote %s (open it in a browser; %zu patches, %s, %.1f MiB of data%s%s)\n", a.out, p.n,
               bn_transport_name(p.k), (double)bytes / 1048576, note[0] ? "; " : "", note);
    bn_pipeline_free(&p);
    return rc == 0 && bn_interrupted() != BN_OK ? bn_cli_interrupted() : rc;
}
