/* OFF scene input. ASCII OFF is read once and parsed here, record by record, with every error
 * naming the file, line and token: the keyword line ([ST][C][N]OFF), the counts line
 * "vertices faces [edges]", vertex lines "x y z [nx ny nz] [r g b [a]] [s t]" and face lines
 * "n i_1 .. i_n [r g b [a]]"; '#' comments anywhere. Colours are 0..255 integers or 0..1 reals.
 * A face takes its own colour as reflectance when every face has one, else the mean of its
 * vertices' colours (COFF), else grey 0.5 with a warning. OFF has no emission.
 *
 * Binary OFF goes to OpenMesh (src/adapters), which reads it from its path: its reader decides the
 * binary layout only when it opens a file. OpenMesh is not used for ASCII OFF: its reader stops at
 * comments, and the fuzzer found it looping on malformed records and reserving whatever count a
 * header announces. Format: Geomview's OFF (http://www.geomview.org/docs/html/OFF.html). */
#include "scene/scene_internal.h"
#include "adapters/adapters.h"

#include <ctype.h>
#include <math.h>
#include <string.h>

#define BN__OFF_TOKENS 72   /* a face line: up to 64 corners, a colour */

typedef struct bn__off {
    const char *path;
    char *text;       /* comments blanked out, line breaks kept */
    char *p, *end;
    unsigned line;
    int normals, colours, texcoords;   /* the keyword's N, C, ST */
} bn__off;

/* '#' to the end of its line becomes spaces; any other control byte is an error. */
static bn_status bn__off_clean(bn__off *O, bn_error *err)
{
    int comment = 0;
    for (char *q = O->text; q < O->end; q++) {
        unsigned char ch = (unsigned char)*q;
        if (ch == '#')
            comment = 1;
        if (ch == '\n')
            comment = 0;
        else if (comment)
            *q = ' ';
        else if (ch < 0x20 && ch != '\t' && ch != '\r')
            return bn_error_set(err, BN_EINPUT, "%s: an ASCII OFF file holds a control byte (0x%02x)", O->path, ch);
    }
    return BN_OK;
}

/* The next non-blank line's tokens (at most max; *n set), its number in *line; 0 at the end. */
static int bn__off_tokens(bn__off *O, char **tok, size_t max, size_t *n)
{
    while (O->p < O->end) {
        char *nl = memchr(O->p, '\n', (size_t)(O->end - O->p)), *q = O->p, *e = nl ? nl : O->end;
        O->line++;
        O->p = nl ? nl + 1 : O->end;
        *n = 0;
        while (q < e) {
            while (q < e && isspace((unsigned char)*q))
                q++;
            if (q >= e)
                break;
            if (*n < max)
                tok[*n] = q;
            (*n)++;
            while (q < e && !isspace((unsigned char)*q))
                q++;
            if (q < e)
                *q++ = '\0';
            else if (e < O->end)
                *e = '\0';   /* the line break itself ends the last token */
        }
        if (*n)
            return 1;
    }
    return 0;
}

/* The keyword: [ST][C][N]OFF alone on its line; 4OFF (homogeneous) and nOFF (any dimension) are not read. */
static bn_status bn__off_keyword(bn__off *O, char **tok, size_t ntok, bn_error *err)
{
    const char *k = tok[0];
    if (strncmp(k, "ST", 2) == 0)
        O->texcoords = 1, k += 2;
    if (*k == 'C')
        O->colours = 1, k++;
    if (*k == 'N')
        O->normals = 1, k++;
    if (strcmp(k, "OFF") != 0 || ntok != 1) {
        if (strstr(tok[0], "4OFF") || strstr(tok[0], "nOFF"))
            return bn_error_set(err, BN_EINPUT, "%s:%u: '%s': 4OFF and nOFF are not read (3-D OFF only)", O->path,
                                O->line, tok[0]);
        return bn_error_set(err, BN_EINPUT, "%s: not an OFF file: no line with the 'OFF' keyword alone, followed by a "
                                            "line 'vertices faces edges'", O->path);
    }
    return BN_OK;
}

/* Every token a finite number. */
static bn_status bn__off_numbers(const bn__off *O, char **tok, size_t n, double *num, bn_error *err)
{
    for (size_t k = 0; k < n; k++) {
        char *end;
        num[k] = strtod(tok[k], &end);
        if (end == tok[k] || *end != '\0' || !isfinite(num[k]))
            return bn_error_set(err, BN_EINPUT, "%s:%u: '%s' is not a finite number", O->path, O->line, tok[k]);
    }
    return BN_OK;
}

/* Colour components as reflectance: reals as they are, integers (no '.', 'e') as n / 255. */
static void bn__off_colour(char **tok, const double *num, double rgb[3])
{
    int real = 0;
    for (int c = 0; c < 3; c++)
        real |= strpbrk(tok[c], ".eE") != NULL;
    for (int c = 0; c < 3; c++)
        rgb[c] = real ? num[c] : num[c] / 255.0;
}

