/* Table-driven option parsing shared by every subcommand: --name VALUE, --name=VALUE, -x VALUE. */
#include "cli/cli.h"
#include "base/internal.h"
#include "bounce/gather.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

const char bn_cli_exit_codes[] =
    "Exit codes: 0 success; 2 usage error; 3 bad input (scene or option values); 4 resource limit\n"
    "(memory); 5 numerical failure (singular, diverged, NaN, not converged within the iteration\n"
    "limit); 6 a cross-check or study verdict failed; 130 / 143 interrupted by SIGINT / SIGTERM.\n";

void bn_optset_add(bn_optset *s, bn_opt o)
{
    BN_CHECK(s->n < BN_CLI_MAX_OPTS);
    s->opt[s->n++] = o;
}

int bn_cli_given(const bn_optset *s, const char *name)
{
    for (size_t i = 0; i < s->n; i++)
        if (strcmp(s->opt[i].name, name) == 0)
            return s->seen[i];
    return 0;
}

static int bn__choice_index(const char *choices, const char *v)
{
    const char *p = choices;
    int idx = 0;
    size_t n = strlen(v);
    while (p && *p) {
        const char *bar = strchr(p, '|');
        size_t len = bar ? (size_t)(bar - p) : strlen(p);
        if (len == n && strncmp(p, v, n) == 0)
            return idx;
        idx++;
        p = bar ? bar + 1 : NULL;
    }
    return -1;
}

static int bn__parse_num(const char *v, double *out)
{
    char *end;
    double x;
    if (!v || !*v)
        return 0;
    errno = 0;
    x = strtod(v, &end);
    if (*end != '\0' || end == v || !isfinite(x))
        return 0;
    *out = x;
    return 1;
}

/* "X,Y,Z": three finite numbers. */
static bn_status bn__set_vec3(const bn_opt *o, const char *v, bn_error *err)
{
    double p[3];
    char buf[256], *a, *b;
    if (strlen(v) >= sizeof buf)
        return bn_error_set(err, BN_EUSAGE, "--%s: value too long", o->name);
    memcpy(buf, v, strlen(v) + 1);
    a = strchr(buf, ',');
    b = a ? strchr(a + 1, ',') : NULL;
    if (!a || !b)
        return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not X,Y,Z", o->name, v);
    *a = *b = '\0';
    if (!bn__parse_num(buf, &p[0]) || !bn__parse_num(a + 1, &p[1]) || !bn__parse_num(b + 1, &p[2]))
        return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not three finite numbers X,Y,Z", o->name, v);
    memcpy(o->dest, p, sizeof p);
    return BN_OK;
}

/* "WIDTHxHEIGHT", each side in [min, max]. */
static bn_status bn__set_wxh(const bn_opt *o, const char *v, bn_error *err)
{
    char *end;
    const char *orig = v;
    long w, h;
    errno = 0;
    w = strtol(v, &end, 10);
    if (end == v || *end != 'x' || errno)
        return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not WIDTHxHEIGHT", o->name, v);
    v = end + 1;
    h = strtol(v, &end, 10);
    if (end == v || *end != '\0' || errno || w < o->min || h < o->min || w > o->max || h > o->max)
        return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not WIDTHxHEIGHT with sides in [%g, %g]", o->name, orig,
                            o->min, o->max);
    ((int *)o->dest)[0] = (int)w;
    ((int *)o->dest)[1] = (int)h;
    return BN_OK;
}

/* An int, size or double within [min, max] (whole for the first two). */
static bn_status bn__set_number(const bn_opt *o, const char *v, bn_error *err)
{
    double x, scale = 1;
    char num[64];
    const char *given = v;   /* messages name the value as given, suffix included */
    size_t len = strlen(v);
    if (o->type == BN_OPT_SIZE && len > 1 && len < sizeof num && (v[len - 1] == 'k' || v[len - 1] == 'M')) {
        scale = v[len - 1] == 'k' ? 1e3 : 1e6;   /* 200k, 1M */
        memcpy(num, v, len - 1);
        num[len - 1] = '\0';
        v = num;
    }
    if (!bn__parse_num(v, &x))
        return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not a finite number", o->name, given);
    x *= scale;
    if (x < o->min || x > o->max)
        return bn_error_set(err, BN_EUSAGE, "--%s: %s is outside [%g, %g]", o->name, given, o->min, o->max);
    if (o->type != BN_OPT_DOUBLE && x != floor(x))
        return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not a whole number", o->name, given);
    if (o->type == BN_OPT_INT)
        *(int *)o->dest = (int)x;
    else if (o->type == BN_OPT_SIZE)
        *(size_t *)o->dest = (size_t)x;
    else
        *(double *)o->dest = x;
    return BN_OK;
}

