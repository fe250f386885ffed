/* Objects: what counts and partitions group faces by (bounce info's table, contact cuts between
 * objects, the cross-check's regions). A file's own groups when it names two or more (OBJ `o`/`g`);
 * else the material names' prefixes up to the first '_' (a furniture export's `couch_Fabric`,
 * `couch_Chrome`: one object "couch"; `wall`: its own), which is how scenes assembled from
 * libraries are usually named. An object is an assembly (one model, whose own touching parts need
 * no contact cuts) when it is a file's group or a prefix before a '_'; a material named without
 * one ("white" on a floor and the block standing on it) is not. */
#include "scene/scene_internal.h"

#include <stdlib.h>
#include <string.h>

/* Objects from the material names' prefixes (of the materials some face uses): per material, its
 * object's index into mobj. */
static bn_status bn__objects_from_materials(bn_scene *sc, unsigned *mobj)
{
    size_t cap = 0, acap = 0;
    for (size_t f = 0; f < sc->nfaces; f++)
        mobj[sc->faces[f].material] = 1;   /* used */
    for (size_t m = 0; m < sc->nmats; m++) {
        char key[BN_NAME_MAX];
        size_t k, before = sc->nobjs;
        if (!mobj[m])
            continue;
        snprintf(key, sizeof key, "%s", sc->mats[m].name);
        key[strcspn(key, "_")] = '\0';
        if (!key[0])
            snprintf(key, sizeof key, "%s", sc->mats[m].name);
        if ((k = bn__name_index(&sc->objnames, &sc->nobjs, &cap, key)) == SIZE_MAX)
            return BN_ENOMEM;
        if (!bn__grow((void **)&sc->obj_assembly, &acap, sc->nobjs, 1))
            return BN_ENOMEM;
        if (sc->nobjs > before)
            sc->obj_assembly[k] = 0;
        sc->obj_assembly[k] |= strcmp(key, sc->mats[m].name) != 0;   /* a prefix before a '_' */
        mobj[m] = (unsigned)k;
    }
    return BN_OK;
}

bn_status bn__scene_objects(bn_scene *sc, const bn__soup *s)
{
    unsigned *mobj;
    bn_status st;
    if (s->obj && s->nobjs >= 2) {
        if (!(sc->objnames = bn__malloc_array(s->nobjs, sizeof *sc->objnames)))
            return BN_ENOMEM;
        memcpy(sc->objnames, s->objnames, s->nobjs * sizeof *sc->objnames);
        if (!(sc->obj_assembly = bn__malloc_array(s->nobjs, 1)))
            return BN_ENOMEM;
        memset(sc->obj_assembly, 1, s->nobjs);
        sc->nobjs = s->nobjs;
        sc->objects_from_file = 1;
        for (size_t f = 0; f < sc->nfaces; f++)
            sc->faces[f].object = s->obj[sc->faces[f].source];
        return BN_OK;
    }
    if (!(mobj = bn__calloc(sc->nmats + 1, sizeof *mobj)))
        return BN_ENOMEM;
    st = bn__objects_from_materials(sc, mobj);
    for (size_t f = 0; st == BN_OK && f < sc->nfaces; f++)
        sc->faces[f].object = mobj[sc->faces[f].material];
    free(mobj);
    return st;
}

size_t bn_scene_object_count(const bn_scene *s) { return s->nobjs; }
const char *bn_scene_object_name(const bn_scene *s, size_t k) { return k < s->nobjs ? s->objnames[k] : "?"; }
int bn_scene_objects_from_file(const bn_scene *s) { return s->objects_from_file; }
int bn_scene_object_is_assembly(const bn_scene *s, size_t k) { return k < s->nobjs && s->obj_assembly[k]; }
