/* Links libbounce from an installed tree: loads a scene, meshes it, prints the patch count. */
#include <bounce/bounce.h>
#include <stdio.h>

int main(int argc, char **argv)
{
    bn_scene *s = NULL;
    bn_error err;
    bn_mesh_opts mo;
    size_t np = 0;
    if (argc != 2)
        return 2;
    if (bn_scene_load(argv[1], NULL, &s, &err) != BN_OK) {
        fprintf(stderr, "%s\n", err.msg);
        return bn_status_exit_code(err.status);
    }
    bn_mesh_opts_default(&mo);
    mo.patch_size = 0.25;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        return 1;
    bn_scene_patches(s, &np);
    printf("bounce %s: %lu patches\n", bn_version(), (unsigned long)np);
    bn_scene_destroy(s);
    return np == 32 ? 0 : 1;
}
