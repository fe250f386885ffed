/* The camera option group (shared by `bounce bounces` and `bounce trace`) and the solver group
 * plus the form factors + solve helper used by `bounces` and `bake`. */
#include "cli/cli.h"
#include "base/internal.h"

#include <string.h>

void bn_cli_add_camera(bn_optset *s, bn_cli_camera *o)
{
    bn_optset_add(s, (bn_opt){"eye", 0, BN_OPT_VEC3, o->eye, NULL, 0, 0, "X,Y,Z",
                              "camera position, scene units (default: sidecar NAME.camera, else in front of the box)"});
    bn_optset_add(s, (bn_opt){"look", 0, BN_OPT_VEC3, o->look, NULL, 0, 0, "X,Y,Z",
                              "point looked at (default: the bounding box's centre)"});
    bn_optset_add(s, (bn_opt){"up", 0, BN_OPT_VEC3, o->up, NULL, 0, 0, "X,Y,Z", "up direction (default 0,1,0)"});
    bn_optset_add(s, (bn_opt){"fov", 0, BN_OPT_DOUBLE, &o->fov, NULL, 1e-3, 179.999, "DEG",
                              "vertical field of view, degrees (default 40)"});
    bn_optset_add(s, (bn_opt){"size", 0, BN_OPT_WXH, o->size, NULL, 1, 32768, "WxH", "image size (default 512x512)"});
    bn_optset_add(s, (bn_opt){"spp", 0, BN_OPT_INT, &o->spp, NULL, 1, 65536, "N",
                              "samples per pixel, stratified and jittered (default 1: pixel centres)"});
}

bn_status bn_cli_make_camera(const bn_optset *s, const bn_cli_camera *o, const char *scene_path, const bn_scene *scene,
                             const bn_cli_common *c, bn_camera *cam, bn_error *err)
{
    bn_status st;
    int found = 0;
    const char *name;
    bn_log lg = {bn_cli_log, (void *)c, c->quiet};
    bn_camera_default(scene, cam);
    st = bn_camera_load_sidecar(scene_path, cam, &found, err);
    if (st != BN_OK)
        return st;
    if (bn_cli_given(s, "eye") || bn_cli_given(s, "look"))
        bn_logf(&lg, BN_LOG_INFO, "camera: --eye/--look as given%s", found ? " (over the scene's .camera sidecar)" : "");
    else if (found)
        bn_logf(&lg, BN_LOG_INFO, "camera: the scene's .camera sidecar (eye %g, %g, %g)", cam->eye[0], cam->eye[1],
                cam->eye[2]);
    else if (bn_scene_camera(scene, (double[3]){0}, (double[3]){0}, (double[3]){0}, &(double){0}, &(double){0}, &name))
        bn_logf(&lg, BN_LOG_INFO, "camera: the scene file's camera '%s' (eye %g, %g, %g, fov %g, %dx%d; --eye/--look, "
                "--size or a .camera sidecar override it)", name, cam->eye[0], cam->eye[1], cam->eye[2], cam->fov_deg,
                cam->width, cam->height);
    else
        bn_logf(&lg, BN_LOG_INFO, "camera: the default, in front of the scene's box looking at its centre (no .camera "
                "sidecar; --eye/--look place it, inside a closed room for an interior)");
    if (bn_cli_given(s, "eye"))
        memcpy(cam->eye, o->eye, sizeof cam->eye);
    if (bn_cli_given(s, "look"))
        memcpy(cam->look, o->look, sizeof cam->look);
    if (bn_cli_given(s, "up"))
        memcpy(cam->up, o->up, sizeof cam->up);
    if (bn_cli_given(s, "fov"))
        cam->fov_deg = o->fov;
    if (bn_cli_given(s, "size")) {
        cam->width = o->size[0];
        cam->height = o->size[1];
    }
    if (bn_cli_given(s, "spp"))
        cam->spp = o->spp;
    return bn_camera_validate(cam, err);
}

