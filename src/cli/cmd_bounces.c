/* `bounce bounces SCENE -n K -o out.exr`: the per-bounce layers E, KE, K2E, ..., K{K}E, rest
 * (L minus their sum) and L seen through a camera, as one multi-layer EXR, a PNG per layer and a
 * labelled contact sheet. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/bake.h"
#include "bounce/gather.h"

#include <string.h>

/* The solution's layers through the camera, with the provenance every file records. */
static bn_status bn__bounces_write(const bn_pipeline *p, const bn_camera *cam, int n, const bn_cli_ff *ff,
                                   const bn_cli_solution *sol, const bn_cli_common *c, bn_bounces_opts *bo,
                                   bn_error *err)
{
    const double **layers = bn__calloc((size_t)bn_layer_count(n), sizeof *layers);
    char solver[256], camdesc[512], patches[32], seedbuf[32], ffdesc[256], tolbuf[64];
    bn_formfactor_opts fo;
    bn_pipeline_opts po;
    bn_status st;
    if (!layers)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    for (int l = 0; l < bn_layer_count(n); l++)
        layers[l] = l <= n ? p->res.terms[l] : l == n + 1 ? p->rest : p->res.L;
    bn_cli_pipeline_opts(&(bn_cli_scene){0}, ff, sol, c, &po);
    bn_pipeline_describe_solve(&po, p, solver, sizeof solver);
    bn_cli_camera_describe(cam, camdesc, sizeof camdesc);
    bn_cli_ff_opts(ff, c, &fo);
    bn_formfactor_opts_describe(&fo, ffdesc, sizeof ffdesc);
    snprintf(patches, sizeof patches, "%zu", p->n);
    snprintf(seedbuf, sizeof seedbuf, "%llu", (unsigned long long)c->seed);
    snprintf(tolbuf, sizeof tolbuf, "%g", po.solve.tol);
    {
        const bn_attr attrs[] = {
            {"bounce:commandLine", c->cmdline},
            {"bounce:version", bn_version()},
            {"bounce:scene", bn_scene_path(p->scene)},
            {"bounce:solver", solver},
            {"bounce:tolerance", tolbuf},
            {"bounce:formFactors", ffdesc},
            {"bounce:patches", patches},
            {"bounce:units", "radiance, W m^-2 sr^-1 (L = E + K L solved in radiance)"},
            {"bounce:layers", "E = K^0 E (emission), KE = K^1 E (direct), K2E = K^2 E, ...; rest = L - their sum"},
            {"bounce:camera", camdesc},
            {"bounce:seed", seedbuf},
        };
        bo->attrs = attrs;
        bo->nattrs = sizeof attrs / sizeof attrs[0];
        st = bn_bounces_write(p->scene, p->rt, cam, layers, n, bo, NULL, err);
    }
    free(layers);
    return st;
}

/* The images' memory before any work: the size from --size, else the sidecar's, else the default. */
static bn_status bn__bounces_precheck(const bn_optset *set, const bn_cli_camera *co, const char *scene, int n,
                                      size_t max_memory, bn_error *err)
{
    bn_camera pre = {{0, 0, 0}, {0, 0, 1}, {0, 1, 0}, 40, 512, 512, 1};
    bn_status st = BN_OK;
    if (bn_cli_given(set, "size")) {
        pre.width = co->size[0];
        pre.height = co->size[1];
    } else {
        st = bn_camera_load_sidecar(scene, &pre, NULL, err);
    }
    return st == BN_OK ? bn_bounces_check_memory(pre.width, pre.height, n, max_memory, err) : st;
}

typedef struct bn__bounces_cli {
    bn_cli_scene so;
    bn_cli_ff ff;
    bn_cli_solution sol;
    bn_cli_camera co;
    const char *out, *patches_out;
    int n, half, smooth, no_previews, tile, gather;
    int light_samples, gather_samples, gather_filter, hit_emitters, tree_emitters;
    double ev, crease;
} bn__bounces_cli;

