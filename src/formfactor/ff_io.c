/* F on disk: CSV for people, the BNFF binary layout for programs and the cache. Both are written
 * row by row through the operator's entries and read back through a storage's builder, so neither
 * knows how F is stored. BNFF v2, little-endian:
 *   0  char[4]  "BNFF"       4  uint32 version (2)       8  uint64 N       16 uint64 nnz (entries written)
 *   24 uint32 value bytes (4 float32, 8 float64)          28 uint32 layout (0 full rows, 1 indexed rows)
 *   32 char[16] the storage the values were kept in (cache files: "dense", "sparse"), else the
 *               operator's name (NUL-padded; a cache is used only when it names the storage asked for)
 *   48 uint64 K, key length  56 uint64 T, text length     64 K bytes of key, then T bytes of '#' lines
 *   then N float64 patch areas (m^2), then
 *     full rows:    N*N values, row-major (F_ij at i*N + j);
 *     indexed rows: N+1 uint64 row starts, nnz uint32 columns (increasing in each row), nnz values. */
#include "formfactor/ff_io.h"
#include "base/internal.h"

#include <errno.h>
#include <string.h>

#define BN__BNFF_VERSION 2u
#define BN__BNFF_HEAD 64
#define BN__BNFF_TEXT_MAX (1u << 20)

typedef struct bn__bnff_head {
    uint64_t n, nnz, klen, tlen;
    uint32_t vbytes, layout;
    char storage[17];
} bn__bnff_head;

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

static double bn__area_m2(const bn_scene *s, size_t i)
{
    size_t np;
    const bn_patch *p = bn_scene_patches(s, &np);
    double m = bn_unit_to_metres(bn_scene_unit(s));
    return p[i].area * m * m;
}

/* Row buffers for reading F through the operator. */
typedef struct bn__rows {
    size_t *cols;
    double *vals;
} bn__rows;

static bn_status bn__rows_init(bn__rows *r, size_t n, bn_error *err)
{
    r->cols = bn__malloc_array(n ? n : 1, sizeof(size_t));
    r->vals = bn__malloc_array(n ? n : 1, sizeof(double));
    if (!r->cols || !r->vals) {
        free(r->cols);
        free(r->vals);
        return bn_error_set(err, BN_ENOMEM, "out of memory for rows of %zu entries", n);
    }
    return BN_OK;
}

static void bn__rows_free(bn__rows *r)
{
    free(r->cols);
    free(r->vals);
}

static bn_status bn__write_csv(FILE *fp, const bn_transport *k, const bn_scene *scene, const char *provenance,
                               bn_precision prec, bn_error *err)
{
    size_t n = bn_transport_size(k), cnt;
    bn__rows r;
    bn_status st = bn__rows_init(&r, n, err);
    if (st != BN_OK)
        return st;
    if (provenance)
        fputs(provenance, fp);
    fprintf(fp, "# F_ij: row i holds the form factors from patch i to patches j = 0..N-1; area in m^2\n");
    fprintf(fp, "patch,area");
    for (size_t j = 0; j < n; j++)
        fprintf(fp, ",F%zu", j);
    fputc('\n', fp);
    for (size_t i = 0; i < n && st == BN_OK && !ferror(fp); i++) {
        size_t q = 0;
        st = bn_transport_row_entries(k, i, r.cols, r.vals, &cnt, err);
        fprintf(fp, "%zu,%.17g", i, bn__area_m2(scene, i));
        for (size_t j = 0; j < n && st == BN_OK; j++) {
            double v = q < cnt && r.cols[q] == j ? r.vals[q++] : 0;
            if (v == 0)
                fputs(",0", fp);
            else
                fprintf(fp, ",%.*g", bn_precision_digits(prec), v);
        }
        fputc('\n', fp);
        if ((i & 63) == 0 && bn_interrupted() != BN_OK)
            st = bn_error_set(err, bn_interrupted(), "interrupted while writing F");
    }
    bn__rows_free(&r);
    return st;
}

static void bn__put_value(FILE *fp, double v, uint32_t vbytes)
{
    if (vbytes == 4) {
        float x = (float)v;
        fwrite(&x, sizeof x, 1, fp);
    } else {
        fwrite(&v, sizeof v, 1, fp);
    }
}

