/* PLY scene input: the file is read into memory once and parsed here, header and body, ASCII and
 * binary (either byte order), with every error naming the file, line (ASCII) or element and the
 * bad value. Per face: vertex_indices, and a material from reflectance_{red,green,blue} and
 * emission_{red,green,blue} properties, else a face colour (red, green, blue: 8-bit / 255 or
 * float), else the mean of the vertices' colours, else grey 0.5 with a warning.
 *
 * Why not OpenMesh's PLY reader: it cannot carry per-face reflectance and emission with the lines
 * they came from, and the fuzzer found it writing out of bounds on five malformed inputs (a NUL in
 * ASCII, a colour on a face it had refused, ...). OpenMesh still writes the baked PLY and reads
 * OFF. Format: Turk, "The PLY polygon file format" (1994). */
#include "scene/scene_internal.h"

#include <ctype.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef enum bn__ply_type { T_INT8, T_UINT8, T_INT16, T_UINT16, T_INT32, T_UINT32, T_FLOAT32, T_FLOAT64, T_BAD } bn__ply_type;
typedef enum bn__ply_format { F_ASCII, F_LE, F_BE } bn__ply_format;

#define BN__PLY_NAME 64
#define BN__PLY_MAXPROPS 64
#define BN__PLY_MAXELEMS 16

typedef struct bn__ply_prop {
    char name[BN__PLY_NAME];
    int list;
    bn__ply_type type, count_type;
} bn__ply_prop;

typedef struct bn__ply_elem {
    char name[BN__PLY_NAME];
    unsigned long long count;
    bn__ply_prop props[BN__PLY_MAXPROPS];
    size_t nprops;
} bn__ply_elem;

typedef struct bn__ply {
    const char *path;
    const char *text, *end;     /* the whole file */
    const char *p;              /* read position */
    unsigned line;              /* ASCII line of p */
    bn__ply_format format;
    bn__ply_elem elems[BN__PLY_MAXELEMS];
    size_t nelems;
} bn__ply;

/* What the faces carry, column by column (one entry per face of the file). */
typedef struct bn__ply_faces {
    size_t n;
    unsigned *line;             /* ASCII line (0 binary) */
    double *props;              /* 6 per face: reflectance RGB, emission RGB */
    double *rgb;                /* 3 per face: face colour as reflectance */
    int has_refl, has_emis, has_rgb;
} bn__ply_faces;

static const char *const bn__face_props[6] = {"reflectance_red", "reflectance_green", "reflectance_blue",
                                              "emission_red",    "emission_green",    "emission_blue"};

static bn__ply_type bn__ply_type_of(const char *t)
{
    static const struct {
        const char *a, *b;
        bn__ply_type t;
    } names[] = {{"char", "int8", T_INT8},     {"uchar", "uint8", T_UINT8},     {"short", "int16", T_INT16},
                 {"ushort", "uint16", T_UINT16}, {"int", "int32", T_INT32},       {"uint", "uint32", T_UINT32},
                 {"float", "float32", T_FLOAT32}, {"double", "float64", T_FLOAT64}};
    for (size_t k = 0; k < sizeof names / sizeof names[0]; k++)
        if (strcmp(t, names[k].a) == 0 || strcmp(t, names[k].b) == 0)
            return names[k].t;
    return T_BAD;
}

/* The values an integer type holds (an ASCII token outside them is an error, not a wrap). */
static int bn__ply_in_range(bn__ply_type t, double v)
{
    static const double lo[] = {-128, 0, -32768, 0, -2147483648.0, 0};
    static const double hi[] = {127, 255, 32767, 65535, 2147483647.0, 4294967295.0};
    return t >= T_FLOAT32 || (v >= lo[t] && v <= hi[t]);
}

static size_t bn__ply_size(bn__ply_type t)
{
    static const size_t sz[] = {1, 1, 2, 2, 4, 4, 4, 8, 0};
    return sz[t];
}

/* A control byte in [a, b) (text: the header, and an ASCII body), with its line counted from `line`. */
static bn_status bn__ply_text_check(const bn__ply *P, const char *a, const char *b, unsigned line, bn_error *err)
{
    for (const char *q = a; q < b; q++) {
        unsigned char ch = (unsigned char)*q;
        if (ch == '\n')
            line++;
        else if (ch < 0x20 && ch != '\t' && ch != '\r')
            return bn_error_set(err, BN_EINPUT, "%s:%u: control byte 0x%02x in PLY text", P->path, line, ch);
    }
    return BN_OK;
}

