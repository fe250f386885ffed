/* Writing baked meshes: PLY (binary, through OpenMesh, provenance added as header comments),
 * OM (OpenMesh), OBJ with `v x y z r g b` written directly (OpenMesh's OBJ writer refuses
 * vertex colours). Colours are radiance in W m^-2 sr^-1 as float, or 8-bit sRGB with --ldr. */
#include "bounce/bake.h"
#include "bake/bake_internal.h"
#include "adapters/adapters.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <string.h>
#include <strings.h>

/* The meshes in enum order (bn_bake_mesh). */
#define BN__BAKE_MESHES(X) X("elements") X("input")
BN__VOCABULARY(bn_bake_mesh, bn_bake_mesh, BN__BAKE_MESHES)

static const char *bn__ext(const char *path)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash))
        return "";
    return dot + 1;
}

/* One line, no control characters: safe inside a PLY or OBJ comment. */
static void bn__comment_text(const char *s, char *out, size_t n)
{
    size_t i = 0;
    for (; *s && i + 1 < n; s++)
        out[i++] = ((unsigned char)*s < 32) ? ' ' : *s;
    out[i] = '\0';
}

/* Copies the PLY at `src` to `dst`, adding `comment KEY: VALUE` lines after its format line. */
static bn_status bn__ply_add_comments(const char *src, const char *dst, const bn_bake_write_opts *o, bn_error *err)
{
    FILE *in = fopen(src, "rb");
    bn__outfile out;
    char line[4096], text[2048];
    bn_status st;
    int header = 1;
    size_t n;
    if (!in)
        return bn_error_set(err, BN_EIO, "%s: cannot reopen the file OpenMesh wrote", dst);
    st = bn__outfile_open(&out, dst, "wb", err);
    if (st != BN_OK) {
        fclose(in);
        return st;
    }
    while (header && fgets(line, sizeof line, in)) {
        fputs(line, out.fp);
        if (strncmp(line, "format ", 7) == 0) {
            fprintf(out.fp, "comment bounce %s: per-vertex radiance baked from the patch solution\n", bn_version());
            for (size_t a = 0; a < o->nattrs; a++) {
                bn__comment_text(o->attrs[a].value, text, sizeof text);
                fprintf(out.fp, "comment %s: %s\n", o->attrs[a].key, text);
            }
        }
        if (strncmp(line, "end_header", 10) == 0 && strspn(line + 10, "\r\n") == strlen(line + 10))
            header = 0;
    }
    while ((n = fread(line, 1, sizeof line, in)) > 0)
        fwrite(line, 1, n, out.fp);
    if (header || ferror(in)) {
        fclose(in);
        bn__outfile_abort(&out);
        return bn_error_set(err, BN_EIO, "%s: the PLY OpenMesh wrote (%s) has no complete header", dst, src);
    }
    fclose(in);
    return bn__outfile_commit(&out, err);
}

static bn_status bn__write_obj(const char *path, size_t nv, const double *pos, size_t nf, const unsigned *face_n,
                               const size_t *face_idx, const float *colour, const unsigned char *c8,
                               const bn_bake_write_opts *o, bn_error *err)
{
    bn__outfile f;
    char text[2048];
    bn_status st = bn__outfile_open(&f, path, "w", err);
    if (st != BN_OK)
        return st;
    fprintf(f.fp, "# bounce %s: per-vertex radiance baked from the patch solution\n", bn_version());
    fprintf(f.fp, "# vertex colours: `v x y z r g b`, %s\n",
            c8 ? "8-bit sRGB at the exposure, written as value/255" : "linear radiance, W m^-2 sr^-1 (not clamped)");
    for (size_t a = 0; a < o->nattrs; a++) {
        bn__comment_text(o->attrs[a].value, text, sizeof text);
        fprintf(f.fp, "# %s: %s\n", o->attrs[a].key, text);
    }
    for (size_t v = 0; v < nv; v++) {
        if (c8)
            fprintf(f.fp, "v %.17g %.17g %.17g %.6g %.6g %.6g\n", pos[3 * v], pos[3 * v + 1], pos[3 * v + 2],
                    c8[3 * v] / 255.0, c8[3 * v + 1] / 255.0, c8[3 * v + 2] / 255.0);
        else
            fprintf(f.fp, "v %.17g %.17g %.17g %.9g %.9g %.9g\n", pos[3 * v], pos[3 * v + 1], pos[3 * v + 2],
                    (double)colour[3 * v], (double)colour[3 * v + 1], (double)colour[3 * v + 2]);
    }
    for (size_t p = 0; p < nf; p++) {
        fputc('f', f.fp);
        for (unsigned c = 0; c < face_n[p]; c++)
            fprintf(f.fp, " %zu", face_idx[4 * p + c] + 1);
        fputc('\n', f.fp);
    }
    return bn__outfile_commit(&f, err);
}

