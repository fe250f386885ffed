/* The polygon soup every reader fills (OBJ, OFF, PLY, OpenMesh's binary OFF, arrays from the
 * API) and scene.c validates: vertices, polygons by vertex index, materials. */
#include "scene/scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void bn__soup_free(bn__soup *s)
{
    free(s->verts);
    free(s->counts);
    free(s->mat);
    free(s->line);
    free(s->idx);
    free(s->mats);
    free(s->obj);
    free(s->objnames);
    free(s->vn);
    free(s->pn);
    free(s->mat_two);
    free(s->cuv);
    bn__texture_free(s->tex, s->ntex);
    free(s->mat_tex);
    free(s->mat_etex);
    bn__file_tree_free(s->tree);
    free(s->lights);
    memset(s, 0, sizeof *s);
}

int bn__grow(void **p, size_t *cap, size_t need, size_t elem)
{
    size_t nc;
    void *q;
    if (need <= *cap)
        return 1;
    nc = *cap ? *cap : 64;
    while (nc < need) {
        if (nc > SIZE_MAX / 2)
            return 0;
        nc *= 2;
    }
    q = bn__realloc_array(*p, nc, elem);
    if (!q)
        return 0;
    *p = q;
    *cap = nc;
    return 1;
}

int bn__soup_add_vertex(bn__soup *s, const double p[3])
{
    if (!bn__grow((void **)&s->verts, &s->verts_cap, 3 * (s->nverts + 1), sizeof(double)))
        return 0;
    memcpy(s->verts + 3 * s->nverts, p, 3 * sizeof(double));
    s->nverts++;
    return 1;
}

int bn__soup_add_polygon(bn__soup *s, const size_t *idx, unsigned n, unsigned mat, unsigned line)
{
    size_t cap = s->polys_cap;
    if (s->npolys + 1 > cap) {
        size_t c1 = cap, c2 = cap, c3 = cap;
        size_t c4 = cap, c5 = cap;
        if (!bn__grow((void **)&s->counts, &c1, s->npolys + 1, sizeof(unsigned)) ||
            !bn__grow((void **)&s->mat, &c2, s->npolys + 1, sizeof(unsigned)) ||
            !bn__grow((void **)&s->line, &c3, s->npolys + 1, sizeof(unsigned)) ||
            (s->nobjs && !bn__grow((void **)&s->obj, &c4, s->npolys + 1, sizeof(unsigned))) ||
            (s->pn && !bn__grow((void **)&s->pn, &c5, s->npolys + 1, 3 * sizeof(double))))
            return 0;
        s->polys_cap = c1;
    }
    if (!s->pn && (s->cur_pn[0] != 0 || s->cur_pn[1] != 0 || s->cur_pn[2] != 0) &&
        !(s->pn = bn__calloc(s->polys_cap, 3 * sizeof(double))))   /* the first polygon with normals */
        return 0;
    if (s->pn)
        memcpy(s->pn + 3 * s->npolys, s->cur_pn, sizeof s->cur_pn);
    if (s->obj)
        s->obj[s->npolys] = s->cur_obj;
    if (!bn__grow((void **)&s->idx, &s->idx_cap, s->nidx + n, sizeof(size_t)))
        return 0;
    memcpy(s->idx + s->nidx, idx, n * sizeof(size_t));
    s->nidx += n;
    s->counts[s->npolys] = n;
    s->mat[s->npolys] = mat;
    s->line[s->npolys] = line;
    s->npolys++;
    return 1;
}

int bn__soup_add_normal(bn__soup *s, const double n[3])
{
    if (!bn__grow((void **)&s->vn, &s->vn_cap, s->nvn + 1, 3 * sizeof(double)))
        return 0;
    memcpy(s->vn + 3 * s->nvn++, n, 3 * sizeof(double));
    return 1;
}

size_t bn__name_index(char (**names)[BN_NAME_MAX], size_t *n, size_t *cap, const char *key)
{
    size_t k = 0;
    while (k < *n && strcmp((*names)[k], key) != 0)
        k++;
    if (k == *n) {
        if (!bn__grow((void **)names, cap, *n + 1, sizeof **names))
            return SIZE_MAX;
        snprintf((*names)[k], BN_NAME_MAX, "%s", key);
        (*n)++;
    }
    return k;
}

int bn__soup_use_object(bn__soup *s, const char *name)
{
    size_t k;
    char key[BN_NAME_MAX];
    snprintf(key, sizeof key, "%s", name && name[0] ? name : "default");
    /* polygons before the first o/g form the object "default" (index 0: obj is zeroed) */
    if (s->nobjs == 0 && s->npolys > 0 && bn__name_index(&s->objnames, &s->nobjs, &s->objs_cap, "default") == SIZE_MAX)
        return 0;
    if ((k = bn__name_index(&s->objnames, &s->nobjs, &s->objs_cap, key)) == SIZE_MAX)
        return 0;
    if (!s->obj && !(s->obj = bn__calloc(s->polys_cap ? s->polys_cap : 1, sizeof(unsigned))))
        return 0;
    s->cur_obj = (unsigned)k;
    return 1;
}