/* ---- the header ---- */

/* The next header line (without its end of line) into buf; 0 at the end of the file. */
static int bn__ply_header_line(bn__ply *P, char *buf, size_t size)
{
    const char *nl;
    size_t n;
    if (P->p >= P->end)
        return 0;
    nl = memchr(P->p, '\n', (size_t)(P->end - P->p));
    n = (size_t)((nl ? nl : P->end) - P->p);
    if (n && P->p[n - 1] == '\r')
        n--;
    snprintf(buf, size, "%.*s", (int)(n < size ? n : size - 1), P->p);
    P->p = nl ? nl + 1 : P->end;
    P->line++;
    return 1;
}

static bn_status bn__ply_property(bn__ply *P, const char *ln, bn_error *err)
{
    bn__ply_prop pr;
    char t[BN__PLY_NAME] = "", ct[BN__PLY_NAME] = "", it[BN__PLY_NAME] = "";
    bn__ply_elem *e;
    memset(&pr, 0, sizeof pr);
    if (P->nelems == 0)
        return bn_error_set(err, BN_EINPUT, "%s:%u: property before any element", P->path, P->line);
    e = &P->elems[P->nelems - 1];
    sscanf(ln, "property %63s", t);
    if (strcmp(t, "list") == 0) {
        sscanf(ln, "property list %63s %63s %63s", ct, it, pr.name);
        pr.list = 1;
        pr.count_type = bn__ply_type_of(ct);
        pr.type = bn__ply_type_of(it);
        if (pr.count_type == T_BAD || pr.count_type == T_FLOAT32 || pr.count_type == T_FLOAT64 || pr.type == T_BAD)
            return bn_error_set(err, BN_EINPUT, "%s:%u: bad list property '%s'", P->path, P->line, ln);
    } else {
        pr.type = bn__ply_type_of(t);
        sscanf(ln, "property %*s %63s", pr.name);
        if (pr.type == T_BAD)
            return bn_error_set(err, BN_EINPUT, "%s:%u: unknown property type '%s'", P->path, P->line, t);
    }
    if (!pr.name[0])
        return bn_error_set(err, BN_EINPUT, "%s:%u: property without a name", P->path, P->line);
    if (e->nprops == BN__PLY_MAXPROPS)
        return bn_error_set(err, BN_EINPUT, "%s:%u: more than %d properties in element '%s'", P->path, P->line,
                            BN__PLY_MAXPROPS, e->name);
    e->props[e->nprops++] = pr;
    return BN_OK;
}

static bn_status bn__ply_element(bn__ply *P, const char *ln, bn_error *err)
{
    bn__ply_elem *e;
    char name[BN__PLY_NAME] = "", cnt[64] = "", extra[8] = "", *end = NULL;
    int got = sscanf(ln, "element %63s %63s %7s", name, cnt, extra);
    unsigned long long count = got >= 2 && cnt[0] != '-' ? strtoull(cnt, &end, 10) : 0;
    if (got != 2 || cnt[0] == '-' || !end || *end)
        return bn_error_set(err, BN_EINPUT, "%s:%u: bad element line '%s' (expected 'element NAME COUNT')", P->path,
                            P->line, ln);
    if (P->nelems == BN__PLY_MAXELEMS)
        return bn_error_set(err, BN_EINPUT, "%s:%u: more than %d elements", P->path, P->line, BN__PLY_MAXELEMS);
    if (strcmp(name, "vertex") == 0 || strcmp(name, "face") == 0)
        for (size_t k = 0; k < P->nelems; k++)
            if (strcmp(P->elems[k].name, name) == 0)
                return bn_error_set(err, BN_EINPUT, "%s:%u: a second '%s' element", P->path, P->line, name);
    e = &P->elems[P->nelems++];
    memset(e, 0, sizeof *e);
    snprintf(e->name, sizeof e->name, "%s", name);
    e->count = count;
    return BN_OK;
}

