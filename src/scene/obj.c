/* Wavefront OBJ and MTL reader: Kd is diffuse reflectance, Ke emitted radiance.
 *
 * Our own reader rather than tinyobjloader: every error must name its line, and tinyobjloader
 * turns `nan` into 0 and keeps out-of-range indices silently, so validation would need a
 * second full parser anyway. tests/ compare this reader with tinyobjloader on real files.
 * Handles CRLF, tabs, comments after values, relative (negative) indices, v/vt/vn forms,
 * `g`/`o`/`s` anywhere, several mtllib files, and MTL statements with leading spaces. */
#define _POSIX_C_SOURCE 200809L
#include "scene/scene_internal.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define BN__MAX_FACE_VERTS 65536u

/* Strips a trailing comment and CR/LF; returns the line. */
static char *bn__strip(char *s)
{
    char *hash = strchr(s, '#');
    size_t n;
    if (hash)
        *hash = '\0';
    n = strlen(s);
    while (n > 0 && (s[n - 1] == '\n' || s[n - 1] == '\r' || isspace((unsigned char)s[n - 1])))
        s[--n] = '\0';
    while (*s && isspace((unsigned char)*s))
        s++;
    return s;
}

/* Next whitespace-separated token, or NULL. */
static char *bn__token(char **cursor)
{
    char *s = *cursor, *start;
    while (*s && isspace((unsigned char)*s))
        s++;
    if (!*s) {
        *cursor = s;
        return NULL;
    }
    start = s;
    while (*s && !isspace((unsigned char)*s))
        s++;
    if (*s)
        *s++ = '\0';
    *cursor = s;
    return start;
}

/* Parses a finite double token; 0 on failure (empty, junk, nan, inf, overflow). */
static int bn__parse_double(const char *tok, double *out)
{
    char *end;
    double v;
    if (!tok)
        return 0;
    errno = 0;
    v = strtod(tok, &end);
    if (end == tok || *end != '\0')
        return 0;
    if (!isfinite(v) || (errno == ERANGE && fabs(v) > 1.0))
        return 0;
    *out = v;
    return 1;
}

static const char *bn__show(const char *tok) { return tok ? tok : "(missing)"; }

typedef struct bn__mtl_ref {
    char name[BN_NAME_MAX];
} bn__mtl_ref;

static int bn__find_material(const bn__soup *s, const char *name)
{
    for (size_t i = 0; i < s->nmats; i++)
        if (strcmp(s->mats[i].name, name) == 0)
            return (int)i;
    return -1;
}

/* Reads `values` finite numbers (a single value means grey). */
static bn_status bn__mtl_rgb(const char *file, unsigned line, const char *key, char **cur,
                             double out[3], bn_error *err)
{
    char *t0 = bn__token(cur), *t1 = bn__token(cur), *t2 = bn__token(cur);
    if (t0 && (strcmp(t0, "spectral") == 0 || strcmp(t0, "xyz") == 0))
        return bn_error_set(err, BN_EINPUT, "%s:%u: %s %s is not supported: give RGB values", file, line, key, t0);
    if (!bn__parse_double(t0, &out[0]))
        return bn_error_set(err, BN_EINPUT, "%s:%u: %s needs finite numbers, got '%s'", file, line, key, bn__show(t0));
    if (!t1) {
        out[1] = out[2] = out[0];
        return BN_OK;
    }
    if (!bn__parse_double(t1, &out[1]) || !bn__parse_double(t2, &out[2]))
        return bn_error_set(err, BN_EINPUT, "%s:%u: %s needs 1 or 3 finite numbers, got '%s %s %s'", file, line,
                            key, t0, bn__show(t1), bn__show(t2));
    return BN_OK;
}

/* The first control byte of a line (not tab, CR, LF, VT, FF), or -1: OBJ and MTL are text, and a
 * byte like NUL would silently cut the line short for every parser after it. */
static int bn__control_byte(const char *buf, ssize_t len)
{
    for (ssize_t k = 0; k < len; k++) {
        unsigned char b = (unsigned char)buf[k];
        if ((b < 0x20 && b != '\t' && b != '\r' && b != '\n' && b != '\v' && b != '\f') || b == 0x7f)
            return b;
    }
    return -1;
}