static bn_status bn__set(const bn_opt *o, const char *v, bn_error *err)
{
    switch (o->type) {
    case BN_OPT_FLAG:
        *(int *)o->dest = 1;
        return BN_OK;
    case BN_OPT_STRING:
        if (!*v)
            return bn_error_set(err, BN_EUSAGE, "--%s needs a non-empty value", o->name);
        *(const char **)o->dest = v;
        return BN_OK;
    case BN_OPT_NAME:
        if (bn__choice_index(o->choices, v) < 0)
            return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not one of %s", o->name, v, o->choices);
        *(const char **)o->dest = v;
        return BN_OK;
    case BN_OPT_CHOICE: {
        int i = bn__choice_index(o->choices, v);
        if (i < 0)
            return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not one of %s", o->name, v, o->choices);
        *(int *)o->dest = i;
        return BN_OK;
    }
    case BN_OPT_VEC3:
        return bn__set_vec3(o, v, err);
    case BN_OPT_WXH:
        return bn__set_wxh(o, v, err);
    case BN_OPT_U64: {
        char *end;
        unsigned long long u;
        errno = 0;
        u = strtoull(v, &end, 0);
        if (end == v || *end != '\0' || errno || v[0] == '-')
            return bn_error_set(err, BN_EUSAGE, "--%s: '%s' is not a non-negative integer", o->name, v);
        *(uint64_t *)o->dest = u;
        return BN_OK;
    }
    case BN_OPT_INT:
    case BN_OPT_SIZE:
    case BN_OPT_DOUBLE:
        return bn__set_number(o, v, err);
    case BN_OPT_EDIT: {
        bn_cli_edits *l = o->dest;
        if (l->n == BN_CLI_MAX_EDITS)
            return bn_error_set(err, BN_EUSAGE, "--%s: more than %d material edits", o->name, BN_CLI_MAX_EDITS);
        bn_status st = bn_material_edit_parse(o->choices, v, &l->e[l->n], err);
        l->n += st == BN_OK;
        return st;
    }
    }
    return bn_error_set(err, BN_EINTERNAL, "option type");
}

bn_status bn_cli_parse(bn_optset *s, int argc, char **argv, const char **positional, size_t max_positional,
                       size_t *npositional, int *help, bn_error *err)
{
    int only_positional = 0;
    *npositional = 0;
    *help = 0;
    memset(s->seen, 0, sizeof s->seen);
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *val = NULL;
        const bn_opt *o = NULL;
        size_t oi = 0;
        char name[128];
        if (only_positional || a[0] != '-' || a[1] == '\0') {
            if (*npositional >= max_positional)
                return bn_error_set(err, BN_EUSAGE, "unexpected argument '%s' (see --help)", a);
            positional[(*npositional)++] = a;
            continue;
        }
        if (strcmp(a, "--") == 0) {
            only_positional = 1;
            continue;
        }
        if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            *help = 1;
            return BN_OK;
        }
        if (strcmp(a, "--version") == 0) {
            *help = 2;
            return BN_OK;
        }
        if (a[1] == '-') {
            const char *eq = strchr(a + 2, '=');
            size_t len = eq ? (size_t)(eq - (a + 2)) : strlen(a + 2);
            if (len >= sizeof name)
                return bn_error_set(err, BN_EUSAGE, "unknown option '%.40s...'", a);
            memcpy(name, a + 2, len);
            name[len] = '\0';
            if (eq)
                val = eq + 1;
            for (oi = 0; oi < s->n; oi++)
                if (strcmp(s->opt[oi].name, name) == 0) {
                    o = &s->opt[oi];
                    break;
                }
        } else if (a[2] == '\0') {
            for (oi = 0; oi < s->n; oi++)
                if (s->opt[oi].short_name == a[1]) {
                    o = &s->opt[oi];
                    break;
                }
        }
        if (!o)
            return bn_error_set(err, BN_EUSAGE, "unknown option '%s' (see --help)", a);
        if (o->type == BN_OPT_FLAG) {
            if (val)
                return bn_error_set(err, BN_EUSAGE, "--%s takes no value", o->name);
        } else if (!val) {
            if (i + 1 >= argc)
                return bn_error_set(err, BN_EUSAGE, "--%s needs a value (%s)", o->name, o->metavar ? o->metavar : "");
            val = argv[++i];
        }
        {
            bn_status st = bn__set(o, val, err);
            if (st != BN_OK)
                return st;
        }
        s->seen[oi] = 1;
    }
    return BN_OK;
}