static bn_status bn__ply_header(bn__ply *P, bn_error *err)
{
    char ln[512], kw[BN__PLY_NAME];
    int have_format = 0;
    bn_status st;
    if (!bn__ply_header_line(P, ln, sizeof ln) || strcmp(ln, "ply") != 0)
        return bn_error_set(err, BN_EINPUT, "%s:1: not a PLY file (the first line must be 'ply')", P->path);
    while (bn__ply_header_line(P, ln, sizeof ln)) {
        kw[0] = '\0';
        sscanf(ln, "%63s", kw);
        if (!kw[0] || strcmp(kw, "comment") == 0 || strcmp(kw, "obj_info") == 0)
            continue;
        if (strcmp(kw, "format") == 0) {
            char f[64] = "", v[64] = "";
            sscanf(ln, "format %63s %63s", f, v);
            if (strcmp(f, "ascii") == 0)
                P->format = F_ASCII;
            else if (strcmp(f, "binary_little_endian") == 0)
                P->format = F_LE;
            else if (strcmp(f, "binary_big_endian") == 0)
                P->format = F_BE;
            else
                return bn_error_set(err, BN_EINPUT, "%s:%u: unknown PLY format '%s'", P->path, P->line, f);
            if (strcmp(v, "1.0") != 0)
                return bn_error_set(err, BN_EINPUT, "%s:%u: PLY version '%s' (bounce reads 1.0)", P->path, P->line, v);
            have_format = 1;
        } else if (strcmp(kw, "element") == 0) {
            if ((st = bn__ply_element(P, ln, err)) != BN_OK)
                return st;
        } else if (strcmp(kw, "property") == 0) {
            if ((st = bn__ply_property(P, ln, err)) != BN_OK)
                return st;
        } else if (strcmp(kw, "end_header") == 0) {
            if (!have_format)
                return bn_error_set(err, BN_EINPUT, "%s: the PLY header has no format line", P->path);
            P->line++;   /* the body's first line */
            return BN_OK;
        } else {
            return bn_error_set(err, BN_EINPUT, "%s:%u: unknown PLY header keyword '%s'", P->path, P->line, kw);
        }
    }
    return bn_error_set(err, BN_EINPUT, "%s: the PLY header has no end_header line", P->path);
}

/* ---- the body ---- */

static void bn__ply_skip_ws(bn__ply *P)
{
    if (P->format != F_ASCII)
        return;
    while (P->p < P->end && isspace((unsigned char)*P->p)) {
        if (*P->p == '\n')
            P->line++;
        P->p++;
    }
}

/* The next value of type t: 1, or 0 at the end of the file or on a bad token (copied to bad). */
static int bn__ply_value(bn__ply *P, bn__ply_type t, double *out, char *bad, size_t nbad)
{
    unsigned char b[8];
    size_t n = bn__ply_size(t);
    bad[0] = '\0';
    if (P->format == F_ASCII) {
        char tok[80], *end;
        size_t len = 0;
        bn__ply_skip_ws(P);
        while (P->p + len < P->end && !isspace((unsigned char)P->p[len]))
            len++;
        if (len == 0)
            return 0;
        snprintf(tok, sizeof tok, "%.*s", (int)(len < sizeof tok ? len : sizeof tok - 1), P->p);
        P->p += len;
        *out = strtod(tok, &end);
        if (*end != '\0' || len >= sizeof tok ||
            (t != T_FLOAT32 && t != T_FLOAT64 && (*out != floor(*out) || !bn__ply_in_range(t, *out)))) {
            snprintf(bad, nbad, "%s", tok);
            return 0;
        }
        return 1;
    }
    if ((size_t)(P->end - P->p) < n)
        return 0;
    memcpy(b, P->p, n);
    P->p += n;
    if (P->format == F_BE)
        for (size_t i = 0; i < n / 2; i++) {
            unsigned char x = b[i];
            b[i] = b[n - 1 - i];
            b[n - 1 - i] = x;
        }
    switch (t) {
    case T_INT8: *out = (int8_t)b[0]; break;
    case T_UINT8: *out = b[0]; break;
    case T_INT16: { int16_t v; memcpy(&v, b, 2); *out = v; break; }
    case T_UINT16: { uint16_t v; memcpy(&v, b, 2); *out = v; break; }
    case T_INT32: { int32_t v; memcpy(&v, b, 4); *out = v; break; }
    case T_UINT32: { uint32_t v; memcpy(&v, b, 4); *out = v; break; }
    case T_FLOAT32: { float v; memcpy(&v, b, 4); *out = v; break; }
    case T_FLOAT64: { double v; memcpy(&v, b, 8); *out = v; break; }
    default: return 0;
    }
    return 1;
}

