/* libFuzzer harness: the OBJ reader and scene validation on arbitrary bytes (from memory). */
#include "scene/scene_internal.h"

#include <stdint.h>
#include <stdio.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    bn__soup soup;
    bn_error err;
    bn_log log = {0};
    bn_load_opts lo;
    FILE *fp;
    if (size == 0)
        return 0;
    fp = fmemopen((void *)data, size, "rb");
    if (!fp)
        return 0;
    log.quiet = 1;
    log.fn = NULL;
    memset(&soup, 0, sizeof soup);
    /* mtllib names resolve in a folder that does not exist: the reader must fail cleanly. */
    if (bn__read_obj_stream(fp, "/nonexistent-bounce-fuzz/x.obj", &soup, &log, &err) == BN_OK) {
        bn_scene *s = NULL;
        bn_load_opts_default(&lo);
        lo.log.quiet = 1;
        lo.log.fn = NULL;
        if (bn__scene_build("fuzz.obj", &soup, &lo, &s, &err) == BN_OK) {
            bn_mesh_opts mo;
            bn_mesh_opts_default(&mo);
            mo.target_patches = 64;
            (void)bn_scene_mesh(s, &mo, &err);
            bn_scene_destroy(s);
        }
    }
    bn__soup_free(&soup);
    fclose(fp);
    return 0;
}
