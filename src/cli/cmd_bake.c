/* `bounce bake SCENE -o baked.ply`: per-vertex radiance from the patch solution, area-weighted
 * within each smooth surface and split at creases and material seams; PLY, OM or OBJ. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/bake.h"
#include "bounce/gather.h"
#include "bounce/trace.h"

#include <math.h>
#include <string.h>

typedef struct bn__bake_cli {
    bn_cli_scene so;
    bn_cli_ff ff;
    bn_cli_solution sol;
    const char *out, *for_tool;
    int n, ldr, flat, per_bounce, mesh, is_gltf, no_colour_sets, gather, gather_rays;
    double ev, crease, bake_tol;
    size_t bake_vertices;
} bn__bake_cli;

/* How the vertices get their values, and where the mesh is refined. */
static void bn__bake_vertex_options(bn_optset *set, bn__bake_cli *a)
{
    bn_optset_add(set, (bn_opt){"gather", 0, BN_OPT_CHOICE, &a->gather, bn_gather_mode_names(), 0, 0,
                                 bn_gather_mode_names(),
                                 "each vertex's values: the final gather at the vertex, as the images' pixels get "
                                 "them (default final), or the mean of the patches around it (none; --flat: none)"});
    bn_optset_add(set, (bn_opt){"gather-rays", 0, BN_OPT_INT, &a->gather_rays, NULL, 1, 1 << 20, "N",
                                 "--gather final: hemisphere rays per vertex for K2E and beyond (default 2048)"});
    bn_optset_add(set, (bn_opt){"bake-vertices", 0, BN_OPT_SIZE, &a->bake_vertices, NULL, 0, 1e9, "N",
                                 "--gather final: the element mesh refined where L changes, up to N vertices (200k, "
                                 "1M; default " BN__STR(BN_BAKE_DEFAULT_VERTICES) "; 0: the patches as they are)"});
    bn_optset_add(set, (bn_opt){"bake-tol", 0, BN_OPT_DOUBLE, &a->bake_tol, NULL, 1e-4, 10, "T",
                                 "an edge whose ends' L differ by more than T relative is probed at its midpoint, and split where "
                                 "the light between them is not linear by as much (default "
                                 BN__STR(BN_BAKE_REFINE_TOL) ")"});
}