static void bn__bounces_options(bn_optset *set, bn__bounces_cli *a, bn_cli_common *c)
{
    *a = (bn__bounces_cli){.out = "bounces.exr", .n = 3, .tile = 320, .light_samples = BN_GATHER_LIGHT_SAMPLES,
                           .gather_samples = BN_GATHER_HEMI_SAMPLES, .gather_filter = BN_GATHER_FILTER,
                           .hit_emitters = BN_GATHER_HIT_EMITTERS, .tree_emitters = BN_GATHER_TREE_EMITTERS,
                           .crease = BN_BAKE_DEFAULT_CREASE};
    set->usage = "bounce bounces SCENE [-n K] [-o out.exr] [camera, solver, form-factor, meshing options]";
    set->summary =
        "Solves L = E + K L keeping every bounce term K^k E and renders, through a pinhole camera, the layers\n"
        "E, KE, K2E, ..., K{K}E (bounce k is K^k E), rest = L - (E + ... + K{K}E) and L as one multi-layer\n"
        "OpenEXR (channels KE.R, KE.G, KE.B, ...; radiance in W m^-2 sr^-1), an sRGB PNG per layer\n"
        "(out.<layer>.png) and a contact sheet (out.sheet.png): row 1 every layer at one exposure, row 2 each\n"
        "normalised on its own. Each pixel by the final gather at the point it sees (KE in closed form with\n"
        "shadow rays, higher terms gathered from the solution; default mesh " BN__STR(BN_GATHER_PATCHES) " patches), or with --gather none\n"
        "the value of the patch it sees. The camera comes from NAME.camera beside the scene if it exists; flags\n"
        "override.";
    bn_optset_add(set, (bn_opt){"bounces", 'n', BN_OPT_INT, &a->n, NULL, 0, 64, "K",
                                "keep terms E .. K^K E as their own layers (default 3)"});
    bn_optset_add(set, (bn_opt){"output", 'o', BN_OPT_STRING, &a->out, NULL, 0, 0, "FILE.exr",
                                "multi-layer EXR (default bounces.exr); previews go beside it"});
    bn_optset_add(set, (bn_opt){"half", 0, BN_OPT_FLAG, &a->half, NULL, 0, 0, NULL,
                                "store half floats (values above 65504 are clamped, with a warning)"});
    bn_optset_add(set, (bn_opt){"exposure", 0, BN_OPT_DOUBLE, &a->ev, NULL, -64, 64, "EV",
                                "preview exposure: value * 2^EV before sRGB (default: auto, the 99th percentile "
                                "of L at 0.9)"});
    bn_optset_add(set, (bn_opt){"smooth", 0, BN_OPT_FLAG, &a->smooth, NULL, 0, 0, NULL,
                                "read the solution interpolated across patches (baked vertex values, crack-free at T-junctions) "
                                "instead of one value per patch: the pixels with --gather none, the gather's hits "
                                "with final"});
    bn_optset_add(set, (bn_opt){"crease", 0, BN_OPT_DOUBLE, &a->crease, NULL, 0, 180, "DEG",
                                "--smooth: faces whose normals differ by more are not blended (default 30)"});
    bn_optset_add(set, (bn_opt){"no-previews", 0, BN_OPT_FLAG, &a->no_previews, NULL, 0, 0, NULL,
                                "write the EXR only"});
    bn_optset_add(set, (bn_opt){"gather", 0, BN_OPT_CHOICE, &a->gather, bn_gather_mode_names(), 0, 0, bn_gather_mode_names(),
                                "final (default): each pixel computed at the point it sees: E there, KE from every "
                                "emitting face in closed form with shadow rays, K^k E (k >= 2), rest and L gathered "
                                "from the solution over the hemisphere; none: each pixel the value of the patch it "
                                "sees (to look at the patches themselves)"});
    bn_optset_add(set, (bn_opt){"light-samples", 0, BN_OPT_INT, &a->light_samples, NULL, 1, 65536, "N",
                                "gather: shadow rays per light (emitting faces; coplanar pieces of one light merged) per "
                                "pixel sample, rounded up to a square (with the light tree: faces picked per pixel "
                                "sample, one ray each; default "
                                BN__STR(BN_GATHER_LIGHT_SAMPLES) ")"});
    bn_optset_add(set, (bn_opt){"gather-samples", 0, BN_OPT_INT, &a->gather_samples, NULL, 1, 1 << 20, "N",
                                "gather: hemisphere rays per pixel sample, rounded up to a square (default "
                                BN__STR(BN_GATHER_HEMI_SAMPLES) ")"});
    bn_optset_add(set, (bn_opt){"gather-filter", 0, BN_OPT_INT, &a->gather_filter, NULL, 0, 64, "PX",
                                "gather: each pixel's gathered (indirect) terms averaged with those of the pixels "
                                "within PX that see the same face, never across a face's edge (default "
                                BN__STR(BN_GATHER_FILTER) "; 0: none)"});
    bn_optset_add(set, (bn_opt){"hit-emitters", 0, BN_OPT_INT, &a->hit_emitters, NULL, 0, 1 << 20, "N",
                                "gather: K2E's hemisphere hits take their KE from the emitting faces themselves "
                                "(one shadow ray each) instead of the hit patch's value, when the scene has at most N "
                                "emitting faces (default " BN__STR(BN_GATHER_HIT_EMITTERS) "; 0: always the patch's; "
                                "with the light tree, one ray each to one picked face)"});
    bn_optset_add(set, (bn_opt){"tree-emitters", 0, BN_OPT_INT, &a->tree_emitters, NULL, 0, 1 << 30, "N",
                                "gather: with more than N lights (emitting faces, the coplanar pieces of one convex "
                                "light merged), each pixel sample picks --light-samples of them from a light tree in "
                                "proportion to their likely contribution (one ray each), so a lampshade cut into "
                                "10,000 triangles costs about what one face does (default "
                                BN__STR(BN_GATHER_TREE_EMITTERS) ")"});
    bn_optset_add(set, (bn_opt){"patches-out", 0, BN_OPT_STRING, &a->patches_out, NULL, 0, 0, "FILE.csv",
                                "also write the per-patch CSV of `bounce solve -n K` (L and every term) from the "
                                "same solution"});
    bn_optset_add(set, (bn_opt){"tile", 0, BN_OPT_INT, &a->tile, NULL, 16, 4096, "PX",
                                "largest tile width on the contact sheet (default 320)"});
    bn_cli_add_camera(set, &a->co);
    bn_cli_add_solution(set, &a->sol);
    bn_cli_add_ff(set, &a->ff);
    bn_cli_add_scene(set, &a->so);
    bn_cli_add_common(set, c);
}