typedef struct bn__off_read {
    double *vrgb;   /* 3 per vertex (COFF) */
    double *keys;   /* 6 per face: reflectance, emission (0) */
    int face_colours;
    size_t dropped;
} bn__off_read;

static bn_status bn__off_vertices(bn__off *O, unsigned long long nv, bn__off_read *R, bn__soup *out, bn_error *err)
{
    char *tok[BN__OFF_TOKENS];
    double num[BN__OFF_TOKENS];
    size_t need = 3 + (O->normals ? 3 : 0), n;
    for (unsigned long long v = 0; v < nv; v++) {
        bn_status st;
        if (!bn__off_tokens(O, tok, BN__OFF_TOKENS, &n))
            return bn_error_set(err, BN_EINPUT, "%s: the file ends after %llu of %llu vertices", O->path, v, nv);
        if (n > BN__OFF_TOKENS)
            n = BN__OFF_TOKENS;
        if ((st = bn__off_numbers(O, tok, n, num, err)) != BN_OK)
            return st;
        if (n < need + (O->colours ? 3 : 0))
            return bn_error_set(err, BN_EINPUT, "%s:%u: vertex %llu needs %zu values (%s%s)", O->path, O->line, v,
                                need + (O->colours ? 3 : 0), O->normals ? "x y z nx ny nz" : "x y z",
                                O->colours ? " r g b" : "");
        if (!bn__soup_add_vertex(out, num))
            return bn_error_set(err, BN_ENOMEM, "out of memory");
        if (O->colours)
            bn__off_colour(tok + need, num + need, R->vrgb + 3 * v);
    }
    return BN_OK;
}

static bn_status bn__off_faces(bn__off *O, unsigned long long nv, unsigned long long nf, bn__off_read *R,
                               bn__soup *out, bn_error *err)
{
    char *tok[BN__OFF_TOKENS];
    double num[BN__OFF_TOKENS];
    size_t idx[BN__OFF_TOKENS], n;
    R->face_colours = nf > 0;
    for (unsigned long long f = 0; f < nf; f++) {
        size_t k, nc, p = out->npolys;
        int distinct = 1;
        bn_status st;
        if (!bn__off_tokens(O, tok, BN__OFF_TOKENS, &n))
            return bn_error_set(err, BN_EINPUT, "%s: the file ends after %llu of %llu faces", O->path, f, nf);
        if (n > BN__OFF_TOKENS)
            return bn_error_set(err, BN_EINPUT, "%s:%u: face %llu has more than %d values", O->path, O->line, f,
                                BN__OFF_TOKENS);
        if ((st = bn__off_numbers(O, tok, n, num, err)) != BN_OK)
            return st;
        if (num[0] != floor(num[0]) || num[0] < 3 || num[0] > BN__OFF_TOKENS - 8 || n < (size_t)num[0] + 1)
            return bn_error_set(err, BN_EINPUT, "%s:%u: face %llu: '%s' vertices, or fewer indices than that", O->path,
                                O->line, f, tok[0]);
        nc = (size_t)num[0];   /* in [3, 64]: checked above */
        for (k = 1; k <= nc; k++) {
            if (num[k] != floor(num[k]) || num[k] < 0 || num[k] >= (double)nv)
                return bn_error_set(err, BN_EINPUT, "%s:%u: face %llu: vertex index %s is out of range (%llu vertices)",
                                    O->path, O->line, f, tok[k], nv);
            idx[k - 1] = (size_t)num[k];
            for (size_t j = 0; j + 1 < k; j++)
                distinct &= idx[j] != idx[k - 1];
        }
        if (!distinct) {   /* a repeated corner: no area to speak of */
            R->dropped++;
            continue;
        }
        if (!bn__soup_add_polygon(out, idx, (unsigned)nc, 0, O->line))
            return bn_error_set(err, BN_ENOMEM, "out of memory");
        if (n >= nc + 4)
            bn__off_colour(tok + nc + 1, num + nc + 1, R->keys + 6 * p);
        else
            R->face_colours = 0;
    }
    return BN_OK;
}

/* Each face's key: its own colour, else its vertices' mean colour, else grey. */
static bn_status bn__off_materials(bn__off *O, bn__off_read *R, const bn_log *log, bn__soup *out, bn_error *err)
{
    size_t first = 0;
    for (size_t f = 0; f < out->npolys; f++) {
        double *key = R->keys + 6 * f;
        if (!R->face_colours) {
            for (int c = 0; c < 3; c++) {
                double s = 0;
                for (unsigned k = 0; O->colours && k < out->counts[f]; k++)
                    s += R->vrgb[3 * out->idx[first + k] + (size_t)c];
                key[c] = O->colours ? s / out->counts[f] : 0.5;
            }
        }
        key[3] = key[4] = key[5] = 0;
        for (int c = 0; c < 3; c++)
            if (!(key[c] >= 0 && key[c] <= 1))
                return bn_error_set(err, BN_EINPUT, "%s:%u: face %zu: reflectance %g is outside [0, 1]", O->path,
                                    out->line[f], f, key[c]);
        first += out->counts[f];
    }
    if (!R->face_colours && !O->colours)
        bn_warnf(log, BN_W_NO_COLOURS, NAN, "%s: no colours: every face has reflectance 0.5", O->path);
    if (!bn__soup_materials_from_keys(out, R->keys, "off"))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    return BN_OK;
}