int bn_cli_parse_scene_command(bn_optset *s, int argc, char **argv, const char **pos, int *rc)
{
    bn_error err;
    size_t npos;
    int help;
    bn_error_clear(&err);
    if (bn_cli_parse(s, argc, argv, pos, 1, &npos, &help, &err) != BN_OK) {
        *rc = bn_cli_fail(&err);
        return 0;
    }
    if (help) {
        if (help == 2)
            printf("bounce %s\n", bn_version());
        else
            bn_cli_print_help(s, stdout);
        *rc = 0;
        return 0;
    }
    if (npos != 1) {
        bn_error_set(&err, BN_EUSAGE, "%s needs one SCENE argument (see --help)", argv[0]);
        *rc = bn_cli_fail(&err);
        return 0;
    }
    return 1;
}

void bn_cli_print_help(const bn_optset *s, FILE *fp)
{
    fprintf(fp, "usage: %s\n\n%s\n\noptions:\n", s->usage, s->summary);
    for (size_t i = 0; i < s->n; i++) {
        const bn_opt *o = &s->opt[i];
        char left[96];
        if (o->short_name)
            snprintf(left, sizeof left, "-%c, --%s%s%s", o->short_name, o->name, o->metavar ? " " : "",
                     o->metavar ? o->metavar : "");
        else
            snprintf(left, sizeof left, "    --%s%s%s", o->name, o->metavar ? " " : "", o->metavar ? o->metavar : "");
        fprintf(fp, "  %-28s %s\n", left, o->help);
    }
    fprintf(fp, "  %-28s %s\n", "    --version", "print the version");
    fprintf(fp, "  %-28s %s\n\n%s", "-h, --help", "this help", bn_cli_exit_codes);
}

void bn_cli_add_common(bn_optset *s, bn_cli_common *c)
{
    bn_optset_add(s, (bn_opt){"threads", 0, BN_OPT_INT, &c->threads, NULL, 0, 4096, "N",
                              "threads (default 0: all cores); results do not depend on it"});
    bn_optset_add(s, (bn_opt){"seed", 0, BN_OPT_U64, &c->seed, NULL, 0, 0, "S",
                              "random seed for every sampled quantity (default 1)"});
    bn_optset_add(s, (bn_opt){"quiet", 'q', BN_OPT_FLAG, &c->quiet, NULL, 0, 0, NULL,
                              "no progress bars or summaries; warnings and errors only"});
}

