/* F on disk: CSV for people, the BNFF binary layout for programs and the cache.
 * BNFF v1, little-endian:
 *   0  char[4]  "BNFF"          4  uint32 version (1)      8  uint64 N
 *   16 uint32 value bytes (4 float32, 8 float64)           20 uint32 layout (0 dense, 1 CSR)
 *   24 uint64 nnz (dense: N*N)  32 uint64 T, text length   40 T bytes of '#' lines (provenance, key)
 *   then N float64 patch areas (m^2), then
 *     dense: N*N values, row-major (F_ij at i*N + j);
 *     CSR:   N+1 uint64 row starts, nnz uint32 columns, nnz values. */
#include "formfactor/ff_io.h"
#include "transport/transport_internal.h"
#include "base/internal.h"

#include <errno.h>
#include <string.h>

#define BN__BNFF_VERSION 1u

static int bn__little_endian(void)
{
    const uint16_t one = 1;
    return *(const unsigned char *)&one == 1;
}

static const char *bn__ext(const char *path)
{
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    return dot && (!slash || dot > slash) ? dot : "";
}

bn_status bn_ff_write(const bn_transport *k, const bn_scene *scene, const char *path, const char *provenance,
                      bn_error *err)
{
    return bn__ff_write_file(k, scene, path, NULL, provenance, err);
}

static double bn__area_m2(const bn_scene *s, size_t i)
{
    size_t np;
    const bn_patch *p = bn_scene_patches(s, &np);
    double m = bn_unit_to_metres(bn_scene_unit(s));
    return p[i].area * m * m;
}

bn_status bn__ff_write_file(const bn_transport *k, const bn_scene *scene, const char *path, const char *key,
                            const char *provenance, bn_error *err)
{
    bn__outfile f;
    bn_status st;
    size_t n = bn_transport_size(k), np;
    const bn__csr *csr = bn__csr_of(k);
    const char *name = bn_transport_name(k);
    int is_float = strstr(name, "float") != NULL;
    const char *ext = bn__ext(path);
    int csv = strcmp(ext, ".csv") == 0 || strcmp(ext, ".CSV") == 0;
    bn_scene_patches(scene, &np);
    if (np != n)
        return bn_error_set(err, BN_EINTERNAL, "F has %zu rows but the scene %zu patches", n, np);
    if (!csv && strcmp(ext, ".bin") != 0 && !key)
        return bn_error_set(err, BN_EUSAGE, "%s: the output must end in .csv or .bin", path);
    st = bn__outfile_open(&f, path, csv ? "w" : "wb", err);
    if (st != BN_OK)
        return st;
    if (csv) {
        if (provenance)
            fputs(provenance, f.fp);
        fprintf(f.fp, "# F_ij: row i holds the form factors from patch i to patches j = 0..N-1; area in m^2\n");
        fprintf(f.fp, "patch,area");
        for (size_t j = 0; j < n; j++)
            fprintf(f.fp, ",F%zu", j);
        fputc('\n', f.fp);
        for (size_t i = 0; i < n && !ferror(f.fp); i++) {
            fprintf(f.fp, "%zu,%.17g", i, bn__area_m2(scene, i));
            for (size_t j = 0; j < n; j++) {
                double v = bn_transport_F(k, i, j);
                if (v == 0)
                    fputs(",0", f.fp);
                else
                    fprintf(f.fp, is_float ? ",%.9g" : ",%.17g", v);
            }
            fputc('\n', f.fp);
            if ((i & 63) == 0 && bn_interrupted() != BN_OK) {
                bn__outfile_abort(&f);
                return bn_error_set(err, bn_interrupted(), "interrupted while writing %s", path);
            }
        }
    } else {
        char head[40];
        uint32_t u32;
        uint64_t u64, tlen;
        size_t klen = key ? strlen(key) + 8 : 0, plen = provenance ? strlen(provenance) : 0;
        if (!bn__little_endian()) {
            bn__outfile_abort(&f);
            return bn_error_set(err, BN_EINTERNAL, "BNFF files are little-endian; this host is not");
        }
        tlen = klen + plen;
        memcpy(head, "BNFF", 4);
        u32 = BN__BNFF_VERSION;
        memcpy(head + 4, &u32, 4);
        u64 = n;
        memcpy(head + 8, &u64, 8);
        u32 = is_float ? 4 : 8;
        memcpy(head + 16, &u32, 4);
        u32 = csr ? 1 : 0;
        memcpy(head + 20, &u32, 4);
        u64 = csr ? csr->nnz : (uint64_t)n * n;
        memcpy(head + 24, &u64, 8);
        memcpy(head + 32, &tlen, 8);
        fwrite(head, 1, sizeof head, f.fp);
        if (key)
            fprintf(f.fp, "# key: %s\n", key);
        if (provenance)
            fwrite(provenance, 1, plen, f.fp);
        for (size_t i = 0; i < n; i++) {
            double a = bn__area_m2(scene, i);
            fwrite(&a, sizeof a, 1, f.fp);
        }
        if (csr) {
            for (size_t i = 0; i <= n; i++) {
                u64 = csr->rowptr[i];
                fwrite(&u64, 8, 1, f.fp);
            }
            fwrite(csr->col, sizeof(uint32_t), csr->nnz, f.fp);
            if (csr->v32)
                fwrite(csr->v32, sizeof(float), csr->nnz, f.fp);
            else
                fwrite(csr->v64, sizeof(double), csr->nnz, f.fp);
        } else {
            for (size_t i = 0; i < n && !ferror(f.fp); i++)
                for (size_t j = 0; j < n; j++) {
                    double v = bn_transport_F(k, i, j);
                    if (is_float) {
                        float x = (float)v;
                        fwrite(&x, sizeof x, 1, f.fp);
                    } else {
                        fwrite(&v, sizeof v, 1, f.fp);
                    }
                }
        }
    }
    return bn__outfile_commit(&f, err);
}

