/* The cross-check run (include/bounce/pipeline.h): radiosity at the mesh asked, the path tracer on
 * the same patches, the allowances (a second mesh level, the hierarchy's eps level), the comparison. */
#include "bounce/pipeline.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <string.h>

/* The allowances in enum order (bn_disc). */
#define BN__DISCS(X) X("auto") X("coarse") X("fine") X("none")
BN__VOCABULARY(bn_disc, bn_disc, BN__DISCS)

void bn_crosscheck_opts_default(bn_crosscheck_opts *o)
{
    memset(o, 0, sizeof *o);
    bn_pipeline_opts_default(&o->pipeline);
    bn_trace_opts_default(&o->trace);
    o->trace.spp = 1024;
    o->trace.model = BN_TRACE_PATCH;
    o->bounces = 3;
    o->solve_tol = 1e-10;
    o->disc = BN_DISC_AUTO;
    o->ratio = 2;
    o->tol_scale = 3;
    o->alpha = 0.01;
    o->worst = 10;
    o->regions_above = BN_CROSSCHECK_REGIONS_ABOVE;
}

/* The reporting partition of scene s that run->regioned says (1: about opts.regions regions; 2:
 * per object and material). */
static bn_status bn__partition(const bn_crosscheck_opts *o, const bn_crosscheck_run *run, const bn_scene *s,
                               bn_partition *part, bn_error *err)
{
    return run->regioned == 1 ? bn_partition_regions(s, o->regions, part, err)
                              : bn_partition_objects(s, BN_PARTITION_OWN_SHARE, part, err);
}

/* One level: the pipeline with mesh m (the rays kept), and its layers in the tracer's layout. */
static bn_status bn__level(const char *path, const bn_crosscheck_opts *o, const bn_mesh_opts *m, bn_pipeline *p,
                           double **layers, double *seconds, bn_error *err)
{
    bn_pipeline_opts po = o->pipeline;
    double t0 = bn__now();
    bn_status st;
    po.mesh = *m;
    if (m != &o->pipeline.mesh)
        po.mesh_auto = 0;   /* the second level: the patch size asked, not the hierarchy's default mesh */
    po.keep_rt = 1;
    po.solve.tol = o->solve_tol;
    po.solve.bounces = o->bounces;
    st = bn_pipeline_run(path, &po, p, err);
    if (st != BN_OK)
        return st;
    *layers = bn__malloc_array(p->n * (size_t)bn_layer_count(o->bounces), 3 * sizeof(double));
    if (!*layers)
        return bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory for %zu patches", p->n);
    bn_layers_stack((const double *const *)p->res.terms, p->res.L, p->n, o->bounces, *layers);
    *seconds = bn__now() - t0;
    return BN_OK;
}

/* The second level's mesh: the patch size of the first times or over the ratio. */
static bn_status bn__second_mesh(const bn_crosscheck_opts *o, const bn_pipeline *fine, bn_mesh_opts *m, bn_error *err)
{
    double h = bn_scene_patch_size(fine->scene);
    *m = o->pipeline.mesh;
    m->target_patches = 0;
    m->no_subdivide = 0;
    m->patch_size = h > 0 ? (o->disc == BN_DISC_FINE ? h / o->ratio : h * o->ratio) : 0;
    if (!(m->patch_size > 0) || o->pipeline.mesh.no_subdivide)
        return bn_error_set(err, BN_EUSAGE, "crosscheck: `no_subdivide` has no patch size to vary; use `disc` none or "
                                            "`patch_size`");
    return BN_OK;
}

/* The discretisation tolerance between the fine level and another (scene2, layers2), per patch (or
 * region) and per layer's power, added to run->tol and run->power_tol (allocated, zero, at the
 * first call): each discretisation parameter's own estimate, so that two errors of opposite sign
 * cannot hide each other. */
