/* Too little address space at the stages a command-line limit cannot single out: the hierarchy's
 * refinement and the bake. The earlier stages (meshing, dense F, the gather's images) each need
 * far more than anything before them, so tests/faults.sh reaches them with `ulimit -v`; here the
 * process does its earlier stages freely, then lowers its own limit (RLIMIT_AS, what `ulimit -v`
 * sets) to what it has mapped plus a margin far below what the stage needs. The stage must fail
 * with BN_ENOMEM and a message, leave no file, and the process must go on once the limit is raised
 * again. Not under AddressSanitizer (it reserves terabytes of address space up front). */
#include <malloc.h>
#include <sys/resource.h>
#include <unistd.h>
#include "bn_test.h"
#include "bounce/bake.h"
#include "bounce/hierarchy.h"
#include "bounce/rt.h"
#include "bounce/scene.h"
#include "base/internal.h"

#if defined(__SANITIZE_ADDRESS__)
#define BN_FAULTS_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define BN_FAULTS_ASAN 1
#endif
#endif


static void no_asan(void)
{
#ifdef BN_FAULTS_ASAN
    BN_SKIP("AddressSanitizer reserves terabytes of address space: RLIMIT_AS cannot be tested under it");
#endif
}

/* The address space mapped now (VmSize), in bytes. */
static rlim_t mapped(void)
{
    FILE *f = fopen("/proc/self/statm", "r");
    unsigned long pages = 0;
    BN_ASSERT(f && fscanf(f, "%lu", &pages) == 1);
    fclose(f);
    return (rlim_t)pages * (rlim_t)sysconf(_SC_PAGESIZE);
}

/* The limit lowered to what is mapped now plus `margin` bytes; returns the old limit. */
static struct rlimit lower_limit(rlim_t margin)
{
    struct rlimit old, lim;
    BN_ASSERT(getrlimit(RLIMIT_AS, &old) == 0);
    malloc_trim(0);   /* freed heap is not a pool the stage may draw on instead */
    lim = old;
    lim.rlim_cur = mapped() + margin;
    BN_ASSERT(setrlimit(RLIMIT_AS, &lim) == 0);
    return old;
}

static void restore_limit(const struct rlimit *old)
{
    BN_ASSERT(setrlimit(RLIMIT_AS, old) == 0);
}

static bn_scene *cornell(size_t patches) { return bn_test_load_meshed("meshes/cornell-box.obj", BN_UNIT_MM, patches); }

/* eps 1e-12 links every pair of the 2,000 patches that see each other: about 3e6 links, 30 MB and
 * more; the margin, 16 MB, runs out part way. */
BN_TEST(refinement_out_of_address_space_fails_cleanly)
{
    no_asan();
    bn_scene *s = cornell(2000);
    bn_rt *rt;
    bn_transport *k = NULL;
    bn_hierarchy_opts ho;
    bn_error err;
    BN_ASSERT_STATUS(bn_rt_create(s, 1, &rt, &err), BN_OK);
    bn_hierarchy_opts_default(&ho);
    ho.eps = 1e-12;   /* splits as eps 0 does, without eps 0's exact leaf links (faster) */
    ho.min_area = -1;
    ho.samples = 1;
    ho.ff.exact_visibility = 0;
    ho.threads = 1;
    ho.quiet = 1;
    ho.log.quiet = 1;
    struct rlimit old = lower_limit((rlim_t)16 << 20);
    bn_status st = bn_hierarchy_build(s, rt, &ho, &k, NULL, &err);
    restore_limit(&old);
    BN_ASSERT_STATUS(st, BN_ENOMEM);
    BN_ASSERT(k == NULL);
    fprintf(stderr, "refinement: %s\n", err.msg);
    BN_ASSERT(strlen(err.msg) > 10);
    /* the process goes on: the same build at a coarse eps succeeds with the limit raised */
    ho.eps = 1e-1;
    BN_ASSERT_STATUS(bn_hierarchy_build(s, rt, &ho, &k, NULL, &err), BN_OK);
    bn_transport_destroy(k);
    bn_rt_destroy(rt);
    bn_scene_destroy(s);
}

static void bake_write_fails(const bn_bake *b, const double *x, const char *name, size_t nlayers)
{
    bn_bake_layer layers[2] = {{"L", x, NULL}, {"KE", x, NULL}};
    bn_bake_write_opts wo;
    bn_error err;
    memset(&wo, 0, sizeof wo);
    const char *path = bn_test_tmp(name);
    unlink(path);
    struct rlimit old = lower_limit((rlim_t)1 << 20);
    bn_status st = bn_bake_write(b, path, layers, nlayers, &wo, &err);
    restore_limit(&old);
    BN_ASSERT_STATUS(st, BN_ENOMEM);
    fprintf(stderr, "bake %s: %s\n", name, err.msg);
    BN_ASSERT(strlen(err.msg) > 10);
    BN_ASSERT(access(path, F_OK) != 0);
    /* no temporary beside it either: the directory holds nothing named after it */
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    BN_ASSERT(access(tmp, F_OK) != 0);
}

