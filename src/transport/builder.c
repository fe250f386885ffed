/* Filling F without knowing its storage: the registry of storages by name and the builder that
 * takes entries (one at a time from many threads, or a row at a time) and hands back K. */
#include "bounce/transport.h"
#include "transport/storage.h"
#include "base/internal.h"

#include <string.h>

/* Every storage bounce has; a new one is one more entry here and its own file. */
#define BN__STORAGES(X) X(dense) X(sparse)
#define BN__STORAGE_PTR(s) &bn__storage_##s,
#define BN__STORAGE_BAR(s) "|" #s
static const bn__storage *const bn__storages[] = {BN__STORAGES(BN__STORAGE_PTR)};
static const char bn__storage_list[] = BN__STORAGES(BN__STORAGE_BAR);
#define BN__NSTORAGES (sizeof bn__storages / sizeof bn__storages[0])

static const bn__storage *bn__storage_find(const char *name)
{
    if (!name)
        name = BN_STORAGE_DEFAULT;
    for (size_t q = 0; q < BN__NSTORAGES; q++)
        if (strcmp(bn__storages[q]->name, name) == 0)
            return bn__storages[q];
    return NULL;
}

const char *bn_storage_names(void) { return bn__storage_list + 1; }
int bn_storage_exists(const char *name) { return bn__storage_find(name) != NULL; }

int bn_storage_needs_pattern(const char *name)
{
    const bn__storage *s = bn__storage_find(name);
    return s && s->needs_pattern;
}

size_t bn_storage_bytes(const char *name, size_t n, size_t nnz, bn_precision prec)
{
    const bn__storage *s = bn__storage_find(name);
    return s ? s->bytes(n, nnz, prec) : SIZE_MAX;
}

void bn_storage_smaller(const char *name, bn_precision prec, char *buf, size_t size)
{
    const bn__storage *s = bn__storage_find(name);
    snprintf(buf, size, "%s%s", s && !s->needs_pattern ? ", `storage` sparse" : "",
             prec == BN_PRECISION_DOUBLE ? ", `precision` float" : "");
}

void bn_builder_opts_default(bn_builder_opts *o)
{
    memset(o, 0, sizeof *o);
    o->storage = BN_STORAGE_DEFAULT;
    o->precision = BN_PRECISION_FLOAT;
}

struct bn_transport_builder {
    const bn__storage *s;
    size_t n;
    double drop_below;
    void *sink;
    size_t lost;
};

/* counts[i] = pattern(i, NULL); the total, or SIZE_MAX on overflow. */
static size_t bn__pattern_counts(const bn_builder_opts *o, size_t n, size_t *counts)
{
    long ln = (long)n;
    size_t total = 0;
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : total)
    for (long i = 0; i < ln; i++) {
        counts[i] = o->pattern(o->pattern_user, (size_t)i, NULL);
        total += counts[i];
    }
    return total;
}

