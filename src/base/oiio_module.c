/* OpenImageIO, loaded when first needed: the previews' writer and the texture reader live in the module
 * libbounce_oiio.so (src/adapters/oiio_io.cpp), looked up beside libbounce.so itself, so that a
 * process that writes no preview never loads OpenImageIO's ~260 shared libraries (0.4 s at every
 * start when they were linked directly). */
#define _GNU_SOURCE   /* dladdr */
#include "adapters/adapters.h"
#include "base/internal.h"

#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <string.h>

static pthread_once_t bn__oiio_once = PTHREAD_ONCE_INIT;
static bn__oiio_write_rgb8_fn *bn__oiio_fn;
static bn__oiio_read_rgb_fn *bn__oiio_read_fn;
static char bn__oiio_why[3800];

static void bn__oiio_open(void)
{
    char path[4096];
    Dl_info info;
    void *h = NULL;
    const char *slash;
    /* beside this library (the build tree, or the install's libdir), else the loader's search path */
    if (dladdr((void *)&bn__oiio_write_rgb8, &info) && info.dli_fname && (slash = strrchr(info.dli_fname, '/'))) {
        snprintf(path, sizeof path, "%.*s/libbounce_oiio.so", (int)(slash - info.dli_fname), info.dli_fname);
        h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    } else
        snprintf(path, sizeof path, "libbounce_oiio.so");
    if (!h) {   /* dlerror's text is only good until the next dl call: keep it */
        const char *e1 = dlerror();
        snprintf(bn__oiio_why, sizeof bn__oiio_why, "cannot load bounce's OpenImageIO module (%.3000s: %.600s)", path,
                 e1 ? e1 : "not found");
        h = dlopen("libbounce_oiio.so", RTLD_NOW | RTLD_LOCAL);
        if (!h)
            return;
    }
    *(void **)&bn__oiio_fn = dlsym(h, "bn__oiio_module_write_rgb8");
    *(void **)&bn__oiio_read_fn = dlsym(h, "bn__oiio_module_read_rgb");
    if (!bn__oiio_fn || !bn__oiio_read_fn)
        snprintf(bn__oiio_why, sizeof bn__oiio_why, "%.3000s lacks bounce's entry points (an older module?)", path);
}

bn_status bn__oiio_write_rgb8(const char *path, int w, int h, const unsigned char *rgb, const bn__label *labels,
                              size_t nlabels, const char *font, const bn_attr *attrs, size_t nattrs, int *labels_ok,
                              bn_error *err)
{
    pthread_once(&bn__oiio_once, bn__oiio_open);
    if (!bn__oiio_fn)
        return bn_error_set(err, BN_EIO, "%s", bn__oiio_why);
    return bn__oiio_fn(path, w, h, rgb, labels, nlabels, font, attrs, nattrs, labels_ok, err);
}

bn_status bn__oiio_read_rgb(const char *path, const void *mem, size_t size, int *w, int *h, float **rgb,
                            unsigned char **rgb8, int *is_float, bn_error *err)
{
    pthread_once(&bn__oiio_once, bn__oiio_open);
    *rgb = NULL;
    *rgb8 = NULL;
    if (!bn__oiio_read_fn)
        return bn_error_set(err, BN_EIO, "%s: %s", path, bn__oiio_why);
    return bn__oiio_read_fn(path, mem, size, w, h, rgb, rgb8, is_float, err);
}