/* Where each wanted property sits in an element (-1: absent). */
typedef struct bn__ply_cols {
    int x, y, z, idx, vrgb[3], frgb[3], fprop[6];
    double frgb_scale[3], vrgb_scale[3];
} bn__ply_cols;

static double bn__colour_scale(bn__ply_type t) { return t == T_FLOAT32 || t == T_FLOAT64 ? 1.0 : 1.0 / 255.0; }

static bn_status bn__ply_columns(const bn__ply *P, const bn__ply_elem *e, int is_v, int is_f, bn__ply_cols *c,
                                 bn_error *err)
{
    static const char *const rgb[3] = {"red", "green", "blue"};
    int nrgb = 0, nrefl = 0, nemis = 0;
    memset(c, -1, sizeof *c);
    for (size_t k = 0; k < e->nprops; k++) {
        const bn__ply_prop *pr = &e->props[k];
        for (int q = 0; q < 3; q++)
            if (strcmp(pr->name, rgb[q]) == 0) {
                if (pr->list && is_f)
                    return bn_error_set(err, BN_EINPUT, "%s: face colour '%s' is a list", P->path, pr->name);
                if (!pr->list) {
                    if (is_v) {
                        c->vrgb[q] = (int)k;
                        c->vrgb_scale[q] = bn__colour_scale(pr->type);
                    } else if (is_f) {
                        c->frgb[q] = (int)k;
                        c->frgb_scale[q] = bn__colour_scale(pr->type);
                        nrgb++;
                    }
                }
            }
        if (is_v && !pr->list) {
            if (strcmp(pr->name, "x") == 0) c->x = (int)k;
            if (strcmp(pr->name, "y") == 0) c->y = (int)k;
            if (strcmp(pr->name, "z") == 0) c->z = (int)k;
        }
        if (is_f && pr->list && (strcmp(pr->name, "vertex_indices") == 0 || strcmp(pr->name, "vertex_index") == 0))
            c->idx = (int)k;
        for (int q = 0; q < 6 && is_f; q++)
            if (!pr->list && strcmp(pr->name, bn__face_props[q]) == 0) {
                c->fprop[q] = (int)k;
                if (q < 3)
                    nrefl++;
                else
                    nemis++;
            }
    }
    if (is_v && (c->x < 0 || c->y < 0 || c->z < 0))
        return bn_error_set(err, BN_EINPUT, "%s: the vertex element lacks x, y or z", P->path);
    if (is_f) {
        if (c->idx < 0)
            return bn_error_set(err, BN_EINPUT, "%s: the face element has no vertex_indices list", P->path);
        if (nrefl != 0 && nrefl != 3)
            return bn_error_set(err, BN_EINPUT, "%s: face reflectance needs all of reflectance_red, _green, _blue",
                                P->path);
        if (nemis != 0 && nemis != 3)
            return bn_error_set(err, BN_EINPUT, "%s: face emission needs all of emission_red, _green, _blue", P->path);
        if (nrgb != 0 && nrgb != 3)
            return bn_error_set(err, BN_EINPUT, "%s: face colours need all of red, green and blue", P->path);
    }
    return BN_OK;
}

/* Growable per-face columns. */
static int bn__faces_grow(bn__ply_faces *F, size_t need)
{
    static const size_t w[3] = {1, 6, 3};
    void **cols[3] = {(void **)&F->line, (void **)&F->props, (void **)&F->rgb};
    size_t sz[3] = {sizeof(unsigned), sizeof(double), sizeof(double)};
    for (int q = 0; q < 3; q++) {
        void *p = bn__realloc_array(*cols[q], need * w[q], sz[q]);
        if (!p)
            return 0;
        *cols[q] = p;
    }
    return 1;
}

typedef struct bn__ply_state {
    bn__ply_faces F;
    double *vrgb;               /* 3 per vertex when the vertices carry colours */
    int vertex_colour;
    size_t nverts, dropped, idx_cap;
    size_t *idx;
    int seen_vertex;
} bn__ply_state;

/* What one record holds as it is read. */
typedef struct bn__ply_rec {
    double p[3], fp[6], rgb[3];   /* position, face properties, colour */
    size_t nidx;                  /* vertex indices read into S->idx */
    unsigned start;               /* its first line (ASCII) */
    unsigned long long r;         /* its number within the element */
} bn__ply_rec;