/* The BNFF header (doc/formfactors.md), the key, the provenance text and the patches' areas. */
static void bn__write_bnff_head(FILE *fp, const bn__bnff_head *h, const bn_scene *scene, const char *key,
                                const char *provenance, const char *storage)
{
    unsigned char head[BN__BNFF_HEAD];
    uint32_t v = BN__BNFF_VERSION;
    memset(head, 0, sizeof head);
    memcpy(head, "BNFF", 4);
    memcpy(head + 4, &v, 4);
    memcpy(head + 8, &h->n, 8);
    memcpy(head + 16, &h->nnz, 8);
    memcpy(head + 24, &h->vbytes, 4);
    memcpy(head + 28, &h->layout, 4);
    strncpy((char *)head + 32, storage ? storage : "", 16);
    memcpy(head + 48, &h->klen, 8);
    memcpy(head + 56, &h->tlen, 8);
    fwrite(head, 1, sizeof head, fp);
    if (key)
        fwrite(key, 1, (size_t)h->klen, fp);
    if (provenance)
        fwrite(provenance, 1, (size_t)h->tlen, fp);
    for (size_t i = 0; i < h->n; i++) {
        double a = bn__area_m2(scene, i);
        fwrite(&a, sizeof a, 1, fp);
    }
}

/* Indexed rows' index: row starts, then every row's columns. */
static bn_status bn__write_bnff_index(FILE *fp, const bn_transport *k, size_t n, bn__rows *r, bn_error *err)
{
    uint64_t pos = 0;
    size_t cnt;
    bn_status st = BN_OK;
    for (size_t i = 0; i < n && st == BN_OK; i++) {
        fwrite(&pos, 8, 1, fp);
        st = bn_transport_row_entries(k, i, r->cols, r->vals, &cnt, err);
        pos += cnt;
    }
    fwrite(&pos, 8, 1, fp);
    for (size_t i = 0; i < n && st == BN_OK; i++) {
        st = bn_transport_row_entries(k, i, r->cols, r->vals, &cnt, err);
        for (size_t q = 0; q < cnt; q++) {
            uint32_t c = (uint32_t)r->cols[q];
            fwrite(&c, 4, 1, fp);
        }
    }
    return st;
}

/* Counts the stored entries (one pass), then writes header, text, areas and rows (a second). */
static bn_status bn__write_bnff(FILE *fp, const bn_transport *k, const bn_scene *scene, const char *key,
                                const char *provenance, bn_precision prec, const char *storage, bn_error *err)
{
    size_t n = bn_transport_size(k), cnt;
    uint64_t nnz = 0;
    bn__bnff_head h;
    bn__rows r;
    bn_status st;
    if (!bn__little_endian())
        return bn_error_set(err, BN_EINTERNAL, "BNFF files are little-endian; this host is not");
    st = bn__rows_init(&r, n, err);
    for (size_t i = 0; i < n && st == BN_OK; i++) {
        st = bn_transport_row_entries(k, i, r.cols, r.vals, &cnt, err);
        nnz += cnt;
    }
    if (st != BN_OK) {
        bn__rows_free(&r);
        return st;
    }
    memset(&h, 0, sizeof h);
    h.n = n;
    h.nnz = nnz;
    h.vbytes = bn_precision_bytes(prec);
    h.layout = nnz == (uint64_t)n * n ? 0 : 1;
    h.klen = key ? strlen(key) : 0;
    h.tlen = provenance ? strlen(provenance) : 0;
    bn__write_bnff_head(fp, &h, scene, key, provenance, storage);
    if (h.layout == 1)
        st = bn__write_bnff_index(fp, k, n, &r, err);
    for (size_t i = 0; i < n && st == BN_OK && !ferror(fp); i++) {
        st = bn_transport_row_entries(k, i, r.cols, r.vals, &cnt, err);
        for (size_t q = 0; q < cnt; q++)
            bn__put_value(fp, r.vals[q], h.vbytes);
        if ((i & 63) == 0 && st == BN_OK && bn_interrupted() != BN_OK)
            st = bn_error_set(err, bn_interrupted(), "interrupted while writing F");
    }
    bn__rows_free(&r);
    return st;
}