/* The input polygons as faces: each corner is the output vertex of a patch of that polygon with a
 * corner at the same point. Fills face_n / face_idx (nf = the faces) with output-vertex numbers. */
static bn_status bn__input_faces(const bn_bake *b, unsigned *face_n, size_t *face_idx, bn_error *err)
{
    const bn_scene *s = bn_bake_scene(b);
    size_t np, nf, nv, ni, npv;
    const bn_patch *pa = bn_scene_patches(s, &np);
    const bn_face *f = bn_scene_faces(s, &nf);
    const double *v = bn_scene_vertices(s, &nv), *pv = bn_scene_patch_vertices(s, &npv);
    const size_t *idx = bn_scene_face_indices(s, &ni);
    size_t *start = bn__calloc(nf + 1, sizeof(size_t)), *order = bn__malloc_array(np + 1, sizeof(size_t));
    double eps;
    bn_status st = BN_OK;
    if (!start || !order) {
        free(start);
        free(order);
        return bn_error_set(err, BN_ENOMEM, "out of memory baking %zu polygons", nf);
    }
    eps = 1e-9 * bn_scene_diameter(s);
    for (size_t p = 0; p < np; p++)
        start[pa[p].face + 1]++;
    for (size_t k = 0; k < nf; k++)
        start[k + 1] += start[k];
    {
        size_t *fill = bn__malloc_array(nf + 1, sizeof(size_t));
        if (!fill) {
            free(start);
            free(order);
            return bn_error_set(err, BN_ENOMEM, "out of memory baking %zu polygons", nf);
        }
        memcpy(fill, start, nf * sizeof(size_t));
        for (size_t p = 0; p < np; p++)
            order[fill[pa[p].face]++] = p;
        free(fill);
    }
    for (size_t k = 0; k < nf && st == BN_OK; k++) {
        face_n[k] = f[k].nverts;
        for (unsigned c = 0; c < f[k].nverts && st == BN_OK; c++) {
            const double *x = v + 3 * idx[f[k].first + c];
            size_t found = SIZE_MAX;
            for (size_t q = start[k]; q < start[k + 1] && found == SIZE_MAX; q++)
                for (unsigned e = 0; e < pa[order[q]].ncorners; e++) {
                    const double *y = pv + 3 * pa[order[q]].corner[e];
                    if (fabs(x[0] - y[0]) <= eps && fabs(x[1] - y[1]) <= eps && fabs(x[2] - y[2]) <= eps) {
                        found = bn_bake_corner_vertex(b, order[q], e);
                        break;
                    }
                }
            if (found == SIZE_MAX)
                st = bn_error_set(err, BN_EINTERNAL, "%s: polygon %zu (line %u) has no patch at its corner %u",
                                  bn_scene_path(s), f[k].source, f[k].line, c + 1);
            face_idx[4 * k + c] = found;
        }
        for (unsigned c = f[k].nverts; c < 4; c++)
            face_idx[4 * k + c] = 0;
    }
    free(start);
    free(order);
    return st;
}

/* What bn_bake_write builds before a writer runs: the faces, the kept vertices and each layer's
 * vertex values (owned). */
typedef struct bn__bake_job {
    size_t nv, nf, nlayers;
    float **vals;          /* nlayers arrays of nv x 3 */
    unsigned *face_n;
    size_t *face_patch;    /* the element mesh: each face's patch */
    size_t *face_idx;      /* 4 per face, numbering the kept vertices */
    const double *pos;     /* cpos, or the bake's own positions */
    double *cpos;          /* --mesh input: the kept vertices' positions */
    unsigned char *c8;     /* --ldr: 8-bit sRGB (3 per vertex) */
} bn__bake_job;