/* "path:line:" for ASCII files (empty for binary ones), with or without the colon. */
static void bn__ply_where(const bn__ply *P, unsigned line, int colon, char *where, size_t size)
{
    where[0] = '\0';
    if (P->format == F_ASCII)
        snprintf(where, size, colon ? "%u:" : "%u", line);
}

/* A face's vertex index, checked against the vertices read. */
static bn_status bn__ply_push_index(const bn__ply *P, bn__ply_state *S, bn__ply_rec *R, double v, bn_error *err)
{
    if (R->nidx == S->idx_cap) {
        size_t cap = S->idx_cap ? 2 * S->idx_cap : 16;
        size_t *q = bn__realloc_array(S->idx, cap, sizeof(size_t));
        if (!q)
            return bn_error_set(err, BN_ENOMEM, "out of memory");
        S->idx = q;
        S->idx_cap = cap;
    }
    if (v < 0 || v >= (double)S->nverts || !S->seen_vertex) {
        char where[24];
        bn__ply_where(P, R->start, 1, where, sizeof where);
        return bn_error_set(err, BN_EINPUT, "%s:%s face %llu: vertex index %.0f is out of range (%zu vertices)",
                            P->path, where, R->r, v, S->nverts);
    }
    S->idx[R->nidx++] = (size_t)v;
    return BN_OK;
}

/* Value v of property k where the columns say it goes. */
static void bn__ply_take(const bn__ply_cols *c, int k, double v, int is_v, int is_f, bn__ply_rec *R)
{
    if (is_v)
        for (int q = 0; q < 3; q++) {
            if (k == (q == 0 ? c->x : q == 1 ? c->y : c->z))
                R->p[q] = v;
            if (k == c->vrgb[q])
                R->rgb[q] = v * c->vrgb_scale[q];
        }
    for (int q = 0; q < 6 && is_f; q++)
        if (k == c->fprop[q])
            R->fp[q] = v;
    for (int q = 0; q < 3 && is_f; q++)
        if (k == c->frgb[q])
            R->rgb[q] = v * c->frgb_scale[q];
}

/* A finished vertex record into the soup (and its colour). */
static bn_status bn__ply_vertex_done(const bn__ply *P, bn__ply_state *S, const bn__ply_rec *R, bn__soup *out,
                                     bn_error *err)
{
    for (int q = 0; q < 3; q++)
        if (!isfinite(R->p[q])) {
            char where[24];
            bn__ply_where(P, R->start, 0, where, sizeof where);
            return bn_error_set(err, BN_EINPUT, "%s:%s vertex %llu has a non-finite coordinate (%g)", P->path, where,
                                R->r, R->p[q]);
        }
    if (!bn__soup_add_vertex(out, R->p))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    if (S->vertex_colour)
        memcpy(S->vrgb + 3 * (out->nverts - 1), R->rgb, sizeof R->rgb);
    return BN_OK;
}

/* A finished face record into the soup and the face columns; one with a repeated vertex has no
 * area to speak of and is dropped (counted). */
static bn_status bn__ply_face_done(const bn__ply *P, const bn__ply_cols *c, bn__ply_state *S, const bn__ply_rec *R,
                                   bn__soup *out, bn_error *err)
{
    char where[24];
    size_t f = S->F.n;
    int distinct = 1;
    bn__ply_where(P, R->start, 1, where, sizeof where);
    if (R->nidx < 3)
        return bn_error_set(err, BN_EINPUT, "%s:%s face %llu has %zu vertices (at least 3 needed)", P->path, where,
                            R->r, R->nidx);
    for (int q = 0; q < 6; q++)
        if (c->fprop[q] >= 0 && !isfinite(R->fp[q]))
            return bn_error_set(err, BN_EINPUT, "%s:%s face %llu: %s is not finite", P->path, where, R->r,
                                bn__face_props[q]);
    for (size_t a = 0; a < R->nidx && distinct; a++)
        for (size_t b = a + 1; b < R->nidx && distinct; b++)
            distinct = S->idx[a] != S->idx[b];
    if (!distinct) {
        S->dropped++;
        return BN_OK;
    }
    if (!bn__faces_grow(&S->F, f + 1) ||
        !bn__soup_add_polygon(out, S->idx, (unsigned)R->nidx, 0, P->format == F_ASCII ? R->start : 0))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    S->F.line[f] = P->format == F_ASCII ? R->start : 0;
    memcpy(S->F.props + 6 * f, R->fp, sizeof R->fp);
    memcpy(S->F.rgb + 3 * f, R->rgb, sizeof R->rgb);
    S->F.n++;
    return BN_OK;
}

