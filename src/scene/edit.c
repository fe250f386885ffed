/* Material edits (include/bounce/scene.h): a named material's reflectance or emitted radiance
 * replaced after loading, for the command line's --set-rho and --set-Le and for relighting a solved
 * scene (bn_pipeline_relight). Nothing geometric changes, so the form factors stay valid. */
#include "scene/scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* "R,G,B" or "V" into v[3]; 0, or -1 when it is neither. */
static int bn__parse_rgb(const char *s, double v[3])
{
    char *end;
    for (int c = 0; c < 3; c++) {
        v[c] = strtod(s, &end);
        if (end == s)
            return -1;
        if (c == 0 && *end == '\0') {
            v[1] = v[2] = v[0];
            return 0;
        }
        if (c < 2 && *end != ',')
            return -1;
        s = end + (c < 2);
    }
    return *end == '\0' ? 0 : -1;
}

/* The values of e checked: rho in [0, 1], Le finite and >= 0. */
static bn_status bn__edit_check(const bn_material_edit *e, bn_error *err)
{
    for (int c = 0; c < 3; c++) {
        if (e->has_rho && !(e->rho[c] >= 0 && e->rho[c] <= 1))
            return bn_error_set(err, BN_EUSAGE, "material '%s': reflectance %g is outside [0, 1]", e->material,
                                e->rho[c]);
        if (e->has_Le && !(e->Le[c] >= 0 && isfinite(e->Le[c])))
            return bn_error_set(err, BN_EUSAGE, "material '%s': emitted radiance %g is not a finite value >= 0",
                                e->material, e->Le[c]);
    }
    return BN_OK;
}

bn_status bn_material_edit_parse(const char *what, const char *text, bn_material_edit *e, bn_error *err)
{
    const char *eq = text ? strrchr(text, '=') : NULL;
    double v[3];
    int rho = what && !strcmp(what, "rho");
    memset(e, 0, sizeof *e);
    if (!eq || eq == text || (size_t)(eq - text) >= sizeof e->material || bn__parse_rgb(eq + 1, v) != 0)
        return bn_error_set(err, BN_EUSAGE, "`set_%s` '%s' is not MATERIAL=R,G,B or MATERIAL=V", rho ? "rho" : "Le",
                            text ? text : "");
    memcpy(e->material, text, (size_t)(eq - text));
    e->has_rho = rho;
    e->has_Le = !rho;
    memcpy(rho ? e->rho : e->Le, v, sizeof v);
    return bn__edit_check(e, err);
}

/* The index of material `name` in s, or nmats. */
static size_t bn__material_index(const bn_scene *s, const char *name)
{
    size_t m = 0;
    while (m < s->nmats && strcmp(s->mats[m].name, name) != 0)
        m++;
    return m;
}

/* BN_EUSAGE for an unknown name, listing the scene's materials (the first 12). */
static bn_status bn__unknown_material(const bn_scene *s, const char *name, bn_error *err)
{
    char list[600] = "";
    size_t len = 0;
    for (size_t m = 0; m < s->nmats && m < 12 && len < sizeof list; m++)
        len += (size_t)snprintf(list + len, sizeof list - len, "%s%s", m ? ", " : "", s->mats[m].name);
    return bn_error_set(err, BN_EUSAGE, "'%s' is not a material of %s (its %zu: %s%s)", name, s->path, s->nmats, list,
                        s->nmats > 12 ? ", ..." : "");
}

bn_status bn_scene_edit_materials(bn_scene *s, const bn_material_edit *e, size_t n, bn_error *err)
{
    bn_status st;
    for (size_t k = 0; k < n; k++) {   /* all checked before any is applied */
        if (bn__material_index(s, e[k].material) == s->nmats)
            return bn__unknown_material(s, e[k].material, err);
        if ((st = bn__edit_check(&e[k], err)) != BN_OK)
            return st;
    }
    for (size_t k = 0; k < n; k++) {
        bn_material *m = &s->mats[bn__material_index(s, e[k].material)];
        if (e[k].has_rho)
            memcpy(m->rho, e[k].rho, sizeof m->rho);
        if (e[k].has_Le)
            memcpy(m->Le, e[k].Le, sizeof m->Le);
    }
    return BN_OK;   /* a textured patch's reflectance is its material's times its texture's mean */
}
