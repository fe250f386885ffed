/* `bounce bounces SCENE -n K -o out.exr`: the per-bounce layers E, KE, K2E, ..., K{K}E, rest
 * (L minus their sum) and L seen through a camera, as one multi-layer EXR, a PNG per layer and a
 * labelled contact sheet. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/bake.h"

#include <math.h>
#include <string.h>

/* "dir/out.exr" + ".KE.png" -> "dir/out.KE.png" (the extension of `path` replaced). */
static char *bn__sibling(const char *path, const char *suffix)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    size_t stem = (dot && (!slash || dot > slash)) ? (size_t)(dot - path) : strlen(path);
    char *s = malloc(stem + strlen(suffix) + 1);
    if (s) {
        memcpy(s, path, stem);
        strcpy(s + stem, suffix);
    }
    return s;
}

int bn_cmd_bounces(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn_cli_scene so;
    bn_cli_ff ff;
    bn_cli_solution sol;
    bn_cli_camera co;
    const char *pos[1], *out = "bounces.exr";
    size_t np, nl;
    int n = 3, half = 0, smooth = 0, no_previews = 0, tile = 320, rc = 0;
    double ev = 0, crease = BN_BAKE_DEFAULT_CREASE;
    bn_error err;
    bn_pipeline p;
    bn_bake *bake = NULL;
    bn_camera cam;
    bn_status st;
    const double **vals = NULL;
    bn_image *imgs = NULL;
    bn_layer *layers = NULL;
    char (*names)[16] = NULL;
    char solver[256], camdesc[512], patches[32], evbuf[32], seedbuf[32], ffdesc[256];
    bn_formfactor_opts fo;

    memset(&set, 0, sizeof set);
    memset(&so, 0, sizeof so);
    memset(&ff, 0, sizeof ff);
    memset(&sol, 0, sizeof sol);
    memset(&co, 0, sizeof co);
    memset(&p, 0, sizeof p);
    set.usage = "bounce bounces SCENE [-n K] [-o out.exr] [camera, solver, form-factor, meshing options]";
    set.summary =
        "Solves L = E + K L keeping every bounce term K^k E and renders, through a pinhole camera, the layers\n"
        "E, KE, K2E, ..., K{K}E (bounce k is K^k E), rest = L - (E + ... + K{K}E) and L as one multi-layer\n"
        "OpenEXR (channels KE.R, KE.G, KE.B, ...; radiance in W m^-2 sr^-1), an sRGB PNG per layer\n"
        "(out.<layer>.png) and a contact sheet (out.sheet.png): row 1 every layer at one exposure, row 2 each\n"
        "normalised on its own. The camera comes from NAME.camera beside the scene if it exists; flags override.";
    bn_optset_add(&set, (bn_opt){"bounces", 'n', BN_OPT_INT, &n, NULL, 0, 64, "K",
                                 "keep terms E .. K^K E as their own layers (default 3)"});
    bn_optset_add(&set, (bn_opt){"output", 'o', BN_OPT_STRING, &out, NULL, 0, 0, "FILE.exr",
                                 "multi-layer EXR (default bounces.exr); previews go beside it"});
    bn_optset_add(&set, (bn_opt){"half", 0, BN_OPT_FLAG, &half, NULL, 0, 0, NULL,
                                 "store half floats (values above 65504 are clamped, with a warning)"});
    bn_optset_add(&set, (bn_opt){"exposure", 0, BN_OPT_DOUBLE, &ev, NULL, -64, 64, "EV",
                                 "preview exposure: value * 2^EV before sRGB (default: auto, the 99th percentile "
                                 "of L at 0.9)"});
    bn_optset_add(&set, (bn_opt){"smooth", 0, BN_OPT_FLAG, &smooth, NULL, 0, 0, NULL,
                                 "interpolate baked vertex values across patches (default flat: one value per patch)"});
    bn_optset_add(&set, (bn_opt){"crease", 0, BN_OPT_DOUBLE, &crease, NULL, 0, 180, "DEG",
                                 "--smooth: faces whose normals differ by more are not blended (default 30)"});
    bn_optset_add(&set, (bn_opt){"no-previews", 0, BN_OPT_FLAG, &no_previews, NULL, 0, 0, NULL,
                                 "write the EXR only"});
    bn_optset_add(&set, (bn_opt){"tile", 0, BN_OPT_INT, &tile, NULL, 16, 4096, "PX",
                                 "largest tile width on the contact sheet (default 320)"});
    bn_cli_add_camera(&set, &co);
    bn_cli_add_solution(&set, &sol);
    bn_cli_add_ff(&set, &ff);
    bn_cli_add_scene(&set, &so);
    bn_cli_add_common(&set, c);
    bn_error_clear(&err);
    {
        int prc;
        if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
            return prc;
    }
    bn_cli_apply_threads(c);
    st = bn_cli_run_solution(pos[0], &so, &ff, &sol, c, n, &p, solver, sizeof solver);
    if (st != BN_OK) {
        rc = bn_status_exit_code(st);
        goto done;
    }
    st = bn_cli_make_camera(&set, &co, pos[0], p.scene, &cam, &err);
    if (st != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    np = p.n;
    nl = (size_t)bn_layer_count(n);
    vals = bn__calloc(nl, sizeof *vals);
    imgs = bn__calloc(nl, sizeof *imgs);
    layers = bn__calloc(nl, sizeof *layers);
    names = bn__calloc(nl, sizeof *names);
    if (!vals || !imgs || !layers || !names) {
        bn_error_set(&err, BN_ENOMEM, "out of memory");
        rc = bn_cli_fail(&err);
        goto done;
    }
    for (size_t l = 0; l < nl; l++) {
        bn_layer_name((int)l, n, names[l], sizeof names[l]);
        vals[l] = (int)l <= n ? p.res.terms[l] : (int)l == n + 1 ? p.rest : p.res.L;
    }
    for (size_t l = 0; l < nl; l++) {
        st = bn_image_alloc(&imgs[l], cam.width, cam.height, &err);
        if (st != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
        layers[l].name = names[l];
        layers[l].img = &imgs[l];
    }
    if (smooth) {
        st = bn_bake_create(p.scene, crease, &bake, &err);
        if (st != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
    }
    st = bn_image_render(p.rt, &cam, vals, nl, bake, c->seed, imgs, &err);
    if (st != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    if (!bn_cli_given(&set, "exposure"))
        ev = bn_image_auto_exposure(&imgs[n + 2]);
    bn_cli_camera_describe(&cam, camdesc, sizeof camdesc);
    bn_cli_ff_opts(&ff, c, &fo);
    bn_formfactor_opts_describe(&fo, ffdesc, sizeof ffdesc);
    snprintf(patches, sizeof patches, "%zu", np);
    snprintf(evbuf, sizeof evbuf, "%.4f", ev);
    snprintf(seedbuf, sizeof seedbuf, "%llu", (unsigned long long)c->seed);
    {
        const bn_attr attrs[] = {
            {"bounce:commandLine", c->cmdline},
            {"bounce:version", bn_version()},
            {"bounce:scene", bn_scene_path(p.scene)},
            {"bounce:solver", solver},
            {"bounce:tolerance", ""},
            {"bounce:formFactors", ffdesc},
            {"bounce:patches", patches},
            {"bounce:units", "radiance, W m^-2 sr^-1 (L = E + K L solved in radiance)"},
            {"bounce:layers", "E = K^0 E (emission), KE = K^1 E (direct), K2E = K^2 E, ...; rest = L - their sum"},
            {"bounce:camera", camdesc},
            {"bounce:shading", smooth ? "smooth (baked vertex values, crease below)" : "flat (patch values)"},
            {"bounce:seed", seedbuf},
            {"bounce:previewExposureEV", evbuf},
        };
        bn_attr a2[sizeof attrs / sizeof attrs[0]];
        char tolbuf[64], sh[64], *path;
        snprintf(tolbuf, sizeof tolbuf, "%g", sol.tol > 0 ? sol.tol : 1e-6);
        memcpy(a2, attrs, sizeof attrs);
        a2[4].value = tolbuf;
        if (smooth) {
            snprintf(sh, sizeof sh, "smooth, crease %g degrees", crease);
            a2[10].value = sh;
        }
        st = bn_exr_write(out, layers, nl, a2, sizeof a2 / sizeof a2[0], half, NULL, &err);
        if (st != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
        if (!c->quiet)
            printf("wrote %s (%zu layers: E .. %s, rest, L; %dx%d, %s)\n", out, nl, names[n], cam.width, cam.height,
                   half ? "half" : "float");
        if (no_previews)
            goto done;
        for (size_t l = 0; l < nl; l++) {
            char suffix[40];
            snprintf(suffix, sizeof suffix, ".%s.png", names[l]);
            path = bn__sibling(out, suffix);
            if (!path) {
                bn_error_set(&err, BN_ENOMEM, "out of memory");
                rc = bn_cli_fail(&err);
                goto done;
            }
            st = bn_png_write(path, &imgs[l], ev, a2, 4, &err);
            if (st == BN_OK && !c->quiet)
                printf("wrote %s (exposure %+.2f EV, sRGB)\n", path, ev);
            free(path);
            if (st != BN_OK) {
                rc = bn_cli_fail(&err);
                goto done;
            }
        }
        path = bn__sibling(out, ".sheet.png");
        if (!path) {
            bn_error_set(&err, BN_ENOMEM, "out of memory");
            rc = bn_cli_fail(&err);
            goto done;
        }
        st = bn_contact_sheet_write(path, layers, nl, ev, tile, a2, 4, NULL, &err);
        if (st == BN_OK && !c->quiet)
            printf("wrote %s (contact sheet: row 1 at %+.2f EV, row 2 each layer normalised)\n", path, ev);
        free(path);
        if (st != BN_OK)
            rc = bn_cli_fail(&err);
    }
done:
    if (imgs)
        for (size_t l = 0; l < (size_t)n + 3; l++)
            bn_image_free(&imgs[l]);
    free(imgs);
    free(layers);
    free(names);
    free(vals);
    bn_bake_destroy(bake);
    bn_pipeline_free(&p);
    if (rc == 0 && bn_interrupted() != BN_OK)
        rc = bn_cli_interrupted();
    return rc;
}
