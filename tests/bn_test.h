/* A small test runner (libuv's test-list style): each BN_TEST in a file is registered with
 * ctest as its own process (`test_x NAME`); assertions print both values. */
#ifndef BN_TEST_H
#define BN_TEST_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "bounce/gather.h"
#include "bounce/scene.h"
#include "bounce/transport.h"

typedef void (*bn_test_fn)(void);
void bn_test_register(const char *name, bn_test_fn fn);

#define BN_TEST(name)                                                                          \
    static void bn_test_##name(void);                                                          \
    __attribute__((constructor)) static void bn_test_reg_##name(void)                          \
    {                                                                                          \
        bn_test_register(#name, bn_test_##name);                                               \
    }                                                                                          \
    static void bn_test_##name(void)

#define BN_FAIL(...)                                                                           \
    do {                                                                                       \
        fprintf(stderr, "%s:%d: FAIL: ", __FILE__, __LINE__);                                  \
        fprintf(stderr, __VA_ARGS__);                                                          \
        fprintf(stderr, "\n");                                                                 \
        exit(1);                                                                               \
    } while (0)

#define BN_ASSERT(c)                                                                           \
    do {                                                                                       \
        if (!(c))                                                                              \
            BN_FAIL("%s", #c);                                                                 \
    } while (0)

#define BN_ASSERT_OP(a, op, b)                                                                 \
    do {                                                                                       \
        double bn_a_ = (double)(a), bn_b_ = (double)(b);                                       \
        if (!(bn_a_ op bn_b_))                                                                 \
            BN_FAIL("%s %s %s (%.17g vs %.17g)", #a, #op, #b, bn_a_, bn_b_);                   \
    } while (0)
#define BN_ASSERT_EQ(a, b) BN_ASSERT_OP(a, ==, b)
#define BN_ASSERT_LE(a, b) BN_ASSERT_OP(a, <=, b)
#define BN_ASSERT_LT(a, b) BN_ASSERT_OP(a, <, b)
#define BN_ASSERT_GE(a, b) BN_ASSERT_OP(a, >=, b)
#define BN_ASSERT_GT(a, b) BN_ASSERT_OP(a, >, b)

/* |a - b| <= tol (absolute). */
#define BN_ASSERT_NEAR(a, b, tol)                                                              \
    do {                                                                                       \
        double bn_a_ = (double)(a), bn_b_ = (double)(b), bn_t_ = (double)(tol);                \
        if (!(fabs(bn_a_ - bn_b_) <= bn_t_))                                                   \
            BN_FAIL("%s = %.17g, %s = %.17g, |diff| %.3g > tol %.3g", #a, bn_a_, #b, bn_b_,     \
                    fabs(bn_a_ - bn_b_), bn_t_);                                               \
    } while (0)
/* |a - b| <= rtol * |b| (relative to the expected value b). */
#define BN_ASSERT_REL(a, b, rtol)                                                              \
    do {                                                                                       \
        double bn_a_ = (double)(a), bn_b_ = (double)(b), bn_t_ = (double)(rtol);               \
        if (!(fabs(bn_a_ - bn_b_) <= bn_t_ * fabs(bn_b_)))                                     \
            BN_FAIL("%s = %.17g, expected %s = %.17g, relative error %.3g > %.3g", #a, bn_a_,   \
                    #b, bn_b_, fabs(bn_a_ - bn_b_) / fabs(bn_b_), bn_t_);                      \
    } while (0)
#define BN_ASSERT_STATUS(expr, expected)                                                       \
    do {                                                                                       \
        int bn_s_ = (int)(expr), bn_e_ = (int)(expected);                                      \
        if (bn_s_ != bn_e_)                                                                    \
            BN_FAIL("%s returned %d, expected %d", #expr, bn_s_, bn_e_);                       \
    } while (0)

/* Skips the test (ctest reports it as skipped, not passed): exit code 77. */
#define BN_SKIP(...)                                                                           \
    do {                                                                                       \
        fprintf(stderr, "skipped: ");                                                          \
        fprintf(stderr, __VA_ARGS__);                                                          \
        fprintf(stderr, "\n");                                                                 \
        exit(77);                                                                              \
    } while (0)
/* Slow tests (marked BN_SLOW) skip themselves when BN_TEST_SKIP_SLOW is set: the sanitized run. */
#define BN_SKIP_IF_SLOW_RUN()                                                                  \
    do {                                                                                       \
        if (getenv("BN_TEST_SKIP_SLOW"))                                                       \
            BN_SKIP("slow test; BN_TEST_SKIP_SLOW is set (sanitized run)");                    \
    } while (0)

/* Paths configured by CMake. */
const char *bn_test_source_dir(void);   /* the repository */
const char *bn_test_bounce_exe(void);   /* the bounce command */
const char *bn_test_tmpdir(void);       /* a fresh folder for this test's files */
/* "<source>/<rel>" in a static buffer rotation (8 slots). */
const char *bn_test_path(const char *rel);
/* "<tmpdir>/<name>". */
const char *bn_test_tmp(const char *name);

/* Runs a shell command line, capturing stdout and stderr together into *output (malloc'd,
 * may be NULL). Returns the exit code, or 128 + signal if it was killed. */
int bn_test_run(const char *cmdline, char **output);
/* Runs `bounce ARGS` (args appended after the executable). */
int bn_test_bounce(const char *args, char **output);
/* A scene of the repository (rel, e.g. "meshes/cornell-box.obj") loaded quietly in `unit` and meshed
 * to about `patches` patches; fails the test on any error. */
bn_scene *bn_test_load_meshed(const char *rel, bn_unit unit, size_t patches);
/* Reads a whole file (malloc'd, NUL-terminated) or NULL. */
char *bn_test_read_file(const char *path, size_t *size);
int bn_test_file_exists(const char *path);
/* meshes/cornell-box.obj with its light cut into an nx x nx grid of quads, two triangles each (the
 * same light), written with its .mtl into the test's folder: the file's path (static). */
const char *bn_test_cornell_cut_light(int nx);
/* The same without one cell (b nx + a; -1: none): a hole or a notch in the light. */
const char *bn_test_cornell_cut_light_without(int nx, int cell);
/* The scene at path (loaded with lo) gathered from its emission alone (no solve) at size x size, one
 * sample a pixel, by go, from its default camera or (sidecar) its .camera: g[0..3] (E, KE, rest, L)
 * allocated here (the caller frees them), the counts into gs. */
void bn_test_gather_emission(const char *path, const bn_load_opts *lo, int size, int sidecar,
                             const bn_gather_opts *go, bn_image g[4], bn_gather_stats *gs);

/* Writes `json` to "<tmpdir>/<name>" with every "@URI@" replaced by the data URI of bin[0 .. n) and "@N@"
 * by n (a glTF with its buffer inline): the path (bn_test_tmp's). */
const char *bn_test_write_gltf(const char *name, const char *json, const void *bin, size_t n);

/* F_ij of an operator with entries; fails the test if the operator cannot give it. */
/* Perpendicular rectangles with a common edge of length l: the form factor from the w x l one to
 * the h x l one (Howell's catalogue, C-14): the independent answer of several tests. */
static inline double bn_test_F_perpendicular(double w, double h, double l)
{
    double W = w / l, H = h / l, w2 = W * W, h2 = H * H, q = sqrt(w2 + h2);
    double a = (1 + w2) * (1 + h2) / (1 + w2 + h2), b = w2 * (1 + w2 + h2) / ((1 + w2) * (w2 + h2)),
           c = h2 * (1 + h2 + w2) / ((1 + h2) * (h2 + w2));
    return (W * atan(1 / W) + H * atan(1 / H) - q * atan(1 / q) + 0.25 * (log(a) + w2 * log(b) + h2 * log(c))) /
           (3.14159265358979323846 * W);
}

static inline double bn_test_F(const bn_transport *k, size_t i, size_t j)
{
    double v = NAN;
    bn_error e;
    if (bn_transport_entry(k, i, j, &v, &e) != BN_OK) {
        fprintf(stderr, "FAIL: F[%zu][%zu]: %s\n", i, j, e.msg);
        exit(1);
    }
    return v;
}

#endif