/* "newmtl NAME": a new material (Kd 0.8, the MTL default, until said), or the earlier one of that
 * name again (a warning: the later definition wins); *cur: its index. */
static bn_status bn__mtl_newmtl(const char *path, unsigned line, char *c, bn__soup *s, const bn_log *log, int *cur,
                                bn_error *err)
{
    char *name = bn__token(&c);
    bn_material m;
    if (!name)
        return bn_error_set(err, BN_EINPUT, "%s:%u: newmtl without a name", path, line);
    if (strlen(name) >= BN_NAME_MAX)
        return bn_error_set(err, BN_EINPUT, "%s:%u: material name longer than %d characters", path, line,
                            BN_NAME_MAX - 1);
    if ((*cur = bn__find_material(s, name)) >= 0) {
        bn_warnf(log, BN_W_MATERIAL, NAN, "%s:%u: material '%s' defined again; the later definition wins", path, line,
                 name);
        return BN_OK;
    }
    memset(&m, 0, sizeof m);
    snprintf(m.name, sizeof m.name, "%s", name);
    m.rho[0] = m.rho[1] = m.rho[2] = 0.8;
    if (!bn__soup_add_material(s, &m))
        return bn_error_set(err, BN_ENOMEM, "out of memory reading %s", path);
    *cur = (int)s->nmats - 1;
    return BN_OK;
}

/* "Kd r g b" (a reflectance in [0, 1]) or "Ke r g b" (an emission >= 0) of material cur. */
static bn_status bn__mtl_colour(const char *path, unsigned line, const char *kw, char *c, bn__soup *s, int cur,
                                bn_error *err)
{
    double v[3];
    int is_kd = kw[1] == 'd';
    bn_status st;
    if (cur < 0)
        return bn_error_set(err, BN_EINPUT, "%s:%u: %s before any newmtl", path, line, kw);
    if ((st = bn__mtl_rgb(path, line, kw, &c, v, err)) != BN_OK)
        return st;
    for (int k = 0; k < 3; k++) {
        if (is_kd && (v[k] < 0.0 || v[k] > 1.0))
            return bn_error_set(err, BN_EINPUT,
                                "%s:%u: material '%s': Kd %g is outside [0, 1] (reflectance above 1 makes the "
                                "light-transport series diverge)",
                                path, line, s->mats[cur].name, v[k]);
        if (!is_kd && v[k] < 0.0)
            return bn_error_set(err, BN_EINPUT, "%s:%u: material '%s': negative emission Ke %g", path, line,
                                s->mats[cur].name, v[k]);
    }
    memcpy(is_kd ? s->mats[cur].rho : s->mats[cur].Le, v, sizeof v);
    return BN_OK;
}

/* "map_Kd [options] FILE": material cur's reflectance texture, Kd times the map as the MTL format says
 * (the file beside the MTL; -clamp on: clamped; the other options are not applied, and said). */
static bn_status bn__mtl_map(const char *path, unsigned line, char *c, bn__soup *s, int cur, const bn_log *log,
                             bn_error *err)
{
    char file[4096], *t;
    int clamp = 0, tex;
    bn__texture tx;
    const char *slash = strrchr(path, '/');
    if (cur < 0)
        return bn_error_set(err, BN_EINPUT, "%s:%u: map_Kd before any newmtl", path, line);
    for (;;) {   /* options: -name and its values */
        while (*c && isspace((unsigned char)*c))
            c++;
        if (*c != '-' || !(t = bn__token(&c)))
            break;
        char *v = bn__token(&c);
        for (;;) {   /* -o, -s, -t take up to three numbers, -mm two */
            while (*c && isspace((unsigned char)*c))
                c++;
            if (!(isdigit((unsigned char)*c) || ((*c == '-' || *c == '.') && isdigit((unsigned char)c[1]))))
                break;
            bn__token(&c);
        }
        if (strcmp(t, "-clamp") == 0)
            clamp = v && strcmp(v, "on") == 0;
        else
            bn_warnf(log, BN_W_MATERIAL, NAN, "%s:%u: map_Kd option %s is not applied", path, line, t);
    }
    if (!*c)
        return bn_error_set(err, BN_EINPUT, "%s:%u: map_Kd without a file name", path, line);
    snprintf(file, sizeof file, "%.*s%s", c[0] == '/' || !slash ? 0 : (int)(slash - path) + 1, path, c);
    if (bn__texture_decode(file, NULL, 0, &tx, err) != BN_OK)
        return err && err->status == BN_ENOMEM ? BN_ENOMEM : bn_error_set(err, BN_EINPUT, "%s:%u: map_Kd: %s", path,
                                                                         line, err ? err->msg : file);
    tx.wrap[0] = tx.wrap[1] = clamp ? BN__WRAP_CLAMP : BN__WRAP_REPEAT;
    if ((tex = bn__soup_add_texture(s, &tx)) < 0 || !bn__soup_set_material_texture(s, (unsigned)cur, tex)) {
        free(tx.rgb);
        free(tx.rgb8);
        return bn_error_set(err, BN_ENOMEM, "out of memory for %s", file);
    }
    return BN_OK;
}

