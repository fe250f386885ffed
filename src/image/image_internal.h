/* Internal to src/image: the camera sidecar's parser on a stream (for the fuzz harness). */
#ifndef BOUNCE_IMAGE_INTERNAL_H
#define BOUNCE_IMAGE_INTERNAL_H

#include <stdio.h>
#include "bounce/image.h"

/* Reads `KEY VALUE` lines (eye, look, up, fov, size, spp; # comments) from fp into *cam, which keeps
 * what the file does not set; path names the file in messages. *cam is changed only on success. */
bn_status bn__camera_parse(FILE *fp, const char *path, bn_camera *cam, bn_error *err);

#endif