static void bn__job_free(bn__bake_job *j)
{
    for (size_t l = 0; j->vals && l < j->nlayers; l++)
        free(j->vals[l]);
    free(j->vals);
    free(j->face_n);
    free(j->face_patch);
    free(j->face_idx);
    free(j->cpos);
    free(j->c8);
}

static bn_status bn__bake_oom(size_t nv, bn_error *err)
{
    return bn_error_set(err, BN_ENOMEM, "out of memory baking %zu vertices", nv);
}

/* Stops before a writer commits anything once SIGINT/SIGTERM has been raised. */
static bn_status bn__bake_poll(const char *path, bn_error *err)
{
    bn_status s = bn_interrupted();
    return s == BN_OK ? BN_OK : bn_error_set(err, s, "%s: interrupted; nothing was written", path);
}

/* Each layer's vertex values as float; BN_ENUMERIC, naming the count, when any is not finite. */
static bn_status bn__job_values(const bn_bake *b, const char *path, const bn_bake_layer *layers, bn__bake_job *j,
                                bn_error *err)
{
    size_t nbad = 0, nv = j->nv;
    double *vv = bn__malloc_array(nv, 3 * sizeof(double));
    j->vals = bn__calloc(j->nlayers, sizeof *j->vals);
    for (size_t l = 0; vv && j->vals && l < j->nlayers; l++) {
        if (!(j->vals[l] = bn__malloc_array(nv, 3 * sizeof(float))))
            break;
        if (layers[l].vertex_values)
            memcpy(vv, layers[l].vertex_values, nv * 3 * sizeof *vv);
        else
            bn_bake_vertex_values(b, layers[l].patch_values, vv);
        for (size_t i = 0; i < 3 * nv; i++) {
            j->vals[l][i] = (float)vv[i];
            nbad += !isfinite(j->vals[l][i]);
        }
    }
    int whole = vv && j->vals && j->vals[j->nlayers - 1];
    free(vv);
    if (!whole)
        return bn__bake_oom(nv, err);
    if (nbad)
        return bn_error_set(err, BN_ENUMERIC, "%s: %zu baked values are not finite; nothing was written", path, nbad);
    return BN_OK;
}

/* --mesh input: keeps only the vertices the polygons' corners use, renumbered in corner order. */
static bn_status bn__job_renumber(const bn_bake *b, bn__bake_job *j, bn_error *err)
{
    size_t nv = j->nv, nout = 0;
    size_t *remap = bn__malloc_array(nv + 1, sizeof *remap);
    const double *opos = bn_bake_vertex_positions(b);
    j->cpos = bn__malloc_array(nv + 1, 3 * sizeof(double));
    if (!remap || !j->cpos) {
        free(remap);
        return bn__bake_oom(nv, err);
    }
    for (size_t i = 0; i < nv; i++)
        remap[i] = SIZE_MAX;
    for (size_t k = 0; k < j->nf; k++)
        for (unsigned c = 0; c < j->face_n[k]; c++) {
            size_t i = j->face_idx[4 * k + c];
            if (remap[i] == SIZE_MAX) {
                remap[i] = nout;
                memcpy(j->cpos + 3 * nout, opos + 3 * i, 3 * sizeof(double));
                nout++;
            }
            j->face_idx[4 * k + c] = remap[i];
        }
    for (size_t l = 0; l < j->nlayers; l++) {   /* values in the new order (a copy: the orders differ) */
        float *c = bn__malloc_array(nout + 1, 3 * sizeof(float));
        if (!c) {
            free(remap);
            return bn__bake_oom(nv, err);
        }
        for (size_t i = 0; i < nv; i++)
            if (remap[i] != SIZE_MAX)
                memcpy(c + 3 * remap[i], j->vals[l] + 3 * i, 3 * sizeof(float));
        free(j->vals[l]);
        j->vals[l] = c;
    }
    free(remap);
    j->pos = j->cpos;
    j->nv = nout;
    return BN_OK;
}