static bn_status bn__read_mtl(const char *path, const char *objpath, unsigned objline, bn__soup *s,
                              const bn_log *log, bn_error *err)
{
    FILE *fp = fopen(path, "rb");
    char *buf = NULL;
    size_t cap = 0;
    unsigned line = 0;
    int cur = -1;
    ssize_t len;
    bn_status st = BN_OK;
    if (!fp)
        return bn_error_set(err, BN_EIO, "%s:%u: cannot open material library %s: %s", objpath, objline, path,
                            strerror(errno));
    while (st == BN_OK && (len = getline(&buf, &cap, fp)) >= 0) {
        char *c, *kw;
        int cb;
        line++;
        if ((cb = bn__control_byte(buf, len)) >= 0) {
            st = bn_error_set(err, BN_EINPUT, "%s:%u: control byte 0x%02x in MTL text (not a text file?)", path, line, cb);
            break;
        }
        c = bn__strip(buf);
        if (!(kw = bn__token(&c)))
            continue;
        if (strcmp(kw, "newmtl") == 0)
            st = bn__mtl_newmtl(path, line, c, s, log, &cur, err);
        else if (strcmp(kw, "Kd") == 0 || strcmp(kw, "Ke") == 0)
            st = bn__mtl_colour(path, line, kw, c, s, cur, err);
        else if (strcmp(kw, "map_Kd") == 0)
            st = bn__mtl_map(path, line, c, s, cur, log, err);
        /* Ka, Ks, Ns, Ni, d, Tr, illum and the other maps: not part of a Lambertian model; ignored. */
    }
    free(buf);
    if (st == BN_OK && ferror(fp))
        st = bn_error_set(err, BN_EIO, "%s: read error", path);
    fclose(fp);
    return st;
}

/* Checks the vt and vn parts of a reference "v", "v/vt", "v//vn" or "v/vt/vn" (integers or empty). */
static int bn__ref_tail_ok(const char *p)
{
    for (int part = 0; part < 2 && *p == '/'; part++) {
        p++;
        if (*p == '-' || *p == '+')
            p++;
        while (isdigit((unsigned char)*p))
            p++;
    }
    return *p == '\0';
}

/* Resolves an OBJ vertex reference (1-based, or negative relative): 1 ok, 0 out of range, -1 malformed. */
static int bn__resolve_index(const char *tok, size_t nverts, size_t *out)
{
    char *end;
    long long v;
    errno = 0;
    v = strtoll(tok, &end, 10);
    if (end == tok || errno == ERANGE || !bn__ref_tail_ok(end))
        return -1;
    if (v > 0 && (unsigned long long)v <= nverts) {
        *out = (size_t)(v - 1);
        return 1;
    }
    if (v < 0 && (unsigned long long)(-v) <= nverts) {
        *out = nverts - (size_t)(-v);
        return 1;
    }
    return 0;
}

