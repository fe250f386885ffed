/* Internal helpers shared by the library's modules: checked allocation, checks, timing,
 * counter-based random numbers, atomic output files, progress. Not installed. */
#ifndef BOUNCE_BASE_INTERNAL_H
#define BOUNCE_BASE_INTERNAL_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include "bounce/status.h"

#ifdef __cplusplus
extern "C" {
#endif

#ifndef BN_VERSION_STRING
#define BN_VERSION_STRING "0.0.0"
#endif

/* Programmer errors: print both values and abort (pbrt's CHECK_*). */
#define BN_CHECK(c)                                                                    \
    do {                                                                               \
        if (!(c)) {                                                                    \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #c);      \
            abort();                                                                   \
        }                                                                              \
    } while (0)
#define BN_CHECK_OP(a, op, b)                                                          \
    do {                                                                               \
        double bn__a = (double)(a), bn__b = (double)(b);                               \
        if (!(bn__a op bn__b)) {                                                       \
            fprintf(stderr, "%s:%d: check failed: %s %s %s (%.17g vs %.17g)\n",        \
                    __FILE__, __LINE__, #a, #op, #b, bn__a, bn__b);                    \
            abort();                                                                   \
        }                                                                              \
    } while (0)

/* Allocation with overflow-checked sizes; NULL on failure or overflow (never aborts). */
void *bn__calloc(size_t n, size_t size);
void *bn__malloc_array(size_t n, size_t size);
void *bn__realloc_array(void *p, size_t n, size_t size);
/* Union-find over indices (parent[i] = i at first): the root of i's set (halving the path on the
 * way), and the union of two sets, the smaller index the root (deterministic representatives). */
size_t bn__uf_find(size_t *parent, size_t i);
void bn__uf_union(size_t *parent, size_t a, size_t b);
char *bn__strdup(const char *s);
/* Multiplies with overflow detection: returns 0 on overflow. */
int bn__mul_size(size_t a, size_t b, size_t *out);

/* A library call's thread count (its opts' `threads`, 0 = all cores), from begin to end: begin
 * returns what end restores. */
int bn__threads_begin(int threads);
void bn__threads_end(int prev);

/* Physical memory in bytes (0 if unknown) and the default --max-memory (80% of it). */
size_t bn__physical_memory(void);
/* Images' and bakes' automatic exposure (EV): the 99th percentile luminance of n RGB values at 0.9. */
double bn__auto_exposure(const float *rgb, size_t n);
/* value x 2^ev, clamped to [0, 1] (NaN: 0), sRGB-encoded to 8 bits (base/exposure.c; public as
 * bn_tonemap_srgb8). */
unsigned char bn__srgb8(double value, double ev);

/* Monotonic wall clock in seconds. */
double bn__now(void);

/* Counter-based random numbers: a stream is fixed by (seed, key1, key2) (patch or pixel, and
 * sample index), so results do not depend on the thread that draws them. */
typedef struct bn__rng { uint64_t state; } bn__rng;
uint64_t bn__hash64(uint64_t x);
bn__rng bn__rng_make(uint64_t seed, uint64_t key1, uint64_t key2);
uint64_t bn__rng_u64(bn__rng *r);
double bn__rng_uniform(bn__rng *r);   /* [0, 1) with 53 bits */

/* Atomic output files: written to a temporary name beside the target and renamed when
 * complete. Every temporary name is registered so an interrupt can remove it; once SIGINT or
 * SIGTERM has been raised (bn_interrupted), a commit removes the temporary instead and fails with
 * that status: an interrupted run leaves no output. */
typedef struct bn__outfile {
    FILE *fp;
    char *path;
    char *tmp;
} bn__outfile;
bn_status bn__outfile_open(bn__outfile *f, const char *path, const char *mode, bn_error *err);
/* Closes, checks for write errors and renames into place (or removes the temp on failure). */
bn_status bn__outfile_commit(bn__outfile *f, bn_error *err);
void bn__outfile_abort(bn__outfile *f);
/* Reserve a temporary name for libraries that write files themselves (OpenEXR, OIIO,
 * OpenMesh): *tmp is malloc'd; call bn__tmpname_commit / bn__tmpname_abort afterwards. */
bn_status bn__tmpname_reserve(const char *path, char **tmp, bn_error *err);
bn_status bn__tmpname_commit(const char *path, char *tmp, bn_error *err);
/* Under mpirun every rank computes and rank 0 alone writes: bn_dist_init gives base the rank, so
 * base needs nothing of src/dist. */
void bn__set_writer_rank(int rank);
void bn__tmpname_abort(char *tmp);
/* Removes every registered temporary file; async-signal-safe. */
void bn__tmp_remove_all(void);

/* A progress bar on a terminal (stderr is a tty and not quiet) for tasks > ~1.5 s. */
typedef struct bn__progress {
    const char *label;
    double start, last;
    size_t total;
    int enabled, shown;
    int plain;   /* stderr not a terminal: a line every BN__PROGRESS_PLAIN_S seconds instead of a bar */
} bn__progress;
#define BN__PROGRESS_PLAIN_S 30.0
void bn__progress_begin(bn__progress *p, const char *label, size_t total, int quiet);
void bn__progress_update(bn__progress *p, size_t done);   /* call from one thread */
/* From inside an OpenMP loop: adds `work` finished items to *done (atomically); thread 0 redraws. */
void bn__progress_step(bn__progress *p, size_t *done, size_t work);
void bn__progress_end(bn__progress *p);

/* A whole file in memory, NUL-terminated (malloc'd; *size excludes the NUL): the one read of a
 * scene file. Fails with BN_EIO naming the file and the system's reason. */
bn_status bn__read_file(const char *path, char **text, size_t *size, bn_error *err);

/* FNV-1a 64 over bytes, chained. */
uint64_t bn__fnv1a(uint64_t h, const void *data, size_t n);
#define BN__FNV_INIT 0xcbf29ce484222325ULL

#ifdef __cplusplus
}
#endif
/* Vocabularies: each enum's names kept once, as an X-list beside the enum's functions, e.g.
 *   #define BN__METHODS(X) X("jacobi") X("gauss-seidel")
 *   static const char *const names[] = {BN__METHODS(BN__NAME_ITEM)};      the table, by value
 *   static const char list[] = BN__METHODS(BN__NAME_BAR);                 "|jacobi|gauss-seidel"
 * and parsed by bn__name_find (the index, or -1). */
/* A macro's value as a string literal (option help: "default " BN__STR(BN_GATHER_FILTER)). */
#define BN__STR_(x) #x
#define BN__STR(x) BN__STR_(x)
#define BN__NAME_ITEM(s) s,
#define BN__NAME_BAR(s) "|" s
int bn__name_find(const char *const *names, size_t n, const char *s);

/* A vocabulary's three public functions from its X-list (in the enum's order):
 *   const char *P_name(T v);  const char *P_names(void);  int P_parse(const char *s, T *out);
 * e.g. BN__VOCABULARY(bn_trace_model, bn_trace_model, BN__TRACE_MODELS). */
#define BN__VOCABULARY(P, T, LIST)                                                                  \
    static const char *const P##__table[] = {LIST(BN__NAME_ITEM)};                                  \
    static const char P##__bar[] = LIST(BN__NAME_BAR);                                              \
    const char *P##_names(void) { return P##__bar + 1; }                                            \
    const char *P##_name(T v)                                                                       \
    {                                                                                               \
        return (unsigned)v < sizeof P##__table / sizeof *P##__table ? P##__table[v] : "?";          \
    }                                                                                               \
    int P##_parse(const char *s, T *out)                                                            \
    {                                                                                               \
        int i = bn__name_find(P##__table, sizeof P##__table / sizeof *P##__table, s);               \
        if (i >= 0)                                                                                 \
            *out = (T)i;                                                                            \
        return i >= 0 ? 0 : -1;                                                                     \
    }

/* Growing buffers (src/base/buffers.c): text (JSON headers of glTF bakes and live pages) and 4-byte
 * aligned binary. A failed allocation sets oom and later appends do nothing; the caller checks oom once
 * and frees s / p. */
typedef struct bn__str {
    char *s;
    size_t n, cap;
    int oom;
} bn__str;
void bn__str_add(bn__str *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* A JSON string literal: quotes, backslashes and control characters escaped; bytes >= 0x80 pass. */
void bn__str_json(bn__str *b, const char *v);
/* A finite double as JSON (%.9g keeps a float's value; not finite: 0). */
void bn__str_num(bn__str *b, double v);
typedef struct bn__blob {
    unsigned char *p;
    size_t n, cap;
    int oom;
} bn__blob;
/* Appends n bytes at a 4-byte boundary; returns their offset. */
size_t bn__blob_add(bn__blob *b, const void *src, size_t n);

#endif