static void bn__bake_options(bn_optset *set, bn__bake_cli *a, bn_cli_common *c)
{
    memset(set, 0, sizeof *set);
    memset(a, 0, sizeof *a);
    a->out = "baked.ply";
    a->n = 3;
    a->crease = BN_BAKE_DEFAULT_CREASE;
    a->gather_rays = BN_BAKE_GATHER_RAYS;
    a->bake_vertices = BN_BAKE_DEFAULT_VERTICES;
    a->bake_tol = BN_BAKE_REFINE_TOL;
    set->usage = "bounce bake SCENE [-o baked.ply|.om|.obj|.glb|.gltf] [--ldr] [--per-bounce -n K] [options]";
    set->summary =
        "Solves L = E + K L and bakes L to vertex colours on the patches (--mesh input: on the input\n"
        "polygons alone): each vertex's values come from the final gather at the vertex, as the images'\n"
        "pixels get theirs (--gather none: the area-weighted mean of the patches around it within one\n"
        "smooth surface, adjacent faces of one material whose normals differ by less than --crease);\n"
        "with the gather the element mesh is refined where L changes (shadow edges, contacts: triangles\n"
        "bisected, no T-junctions, up to --bake-vertices); vertices are split at creases and material seams. Colours are float radiance (W m^-2 sr^-1) by\n"
        "default, 8-bit sRGB with --ldr. .ply (binary) and .om are written through OpenMesh,\n"
        ".obj directly as `v x y z r g b`. --per-bounce adds float vertex properties E_red, E_green, E_blue,\n"
        "KE_red, ..., K{K}E_*, rest_* (PLY, OM) so engines can blend bounces; their sum is L.\n"
        ".glb / .gltf (+ .bin): glTF 2.0 in metres, COLOR_0 = L x 2^EV clamped to [0, 1] (linear, what an\n"
        "engine shows), _L the radiance itself; --per-bounce adds the radiance attributes _E, _KE, ..., _REST\n"
        "and the colour sets COLOR_1, COLOR_2, ... of the terms at COLOR_0's scale (Blender 3.4 imports those\n"
        "as Col.001, Col.002, ...); unlit materials with the reflectance in their extras, provenance in the\n"
        "asset's extras. --for blender: what Blender 3.4 shows as meant (PLY, OBJ: 8-bit sRGB as --ldr).";
    bn_optset_add(set, (bn_opt){"output", 'o', BN_OPT_STRING, &a->out, NULL, 0, 0, "FILE",
                                 "baked mesh: .ply, .om, .obj, .glb or .gltf (default baked.ply)"});
    bn_optset_add(set, (bn_opt){"crease", 0, BN_OPT_DOUBLE, &a->crease, NULL, 0, 180, "DEG",
                                 "faces whose normals differ by more do not share vertices (default 30)"});
    bn_optset_add(set, (bn_opt){"flat", 0, BN_OPT_FLAG, &a->flat, NULL, 0, 0, NULL,
                                 "every patch its own vertices, each with its patch's value (no blending: the patches "
                                 "as the solve sees them)"});
    bn_optset_add(set, (bn_opt){"ldr", 0, BN_OPT_FLAG, &a->ldr, NULL, 0, 0, NULL,
                                 "8-bit sRGB colours at --exposure instead of float radiance"});
    bn__bake_vertex_options(set, a);
    bn_optset_add(set, (bn_opt){"no-colour-sets", 0, BN_OPT_FLAG, &a->no_colour_sets, NULL, 0, 0, NULL,
                                 "glTF with --per-bounce: the terms as float attributes only, no COLOR_1 .. "
                                 "(smaller; engines and the viewer read the float ones)"});
    bn_optset_add(set, (bn_opt){"for", 0, BN_OPT_STRING, &a->for_tool, NULL, 0, 0, "TOOL",
                                 "blender: colours as Blender 3.4 shows them (PLY, OBJ: --ldr; glTF as always), and "
                                 "how to import the file"});
    bn_optset_add(set, (bn_opt){"exposure", 0, BN_OPT_DOUBLE, &a->ev, NULL, -64, 64, "EV",
                                 "--ldr: value * 2^EV before sRGB (default: auto, the 99th percentile of the "
                                 "patches' L at 0.9)"});
    bn_optset_add(set, (bn_opt){"per-bounce", 0, BN_OPT_FLAG, &a->per_bounce, NULL, 0, 0, NULL,
                                 "also write each term E .. K^K E and rest as float vertex properties (PLY, OM, glTF)"});
    bn_optset_add(set, (bn_opt){"bounces", 'n', BN_OPT_INT, &a->n, NULL, 0, 64, "K",
                                 "--per-bounce: terms E .. K^K E (default 3)"});
    bn_optset_add(set, (bn_opt){"mesh", 0, BN_OPT_CHOICE, &a->mesh, bn_bake_mesh_names(), 0, 0, bn_bake_mesh_names(),
                                 "faces written: every patch, the element mesh the solution lives on, whose vertices "
                                 "include every input vertex (default); or the scene's input polygons alone, each "
                                 "corner the mean of the patches around it"});
    bn_cli_add_solution(set, &a->sol);
    bn_cli_add_ff(set, &a->ff);
    bn_cli_add_scene(set, &a->so);
    bn_cli_add_common(set, c);
}