/* The faces written: every patch or the refined triangles (the element mesh), or the input polygons. */
static bn_status bn__job_faces(const bn_bake *b, int input_mesh, bn__bake_job *j, bn_error *err)
{
    bn_scene_faces(bn_bake_scene(b), &j->nf);
    if (!input_mesh)
        j->nf = bn_bake_face_count(b);
    j->pos = bn_bake_vertex_positions(b);
    j->face_n = bn__malloc_array(j->nf + 1, sizeof *j->face_n);
    j->face_idx = bn__malloc_array(j->nf + 1, 4 * sizeof *j->face_idx);
    j->face_patch = input_mesh ? NULL : bn__malloc_array(j->nf + 1, sizeof *j->face_patch);
    if (!j->face_n || !j->face_idx || (!input_mesh && !j->face_patch))
        return bn__bake_oom(j->nv, err);
    if (input_mesh) {
        bn_status st = bn__input_faces(b, j->face_n, j->face_idx, err);
        return st == BN_OK ? bn__job_renumber(b, j, err) : st;
    }
    for (size_t f = 0; f < j->nf; f++)
        j->face_n[f] = bn_bake_face(b, f, j->face_idx + 4 * f, j->face_patch + f);
    return BN_OK;
}

static bn_status bn__job_ldr(bn__bake_job *j, double exposure_ev, bn_error *err)
{
    if (!(j->c8 = bn__malloc_array(j->nv, 3)))
        return bn__bake_oom(j->nv, err);
    for (size_t i = 0; i < 3 * j->nv; i++)
        j->c8[i] = bn__srgb8(j->vals[0][i], exposure_ev);
    return BN_OK;
}

/* Each vertex's face normal (bn__bake_out.face_normal: the face its values were gathered on), nv x 3;
 * NULL when out of memory. */
static float *bn__vertex_face_normals(const bn_bake *b, size_t nv)
{
    const bn_patch *pa = bn_scene_patches(bn_bake_scene(b), NULL);
    float *fn = bn__malloc_array(nv + 1, 3 * sizeof(float));
    for (size_t v = 0; fn && v < nv; v++)
        for (int c = 0; c < 3; c++)
            fn[3 * v + c] = (float)pa[bn_bake_vertex_patch(b, v)].normal[c];
    return fn;
}

/* glTF: each face's material, the layers' names and each layer's power pi sum_p A_p x_p (W); in a
 * per-bounce bake on the element mesh, each vertex's face normal (_FACE_NORMAL: `bounce trace --points`
 * given it meets the face the vertex's values belong to). */
static bn_status bn__bake_gltf(const bn_bake *b, const char *path, int is_glb, const bn_bake_layer *layers,
                               const bn_bake_write_opts *o, const bn__bake_job *j, bn_error *err)
{
    const bn_scene *s = bn_bake_scene(b);
    size_t np, nl = j->nlayers;
    const bn_patch *patches = bn_scene_patches(s, &np);
    const bn_face *faces = bn_scene_faces(s, &(size_t){0});
    const size_t *fp = j->face_patch;
    size_t nobj = bn_scene_object_count(s);
    unsigned *fm = bn__malloc_array(j->nf + 1, sizeof *fm), *fo = bn__malloc_array(j->nf + 1, sizeof *fo);
    const char **lnames = bn__malloc_array(nl, sizeof *lnames), **onames = bn__malloc_array(nobj + 1, sizeof *onames);
    double *power = bn__calloc(3 * nl, sizeof(double));
    float *fn = nl > 1 && !o->input_mesh ? bn__vertex_face_normals(b, j->nv) : NULL;
    int ok = fm && fo && lnames && onames && power && (fn || nl == 1 || o->input_mesh);
    bn_status st = ok ? BN_OK : bn__bake_oom(j->nv, err);
    for (size_t k = 0; st == BN_OK && k < j->nf; k++) {
        fm[k] = o->input_mesh ? faces[k].material : patches[fp[k]].material;
        fo[k] = faces[o->input_mesh ? k : patches[fp[k]].face].object;
    }
    for (size_t k = 0; st == BN_OK && k < nobj; k++)
        onames[k] = bn_scene_object_name(s, k);
    for (size_t l = 0; st == BN_OK && l < nl; l++) {
        lnames[l] = layers[l].name;
        bn_scene_power(s, layers[l].patch_values, power + 3 * l);
    }
    if (st == BN_OK) {
        bn__bake_out g = {j->nv,  j->pos, j->nf,          j->face_n, j->face_idx, fm,
                          nl,     (const float *const *)j->vals, lnames, j->c8, o->exposure_ev, o->colour_sets,
                          power,  fo, nobj, onames, fn};
        st = bn__write_gltf(path, is_glb, &g, s, o, err);
    }
    free(fm);
    free(fo);
    free(onames);
    free(lnames);
    free(power);
    free(fn);
    return st;
}

