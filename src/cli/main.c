/* `bounce`: argv -> subcommand -> option structs -> library calls. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/dist.h"

#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef struct bn_command {
    const char *name;
    int (*run)(int argc, char **argv, bn_cli_common *c);
    const char *summary;
} bn_command;

static const bn_command bn__commands[] = {
    {"info", bn_cmd_info, "describe a scene: faces, patches, emitters, materials, power, memory"},
    {"formfactors", bn_cmd_formfactors, "compute the form factors F (with visibility) and write them"},
    {"solve", bn_cmd_solve, "solve L = E + K L per patch (Jacobi, Gauss-Seidel, Neumann, direct)"},
    {"bounces", bn_cmd_bounces, "per-bounce images E, KE, K2E, ... as multi-layer EXR and PNG previews"},
    {"bake", bn_cmd_bake, "bake the solution to vertex colours (PLY, OM, OBJ, glTF)"},
    {"view", bn_cmd_view, "a self-contained HTML page showing a bake bounce by bounce in a browser"},
    {"trace", bn_cmd_trace, "Monte Carlo path tracer over the same patches, per-bounce layers"},
    {"crosscheck", bn_cmd_crosscheck, "compare radiosity with the path tracer, per patch and bounce"},
    {"study", bn_cmd_study, "speed-accuracy studies: error against bounces, iterations, mesh, samples, time"},
};
#define BN__NCOMMANDS (sizeof bn__commands / sizeof bn__commands[0])

static void bn__usage(FILE *fp)
{
    fprintf(fp, "usage: bounce COMMAND [options]   (bounce COMMAND --help for its options)\n\n"
                "Radiosity and Neumann-series light transport: L = E + K L, K = diag(rho) F,\n"
                "with every bounce term K^k E kept (E emission, KE direct light, K2E first indirect).\n\ncommands:\n");
    for (size_t i = 0; i < BN__NCOMMANDS; i++)
        fprintf(fp, "  %-12s %s\n", bn__commands[i].name, bn__commands[i].summary);
    fprintf(fp, "\n  --version    print the version\n  --help       this help\n\n%s", bn_cli_exit_codes);
}

static void bn__on_signal(int sig)
{
    if (bn_interrupted() != BN_OK) {
        /* Second signal: stop now, leaving no temporary file behind. */
        bn__tmp_remove_all();
        _exit(sig == SIGINT ? 130 : 143);
    }
    bn_interrupt_raise(sig == SIGINT ? BN_EINTR : BN_ETERM);
}

static char *bn__join_cmdline(int argc, char **argv)
{
    size_t n = 1;
    char *s;
    for (int i = 0; i < argc; i++)
        n += strlen(argv[i]) + 3;
    s = malloc(n);
    if (!s)
        return NULL;
    s[0] = '\0';
    for (int i = 0; i < argc; i++) {
        int quote = strpbrk(argv[i], " \t\"'") != NULL || argv[i][0] == '\0';
        if (i)
            strcat(s, " ");
        if (quote)
            strcat(s, "'");
        strcat(s, argv[i]);
        if (quote)
            strcat(s, "'");
    }
    return s;
}

/* Ctrl-C and kill stop the run cleanly (bn_interrupted); a file-size limit fails a write. */
static void bn__signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = bn__on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    /* Past a file-size limit (ulimit -f) a write fails with EFBIG, which every writer reports and
     * cleans up after, instead of the default SIGXFSZ killing the process mid-file. */
    signal(SIGXFSZ, SIG_IGN);
}

/* Under mpirun: join MPI; rank 0 alone prints (outputs: bn__tmpname_commit). The exit code on
 * failure, else -1. */
static int bn__join_mpi(int *argc, char ***argv)
{
    bn_error err;
    bn_error_clear(&err);
    if (bn_dist_init(argc, argv, &err) != BN_OK) {
        bn_cli_fail(&err);
        return bn_status_exit_code(err.status);
    }
    if (bn_dist_rank() != 0 && (!freopen("/dev/null", "w", stdout) || !freopen("/dev/null", "w", stderr)))
        bn_dist_abort(1);
    return -1;
}

/* The command line for every output's provenance, with the process count under mpirun (NULL when
 * out of memory). */
static char *bn__provenance_cmdline(int argc, char **argv)
{
    char *cmdline = bn__join_cmdline(argc, argv);
    if (cmdline && bn_dist_size() > 1) {
        size_t n = strlen(cmdline) + 48;
        char *m = malloc(n);
        if (m) {
            snprintf(m, n, "mpirun -np %d %s", bn_dist_size(), cmdline);
            free(cmdline);
            cmdline = m;
        }
    }
    return cmdline;
}

int main(int argc, char **argv)
{
    bn_cli_common common;
    int rc;
    char *cmdline;

    bn__signals();
    if (argc < 2) {
        bn__usage(stderr);
        return 2;
    }
    if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0 || strcmp(argv[1], "help") == 0) {
        bn__usage(stdout);
        return 0;
    }
    if (strcmp(argv[1], "--version") == 0) {
        printf("bounce %s\n", bn_version());
        return 0;
    }
    if ((rc = bn__join_mpi(&argc, &argv)) >= 0)
        return rc;
    memset(&common, 0, sizeof common);
    common.seed = 1;
    common.quiet = bn_dist_rank() != 0;
    cmdline = bn__provenance_cmdline(argc, argv);
    common.cmdline = cmdline ? cmdline : "bounce";
    for (size_t i = 0; i < BN__NCOMMANDS; i++)
        if (strcmp(argv[1], bn__commands[i].name) == 0) {
            rc = bn__commands[i].run(argc - 1, argv + 1, &common);
            if (bn_interrupted() != BN_OK) {
                bn__tmp_remove_all();
                fprintf(stderr, "bounce: interrupted; no partial output was left\n");
                rc = bn_cli_interrupted();
            }
            free(cmdline);
            bn_dist_finalize();
            return rc;
        }
    fprintf(stderr, "bounce: error: unknown command '%s'\n\n", argv[1]);
    bn__usage(stderr);
    free(cmdline);
    return 2;
}