void bn_cli_camera_describe(const bn_camera *c, char *buf, size_t n)
{
    snprintf(buf, n, "eye %.9g,%.9g,%.9g look %.9g,%.9g,%.9g up %.9g,%.9g,%.9g fov %.9g size %dx%d spp %d", c->eye[0],
             c->eye[1], c->eye[2], c->look[0], c->look[1], c->look[2], c->up[0], c->up[1], c->up[2], c->fov_deg,
             c->width, c->height, c->spp);
}

void bn_cli_add_solution(bn_optset *s, bn_cli_solution *o)
{
    o->method = NULL;
    bn_optset_add(s, (bn_opt){"method", 'm', BN_OPT_NAME, &o->method, bn_cli_auto_or(bn_solve_method_names()), 0,
                              0, "METHOD",
                              "jacobi, gauss-seidel, neumann or direct; auto (default): gauss-seidel, or jacobi where K "
                              "has no rows (the hierarchy)"});
    bn_optset_add(s, (bn_opt){"tol", 0, BN_OPT_DOUBLE, &o->tol, NULL, 1e-300, 1, "T",
                              "stop when ||E - (I - K) L||_inf <= T ||E||_inf (default 1e-6)"});
    bn_optset_add(s, (bn_opt){"max-iter", 0, BN_OPT_SIZE, &o->max_iter, NULL, 1, 1e12, "N",
                              "iteration limit (default 100000)"});
}

void bn_cli_pipeline_opts(const bn_cli_scene *so, const bn_cli_ff *ff, const bn_cli_solution *sol,
                          const bn_cli_common *c, bn_pipeline_opts *out)
{
    bn_pipeline_opts_default(out);
    out->load.unit = (bn_unit)so->unit;
    if (so->planar_tol > 0)
        out->load.planar_tol = so->planar_tol;
    out->load.orient = (bn_orient)so->orient;
    out->load.two_sided = so->two_sided;
    out->load.edits = so->edits.e;
    out->load.nedits = so->edits.n;
    out->load.log = (bn_log){bn_cli_log, (void *)c, c->quiet};
    out->mesh.patch_size = so->patch_size;
    if (so->patches)
        out->mesh.target_patches = so->patches;
    else if (so->default_patches)
        out->mesh.target_patches = so->default_patches;
    out->mesh.no_subdivide = so->no_subdivide;
    out->mesh.no_contacts = so->no_contacts;
    out->mesh.self_contacts = so->self_contacts;
    out->mesh.contact_gap = so->contact_gap;
    out->mesh_auto = !(so->patch_size > 0) && !so->patches && !so->no_subdivide;
    if (ff) {
        bn_cli_ff_opts(ff, c, &out->ff);
        out->auto_precision = !ff->precision || strcmp(ff->precision, "auto") == 0;
        out->transport = !ff->transport && ff->storage ? ff->storage : ff->transport ? ff->transport : "auto";
        bn_cli_hier_opts(ff, &out->hier);
    }
    out->method_auto = 1;   /* no solver options given: the default method, chosen by K's capabilities */
    if (sol) {
        bn_cli_method(sol->method, &out->solve.method, &out->method_auto);
        if (sol->tol > 0)
            out->solve.tol = sol->tol;
        if (sol->max_iter > 0)
            out->solve.max_iter = sol->max_iter;
    }
    out->solve.quiet = c->quiet;
    out->solve.log_sink = (bn_log){bn_cli_log, (void *)c, c->quiet};
    out->threads = c->threads;
}

bn_status bn_cli_run_solution(const char *path, const bn_cli_scene *so, const bn_cli_ff *ff,
                              const bn_cli_solution *sol, const bn_cli_common *c, int bounces, bn_pipeline *p,
                              char *describe, size_t ndescribe)
{
    bn_pipeline_opts po;
    bn_error err;
    bn_status st;
    bn_error_clear(&err);
    bn_cli_pipeline_opts(so, ff, sol, c, &po);
    po.solve.bounces = bounces;
    po.keep_rt = 1;
    st = bn_pipeline_run(path, &po, p, &err);
    if (describe)
        bn_pipeline_describe_solve(&po, p, describe, ndescribe);
    if (st != BN_OK)
        bn_cli_fail(&err);
    return st;
}
