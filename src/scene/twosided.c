/* Two-sided surfaces. bounce's surfaces are one-sided (the front by the right-hand rule); a face
 * whose material is marked two-sided (a leaf, a thin panel, cloth, a sheet of paper) reflects and
 * emits on both sides, each with its own radiance. It becomes two faces back to back sharing its
 * corners: the face, and after it its back side, wound the other way (bn_face.back). Everything
 * downstream (patches, form factors, the solve, the tracer, the gather, bakes) then sees two
 * one-sided surfaces, and the ray caster returns, of two patches at one distance, the one whose
 * front the ray meets (src/rt/rt.c). */
#include "scene/scene_internal.h"

#include <stdlib.h>
#include <string.h>

/* Marks the materials `spec` names ("all", or names separated by commas) two-sided; an unknown
 * name is an error that names it and the file. */
static bn_status bn__mark(bn_scene *sc, const char *path, const char *spec, unsigned char *two, bn_error *err)
{
    const char *p = spec;
    if (strcmp(spec, "all") == 0) {
        memset(two, 1, sc->nmats);
        return BN_OK;
    }
    while (*p) {
        size_t len = strcspn(p, ","), m = 0;
        while (m < sc->nmats && !(strlen(sc->mats[m].name) == len && strncmp(sc->mats[m].name, p, len) == 0))
            m++;
        if (len == 0 || m == sc->nmats)
            return bn_error_set(err, BN_EUSAGE, "two-sided material '%.*s' is not a material of %s", (int)len, p, path);
        two[m] = 1;
        p += len + (p[len] == ',');
    }
    return BN_OK;
}

/* Face f's back side, appended: its corners in reverse order, the normal negated. */
static int bn__append_back(bn_scene *sc, size_t f, size_t *faces_cap, size_t *fidx_cap)
{
    bn_face *b;
    if (!bn__grow((void **)&sc->faces, faces_cap, sc->nfaces + 1, sizeof *sc->faces) ||
        !bn__grow((void **)&sc->fidx, fidx_cap, sc->nfidx + sc->faces[f].nverts, sizeof *sc->fidx))
        return 0;
    b = &sc->faces[sc->nfaces];
    *b = sc->faces[f];
    b->first = sc->nfidx;
    b->back = 1;
    for (int k = 0; k < 3; k++)
        b->normal[k] = -b->normal[k];
    for (unsigned k = 0; k < b->nverts; k++)
        sc->fidx[sc->nfidx + k] = sc->fidx[sc->faces[f].first + b->nverts - 1 - k];
    sc->nfidx += b->nverts;
    sc->nfaces++;
    return 1;
}

bn_status bn__scene_two_sided(bn_scene *sc, const char *path, const unsigned char *file_two, size_t nfile_two,
                              const char *spec, bn_error *err)
{
    unsigned char *two;
    size_t nf = sc->nfaces, faces_cap = sc->nfaces, fidx_cap = sc->nfidx;
    bn_status st = BN_OK;
    if (spec && strncmp(spec, "none", 4) == 0 && (spec[4] == '\0' || spec[4] == ',')) {
        file_two = NULL;   /* "none": the file's marks dropped; "none,NAMES": only these */
        spec += spec[4] ? 5 : 4;
    }
    if ((!spec || !spec[0]) && !file_two)
        return BN_OK;
    if (!(two = bn__calloc(sc->nmats + 1, 1)))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    if (file_two)
        for (size_t m = 0; m < sc->nmats && m < nfile_two; m++)
            two[m] = file_two[m] != 0;
    if (spec && spec[0])
        st = bn__mark(sc, path, spec, two, err);
    if (st == BN_OK) {
        sc->mat_two_sided = two;
        two = NULL;
    }
    for (size_t f = 0; st == BN_OK && f < nf; f++)
        if (sc->mat_two_sided[sc->faces[f].material] && !bn__append_back(sc, f, &faces_cap, &fidx_cap))
            st = bn_error_set(err, BN_ENOMEM, "out of memory for the back sides of two-sided faces of %s", path);
    free(two);
    return st;
}

int bn_scene_material_two_sided(const bn_scene *s, size_t m)
{
    return s->mat_two_sided && m < s->nmats && s->mat_two_sided[m];
}
