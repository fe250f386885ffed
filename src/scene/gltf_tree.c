/* A glTF file's node tree as the scene keeps it (bn_scene_nodes): the nodes the default scene reaches,
 * in the file's order, with their names, transforms as given, world transforms, cameras and the
 * objects their meshes became, so a bake can be written back under the same nodes. */
#include "scene/gltf_tree.h"

#include <stdlib.h>
#include <string.h>

static void bn__node_free(bn_scene_node *n)
{
    free((char *)n->name);
    free((char *)n->mesh_name);
    free((char *)n->object);
    free((char *)n->camera_name);
}

void bn__file_tree_free(bn__file_tree *t)
{
    if (!t)
        return;
    for (size_t i = 0; t->nodes && i < t->nnodes; i++)
        bn__node_free(&t->nodes[i]);
    free(t->nodes);
    free(t->children);
    free(t->roots);
    free(t);
}

static char *bn__dup(const char *s)
{
    size_t n = s ? strlen(s) : 0;
    char *d = malloc(n + 1);
    if (d) {
        memcpy(d, s ? s : "", n);
        d[n] = '\0';
    }
    return d;
}

/* glTF node i as tree node out (its children filled by the caller). */
static int bn__node_copy(const bn__gltf *g, size_t i, const bn__tree_capture *c, bn_scene_node *out)
{
    const bn__gltf_node *n = &g->nodes[i];
    int mesh = n->mesh >= 0 && (size_t)n->mesh < g->nmeshes;
    int cam = n->camera >= 0 && (size_t)n->camera < g->ncameras && g->cameras[n->camera].perspective;
    out->nmatrix = n->nmatrix, out->nt = n->nt, out->nr = n->nr, out->ns = n->ns;
    memcpy(out->matrix, n->matrix, sizeof out->matrix);
    memcpy(out->t, n->t, sizeof out->t);
    memcpy(out->r, n->r, sizeof out->r);
    memcpy(out->s, n->s, sizeof out->s);
    memcpy(out->world, c->world + 16 * i, sizeof out->world);
    out->name = bn__dup(n->name);
    out->mesh_name = bn__dup(mesh ? g->meshes[n->mesh].name : "");
    out->object = c->objname[i] ? bn__dup(c->objname[i]) : NULL;
    out->light = c->light[i];
    if (cam) {
        const bn__gltf_camera *k = &g->cameras[n->camera];
        out->camera = 1;
        out->yfov = k->yfov, out->aspect = k->aspect > 0 ? k->aspect : 0;
        out->znear = k->znear > 0 ? k->znear : 0.01, out->zfar = k->zfar > out->znear ? k->zfar : 0;
        out->camera_name = bn__dup(k->name);
    }
    return out->name && out->mesh_name && (!c->objname[i] || out->object) && (!cam || out->camera_name);
}

/* The reached nodes' new indices (their order in the file kept) and the count of their children. */
static size_t bn__tree_index(const bn__gltf *g, const unsigned char *seen, size_t *remap, size_t *nchildren)
{
    size_t n = 0;
    *nchildren = 0;
    for (size_t i = 0; i < g->nnodes; i++) {
        remap[i] = seen[i] ? n++ : SIZE_MAX;
        if (seen[i])
            *nchildren += g->nodes[i].n;
    }
    return n;
}

/* The tree of the nodes the walk reached (c->seen), every child of a reached node reached too. */
static bn_status bn__tree_fill(const bn__gltf *g, const bn__tree_capture *c, const size_t *remap, bn__file_tree *t)
{
    size_t k = 0, at = 0;
    for (size_t i = 0; i < g->nnodes; i++) {
        if (!c->seen[i])
            continue;
        bn_scene_node *o = &t->nodes[k++];
        const bn__gltf_node *n = &g->nodes[i];
        if (!bn__node_copy(g, i, c, o))
            return BN_ENOMEM;
        o->children = t->children + at;
        for (size_t j = 0; j < n->n; j++) {
            int ch = g->children[n->first + j];   /* checked by the walk: reached, in range */
            t->children[at + o->nchildren++] = remap[ch];
        }
        at += o->nchildren;
    }
    for (size_t j = 0; j < c->nroots; j++)
        t->roots[j] = remap[c->roots[j]];
    return BN_OK;
}

bn_status bn__gltf_tree(const bn__gltf *g, const bn__tree_capture *c, bn__file_tree **out)
{
    size_t nchildren, *remap = malloc((g->nnodes + 1) * sizeof *remap);
    bn__file_tree *t = calloc(1, sizeof *t);
    bn_status st = BN_ENOMEM;
    *out = NULL;
    if (remap && t) {
        t->nnodes = bn__tree_index(g, c->seen, remap, &nchildren);
        t->nroots = c->nroots;
        t->nodes = calloc(t->nnodes + 1, sizeof *t->nodes);
        t->children = malloc((nchildren + 1) * sizeof *t->children);
        t->roots = malloc((c->nroots + 1) * sizeof *t->roots);
        if (t->nodes && t->children && t->roots)
            st = bn__tree_fill(g, c, remap, t);
    }
    free(remap);
    if (st != BN_OK)
        bn__file_tree_free(t);
    else
        *out = t;
    return st;
}
