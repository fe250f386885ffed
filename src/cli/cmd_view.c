/* `bounce view SCENE-or-BAKE.glb -o page.html`: the viewer page (bn_view_write). A scene is baked
 * first (`bounce bake --per-bounce` with the options given, into a temporary .glb beside the page). */
#include "cli/cli.h"
#include "bounce/bake.h"
#include "base/internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

static const char *bn__view_help =
    "usage: bounce view SCENE-or-BAKE.glb [-o page.html] [bake options]\n\n"
    "Writes one self-contained HTML page (the bake and three.js embedded; no network when viewing)\n"
    "that shows the baked radiance in a browser: orbit the camera (drag, wheel), show each term\n"
    "E, KE, K2E, ..., rest alone ('alone') or summed (check boxes; 'L' shows them all), set the\n"
    "exposure, switch to false colour (log10 radiance, with its scale), and read the power of each\n"
    "term. A .glb from `bounce bake --per-bounce` is embedded as it is; a scene (.obj, .ply, .off) is\n"
    "baked first with `bounce bake --per-bounce` and the options given (see bounce bake --help).\n"
    "The page's URL may carry #terms=E,KE&ev=1.5&fc=1 (terms shown, exposure, false colour).\n\n"
    "options:\n"
    "  -o, --output FILE.html   the page (default view.html)\n"
    "  -q, --quiet              no progress or summary\n"
    "  -h, --help               this help\n";

int bn_cmd_view(int argc, char **argv, bn_cli_common *c)
{
    const char *in = NULL, *out = "view.html", *title;
    char **bargv = NULL, *tmp = NULL;
    int bargc = 0, rc = 0, quiet = 0;
    bn_error err;
    bn_status st;
    bn_error_clear(&err);
    bargv = calloc((size_t)argc + 6, sizeof *bargv);
    if (!bargv) {
        fprintf(stderr, "bounce: error: out of memory\n");
        return bn_status_exit_code(BN_ENOMEM);
    }
    bargv[bargc++] = "bake";
    for (int i = 1; i < argc; i++) {   /* -o is the page's; everything else goes to the bake */
        if (strcmp(argv[i], "-h") == 0 || strcmp(argv[i], "--help") == 0) {
            fputs(bn__view_help, stdout);
            free(bargv);
            return 0;
        }
        if (strcmp(argv[i], "-o") == 0 || strcmp(argv[i], "--output") == 0) {
            if (i + 1 >= argc) {
                fprintf(stderr, "bounce: error: %s needs a value (see --help)\n", argv[i]);
                free(bargv);
                return 2;
            }
            out = argv[++i];
            continue;
        }
        if (strncmp(argv[i], "--output=", 9) == 0) {
            out = argv[i] + 9;
            continue;
        }
        if (strcmp(argv[i], "-q") == 0 || strcmp(argv[i], "--quiet") == 0) {
            quiet = 1;
            continue;   /* the bake is quiet anyway (below) */
        }
        if (argv[i][0] != '-' && !in)
            in = argv[i];
        bargv[bargc++] = argv[i];
    }
    if (!in) {
        fprintf(stderr, "bounce: error: view needs a scene or a .glb bake (see --help)\n");
        free(bargv);
        return 2;
    }
    {
        size_t n = strlen(out);
        if (n < 5 || strcasecmp(out + n - 5, ".html") != 0) {
            fprintf(stderr, "bounce: error: -o %s: the page is written as .html\n", out);
            free(bargv);
            return 2;
        }
    }
    title = strrchr(in, '/') ? strrchr(in, '/') + 1 : in;
    {
        size_t n = strlen(in);
        if (n > 4 && strcasecmp(in + n - 4, ".glb") == 0) {
            if (bargc > 2) {
                fprintf(stderr, "bounce: error: view of a .glb takes no bake options (only -o): %s\n", bargv[2]);
                free(bargv);
                return 2;
            }
            st = bn_view_write(in, title, out, &err);
        } else {   /* bake into a temporary .glb beside the page, then embed it */
            size_t len = strlen(out) + 32;
            tmp = malloc(len);
            if (!tmp) {
                free(bargv);
                return bn_status_exit_code(BN_ENOMEM);
            }
            snprintf(tmp, len, "%s.%ld.bake.glb", out, (long)getpid());
            bargv[bargc++] = "--per-bounce";
            bargv[bargc++] = "-q";
            bargv[bargc++] = "-o";
            bargv[bargc++] = tmp;
            {
                int q = c->quiet;   /* the bake runs with -q, which sets it */
                rc = bn_cmd_bake(bargc, bargv, c);
                c->quiet = q;
            }
            if (rc != 0) {
                unlink(tmp);
                free(tmp);
                free(bargv);
                return rc;
            }
            st = bn_view_write(tmp, title, out, &err);
            unlink(tmp);
        }
    }
    if (st != BN_OK)
        rc = bn_cli_fail(&err);
    else if (!quiet && !c->quiet)
        printf("wrote %s (open it in a browser; %s)\n", out, title);
    free(tmp);
    free(bargv);
    return rc;
}
