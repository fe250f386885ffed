/* The test runner: `test_x --list`, `test_x NAME` (one test), `test_x` (all, in order). */
#define _POSIX_C_SOURCE 200809L
#include "bn_test.h"
#include "bounce/rt.h"

#include <stdint.h>

#include <errno.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#define BN_MAX_TESTS 512
static struct {
    const char *name;
    bn_test_fn fn;
} bn_tests[BN_MAX_TESTS];
static int bn_ntests;
static char bn_tmpdir[8192];

void bn_test_register(const char *name, bn_test_fn fn)
{
    if (bn_ntests < BN_MAX_TESTS) {
        bn_tests[bn_ntests].name = name;
        bn_tests[bn_ntests].fn = fn;
        bn_ntests++;
    }
}

const char *bn_test_source_dir(void) { return BN_TEST_SOURCE_DIR; }
const char *bn_test_bounce_exe(void) { return BN_TEST_BOUNCE_EXE; }
const char *bn_test_tmpdir(void) { return bn_tmpdir; }

const char *bn_test_path(const char *rel)
{
    static char buf[8][4096];
    static int k;
    char *b = buf[k++ & 7];
    snprintf(b, 4096, "%s/%s", BN_TEST_SOURCE_DIR, rel);
    return b;
}

const char *bn_test_tmp(const char *name)
{
    static char buf[8][16384];
    static int k;
    char *b = buf[k++ & 7];
    snprintf(b, 16384, "%s/%s", bn_tmpdir, name);
    return b;
}

int bn_test_run(const char *cmdline, char **output)
{
    char *full;
    size_t n = strlen(cmdline) + 16;
    FILE *p;
    int st;
    full = malloc(n);
    snprintf(full, n, "%s 2>&1", cmdline);
    p = popen(full, "r");
    free(full);
    if (!p)
        BN_FAIL("popen failed: %s", strerror(errno));
    {
        size_t cap = 4096, len = 0, r;
        char *buf = malloc(cap);
        while ((r = fread(buf + len, 1, cap - len - 1, p)) > 0) {
            len += r;
            if (cap - len < 1024) {
                cap *= 2;
                buf = realloc(buf, cap);
            }
        }
        buf[len] = '\0';
        if (output)
            *output = buf;
        else
            free(buf);
    }
    st = pclose(p);
    if (WIFEXITED(st))
        return WEXITSTATUS(st);
    if (WIFSIGNALED(st))
        return 128 + WTERMSIG(st);
    return -1;
}

int bn_test_bounce(const char *args, char **output)
{
    size_t n = strlen(args) + strlen(BN_TEST_BOUNCE_EXE) + 8;
    char *cmd = malloc(n);
    int rc;
    snprintf(cmd, n, "%s %s", BN_TEST_BOUNCE_EXE, args);
    rc = bn_test_run(cmd, output);
    free(cmd);
    return rc;
}

char *bn_test_read_file(const char *path, size_t *size)
{
    FILE *fp = fopen(path, "rb");
    long len;
    char *buf;
    if (!fp)
        return NULL;
    fseek(fp, 0, SEEK_END);
    len = ftell(fp);
    fseek(fp, 0, SEEK_SET);
    buf = malloc((size_t)len + 1);
    if (fread(buf, 1, (size_t)len, fp) != (size_t)len) {
        free(buf);
        fclose(fp);
        return NULL;
    }
    buf[len] = '\0';
    fclose(fp);
    if (size)
        *size = (size_t)len;
    return buf;
}

int bn_test_file_exists(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0;
}

static void bn_make_tmpdir(const char *name)
{
    char cmd[20000];
    snprintf(bn_tmpdir, sizeof bn_tmpdir, "%s/%s", BN_TEST_BINARY_DIR, name);
    snprintf(cmd, sizeof cmd, "rm -rf '%s' && mkdir -p '%s'", bn_tmpdir, bn_tmpdir);
    if (system(cmd) != 0)
        BN_FAIL("cannot make %s", bn_tmpdir);
}

int main(int argc, char **argv)
{
    if (argc > 1 && strcmp(argv[1], "--list") == 0) {
        for (int i = 0; i < bn_ntests; i++)
            printf("%s\n", bn_tests[i].name);
        return 0;
    }
    for (int i = 0; i < bn_ntests; i++) {
        if (argc > 1 && strcmp(argv[1], bn_tests[i].name) != 0)
            continue;
        bn_make_tmpdir(bn_tests[i].name);
        bn_tests[i].fn();
        printf("ok %s\n", bn_tests[i].name);
        if (argc > 1)
            return 0;
    }
    if (argc > 1) {
        fprintf(stderr, "no test named %s\n", argv[1]);
        return 2;
    }
    return 0;
}

/* The Cornell box with its light cut into an nx x nx grid of quads, each two triangles (the same
 * surface, the same emitted radiance, so the same light): written beside its material file. */
const char *bn_test_cornell_cut_light(int nx)
{
    return bn_test_cornell_cut_light_without(nx, -1);
}

