// OpenImageIO behind extern "C": 8-bit image writing with text labels (ImageBufAlgo::render_text).
// Built as a module of its own (libbounce_oiio.so, beside libbounce.so) that the library opens on
// the first preview (src/image/oiio_module.c): OpenImageIO brings some 260 shared libraries, whose
// loading and relocation cost every bounce process 0.4 s at start when linked directly.
#include "adapters/adapters.h"
#include "base/internal.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <new>
#include <string>

extern "C" bn_status bn__oiio_module_write_rgb8(const char *path, int w, int h, const unsigned char *rgb,
                                                const bn__label *labels, size_t nlabels, const char *font,
                                                const bn_attr *attrs, size_t nattrs, int *labels_ok,
                                                bn_error *err)
{
    try {
        OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
        for (size_t i = 0; i < nattrs; i++)
            spec.attribute(attrs[i].key, attrs[i].value);
        OIIO::ImageBuf buf(spec);
        if (!buf.set_pixels(OIIO::ROI(0, w, 0, h, 0, 1, 0, 3), OIIO::TypeDesc::UINT8, rgb))
            return bn_error_set(err, BN_EINTERNAL, "OpenImageIO: %s", buf.geterror().c_str());
        *labels_ok = 1;
        for (size_t i = 0; i < nlabels; i++) {
            const float white[3] = {0.95f, 0.95f, 0.95f};
            if (!OIIO::ImageBufAlgo::render_text(buf, labels[i].x, labels[i].y, labels[i].text, labels[i].size, font,
                                                 white)) {
                *labels_ok = 0;
                (void)buf.geterror();   // clear the message; the image is written unlabelled
                break;
            }
        }
        if (!buf.write(path))
            return bn_error_set(err, BN_EIO, "OpenImageIO: %s", buf.geterror().c_str());
        return BN_OK;
    } catch (const std::bad_alloc &) {
        return bn_error_set(err, BN_ENOMEM, "out of memory in OpenImageIO");
    } catch (const std::exception &e) {
        return bn_error_set(err, BN_EINTERNAL, "OpenImageIO: %s", e.what());
    } catch (...) {
        return bn_error_set(err, BN_EINTERNAL, "OpenImageIO: unknown exception");
    }
}