bn_status bn__read_obj(const char *path, bn__soup *s, const bn_log *log, bn_error *err)
{
    FILE *fp = fopen(path, "rb");
    bn_status st;
    if (!fp)
        return bn_error_set(err, BN_EIO, "%s: cannot open: %s", path, strerror(errno));
    st = bn__read_obj_stream(fp, path, s, log, err);
    fclose(fp);
    return st;
}

/* The OBJ reader's state across lines. */
typedef struct bn__objr {
    const char *path;
    bn__soup *s;
    const bn_log *log;
    char *dir;              /* the file's folder, for mtllib */
    size_t *fv, fv_cap;     /* the face being read */
    double *fuv;            /* its corners' texture coordinates (2 each, NaN: none), fv_cap of them */
    double *vt;             /* texture coordinates read (vt u v), v turned to glTF's (row 0 at v = 0) */
    size_t nvt, vt_cap;
    int any_uv;             /* the face being read has texture coordinates */
    int vt_said;            /* a vt index out of range was said */
    unsigned line;
    int cur, default_mat;   /* the material in use (-1: none yet), the default one (-1: not made) */
} bn__objr;

/* "v x y z", or with normal "vn x y z" */
static bn_status bn__obj_vertex(bn__objr *R, char *c, bn_error *err, int normal)
{
    double p[3];
    char *t[3];
    for (int k = 0; k < 3; k++)
        t[k] = bn__token(&c);
    for (int k = 0; k < 3; k++)
        if (!bn__parse_double(t[k], &p[k]))
            return bn_error_set(err, BN_EINPUT, "%s:%u: %s '%s' is not a finite number", R->path, R->line,
                                normal ? "vertex normal component" : "vertex coordinate", bn__show(t[k]));
    if (normal ? !bn__soup_add_normal(R->s, p) : !bn__soup_add_vertex(R->s, p))
        return bn_error_set(err, BN_ENOMEM, "out of memory reading %s", R->path);
    return BN_OK;
}

/* "vt u [v [w]]": texture coordinates (v 0 at the image's bottom, as OBJ has it; kept as 1 - v). */
static bn_status bn__obj_texcoord(bn__objr *R, char *c, bn_error *err)
{
    double uv[2] = {0, 0};
    char *t[2] = {bn__token(&c), bn__token(&c)};
    for (int k = 0; k < 2; k++)
        if ((k == 0 || t[k]) && !bn__parse_double(t[k], &uv[k]))
            return bn_error_set(err, BN_EINPUT, "%s:%u: texture coordinate '%s' is not a finite number", R->path, R->line,
                                bn__show(t[k]));
    if (!bn__grow((void **)&R->vt, &R->vt_cap, 2 * (R->nvt + 1), sizeof(double)))
        return bn_error_set(err, BN_ENOMEM, "out of memory reading %s", R->path);
    R->vt[2 * R->nvt] = uv[0];
    R->vt[2 * R->nvt + 1] = 1 - uv[1];
    R->nvt++;
    return BN_OK;
}

/* The vt part of a reference "v/vt" or "v/vt/vn" as corner k's texture coordinates (NaN without one). */
static bn_status bn__obj_corner_uv(bn__objr *R, const char *t, unsigned k, bn_error *err)
{
    const char *p = strchr(t, '/');
    long long i;
    R->fuv[2 * k] = R->fuv[2 * k + 1] = NAN;
    if (!p || p[1] == '/' || !p[1])
        return BN_OK;
    i = strtoll(p + 1, NULL, 10);
    if (i < 0)
        i += (long long)R->nvt + 1;
    if (i < 1 || (unsigned long long)i > R->nvt) {   /* said once: only a texture needs them */
        if (!R->vt_said++)
            bn_warnf(R->log, BN_W_MATERIAL, NAN, "%s:%u: texture coordinate index in '%s' is out of range (%zu vt so far): "
                     "such corners have no texture coordinates (a texture is not applied to their faces)", R->path,
                     R->line, t, R->nvt);
        return BN_OK;
    }
    R->fuv[2 * k] = R->vt[2 * (size_t)(i - 1)];
    R->fuv[2 * k + 1] = R->vt[2 * (size_t)(i - 1) + 1];
    R->any_uv = 1;
    return BN_OK;
}

