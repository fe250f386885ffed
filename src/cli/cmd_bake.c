/* `bounce bake SCENE -o baked.ply`: per-vertex radiance from the patch solution, area-weighted
 * within each smooth surface and split at creases and material seams; PLY, OM or OBJ. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/bake.h"

#include <math.h>
#include <string.h>

int bn_cmd_bake(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn_cli_scene so;
    bn_cli_ff ff;
    bn_cli_solution sol;
    const char *pos[1], *out = "baked.ply";
    size_t np, nl = 1;
    int n = 3, ldr = 0, flat = 0, per_bounce = 0, rc = 0, mesh = 0, elements, is_gltf = 0;
    double ev = 0, crease = BN_BAKE_DEFAULT_CREASE;
    bn_error err;
    bn_pipeline p;
    bn_bake *bake = NULL;
    bn_status st;
    bn_bake_layer *layers = NULL;
    char (*names)[16] = NULL;
    char solver[256], ffdesc[256], patches[32], evbuf[160], creasebuf[32], verts[32];
    bn_formfactor_opts fo;
    bn_bake_write_opts wo;

    memset(&set, 0, sizeof set);
    memset(&so, 0, sizeof so);
    memset(&ff, 0, sizeof ff);
    memset(&sol, 0, sizeof sol);
    memset(&p, 0, sizeof p);
    set.usage = "bounce bake SCENE [-o baked.ply|.om|.obj|.glb|.gltf] [--ldr] [--per-bounce -n K] [options]";
    set.summary =
        "Solves L = E + K L and bakes L to vertex colours on the patches (--mesh input: on the input\n"
        "polygons alone): each vertex takes the area-weighted mean of the patches around it within one\n"
        "smooth surface (adjacent faces of one material whose normals differ by less than --crease);\n"
        "vertices are split at creases and material seams. Colours are float radiance (W m^-2 sr^-1) by\n"
        "default, 8-bit sRGB with --ldr. .ply (binary) and .om are written through OpenMesh,\n"
        ".obj directly as `v x y z r g b`. --per-bounce adds float vertex properties E_red, E_green, E_blue,\n"
        "KE_red, ..., K{K}E_*, rest_* (PLY, OM) so engines can blend bounces; their sum is L.\n"
        ".glb / .gltf (+ .bin): glTF 2.0 in metres, COLOR_0 = L as float radiance, --per-bounce adds the\n"
        "attributes _E, _KE, ..., _REST, unlit materials with the reflectance in their extras, provenance in\n"
        "the asset's extras; --ldr adds COLOR_1, the 8-bit sRGB display set, beside the float ones.";
    bn_optset_add(&set, (bn_opt){"output", 'o', BN_OPT_STRING, &out, NULL, 0, 0, "FILE",
                                 "baked mesh: .ply, .om, .obj, .glb or .gltf (default baked.ply)"});
    bn_optset_add(&set, (bn_opt){"crease", 0, BN_OPT_DOUBLE, &crease, NULL, 0, 180, "DEG",
                                 "faces whose normals differ by more do not share vertices (default 30)"});
    bn_optset_add(&set, (bn_opt){"flat", 0, BN_OPT_FLAG, &flat, NULL, 0, 0, NULL,
                                 "every patch its own vertices, each with its patch's value (no blending: the patches "
                                 "as the solve sees them)"});
    bn_optset_add(&set, (bn_opt){"ldr", 0, BN_OPT_FLAG, &ldr, NULL, 0, 0, NULL,
                                 "8-bit sRGB colours at --exposure instead of float radiance"});
    bn_optset_add(&set, (bn_opt){"exposure", 0, BN_OPT_DOUBLE, &ev, NULL, -64, 64, "EV",
                                 "--ldr: value * 2^EV before sRGB (default: auto, the 99th percentile of the "
                                 "patches' L at 0.9)"});
    bn_optset_add(&set, (bn_opt){"per-bounce", 0, BN_OPT_FLAG, &per_bounce, NULL, 0, 0, NULL,
                                 "also write each term E .. K^K E and rest as float vertex properties (PLY, OM, glTF)"});
    bn_optset_add(&set, (bn_opt){"bounces", 'n', BN_OPT_INT, &n, NULL, 0, 64, "K",
                                 "--per-bounce: terms E .. K^K E (default 3)"});
    bn_optset_add(&set, (bn_opt){"mesh", 0, BN_OPT_CHOICE, &mesh, "elements|input", 0, 0, "elements|input",
                                 "faces written: every patch, the element mesh the solution lives on, whose vertices "
                                 "include every input vertex (default); or the scene's input polygons alone, each "
                                 "corner the mean of the patches around it"});
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
    elements = mesh == 0;
    if (flat && bn_cli_given(&set, "crease")) {
        bn_error_set(&err, BN_EUSAGE, "--flat and --crease: a flat bake shares no vertices, so no crease applies");
        return bn_cli_fail(&err);
    }
    {
        const char *dot = strrchr(out, '.');
        if (!dot || (strcmp(dot, ".ply") && strcmp(dot, ".om") && strcmp(dot, ".obj") && strcmp(dot, ".glb") &&
                     strcmp(dot, ".gltf"))) {
            bn_error_set(&err, BN_EUSAGE, "-o %s: bake writes .ply, .om, .obj, .glb or .gltf", out);
            return bn_cli_fail(&err);
        }
        is_gltf = strcmp(dot, ".glb") == 0 || strcmp(dot, ".gltf") == 0;
        if (per_bounce && strcmp(dot, ".obj") == 0) {
            bn_error_set(&err, BN_EUSAGE, "--per-bounce needs .ply or .om (OBJ holds one colour per vertex)");
            return bn_cli_fail(&err);
        }
    }
    st = bn_cli_run_solution(pos[0], &so, &ff, &sol, c, per_bounce ? n : 0, &p, solver, sizeof solver);
    if (st != BN_OK) {
        rc = bn_status_exit_code(st);
        goto done;
    }
    np = p.n;
    nl = per_bounce ? (size_t)bn_layer_count(n) : 1;   /* L first, then E .. K^n E and rest */
    layers = bn__calloc(nl, sizeof *layers);
    names = bn__calloc(nl, sizeof *names);
    if (!layers || !names) {
        bn_error_set(&err, BN_ENOMEM, "out of memory");
        rc = bn_cli_fail(&err);
        goto done;
    }
    layers[0] = (bn_bake_layer){"L", p.res.L};
    for (size_t l = 1; l < nl; l++) {
        int layer = (int)l - 1;
        bn_layer_name(layer, n, names[l], sizeof names[l]);
        layers[l] = (bn_bake_layer){names[l], layer <= n ? p.res.terms[layer] : p.rest};
    }
    st = bn_bake_create(p.scene, flat ? BN_BAKE_FLAT : crease, &bake, &err);
    if (st != BN_OK) {
        rc = bn_cli_fail(&err);
        goto done;
    }
    if (!flat && p.rt) {
        size_t enc = bn_bake_exclude_enclosed(bake, p.rt);
        if (enc && !c->quiet)
            fprintf(stderr, "bounce: bake: %zu patches inside closed objects (under the blocks) left out of the "
                            "vertex averages\n", enc);
    }
    if ((ldr || is_gltf) && !bn_cli_given(&set, "exposure"))
        ev = bn_bake_auto_exposure(p.res.L, np);
    bn_cli_ff_opts(&ff, c, &fo);
    bn_formfactor_opts_describe(&fo, ffdesc, sizeof ffdesc);
    snprintf(patches, sizeof patches, "%zu", np);
    if (elements)
        snprintf(verts, sizeof verts, "%zu", bn_bake_vertex_count(bake));
    else
        snprintf(verts, sizeof verts, "input polygons' corners");
    if (flat)
        snprintf(creasebuf, sizeof creasebuf, "flat (no shared vertices)");
    else
        snprintf(creasebuf, sizeof creasebuf, "%g degrees", crease);
    if (is_gltf)
        snprintf(evbuf, sizeof evbuf, "COLOR_0 L x 2^%+.4f clamped to [0, 1]; _L radiance W m^-2 sr^-1%s", ev,
                 ldr ? "; COLOR_1 8-bit sRGB" : "");
    else if (ldr)
        snprintf(evbuf, sizeof evbuf, "8-bit sRGB at %+.4f EV", ev);
    else
        snprintf(evbuf, sizeof evbuf, "float radiance, W m^-2 sr^-1");
    {
        char tolbuf[64];
        bn_attr attrs[] = {
            {"command line", c->cmdline}, {"scene", bn_scene_path(p.scene)}, {"solver", solver}, {"tolerance", tolbuf},
            {"form factors", ffdesc},      {"patches", patches},         {"vertices", verts}, {"crease", creasebuf},
            {"colours", evbuf},           {"faces", elements ? "the patches (element mesh)" : "the input polygons"},
            {"vertex colour", flat ? "L of the vertex's own patch (flat: no vertex shared between patches)"
                                   : "L, area-weighted mean of the patches around the vertex within its smooth surface"},
        };
        snprintf(tolbuf, sizeof tolbuf, "%g", sol.tol > 0 ? sol.tol : 1e-6);
        memset(&wo, 0, sizeof wo);
        wo.input_mesh = !elements;
        wo.ldr = ldr;
        wo.exposure_ev = ev;
        wo.attrs = attrs;
        wo.nattrs = sizeof attrs / sizeof attrs[0];
        st = bn_bake_write(bake, out, layers, nl, &wo, &err);
        if (st != BN_OK) {
            rc = bn_cli_fail(&err);
            goto done;
        }
    }
    if (!c->quiet) {
        size_t nf;
        bn_scene_faces(p.scene, &nf);
        if (elements)
            printf("wrote %s (the element mesh: %zu vertices, %zu patches; %s%s)\n", out, bn_bake_vertex_count(bake),
                   np, evbuf, per_bounce ? "; per-bounce properties E .. rest" : "");
        else
            printf("wrote %s (the input mesh: %zu polygons; %s%s)\n", out, nf, evbuf,
                   per_bounce ? "; per-bounce properties E .. rest" : "");
    }
done:
    free(layers);
    free(names);
    bn_bake_destroy(bake);
    bn_pipeline_free(&p);
    if (rc == 0 && bn_interrupted() != BN_OK)
        rc = bn_cli_interrupted();
    return rc;
}