static bn_status bn__tolerance(const bn_crosscheck_opts *o, bn_crosscheck_run *run, const bn_scene *scene2,
                               const double *layers2, bn_error *err)
{
    size_t nl = (size_t)bn_layer_count(o->bounces), n = run->regioned ? run->part.n : run->fine.n;
    double *tol = bn__malloc_array(n * nl, 3 * sizeof(double)), *ptol = bn__malloc_array(nl, 3 * sizeof(double));
    bn_status st = BN_OK;
    if (!run->tol) {
        run->tol = bn__calloc(n * nl, 3 * sizeof(double));
        run->power_tol = bn__calloc(nl, 3 * sizeof(double));
    }
    if (!tol || !ptol || !run->tol || !run->power_tol) {
        free(tol);
        free(ptol);
        return bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory");
    }
    if (!run->regioned) {
        st = bn_crosscheck_mesh_tolerance(run->fine.scene, run->layers_fine, scene2, layers2, o->bounces, tol, ptol,
                                          err);
    } else {   /* regions are whole polygons, so both levels have the same ones: compare their means */
        bn_partition q;
        double m = bn_unit_to_metres(bn_scene_unit(run->fine.scene)), *b = NULL;
        st = bn__partition(o, run, scene2, &q, err);
        if (st == BN_OK) {
            b = bn__malloc_array(n * nl, 3 * sizeof(double));
            if (!b || q.n != n)
                st = b ? bn_error_set(err, BN_EINTERNAL, "crosscheck: the levels have %zu and %zu regions", n, q.n)
                       : bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory");
        }
        if (st == BN_OK) {
            bn_partition_mean(&q, scene2, layers2, (int)nl, b);
            for (size_t l = 0; l < nl; l++)
                for (int c = 0; c < 3; c++) {
                    double pa = 0, pb = 0;
                    for (size_t g = 0; g < n; g++) {
                        size_t k = (l * n + g) * 3 + (size_t)c;
                        tol[k] = fabs(run->rad_regions[k] - b[k]);
                        pa += run->part.area[g] * run->rad_regions[k];
                        pb += q.area[g] * b[k];
                    }
                    ptol[3 * l + (size_t)c] = BN_PI * m * m * fabs(pa - pb);
                }
            bn_partition_free(&q);
        }
        free(b);
    }
    if (st == BN_OK) {
        for (size_t k = 0; k < n * nl * 3; k++)
            run->tol[k] += tol[k];
        for (size_t k = 0; k < nl * 3; k++)
            run->power_tol[k] += ptol[k];
    }
    free(tol);
    free(ptol);
    return st;
}

/* Which allowances a run makes (bn_crosscheck_opts.disc): the second mesh level, the eps level. */
static int bn__mesh_level(const bn_crosscheck_opts *o)
{
    return o->disc == BN_DISC_COARSE || o->disc == BN_DISC_FINE ||
           (o->disc == BN_DISC_AUTO && o->trace.model == BN_TRACE_CONTINUOUS);
}

static int bn__eps_level(const bn_crosscheck_opts *o, const bn_crosscheck_run *run)
{
    return o->disc != BN_DISC_NONE && run->fine.hierarchical && o->pipeline.hier.eps > 0;
}

