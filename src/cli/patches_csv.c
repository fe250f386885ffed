/* The per-patch CSV of `bounce solve -o` and `bounce bounces --patches-out`: the run's provenance as
 * `# key=value` lines, then one row per patch with L and (with terms) E, KE, K2E, ... */
#include "cli/cli.h"
#include "base/internal.h"

#include <string.h>

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
void bn_cli_provenance_run(char *buf, size_t n, const bn_cli_common *c, const bn_pipeline_opts *po,
                               const bn_pipeline *p)
{
    const bn_scene *s = p->scene;
    const bn_ff_diagnostics *d = &p->ff;
    snprintf(buf, n,
             "# command=%s\n# scene=%s\n# unit=%s\n# seed=%llu\n# threads=%d\n# ff_method=%s\n"
             "# ff_row_sum_min=%.9g\n# ff_row_sum_max=%.9g\n# ff_reciprocity_residual=%.3g\n# ff_seconds=%.3f\n",
             c->cmdline ? c->cmdline : "bounce solve", bn_scene_path(s), bn_unit_name(bn_scene_unit(s)),
             (unsigned long long)c->seed, bn_threads_resolve(c->threads), bn_ff_method_name(po->ff.method), d->row_sum_min,
             d->row_sum_max, d->reciprocity_residual, d->seconds);
    if (p->hierarchical) {
        size_t len = strlen(buf);
        const bn_hierarchy_report *h = &p->hier;
        snprintf(buf + len, n > len ? n - len : 0,
                 "# hierarchy_eps=%.9g\n# hierarchy_eps_abs=%.9g\n# hierarchy_clusters=%d\n# hierarchy_nodes=%zu\n"
                 "# hierarchy_links=%zu\n# hierarchy_leaf_links=%zu\n# hierarchy_cluster_links=%zu\n"
                 "# hierarchy_passes=%zu\n# hierarchy_settled=%d\n# hierarchy_rays=%zu\n# hierarchy_bytes=%zu\n"
                 "# hierarchy_seconds=%.3f\n# hierarchy_polygons=%zu\n# hierarchy_planes=%zu\n"
                 "# hierarchy_min_area=%.9g\n# hierarchy_peak_link_bytes=%zu\n",
                 po->hier.eps, h->eps_abs, po->hier.clusters, h->nodes, h->links, h->leaf_links, h->cluster_links,
                 h->passes, h->settled, h->rays, h->bytes, h->seconds_tree + h->seconds_refine, h->polygons,
                 h->planes, h->min_area, h->peak_link_bytes);
    }
}

static void bn__provenance_solve(FILE *fp, const bn_solve_opts *o, const bn_pipeline *p)
{
    const bn_solve_result *res = &p->res;
    fprintf(fp,
            "# version=%s\n# patches=%zu\n# method=%s%s\n# tol=%.9g\n# atol=%.9g\n# max_iter=%zu\n# stop=%s\n"
            "# bounces=%d\n# singular_threshold=%.3g\n# transport=%s\n# radiance_unit=W m^-2 sr^-1\n# area_unit=m^2\n"
            "# stop_reason=%s\n# iterations=%zu\n# residual_max=%.9g\n# error_bound=%.9g\n# k_norm_inf=%.9g\n"
            "# spectral_radius=%.9g\n",
            bn_version(), res->n, bn_solve_method_name(o->method),
            o->symmetric && o->method == BN_SOLVE_GAUSS_SEIDEL ? "-symmetric" : "", o->tol, o->atol, o->max_iter,
            bn_solve_stop_name(o->stop), o->bounces, p->singular_threshold, bn_transport_name(p->k),
            bn_stop_reason_name(res->reason), res->iterations, res->residual_max, res->error_bound, res->k_norm_inf,
            res->spectral_radius);
}

/* The per-patch CSV: provenance, then one row per patch with L (and the terms with -n). */
bn_status bn_cli_patches_csv_write(const char *path, const char *prov, const bn_solve_opts *o, const bn_pipeline *p,
                                  int with_terms, bn_error *err)
{
    bn__outfile f;
    size_t nm;
    const bn_patch *patches = bn_scene_patches(p->scene, &nm);
    const bn_material *mats = bn_scene_materials(p->scene, &nm);
    const bn_solve_result *res = &p->res;
    double m2 = bn_unit_to_metres(bn_scene_unit(p->scene));
    bn_status st = bn__outfile_open(&f, path, "w", err);
    if (st != BN_OK)
        return st;
    m2 *= m2;
    fputs(prov, f.fp);
    bn__provenance_solve(f.fp, o, p);
    fputs("patch,face,material,area,L_R,L_G,L_B", f.fp);
    if (with_terms)
        for (int q = 0; q < res->nterms; q++) {
            char nm_[32];
            bn_term_name(q, nm_, sizeof nm_);
            fprintf(f.fp, ",%s_R,%s_G,%s_B", nm_, nm_, nm_);
        }
    fputc('\n', f.fp);
    for (size_t i = 0; i < p->n; i++) {
        fprintf(f.fp, "%zu,%zu,", i, patches[i].face);
        bn__csv_str(f.fp, patches[i].material < nm ? mats[patches[i].material].name : "?");
        fprintf(f.fp, ",%.10g,%.9g,%.9g,%.9g", patches[i].area * m2, res->L[3 * i], res->L[3 * i + 1],
                res->L[3 * i + 2]);
        if (with_terms)
            for (int q = 0; q < res->nterms; q++)
                fprintf(f.fp, ",%.9g,%.9g,%.9g", res->terms[q][3 * i], res->terms[q][3 * i + 1],
                        res->terms[q][3 * i + 2]);
        fputc('\n', f.fp);
    }
    return bn__outfile_commit(&f, err);
}