/* 50,000 patches: the bake's tables and each writer's buffers are MBs above the 1 MB margin. */
BN_TEST(bake_out_of_address_space_fails_cleanly)
{
    no_asan();
    bn_scene *s = cornell(50000);
    bn_bake *b = NULL;
    bn_error err;
    size_t np;
    bn_scene_patches(s, &np);
    struct rlimit old = lower_limit((rlim_t)1 << 20);
    bn_status st = bn_bake_create(s, 30, &b, &err);
    restore_limit(&old);
    BN_ASSERT_STATUS(st, BN_ENOMEM);
    BN_ASSERT(b == NULL);
    fprintf(stderr, "bake create: %s\n", err.msg);
    BN_ASSERT_STATUS(bn_bake_create(s, 30, &b, &err), BN_OK);
    double *x = malloc(np * 3 * sizeof *x);
    BN_ASSERT(x);
    for (size_t i = 0; i < 3 * np; i++)
        x[i] = 0.5;
    bake_write_fails(b, x, "b.glb", 2);
    bake_write_fails(b, x, "b.gltf", 2);
    BN_ASSERT(access(bn_test_tmp("b.bin"), F_OK) != 0);   /* nor the .gltf's buffer */
    bake_write_fails(b, x, "b.ply", 2);
    bake_write_fails(b, x, "b.om", 2);
    /* .obj is written as it goes, in stdio's buffer: it needs no more than the margin */
    free(x);
    bn_bake_destroy(b);
    bn_scene_destroy(s);
}

/* SIGTERM during the bake: the handler raises BN_ETERM (bn_interrupt_raise), which each writer
 * meets before it commits; here it is raised at the bake's start, as a signal arriving then would. */
BN_TEST(bake_interrupted_writes_nothing)
{
    bn_scene *s = cornell(500);
    bn_bake *b = NULL;
    bn_error err;
    size_t np;
    static const char *names[] = {"b.glb", "b.gltf", "b.ply", "b.om", "b.obj"};
    bn_scene_patches(s, &np);
    BN_ASSERT_STATUS(bn_bake_create(s, 30, &b, &err), BN_OK);
    double *x = calloc(np * 3, sizeof *x);
    BN_ASSERT(x);
    bn_bake_layer layer = {"L", x, NULL};
    bn_bake_write_opts wo;
    memset(&wo, 0, sizeof wo);
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        const char *path = bn_test_tmp(names[i]);
        bn_interrupt_raise(BN_ETERM);
        bn_status st = bn_bake_write(b, path, &layer, 1, &wo, &err);
        bn_interrupt_raise(BN_OK);
        BN_ASSERT_STATUS(st, BN_ETERM);
        fprintf(stderr, "%s: %s\n", names[i], err.msg);
        BN_ASSERT(access(path, F_OK) != 0);
        /* and written once the flag is down: the same call was not refused for another reason */
        BN_ASSERT_STATUS(bn_bake_write(b, path, &layer, 1, &wo, &err), BN_OK);
        BN_ASSERT(access(path, F_OK) == 0);
    }
    BN_ASSERT(access(bn_test_tmp("b.bin"), F_OK) == 0);
    free(x);
    bn_bake_destroy(b);
    bn_scene_destroy(s);
}

/* SIGTERM while a file is being written: the commit meets the flag and leaves nothing. */
BN_TEST(commit_after_interrupt_leaves_nothing)
{
    bn__outfile f;
    bn_error err;
    const char *path = bn_test_tmp("out.csv");
    BN_ASSERT_STATUS(bn__outfile_open(&f, path, "w", &err), BN_OK);
    fprintf(f.fp, "a,b\n1,2\n");
    char *tmp = strdup(f.tmp);
    bn_interrupt_raise(BN_EINTR);
    bn_status st = bn__outfile_commit(&f, &err);
    bn_interrupt_raise(BN_OK);
    BN_ASSERT_STATUS(st, BN_EINTR);
    fprintf(stderr, "%s\n", err.msg);
    BN_ASSERT(strstr(err.msg, "interrupted"));
    BN_ASSERT(access(path, F_OK) != 0);
    BN_ASSERT(access(tmp, F_OK) != 0);
    free(tmp);
}