/* The options that go together, and the output's format. */
static bn_status bn__bake_check(const bn_optset *set, bn__bake_cli *a, bn_error *err)
{
    const char *dot = strrchr(a->out, '.');
    if (a->flat && bn_cli_given(set, "crease"))
        return bn_error_set(err, BN_EUSAGE, "--flat and --crease: a flat bake shares no vertices, so no crease applies");
    if (!dot || (strcmp(dot, ".ply") && strcmp(dot, ".om") && strcmp(dot, ".obj") && strcmp(dot, ".glb") &&
                 strcmp(dot, ".gltf")))
        return bn_error_set(err, BN_EUSAGE, "-o %s: bake writes .ply, .om, .obj, .glb or .gltf", a->out);
    a->is_gltf = strcmp(dot, ".glb") == 0 || strcmp(dot, ".gltf") == 0;
    if (a->for_tool && strcmp(a->for_tool, "blender") != 0)
        return bn_error_set(err, BN_EUSAGE, "--for %s: the tool bounce knows is blender", a->for_tool);
    if (a->gather == BN_GATHER_FINAL && !a->flat && a->per_bounce && a->n < 1)
        return bn_error_set(err, BN_EUSAGE, "--per-bounce -n 0 with --gather final: the gather at the vertices needs "
                            "KE kept (-n 1 or more), or --gather none");
    if ((bn_cli_given(set, "bake-vertices") || bn_cli_given(set, "bake-tol")) &&
        (a->flat || a->gather != BN_GATHER_FINAL || a->mesh != BN_BAKE_ELEMENTS))
        return bn_error_set(err, BN_EUSAGE, "--bake-vertices, --bake-tol: the refined mesh is the element mesh's with "
                            "the gather at its vertices (not with --flat, --gather none or --mesh input)");
    if (a->flat || a->gather != BN_GATHER_FINAL || a->mesh != BN_BAKE_ELEMENTS)
        a->bake_vertices = 0;
    if (a->for_tool && a->no_colour_sets)
        return bn_error_set(err, BN_EUSAGE, "--for blender and --no-colour-sets: Blender imports colour sets only");
    if (a->for_tool && !a->is_gltf)
        a->ldr = 1;   /* Blender reads a PLY's colours as 8-bit sRGB: the display colours */
    if (a->per_bounce && strcmp(dot, ".obj") == 0)
        return bn_error_set(err, BN_EUSAGE, "--per-bounce needs .ply or .om (OBJ holds one colour per vertex)");
    return BN_OK;
}

/* L first, then (per bounce) E .. K^n E and rest; names: nl slots. */
static bn_status bn__bake_layers(const bn__bake_cli *a, const bn_pipeline *p, bn_bake_layer **layers,
                                 char (**names)[16], size_t *nl, bn_error *err)
{
    *nl = a->per_bounce ? (size_t)bn_layer_count(a->n) : 1;
    *layers = bn__calloc(*nl, sizeof **layers);
    *names = bn__calloc(*nl, sizeof **names);
    if (!*layers || !*names)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    (*layers)[0] = (bn_bake_layer){"L", p->res.L, NULL};
    for (size_t l = 1; l < *nl; l++) {
        int layer = (int)l - 1;
        bn_layer_name(layer, a->n, (*names)[l], sizeof (*names)[l]);
        (*layers)[l] = (bn_bake_layer){(*names)[l], layer <= a->n ? p->res.terms[layer] : p->rest, NULL};
    }
    return BN_OK;
}

/* How the colours are written, for the provenance and the summary line. */
static void bn__bake_colours(const bn__bake_cli *a, char *buf, size_t n)
{
    if (a->is_gltf)
        snprintf(buf, n, "COLOR_0 L x 2^%+.4f clamped to [0, 1], linear%s; _L radiance W m^-2 sr^-1", a->ev,
                 a->per_bounce && !a->no_colour_sets ? ", COLOR_1 .. the terms alike" : "");
    else if (a->ldr)
        snprintf(buf, n, "8-bit sRGB at %+.4f EV", a->ev);
    else
        snprintf(buf, n, "float radiance, W m^-2 sr^-1");
}

