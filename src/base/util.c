/* Checked allocation, clocks, counter-based RNG, atomic output files and progress bars. */
#define _POSIX_C_SOURCE 200809L
#include "base/internal.h"

#include <errno.h>
#include <signal.h>
#include <stdint.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include <omp.h>

int bn__mul_size(size_t a, size_t b, size_t *out)
{
    if (a != 0 && b > SIZE_MAX / a)
        return 0;
    *out = a * b;
    return 1;
}

void *bn__calloc(size_t n, size_t size)
{
    size_t total;
    if (!bn__mul_size(n, size, &total))
        return NULL;
    return calloc(n ? n : 1, size ? size : 1);
}

void *bn__malloc_array(size_t n, size_t size)
{
    size_t total;
    if (!bn__mul_size(n, size, &total))
        return NULL;
    return malloc(total ? total : 1);
}

void *bn__realloc_array(void *p, size_t n, size_t size)
{
    size_t total;
    if (!bn__mul_size(n, size, &total))
        return NULL;
    return realloc(p, total ? total : 1);
}

size_t bn__uf_find(size_t *parent, size_t i)
{
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

void bn__uf_union(size_t *parent, size_t a, size_t b)
{
    a = bn__uf_find(parent, a);
    b = bn__uf_find(parent, b);
    if (a < b)
        parent[b] = a;
    else if (b < a)
        parent[a] = b;
}

char *bn__strdup(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = malloc(n);
    if (d)
        memcpy(d, s, n);
    return d;
}

size_t bn__physical_memory(void)
{
    long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
    if (pages <= 0 || page <= 0)
        return 0;
    return (size_t)pages * (size_t)page;
}

double bn__now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* splitmix64 finaliser: a bijective 64-bit mix (Steele et al. 2014). */
uint64_t bn__hash64(uint64_t x)
{
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

bn__rng bn__rng_make(uint64_t seed, uint64_t key1, uint64_t key2)
{
    bn__rng r;
    r.state = bn__hash64(bn__hash64(bn__hash64(seed) ^ key1) ^ (key2 * 0xd1342543de82ef95ULL));
    return r;
}

uint64_t bn__rng_u64(bn__rng *r)
{
    uint64_t z = (r->state += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

double bn__rng_uniform(bn__rng *r) { return (double)(bn__rng_u64(r) >> 11) * 0x1.0p-53; }

uint64_t bn__fnv1a(uint64_t h, const void *data, size_t n)
{
    const unsigned char *p = data;
    for (size_t i = 0; i < n; i++) {
        h ^= p[i];
        h *= 0x100000001b3ULL;
    }
    return h;
}

/* ---- temporary-file registry (fixed slots so a signal handler can walk it) ---- */
#define BN__TMP_SLOTS 64
#define BN__TMP_PATH 4096
static char bn__tmp_paths[BN__TMP_SLOTS][BN__TMP_PATH];
static volatile sig_atomic_t bn__tmp_used[BN__TMP_SLOTS];

static void bn__tmp_register(const char *tmp)
{
    for (int i = 0; i < BN__TMP_SLOTS; i++) {
        if (!bn__tmp_used[i] && strlen(tmp) < BN__TMP_PATH) {
            memcpy(bn__tmp_paths[i], tmp, strlen(tmp) + 1);
            bn__tmp_used[i] = 1;
            return;
        }
    }
}

static void bn__tmp_unregister(const char *tmp)
{
    for (int i = 0; i < BN__TMP_SLOTS; i++)
        if (bn__tmp_used[i] && strcmp(bn__tmp_paths[i], tmp) == 0) {
            bn__tmp_used[i] = 0;
            return;
        }
}

void bn__tmp_remove_all(void)
{
    for (int i = 0; i < BN__TMP_SLOTS; i++)
        if (bn__tmp_used[i]) {
            unlink(bn__tmp_paths[i]);
            bn__tmp_used[i] = 0;
        }
}

bn_status bn__tmpname_reserve(const char *path, char **tmp, bn_error *err)
{
    /* Same folder as the target (rename is atomic only within a filesystem); the extension is
     * kept last because OpenImageIO and OpenMesh pick the format from it. */
    const char *slash = strrchr(path, '/');
    const char *base = slash ? slash + 1 : path;
    const char *dot = strrchr(base, '.');
    size_t dirlen = (size_t)(base - path);
    size_t stemlen = dot ? (size_t)(dot - base) : strlen(base);
    const char *ext = dot ? dot : "";
    size_t n = strlen(path) + 64;
    char *t = malloc(n);
    if (!t)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    snprintf(t, n, "%.*s.%.*s.tmp%ld%s", (int)dirlen, path, (int)stemlen, base, (long)getpid(), ext);
    bn__tmp_register(t);
    *tmp = t;
    return BN_OK;
}

/* This process's rank under mpirun (bn_dist_init says so): only rank 0 commits outputs. */
static int bn__writer_rank = 0;
void bn__set_writer_rank(int rank) { bn__writer_rank = rank; }

bn_status bn__tmpname_commit(const char *path, char *tmp, bn_error *err)
{
    bn_status st = BN_OK;
    if (bn__writer_rank != 0) {   /* under mpirun, rank 0 alone writes outputs: the others drop theirs */
        bn__tmpname_abort(tmp);
        return BN_OK;
    }
    if (bn_interrupted() != BN_OK) {   /* an interrupted run commits nothing, whatever it had finished */
        st = bn_error_set(err, bn_interrupted(), "%s: interrupted; not written", path);
        unlink(tmp);
    } else if (rename(tmp, path) != 0) {
        st = bn_error_set(err, BN_EIO, "%s: cannot rename %s into place: %s", path, tmp, strerror(errno));
        unlink(tmp);
    }
    bn__tmp_unregister(tmp);
    free(tmp);
    return st;
}

void bn__tmpname_abort(char *tmp)
{
    if (!tmp)
        return;
    unlink(tmp);
    bn__tmp_unregister(tmp);
    free(tmp);
}

bn_status bn__outfile_open(bn__outfile *f, const char *path, const char *mode, bn_error *err)
{
    bn_status st;
    memset(f, 0, sizeof *f);
    f->path = bn__strdup(path);
    if (!f->path)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    st = bn__tmpname_reserve(path, &f->tmp, err);
    if (st != BN_OK) {
        free(f->path);
        f->path = NULL;
        return st;
    }
    f->fp = fopen(f->tmp, mode);
    if (!f->fp) {
        st = bn_error_set(err, BN_EIO, "%s: cannot write: %s", path, strerror(errno));
        bn__tmpname_abort(f->tmp);
        free(f->path);
        memset(f, 0, sizeof *f);
        return st;
    }
    return BN_OK;
}

bn_status bn__outfile_commit(bn__outfile *f, bn_error *err)
{
    bn_status st = BN_OK;
    int bad = ferror(f->fp), e;
    errno = 0;
    if (fflush(f->fp) != 0)   /* the buffer's last bytes: a full disk or a size limit says why here */
        bad = 1;
    e = errno;
    if (fclose(f->fp) != 0)
        bad = 1;
    e = e ? e : errno;
    f->fp = NULL;
    if (bad) {
        st = bn_error_set(err, BN_EIO, "%s: write failed: %s", f->path,
                          e ? strerror(e) : "an earlier write failed (disk full, or a file size limit?)");
        bn__tmpname_abort(f->tmp);
    } else {
        st = bn__tmpname_commit(f->path, f->tmp, err);
    }
    free(f->path);
    memset(f, 0, sizeof *f);
    return st;
}

void bn__outfile_abort(bn__outfile *f)
{
    if (f->fp)
        fclose(f->fp);
    bn__tmpname_abort(f->tmp);
    free(f->path);
    memset(f, 0, sizeof *f);
}

/* ---- progress bar ---- */
void bn__progress_begin(bn__progress *p, const char *label, size_t total, int quiet)
{
    memset(p, 0, sizeof *p);
    p->label = label;
    p->total = total;
    p->start = p->last = bn__now();
    p->enabled = !quiet && isatty(STDERR_FILENO);
    p->plain = !quiet && !p->enabled;
}

void bn__progress_update(bn__progress *p, size_t done)
{
    double now;
    if ((!p->enabled && !p->plain) || p->total == 0)
        return;
    now = bn__now();
    if (p->plain) {   /* a log or a pipe: a plain line now and then, for stages that take minutes */
        double frac = (double)done / (double)p->total;
        if (now - p->last < BN__PROGRESS_PLAIN_S)
            return;
        p->last = now;
        fprintf(stderr, "bounce: %s: %.0f%% after %.0f s (about %.0f s left)\n", p->label, 100 * frac,
                now - p->start, frac > 0 ? (now - p->start) * (1 - frac) / frac : 0);
        return;
    }
    if (now - p->start < 1.5 || now - p->last < 0.2)
        return;
    p->last = now;
    p->shown = 1;
    {
        double frac = (double)done / (double)p->total;
        double left = frac > 0 ? (now - p->start) * (1 - frac) / frac : 0;
        int bars = (int)(frac * 30);
        char bar[31];
        for (int i = 0; i < 30; i++)
            bar[i] = i < bars ? '#' : '.';
        bar[30] = '\0';
        fprintf(stderr, "\r%-14s [%s] %5.1f%%  %6.1fs left ", p->label, bar, 100 * frac, left);
        fflush(stderr);
    }
}

void bn__progress_step(bn__progress *p, size_t *done, size_t work)
{
    size_t d;
#pragma omp atomic capture
    d = *done += work;
    if (omp_get_thread_num() == 0)
        bn__progress_update(p, d);
}

void bn__progress_end(bn__progress *p)
{
    if (p->enabled && p->shown)
        fprintf(stderr, "\r%-14s done in %.1fs%40s\n", p->label, bn__now() - p->start, "");
}

bn_status bn__read_file(const char *path, char **text, size_t *size, bn_error *err)
{
    FILE *fp = fopen(path, "rb");
    long n;
    *text = NULL;
    *size = 0;
    if (!fp)
        return bn_error_set(err, BN_EIO, "%s: cannot open: %s", path, strerror(errno));
    if (fseek(fp, 0, SEEK_END) != 0 || (n = ftell(fp)) < 0 || fseek(fp, 0, SEEK_SET) != 0) {
        fclose(fp);
        return bn_error_set(err, BN_EIO, "%s: cannot read: %s", path, strerror(errno));
    }
    *text = malloc((size_t)n + 1);
    if (!*text) {
        fclose(fp);
        return bn_error_set(err, BN_ENOMEM, "%s: out of memory for its %ld bytes", path, n);
    }
    if (fread(*text, 1, (size_t)n, fp) != (size_t)n) {
        fclose(fp);
        free(*text);
        *text = NULL;
        return bn_error_set(err, BN_EIO, "%s: cannot read: %s", path, strerror(errno));
    }
    fclose(fp);
    (*text)[n] = '\0';
    *size = (size_t)n;
    return BN_OK;
}

int bn__name_find(const char *const *names, size_t n, const char *s)
{
    for (size_t i = 0; s && i < n; i++)
        if (strcmp(names[i], s) == 0)
            return (int)i;
    return -1;
}
