/* Relighting benchmark (issue 37): a scene solved once, then relit R times on its own F with new
 * materials (the light's emission and a wall's reflectance, alternating), every term again. Prints
 * a markdown row per scene: patches, transport, the form factors' (or links') time, the fresh solve's,
 * and the relight's median and worst, the relight against the whole run as a ratio. Not a test.
 * usage: relight_bench [--reps R] [--bounces B] [--method M] SCENE UNIT TRANSPORT LIGHT WALL [SCENE UNIT ...]
 *   LIGHT: the emitting material relit (Le x 2 and x 1/2 in turn); WALL: a material whose rho changes */
#include "bounce/pipeline.h"
#include "base/internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static void quiet(void *user, const bn_message *m)
{
    (void)user;
    (void)m;
}

/* One scene: solve, then reps relights; one table row. */
static const char *method;   /* --method: the solver (default: auto) */

static int bench_scene(const char *path, const char *unit, const char *transport, const char *light, const char *wall,
                       int reps, int bounces)
{
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_error err;
    bn_pipeline_opts_default(&o);
    bn_unit_parse(unit, &o.load.unit);
    o.transport = transport;
    o.mesh_auto = 1;
    o.method_auto = !method;
    if (method && bn_solve_method_parse(method, &o.solve.method) != 0) {
        fprintf(stderr, "unknown method %s\n", method);
        return 1;
    }
    o.ff.quiet = o.hier.quiet = 1;
    o.solve.bounces = bounces;
    o.load.log = o.solve.log_sink = o.ff.log = (bn_log){quiet, NULL, 1};
    if (bn_pipeline_run(path, &o, &p, &err) != BN_OK) {
        fprintf(stderr, "%s: %s\n", path, err.msg);
        return 1;
    }
    size_t nm;
    const bn_material *m = bn_scene_materials(p.scene, &nm);
    double fresh = p.seconds_solve, whole = p.seconds_load + p.seconds_mesh + p.seconds_operator + p.seconds_solve;
    bn_material_edit e[2];
    double Le0[3] = {0, 0, 0}, *t = calloc((size_t)reps, sizeof *t);
    for (size_t k = 0; k < nm; k++)
        if (!strcmp(m[k].name, light))
            memcpy(Le0, m[k].Le, sizeof Le0);
    memset(e, 0, sizeof e);
    snprintf(e[0].material, sizeof e[0].material, "%s", light);
    snprintf(e[1].material, sizeof e[1].material, "%s", wall);
    e[0].has_Le = e[1].has_rho = 1;
    for (int r = 0; r < reps; r++) {
        for (int c = 0; c < 3; c++) {
            e[0].Le[c] = Le0[c] * (r % 2 ? 0.5 : 2);
            e[1].rho[c] = r % 2 ? 0.2 : 0.6;
        }
        double t0 = bn__now();
        if (bn_pipeline_relight(&o, &p, e, 2, 0, &err) != BN_OK) {
            fprintf(stderr, "%s: relight: %s\n", path, err.msg);
            return 1;
        }
        t[r] = bn__now() - t0;
        if (getenv("RELIGHT_BENCH_DEBUG"))
            fprintf(stderr, "relight %d: %.2f ms: analysis %.2f (%zu power steps), iterations %.2f (%zu), terms %.2f\n", r,
                    1e3 * t[r], 1e3 * p.res.seconds_analyse, p.res.power_iterations, 1e3 * p.res.seconds_iterate,
                    p.res.iterations, 1e3 * p.res.seconds_terms);
    }
    qsort(t, (size_t)reps, sizeof *t, cmp_double);
    printf("| %s | %zu | %s | %s | %.2f s | %.3f s | %.2f ms | %.2f ms | %.4f | %.0fx |\n", path, p.n,
           p.hierarchical ? "hierarchical" : bn_transport_name(p.k), bn_solve_method_name(p.method_used), p.seconds_operator, fresh,
           1e3 * t[reps / 2], 1e3 * t[reps - 1], t[reps / 2] / whole, whole / t[reps / 2]);
    free(t);
    bn_pipeline_free(&p);
    return 0;
}

int main(int argc, char **argv)
{
    int reps = 20, bounces = 10, i = 1, rc = 0;
    for (; i + 1 < argc && argv[i][0] == '-'; i += 2) {
        if (!strcmp(argv[i], "--reps"))
            reps = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--bounces"))
            bounces = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--method"))
            method = argv[i + 1];
    }
    if (reps < 1 || (argc - i) % 5 != 0 || argc == i) {
        fprintf(stderr, "usage: relight_bench [--reps R] [--bounces B] [--method M] SCENE UNIT TRANSPORT LIGHT WALL ...\n");
        return 2;
    }
    printf("| scene | patches | K | solver | form factors | solve | relight (median) | relight (worst) | relight / whole "
           "run | speed-up |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for (; i + 4 < argc; i += 5)
        rc |= bench_scene(argv[i], argv[i + 1], argv[i + 2], argv[i + 3], argv[i + 4], reps, bounces);
    printf("\n%d relights each, %d bounce terms kept, the solver's default tolerance; relight = new rho and Le, "
           "every term solved again on the same F.\n", reps, bounces);
    return rc;
}