/* The bake written with its provenance: how it was made, down to the crease and the colours. */
static bn_status bn__bake_write(const bn__bake_cli *a, const bn_cli_common *c, const bn_pipeline *p,
                                const bn_bake *bake, const bn_bake_layer *layers, size_t nl, const char *solver,
                                bn_error *err)
{
    char ffdesc[256], patches[32], evbuf[160], creasebuf[32], verts[32], tolbuf[64], gatherbuf[256], refbuf[320];
    int elements = a->mesh == BN_BAKE_ELEMENTS;
    bn_formfactor_opts fo;
    bn_bake_write_opts wo;
    bn_cli_ff_opts(&a->ff, c, &fo);
    bn_formfactor_opts_describe(&fo, ffdesc, sizeof ffdesc);
    snprintf(patches, sizeof patches, "%zu", p->n);
    if (elements)
        snprintf(verts, sizeof verts, "%zu", bn_bake_vertex_count(bake));
    else
        snprintf(verts, sizeof verts, "input polygons' corners");
    if (a->flat)
        snprintf(creasebuf, sizeof creasebuf, "flat (no shared vertices)");
    else
        snprintf(creasebuf, sizeof creasebuf, "%g degrees", a->crease);
    bn__bake_colours(a, evbuf, sizeof evbuf);
    snprintf(tolbuf, sizeof tolbuf, "%g", a->sol.tol > 0 ? a->sol.tol : 1e-6);
    if (a->bake_vertices)
        snprintf(refbuf, sizeof refbuf, "the element mesh's triangles bisected (longest edge first, no T-junction) where "
                 "L differs by more than %g relative between an edge's ends and its probed midpoint is off their mean by as "
                 "much, up to %zu vertices: %zu triangles",
                 a->bake_tol, a->bake_vertices, bn_bake_face_count(bake));
    else
        snprintf(refbuf, sizeof refbuf, "none (the patches as faces)");
    snprintf(gatherbuf, sizeof gatherbuf, "each layer by the final gather at the vertex, 1%% into one of its patches: KE in "
             "closed form (%d shadow rays a face), K2E and beyond from %d hemisphere rays, seed %llu", BN_BAKE_GATHER_LIGHT,
             a->gather_rays, (unsigned long long)c->seed);
    bn_attr attrs[] = {
        {"command line", c->cmdline}, {"scene", bn_scene_path(p->scene)}, {"solver", solver}, {"tolerance", tolbuf},
        {"form factors", ffdesc},      {"patches", patches},          {"vertices", verts}, {"crease", creasebuf},
        {"colours", evbuf},           {"faces", elements ? "the patches (element mesh)" : "the input polygons"},
        {"refinement", refbuf},
        {"vertex colour", a->flat ? "L of the vertex's own patch (flat: no vertex shared between patches)"
                          : a->gather == BN_GATHER_FINAL ? gatherbuf
                                                         : "L, area-weighted mean of the patches around the vertex within "
                                                           "its smooth surface (gather none)"},
    };
    memset(&wo, 0, sizeof wo);
    wo.input_mesh = !elements;
    wo.ldr = a->ldr;
    wo.colour_sets = !a->no_colour_sets;
    wo.exposure_ev = a->ev;
    wo.attrs = attrs;
    wo.nattrs = sizeof attrs / sizeof attrs[0];
    return bn_bake_write(bake, a->out, layers, nl, &wo, err);
}

static void bn__bake_summary(const bn__bake_cli *a, const bn_pipeline *p, const bn_bake *bake)
{
    char evbuf[160];
    size_t nf;
    bn_scene_faces(p->scene, &nf);
    bn__bake_colours(a, evbuf, sizeof evbuf);
    if (a->mesh == BN_BAKE_ELEMENTS)
        printf("wrote %s (the element mesh%s: %zu vertices, %zu faces in %zu patches; %s%s)\n", a->out,
               a->bake_vertices ? " refined where L changes" : "", bn_bake_vertex_count(bake), bn_bake_face_count(bake),
               p->n, evbuf, a->per_bounce ? "; per-bounce properties E .. rest" : "");
    else
        printf("wrote %s (the input mesh: %zu polygons; %s%s)\n", a->out, nf, evbuf,
               a->per_bounce ? "; per-bounce properties E .. rest" : "");
}

/* The final gather at a batch of the bake's vertices (bn_bake_eval_fn): E, KE, ..., rest, L. Each batch
 * after the first draws streams of its own (the seed mixed with its first vertex's number). */
/* Each bake vertex's values by the final gather, the mesh refined where L changes first
 * (bn_pipeline_bake_gather, with the command line's rays, budget, tolerance and seed). */
static bn_status bn__bake_gather(const bn__bake_cli *a, const bn_cli_common *c, const bn_pipeline *p, bn_bake *bake,
                                 bn_bake_layer *layers, size_t nl, double **vbuf, bn_error *err)
{
    bn_log lg = {bn_cli_log, (void *)c, c->quiet};
    bn_bake_gather_opts go;
    bn_bake_gather_opts_default(&go);
    go.gather_rays = a->gather_rays;
    go.max_vertices = a->bake_vertices;
    go.tol = a->bake_tol;
    go.seed = c->seed;
    go.threads = c->threads;
    go.quiet = c->quiet;
    go.log = &lg;
    return bn_pipeline_bake_gather(p, bake, &go, layers, nl, vbuf, err);
}

