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
    double lo[3], hi[3], eps;
    bn_status st = BN_OK;
    if (!start || !order) {
        free(start);
        free(order);
        return bn_error_set(err, BN_ENOMEM, "out of memory baking %zu polygons", nf);
    }
    bn_scene_bounds(s, lo, hi);
    eps = 1e-9 * sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                      (hi[2] - lo[2]) * (hi[2] - lo[2]));
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

bn_status bn_bake_write(const bn_bake *b, const char *path, const bn_bake_layer *layers, size_t nlayers,
                        const bn_bake_write_opts *o, bn_error *err)
{
    const char *ext = bn__ext(path);
    size_t nv = bn_bake_vertex_count(b), np, nf, nbad = 0, nout = nv;
    const bn_patch *patches = bn_scene_patches(bn_bake_scene(b), &np);
    const double *opos = bn_bake_vertex_positions(b);
    double *cpos = NULL;
    size_t *remap = NULL;
    double *vv = NULL;
    float **vals = NULL;
    unsigned char *c8 = NULL;
    unsigned *face_n = NULL;
    size_t *face_idx = NULL;
    char **names = NULL;
    char *tmp = NULL, *prov = NULL;
    bn_status st = BN_OK;
    int is_ply = strcasecmp(ext, "ply") == 0, is_om = strcasecmp(ext, "om") == 0, is_obj = strcasecmp(ext, "obj") == 0;
    int is_glb = strcasecmp(ext, "glb") == 0, is_gltf = strcasecmp(ext, "gltf") == 0;

    if (!is_ply && !is_om && !is_obj && !is_glb && !is_gltf)
        return bn_error_set(err, BN_EUSAGE, "%s: unknown mesh format '.%s' (bake writes .ply, .om, .obj, .glb and .gltf)",
                            path, ext);
    if (nlayers == 0)
        return bn_error_set(err, BN_EINTERNAL, "%s: nothing to bake", path);
    if (is_obj && nlayers > 1)
        return bn_error_set(err, BN_EUSAGE, "%s: per-bounce colour sets need .ply or .om (OBJ has one colour per vertex)",
                            path);
    vv = bn__malloc_array(nv, 3 * sizeof(double));
    vals = bn__calloc(nlayers, sizeof *vals);
    names = bn__calloc(3 * nlayers, sizeof *names);
    bn_scene_faces(bn_bake_scene(b), &nf);
    if (!o->input_mesh)
        nf = np;
    face_n = bn__malloc_array(nf + 1, sizeof *face_n);
    face_idx = bn__malloc_array(nf + 1, 4 * sizeof *face_idx);
    if (!vv || !vals || !names || !face_n || !face_idx)
        goto oom;
    for (size_t l = 0; l < nlayers; l++) {
        vals[l] = bn__malloc_array(nv, 3 * sizeof(float));
        if (!vals[l])
            goto oom;
        bn_bake_vertex_values(b, layers[l].patch_values, vv);
        for (size_t i = 0; i < 3 * nv; i++) {
            vals[l][i] = (float)vv[i];
            nbad += !isfinite(vals[l][i]);
        }
    }
    if (nbad) {
        st = bn_error_set(err, BN_ENUMERIC, "%s: %zu baked values are not finite; nothing was written", path, nbad);
        goto done;
    }
    if (o->input_mesh) {   /* the input polygons: keep only the vertices their corners use, renumbered */
        st = bn__input_faces(b, face_n, face_idx, err);
        if (st != BN_OK)
            goto done;
        remap = bn__malloc_array(nv + 1, sizeof *remap);
        cpos = bn__malloc_array(nv + 1, 3 * sizeof(double));
        if (!remap || !cpos)
            goto oom;
        for (size_t i = 0; i < nv; i++)
            remap[i] = SIZE_MAX;
        nout = 0;
        for (size_t k = 0; k < nf; k++)
            for (unsigned c = 0; c < face_n[k]; c++) {
                size_t i = face_idx[4 * k + c];
                if (remap[i] == SIZE_MAX) {
                    remap[i] = nout;
                    memcpy(cpos + 3 * nout, opos + 3 * i, 3 * sizeof(double));
                    nout++;
                }
                face_idx[4 * k + c] = remap[i];
            }
        for (size_t l = 0; l < nlayers; l++) {   /* values in the new order (a copy: the orders differ) */
            float *c = bn__malloc_array(nout + 1, 3 * sizeof(float));
            if (!c)
                goto oom;
            for (size_t i = 0; i < nv; i++)
                if (remap[i] != SIZE_MAX)
                    memcpy(c + 3 * remap[i], vals[l] + 3 * i, 3 * sizeof(float));
            free(vals[l]);
            vals[l] = c;
        }
        opos = cpos;
    } else {
        for (size_t p = 0; p < np; p++) {
            face_n[p] = patches[p].ncorners;
            for (unsigned c = 0; c < 4; c++)
                face_idx[4 * p + c] = c < patches[p].ncorners ? bn_bake_corner_vertex(b, p, c) : 0;
        }
    }
    nv = nout;
    if (o->ldr) {
        c8 = bn__malloc_array(nv, 3);
        if (!c8)
            goto oom;
        for (size_t i = 0; i < 3 * nv; i++)
            c8[i] = bn_tonemap_srgb8(vals[0][i], o->exposure_ev);
    }
    if (is_obj) {
        st = bn__write_obj(path, nv, opos, nf, face_n, face_idx, vals[0], c8, o, err);
        goto done;
    }
    if (is_glb || is_gltf) {
        const bn_face *faces = bn_scene_faces(bn_bake_scene(b), &(size_t){0});
        unsigned *fm = bn__malloc_array(nf + 1, sizeof *fm);
        const char **lnames = bn__malloc_array(nlayers, sizeof *lnames);
        bn__bake_out g;
        if (!fm || !lnames) {
            free(fm);
            free(lnames);
            goto oom;
        }
        for (size_t k = 0; k < nf; k++)
            fm[k] = o->input_mesh ? faces[k].material : patches[k].material;
        double *power = bn__calloc(3 * nlayers, sizeof(double)),
               m2 = bn_unit_to_metres(bn_scene_unit(bn_bake_scene(b)));
        if (!power) {
            free(fm);
            free(lnames);
            goto oom;
        }
        for (size_t l = 0; l < nlayers; l++) {
            lnames[l] = layers[l].name;
            for (size_t p = 0; p < np; p++)
                for (int c = 0; c < 3; c++)
                    power[3 * l + (size_t)c] += BN_PI * patches[p].area * m2 * m2 * layers[l].patch_values[3 * p + (size_t)c];
        }
        g = (bn__bake_out){nv, opos, nf, face_n, face_idx, fm, nlayers, (const float *const *)vals, lnames, c8,
                           o->exposure_ev, power};
        st = bn__write_gltf(path, is_glb, &g, bn_bake_scene(b), o, err);
        free(fm);
        free(lnames);
        free(power);
        goto done;
    }
    {
        const char *suffix[3] = {"red", "green", "blue"};
        float **extra = bn__calloc(3 * nlayers, sizeof *extra);
        size_t nextra = 0, dup = 0, plen = 64;
        bn__bake_mesh m;
        if (!extra)
            goto oom;
        for (size_t l = 1; l < nlayers; l++)
            for (int c = 0; c < 3; c++) {
                size_t len = strlen(layers[l].name) + 8;
                names[nextra] = malloc(len);
                extra[nextra] = bn__malloc_array(nv, sizeof(float));
                if (!names[nextra] || !extra[nextra]) {
                    free(names[nextra]);
                    free(extra[nextra]);
                    names[nextra] = NULL;
                    for (size_t e = 0; e < nextra; e++)
                        free(extra[e]);
                    free(extra);
                    goto oom;
                }
                snprintf(names[nextra], len, "%s_%s", layers[l].name, suffix[c]);
                for (size_t v = 0; v < nv; v++)
                    extra[nextra][v] = vals[l][3 * v + c];
                nextra++;
            }
        for (size_t a = 0; a < o->nattrs; a++)
            plen += strlen(o->attrs[a].key) + strlen(o->attrs[a].value) + 4;
        prov = malloc(plen);
        if (prov) {
            size_t k = (size_t)snprintf(prov, plen, "bounce %s\n", bn_version());
            for (size_t a = 0; a < o->nattrs && k < plen; a++)
                k += (size_t)snprintf(prov + k, plen - k, "%s: %s\n", o->attrs[a].key, o->attrs[a].value);
        }
        memset(&m, 0, sizeof m);
        m.nverts = nv;
        m.pos = opos;
        m.nfaces = nf;
        m.face_n = face_n;
        m.face_idx = face_idx;
        m.colour = c8 ? NULL : vals[0];
        m.colour8 = c8;
        m.nextra = nextra;
        m.extra_name = (const char *const *)names;
        m.extra = (const float *const *)extra;
        m.provenance = is_om ? prov : NULL;
        /* PLY: OpenMesh writes a first temporary, which is copied with comments into the second
         * (bn__outfile); both temporaries need distinct names, so the first is named after
         * "<stem>.openmesh.ply". */
        if (is_ply) {
            size_t len = strlen(path) + 16;
            char *alt = malloc(len);
            if (!alt)
                goto oom;
            snprintf(alt, len, "%.*s.openmesh.ply", (int)(strlen(path) - 4), path);
            st = bn__tmpname_reserve(alt, &tmp, err);
            free(alt);
        } else {
            st = bn__tmpname_reserve(path, &tmp, err);
        }
        if (st == BN_OK && (st = bn__openmesh_write(tmp, &m, &dup, err)) != BN_OK && err) {
            char inner[BN_ERROR_MSG_MAX];   /* the message names the output, not the temporary */
            snprintf(inner, sizeof inner, "%s", err->msg);
            bn_error_set(err, st, "%s: %s", path, inner);
        }
        for (size_t e = 0; e < nextra; e++)
            free(extra[e]);
        free(extra);
        if (st == BN_OK && dup)
            bn_logf(o->log, BN_LOG_WARN,
                    "%s: %zu vertices were duplicated for faces OpenMesh's half-edge mesh cannot share (non-manifold)",
                    path, dup);
        if (st == BN_OK && is_ply) {
            st = bn__ply_add_comments(tmp, path, o, err);
            bn__tmpname_abort(tmp);
        } else if (st == BN_OK) {
            st = bn__tmpname_commit(path, tmp, err);
        } else {
            bn__tmpname_abort(tmp);
        }
        tmp = NULL;
    }
    goto done;
oom:
    st = bn_error_set(err, BN_ENOMEM, "out of memory baking %zu vertices", nv);
done:
    if (vals)
        for (size_t l = 0; l < nlayers; l++)
            free(vals[l]);
    if (names)
        for (size_t i = 0; i < 3 * nlayers; i++)
            free(names[i]);
    free(vals);
    free(names);
    free(vv);
    free(c8);
    free(face_n);
    free(face_idx);
    free(prov);
    free(remap);
    free(cpos);
    return st;
}