bn_status bn__ff_write_file(const bn_transport *k, const bn_scene *scene, const char *path, const char *key,
                            const char *provenance, bn_precision prec, const char *storage, bn_error *err)
{
    bn__outfile f;
    bn_status st;
    size_t n = bn_transport_size(k), np;
    const char *ext = bn__ext(path);
    int csv = strcmp(ext, ".csv") == 0 || strcmp(ext, ".CSV") == 0;
    bn_scene_patches(scene, &np);
    if (np != n)
        return bn_error_set(err, BN_EINTERNAL, "F has %zu rows but the scene %zu patches", n, np);
    if (!csv && strcmp(ext, ".bin") != 0 && !key)
        return bn_error_set(err, BN_EUSAGE, "%s: the output must end in .csv or .bin", path);
    st = bn_transport_require(k, BN_OP_ENTRIES, "writing F to a file", err);
    if (st != BN_OK)
        return st;
    st = bn__outfile_open(&f, path, csv ? "w" : "wb", err);
    if (st != BN_OK)
        return st;
    st = csv ? bn__write_csv(f.fp, k, scene, provenance, prec, err)
             : bn__write_bnff(f.fp, k, scene, key, provenance, prec, storage ? storage : bn_transport_name(k), err);
    if (st != BN_OK) {
        bn__outfile_abort(&f);
        return st;
    }
    return bn__outfile_commit(&f, err);
}

bn_status bn_ff_write(const bn_transport *k, const bn_scene *scene, const char *path, const char *provenance,
                      bn_precision prec, bn_error *err)
{
    return bn__ff_write_file(k, scene, path, NULL, provenance, prec, NULL, err);
}

/* ---- reading the cache ---- */

static int bn__read(FILE *fp, void *p, size_t size, size_t n) { return fread(p, size, n, fp) == n; }

static int bn__read_head(FILE *fp, bn__bnff_head *h, char *why, size_t why_size)
{
    unsigned char head[BN__BNFF_HEAD];
    uint32_t version;
    if (!bn__read(fp, head, 1, sizeof head) || memcmp(head, "BNFF", 4) != 0) {
        snprintf(why, why_size, "not a BNFF file");
        return 0;
    }
    memcpy(&version, head + 4, 4);
    if (version != BN__BNFF_VERSION) {
        snprintf(why, why_size, "BNFF version %u, not %u", version, BN__BNFF_VERSION);
        return 0;
    }
    memcpy(&h->n, head + 8, 8);
    memcpy(&h->nnz, head + 16, 8);
    memcpy(&h->vbytes, head + 24, 4);
    memcpy(&h->layout, head + 28, 4);
    memcpy(h->storage, head + 32, 16);
    h->storage[16] = '\0';
    memcpy(&h->klen, head + 48, 8);
    memcpy(&h->tlen, head + 56, 8);
    return 1;
}

/* The file's pattern for storages that want one: row i's columns from the indexed layout (or
 * every column for full rows). */
typedef struct bn__file_pattern {
    size_t n;
    const uint64_t *rowptr;   /* NULL: full rows */
    const uint32_t *col;
} bn__file_pattern;

static size_t bn__file_cols(void *user, size_t i, uint32_t *cols)
{
    const bn__file_pattern *p = user;
    size_t b = p->rowptr ? (size_t)p->rowptr[i] : 0, e = p->rowptr ? (size_t)p->rowptr[i + 1] : p->n;
    if (cols)
        for (size_t q = b; q < e; q++)
            cols[q - b] = p->rowptr ? p->col[q] : (uint32_t)q;
    return e - b;
}

/* The indexed layout's row starts and columns, checked (monotone, in range, increasing). */
static int bn__read_index(FILE *fp, const bn__bnff_head *h, uint64_t **rowptr, uint32_t **col)
{
    size_t n = (size_t)h->n;
    int ok;
    *rowptr = bn__malloc_array(n + 1, sizeof(uint64_t));
    *col = bn__malloc_array(h->nnz ? (size_t)h->nnz : 1, sizeof(uint32_t));
    ok = *rowptr && *col && bn__read(fp, *rowptr, 8, n + 1) && (*rowptr)[0] == 0 && (*rowptr)[n] == h->nnz &&
         bn__read(fp, *col, 4, (size_t)h->nnz);
    for (size_t i = 0; ok && i < n; i++) {
        ok = (*rowptr)[i + 1] >= (*rowptr)[i];
        for (uint64_t q = (*rowptr)[i]; ok && q < (*rowptr)[i + 1]; q++)
            ok = (*col)[q] < n && (q == (*rowptr)[i] || (*col)[q] > (*col)[q - 1]);
    }
    return ok;
}