/* One record of element e: its values into the soup (vertex) or the face columns (face). */
static bn_status bn__ply_record(bn__ply *P, const bn__ply_elem *e, const bn__ply_cols *c, int is_v, int is_f,
                                unsigned long long r, bn__ply_state *S, bn__soup *out, bn_error *err)
{
    bn__ply_rec R;
    char bad[80];
    memset(&R, 0, sizeof R);
    R.r = r;
    bn__ply_skip_ws(P);
    R.start = P->line;
    for (size_t k = 0; k < e->nprops; k++) {
        const bn__ply_prop *pr = &e->props[k];
        double v;
        size_t n = 1;
        if (pr->list) {
            if (!bn__ply_value(P, pr->count_type, &v, bad, sizeof bad)) {
                if (bad[0])
                    return bn_error_set(err, BN_EINPUT, "%s:%u: '%s' is not a valid %s count in %s %llu", P->path,
                                        P->line, bad, pr->name, e->name, r);
                goto truncated;
            }
            if (v < 0)
                return bn_error_set(err, BN_EINPUT, "%s:%u: %s count %g is negative in %s %llu", P->path, P->line,
                                    pr->name, v, e->name, r);
            n = (size_t)v;   /* an integer type's value: at most 2^32 - 1 */
        }
        for (size_t j = 0; j < n; j++) {
            if (!bn__ply_value(P, pr->type, &v, bad, sizeof bad)) {
                if (bad[0])
                    return bn_error_set(err, BN_EINPUT, "%s:%u: '%s' is not a valid %s value in %s %llu", P->path,
                                        P->line, bad, pr->name, e->name, r);
                goto truncated;
            }
            if ((int)k == c->idx) {
                bn_status st = bn__ply_push_index(P, S, &R, v, err);
                if (st != BN_OK)
                    return st;
            }
            bn__ply_take(c, (int)k, v, is_v, is_f, &R);
        }
    }
    if (is_v)
        return bn__ply_vertex_done(P, S, &R, out, err);
    if (is_f)
        return bn__ply_face_done(P, c, S, &R, out, err);
    return BN_OK;
truncated:
    return bn_error_set(err, BN_EINPUT, "%s: the file ends inside element '%s' (the header promises %llu)", P->path,
                        e->name, e->count);
}

static bn_status bn__ply_body(bn__ply *P, bn__ply_state *S, bn__soup *out, bn_error *err)
{
    int seen_face = 0;
    for (size_t ei = 0; ei < P->nelems; ei++) {
        const bn__ply_elem *e = &P->elems[ei];
        int is_v = strcmp(e->name, "vertex") == 0, is_f = strcmp(e->name, "face") == 0;
        bn__ply_cols c;
        bn_status st = bn__ply_columns(P, e, is_v, is_f, &c, err);
        if (st != BN_OK)
            return st;
        /* a record takes at least one byte (binary) or two (ASCII): a count above that is a lie */
        if (e->count > (unsigned long long)(P->end - P->p))
            return bn_error_set(err, BN_EINPUT, "%s: the file ends inside element '%s' (the header promises %llu)",
                                P->path, e->name, e->count);
        if (is_v) {
            S->nverts = (size_t)e->count;
            S->seen_vertex = 1;
            S->vertex_colour = c.vrgb[0] >= 0 && c.vrgb[1] >= 0 && c.vrgb[2] >= 0;
            if (S->vertex_colour && !(S->vrgb = bn__malloc_array(S->nverts ? S->nverts : 1, 3 * sizeof(double))))
                return bn_error_set(err, BN_ENOMEM, "out of memory for %zu vertex colours", S->nverts);
        }
        if (is_f) {
            seen_face = 1;
            S->F.has_refl = c.fprop[0] >= 0;
            S->F.has_emis = c.fprop[3] >= 0;
            S->F.has_rgb = c.frgb[0] >= 0;
        }
        for (unsigned long long r = 0; r < e->count; r++) {
            st = bn__ply_record(P, e, &c, is_v, is_f, r, S, out, err);
            if (st != BN_OK)
                return st;
        }
    }
    if (!S->seen_vertex || !seen_face)
        return bn_error_set(err, BN_EINPUT, "%s: a PLY scene needs vertex and face elements", P->path);
    if (S->F.n == 0 && S->dropped == 0)
        return bn_error_set(err, BN_EINPUT, "%s: the PLY file has no faces", P->path);
    return BN_OK;
}