/* Layers 1.. as float vertex properties NAME_red, NAME_green, NAME_blue: 3 (nlayers - 1) names and
 * arrays, allocated in (*names)[] and (*extra)[] (3 nlayers slots, freed by bn__extra_free). */
static bn_status bn__extra_props(const bn_bake_layer *layers, const bn__bake_job *j, char ***names, float ***extra,
                                 bn_error *err)
{
    static const char *suffix[3] = {"red", "green", "blue"};
    size_t n = 0;
    *names = bn__calloc(3 * j->nlayers, sizeof **names);
    *extra = bn__calloc(3 * j->nlayers, sizeof **extra);
    if (!*names || !*extra)
        return bn__bake_oom(j->nv, err);
    for (size_t l = 1; l < j->nlayers; l++)
        for (size_t c = 0; c < 3; c++, n++) {
            size_t len = strlen(layers[l].name) + 8;
            (*names)[n] = malloc(len);
            (*extra)[n] = bn__malloc_array(j->nv + 1, sizeof(float));
            if (!(*names)[n] || !(*extra)[n])
                return bn__bake_oom(j->nv, err);
            snprintf((*names)[n], len, "%s_%s", layers[l].name, suffix[c]);
            for (size_t v = 0; v < j->nv; v++)
                (*extra)[n][v] = j->vals[l][3 * v + c];
        }
    return BN_OK;
}

static void bn__extra_free(char **names, float **extra, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        free(names ? names[i] : NULL);
        free(extra ? extra[i] : NULL);
    }
    free(names);
    free(extra);
}

/* "bounce VERSION" and each attribute as `key: value` lines (the OM mesh property); NULL without memory. */
static char *bn__provenance_text(const bn_bake_write_opts *o)
{
    size_t plen = 64, k;
    for (size_t a = 0; a < o->nattrs; a++)
        plen += strlen(o->attrs[a].key) + strlen(o->attrs[a].value) + 4;
    char *prov = malloc(plen);
    if (!prov)
        return NULL;
    k = (size_t)snprintf(prov, plen, "bounce %s\n", bn_version());
    for (size_t a = 0; a < o->nattrs && k < plen; a++)
        k += (size_t)snprintf(prov + k, plen - k, "%s: %s\n", o->attrs[a].key, o->attrs[a].value);
    return prov;
}

/* PLY: OpenMesh writes a first temporary, which is copied with comments into the second
 * (bn__outfile); the two need distinct names, so the first is named after "<stem>.openmesh.ply". */
static bn_status bn__openmesh_tmp(const char *path, int is_ply, char **tmp, bn_error *err)
{
    if (!is_ply)
        return bn__tmpname_reserve(path, tmp, err);
    size_t len = strlen(path) + 16;
    char *alt = malloc(len);
    if (!alt)
        return bn_error_set(err, BN_ENOMEM, "%s: out of memory", path);
    snprintf(alt, len, "%.*s.openmesh.ply", (int)(strlen(path) - 4), path);
    bn_status st = bn__tmpname_reserve(alt, tmp, err);
    free(alt);
    return st;
}

