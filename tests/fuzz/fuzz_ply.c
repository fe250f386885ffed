/* libFuzzer harness: PLY input (bounce's own reader) and OFF input (checks, then OpenMesh) on
 * arbitrary bytes. The first byte picks the extension; the rest is written to a temporary file,
 * which each reader reads once. */
#include "scene/scene_internal.h"

#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static char path[2][64];
    bn__soup soup;
    bn_error err;
    bn_log log = {0};
    FILE *fp;
    int off;
    if (size < 1)
        return 0;
    off = data[0] & 1;
    if (!path[0][0]) {
        snprintf(path[0], sizeof path[0], "/tmp/bounce-fuzz-%ld.ply", (long)getpid());
        snprintf(path[1], sizeof path[1], "/tmp/bounce-fuzz-%ld.off", (long)getpid());
    }
    fp = fopen(path[off], "wb");
    if (!fp)
        return 0;
    fwrite(data + 1, 1, size - 1, fp);
    fclose(fp);
    log.quiet = 1;
    memset(&soup, 0, sizeof soup);
    if ((off ? bn__read_off : bn__read_ply)(path[off], &soup, &log, &err) == BN_OK) {
        bn_scene *s = NULL;
        bn_load_opts lo;
        bn_load_opts_default(&lo);
        lo.log.quiet = 1;
        if (bn__scene_build("fuzz", &soup, &lo, &s, &err) == BN_OK)
            bn_scene_destroy(s);
    }
    bn__soup_free(&soup);
    return 0;
}
