/* The stages from a scene file to a solved result (include/bounce/pipeline.h): load and mesh;
 * ray scene and K; E, solve, terms and rest. Each stage is timed; nothing here knows how K is
 * stored. */
#include "bounce/pipeline.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

void bn_pipeline_opts_default(bn_pipeline_opts *o)
{
    memset(o, 0, sizeof *o);
    bn_load_opts_default(&o->load);
    bn_mesh_opts_default(&o->mesh);
    bn_formfactor_opts_default(&o->ff);
    bn_solve_opts_default(&o->solve);
    o->tie_threshold = 1;
    o->auto_precision = 1;
}

/* Float storage rounds each F_ij by 2^-24; the solve amplifies that by up to 1 / (1 - rho_max)
 * (rho_max the largest reflectance): above the requested tolerance, F is kept in double. */
static bn_precision bn__precision_by_need(const bn_pipeline_opts *o, const bn_scene *s, double *amplified)
{
    size_t nm;
    const bn_material *m = bn_scene_materials(s, &nm);
    double rho = 0;
    for (size_t k = 0; k < nm; k++)
        for (int c = 0; c < 3; c++)
            rho = fmax(rho, m[k].rho[c]);
    *amplified = rho < 1 ? bn_precision_epsilon(BN_PRECISION_FLOAT) / (1 - rho) : INFINITY;
    return *amplified > o->solve.tol ? BN_PRECISION_DOUBLE : o->ff.precision;
}

bn_status bn_pipeline_scene(const char *path, const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    double t0 = bn__now();
    bn_status st;
    memset(p, 0, sizeof *p);
    st = bn_scene_load(path, &o->load, &p->scene, err);
    p->seconds_load = bn__now() - t0;
    t0 = bn__now();
    if (st == BN_OK)
        st = bn_scene_mesh(p->scene, &o->mesh, err);
    p->seconds_mesh = bn__now() - t0;
    if (st != BN_OK) {
        bn_scene_destroy(p->scene);
        p->scene = NULL;
        return st;
    }
    bn_scene_patches(p->scene, &p->n);
    return BN_OK;
}

bn_status bn_pipeline_operator(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    bn_formfactor_opts fo = o->ff;
    double t0 = bn__now(), amp;
    if (o->auto_precision && fo.precision != bn__precision_by_need(o, p->scene, &amp)) {
        fo.precision = BN_PRECISION_DOUBLE;
        bn_logf(&o->solve.log_sink, BN_LOG_INFO,
                "F stored in double: float's rounding (2^-24) amplified by 1 / (1 - rho_max) is %.2g, above the "
                "tolerance %g (--precision float keeps float)", amp, o->solve.tol);
    }
    bn_status st = bn_rt_create(p->scene, o->threads, &p->rt, err);
    if (!fo.threads)
        fo.threads = o->threads;
    if (st == BN_OK)
        st = bn_formfactor_build(p->scene, p->rt, &fo, &p->k, &p->ff, err);
    if (st != BN_OK || !o->keep_rt) {
        bn_rt_destroy(p->rt);
        p->rt = NULL;
    }
    p->seconds_operator = bn__now() - t0;
    return st;
}

bn_status bn_pipeline_solve(const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    bn_solve_opts so = o->solve;
    double t0 = bn__now();
    if (!so.threads)
        so.threads = o->threads;
    bn_status st;
    p->E = bn__malloc_array(p->n ? 3 * p->n : 1, sizeof(double));
    if (!p->E)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the emission of %zu patches", p->n);
    bn_scene_patch_emission(p->scene, p->E);
    if (o->tie_threshold && p->ff.row_sum_max - 1.0 > so.singular_threshold) {
        bn_logf(&so.log_sink, BN_LOG_INFO,
                "F's rows sum up to %.9g: singular threshold raised from %g to %.3g (F's measured row-sum error)",
                p->ff.row_sum_max, so.singular_threshold, p->ff.row_sum_max - 1.0);
        so.singular_threshold = p->ff.row_sum_max - 1.0;
    }
    p->singular_threshold = so.singular_threshold;
    st = bn_solve(p->k, p->E, &so, &p->res, err);
    if ((st == BN_OK || st == BN_ENOTCONV) && p->res.nterms > 0) {
        p->rest = bn__malloc_array(3 * p->n + 1, sizeof(double));
        if (!p->rest)
            st = bn_error_set(err, BN_ENOMEM, "out of memory for rest");
        else
            bn_layers_rest((const double *const *)p->res.terms, p->res.nterms, p->res.L, 3 * p->n, p->rest);
    }
    p->seconds_solve = bn__now() - t0;
    return st;
}

bn_status bn_pipeline_run(const char *path, const bn_pipeline_opts *o, bn_pipeline *p, bn_error *err)
{
    bn_status st = bn_pipeline_scene(path, o, p, err);
    if (st == BN_OK)
        st = bn_pipeline_operator(o, p, err);
    if (st == BN_OK)
        st = bn_pipeline_solve(o, p, err);
    return st;
}

void bn_pipeline_free(bn_pipeline *p)
{
    if (!p)
        return;
    bn_solve_result_free(&p->res);
    free(p->rest);
    free(p->E);
    bn_transport_destroy(p->k);
    bn_rt_destroy(p->rt);
    bn_scene_destroy(p->scene);
    memset(p, 0, sizeof *p);
}

void bn_pipeline_describe_solve(const bn_pipeline_opts *o, const bn_pipeline *p, char *buf, size_t size)
{
    snprintf(buf, size, "%s%s tol=%g max_iter=%zu: %s after %zu iterations, residual %.3g",
             bn_solve_method_name(o->solve.method),
             o->solve.symmetric && o->solve.method == BN_SOLVE_GAUSS_SEIDEL ? "-symmetric" : "", o->solve.tol,
             o->solve.max_iter, bn_stop_reason_name(p->res.reason), p->res.iterations, p->res.residual_max);
}
