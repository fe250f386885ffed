/* libFuzzer harness: the option parser, with every shared option group (common, scene, form
 * factors, camera, solver) and one option of each type, on arbitrary argument vectors
 * (NUL-separated). */
#include "cli/cli.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    bn_optset set;
    bn_cli_common common;
    bn_cli_scene scene;
    bn_cli_ff ff;
    bn_cli_camera cam;
    bn_cli_solution sol;
    char *buf, *argv[64];
    const char *pos[4];
    int argc = 1, help = 0, ival = 0, choice = 0, wh[2] = {0, 0};
    double d = 0, v3[3];
    size_t npos, sz = 0;
    uint64_t u = 0;
    const char *str = NULL;
    bn_error err;

    if (size > 4096)
        return 0;
    buf = malloc(size + 1);
    memcpy(buf, data, size);
    buf[size] = '\0';
    argv[0] = "bounce-fuzz";
    for (size_t i = 0; i < size && argc < 63;) {
        argv[argc++] = buf + i;
        i += strlen(buf + i) + 1;
    }
    argv[argc] = NULL;
    memset(&set, 0, sizeof set);
    memset(&common, 0, sizeof common);
    memset(&scene, 0, sizeof scene);
    memset(&ff, 0, sizeof ff);
    memset(&cam, 0, sizeof cam);
    memset(&sol, 0, sizeof sol);
    set.usage = "fuzz";
    set.summary = "fuzz";
    bn_cli_add_scene(&set, &scene);
    bn_cli_add_ff(&set, &ff);
    bn_cli_add_camera(&set, &cam);
    bn_cli_add_solution(&set, &sol);
    bn_cli_add_common(&set, &common);
    bn_optset_add(&set, (bn_opt){"fz-int", 'i', BN_OPT_INT, &ival, NULL, -5, 5, "N", ""});
    bn_optset_add(&set, (bn_opt){"fz-size", 0, BN_OPT_SIZE, &sz, NULL, 0, 1e12, "N", ""});
    bn_optset_add(&set, (bn_opt){"fz-dbl", 0, BN_OPT_DOUBLE, &d, NULL, -1e3, 1e3, "X", ""});
    bn_optset_add(&set, (bn_opt){"fz-choice", 'c', BN_OPT_CHOICE, &choice, "a|bb|ccc", 0, 0, "C", ""});
    bn_optset_add(&set, (bn_opt){"fz-vec", 0, BN_OPT_VEC3, v3, NULL, 0, 0, "X,Y,Z", ""});
    bn_optset_add(&set, (bn_opt){"fz-wxh", 0, BN_OPT_WXH, wh, NULL, 1, 16384, "WxH", ""});
    bn_optset_add(&set, (bn_opt){"fz-u64", 0, BN_OPT_U64, &u, NULL, 0, 0, "S", ""});
    bn_optset_add(&set, (bn_opt){"fz-str", 's', BN_OPT_STRING, &str, NULL, 0, 0, "S", ""});
    (void)bn_cli_parse(&set, argc, argv, pos, 4, &npos, &help, &err);
    free(buf);
    return 0;
}
