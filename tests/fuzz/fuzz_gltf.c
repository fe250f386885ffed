/* libFuzzer harness: glTF 2.0 input (tinygltf's parse, then bounce's checks and walk in
 * src/scene/gltf.c, then validation) on arbitrary bytes. The first byte picks .gltf (JSON) or .glb;
 * the rest is written to a temporary file, which tinygltf reads (with any buffers it names beside it). */
#include "bounce/scene.h"

#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static char path[2][64];
    bn_scene *s = NULL;
    bn_load_opts lo;
    bn_error err;
    FILE *fp;
    int glb;
    if (size < 1)
        return 0;
    glb = data[0] & 1;
    if (!path[0][0]) {
        snprintf(path[0], sizeof path[0], "/tmp/bounce-fuzz-%ld.gltf", (long)getpid());
        snprintf(path[1], sizeof path[1], "/tmp/bounce-fuzz-%ld.glb", (long)getpid());
    }
    fp = fopen(path[glb], "wb");
    if (!fp)
        return 0;
    fwrite(data + 1, 1, size - 1, fp);
    fclose(fp);
    bn_load_opts_default(&lo);
    lo.log.quiet = 1;
    if (bn_scene_load(path[glb], &lo, &s, &err) == BN_OK)
        bn_scene_destroy(s);
    return 0;
}
