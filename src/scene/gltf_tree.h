/* The glTF reader's node tree, kept for the bake (src/scene/gltf_tree.c). Not installed. */
#ifndef BN_SCENE_GLTF_TREE_H
#define BN_SCENE_GLTF_TREE_H

#include "scene/scene_internal.h"
#include "adapters/adapters.h"

/* What the node walk saw: per glTF node, reached (seen), its world transform (16 doubles, column-major)
 * and the name of the object its mesh became (NULL: none); and the roots it started from. */
typedef struct bn__tree_capture {
    const unsigned char *seen;
    const double *world;
    char *const *objname;
    const int *light;          /* per glTF node: its light's index in the soup, -1 none */
    const int *roots;
    size_t nroots;
} bn__tree_capture;

/* The reached nodes as a tree (their order in the file kept, children and roots renumbered): *out, or
 * BN_ENOMEM. The roots and every reached node's children must be valid reached nodes (the walk checks). */
bn_status bn__gltf_tree(const bn__gltf *g, const bn__tree_capture *c, bn__file_tree **out);

#endif
