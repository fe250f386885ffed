// OpenImageIO behind extern "C": 8-bit image writing with text labels (ImageBufAlgo::render_text), and
// reading textures (any format OpenImageIO reads, from a file or from memory: glTF's embedded images).
// Built as a module of its own (libbounce_oiio.so, beside libbounce.so) that the library opens on
// the first preview (src/image/oiio_module.c): OpenImageIO brings some 260 shared libraries, whose
// loading and relocation cost every bounce process 0.4 s at start when linked directly.
#include "adapters/adapters.h"
#include "base/internal.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <cctype>
#include <cstdlib>
#include <new>
#include <string>
#include <vector>

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

// Which channels are R, G and B: by name ("R" or "layer.R": EXR stores channels sorted), else by position
// (grey, and grey + alpha, to RGB; alpha dropped).
static void rgb_channels(const OIIO::ImageSpec &spec, int ch[3])
{
    int nc = spec.nchannels;
    for (int c = 0; c < 3; c++) {
        ch[c] = nc >= 3 ? c : 0;
        for (int k = 0; nc >= 3 && k < nc; k++) {
            const std::string &n = spec.channelnames[k];
            if (!n.empty() && std::toupper((unsigned char)n.back()) == "RGB"[c] && (n.size() == 1 || n[n.size() - 2] == '.'))
                ch[c] = k;
        }
    }
}

// The image's pixels as type T (unsigned char or float), 3 per texel, malloc'd.
template <typename T>
static T *read_rgb(OIIO::ImageInput &in, OIIO::TypeDesc type, const char *path, bn_error *err)
{
    const OIIO::ImageSpec &spec = in.spec();
    size_t n = (size_t)spec.width * (size_t)spec.height, nc = (size_t)spec.nchannels;
    int ch[3];
    std::vector<T> px(n * nc);
    if (!in.read_image(0, 0, 0, (int)nc, type, px.data())) {
        bn_error_set(err, BN_EINPUT, "%s: cannot read the image: %s", path, in.geterror().c_str());
        return nullptr;
    }
    T *out = static_cast<T *>(std::malloc(sizeof(T) * 3 * n));
    if (!out) {
        bn_error_set(err, BN_ENOMEM, "%s: out of memory for the image", path);
        return nullptr;
    }
    rgb_channels(spec, ch);
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++)
            out[3 * i + c] = px[i * nc + (size_t)ch[c]];
    return out;
}

// An image as stored (no colour conversion): 8-bit images as bytes, others as floats, 3 per texel, row 0 on
// top. From `path`, or from mem[0 .. size) when mem is not NULL (`path` then only names the format by its
// extension and the image in messages). *is_float: the file holds float or half values.
extern "C" bn_status bn__oiio_module_read_rgb(const char *path, const void *mem, size_t size, int *w, int *h,
                                              float **rgb, unsigned char **rgb8, int *is_float, bn_error *err)
{
    *rgb = nullptr;
    *rgb8 = nullptr;
    try {
        OIIO::Filesystem::IOMemReader proxy(mem, mem ? size : 0);
        auto in = OIIO::ImageInput::open(path, nullptr, mem ? &proxy : nullptr);
        if (!in)
            return bn_error_set(err, BN_EINPUT, "%s: cannot read the image: %s", path, OIIO::geterror().c_str());
        const OIIO::ImageSpec &spec = in->spec();
        if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 ||
            (size_t)spec.width * spec.height > ((size_t)1 << 28))
            return bn_error_set(err, BN_EINPUT, "%s: an image of %d x %d pixels and %d channels is not a texture bounce "
                                "reads", path, spec.width, spec.height, spec.nchannels);
        OIIO::TypeDesc::BASETYPE b = (OIIO::TypeDesc::BASETYPE)spec.format.basetype;
        *is_float = b == OIIO::TypeDesc::FLOAT || b == OIIO::TypeDesc::HALF || b == OIIO::TypeDesc::DOUBLE;
        if (b == OIIO::TypeDesc::UINT8)
            *rgb8 = read_rgb<unsigned char>(*in, OIIO::TypeDesc::UINT8, path, err);
        else
            *rgb = read_rgb<float>(*in, OIIO::TypeDesc::FLOAT, path, err);
        if (!*rgb8 && !*rgb)
            return err ? err->status : BN_EINPUT;
        *w = spec.width, *h = spec.height;
        return BN_OK;
    } catch (const std::bad_alloc &) {
        std::free(*rgb8), std::free(*rgb);
        *rgb = nullptr, *rgb8 = nullptr;
        return bn_error_set(err, BN_ENOMEM, "%s: out of memory reading the image", path);
    } catch (const std::exception &e) {
        std::free(*rgb8), std::free(*rgb);
        *rgb = nullptr, *rgb8 = nullptr;
        return bn_error_set(err, BN_EINPUT, "%s: cannot read the image: %s", path, e.what());
    }
}