void bn_cli_add_scene(bn_optset *s, bn_cli_scene *o)
{
    bn_optset_add(s, (bn_opt){"unit", 0, BN_OPT_CHOICE, &o->unit, bn_unit_names(), 0, 0, bn_unit_names(),
                              "length unit of the scene file, for SI areas and powers (default m)"});
    bn_optset_add(s, (bn_opt){"patch-size", 0, BN_OPT_DOUBLE, &o->patch_size, NULL, 1e-300, 1e300, "S",
                              "largest patch edge, scene units (default: from --patches)"});
    bn_optset_add(s, (bn_opt){"patches", 0, BN_OPT_SIZE, &o->patches, NULL, 1, 1e9, "N",
                              "target patch count of the faces the mesher splits; faces smaller than the patch stay whole "
                              "besides (default " BN__STR(BN_DEFAULT_PATCHES) "; `bounce bounces` with the final "
                              "gather: " BN__STR(BN_GATHER_PATCHES) ")"});
    bn_optset_add(s, (bn_opt){"no-subdivide", 0, BN_OPT_FLAG, &o->no_subdivide, NULL, 0, 0, NULL,
                              "one patch per input polygon (after triangulation; no contact cuts)"});
    bn_optset_add(s, (bn_opt){"no-contacts", 0, BN_OPT_FLAG, &o->no_contacts, NULL, 0, 0, NULL,
                              "do not split patches along contact lines (where a face touches or pierces another's front, as a block on the floor)"});
    bn_optset_add(s, (bn_opt){"self-contacts", 0, BN_OPT_FLAG, &o->self_contacts, NULL, 0, 0, NULL,
                              "also split where an object touches itself (its own touching or interpenetrating parts; default: only where one object touches another; objects: `bounce info`)"});
    bn_optset_add(s, (bn_opt){"contact-gap", 0, BN_OPT_DOUBLE, &o->contact_gap, NULL, 0, 1e300, "G",
                              "distance from a face's plane that still counts as touching it, scene units (default 1e-6 of the scene's diameter)"});
    bn_optset_add(s, (bn_opt){"two-sided", 0, BN_OPT_STRING, &o->two_sided, NULL, 0, 0, "MATERIALS|all|none",
                              "materials (names separated by commas, or all) whose faces reflect and emit on both sides, each side with its own radiance, besides those the file marks (glTF doubleSided); none: every surface one-sided, the file's marks too; none,NAMES: only these (default: only the file's; OBJ, PLY and OFF have none)"});
    bn_optset_add(s, (bn_opt){"set-rho", 0, BN_OPT_EDIT, &o->edits, "rho", 0, 0, "MATERIAL=R,G,B",
                              "the material's reflectance replaced (each channel in [0, 1]; one value: grey; given "
                              "again for more materials); F does not change, so a form-factor --cache made before "
                              "still serves"});
    bn_optset_add(s, (bn_opt){"set-Le", 0, BN_OPT_EDIT, &o->edits, "Le", 0, 0, "MATERIAL=R,G,B",
                              "the material's emitted radiance replaced, W m^-2 sr^-1 (>= 0; 0 turns a light off; "
                              "given again for more)"});
    bn_optset_add(s, (bn_opt){"orient", 0, BN_OPT_CHOICE, &o->orient, "normals|winding", 0, 0, "normals|winding",
                              "which side of a face is its front where the file gives vertex normals (OBJ vn): the side they point to, faces wound against them turned (default), or the winding's (right-hand rule)"});
    bn_optset_add(s, (bn_opt){"planar-tol", 0, BN_OPT_DOUBLE, &o->planar_tol, NULL, 0, 1, "T",
                              "non-planarity allowed before a polygon is split, relative to its size (default 1e-6)"});
}

/* The library names its options as they are in its structs, backquoted (`max_iter`, `patch_size`);
 * on the command line they are flags: `--max-iter`, `--patch-size`, with these exceptions. */
static const char *const bn__flag_exceptions[][2] = {
    {"ff_method", "--ff"}, {"visibility", "--ff-visibility"},
};

/* msg with each `name` written as its command-line flag, into out. */
const char *bn_cli_translate(const char *msg, char *out, size_t n)
{
    size_t k = 0;
    for (const char *p = msg; *p && k + 1 < n; p++) {
        const char *e = *p == '`' ? strchr(p + 1, '`') : NULL;
        if (!e) {
            out[k++] = *p;
            continue;
        }
        char name[64], flag[80];
        snprintf(name, sizeof name, "%.*s", (int)(e - p - 1), p + 1);
        snprintf(flag, sizeof flag, "--%s", name);
        for (char *q = flag; *q; q++)
            *q = *q == '_' ? '-' : *q;
        for (size_t i = 0; i < sizeof bn__flag_exceptions / sizeof bn__flag_exceptions[0]; i++)
            if (!strcmp(name, bn__flag_exceptions[i][0]))
                snprintf(flag, sizeof flag, "%s", bn__flag_exceptions[i][1]);
        k += (size_t)snprintf(out + k, n - k, "%s", flag);
        k = k < n ? k : n - 1;
        p = e;
    }
    out[k] = '\0';
    return out;
}

/* A warning as the compilers write theirs: the text, then its code in brackets. The first
 * BN__CLI_WARN_SHOWN of each code are printed as they come; the rest are counted, the worst kept
 * (by the warning's measure; the latest when it has none), and said once when the command ends
 * (a real asset's 2,321 back-to-back faces are 5 lines and a count, not 2,321 lines). */