/* The vn part of a reference "v//vn" or "v/vt/vn" added to the polygon's normal sum (a vn index
 * out of range is ignored: the sum is then over the corners that have one; a zero sum means none). */
static void bn__obj_corner_normal(bn__objr *R, const char *t)
{
    const char *p = strchr(t, '/');
    long long k;
    if (!p || !(p = strchr(p + 1, '/')) || !p[1])
        return;
    k = strtoll(p + 1, NULL, 10);
    if (k < 0)
        k += (long long)R->s->nvn + 1;
    if (k < 1 || (unsigned long long)k > R->s->nvn)
        return;
    for (int c = 0; c < 3; c++)
        R->s->cur_pn[c] += R->s->vn[3 * (size_t)(k - 1) + c];
}

/* The vertex references of an "f" line into R->fv, *n of them. */
static bn_status bn__obj_face_refs(bn__objr *R, char *c, unsigned *n, bn_error *err)
{
    char *t;
    *n = 0;
    R->any_uv = 0;
    memset(R->s->cur_pn, 0, sizeof R->s->cur_pn);
    while ((t = bn__token(&c)) != NULL) {
        size_t vi;
        int r;
        if (*n >= BN__MAX_FACE_VERTS)
            return bn_error_set(err, BN_EINPUT, "%s:%u: face with more than %u vertices", R->path, R->line,
                                BN__MAX_FACE_VERTS);
        r = bn__resolve_index(t, R->s->nverts, &vi);
        if (r < 0)
            return bn_error_set(err, BN_EINPUT,
                                "%s:%u: malformed vertex reference '%s' (expected v, v/vt, v//vn or v/vt/vn)", R->path,
                                R->line, t);
        if (r == 0)
            return bn_error_set(err, BN_EINPUT, "%s:%u: vertex index '%s' is out of range (%zu vertices defined so far)",
                                R->path, R->line, t, R->s->nverts);
        if (*n >= R->fv_cap) {
            size_t nc = R->fv_cap ? 2 * R->fv_cap : 16;
            size_t *p = bn__realloc_array(R->fv, nc, sizeof *p);
            double *q = p ? bn__realloc_array(R->fuv, 2 * nc, sizeof *q) : NULL;
            if (p)
                R->fv = p;
            if (!q)
                return bn_error_set(err, BN_ENOMEM, "out of memory reading %s", R->path);
            R->fuv = q;
            R->fv_cap = nc;
        }
        if (bn__obj_corner_uv(R, t, *n, err) != BN_OK)
            return BN_EINPUT;
        R->fv[(*n)++] = vi;
        bn__obj_corner_normal(R, t);
    }
    return BN_OK;
}

/* "f v1 v2 v3 ...": a polygon of the material in use, or of the default one (made once, said once). */
static bn_status bn__obj_face(bn__objr *R, char *c, bn_error *err)
{
    unsigned n;
    bn_status st = bn__obj_face_refs(R, c, &n, err);
    if (st != BN_OK)
        return st;
    if (n < 3)
        return bn_error_set(err, BN_EINPUT, "%s:%u: face with %u vertices (a face needs at least 3)", R->path, R->line,
                            n);
    if (R->cur < 0) {
        if (R->default_mat < 0) {
            bn_material m;
            memset(&m, 0, sizeof m);
            snprintf(m.name, sizeof m.name, "(default)");
            m.rho[0] = m.rho[1] = m.rho[2] = 0.5;
            bn_warnf(R->log, BN_W_MATERIAL, NAN, "%s:%u: faces without usemtl get the default material (grey, rho 0.5)",
                    R->path, R->line);
            if (!bn__soup_add_material(R->s, &m))
                return bn_error_set(err, BN_ENOMEM, "out of memory");
            R->default_mat = (int)R->s->nmats - 1;
        }
        R->cur = R->default_mat;
    }
    if (!bn__soup_add_polygon(R->s, R->fv, n, (unsigned)R->cur, R->line) ||
        (R->any_uv && !bn__soup_set_corner_uv(R->s, R->fuv, n)))
        return bn_error_set(err, BN_ENOMEM, "out of memory reading %s", R->path);
    return BN_OK;
}