/* .ply and .om through OpenMesh, layers 1.. as extra float vertex properties. */
static bn_status bn__bake_openmesh(const char *path, int is_ply, const bn_bake_layer *layers,
                                   const bn_bake_write_opts *o, const bn__bake_job *j, bn_error *err)
{
    char **names = NULL, *tmp = NULL, *prov = is_ply ? NULL : bn__provenance_text(o);
    float **extra = NULL;
    size_t dup = 0;
    bn_status st = bn__extra_props(layers, j, &names, &extra, err);
    if (st == BN_OK)
        st = bn__openmesh_tmp(path, is_ply, &tmp, err);
    if (st == BN_OK) {
        bn__bake_mesh m = {j->nv, j->pos, j->nf, j->face_n, j->face_idx, j->c8 ? NULL : j->vals[0], j->c8,
                           3 * (j->nlayers - 1), (const char *const *)names, (const float *const *)extra, prov};
        if ((st = bn__openmesh_write(tmp, &m, &dup, err)) != BN_OK && err) {
            char inner[BN_ERROR_MSG_MAX];   /* the message names the output, not the temporary */
            snprintf(inner, sizeof inner, "%s", err->msg);
            bn_error_set(err, st, "%s: %s", path, inner);
        }
    }
    bn__extra_free(names, extra, 3 * j->nlayers);
    free(prov);
    if (st == BN_OK && dup)
        bn_warnf(o->log, BN_W_NON_MANIFOLD, (double)dup,
                "%s: %zu vertices were duplicated for faces OpenMesh's half-edge mesh cannot share (non-manifold)",
                path, dup);
    if (st == BN_OK && (st = bn__bake_poll(path, err)) == BN_OK && is_ply)
        st = bn__ply_add_comments(tmp, path, o, err);
    else if (st == BN_OK)
        return bn__tmpname_commit(path, tmp, err);
    bn__tmpname_abort(tmp);
    return st;
}

enum { BN__BAKE_PLY, BN__BAKE_OM, BN__BAKE_OBJ, BN__BAKE_GLB, BN__BAKE_GLTF };

/* The format from the extension, and what it can carry. */
static bn_status bn__bake_format(const char *path, size_t nlayers, int *fmt, bn_error *err)
{
    static const char *ext[] = {"ply", "om", "obj", "glb", "gltf"};
    const char *e = bn__ext(path);
    *fmt = -1;
    for (int i = 0; i < 5; i++)
        if (strcasecmp(e, ext[i]) == 0)
            *fmt = i;
    if (*fmt < 0)
        return bn_error_set(err, BN_EUSAGE, "%s: unknown mesh format '.%s' (bake writes .ply, .om, .obj, .glb and .gltf)",
                            path, e);
    if (nlayers == 0)
        return bn_error_set(err, BN_EINTERNAL, "%s: nothing to bake", path);
    if (*fmt == BN__BAKE_OBJ && nlayers > 1)
        return bn_error_set(err, BN_EUSAGE, "%s: per-bounce colour sets need .ply or .om (OBJ has one colour per vertex)",
                            path);
    return BN_OK;
}

bn_status bn_bake_write(const bn_bake *b, const char *path, const bn_bake_layer *layers, size_t nlayers,
                        const bn_bake_write_opts *o, bn_error *err)
{
    bn__bake_job j = {.nv = bn_bake_vertex_count(b), .nlayers = nlayers};
    int fmt;
    bn_status st = bn__bake_format(path, nlayers, &fmt, err);
    if (st == BN_OK)
        st = bn__job_values(b, path, layers, &j, err);
    if (st == BN_OK)
        st = bn__job_faces(b, o->input_mesh, &j, err);
    if (st == BN_OK && o->ldr)
        st = bn__job_ldr(&j, o->exposure_ev, err);
    if (st == BN_OK)
        st = bn__bake_poll(path, err);
    if (st == BN_OK && fmt == BN__BAKE_OBJ)
        st = bn__write_obj(path, j.nv, j.pos, j.nf, j.face_n, j.face_idx, j.vals[0], j.c8, o, err);
    else if (st == BN_OK && (fmt == BN__BAKE_GLB || fmt == BN__BAKE_GLTF))
        st = bn__bake_gltf(b, path, fmt == BN__BAKE_GLB, layers, o, &j, err);
    else if (st == BN_OK)
        st = bn__bake_openmesh(path, fmt == BN__BAKE_PLY, layers, o, &j, err);
    bn__job_free(&j);
    return st;
}
