// PLY and OFF input through OpenMesh (placeholder: filled in by the OpenMesh adapter work).
#include "scene/scene_internal.h"

extern "C" bn_status bn__read_openmesh(const char *path, bn__soup *out, const bn_log *log, bn_error *err)
{
    (void)out;
    (void)log;
    return bn_error_set(err, BN_EINPUT, "%s: PLY/OFF reading is not implemented yet", path);
}
