/* bounce: status codes, error details and exit codes shared by every module. */
#ifndef BOUNCE_STATUS_H
#define BOUNCE_STATUS_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* One list makes the enum, bn_status_name() and bn_status_str() (libuv's UV_ERRNO_MAP).
 * X(NAME, exit code, description). Exit codes are those of the `bounce` command:
 * 0 success, 2 usage, 3 bad input, 4 resource limit, 5 numerical failure,
 * 6 failed verdict, 130/143 interrupted by SIGINT/SIGTERM, 1 internal error. */
#define BN_STATUS_MAP(X)                                                        \
    X(OK,        0,   "success")                                                \
    X(EUSAGE,    2,   "usage error")                                            \
    X(EINPUT,    3,   "bad input")                                              \
    X(EIO,       3,   "cannot read or write a file")                            \
    X(ENOMEM,    4,   "resource limit (memory)")                                \
    X(ENUMERIC,  5,   "numerical failure")                                      \
    X(ENOTCONV,  5,   "not converged within the iteration limit")               \
    X(ENOTSUP,   2,   "the operator cannot do what was asked")                  \
    X(EVERDICT,  6,   "a check or study verdict failed")                        \
    X(EINTR,     130, "interrupted by SIGINT")                                  \
    X(ETERM,     143, "interrupted by SIGTERM")                                 \
    X(EINTERNAL, 1,   "internal error")

typedef enum bn_status {
#define BN__STATUS_ENUM(name, code, desc) BN_##name,
    BN_STATUS_MAP(BN__STATUS_ENUM)
#undef BN__STATUS_ENUM
    BN_STATUS_COUNT
} bn_status;

const char *bn_status_name(bn_status s);   /* "EINPUT" */
const char *bn_status_str(bn_status s);    /* "bad input" */
int bn_status_exit_code(bn_status s);      /* the process exit code for s */

/* The detail of a failure: the status and a message naming the file, line or value.
 * Functions that can fail take a `bn_error *err` (may be NULL) and fill it on failure. */
#define BN_ERROR_MSG_MAX 1024
typedef struct bn_error {
    bn_status status;
    char msg[BN_ERROR_MSG_MAX];
} bn_error;

void bn_error_clear(bn_error *err);
/* Sets err (if not NULL) and returns s. printf-style message. */
bn_status bn_error_set(bn_error *err, bn_status s, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Log levels for the warnings and notes a library call may emit. */
typedef enum bn_log_level { BN_LOG_DEBUG, BN_LOG_INFO, BN_LOG_WARN } bn_log_level;

/* What a warning is about, so that a caller can count, gather or silence warnings without reading
 * their text (a study says each kind once, with its worst). One list makes the enum and
 * bn_warning_name(): BN_W_<ID>, "name". Notes carry BN_W_NONE. */
#define BN_WARNING_MAP(X)                                                                          \
    X(NONE, "none")                 /* not a warning: a note */                                   \
    X(FACE_DROPPED, "face-dropped") /* degenerate, repeated-vertex or duplicate faces dropped */  \
    X(BACK_TO_BACK, "back-to-back") /* faces back to back (a two-sided panel), both kept */       \
    X(ORIENTATION, "orientation")   /* faces wound against their vertex normals */                \
    X(NONPLANAR, "nonplanar")       /* a polygon bent enough that its triangulation shows */      \
    X(NO_COLOURS, "no-colours")     /* a mesh file without colours: reflectance 0.5 */            \
    X(MATERIAL, "material")         /* a material defined twice, or faces without one */          \
    X(NO_EMITTER, "no-emitter")     /* nothing emits: the result is black */                      \
    X(ROW_SUM, "row-sum")           /* rows of F off their exact sums (dense, sparse F) */        \
    X(BALANCE, "balance")           /* the operator makes or loses more than 1% of the light */   \
    X(PATTERN, "pattern")           /* hemisphere hits outside the sparse pattern */              \
    X(CACHE, "cache")               /* the form-factor cache could not be written */              \
    X(BOUNDS, "bounds")             /* ||K||_inf >= 1: the a priori bounds do not apply */        \
    X(ITERATIONS, "iterations")     /* the predicted iterations exceed max_iter */                \
    X(METHOD, "method")             /* a method the operator cannot run, replaced */              \
    X(LINKS, "links")               /* the hierarchy's links still splitting when frozen */       \
    X(REFERENCE, "reference")       /* a study's reference not well below the errors measured */  \
    X(CLAMPED, "clamped")           /* values clamped on output (half floats) */                  \
    X(FONT, "font")                 /* a contact sheet without labels */                          \
    X(NON_MANIFOLD, "non-manifold") /* bake vertices duplicated for OpenMesh */                   \
    X(CAMERA, "camera")             /* the camera sees almost no front face: a black image */
#define BN__WARNING_ENUM(id, name) BN_W_##id,
typedef enum bn_warning { BN_WARNING_MAP(BN__WARNING_ENUM) BN_WARNING_COUNT } bn_warning;
#undef BN__WARNING_ENUM
const char *bn_warning_name(bn_warning w);   /* "row-sum"; "?" for no such code */

/* One message as a sink gets it. */
typedef struct bn_message {
    bn_log_level level;
    bn_warning   code;    /* BN_W_NONE for notes */
    double       value;   /* a warning's measure, larger is worse (a count, the largest row sum), by
                             which a gatherer keeps the worst; NAN when it has none */
    const char  *text;    /* the whole message, without "warning:" or the code */
} bn_message;
/* The one sink type of the library; `user` is passed through. */
typedef void (*bn_log_fn)(void *user, const bn_message *m);
typedef struct bn_log {
    bn_log_fn fn;    /* NULL: warnings to stderr ("bounce: warning: TEXT [code]"), info and debug dropped */
    void *user;
    int quiet;       /* nonzero: drop everything but warnings */
} bn_log;
/* A note (level INFO or DEBUG; code BN_W_NONE). */
void bn_logf(const bn_log *log, bn_log_level level, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* A warning with its code and measure (NAN: none). */
void bn_warnf(const bn_log *log, bn_warning code, double value, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

/* Version of the library, "MAJOR.MINOR.PATCH". */
const char *bn_version(void);

/* Threads are an option of each call that runs parallel loops (form factors, solve, tracer,
 * images, pipeline, study: their opts' `threads`), scoped to that call; 0 inherits the caller's
 * setting (OpenMP's default: all cores, or OMP_NUM_THREADS), so a call made inside another uses
 * the outer call's count. Results never depend on it: random streams are seeded per patch or pixel
 * and sample, not per thread, and sums run in a fixed order. The count a `threads` value means: */
int bn_threads_resolve(int threads);

/* The memory limit wherever an option's "0 = default" applies (form factors' storage, the direct
 * solve's dense copy): 80% of physical memory, or SIZE_MAX when it cannot be known. */
size_t bn_memory_limit_default(void);

/* Interruption: the CLI installs handlers for SIGINT/SIGTERM that call bn_interrupt_raise;
 * long loops poll bn_interrupted() and return BN_EINTR or BN_ETERM (its value). */
void bn_interrupt_raise(bn_status s);
bn_status bn_interrupted(void);   /* BN_OK while not interrupted */

#ifdef __cplusplus
}
#endif
#endif