/* "usemtl NAME": a material some mtllib defined. */
static bn_status bn__obj_usemtl(bn__objr *R, char *c, bn_error *err)
{
    char *name = bn__token(&c);
    if (!name)
        return bn_error_set(err, BN_EINPUT, "%s:%u: usemtl without a name", R->path, R->line);
    R->cur = bn__find_material(R->s, name);
    if (R->cur < 0)
        return bn_error_set(err, BN_EINPUT, "%s:%u: unknown material '%s' (not defined in any mtllib read so far)",
                            R->path, R->line, name);
    return BN_OK;
}

/* "mtllib A.mtl [B.mtl ...]", relative to the OBJ's folder. */
static bn_status bn__obj_mtllib(bn__objr *R, char *c, bn_error *err)
{
    char *name;
    bn_status st = BN_OK;
    while (st == BN_OK && (name = bn__token(&c)) != NULL) {
        size_t n = strlen(R->dir) + strlen(name) + 1;
        char *p = malloc(n);
        if (!p)
            return bn_error_set(err, BN_ENOMEM, "out of memory");
        snprintf(p, n, "%s%s", name[0] == '/' ? "" : R->dir, name);
        st = bn__read_mtl(p, R->path, R->line, R->s, R->log, err);
        free(p);
    }
    return st;
}

/* Statements a Lambertian patch model does not need. */
static int bn__obj_ignored(const char *kw)
{
    static const char *const skip[] = {"vp", "s", "l", "p", "mg", "usemap", "maplib"};
    for (size_t i = 0; i < sizeof skip / sizeof *skip; i++)
        if (strcmp(kw, skip[i]) == 0)
            return 1;
    return 0;
}

bn_status bn__read_obj_stream(FILE *fp, const char *path, bn__soup *s, const bn_log *log, bn_error *err)
{
    bn__objr R = {path, s, log, NULL, NULL, 0, NULL, NULL, 0, 0, 0, 0, 0, -1, -1};
    const char *slash = strrchr(path, '/');
    char *buf = NULL;
    size_t cap = 0;
    ssize_t len;
    bn_status st = BN_OK;

    if (!(R.dir = bn__strdup(path)))
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    R.dir[slash ? (size_t)(slash - path) + 1 : 0] = '\0';
    while (st == BN_OK && (len = getline(&buf, &cap, fp)) >= 0) {
        char *c, *kw;
        int cb;
        R.line++;
        if ((cb = bn__control_byte(buf, len)) >= 0) {
            st = bn_error_set(err, BN_EINPUT, "%s:%u: control byte 0x%02x in OBJ text (not a text file?)", path, R.line,
                              cb);
            break;
        }
        c = bn__strip(buf);
        if (!(kw = bn__token(&c)))
            continue;
        if (strcmp(kw, "v") == 0)
            st = bn__obj_vertex(&R, c, err, 0);
        else if (strcmp(kw, "vn") == 0)
            st = bn__obj_vertex(&R, c, err, 1);
        else if (strcmp(kw, "vt") == 0)
            st = bn__obj_texcoord(&R, c, err);
        else if (strcmp(kw, "f") == 0)
            st = bn__obj_face(&R, c, err);
        else if (strcmp(kw, "usemtl") == 0)
            st = bn__obj_usemtl(&R, c, err);
        else if (strcmp(kw, "mtllib") == 0)
            st = bn__obj_mtllib(&R, c, err);
        else if (strcmp(kw, "o") == 0 || strcmp(kw, "g") == 0) {
            /* the object the next faces belong to (a group with several names: its first) */
            if (!bn__soup_use_object(s, bn__token(&c)))
                st = bn_error_set(err, BN_ENOMEM, "out of memory");
        }
        else if (!bn__obj_ignored(kw))
            bn_logf(log, BN_LOG_DEBUG, "%s:%u: statement '%s' ignored", path, R.line, kw);
    }
    if (st == BN_OK && ferror(fp))
        st = bn_error_set(err, BN_EIO, "%s: read error", path);
    free(buf);
    free(R.fv);
    free(R.fuv);
    free(R.vt);
    free(R.dir);
    return st;
}