/* The image stage's options from the command line. */
static void bn__bounces_opts(const bn_optset *set, const bn__bounces_cli *a, const bn_cli_common *c,
                             bn_bounces_opts *bo)
{
    bn_bounces_opts_default(bo);
    bo->output = a->out;
    bo->half = a->half;
    bo->previews = !a->no_previews;
    bo->tile = a->tile;
    bo->smooth = a->smooth;
    bo->crease = a->crease;
    bo->auto_exposure = !bn_cli_given(set, "exposure");
    bo->ev = a->ev;
    bo->seed = c->seed;
    bo->threads = c->threads;
    bo->gather = a->gather == BN_GATHER_FINAL;
    bo->light_samples = a->light_samples;
    bo->gather_samples = a->gather_samples;
    bo->gather_filter = a->gather_filter;
    bo->hit_emitters = a->hit_emitters;
    bo->tree_emitters = a->tree_emitters;
    bo->quiet = c->quiet;
    bo->log = (bn_log){bn_cli_stdout_log, (void *)c, c->quiet};
}

/* --patches-out: the per-patch CSV of the same solution. */
static bn_status bn__bounces_patches_out(bn__bounces_cli *a, bn_cli_common *c, const bn_pipeline *p, bn_error *err)
{
    bn_pipeline_opts po;
    char prov[4096];
    bn_cli_pipeline_opts(&a->so, &a->ff, &a->sol, c, &po);
    po.solve.bounces = a->n;
    po.solve.method = p->method_used;
    bn_cli_provenance_run(prov, sizeof prov, c, &po, p);
    return bn_cli_patches_csv_write(a->patches_out, prov, &po.solve, p, 1, err);
}

int bn_cmd_bounces(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn__bounces_cli a;
    const char *pos[1];
    int rc, prc;
    bn_error err;
    bn_pipeline p;
    bn_camera cam;
    bn_status st;

    memset(&set, 0, sizeof set);
    memset(&p, 0, sizeof p);
    bn__bounces_options(&set, &a, c);
    bn_error_clear(&err);
    if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
        return prc;
    if (a.gather == BN_GATHER_FINAL)
        a.so.default_patches = BN_GATHER_PATCHES;   /* the gather's default mesh (bench/results.md) */
    if (a.gather == BN_GATHER_FINAL && (a.n < 1 || a.n > 20)) {
        bn_error_set(&err, BN_EUSAGE, "--gather final needs -n between 1 (KE is computed per pixel) and 20, not %d; or "
                     "--gather none", a.n);
        return bn_cli_fail(&err);
    }
    if (bn__bounces_precheck(&set, &a.co, pos[0], a.n, a.ff.max_memory, &err) != BN_OK)
        return bn_cli_fail(&err);
    st = bn_cli_run_solution(pos[0], &a.so, &a.ff, &a.sol, c, a.n, &p, NULL, 0);
    if (st == BN_OK)
        st = bn_cli_make_camera(&set, &a.co, pos[0], p.scene, c, &cam, &err);
    else
        err.status = BN_OK;   /* already printed */
    if (st == BN_OK) {
        bn_bounces_opts bo;
        bn__bounces_opts(&set, &a, c, &bo);
        st = bn__bounces_write(&p, &cam, a.n, &a.ff, &a.sol, c, &bo, &err);
    }
    if (st == BN_OK && a.patches_out)
        st = bn__bounces_patches_out(&a, c, &p, &err);
    rc = st == BN_OK ? 0 : err.status != BN_OK ? bn_cli_fail(&err) : bn_status_exit_code(st);
    bn_pipeline_free(&p);
    if (rc == 0 && bn_interrupted() != BN_OK)
        rc = bn_cli_interrupted();
    return rc;
}
