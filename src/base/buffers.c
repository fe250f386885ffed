/* Growing buffers: text for JSON, 4-byte aligned binary (the glTF writer's and the live page's). */
#include "base/internal.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void bn__str_add(bn__str *b, const char *fmt, ...)
{
    va_list ap;
    int k;
    if (b->oom)
        return;
    for (;;) {
        size_t room = b->cap - b->n;
        va_start(ap, fmt);
        k = vsnprintf(b->s ? b->s + b->n : NULL, b->s ? room : 0, fmt, ap);
        va_end(ap);
        if (k < 0) {
            b->oom = 1;
            return;
        }
        if (b->s && (size_t)k < room) {
            b->n += (size_t)k;
            return;
        }
        size_t cap = (b->cap + (size_t)k + 1) * 2;
        char *s = realloc(b->s, cap);
        if (!s) {
            b->oom = 1;
            return;
        }
        b->s = s;
        b->cap = cap;
    }
}

/* A JSON string literal: quotes, backslashes and control characters escaped; bytes >= 0x80 pass
 * (UTF-8 as given). */
void bn__str_json(bn__str *b, const char *v)
{
    bn__str_add(b, "\"");
    for (const unsigned char *p = (const unsigned char *)v; *p; p++) {
        if (*p == '"' || *p == '\\')
            bn__str_add(b, "\\%c", *p);
        else if (*p < 0x20)
            bn__str_add(b, "\\u%04x", *p);
        else
            bn__str_add(b, "%c", *p);
    }
    bn__str_add(b, "\"");
}

/* A finite double as JSON (%.9g keeps a float's value). */
void bn__str_num(bn__str *b, double v) { bn__str_add(b, "%.9g", isfinite(v) ? v : 0.0); }

/* Appends n bytes at a 4-byte boundary (the buffer view's offset is returned). */
size_t bn__blob_add(bn__blob *b, const void *src, size_t n)
{
    size_t off = (b->n + 3) & ~(size_t)3;
    if (b->oom)
        return 0;
    if (off + n > b->cap) {
        size_t cap = (off + n) * 3 / 2 + 64;
        unsigned char *p = realloc(b->p, cap);
        if (!p) {
            b->oom = 1;
            return 0;
        }
        b->p = p;
        b->cap = cap;
    }
    memset(b->p + b->n, 0, off - b->n);
    memcpy(b->p + off, src, n);
    b->n = off + n;
    return off;
}

