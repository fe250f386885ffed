/* libFuzzer harness: the .glb header and first-chunk check that `bounce view` makes of a bake. */
#include "bake/bake_internal.h"

#include <stdint.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    bn_error err;
    if (bn__glb_check(data, size, "fuzz.glb", &err) == BN_OK) {
        /* accepted: a glTF 2.0 header whose length is the file's and a whole JSON chunk after it */
        unsigned long total = (unsigned long)data[8] | (unsigned long)data[9] << 8 | (unsigned long)data[10] << 16 |
                              (unsigned long)data[11] << 24;
        if (size < 20 || memcmp(data, "glTF", 4) != 0 || total != size || memcmp(data + 16, "JSON", 4) != 0)
            __builtin_trap();
    }
    return 0;
}