/* ---- materials ---- */

/* Polygon f's reflectance and emission from what the file gives; its corners at out->idx[first..]. */
static void bn__ply_face_material(const bn__ply_state *S, const bn__soup *out, size_t f, size_t first, double key[6])
{
    const bn__ply_faces *F = &S->F;
    for (int q = 0; q < 3; q++) {
        key[q] = 0.5;
        key[3 + q] = F->has_emis ? F->props[6 * f + 3 + q] : 0;
    }
    if (F->has_refl) {
        memcpy(key, F->props + 6 * f, 3 * sizeof(double));
    } else if (F->has_rgb) {
        memcpy(key, F->rgb + 3 * f, 3 * sizeof(double));
    } else if (S->vertex_colour) {
        for (int q = 0; q < 3; q++) {
            double s = 0;
            for (unsigned k = 0; k < out->counts[f]; k++)
                s += S->vrgb[3 * out->idx[first + k] + (size_t)q];
            key[q] = s / out->counts[f];
        }
    }
}

static bn_status bn__ply_materials(const bn__ply *P, const bn__ply_state *S, bn__soup *out, bn_error *err)
{
    size_t n = S->F.n, first = 0;
    double *keys = bn__malloc_array(n ? 6 * n : 1, sizeof(double));
    bn_status st = BN_OK;
    if (!keys)
        return bn_error_set(err, BN_ENOMEM, "out of memory for the materials of %zu faces", n);
    for (size_t f = 0; f < n && st == BN_OK; f++) {
        double *key = keys + 6 * f;
        char where[24] = "";
        bn__ply_face_material(S, out, f, first, key);
        first += out->counts[f];
        if (S->F.line[f])
            snprintf(where, sizeof where, ":%u", S->F.line[f]);
        for (int q = 0; q < 3 && st == BN_OK; q++) {
            if (!(key[q] >= 0 && key[q] <= 1))
                st = bn_error_set(err, BN_EINPUT, "%s%s: face %zu: reflectance %g is outside [0, 1]", P->path, where, f,
                                  key[q]);
            else if (!(key[3 + q] >= 0))
                st = bn_error_set(err, BN_EINPUT, "%s%s: face %zu: emission %g is negative", P->path, where, f,
                                  key[3 + q]);
        }
    }
    if (st == BN_OK && !bn__soup_materials_from_keys(out, keys, "ply"))
        st = bn_error_set(err, BN_ENOMEM, "out of memory");
    free(keys);
    return st;
}

bn_status bn__read_ply(const char *path, bn__soup *out, const bn_log *log, bn_error *err)
{
    bn__ply P;
    bn__ply_state S;
    char *text = NULL;
    size_t size = 0;
    const char *body;
    bn_status st = bn__read_file(path, &text, &size, err);
    if (st != BN_OK)
        return st;
    memset(&P, 0, sizeof P);
    memset(&S, 0, sizeof S);
    P.path = path;
    P.text = P.p = text;
    P.end = text + size;
    {
        /* the header is text; so is an ASCII body */
        const char *eh = strstr(text, "end_header");
        size_t hlen = eh ? (size_t)(eh - text) : size;
        st = bn__ply_text_check(&P, text, text + hlen, 1, err);
    }
    if (st == BN_OK)
        st = bn__ply_header(&P, err);
    body = P.p;
    if (st == BN_OK && P.format == F_ASCII)
        st = bn__ply_text_check(&P, body, P.end, P.line, err);
    if (st == BN_OK)
        st = bn__ply_body(&P, &S, out, err);
    if (st == BN_OK)
        st = bn__ply_materials(&P, &S, out, err);
    if (st == BN_OK && S.dropped)
        bn_warnf(log, BN_W_FACE_DROPPED, (double)S.dropped, "%s: %zu faces with a repeated vertex were dropped", path, S.dropped);
    if (st == BN_OK && !S.F.has_refl && !S.F.has_rgb && !S.vertex_colour)
        bn_warnf(log, BN_W_NO_COLOURS, NAN, "%s: no colours or reflectance properties: every face has reflectance 0.5", path);
    free(S.F.line);
    free(S.F.props);
    free(S.F.rgb);
    free(S.vrgb);
    free(S.idx);
    free(text);
    return st;
}