static int bn__read(FILE *fp, void *p, size_t size, size_t n) { return fread(p, size, n, fp) == n; }

bn_status bn__ff_read_cache(const char *path, const char *key, size_t n, bn_precision prec, bn_storage storage,
                            float **f32, double **f64, bn__csr **csr, void **impl, const bn_transport_ops **ops,
                            char *why, size_t why_size)
{
    FILE *fp = fopen(path, "rb");
    char head[40], *text = NULL, *want = NULL;
    uint32_t version, vbytes, layout;
    uint64_t N, nnz, tlen;
    size_t elem = prec == BN_PRECISION_FLOAT ? 4 : 8;
    bn_status st = BN_EINPUT;
    bn_error err;
    *f32 = NULL;
    *f64 = NULL;
    *csr = NULL;
    *impl = NULL;
    *ops = NULL;
    bn_error_clear(&err);
    if (!fp) {
        if (errno != ENOENT)
            snprintf(why, why_size, "cannot read it: %s", strerror(errno));
        return BN_EIO;
    }
    if (!bn__read(fp, head, 1, sizeof head) || memcmp(head, "BNFF", 4) != 0) {
        snprintf(why, why_size, "not a BNFF file");
        goto done;
    }
    memcpy(&version, head + 4, 4);
    memcpy(&N, head + 8, 8);
    memcpy(&vbytes, head + 16, 4);
    memcpy(&layout, head + 20, 4);
    memcpy(&nnz, head + 24, 8);
    memcpy(&tlen, head + 32, 8);
    if (version != BN__BNFF_VERSION || N != n || vbytes != elem ||
        layout != (storage == BN_STORAGE_SPARSE ? 1u : 0u) || tlen > (1u << 20)) {
        snprintf(why, why_size, "its version, patch count, precision or storage differ");
        goto done;
    }
    text = malloc(tlen + 1);
    want = malloc(strlen(key) + 16);
    if (!text || !want || !bn__read(fp, text, 1, tlen)) {
        snprintf(why, why_size, "truncated header");
        goto done;
    }
    text[tlen] = '\0';
    snprintf(want, strlen(key) + 16, "# key: %s\n", key);
    if (strncmp(text, want, strlen(want)) != 0) {
        snprintf(why, why_size, "its key differs (scene, meshing or form-factor options changed)");
        goto done;
    }
    if (fseek(fp, (long)(8 * n), SEEK_CUR) != 0) {
        snprintf(why, why_size, "truncated areas");
        goto done;
    }
    if (layout == 0) {
        bn__dense_view v;
        if (nnz != (uint64_t)n * n || bn__dense_alloc(n, prec, &v, impl, ops, &err) != BN_OK) {
            snprintf(why, why_size, "bad size or out of memory");
            goto done;
        }
        if (!bn__read(fp, v.f32 ? (void *)v.f32 : (void *)v.f64, elem, n * n)) {
            (*ops)->destroy(*impl);
            *impl = NULL;
            snprintf(why, why_size, "truncated values");
            goto done;
        }
        *f32 = v.f32;
        *f64 = v.f64;
    } else {
        size_t *counts = bn__malloc_array(n + 1, sizeof(size_t));
        uint64_t *rp = bn__malloc_array(n + 1, sizeof(uint64_t));
        bn__csr *c = NULL;
        int ok = counts && rp && bn__read(fp, rp, 8, n + 1) && rp[0] == 0 && rp[n] == nnz;
        for (size_t i = 0; ok && i < n; i++) {
            ok = rp[i + 1] >= rp[i];
            counts[i] = (size_t)(rp[i + 1] - rp[i]);
        }
        if (ok)
            ok = bn__csr_alloc(n, counts, prec, &c, &err) == BN_OK;
        free(counts);
        free(rp);
        if (ok)
            ok = bn__read(fp, c->col, 4, c->nnz) &&
                 bn__read(fp, c->v32 ? (void *)c->v32 : (void *)c->v64, elem, c->nnz);
        for (size_t i = 0; ok && i < n; i++)
            for (size_t k = c->rowptr[i]; ok && k < c->rowptr[i + 1]; k++)
                ok = c->col[k] < n && (k == c->rowptr[i] || c->col[k] > c->col[k - 1]);
        if (!ok) {
            bn__csr_free(c);
            snprintf(why, why_size, "malformed sparse data");
            goto done;
        }
        *csr = c;
        *impl = c;
        *ops = bn__csr_ops(c);
    }
    st = BN_OK;
done:
    free(text);
    free(want);
    fclose(fp);
    return st;
}