/* The allowances, each level's |difference| added to run->tol and run->power_tol. */
static bn_status bn__allowances(const char *path, const bn_crosscheck_opts *o, bn_crosscheck_run *run, bn_error *err)
{
    bn_crosscheck_opts o2 = *o;
    bn_mesh_opts m2;
    bn_status st = BN_OK;
    o2.pipeline.ff.cache_path = NULL;   /* the cache holds the mesh asked for */
    if (bn__mesh_level(o)) {
        st = bn__second_mesh(o, &run->fine, &m2, err);
        if (st == BN_OK)
            st = bn__level(path, &o2, &m2, &run->other, &run->layers_other, &run->seconds_other, err);
        if (st == BN_OK)
            st = bn__tolerance(o, run, run->other.scene, run->layers_other, err);
    }
    if (st == BN_OK && bn__eps_level(o, run)) {
        /* the hierarchy's other discretisation parameter on the mesh asked: eps x r^2 (its error
         * falls about as sqrt(eps) on the Cornell box, so as h, and one order fits both). Coarsened
         * together with the mesh, the two errors cancelled at the bunny box's base (the regions'
         * values there move one way with eps and the other with h): each counts on its own. */
        double r2 = o->ratio * o->ratio, *layers = NULL;
        o2.pipeline.hier.eps = o->disc == BN_DISC_FINE ? o->pipeline.hier.eps / r2 : o->pipeline.hier.eps * r2;
        st = bn__level(path, &o2, &o2.pipeline.mesh, &run->other_eps, &layers, &run->seconds_other_eps, err);
        if (st == BN_OK)
            st = bn__tolerance(o, run, run->other_eps.scene, layers, err);
        free(layers);
    }
    return st;
}

bn_status bn_crosscheck_run_scene(const char *path, const bn_crosscheck_opts *o, bn_crosscheck_run *run,
                                  bn_error *err)
{
    bn_trace_opts to = o->trace;
    bn_crosscheck_input *in = &run->in;
    bn_status st;
    memset(run, 0, sizeof *run);
    to.bounces = o->bounces;
    st = bn__level(path, o, &o->pipeline.mesh, &run->fine, &run->layers_fine, &run->seconds_fine, err);
    run->regioned = o->regions ? 1 : o->regions_above && run->fine.n > o->regions_above ? 2 : 0;
    if (st == BN_OK && run->regioned) {
        size_t nl = (size_t)bn_layer_count(o->bounces);
        st = bn__partition(o, run, run->fine.scene, &run->part, err);
        if (st == BN_OK && !(run->rad_regions = bn__malloc_array(run->part.n * nl, 3 * sizeof(double))))
            st = bn_error_set(err, BN_ENOMEM, "crosscheck: out of memory");
        if (st == BN_OK) {
            bn_partition_mean(&run->part, run->fine.scene, run->layers_fine, (int)nl, run->rad_regions);
            st = bn_trace_regions_run(run->fine.rt, &run->part, &to, &run->trace, err);
        }
    } else if (st == BN_OK)
        st = bn_trace_patches_run(run->fine.rt, &to, &run->trace, err);
    if (st == BN_OK)
        st = bn__allowances(path, o, run, err);
    if (st != BN_OK)
        return st;
    bn_crosscheck_input_default(in);
    in->scene = run->fine.scene;
    in->trace = &run->trace;
    in->rad = run->regioned ? run->rad_regions : run->layers_fine;
    in->part = run->regioned ? &run->part : NULL;
    in->tol = run->tol;
    in->power_tol = run->power_tol;
    /* Two-level grid-convergence estimate with order p = 1 (patch-constant radiosity): the error of
     * the mesh asked is |R_h - R_other| / (r - 1) when the other level is coarser by r, and
     * r |R_h - R_other| / (r - 1) when it is finer; times the safety factor Fs. */
    in->tol_scale = !run->tol ? 0
                              : o->tol_scale * (o->disc == BN_DISC_FINE ? o->ratio / (o->ratio - 1) : 1 / (o->ratio - 1));
    in->rtol = o->rtol;
    in->alpha = o->alpha;
    in->worst = o->worst;
    return bn_crosscheck_compare(in, &run->result, err);
}

void bn_crosscheck_run_free(bn_crosscheck_run *run)
{
    bn_crosscheck_result_free(&run->result);
    bn_trace_patches_free(&run->trace);
    free(run->tol);
    free(run->power_tol);
    free(run->layers_fine);
    free(run->layers_other);
    free(run->rad_regions);
    bn_partition_free(&run->part);
    bn_pipeline_free(&run->fine);
    bn_pipeline_free(&run->other);
    bn_pipeline_free(&run->other_eps);
    memset(run, 0, sizeof *run);
}
