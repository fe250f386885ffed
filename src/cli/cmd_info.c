/* `bounce info SCENE`: faces, patches, emitters, materials, bounds, area, power, memory. */
#include "cli/cli.h"
#include "bounce/pipeline.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

static void bn__bytes(double b, char *buf, size_t n)
{
    const char *u[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB"};
    int i = 0;
    while (b >= 1024 && i < 5) {
        b /= 1024;
        i++;
    }
    snprintf(buf, n, "%.3g %s", b, u[i]);
}

/* The objects (the file's groups or the material names' prefixes), with their faces, the largest
 * first (at most 24 named). */
static void bn__info_objects(const bn_scene *s)
{
    size_t nf, no = bn_scene_object_count(s), *count = bn__calloc(no + 1, sizeof(size_t));
    const bn_face *faces = bn_scene_faces(s, &nf);
    char *shown = bn__calloc(no + 1, 1);
    if (count && shown) {
        for (size_t f = 0; f < nf; f++)
            count[faces[f].object]++;
        printf("objects     %zu (%s):", no,
               bn_scene_objects_from_file(s) ? "the file's o/g groups" : "material-name prefixes");
        for (size_t n = 0; n < no && n < 24; n++) {
            size_t best = SIZE_MAX;
            for (size_t k = 0; k < no; k++)
                if (!shown[k] && (best == SIZE_MAX || count[k] > count[best]))
                    best = k;
            shown[best] = 1;
            printf("%s %s %zu", n ? "," : "", bn_scene_object_name(s, best), count[best]);
        }
        printf("%s faces\n", no > 24 ? ", ..." : "");
    }
    free(count);
    free(shown);
}

/* Polygons wound against their vertex normals, per object (faces: a split polygon counts per face). */
static void bn__info_orientation(const bn_scene *s)
{
    size_t nf, no = bn_scene_object_count(s), *count = bn__calloc(no + 1, sizeof(size_t)), shown = 0;
    const bn_face *faces = bn_scene_faces(s, &nf);
    bn_scene_stats st = bn_scene_stats_get(s);
    if (!count)
        return;
    if (!st.with_normals)
        printf("orientation by winding (no vertex normals in the file)\n");
    else if (!st.winding_disagree)
        printf("orientation all %zu polygons with vertex normals are wound the way they point\n", st.with_normals);
    else {
        for (size_t f = 0; f < nf; f++)
            count[faces[f].object] += faces[f].vn < 0;
        printf("orientation %zu of %zu polygons with vertex normals wound against them (the most opposed at line %u), "
               "%s; faces per object:", st.winding_disagree, st.with_normals, st.winding_worst_line,
               st.flipped ? "turned to agree" : "kept as wound (--orient winding)");
        for (size_t k = 0; k < no; k++)
            if (count[k] && shown++ < 24)
                printf("%s %s %zu", shown > 1 ? "," : "", bn_scene_object_name(s, k), count[k]);
        printf("%s\n", shown > 24 ? ", ..." : "");
    }
    free(count);
}

/* The punctual lights: each with its place, its intensity and its power. */
static void bn__info_lights(const bn_scene *s)
{
    static const char *type[] = {"point", "spot", "directional"};
    size_t n;
    const bn_light *l = bn_scene_lights(s, &n);
    for (size_t k = 0; k < n; k++) {
        double w[3];
        bn_light_power(&l[k], w);
        printf("light       %s '%s'", type[l[k].type], l[k].name);
        if (l[k].type != BN_LIGHT_DIRECTIONAL)
            printf(" at (%.6g, %.6g, %.6g)", l[k].pos[0], l[k].pos[1], l[k].pos[2]);
        if (l[k].type != BN_LIGHT_POINT)
            printf(" towards (%.4g, %.4g, %.4g)", l[k].dir[0] + 0.0, l[k].dir[1] + 0.0, l[k].dir[2] + 0.0);
        if (l[k].type == BN_LIGHT_DIRECTIONAL)
            printf("; %.6g %.6g %.6g W m^-2 on a surface facing it\n", l[k].I[0], l[k].I[1], l[k].I[2]);
        else
            printf("; %.6g %.6g %.6g W sr^-1%s; power %.6g %.6g %.6g W\n", l[k].I[0], l[k].I[1], l[k].I[2],
                   l[k].type == BN_LIGHT_SPOT ? " on its axis" : "", w[0], w[1], w[2]);
    }
}

/* Faces, vertices, bounds, area, emitters, punctual lights, patches, contacts and dense K's size. */
static void bn__info_summary(const bn_scene *s, const bn_cli_scene *so)
{
    size_t nf, np, nv;
    const bn_face *faces = bn_scene_faces(s, &nf);
    bn_scene_stats st = bn_scene_stats_get(s);
    double lo[3], hi[3], total = 0, watts[3], m = bn_unit_to_metres(bn_scene_unit(s));
    const char *unit = bn_unit_name(bn_scene_unit(s));
    char buf[64];
    bn_scene_patches(s, &np);
    bn_scene_vertices(s, &nv);
    bn_scene_bounds(s, lo, hi);
    for (size_t f = 0; f < nf; f++)
        total += faces[f].area;
    bn_scene_emitted_power(s, watts);
    printf("scene       %s\n", bn_scene_path(s));
    printf("unit        %s (areas below in %s^2; powers in W)\n", unit, unit);
    printf("polygons    %zu read; %zu faces after validation (%zu non-planar split, %zu triangulated, "
           "%zu degenerate dropped, %zu duplicates dropped)\n",
           st.input_polygons, nf, st.nonplanar_split, st.polygons_triangulated, st.degenerate_dropped,
           st.duplicates_dropped);
    printf("vertices    %zu\n", nv);
    printf("bounds      (%.6g, %.6g, %.6g) .. (%.6g, %.6g, %.6g)\n", lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
    printf("total area  %.10g %s^2 (%.6g m^2)\n", total, unit, total * m * m);
    printf("emitters    %zu face%s; emitted power %.6g %.6g %.6g W (R G B; pi * sum A Le)\n",
           bn_scene_emitter_count(s), bn_scene_emitter_count(s) == 1 ? "" : "s", watts[0], watts[1], watts[2]);
    bn__info_lights(s);
    printf("patches     %zu (largest patch edge %.6g %s)\n", np, bn_scene_largest_patch_edge(s), unit);
    printf("contacts    %zu segments on %zu faces split %zu patches into %zu%s\n", st.contact_segments,
           st.contact_faces, st.contact_patches_split, st.contact_patches_made,
           so->no_contacts                                        ? " (--no-contacts)"
           : so->self_contacts || bn_scene_object_count(s) < 2 ? " (inside objects too)"
                                                               : " (between objects only; --self-contacts: inside them too)");
    bn__info_objects(s);
    bn__info_orientation(s);
    bn__bytes((double)np * (double)np * 4.0, buf, sizeof buf);
    printf("dense K     %s as float (N^2 x 4 bytes; F is stored once for all channels)\n", buf);
}

/* What auto would choose, and the hierarchy's size: its nodes exactly, its links as the range seen
 * at the default eps (15 to 250 links per patch, Cornell box to bunny box); how long a link takes
 * is a measured figure, in bench/results.md, not here. */
static void bn__info_hierarchy(const bn_scene *s, const bn_cli_scene *so, bn_cli_common *c)
{
    bn_pipeline_opts po;
    char why[200], b1[32], b2[32], b3[32];
    size_t nf, np;
    int mesh_given = so->patch_size > 0 || so->patches || so->no_subdivide;
    bn_scene_faces(s, &nf);
    bn_scene_patches(s, &np);
    size_t nh = np;
    bn_cli_pipeline_opts(so, NULL, NULL, c, &po);
    po.transport = "auto";
    int h = bn_pipeline_use_hierarchy(&po, np, why, sizeof why);
    printf("transport   auto chooses %s: %s\n", h ? "hierarchical" : "dense", why);
    if (!mesh_given && nh < nf + BN_HIERARCHY_EXTRA_PATCHES)
        nh = nf + BN_HIERARCHY_EXTRA_PATCHES;   /* its default mesh aims at this */
    bn__bytes((double)(2 * nh) * 88.0, b1, sizeof b1);
    bn__bytes((double)nh * 15 * 8.0, b2, sizeof b2);
    bn__bytes((double)nh * 250 * 8.0, b3, sizeof b3);
    printf("hierarchy   %s%zu patches, %zu nodes (%s); at eps %g typically 15 to 250 links per patch (%s to %s "
           "at 8 bytes a link, twice that while refining; time per link: bench/results.md)\n",
           mesh_given ? "" : "about ", nh, 2 * nh - 1, b1, BN_HIERARCHY_EPS_DEFAULT, b2, b3);
}

/* The materials with their faces and areas, then the faces (64 unless all). */
static void bn__info_tables(const bn_scene *s, int all_faces)
{
    size_t nf, nm;
    const bn_face *faces = bn_scene_faces(s, &nf);
    const bn_material *mats = bn_scene_materials(s, &nm);
    printf("\nmaterials   %zu\n", nm);
    printf("  %-3s %-20s %-26s %-26s %6s %14s\n", "id", "name", "rho", "Le (W m^-2 sr^-1)", "faces", "area");
    for (size_t i = 0; i < nm; i++) {
        size_t count = 0;
        double a = 0;
        for (size_t f = 0; f < nf; f++)
            if (faces[f].material == i) {
                count++;
                a += faces[f].area;
            }
        printf("  %-3zu %-20s %-8.4g %-8.4g %-8.4g %-8.4g %-8.4g %-8.4g %6zu %14.10g\n", i, mats[i].name,
               mats[i].rho[0], mats[i].rho[1], mats[i].rho[2], mats[i].Le[0], mats[i].Le[1], mats[i].Le[2], count, a);
    }
    for (size_t i = 0; i < nm; i++) {
        const char *tn;
        int w, h;
        double mean[3];
        if (bn_scene_material_texture(s, i, &tn, &w, &h, mean))
            printf("  %-3zu %-20s x texture %s (%d x %d, mean %.4g %.4g %.4g): each patch takes its mean over the patch\n",
                   i, mats[i].name, tn, w, h, mean[0], mean[1], mean[2]);
    }
    printf("\nfaces       (front = right-hand rule of the vertex order; triangles of a split polygon share its line)\n");
    printf("  %-5s %-6s %-20s %-5s %18s  %s\n", "face", "line", "material", "verts", "area", "normal");
    for (size_t f = 0; f < nf && (f < 64 || all_faces); f++)
        printf("  %-5zu %-6u %-20s %-5u %18.12g  (%.4f, %.4f, %.4f)\n", f, faces[f].line, mats[faces[f].material].name,
               faces[f].nverts, faces[f].area, faces[f].normal[0], faces[f].normal[1], faces[f].normal[2]);
    if (nf > 64 && !all_faces)
        printf("  ... %zu more (--all-faces lists them)\n", nf - 64);
}

int bn_cmd_info(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn_cli_scene so;
    const char *pos[1];
    int all_faces = 0, prc;
    bn_error err;
    bn_scene *s = NULL;
    bn_status st;

    memset(&set, 0, sizeof set);
    memset(&so, 0, sizeof so);
    set.usage = "bounce info SCENE [meshing options]";
    set.summary = "Loads and validates SCENE (.obj with .mtl, .ply, .off), meshes it into patches and prints\n"
                  "its faces, patches, emitters, materials, bounding box, total area, emitted power and the\n"
                  "memory a dense K would take (N^2 floats).";
    bn_cli_add_scene(&set, &so);
    bn_optset_add(&set, (bn_opt){"all-faces", 0, BN_OPT_FLAG, &all_faces, NULL, 0, 0, NULL,
                                 "list every face even when there are more than 64"});
    bn_cli_add_common(&set, c);
    bn_error_clear(&err);
    if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
        return prc;
    /* meshed as `bounce solve` would (the hierarchy's mesh for a large scene) */
    if ((st = bn_cli_load_scene(pos[0], &so, c, "auto", &s)) != BN_OK)
        return bn_status_exit_code(st);
    bn__info_summary(s, &so);
    bn__info_hierarchy(s, &so, c);
    bn__info_tables(s, all_faces);
    bn_scene_destroy(s);
    return 0;
}