/* The same without the grid's cell `cell` (b nx + a; -1: none), a hole or a notch in the light. */
const char *bn_test_cornell_cut_light_without(int nx, int cell)
{
    static char path[4096];
    const double v0[3] = {343.0, 548.8, 227.0}, v1[3] = {343.0, 548.8, 332.0}, v3[3] = {213.0, 548.8, 227.0};
    size_t size;
    char *src = bn_test_read_file(bn_test_path("meshes/cornell-box.obj"), &size), *mtl, *light, *after;
    FILE *fp;
    BN_ASSERT(src && (light = strstr(src, "o light\n")) && (after = strstr(light, "\n\n")));
    BN_ASSERT((mtl = bn_test_read_file(bn_test_path("meshes/cornell-box.mtl"), &size)) != NULL);
    BN_ASSERT((fp = fopen(bn_test_tmp("cornell-box.mtl"), "w")) && fputs(mtl, fp) >= 0 && fclose(fp) == 0);
    snprintf(path, sizeof path, "%s", bn_test_tmp("cornell-cut.obj"));
    BN_ASSERT((fp = fopen(path, "w")) != NULL);
    fprintf(fp, "%.*so light\nusemtl light\n", (int)(light - src), src);
    for (int b = 0; b <= nx; b++)
        for (int a = 0; a <= nx; a++)
            fprintf(fp, "v %.9g %.9g %.9g\n", v0[0] + (v1[0] - v0[0]) * a / nx + (v3[0] - v0[0]) * b / nx, v0[1],
                    v0[2] + (v1[2] - v0[2]) * a / nx + (v3[2] - v0[2]) * b / nx);
    for (int b = 0; b < nx; b++)
        for (int a = 0; a < nx; a++) {
            int g = (nx + 1) * (nx + 1), i = b * (nx + 1) + a - g;   /* relative: from the end */
            if (b * nx + a == cell)
                continue;
            fprintf(fp, "f %d %d %d\nf %d %d %d\n", i, i + 1, i + nx + 2, i, i + nx + 2, i + nx + 1);
        }
    BN_ASSERT(fputs(after, fp) >= 0 && fclose(fp) == 0);
    free(src);
    free(mtl);
    return path;
}

static char *bn_test_base64(const unsigned char *p, size_t n)
{
    static const char *t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    char *out = malloc(4 * (n / 3 + 1) + 1), *o = out;
    BN_ASSERT(out);
    for (size_t i = 0; i < n; i += 3) {
        uint32_t v = (uint32_t)p[i] << 16 | (i + 1 < n ? (uint32_t)p[i + 1] << 8 : 0) | (i + 2 < n ? p[i + 2] : 0);
        *o++ = t[v >> 18 & 63], *o++ = t[v >> 12 & 63];
        *o++ = i + 1 < n ? t[v >> 6 & 63] : '=';
        *o++ = i + 2 < n ? t[v & 63] : '=';
    }
    *o = 0;
    return out;
}

const char *bn_test_write_gltf(const char *name, const char *json, const void *bin, size_t n)
{
    const char *path = bn_test_tmp(name);
    char *b64 = bn_test_base64(bin, n), num[32];
    FILE *f = fopen(path, "w");
    BN_ASSERT(f);
    snprintf(num, sizeof num, "%zu", n);
    for (const char *p = json; *p;) {
        if (strncmp(p, "@URI@", 5) == 0)
            fprintf(f, "data:application/octet-stream;base64,%s", b64), p += 5;
        else if (strncmp(p, "@N@", 3) == 0)
            fputs(num, f), p += 3;
        else
            fputc(*p++, f);
    }
    BN_ASSERT(fclose(f) == 0);
    free(b64);
    return path;
}

bn_scene *bn_test_load_meshed(const char *rel, bn_unit unit, size_t patches)
{
    bn_load_opts lo;
    bn_mesh_opts mo;
    bn_error err;
    bn_scene *s = NULL;
    bn_load_opts_default(&lo);
    lo.unit = unit;
    lo.log.quiet = 1;
    if (bn_scene_load(bn_test_path(rel), &lo, &s, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    bn_mesh_opts_default(&mo);
    mo.target_patches = patches;
    if (bn_scene_mesh(s, &mo, &err) != BN_OK)
        BN_FAIL("%s", err.msg);
    return s;
}

/* The scene at path (loaded with lo, meshed by default) gathered from its emission alone (E; KE from the
 * emitters; no solve) at size x size, one sample a pixel, by go, from its default camera or (sidecar) the
 * camera file beside it: g[0..3] (E, KE, rest, L) allocated here, the counts into gs. */
void bn_test_gather_emission(const char *path, const bn_load_opts *lo, int size, int sidecar,
                             const bn_gather_opts *go, bn_image g[4], bn_gather_stats *gs)
{
    bn_scene *s = NULL;
    bn_rt *rt = NULL;
    bn_error err;
    bn_camera cam;
    size_t np;
    double *E, *zero;
    const double *terms[2];
    BN_ASSERT_STATUS(bn_scene_load(path, lo, &s, &err), BN_OK);
    BN_ASSERT_STATUS(bn_scene_mesh(s, NULL, &err), BN_OK);
    BN_ASSERT_STATUS(bn_rt_create(s, 0, &rt, &err), BN_OK);
    bn_scene_patches(s, &np);
    BN_ASSERT((E = calloc(3 * np, sizeof *E)) && (zero = calloc(3 * np, sizeof *zero)));
    bn_scene_patch_emission(s, E);
    terms[0] = E;
    terms[1] = zero;
    bn_camera_default(s, &cam);
    if (sidecar)
        BN_ASSERT_STATUS(bn_camera_load_sidecar(path, &cam, NULL, &err), BN_OK);
    cam.width = cam.height = size;
    cam.spp = 1;
    for (int l = 0; l < 4; l++)
        BN_ASSERT_STATUS(bn_image_alloc(&g[l], size, size, &err), BN_OK);
    BN_ASSERT_STATUS(bn_gather_render(rt, &cam, terms, 1, zero, go, g, gs, &err), BN_OK);
    free(E);
    free(zero);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}