int bn__soup_add_material(bn__soup *s, const bn_material *m)
{
    if (!bn__grow((void **)&s->mats, &s->mats_cap, s->nmats + 1, sizeof *m))
        return 0;
    s->mats[s->nmats++] = *m;
    return 1;
}

int bn__soup_set_two_sided(bn__soup *s, unsigned mat)
{
    size_t old = s->mat_two_cap;
    if (!bn__grow((void **)&s->mat_two, &s->mat_two_cap, (size_t)mat + 1, 1))
        return 0;
    memset(s->mat_two + old, 0, s->mat_two_cap - old);
    s->mat_two[mat] = 1;
    return 1;
}

int bn__soup_set_corner_uv(bn__soup *s, const double *uv, unsigned n)
{
    size_t old = s->cuv_cap, first = s->nidx - n;   /* entries past cuv_cap are NaN too */
    if (!bn__grow((void **)&s->cuv, &s->cuv_cap, 2 * s->idx_cap, sizeof(double)))
        return 0;
    for (size_t k = old; k < s->cuv_cap; k++)   /* corners without coordinates: NaN */
        s->cuv[k] = NAN;
    memcpy(s->cuv + 2 * first, uv, 2 * n * sizeof(double));
    return 1;
}

int bn__soup_add_texture(bn__soup *s, bn__texture *t)
{
    if (!bn__grow((void **)&s->tex, &s->tex_cap, s->ntex + 1, sizeof *s->tex))
        return -1;
    s->tex[s->ntex] = *t;
    t->rgb = NULL;
    t->rgb8 = NULL;
    return (int)s->ntex++;
}

static int bn__soup_set_tex(int **arr, size_t *cap, unsigned mat, int tex)
{
    size_t old = *cap;
    if (!bn__grow((void **)arr, cap, (size_t)mat + 1, sizeof(int)))
        return 0;
    for (size_t k = old; k < *cap; k++)
        (*arr)[k] = -1;
    (*arr)[mat] = tex;
    return 1;
}

int bn__soup_add_light(bn__soup *s, const bn_light *l)
{
    if (!bn__grow((void **)&s->lights, &s->lights_cap, s->nlights + 1, sizeof *s->lights))
        return 0;
    s->lights[s->nlights++] = *l;
    return 1;
}

int bn__soup_set_material_texture(bn__soup *s, unsigned mat, int tex)
{
    return bn__soup_set_tex(&s->mat_tex, &s->mat_tex_cap, mat, tex);
}

int bn__soup_set_material_emissive(bn__soup *s, unsigned mat, int tex)
{
    return bn__soup_set_tex(&s->mat_etex, &s->mat_etex_cap, mat, tex);
}

/* Materials from per-polygon keys (reflectance RGB, emission RGB: 6 values a polygon): one material
 * per distinct key, named prefix0, prefix1, ... in order of first use. Sorting groups equal keys
 * (each run in polygon order), so this is O(n log n) even when every polygon has its own colour. */
typedef struct bn__mat_key {
    double v[6];
    size_t poly;
} bn__mat_key;

static int bn__mat_key_cmp(const void *a, const void *b)
{
    const bn__mat_key *x = a, *y = b;
    for (int q = 0; q < 6; q++)
        if (x->v[q] != y->v[q])
            return x->v[q] < y->v[q] ? -1 : 1;
    return x->poly < y->poly ? -1 : x->poly > y->poly;
}

int bn__soup_materials_from_keys(bn__soup *s, const double *keys, const char *prefix)
{
    size_t n = s->npolys;
    bn__mat_key *k = bn__malloc_array(n ? n : 1, sizeof *k);
    size_t *head = bn__malloc_array(n ? n : 1, sizeof(size_t));    /* first polygon with the same key */
    unsigned *num = bn__malloc_array(n ? n : 1, sizeof(unsigned)); /* material of a head polygon */
    int ok = k && head && num;
    for (size_t f = 0; ok && f < n; f++) {
        memcpy(k[f].v, keys + 6 * f, sizeof k[f].v);
        k[f].poly = f;
        num[f] = UINT32_MAX;
    }
    if (ok)
        qsort(k, n, sizeof *k, bn__mat_key_cmp);
    for (size_t q = 0, run = 0; ok && q < n; q++) {
        if (q > 0 && memcmp(k[q].v, k[q - 1].v, sizeof k[q].v) != 0)
            run = q;
        head[k[q].poly] = k[run].poly;
    }
    /* Walking the polygons in order, a run is first met at its head, whose key is its own. */
    for (size_t f = 0; ok && f < n; f++) {
        size_t h = head[f];
        if (num[h] == UINT32_MAX) {
            bn_material m;
            memset(&m, 0, sizeof m);
            snprintf(m.name, sizeof m.name, "%s%zu", prefix, s->nmats);
            memcpy(m.rho, keys + 6 * f, 3 * sizeof(double));
            memcpy(m.Le, keys + 6 * f + 3, 3 * sizeof(double));
            num[h] = (unsigned)s->nmats;
            ok = bn__soup_add_material(s, &m);
        }
        s->mat[f] = num[h];
    }
    free(k);
    free(head);
    free(num);
    return ok;
}