static bn_status bn__read_off_ascii(bn__off *O, const bn_log *log, bn__soup *out, bn_error *err)
{
    char *tok[BN__OFF_TOKENS];
    size_t n, size = (size_t)(O->end - O->text);
    unsigned long long nv, nf;
    bn__off_read R;
    bn_status st;
    memset(&R, 0, sizeof R);
    if ((st = bn__off_clean(O, err)) != BN_OK)
        return st;
    if (!bn__off_tokens(O, tok, BN__OFF_TOKENS, &n))
        return bn_error_set(err, BN_EINPUT, "%s: not an OFF file: no line with the 'OFF' keyword alone, followed by a "
                                            "line 'vertices faces edges'", O->path);
    if ((st = bn__off_keyword(O, tok, n, err)) != BN_OK)
        return st;
    if (!bn__off_tokens(O, tok, BN__OFF_TOKENS, &n) || n < 2 || sscanf(tok[0], "%llu", &nv) != 1 ||
        sscanf(tok[1], "%llu", &nf) != 1 || tok[0][0] == '-' || tok[1][0] == '-')
        return bn_error_set(err, BN_EINPUT, "%s: not an OFF file: no line with the 'OFF' keyword alone, followed by a "
                                            "line 'vertices faces edges'", O->path);
    /* a vertex takes at least 4 bytes of text, a face 4 more: a larger count is a lie */
    if (nv > size / 4 || nf > size / 4)
        return bn_error_set(err, BN_EINPUT,
                            "%s: the header announces %llu vertices and %llu faces, more than a file of %zu bytes can "
                            "hold", O->path, nv, nf, size);
    R.vrgb = bn__malloc_array(O->colours && nv ? (size_t)nv : 1, 3 * sizeof(double));
    R.keys = bn__calloc(nf ? (size_t)nf : 1, 6 * sizeof(double));
    if (!R.vrgb || !R.keys)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for %llu vertices and %llu faces", nv, nf);
    if (st == BN_OK)
        st = bn__off_vertices(O, nv, &R, out, err);
    if (st == BN_OK)
        st = bn__off_faces(O, nv, nf, &R, out, err);
    if (st == BN_OK && out->npolys == 0)
        st = bn_error_set(err, BN_EINPUT, "%s: the OFF file has no faces", O->path);
    if (st == BN_OK)
        st = bn__off_materials(O, &R, log, out, err);
    if (st == BN_OK && R.dropped)
        bn_warnf(log, BN_W_FACE_DROPPED, (double)R.dropped, "%s: %zu faces with a repeated vertex were dropped", O->path, R.dropped);
    free(R.vrgb);
    free(R.keys);
    return st;
}

/* Is the file's keyword line "... BINARY"? Reads only its first bytes. */
static int bn__off_is_binary(const char *path, char *head, size_t cap, size_t *got)
{
    FILE *fp = fopen(path, "rb");
    char *nl;
    *got = 0;
    if (!fp)
        return 0;
    *got = fread(head, 1, cap - 1, fp);
    fclose(fp);
    head[*got] = '\0';
    nl = memchr(head, '\n', *got);
    if (nl)
        *nl = '\0';
    return strstr(head, "BINARY") != NULL;   /* a NUL earlier on the line ends the search: not binary */
}

static int bn__sink_vertex(void *user, const double p[3]) { return bn__soup_add_vertex(user, p); }
static int bn__sink_polygon(void *user, const size_t *idx, unsigned n)
{
    return bn__soup_add_polygon(user, idx, n, 0, 0);
}

/* Binary OFF through OpenMesh into the soup, every face grey 0.5 (material "off0"). */
static bn_status bn__read_off_bin(const char *path, bn__soup *out, const bn_log *log, bn_error *err)
{
    bn__mesh_sink sink = {out, bn__sink_vertex, bn__sink_polygon};
    bn_material grey;
    memset(&grey, 0, sizeof grey);
    snprintf(grey.name, sizeof grey.name, "off0");
    grey.rho[0] = grey.rho[1] = grey.rho[2] = 0.5;
    if (!bn__soup_add_material(out, &grey))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    return bn__read_off_binary(path, &sink, log, err);
}

bn_status bn__read_off(const char *path, bn__soup *out, const bn_log *log, bn_error *err)
{
    bn__off O;
    char head[64];
    size_t size, got;
    bn_status st;
    /* the keyword line decides: binary OFF is OpenMesh's to read, from the path */
    if (bn__off_is_binary(path, head, sizeof head, &got))
        return bn__read_off_bin(path, out, log, err);
    memset(&O, 0, sizeof O);
    O.path = path;
    st = bn__read_file(path, &O.text, &size, err);
    if (st != BN_OK)
        return st;
    O.p = O.text;
    O.end = O.text + size;
    st = bn__read_off_ascii(&O, log, out, err);
    free(O.text);
    return st;
}