/* Values row by row into the builder. */
static int bn__read_values(FILE *fp, const bn__bnff_head *h, const bn__file_pattern *p, bn_transport_builder *b)
{
    size_t n = (size_t)h->n;
    bn__rows r;
    int ok = 1;
    if (bn__rows_init(&r, n, NULL) != BN_OK)
        return 0;
    for (size_t i = 0; ok && i < n; i++) {
        size_t cnt = p->rowptr ? (size_t)(p->rowptr[i + 1] - p->rowptr[i]) : n, base = p->rowptr ? (size_t)p->rowptr[i] : 0;
        for (size_t q = 0; ok && q < cnt; q++) {
            r.cols[q] = p->rowptr ? p->col[base + q] : q;
            if (h->vbytes == 4) {
                float x;
                ok = bn__read(fp, &x, 4, 1);
                r.vals[q] = x;
            } else {
                ok = bn__read(fp, &r.vals[q], 8, 1);
            }
        }
        ok = ok && bn_transport_builder_put_row(b, i, r.cols, r.vals, cnt, NULL) == BN_OK;
    }
    bn__rows_free(&r);
    return ok;
}

/* Does the file's key text (klen bytes) equal `key` or, when given, `alt`? */
static int bn__key_matches(const char *text, uint64_t klen, const char *key, const char *alt)
{
    return (klen == strlen(key) && memcmp(text, key, (size_t)klen) == 0) ||
           (alt && klen == strlen(alt) && memcmp(text, alt, (size_t)klen) == 0);
}

bn_status bn__ff_read_cache(const char *path, const char *key, const char *alt, size_t n, const char *storage,
                            bn_precision prec, const double *rho, bn_transport **out, char *why, size_t why_size)
{
    FILE *fp = fopen(path, "rb");
    bn__bnff_head h;
    char *text = NULL;
    uint64_t *rowptr = NULL;
    uint32_t *col = NULL;
    bn_transport_builder *b = NULL;
    bn_builder_opts bo;
    bn__file_pattern pat;
    bn_status st = BN_EINPUT;
    *out = NULL;
    if (!fp) {
        if (errno != ENOENT)
            snprintf(why, why_size, "cannot read it: %s", strerror(errno));
        return BN_EIO;
    }
    if (!bn__read_head(fp, &h, why, why_size))
        goto done;
    if (h.n != n || strcmp(h.storage, storage) != 0 || h.vbytes != bn_precision_bytes(prec) ||
        h.layout > 1 || h.klen > 4096 || h.tlen > BN__BNFF_TEXT_MAX ||
        (h.layout == 0 && h.nnz != (uint64_t)n * n) || h.nnz > (uint64_t)n * n) {
        snprintf(why, why_size, "its patch count, storage, precision or layout differ");
        goto done;
    }
    text = malloc((size_t)h.klen + 1);
    if (!text || !bn__read(fp, text, 1, (size_t)h.klen) || !bn__key_matches(text, h.klen, key, alt)) {
        snprintf(why, why_size, "its key differs (scene, meshing or form-factor options changed)");
        goto done;
    }
    if (fseek(fp, (long)(h.tlen + 8 * n), SEEK_CUR) != 0) {
        snprintf(why, why_size, "truncated text or areas");
        goto done;
    }
    if (h.layout == 1 && !bn__read_index(fp, &h, &rowptr, &col)) {
        snprintf(why, why_size, "malformed row index");
        goto done;
    }
    pat.n = n;
    pat.rowptr = rowptr;
    pat.col = col;
    bn_builder_opts_default(&bo);
    bo.storage = storage;
    bo.precision = prec;
    bo.pattern = bn__file_cols;
    bo.pattern_user = &pat;
    if (bn_transport_builder_create(n, &bo, NULL, &b, NULL) != BN_OK) {
        snprintf(why, why_size, "out of memory");
        goto done;
    }
    if (!bn__read_values(fp, &h, &pat, b)) {
        snprintf(why, why_size, "truncated values");
        goto done;
    }
    st = bn_transport_builder_finish(b, rho, out, NULL, NULL);
    b = NULL;
    if (st != BN_OK)
        snprintf(why, why_size, "cannot make the operator");
done:
    bn_transport_builder_destroy(b);
    free(text);
    free(rowptr);
    free(col);
    fclose(fp);
    return st;
}