/* What the file needs to show as meant where it is opened (Blender 3.4 as Debian ships it). */
static void bn__bake_hints(const bn__bake_cli *a)
{
    if (a->is_gltf && a->for_tool)
        printf("Blender 3.4: File > Import > glTF 2.0 with Shading: Flat (Debian's Blender fails in the default "
               "shading path: numpy has no attribute bool); headless: bpy.ops.import_scene.gltf(filepath='%s', "
               "import_shading='FLAT'). L is the colour attribute Col%s\n", a->out,
               a->per_bounce ? ", the terms Col.001, Col.002, ... in the order E, KE, K2E, ..., rest" : "");
    else if (a->is_gltf && a->ldr)
        printf("note: --ldr changes nothing in glTF: its colour sets are linear display colours already (COLOR_0 = L "
               "x 2^EV, clamped)\n");
    else if (a->for_tool)
        printf("Blender 3.4: File > Import > Stanford (.ply): the colours are 8-bit sRGB at the exposure, as Blender "
               "shows vertex colours\n");
    else if (!a->ldr && !strcmp(strrchr(a->out, '.'), ".ply"))
        printf("note: a float PLY imports into Blender as 8-bit colours, clamped and dark; --for blender writes the "
               "display colours it shows as meant (or bake to .glb)\n");
}

/* The bake's vertices, leaving out patches inside closed objects, and the exposure. */
static bn_status bn__bake_make(bn__bake_cli *a, const bn_optset *set, const bn_cli_common *c, const bn_pipeline *p,
                               bn_bake **bake, bn_error *err)
{
    bn_status st = bn_bake_create(p->scene, a->flat ? BN_BAKE_FLAT : a->crease, bake, err);
    if (st != BN_OK)
        return st;
    if (!a->flat && p->rt) {
        size_t enc = bn_bake_exclude_enclosed(*bake, p->rt);
        if (enc && !c->quiet)
            fprintf(stderr, "bounce: bake: %zu patches inside closed objects (under the blocks) left out of the "
                            "vertex averages\n", enc);
    }
    if ((a->ldr || a->is_gltf) && !bn_cli_given(set, "exposure"))
        a->ev = bn_bake_auto_exposure(p->res.L, p->n);
    return BN_OK;
}

int bn_cmd_bake(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn__bake_cli a;
    const char *pos[1];
    size_t nl = 1;
    int rc = 0, prc;
    bn_error err;
    bn_pipeline p;
    bn_bake *bake = NULL;
    bn_bake_layer *layers = NULL;
    char (*names)[16] = NULL;
    double *vbuf = NULL;
    char solver[256];
    bn_status st;

    memset(&p, 0, sizeof p);
    bn_error_clear(&err);
    bn__bake_options(&set, &a, c);
    if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
        return prc;
    if (bn__bake_check(&set, &a, &err) != BN_OK)
        return bn_cli_fail(&err);
    int gather = a.gather == BN_GATHER_FINAL && !a.flat;   /* a flat bake is the patches' values */
    st = bn_cli_run_solution(pos[0], &a.so, &a.ff, &a.sol, c, a.per_bounce ? a.n : gather, &p, solver, sizeof solver);
    if (st != BN_OK)
        rc = bn_status_exit_code(st);
    else if (bn__bake_layers(&a, &p, &layers, &names, &nl, &err) != BN_OK ||
             bn__bake_make(&a, &set, c, &p, &bake, &err) != BN_OK ||
             (gather && bn__bake_gather(&a, c, &p, bake, layers, nl, &vbuf, &err) != BN_OK) ||
             bn__bake_write(&a, c, &p, bake, layers, nl, solver, &err) != BN_OK)
        rc = bn_cli_fail(&err);
    else if (!c->quiet && !c->no_summary) {
        bn__bake_summary(&a, &p, bake);
        bn__bake_hints(&a);
    }
    free(layers);
    free(names);
    free(vbuf);
    bn_bake_destroy(bake);
    bn_pipeline_free(&p);
    if (rc == 0 && bn_interrupted() != BN_OK)
        rc = bn_cli_interrupted();
    return rc;
}