bn_status bn_transport_builder_create(size_t n, const bn_builder_opts *o, size_t *need, bn_transport_builder **out,
                                      bn_error *err)
{
    const bn__storage *s = bn__storage_find(o->storage);
    size_t *counts = NULL, bytes, nnz = 0;
    bn_transport_builder *b;
    bn_status st;
    *out = NULL;
    if (need)
        *need = SIZE_MAX;
    if (!s)
        return bn_error_set(err, BN_EUSAGE, "unknown storage '%s' (one of %s)", o->storage, bn_storage_names());
    if (!(o->drop_below >= 0 && o->drop_below < 1))
        return bn_error_set(err, BN_EINPUT, "drop threshold %g is outside [0, 1)", o->drop_below);
    if (s->needs_pattern) {
        if (!o->pattern)
            return bn_error_set(err, BN_EINTERNAL, "%s storage needs a pattern and none was given", s->name);
        if (n > UINT32_MAX)
            return bn_error_set(err, BN_ENOMEM, "%s F: %zu patches exceed 32-bit column indices", s->name, n);
        counts = bn__malloc_array(n ? n : 1, sizeof(size_t));
        if (!counts)
            return bn_error_set(err, BN_ENOMEM, "out of memory for the pattern of %zu rows", n);
        nnz = bn__pattern_counts(o, n, counts);
    }
    bytes = s->bytes(n, nnz, o->precision);
    if (need)
        *need = bytes;
    if (bytes == SIZE_MAX || (o->max_bytes && bytes > o->max_bytes)) {
        free(counts);
        return bn_error_set(err, BN_ENOMEM, "%s F for %zu patches needs %zu bytes, above the limit of %zu", s->name, n,
                            bytes, o->max_bytes);
    }
    b = calloc(1, sizeof *b);
    if (!b) {
        free(counts);
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    st = s->begin(n, o->precision, counts, &b->sink, err);
    free(counts);
    if (st != BN_OK) {
        free(b);
        return st;
    }
    if (s->needs_pattern) {
        long ln = (long)n;
#pragma omp parallel for schedule(dynamic, 16)
        for (long i = 0; i < ln; i++)
            o->pattern(o->pattern_user, (size_t)i, s->pattern_row(b->sink, (size_t)i));
    }
    b->s = s;
    b->n = n;
    b->drop_below = o->drop_below;
    *out = b;
    return BN_OK;
}

int bn_transport_builder_put(bn_transport_builder *b, size_t i, size_t j, double v)
{
    if (b->s->put(b->sink, i, j, v))
        return 1;
#pragma omp atomic
    b->lost++;
    return 0;
}

bn_status bn_transport_builder_put_row(bn_transport_builder *b, size_t i, const size_t *cols, const double *vals,
                                       size_t count, bn_error *err)
{
    if (i >= b->n)
        return bn_error_set(err, BN_EINPUT, "row %zu of %zu", i, b->n);
    for (size_t q = 0; q < count; q++) {
        if (cols[q] >= b->n || (q && cols[q] <= cols[q - 1]))
            return bn_error_set(err, BN_EINPUT, "row %zu: column %zu out of range or out of order", i, cols[q]);
        bn_transport_builder_put(b, i, cols[q], vals[q]);
    }
    return BN_OK;
}

bn_status bn_transport_builder_finish(bn_transport_builder *b, const double *rho, bn_transport **out,
                                      bn_builder_report *rep, bn_error *err)
{
    bn_builder_report r;
    const bn_transport_ops *ops = NULL;
    void *ctx = NULL;
    size_t n = b->n;
    bn_status st;
    memset(&r, 0, sizeof r);
    *out = NULL;
    st = b->s->finish(b->sink, b->drop_below, &r, &ops, &ctx, err);
    r.lost_puts = b->lost;
    free(b);
    if (rep)
        *rep = r;
    if (st != BN_OK)
        return st;
    return bn_transport_create(n, rho, ops, ctx, out, err);
}

void bn_transport_builder_destroy(bn_transport_builder *b)
{
    if (!b)
        return;
    b->s->abort(b->sink);
    free(b);
}

/* Row i's nonzero columns of a dense array: the pattern of bn_transport_from_array. */
typedef struct bn__array_pattern {
    size_t n;
    const double *F;
} bn__array_pattern;

static size_t bn__array_cols(void *user, size_t i, uint32_t *cols)
{
    const bn__array_pattern *p = user;
    size_t m = 0;
    for (size_t j = 0; j < p->n; j++)
        if (p->F[i * p->n + j] != 0) {
            if (cols)
                cols[m] = (uint32_t)j;
            m++;
        }
    return m;
}

bn_status bn_transport_from_array(size_t n, const double *F, const double *rho, const char *storage,
                                  bn_precision prec, double drop_below, bn_transport **out, bn_error *err)
{
    bn_builder_opts o;
    bn__array_pattern p = {n, F};
    bn_transport_builder *b;
    bn_status st;
    bn_builder_opts_default(&o);
    o.storage = storage;
    o.precision = prec;
    o.drop_below = drop_below;
    o.pattern = bn__array_cols;
    o.pattern_user = &p;
    *out = NULL;
    st = bn_transport_builder_create(n, &o, NULL, &b, err);
    if (st != BN_OK)
        return st;
    for (size_t i = 0; i < n; i++)
        for (size_t j = 0; j < n; j++)
            if (F[i * n + j] != 0)
                bn_transport_builder_put(b, i, j, F[i * n + j]);
    return bn_transport_builder_finish(b, rho, out, NULL, err);
}
