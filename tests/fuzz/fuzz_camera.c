/* libFuzzer harness: the camera sidecar's parser (NAME.camera) on arbitrary bytes (from memory). */
#include "image/image_internal.h"

#include <stdint.h>
#include <stdio.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    bn_camera cam = {{0, 0, -1}, {0, 0, 0}, {0, 1, 0}, 40, 64, 64, 1};
    bn_error err;
    FILE *fp;
    if (size == 0)
        return 0;
    fp = fmemopen((void *)data, size, "rb");
    if (!fp)
        return 0;
    if (bn__camera_parse(fp, "fuzz.camera", &cam, &err) == BN_OK) {
        /* what a successful parse gives is in range, whatever the bytes */
        if (!(cam.fov_deg > 0 && cam.fov_deg < 180) || cam.width < 1 || cam.width > 32768 || cam.height < 1 ||
            cam.height > 32768 || cam.spp < 1 || cam.spp > 65536)
            __builtin_trap();
    }
    fclose(fp);
    return 0;
}