#define BN__CLI_WARN_SHOWN 5

typedef struct bn__cli_held {
    size_t count;
    double value;
    char text[2304];
} bn__cli_held;

static bn__cli_held bn__cli_held_[BN_WARNING_COUNT];
static size_t bn__cli_seen[BN_WARNING_COUNT];
static pthread_mutex_t bn__cli_warn_lock = PTHREAD_MUTEX_INITIALIZER;

static void bn__cli_held_flush(void)
{
    for (int c = 0; c < BN_WARNING_COUNT; c++) {
        const bn__cli_held *h = &bn__cli_held_[c];
        if (h->count)
            fprintf(stderr, "bounce: warning: %zu more like the %d above (%zu in all; %s): %s [%s]\n", h->count,
                    BN__CLI_WARN_SHOWN, h->count + BN__CLI_WARN_SHOWN,
                    isfinite(h->value) ? "the worst of them" : "the last of them", h->text,
                    bn_warning_name((bn_warning)c));
    }
}

static void bn__cli_warning(const bn_message *m)
{
    char t[2304];
    unsigned c = (unsigned)m->code;
    bn_cli_translate(m->text, t, sizeof t);
    pthread_mutex_lock(&bn__cli_warn_lock);   /* warnings may come from the library's threads */
    {
        if (c >= BN_WARNING_COUNT || bn__cli_seen[c]++ < BN__CLI_WARN_SHOWN) {
            fprintf(stderr, "bounce: warning: %s [%s]\n", t, bn_warning_name(m->code));
        } else {
            bn__cli_held *h = &bn__cli_held_[c];
            static int registered;
            if (!registered)
                registered = atexit(bn__cli_held_flush) == 0;
            if (h->count++ == 0 || !isfinite(m->value) || !(m->value <= h->value)) {
                h->value = m->value;
                snprintf(h->text, sizeof h->text, "%s", t);
            }
        }
    }
    pthread_mutex_unlock(&bn__cli_warn_lock);
}

void bn_cli_log(void *user, const bn_message *m)
{
    const bn_cli_common *c = user;
    char t[2304];
    if (m->level == BN_LOG_WARN)
        bn__cli_warning(m);
    else if (m->level == BN_LOG_INFO && !c->quiet)
        fprintf(stderr, "bounce: %s\n", bn_cli_translate(m->text, t, sizeof t));
}

bn_status bn_cli_load_scene(const char *path, const bn_cli_scene *o, const bn_cli_common *c, const char *transport,
                            bn_scene **out)
{
    bn_pipeline_opts po;
    bn_pipeline p;
    bn_error err;
    bn_status st;
    bn_error_clear(&err);
    bn_cli_pipeline_opts(o, NULL, NULL, c, &po);
    po.transport = transport;
    st = bn_pipeline_scene(path, &po, &p, &err);
    *out = p.scene;
    if (st != BN_OK)
        bn_cli_fail(&err);
    return st;
}

void bn_cli_stdout_log(void *user, const bn_message *m)
{
    const bn_cli_common *c = user;
    char t[2304];
    if (m->level == BN_LOG_WARN)
        bn__cli_warning(m);
    else if (m->level == BN_LOG_INFO && !c->quiet)
        printf("%s\n", bn_cli_translate(m->text, t, sizeof t));
}

int bn_cli_fail(const bn_error *err)
{
    char t[BN_ERROR_MSG_MAX + 256];
    fprintf(stderr, "bounce: error: %s\n", err->msg[0] ? bn_cli_translate(err->msg, t, sizeof t) : bn_status_str(err->status));
    return bn_status_exit_code(err->status);
}

int bn_cli_interrupted(void)
{
    bn_status s = bn_interrupted();
    return s == BN_OK ? 0 : bn_status_exit_code(s);
}


const char *bn_cli_auto_or(const char *names)
{
    static char buf[8][160];
    static int next;
    char *b = buf[next++ % 8];
    snprintf(b, sizeof buf[0], "auto|%s", names);
    return b;
}

void bn_cli_method(const char *name, bn_solve_method *m, int *method_auto)
{
    *method_auto = !name || !strcmp(name, "auto");
    if (!*method_auto)
        bn_solve_method_parse(name, m);   /* checked against the names when parsed */
}
