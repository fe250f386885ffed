/* The viewer page (bounce view): one self-contained HTML file, the bake (.glb) and three.js
 * embedded as base64, our page template (web/viewer.html) around them; both vendored into the
 * library at build time (cmake/embed.cmake). No network at view time. */
#include "bounce/bake.h"
#include "base/internal.h"
#include "bake/bake_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

extern const unsigned char bn__web_viewer[], bn__web_three[], bn__web_orbit[], bn__web_meshopt[], bn__web_worker[],
    bn__web_kernel[];
extern const size_t bn__web_viewer_size, bn__web_three_size, bn__web_orbit_size, bn__web_meshopt_size,
    bn__web_worker_size, bn__web_kernel_size;
extern const int bn__web_have_assets;

static void bn__base64(FILE *fp, const unsigned char *p, size_t n)
{
    static const char a[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    char q[4];
    for (size_t i = 0; i < n; i += 3) {
        unsigned v = (unsigned)p[i] << 16 | (i + 1 < n ? (unsigned)p[i + 1] << 8 : 0) | (i + 2 < n ? p[i + 2] : 0);
        q[0] = a[v >> 18 & 63];
        q[1] = a[v >> 12 & 63];
        q[2] = i + 1 < n ? a[v >> 6 & 63] : '=';
        q[3] = i + 2 < n ? a[v & 63] : '=';
        fwrite(q, 1, 4, fp);
    }
}

static void bn__html_text(FILE *fp, const char *s)
{
    for (; *s; s++) {
        switch (*s) {
        case '&': fputs("&amp;", fp); break;
        case '<': fputs("&lt;", fp); break;
        case '>': fputs("&gt;", fp); break;
        case '"': fputs("&quot;", fp); break;
        default: fputc(*s, fp);
        }
    }
}

static unsigned long bn__le32(const unsigned char *p)
{
    return (unsigned long)p[0] | (unsigned long)p[1] << 8 | (unsigned long)p[2] << 16 | (unsigned long)p[3] << 24;
}

bn_status bn__glb_check(const unsigned char *glb, size_t len, const char *path, bn_error *err)
{
    unsigned long version, total, jlen;
    const char *why = NULL;
    if (len < 12 || memcmp(glb, "glTF", 4) != 0)
        return bn_error_set(err, BN_EINPUT, "%s: not a glTF binary (.glb): bounce view takes a scene or a .glb bake",
                            path);
    /* the header's version and length words, and the JSON chunk's, against the file */
    version = bn__le32(glb + 4);
    total = bn__le32(glb + 8);
    jlen = len >= 20 ? bn__le32(glb + 12) : 0;
    if (version != 2)
        why = "is not glTF 2.0";
    else if (total != (unsigned long)len)
        why = "is truncated or has trailing bytes (its header's length differs from the file's size)";
    else if (len < 20 || memcmp(glb + 16, "JSON", 4) != 0 || jlen > (unsigned long)len - 20)
        why = "has no whole JSON chunk first";
    if (why)
        return bn_error_set(err, BN_EINPUT, "%s: a .glb that %s: %zu bytes, header says version %lu and %lu bytes",
                            path, why, len, version, total);
    return BN_OK;
}

int bn_view_is_bake(const char *glb_path)
{
    unsigned char head[20];
    char json[4097];
    FILE *f = fopen(glb_path, "rb");
    size_t n = 0;
    if (!f)
        return -1;
    long size = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    rewind(f);
    if (fread(head, 1, 20, f) == 20 && memcmp(head, "glTF", 4) == 0 && memcmp(head + 16, "JSON", 4) == 0 &&
        size == (long)bn__le32(head + 8)) {   /* whole: its header's length is the file's */
        unsigned long jlen = bn__le32(head + 12);
        n = fread(json, 1, jlen < sizeof json - 1 ? jlen : sizeof json - 1, f);
    }
    fclose(f);
    if (n == 0)
        return -1;   /* not a whole .glb: bn_view_write says what is wrong with it */
    json[n] = '\0';   /* the asset object comes first in bounce's bakes: its generator within 4 KiB */
    return strstr(json, "\"generator\":\"bounce") != NULL;
}

/* The template with its __BN_*__ placeholders filled: the bake (glb) or the live payload, the other empty. */
static bn_status bn__view_page(const unsigned char *glb, size_t glen, const unsigned char *live, size_t llen,
                               const char *title, const char *out, bn_error *err)
{
    static const struct {
        const char *key;
        int what;   /* 0 title, 1 three, 2 orbit, 3 meshopt, 4 glb, 5 live, 6 the live page's worker, 7 its kernel */
    } keys[] = {{"__BN_TITLE__", 0}, {"__BN_THREE__", 1}, {"__BN_ORBIT__", 2}, {"__BN_MESHOPT__", 3},
                {"__BN_GLB__", 4},   {"__BN_LIVE__", 5},  {"__BN_WORKER__", 6},
                {"__BN_KERNEL__", 7}};
    const char *t = (const char *)bn__web_viewer, *end = t + bn__web_viewer_size;
    bn__outfile f;
    bn_status st = bn__outfile_open(&f, out, "wb", err);
    if (st != BN_OK)
        return st;
    while (t < end) {
        const char *m = strstr(t, "__BN_");
        size_t k = 0;
        if (!m || m >= end) {
            fwrite(t, 1, (size_t)(end - t), f.fp);
            break;
        }
        fwrite(t, 1, (size_t)(m - t), f.fp);
        while (k < sizeof keys / sizeof *keys && strncmp(m, keys[k].key, strlen(keys[k].key)) != 0)
            k++;
        if (k == sizeof keys / sizeof *keys) {
            fwrite(m, 1, 5, f.fp);
            t = m + 5;
            continue;
        }
        switch (keys[k].what) {
        case 0: bn__html_text(f.fp, title); break;
        case 1: bn__base64(f.fp, bn__web_three, bn__web_three_size); break;
        case 2: bn__base64(f.fp, bn__web_orbit, bn__web_orbit_size); break;
        case 3: bn__base64(f.fp, bn__web_meshopt, bn__web_meshopt_size); break;
        case 4: bn__base64(f.fp, glb, glen); break;
        case 5: bn__base64(f.fp, live, llen); break;
        case 6: bn__base64(f.fp, live ? bn__web_worker : NULL, live ? bn__web_worker_size : 0); break;
        default: bn__base64(f.fp, live ? bn__web_kernel : NULL, live ? bn__web_kernel_size : 0); break;
        }
        t = m + strlen(keys[k].key);
    }
    return bn__outfile_commit(&f, err);
}

static bn_status bn__view_assets(bn_error *err)
{
    if (!bn__web_have_assets)
        return bn_error_set(err, BN_EUSAGE, "this bounce was built without three.js or meshoptimizer "
                                            "(web/node_modules was incomplete): run scripts/setup.sh, which installs it, and rebuild");
    return BN_OK;
}

bn_status bn_view_write_live(const unsigned char *live, size_t n, const char *title, const char *out, bn_error *err)
{
    bn_status st = bn__view_assets(err);
    return st != BN_OK ? st : bn__view_page(NULL, 0, live, n, title, out, err);
}

bn_status bn_view_write(const char *glb_path, const char *title, const char *out, bn_error *err)
{
    FILE *in;
    unsigned char *glb = NULL;
    long len;
    bn_status st;
    if ((st = bn__view_assets(err)) != BN_OK)
        return st;
    if (!(in = fopen(glb_path, "rb")))
        return bn_error_set(err, BN_EIO, "%s: cannot open the bake", glb_path);
    if (fseek(in, 0, SEEK_END) != 0 || (len = ftell(in)) < 0 || fseek(in, 0, SEEK_SET) != 0) {
        fclose(in);
        return bn_error_set(err, BN_EIO, "%s: cannot read the bake", glb_path);
    }
    glb = bn__malloc_array((size_t)len + 1, 1);
    if (!glb) {
        fclose(in);
        return bn_error_set(err, BN_ENOMEM, "%s: out of memory for %ld bytes", glb_path, len);
    }
    if (fread(glb, 1, (size_t)len, in) != (size_t)len) {
        fclose(in);
        free(glb);
        return bn_error_set(err, BN_EIO, "%s: short read", glb_path);
    }
    fclose(in);
    if ((st = bn__glb_check(glb, (size_t)len, glb_path, err)) != BN_OK) {
        free(glb);
        return st;
    }
    st = bn__view_page(glb, (size_t)len, NULL, 0, title, out, err);
    free(glb);
    return st;
}
