/* C declarations of the C++ adapters (OpenImageIO, OpenMesh): every entry point catches all
 * exceptions and returns a status (std::bad_alloc -> BN_ENOMEM). Not installed. */
#ifndef BOUNCE_ADAPTERS_H
#define BOUNCE_ADAPTERS_H

#include <stddef.h>
#include "bounce/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A text label drawn onto an image: left end of the baseline at (x, y), pixel size `size`. */
typedef struct bn__label {
    int x, y, size;
    const char *text;
} bn__label;

/* Writes an 8-bit RGB image (w*h*3, row 0 on top) to `path` through OpenImageIO (format from the
 * extension; the caller manages temp names), drawing `labels` in white with the TrueType font
 * `font`. *labels_ok = 0 when text could not be drawn (font missing or OIIO without FreeType);
 * the image is written anyway. attrs become metadata (PNG text chunks).
 * bn__oiio_write_rgb8 (src/image/oiio_module.c) opens the module libbounce_oiio.so on first use
 * and calls its bn__oiio_module_write_rgb8 (src/adapters/oiio_io.cpp), which has this signature. */
typedef bn_status bn__oiio_write_rgb8_fn(const char *path, int w, int h, const unsigned char *rgb,
                                         const bn__label *labels, size_t nlabels, const char *font,
                                         const bn_attr *attrs, size_t nattrs, int *labels_ok, bn_error *err);
bn_status bn__oiio_write_rgb8(const char *path, int w, int h, const unsigned char *rgb, const bn__label *labels,
                              size_t nlabels, const char *font, const bn_attr *attrs, size_t nattrs, int *labels_ok,
                              bn_error *err);

/* Where a reader puts the mesh it reads: vertices in order, then polygons of vertex indices; each
 * returns 0 when out of memory. (The scene module passes its soup in; the adapter calls back, so
 * that src/adapters depends on nothing above it.) */
typedef struct bn__mesh_sink {
    void *user;
    int (*vertex)(void *user, const double p[3]);
    int (*polygon)(void *user, const size_t *idx, unsigned n);
} bn__mesh_sink;
/* Binary OFF through OpenMesh, after a check of the header's counts and every face's corner
 * count against the file (src/adapters/openmesh_io.cpp). Colours are not read (said once). */
bn_status bn__read_off_binary(const char *path, const bn__mesh_sink *sink, const bn_log *log, bn_error *err);

/* A baked mesh handed to OpenMesh for writing. */
typedef struct bn__bake_mesh {
    size_t nverts;
    const double *pos;          /* nverts*3 */
    size_t nfaces;
    const unsigned *face_n;     /* corners per face (3 or 4) */
    const size_t *face_idx;     /* 4 slots per face */
    const float *colour;        /* nverts*3 float radiance, or NULL */
    const unsigned char *colour8; /* nverts*3 8-bit sRGB, or NULL */
    size_t nextra;              /* extra float vertex properties */
    const char *const *extra_name;   /* nextra names */
    const float *const *extra;  /* nextra arrays of nverts floats */
    const char *provenance;     /* OM: stored as a mesh property "bounce:provenance" */
} bn__bake_mesh;
/* Writes through OpenMesh to `path` (.ply binary or .om by extension; caller manages temp names).
 * *duplicated counts vertices OpenMesh needed duplicated for non-manifold faces. */
bn_status bn__openmesh_write(const char *path, const bn__bake_mesh *m, size_t *duplicated, bn_error *err);

#ifdef __cplusplus
}
#endif
#endif
