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
    "term. A .glb from `bounce bake --per-bounce` is embedded as it is; a scene (.obj, .ply, .off, a glTF) is\n"
    "baked first with `bounce bake --per-bounce` and the options given (see bounce bake --help; --cache FILE\n"
    "keeps the form factors of dense and sparse transports for the next run), and the bake is kept beside\n"
    "the page (view.html: view.bake.glb): `bounce view view.bake.glb` shows it again without solving.\n"
    "The page's URL follows what it shows: #terms=E,KE&ev=1.5 (or ev=auto: each view exposed by\n"
    "itself)&fc=1&cam=x,y,z,tx,ty,tz (metres)&panel=folded; copy it to share the view.\n"
    "bounce view --live SCENE: a page that relights the scene in the browser (see bounce view --live --help).\n\n"
    "options:\n"
    "  -o, --output FILE.html   the page (default view.html)\n"
    "  -q, --quiet              no progress or summary\n"
    "  -h, --help               this help\n";

/* The command line: the page (-o), -q, and everything else for the bake (bargv, from "bake"; room for
 * four more). 0 to go on; else the exit code (after --help: 0 through *done). */
typedef struct bn__view_cli {
    const char *in, *out;
    char **bargv;
    int bargc, quiet;
} bn__view_cli;

static int bn__view_args(int argc, char **argv, bn__view_cli *v, int *done)
{
    *done = 0;
    v->out = "view.html";
    if (!(v->bargv = calloc((size_t)argc + 7, sizeof *v->bargv))) {
        fprintf(stderr, "bounce: error: out of memory\n");
        return bn_status_exit_code(BN_ENOMEM);
    }
    v->bargv[v->bargc++] = "bake";
    for (int i = 1; i < argc; i++) {   /* -o is the page's; everything else goes to the bake */
        if (strcmp(argv[i], "-h") == 0 || strcmp(argv[i], "--help") == 0) {
            fputs(bn__view_help, stdout);
            *done = 1;
            return 0;
        }
        if (strcmp(argv[i], "-o") == 0 || strcmp(argv[i], "--output") == 0) {
            if (i + 1 >= argc) {
                fprintf(stderr, "bounce: error: %s needs a value (see --help)\n", argv[i]);
                return 2;
            }
            v->out = argv[++i];
        } else if (strncmp(argv[i], "--output=", 9) == 0)
            v->out = argv[i] + 9;
        else if (strcmp(argv[i], "-q") == 0 || strcmp(argv[i], "--quiet") == 0)
            v->quiet = 1;   /* and the bake's progress and notes (bn__view_bake) */
        else {
            if (argv[i][0] != '-' && !v->in)
                v->in = argv[i];
            v->bargv[v->bargc++] = argv[i];
        }
    }
    if (!v->in) {
        fprintf(stderr, "bounce: error: view needs a scene or a .glb bake (see --help)\n");
        return 2;
    }
    size_t n = strlen(v->out);
    if (n < 5 || strcasecmp(v->out + n - 5, ".html") != 0) {
        fprintf(stderr, "bounce: error: -o %s: the page is written as .html\n", v->out);
        return 2;
    }
    return 0;
}

/* Where a scene's bake is kept: the page's stem + ".bake.glb" (view.html: view.bake.glb), so the next
 * `bounce view view.bake.glb` builds the page again without solving; malloc'd. */
static char *bn__view_bake_path(const bn__view_cli *v)
{
    size_t n = strlen(v->out), len = n + 16;
    char *path = malloc(len);
    if (path)
        snprintf(path, len, "%.*s.bake.glb", (int)(n - 5), v->out);
    return path;
}

/* A scene baked (bounce bake --per-bounce, its progress and notes shown unless -q) into the .glb beside the
 * page (bn__view_bake_path; a temporary when that would be the input itself), then embedded. */
static int bn__view_bake(bn__view_cli *v, const char *title, bn_cli_common *c, bn_error *err, bn_status *st,
                         char **kept)
{
    char *glb = bn__view_bake_path(v);
    int rc, temporary = glb && strcmp(glb, v->in) == 0;
    if (!glb)
        return bn_status_exit_code(BN_ENOMEM);
    if (temporary)
        snprintf(glb + strlen(v->out) - 5, 16 + 5, ".%ld.glb", (long)getpid());
    v->bargv[v->bargc++] = "--per-bounce";
    v->bargv[v->bargc++] = "--no-colour-sets";   /* the page reads the float terms: half the bytes */
    v->bargv[v->bargc++] = "-o";
    v->bargv[v->bargc++] = glb;
    if (v->quiet)
        v->bargv[v->bargc++] = "-q";
    else
        fprintf(stderr, "bounce: view: baking %s first (bounce bake --per-bounce, kept as %s; a .glb bake is "
                        "embedded as it is, without solving)\n", v->in, glb);
    c->no_summary = 1;   /* its progress and notes, not its "wrote" line */
    rc = bn_cmd_bake(v->bargc, v->bargv, c);
    c->no_summary = 0;
    if (rc == 0)
        *st = bn_view_write(glb, title, v->out, err);
    if (temporary || rc != 0 || *st != BN_OK) {
        unlink(glb);
        free(glb);
        glb = NULL;
    }
    *kept = glb;
    return rc;
}

int bn_cmd_view(int argc, char **argv, bn_cli_common *c)
{
    bn__view_cli v = {0};
    const char *title;
    char *kept = NULL;
    int rc, done;
    bn_error err;
    bn_status st = BN_OK;
    bn_error_clear(&err);
    for (int i = 1; i < argc; i++)
        if (strcmp(argv[i], "--live") == 0)
            return bn_cmd_view_live(argc, argv, c);
    rc = bn__view_args(argc, argv, &v, &done);
    if (rc != 0 || done) {
        free(v.bargv);
        return rc;
    }
    title = strrchr(v.in, '/') ? strrchr(v.in, '/') + 1 : v.in;
    size_t n = strlen(v.in);
    if (n > 4 && strcasecmp(v.in + n - 4, ".glb") == 0 && bn_view_is_bake(v.in) != 0) {   /* a bake (or unreadable) */
        if (v.bargc > 2) {
            fprintf(stderr, "bounce: error: view of a .glb takes no bake options (only -o): %s\n", v.bargv[2]);
            free(v.bargv);
            return 2;
        }
        st = bn_view_write(v.in, title, v.out, &err);
    } else if ((rc = bn__view_bake(&v, title, c, &err, &st, &kept)) != 0) {
        free(v.bargv);
        return rc;
    }
    if (st != BN_OK)
        rc = bn_cli_fail(&err);
    else if (!v.quiet && !c->quiet && kept)
        printf("wrote %s (open it in a browser; %s) and its bake %s: `bounce view %s -o %s` builds the page again "
               "without solving\n", v.out, title, kept, kept, v.out);
    else if (!v.quiet && !c->quiet)
        printf("wrote %s (open it in a browser; %s)\n", v.out, title);
    free(kept);
    free(v.bargv);
    return rc;
}
